//! Tuning aid: what the skeleton's length errors are made of, against synthetic ground truth.
//!
//! Precision side: every sample of the predicted centrelines is on the plant (within the
//! evaluation's tolerance of a true centreline: two true radii, at least 3 mm) or off it, and
//! has reconstructed points near it (within two point spacings) or not: on the plant with
//! points, on the plant where no point is (a bridge that found the organ), off the plant near
//! non-leaf points (split by distance from the truth in tolerances: a near miss or something
//! else), off near leaf points only, off with no point near (a bridge through air).
//!
//! Recall side: every sample of the true centrelines (stem and branches apart from petioles)
//! that no predicted centreline covers, by what the reconstruction has there (within the
//! organ's radius plus two point spacings): non-leaf points (the skeleton did not use them),
//! leaf points only, or no points (the stereo step lost it); for the last, where along the
//! organ (tenths from its base) and in how many views the spot is not behind a true leaf
//! (`gt/masks`), i.e. whether the photos show it.
//!
//! Usage: `cargo run --release --example skeleton_misses -- DATASET RECONSTRUCTION [PRED_MODEL]`
//! (PRED_MODEL: the COLMAP model the reconstruction was made from, when it is not the
//! dataset's own; it aligns the prediction to the truth by the camera centres).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::geometry::petiole_ids;
use frond::graph::neighbours::Neighbours;
use nalgebra::Point3;

mod truth;

