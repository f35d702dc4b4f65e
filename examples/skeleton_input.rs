//! Tuning aid for the skeleton from photos: where the points the automatic skeleton is built
//! from lie on a synthetic plant (true stem, leaf, pot, or nothing), which of the points on the
//! true stems and petioles reach it (and what the foreground and the segment labels made of
//! the others), and a picture: side and top views with the skeleton's input points coloured by
//! their true part, the true centrelines (green) and the predicted skeleton (red).
//! Usage: `cargo run --release --example skeleton_input -- DATASET DENSE_FOLDER [OUT.png]`
//! (DENSE_FOLDER: a COLMAP folder with images, e.g. `frond reconstruct` output's `dense/`).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use frond::branch::plant::skeleton_point_indices;
use frond::eval::dense::thin_organ_accuracy;
use frond::eval::{GroundTruth, align_to_ground_truth};
use frond::graph::neighbours::Neighbours;
use frond::pipeline::automatic_skeleton;
use frond::scene::Scene;
use frond::segment::{Labels, SegmentOptions, segment_scene};
use frond::util::progress::NoProgress;
use image::{Rgb, RgbImage};
use nalgebra::Point3;

const NEAR: f64 = 0.002;

fn part_name(part: Option<i64>) -> &'static str {
    match part {
        Some(0) => "leaf",
        Some(1) => "stem",
        Some(2) => "pot",
        Some(_) => "other",
        None => "far (halo, floor, soil)",
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = Path::new(
        args.get(1)
            .context("usage: DATASET DENSE_FOLDER [OUT.png]")?,
    );
    let dense = Path::new(
        args.get(2)
            .context("usage: DATASET DENSE_FOLDER [OUT.png]")?,
    );
    let truth = GroundTruth::load(root)?;
    let scene = Scene::open(dense)?;
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress)?;
    let labels = Labels::automatic(&segmentation);
    let (tree, run) = automatic_skeleton(&segmentation, &labels);
    let (similarity, _) = align_to_ground_truth(root, &dense.join("sparse"))
        .or_else(|_| align_to_ground_truth(root, dense))?;
    let positions: Vec<Point3<f64>> = segmentation
        .points
        .positions
        .iter()
        .map(|p| similarity.apply(p))
        .collect();
    let samples = &truth.surface_samples;
    let parts = samples.parts.as_ref().context("no part column")?;
    let index =
        Neighbours::new(samples.positions.iter().copied()).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let part_of: Vec<Option<i64>> = positions
        .iter()
        .map(|p| {
            let nearest = index.nearest(p)?;
            (nearest.distance() <= NEAR).then(|| parts[nearest.index] as i64)
        })
        .collect();
    let thin = thin_organ_accuracy(&truth, &positions, NEAR)?;
    let length = thin.centerline_length;
    println!(
        "true stem and petiole centreline: {:.3} m, {:.1} % with a point within radius + {} mm",
        length,
        100.0 * thin.centerline_coverage,
        NEAR * 1e3
    );
    let input = skeleton_point_indices(&segmentation.foreground, &labels);
    let mut in_input = vec![false; positions.len()];
    for &i in &input {
        in_input[i as usize] = true;
    }
    let mut by_part: BTreeMap<&str, usize> = BTreeMap::new();
    for &i in &input {
        *by_part.entry(part_name(part_of[i as usize])).or_default() += 1;
    }
    println!(
        "skeleton input: {} of {} points; by true part within {} mm:",
        input.len(),
        positions.len(),
        NEAR * 1e3
    );
    for (part, n) in &by_part {
        println!(
            "  {part:24} {n:7} ({:.1} %)",
            100.0 * *n as f64 / input.len().max(1) as f64
        );
    }
    let on_stem: Vec<usize> = (0..positions.len())
        .filter(|&i| part_of[i] == Some(1))
        .collect();
    let mut fates: BTreeMap<String, usize> = BTreeMap::new();
    for &i in &on_stem {
        let label = labels
            .label_of_point(i)
            .map_or("no segment".to_owned(), |l| format!("{l:?}"));
        let fate = format!(
            "{:?} / {label} / {}",
            segmentation.foreground.class[i],
            if in_input[i] { "input" } else { "left out" }
        );
        *fates.entry(fate).or_default() += 1;
    }
    println!(
        "points on true stems and petioles: {} ({:.0} per metre of centreline; foreground class / segment label / skeleton):",
        on_stem.len(),
        on_stem.len() as f64 / length.max(1e-12)
    );
    for (fate, n) in &fates {
        println!(
            "  {fate:40} {n:7} ({:.1} %)",
            100.0 * *n as f64 / on_stem.len().max(1) as f64
        );
    }
    println!(
        "skeleton: {} branches ({:?})",
        tree.branches.len(),
        run.error
    );
    // The thin-organ sweep's points come after the fused ones (densify.json says how many).
    let fused_count = std::fs::read_to_string(dense.join("densify.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["report"]["fusion"]["points"].as_u64())
        .map(|n| n as usize);
    if let Some(fused) = fused_count.filter(|&n| n < positions.len()) {
        let mut histogram: BTreeMap<&str, usize> = BTreeMap::new();
        let mut offsets: Vec<f64> = Vec::new();
        for (k, p) in positions.iter().enumerate().skip(fused) {
            let axis = truth
                .branches
                .iter()
                .map(|b| {
                    b.centerline
                        .windows(2)
                        .map(|w| {
                            frond::branch::spline::point_segment_distance(
                                p,
                                &Point3::from(w[0]),
                                &Point3::from(w[1]),
                            ) - b.mean_radius()
                        })
                        .fold(f64::INFINITY, f64::min)
                })
                .fold(f64::INFINITY, f64::min);
            let class = match (part_of[k], axis) {
                (Some(1), _) => "on a stem surface",
                (Some(0), _) => "on a leaf",
                (Some(2), _) => "on the pot",
                (_, a) if a < 0.005 => "within 5 mm of a stem surface",
                (_, a) if a < 0.02 => "5-20 mm from a stem surface",
                _ => "elsewhere",
            };
            *histogram.entry(class).or_default() += 1;
            if axis < 0.02 {
                offsets.push(axis);
            }
        }
        offsets.sort_by(f64::total_cmp);
        if !offsets.is_empty() {
            let q = |f: f64| offsets[((offsets.len() - 1) as f64 * f) as usize] * 1e3;
            println!(
                "thin points within 20 mm of a stem: distance to its surface (mm, negative inside) 10/25/50/75/90 %: {:.1} {:.1} {:.1} {:.1} {:.1}",
                q(0.1),
                q(0.25),
                q(0.5),
                q(0.75),
                q(0.9)
            );
        }
        println!("thin-organ sweep points: {}", positions.len() - fused);
        for (class, n) in &histogram {
            println!("  {class:32} {n:7}");
        }
    }
    let Some(out) = args.get(3).filter(|a| !a.starts_with("--")) else {
        return Ok(());
    };
    // Two panels: side (x, z) and top (x, y), around the true plant.
    let (w, h) = (700u32, 700u32);
    let mut image = RgbImage::from_pixel(2 * w, h, Rgb([255, 255, 255]));
    let gt_points: Vec<Point3<f64>> = truth
        .branches
        .iter()
        .flat_map(|b| b.centerline.iter().map(|c| Point3::from(*c)))
        .collect();
    let extent = truth.plant_height.max(1e-6) * 0.75;
    let center = gt_points.iter().fold(Point3::origin(), |a, p| {
        a + p.coords / gt_points.len().max(1) as f64
    });
    let mut plot = |p: &Point3<f64>, color: Rgb<u8>, size: i64| {
        let d = p - center;
        for (panel, (u, v)) in [(d.x, d.z), (d.x, d.y)].into_iter().enumerate() {
            let x = ((u / extent * 0.5 + 0.5) * w as f64) as i64 + panel as i64 * w as i64;
            let y = ((0.5 - v / extent * 0.5) * h as f64) as i64;
            for dx in 0..size {
                for dy in 0..size {
                    let (px, py) = (x + dx, y + dy);
                    let lo = panel as i64 * w as i64;
                    if px >= lo && px < lo + w as i64 && py >= 0 && py < h as i64 {
                        image.put_pixel(px as u32, py as u32, color);
                    }
                }
            }
        }
    };
    for (i, p) in positions.iter().enumerate() {
        if !in_input[i] && part_of[i].is_some() {
            plot(p, Rgb([215, 215, 215]), 1);
        }
    }
    // With --halo: every point away from the true surfaces inside the plant's box, in orange.
    if args.iter().any(|a| a == "--halo") {
        let (lo, hi) = gt_points.iter().fold(
            (
                Point3::from([f64::INFINITY; 3]),
                Point3::from([f64::NEG_INFINITY; 3]),
            ),
            |(lo, hi), p| (lo.inf(p), hi.sup(p)),
        );
        let margin = 0.3 * (hi - lo).norm();
        for (i, p) in positions.iter().enumerate() {
            let inside =
                (0..3).all(|a| p[a] > lo[a] - margin && p[a] < hi[a] + margin) && p.z > lo.z + 0.01;
            if part_of[i].is_none() && inside {
                plot(p, Rgb([255, 140, 0]), 1);
            }
        }
    }
    for &i in &input {
        let color = match part_of[i as usize] {
            Some(0) => Rgb([60, 160, 255]),
            Some(1) => Rgb([0, 0, 0]),
            Some(2) => Rgb([200, 120, 0]),
            _ => Rgb([255, 0, 255]),
        };
        plot(&positions[i as usize], color, 1);
    }
    for p in &gt_points {
        plot(p, Rgb([0, 170, 0]), 2);
    }
    for branch in &tree.branches {
        for k in 0..=200 {
            let p = branch.cylinder.skeleton.point_at_fraction(k as f64 / 200.0);
            plot(&similarity.apply(&p), Rgb([230, 0, 0]), 2);
        }
    }
    image.save(out)?;
    println!("wrote {out}");
    Ok(())
}
