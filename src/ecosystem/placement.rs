//! Plant positions from a density image by Floyd–Steinberg half-toning (seed 003 §3): the
//! density is scaled so that it sums to the wanted plant count on a raster fine enough that a
//! cell rarely holds more than one plant, error diffusion turns it into black cells, and each
//! black cell gets one plant at a seeded jittered position inside it.

use image::GrayImage;
use nalgebra::Point2;

use crate::util::rng::Rng;

/// Cells per plant of the half-toning raster (density ≤ 1/4 per cell on average).
const CELLS_PER_PLANT: f64 = 4.0;

/// Bilinear sample of a grey image at `(u, v)` ∈ [0, 1]², in [0, 1].
pub(crate) fn sample(image: &GrayImage, u: f64, v: f64) -> f64 {
    let (w, h) = image.dimensions();
    let x = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
    let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (i, j) = (x.floor() as u32, y.floor() as u32);
    let (fx, fy) = (x - i as f64, y - j as f64);
    let at = |i: u32, j: u32| image.get_pixel(i.min(w - 1), j.min(h - 1))[0] as f64 / 255.0;
    let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
    let bottom = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// `count` positions (to within one: error diffusion conserves the total) in `[0, size_x] × [0, size_y]` distributed like `density` (grey,
/// black = none); empty when the density is zero everywhere. Deterministic in `seed`.
pub fn halftone_positions(
    density: &GrayImage,
    count: usize,
    size_m: [f64; 2],
    seed: u64,
) -> Vec<Point2<f64>> {
    if count == 0 || density.width() == 0 || density.height() == 0 {
        return Vec::new();
    }
    // A raster with the field's aspect and CELLS_PER_PLANT cells per plant.
    let aspect = size_m[0] / size_m[1].max(1e-9);
    let cells = count as f64 * CELLS_PER_PLANT;
    let columns = ((cells * aspect).sqrt().round() as usize).max(1);
    let rows = ((cells / aspect).sqrt().round() as usize).max(1);
    let mut raster: Vec<f64> = (0..rows * columns)
        .map(|k| {
            let (i, j) = (k % columns, k / columns);
            sample(
                density,
                (i as f64 + 0.5) / columns as f64,
                (j as f64 + 0.5) / rows as f64,
            )
        })
        .collect();
    let total: f64 = raster.iter().sum();
    if total <= 0.0 {
        return Vec::new();
    }
    let density_at = raster.clone();
    let scale = count as f64 / total;
    for value in &mut raster {
        *value *= scale;
    }
    let mut rng = Rng::seed_from(seed);
    let mut positions = Vec::with_capacity(count);
    let (cell_x, cell_y) = (size_m[0] / columns as f64, size_m[1] / rows as f64);
    for j in 0..rows {
        for i in 0..columns {
            let value = raster[j * columns + i];
            // Where the density is zero no plant stands, and no error is sent there.
            let allowed = |cell: usize| density_at[cell] > 0.0;
            let black = allowed(j * columns + i) && value >= 0.5;
            if black {
                positions.push(Point2::new(
                    (i as f64 + rng.uniform()) * cell_x,
                    (j as f64 + rng.uniform()) * cell_y,
                ));
            }
            let error = value - if black { 1.0 } else { 0.0 };
            // Floyd–Steinberg weights; at the raster's edges and next to empty cells the error
            // goes to the neighbours that can take it (renormalised), so the count is kept.
            let neighbours: Vec<(usize, f64)> = [
                (1isize, 0usize, 7.0),
                (-1, 1, 3.0),
                (0, 1, 5.0),
                (1, 1, 1.0),
            ]
            .iter()
            .filter_map(|&(di, dj, weight)| {
                let (ni, nj) = (i as isize + di, j + dj);
                (ni >= 0 && (ni as usize) < columns && nj < rows)
                    .then(|| (nj * columns + ni as usize, weight))
            })
            .filter(|&(cell, _)| allowed(cell))
            .collect();
            let total_weight: f64 = neighbours.iter().map(|(_, w)| w).sum();
            for (cell, weight) in neighbours {
                raster[cell] += error * weight / total_weight;
            }
        }
    }
    positions
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    #[test]
    fn plant_count_is_within_one_percent_and_follows_the_density() {
        // Dense on the left, empty on the right quarter.
        let density = GrayImage::from_fn(64, 64, |x, _| {
            Luma([if x >= 48 { 0 } else { (255 - 4 * x) as u8 }])
        });
        for count in [200usize, 1000, 5000] {
            let positions = halftone_positions(&density, count, [40.0, 30.0], 3);
            let error = (positions.len() as f64 - count as f64).abs() / count as f64;
            assert!(error <= 0.01, "{count}: {} positions", positions.len());
            assert!(
                positions.iter().all(|p| p.x < 30.5),
                "plants in the empty quarter"
            );
            let left = positions.iter().filter(|p| p.x < 15.0).count();
            let middle = positions.iter().filter(|p| p.x >= 15.0).count();
            assert!(left > middle, "{left} vs {middle}");
        }
        assert_eq!(
            halftone_positions(&density, 300, [40.0, 30.0], 3),
            halftone_positions(&density, 300, [40.0, 30.0], 3)
        );
        assert!(halftone_positions(&GrayImage::new(8, 8), 300, [1.0, 1.0], 3).is_empty());
    }

    #[test]
    fn half_toning_spreads_plants_more_evenly_than_random_placement() {
        let density = GrayImage::from_pixel(16, 16, Luma([200]));
        let size = [20.0, 20.0];
        let toned = halftone_positions(&density, 400, size, 1);
        let mut rng = Rng::seed_from(1);
        let random: Vec<Point2<f64>> = (0..toned.len())
            .map(|_| Point2::new(rng.range(0.0, size[0]), rng.range(0.0, size[1])))
            .collect();
        // Coefficient of variation of nearest-neighbour distances.
        let cv = |points: &[Point2<f64>]| {
            let d: Vec<f64> = points
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    points
                        .iter()
                        .enumerate()
                        .filter(|(j, _)| *j != i)
                        .map(|(_, q)| (p - q).norm())
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64;
            var.sqrt() / mean
        };
        assert!(
            cv(&toned) < 0.8 * cv(&random),
            "{} vs {}",
            cv(&toned),
            cv(&random)
        );
    }
}
