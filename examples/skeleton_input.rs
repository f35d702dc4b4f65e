//! Tuning aid for the skeleton from photos: where the points the automatic skeleton is built
//! from lie on a synthetic plant (true stem, leaf, pot, or nothing), which of the points on the
//! true stems and petioles reach it (and what the foreground and the segment labels made of
//! the others), and a picture: side and top views with the skeleton's input points coloured by
//! their true part, the true centrelines (green) and the predicted skeleton (red).
//! It also prints the pot found, the skeleton's length scores against the truth, and with
//! `--tube` the leaf shares and principal width ratios of the input's surroundings.
//! Usage: `cargo run --release --example skeleton_input -- DATASET DENSE_FOLDER [OUT.png]
//! [--all-candidates] [--tube] [--tube-radius SPACINGS] [--tube-sheet SHARE]`
//! (DENSE_FOLDER: a COLMAP folder with images, e.g. `frond reconstruct` output's `dense/`, or a
//! synthetic dataset itself for its semi-dense points).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use frond::branch::plant::{
    PlantSkeletonOptions, leaf_sheet_pieces, skeleton_point_indices, tube_point_indices,
};
use frond::eval::dense::thin_organ_accuracy;
use frond::eval::{GroundTruth, align_to_ground_truth};
use frond::graph::neighbours::Neighbours;
use frond::pipeline::automatic_skeleton;
use frond::scene::Scene;
use frond::segment::{Labels, SegmentOptions, segment_scene};
use frond::util::progress::NoProgress;
use frond::util::stats::quantile_sorted;
use image::{Rgb, RgbImage};
use nalgebra::Point3;

const NEAR: f64 = 0.002;

/// Distance from a point to the nearest true stem or petiole surface (negative inside).
fn gap_to_true_stems(truth: &GroundTruth, p: &Point3<f64>) -> f64 {
    truth
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
        .fold(f64::INFINITY, f64::min)
}

