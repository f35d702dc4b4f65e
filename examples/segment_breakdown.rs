//! Tuning aid: runs the segmentation on a synthetic dataset and shows, for each ground-truth
//! leaf, where its points went: leaf segments (by id), or why not (stem class, a segment
//! labelled other/stem/pot, unassigned, floor/background/outlier).
//! Usage: `cargo run --release --example segment_breakdown -- DATASET [--only-missed]`.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::{EvalOptions, GroundTruth, MatchingOptions, score_leaves};
use frond::scene::Scene;
use frond::segment::foreground::PointClass;
use frond::segment::{SegmentOptions, segment_scene};
use frond::util::progress::NoProgress;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = Path::new(args.get(1).context("dataset")?);
    let only_missed = args.iter().any(|a| a == "--only-missed");
    let truth = GroundTruth::load(root)?;
    let scene = Scene::open(root)?;
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress)?;
    let predicted = segmentation.leaf_ids();
    let scores = score_leaves(
        &truth.points.leaf_ids,
        &predicted,
        &MatchingOptions::default(),
    );
    let matched: std::collections::HashSet<i64> =
        scores.matches.iter().map(|m| m.gt_leaf).collect();
    let _ = EvalOptions::default();
    let fate = |i: usize| -> String {
        if predicted[i] >= 0 {
            return format!("{}", predicted[i]);
        }
        match segmentation.foreground.class[i] {
            PointClass::Plant => match segmentation.point_segment[i] {
                Some(s) => {
                    format!("{:?}#{s}", segmentation.segments[s as usize].label).to_lowercase()
                }
                None => "unassigned".into(),
            },
            other => format!("{other:?}").to_lowercase(),
        }
    };
    // A segment's classification features.
    let local: HashMap<u32, usize> = segmentation
        .graph_points
        .iter()
        .enumerate()
        .map(|(l, &g)| (g as u32, l))
        .collect();
    // A segment's graph nodes and its mean facing (as the classifier measures it).
    let nodes_and_facing = |segment: &frond::segment::Segment| -> (Vec<usize>, f64) {
        let nodes: Vec<usize> = segment
            .points
            .iter()
            .filter_map(|g| local.get(g).copied())
            .collect();
        let facing = nodes
            .iter()
            .map(|&l| {
                segmentation.graph.normals[l]
                    .dot(&segment.shape.normal())
                    .abs()
            })
            .sum::<f64>()
            / nodes.len().max(1) as f64;
        (nodes, facing)
    };
    let describe = |id: usize, leaf: Option<i64>| {
        let segment = &segmentation.segments[id];
        let positions: Vec<nalgebra::Point3<f64>> = segment
            .points
            .iter()
            .map(|&g| segmentation.points.positions[g as usize])
            .collect();
        let (nodes, facing) = nodes_and_facing(segment);
        let noise =
            frond::graph::ncut::median_noise(&segmentation.graph.plane_rms, nodes.iter().copied());
        let tolerance = frond::graph::ncut::sheet_tolerance(
            &SegmentOptions::default().ncut,
            &segment.shape,
            noise,
        );
        let share = leaf.map_or(String::new(), |leaf| {
            let n = segment
                .points
                .iter()
                .filter(|&&g| truth.points.leaf_ids[g as usize] == leaf)
                .count();
            format!(
                " ({:.0}% this leaf)",
                100.0 * n as f64 / segment.points.len().max(1) as f64
            )
        });
        println!(
            "      segment {id} ({:?}): {} points{share}, length {:.1} mm, width ratio {:.3}, facing {:.3}, cubic residual {:.4} (tolerance {:.4}, noise {:.2} mm)",
            segment.label,
            segment.points.len(),
            1e3 * segment.shape.length(),
            segment.shape.width_ratio(),
            facing,
            segment
                .shape
                .cubic_sheet_residual(positions.iter().copied()),
            tolerance,
            1e3 * noise
        );
    };
    let mut by_gt: BTreeMap<i64, HashMap<String, usize>> = BTreeMap::new();
    for i in 0..predicted.len() {
        let l = truth.points.leaf_ids[i];
        if l >= 0 {
            *by_gt.entry(l).or_default().entry(fate(i)).or_insert(0) += 1;
        }
    }
    println!(
        "recall {:.3} ({}/{}), precision {:.3} ({} leaf segments)",
        scores.recall,
        scores.matched,
        scores.gt_leaves,
        scores.precision,
        scores.predicted_segments
    );
    for (leaf, fates) in &by_gt {
        let total: usize = fates.values().sum();
        if total < 20 || (only_missed && matched.contains(leaf)) {
            continue;
        }
        let mut top: Vec<(&String, &usize)> = fates.iter().collect();
        top.sort_by_key(|&(f, c)| (std::cmp::Reverse(*c), f.clone()));
        let shown: Vec<String> = top
            .iter()
            .take(5)
            .map(|(f, c)| format!("{f}:{c}"))
            .collect();
        let mark = if matched.contains(leaf) { " " } else { "✗" };
        println!("{mark} leaf{leaf:<4} {total:>5}  {}", shown.join("  "));
        // Why the segment holding most of a missed leaf is not a leaf segment.
        if let Some(id) = top
            .first()
            .and_then(|(f, _)| f.split_once('#'))
            .and_then(|(_, id)| id.parse::<usize>().ok())
        {
            describe(id, Some(*leaf));
        }
        // For leaves split between leaf segments: is the union of the two largest a sheet?
        let segments: Vec<i64> = top
            .iter()
            .filter_map(|(f, _)| f.parse::<i64>().ok())
            .take(2)
            .collect();
        if segments.len() == 2 {
            let members = |s: i64| -> Vec<nalgebra::Point3<f64>> {
                (0..predicted.len())
                    .filter(|&i| predicted[i] == s)
                    .map(|i| segmentation.points.positions[i])
                    .collect()
            };
            let residual = |points: &[nalgebra::Point3<f64>]| {
                frond::graph::shape::Shape::of(points.iter().copied())
                    .sheet_residual(points.iter().copied())
            };
            let (a, b) = (members(segments[0]), members(segments[1]));
            let union: Vec<_> = a.iter().chain(&b).copied().collect();
            // Contact: kNN pairs (K=3) between the two within the 3D threshold.
            let idx = |s: i64| -> Vec<usize> {
                (0..predicted.len())
                    .filter(|&i| predicted[i] == s)
                    .collect()
            };
            let (ia, ib) = (idx(segments[0]), idx(segments[1]));
            let both: Vec<usize> = ia.iter().chain(&ib).copied().collect();
            let subset = segmentation.points.subset(&both);
            let pairs = frond::graph::knn_pairs(&subset, 3);
            let crossing = pairs
                .iter()
                .filter(|(x, y)| ((*x as usize) < ia.len()) != ((*y as usize) < ia.len()))
                .count();
            if std::env::var("FROND_HIST").is_ok() {
                let shape = frond::graph::shape::Shape::of(
                    both.iter().map(|&i| segmentation.points.positions[i]),
                );
                let mut hist = [[0usize; 2]; 24];
                for (k, &i) in both.iter().enumerate() {
                    let d = segmentation.points.positions[i] - shape.centroid;
                    let v =
                        d.dot(&shape.axes[1]) / (4.0 * shape.eigenvalues[1].sqrt()) * 12.0 + 12.0;
                    let bin = (v.max(0.0) as usize).min(23);
                    hist[bin][(k >= ia.len()) as usize] += 1;
                }
                println!("      across-axis histogram (a|b): {:?}", hist);
            }
            println!(
                "      contact pairs {crossing} (ratio {:.2})",
                crossing as f64 / (ia.len().min(ib.len()) as f64).sqrt()
            );
            println!(
                "      sheet residual: {:.4} + {:.4} -> union {:.4}",
                residual(&a),
                residual(&b),
                residual(&union)
            );
        }
    }
    // Leaf segments that recover no GT leaf: what are they made of?
    let matched_segments: std::collections::HashSet<i64> =
        scores.matches.iter().map(|m| m.segment).collect();
    let parts = truth.points.parts.clone().context("parts")?;
    let mut extra: BTreeMap<i64, HashMap<String, usize>> = BTreeMap::new();
    for i in 0..predicted.len() {
        if predicted[i] >= 0 && !matched_segments.contains(&predicted[i]) {
            let what = match truth.points.leaf_ids[i] {
                l if l >= 0 => format!("leaf{l}"),
                _ => parts[i].name().to_owned(),
            };
            *extra
                .entry(predicted[i])
                .or_default()
                .entry(what)
                .or_insert(0) += 1;
        }
    }
    // Facing of the leaf segments that recover a leaf (the classifier's MIN_LEAF_FACING).
    let mut facings: Vec<f64> = scores
        .matches
        .iter()
        .filter_map(|m| {
            let segment = segmentation
                .segments
                .iter()
                .find(|s| s.leaf_id == Some(m.segment as u32))?;
            Some(nodes_and_facing(segment).1)
        })
        .collect();
    facings.sort_by(f64::total_cmp);
    if !facings.is_empty() {
        let q = |f: f64| facings[((facings.len() - 1) as f64 * f).round() as usize];
        println!(
            "facing of matched leaf segments: min {:.3} q01 {:.3} q05 {:.3} median {:.3}",
            q(0.0),
            q(0.01),
            q(0.05),
            q(0.5)
        );
    }
    for (segment, content) in extra {
        let mut top: Vec<(String, usize)> = content.into_iter().collect();
        top.sort_by_key(|(w, c)| (std::cmp::Reverse(*c), w.clone()));
        let shown: Vec<String> = top
            .iter()
            .take(4)
            .map(|(w, c)| format!("{w}:{c}"))
            .collect();
        println!("  unmatched segment {segment}: {}", shown.join("  "));
        if let Some(id) = segmentation
            .segments
            .iter()
            .position(|s| s.leaf_id == Some(segment as u32))
        {
            describe(id, None);
        }
    }
    Ok(())
}