/// Points this many spacings from a centreline sample are "near" it.
const NEAR_SPACINGS: f64 = 2.0;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let gt_root = Path::new(args.get(1).context("dataset")?);
    let out = Path::new(args.get(2).context("reconstruction folder")?);
    let model = args.get(3).map(Path::new);
    let (truth, pred) = truth::load_aligned(gt_root, out, model)?;
    let skeleton = pred.skeleton.clone().unwrap_or_default();
    anyhow::ensure!(!skeleton.is_empty(), "{}: no skeleton", out.display());
    let all_points = Neighbours::new(pred.points.positions.iter().copied())?;
    let non_leaf: Vec<Point3<f64>> = pred
        .points
        .positions
        .iter()
        .zip(&pred.points.leaf_ids)
        .filter(|(_, leaf)| **leaf < 0)
        .map(|(p, _)| *p)
        .collect();
    let non_leaf = Neighbours::new(non_leaf)?;
    let spacing = truth::point_spacing(&all_points);
    let near = NEAR_SPACINGS * spacing;
    println!(
        "{} predicted branches, {} true; point spacing {:.2} mm",
        skeleton.len(),
        truth.branches.len(),
        spacing * 1e3
    );

    // Precision side.
    let mut true_samples = Vec::new();
    let mut tolerance_of = Vec::new();
    for branch in &truth.branches {
        let tolerance = (2.0 * branch.mean_radius()).max(0.003);
        for c in &branch.centerline {
            true_samples.push(Point3::from(*c));
            tolerance_of.push(tolerance);
        }
    }
    let true_tree = Neighbours::new(true_samples.iter().copied())?;
    let mut predicted: BTreeMap<&str, f64> = BTreeMap::new();
    let mut off_by_branch: Vec<(u32, f64, f64, f64)> = Vec::new();
    for branch in &skeleton {
        let line: Vec<Point3<f64>> = branch.centerline.iter().map(|c| Point3::from(*c)).collect();
        let (mut length, mut off, mut through_air) = (0.0, 0.0, 0.0);
        for w in line.windows(2) {
            let step = (w[1] - w[0]).norm();
            let p = nalgebra::center(&w[0], &w[1]);
            let nearest = true_tree.nearest_one(&p);
            let tolerance = tolerance_of[nearest.index];
            let on_plant = nearest.distance() <= tolerance;
            let observed = all_points.nearest_one(&p).distance() <= near;
            let by_non_leaf = non_leaf.nearest_one(&p).distance() <= near;
            let class = match (on_plant, observed, by_non_leaf) {
                (true, true, _) => "on the plant, points near",
                (true, false, _) => "on the plant, no point near",
                (false, true, true) => match nearest.distance() / tolerance {
                    r if r < 2.0 => "off, non-leaf points, 1-2 tolerances",
                    r if r < 4.0 => "off, non-leaf points, 2-4 tolerances",
                    _ => "off, non-leaf points, over 4 tolerances",
                },
                (false, true, false) => "off, leaf points only",
                (false, false, _) => "off, no point near",
            };
            *predicted.entry(class).or_default() += step;
            length += step;
            if !on_plant {
                off += step;
                if !observed {
                    through_air += step;
                }
            }
        }
        off_by_branch.push((branch.id, length, off, through_air));
    }
    print_lengths(
        "predicted centreline length",
        &predicted,
        predicted.values().sum(),
    );
    off_by_branch.sort_by(|a, b| b.2.total_cmp(&a.2));
    let worst: Vec<String> = off_by_branch
        .iter()
        .take(5)
        .filter(|b| b.2 > 0.0)
        .map(|(id, length, off, air)| {
            format!(
                "branch {id}: {:.0} of {:.0} mm off ({:.0} with no point near)",
                off * 1e3,
                length * 1e3,
                air * 1e3
            )
        })
        .collect();
    println!("most off the plant: {}", worst.join("; "));

    // Recall side.
    let predicted_samples: Vec<Point3<f64>> = skeleton
        .iter()
        .flat_map(|b| b.centerline.iter().map(|c| Point3::from(*c)))
        .collect();
    let predicted_tree = Neighbours::new(predicted_samples)?;
    let petioles = petiole_ids(&truth.branches, &truth.leaves);
    let masks = truth::LeafMasks::load(gt_root)?;
    let mut missed: BTreeMap<String, f64> = BTreeMap::new();
    let mut lost_along = [0.0f64; 10];
    let mut lost_views = Vec::new();
    let mut true_total = 0.0;
    for branch in &truth.branches {
        let kind = if petioles.contains(&branch.id) {
            "petiole"
        } else {
            "branch"
        };
        let tolerance = (2.0 * branch.mean_radius()).max(0.003);
        let reach = branch.mean_radius() + near;
        let line: Vec<Point3<f64>> = branch.centerline.iter().map(|c| Point3::from(*c)).collect();
        let segments = line.len().saturating_sub(1).max(1) as f64;
        for (k, w) in line.windows(2).enumerate() {
            let step = (w[1] - w[0]).norm();
            let p = nalgebra::center(&w[0], &w[1]);
            true_total += step;
            let fate = if predicted_tree.nearest_one(&p).distance() <= tolerance {
                "covered"
            } else if non_leaf.nearest_one(&p).distance() <= reach {
                "missed, non-leaf points there"
            } else if all_points.nearest_one(&p).distance() <= reach {
                "missed, leaf points only"
            } else {
                let decile = ((k as f64 + 0.5) / segments * 10.0).floor() as usize;
                lost_along[decile.min(9)] += step;
                lost_views.push(masks.views_where(&p, |label| label == 0));
                "missed, no points there"
            };
            *missed.entry(format!("{kind}: {fate}")).or_default() += step;
        }
    }
    print_lengths("true centreline length", &missed, true_total);
    let lost: f64 = lost_along.iter().sum();
    if lost > 0.0 {
        let shares: Vec<String> = lost_along
            .iter()
            .map(|l| format!("{:.0}", 100.0 * l / lost))
            .collect();
        lost_views.sort_unstable();
        println!(
            "where no points are, % by tenth of the organ from its base: {}",
            shares.join(" ")
        );
        println!(
            "views not behind a true leaf there ({} views): median {}, tenth percentile {}",
            masks.len(),
            lost_views[lost_views.len() / 2],
            lost_views[lost_views.len() / 10]
        );
    }
    Ok(())
}

/// Prints `title` with `total` and each class's length (metres) in mm and as a share of it.
fn print_lengths<K: std::fmt::Display>(title: &str, lengths: &BTreeMap<K, f64>, total: f64) {
    println!("{title} {:.0} mm:", total * 1e3);
    for (class, length) in lengths {
        println!(
            "  {:<40} {:>7.0} mm  {:>5.1} %",
            class.to_string(),
            length * 1e3,
            100.0 * length / total.max(1e-12)
        );
    }
}
