//! The batch's picture: leaf area per plant, one column per plant (in table order), every
//! leaf a dot and the median a bar, drawn with OpenCV and written as PNG.

use opencv::core::{Mat, Point, Scalar, Vector};
use opencv::imgproc;

use crate::traits::TraitRow;

/// A strip plot of the `leaf`/`area` rows, grouped by plant. `metric`: the values are m²
/// (shown as cm²), else model units². Errors when no row is a leaf area.
pub fn leaf_area_plot(rows: &[TraitRow], metric: bool) -> Result<Vec<u8>, String> {
    let synthesized: std::collections::HashSet<(&str, &str)> = rows
        .iter()
        .filter(|r| r.organ_type == "leaf" && r.trait_name == "synthesized" && r.value > 0.5)
        .map(|r| (r.plant.as_str(), r.organ_id.as_str()))
        .collect();
    // Per plant: (area, synthesized) of every leaf.
    let mut plants: Vec<(String, Vec<(f64, bool)>)> = Vec::new();
    for r in rows
        .iter()
        .filter(|r| r.organ_type == "leaf" && r.trait_name == "area" && r.value.is_finite())
    {
        let value = if metric { r.value * 1e4 } else { r.value };
        let posed = synthesized.contains(&(r.plant.as_str(), r.organ_id.as_str()));
        match plants.iter_mut().find(|(p, _)| *p == r.plant) {
            Some((_, values)) => values.push((value, posed)),
            None => plants.push((r.plant.clone(), vec![(value, posed)])),
        }
    }
    if plants.is_empty() {
        return Err("no leaf areas in the table".into());
    }
    let max = plants
        .iter()
        .flat_map(|(_, v)| v.iter().map(|(a, _)| *a))
        .fold(0.0f64, f64::max);
    let top = nice_ceiling(max);
    let (left, right, upper, lower) = (110, 30, 50, 90);
    let column = 90;
    let width = (left + right + column * plants.len() as i32).max(360);
    let height = 480;
    let cv = |e: opencv::Error| e.to_string();
    let mut mat = Mat::new_rows_cols_with_default(
        height,
        width,
        opencv::core::CV_8UC3,
        Scalar::new(255.0, 255.0, 255.0, 0.0),
    )
    .map_err(cv)?;
    let black = Scalar::new(30.0, 30.0, 30.0, 0.0);
    let grey = Scalar::new(200.0, 200.0, 200.0, 0.0);
    let plot_height = (height - upper - lower) as f64;
    let y_of = |v: f64| height - lower - (v / top * plot_height).round() as i32;
    let text = |mat: &mut Mat, s: &str, at: Point, scale: f64| {
        imgproc::put_text(
            mat,
            s,
            at,
            imgproc::FONT_HERSHEY_SIMPLEX,
            scale,
            black,
            1,
            imgproc::LINE_AA,
            false,
        )
    };
    for k in 0..=5 {
        let v = top * k as f64 / 5.0;
        let y = y_of(v);
        imgproc::line(
            &mut mat,
            Point::new(left, y),
            Point::new(width - right, y),
            grey,
            1,
            imgproc::LINE_8,
            0,
        )
        .map_err(cv)?;
        text(&mut mat, &format_tick(v), Point::new(10, y + 5), 0.45).map_err(cv)?;
    }
    let unit = if metric {
        "leaf area (cm2)"
    } else {
        "leaf area (model units^2)"
    };
    text(&mut mat, unit, Point::new(10, 30), 0.6).map_err(cv)?;
    let green = Scalar::new(60.0, 140.0, 40.0, 0.0);
    let red = Scalar::new(40.0, 40.0, 200.0, 0.0);
    let light = Scalar::new(170.0, 200.0, 160.0, 0.0);
    for (k, (plant, values)) in plants.iter().enumerate() {
        let x = left + column * k as i32 + column / 2;
        for (j, (v, posed)) in values.iter().enumerate() {
            // A deterministic spread across the column so that equal areas stay visible.
            let jitter = ((j * 37) % 29) as i32 - 14;
            imgproc::circle(
                &mut mat,
                Point::new(x + jitter, y_of(*v)),
                4,
                if *posed { light } else { green },
                -1,
                imgproc::LINE_AA,
                0,
            )
            .map_err(cv)?;
        }
        let mut sorted: Vec<f64> = values.iter().map(|(a, _)| *a).collect();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
        };
        imgproc::line(
            &mut mat,
            Point::new(x - 25, y_of(median)),
            Point::new(x + 25, y_of(median)),
            red,
            2,
            imgproc::LINE_AA,
            0,
        )
        .map_err(cv)?;
        let label: String = plant.chars().take(10).collect();
        text(
            &mut mat,
            &label,
            Point::new(x - 38, height - lower + 25),
            0.45,
        )
        .map_err(cv)?;
        let count = format!("n={}", values.len());
        text(
            &mut mat,
            &count,
            Point::new(x - 20, height - lower + 45),
            0.4,
        )
        .map_err(cv)?;
    }
    imgproc::line(
        &mut mat,
        Point::new(left, height - lower),
        Point::new(width - right, height - lower),
        black,
        1,
        imgproc::LINE_8,
        0,
    )
    .map_err(cv)?;
    text(
        &mut mat,
        "dots: leaves (pale: synthesized); bar: median",
        Point::new(10, height - 15),
        0.45,
    )
    .map_err(cv)?;
    let mut encoded = Vector::<u8>::new();
    opencv::imgcodecs::imencode(".png", &mat, &mut encoded, &Vector::new()).map_err(cv)?;
    Ok(encoded.as_slice().to_vec())
}

/// 1, 2 or 5 times a power of ten, at least `v`.
fn nice_ceiling(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|c| *c >= v)
        .unwrap_or(10.0 * power)
}

fn format_tick(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 0.1 {
        format!("{v:.1}")
    } else {
        format!("{v:.1e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(plant: &str, value: f64) -> TraitRow {
        TraitRow {
            plant: plant.into(),
            organ_id: "leaf_000".into(),
            organ_type: "leaf".into(),
            trait_name: "area".into(),
            value,
            unit: "m2".into(),
        }
    }

    #[test]
    fn the_plot_has_a_column_per_plant_and_refuses_an_empty_table() {
        let rows = vec![row("a", 0.001), row("a", 0.002), row("b", 0.004)];
        let png = leaf_area_plot(&rows, true).unwrap();
        let image = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(image.height(), 480);
        // At least 360 pixels wide (the axis label's room).
        assert_eq!(image.width(), 360);
        // Green dots in both columns.
        let green_in = |x0: u32, x1: u32| {
            image
                .enumerate_pixels()
                .filter(|(x, _, p)| *x >= x0 && *x < x1 && p[1] > 120 && p[0] < 80 && p[2] < 80)
                .count()
        };
        assert!(green_in(110, 200) > 20);
        assert!(green_in(200, 290) > 10);
        assert!(leaf_area_plot(&[], true).is_err());
        assert_eq!(nice_ceiling(37.0), 50.0);
        assert_eq!(nice_ceiling(0.011), 0.02);
    }
}