/// The 10/25/50/75/90 % quantiles (nearest rank) of sorted values, scaled, to two decimals.
fn quantiles(sorted: &[f64], scale: f64) -> String {
    [0.1, 0.25, 0.5, 0.75, 0.9]
        .iter()
        .map(|&f| format!("{:.2}", quantile_sorted(sorted, f) * scale))
        .collect::<Vec<_>>()
        .join(" ")
}

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
    let (similarity, _) = align_to_ground_truth(root, &dense.join("sparse"))
        .or_else(|_| align_to_ground_truth(root, &dense.join("sparse/0")))
        .or_else(|_| align_to_ground_truth(root, dense))?;
    if let Some(pot) = frond::branch::plant::pot_shape(&segmentation, &labels) {
        let rim = similarity.apply(&pot.rim_centre);
        println!(
            "pot: rim centre {:.4} {:.4} {:.4}, radius {:.4} (true frame)",
            rim.x,
            rim.y,
            rim.z,
            pot.radius * similarity.scale
        );
    }
    let flag = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|k| args.get(k + 1))
            .and_then(|v| v.parse::<f64>().ok())
    };
    let mut options = PlantSkeletonOptions::default();
    if let Some(v) = flag("--tube-radius") {
        options.tube.radius_spacings = v;
    }
    if let Some(v) = flag("--tube-sheet") {
        options.tube.max_sheet_share = v;
    }
    let (tree, run) = automatic_skeleton(&segmentation, &labels, &options);
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
    let candidates =
        skeleton_point_indices(&segmentation.points, &segmentation.foreground, &labels);
    let input = if args.iter().any(|a| a == "--all-candidates") {
        candidates
    } else {
        let pieces = leaf_sheet_pieces(
            &segmentation.points,
            &segmentation.foreground.class,
            &labels,
        );
        tube_point_indices(&segmentation, &labels, &pieces, &candidates, &options.tube)
    };
    let mut in_input = vec![false; positions.len()];
    for &i in &input {
        in_input[i as usize] = true;
    }
    let mut by_part: BTreeMap<&str, usize> = BTreeMap::new();
    let mut by_source: BTreeMap<(String, &str), usize> = BTreeMap::new();
    for &i in &input {
        let i = i as usize;
        *by_part.entry(part_name(part_of[i])).or_default() += 1;
        let label = labels
            .label_of_point(i)
            .map_or("no segment".to_owned(), |l| format!("{l:?}"));
        let source = format!("{:?} / {label}", segmentation.foreground.class[i]);
        *by_source
            .entry((source, part_name(part_of[i])))
            .or_default() += 1;
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
    {
        let input_points: Vec<Point3<f64>> = input.iter().map(|&i| positions[i as usize]).collect();
        let near =
            Neighbours::new(input_points.iter().copied()).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let mut gaps: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
        for (k, &i) in input.iter().enumerate() {
            if let Some(g) = near.around(k, 2).into_iter().find(|f| f.index != k) {
                gaps.entry(part_name(part_of[i as usize]))
                    .or_default()
                    .push(g.distance() * 1e3);
            }
        }
        println!("skeleton input: nearest-neighbour distance (mm) 10/25/50/75/90 %");
        for (part, mut g) in gaps {
            g.sort_by(f64::total_cmp);
            println!("  {part:24} {}", quantiles(&g, 1.0));
        }
    }
    println!("skeleton input by foreground class / segment label and true part:");
    for ((source, part), n) in &by_source {
        println!("  {source:28} {part:24} {n:7}");
    }
    // Where the skeleton input's points near no true surface lie: by distance from the true
    // stem and petiole surfaces, and by height above the lowest true centreline point.
    let axis_gap = |p: &Point3<f64>| gap_to_true_stems(&truth, p);
    let base_z = truth
        .branches
        .iter()
        .flat_map(|b| b.centerline.iter().map(|c| c[2]))
        .fold(f64::INFINITY, f64::min);
    let mut far_input: BTreeMap<(&str, &str), usize> = BTreeMap::new();
    for &i in &input {
        let i = i as usize;
        if part_of[i].is_some() {
            continue;
        }
        let gap = axis_gap(&positions[i]);
        let near = if gap < 0.005 {
            "< 5 mm from a stem"
        } else if gap < 0.02 {
            "5-20 mm from a stem"
        } else {
            "> 20 mm from a stem"
        };
        let z = positions[i].z - base_z;
        let height = if z < -0.01 {
            "below the stem base"
        } else if z < 0.02 {
            "0-2 cm above the base"
        } else {
            "higher"
        };
        *far_input.entry((near, height)).or_default() += 1;
    }
    println!("skeleton input near no true surface:");
    for ((near, height), n) in &far_input {
        println!("  {near:22} {height:24} {n:7}");
    }
    if args.iter().any(|a| a == "--tube") {
        tube_features(&positions, &input, &part_of, &labels, &axis_gap)?;
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
        "skeleton: {} branches ({:?}), {:?}",
        tree.branches.len(),
        run.error,
        run.stats
    );
    {
        let mut records =
            frond::branch::plant::skeleton_records(&tree, 0.002 / similarity.scale.max(1e-12), 2);
        for branch in &mut records {
            for c in &mut branch.centerline {
                let p = similarity.apply(&Point3::from(*c));
                *c = [p.x, p.y, p.z];
            }
            branch.radius_start *= similarity.scale;
            branch.radius_end *= similarity.scale;
        }
        let petioles = frond::eval::geometry::petiole_ids(&truth.branches, &truth.leaves);
        let surfaces = frond::eval::geometry::TrueSurfaces::new(&truth.surface_samples);
        let scores = frond::eval::geometry::skeleton_length_scores(
            &truth.branches,
            &petioles,
            &records,
            &surfaces,
        );
        println!(
            "SCORE branch recall {:.3} petiole recall {:.3} precision {:.3} of {:.3} m",
            scores.branch_recall, scores.petiole_recall, scores.precision, scores.predicted_length
        );
    }
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
            let axis = gap_to_true_stems(&truth, p);
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
            println!(
                "thin points within 20 mm of a stem: distance to its surface (mm, negative inside) 10/25/50/75/90 %: {}",
                quantiles(&offsets, 1e3)
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

/// Deciles of candidate tube features of the skeleton input, by what the points truly are.
fn tube_features(
    positions: &[Point3<f64>],
    input: &[u32],
    part_of: &[Option<i64>],
    labels: &Labels,
    axis_gap: &dyn Fn(&Point3<f64>) -> f64,
) -> Result<()> {
    use frond::graph::shape::Shape;
    use frond::segment::SegmentLabel;
    let all = Neighbours::new(positions.iter().copied()).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut nearest: Vec<f64> = (0..positions.len())
        .step_by(7)
        .filter_map(|i| {
            all.around(i, 2)
                .into_iter()
                .find(|n| n.index != i)
                .map(|n| n.distance())
        })
        .collect();
    nearest.sort_by(f64::total_cmp);
    let spacing = nearest[nearest.len() / 2];
    println!("median spacing {:.2} mm", spacing * 1e3);
    for scale in [6.0, 12.0, 20.0] {
        let radius = scale * spacing;
        let mut features: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
        for &i in input {
            let i = i as usize;
            let kind = match part_of[i] {
                Some(0) => "leaf",
                Some(1) => "stem",
                Some(2) => "pot",
                Some(_) => "other",
                None if axis_gap(&positions[i]) < 0.005 => "halo < 5 mm",
                None => "far",
            };
            let around = all.within_radius(&positions[i], radius);
            let leafy = around
                .iter()
                .filter(|n| labels.label_of_point(n.index) == Some(SegmentLabel::Leaf))
                .count() as f64
                / around.len().max(1) as f64;
            let shape = Shape::of(around.iter().map(|n| positions[n.index]));
            features
                .entry(kind)
                .or_default()
                .push((shape.width_ratio(), leafy));
        }
        println!(
            "radius {scale} spacings ({:.1} mm): width ratio | leaf share, 10/25/50/75/90 %",
            radius * 1e3
        );
        for (kind, mut values) in features {
            let mut a: Vec<f64> = values.iter().map(|v| v.0).collect();
            a.sort_by(f64::total_cmp);
            values.sort_by(|x, y| x.1.total_cmp(&y.1));
            let b: Vec<f64> = values.iter().map(|v| v.1).collect();
            println!(
                "  {kind:12} {:6} | {} | {}",
                a.len(),
                quantiles(&a, 1.0),
                quantiles(&b, 1.0)
            );
        }
    }
    Ok(())
}
