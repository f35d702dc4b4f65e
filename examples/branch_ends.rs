//! Tuning aid: where a matched branch's length error comes from. For each true branch that
//! `frond eval --traits` pairs with a predicted one, the predicted centreline's two ends are
//! placed on the true centreline (arc length of the nearest point), which splits the length
//! error into what the base adds (a base that starts before the true insertion, negative
//! when it starts late), what the tip adds (past the true tip, negative when short), and what
//! the path adds (a predicted centreline longer than the stretch of truth it covers: wiggles,
//! detours); the three sum to the length error. Also: how far each end lies off the true
//! centreline, and whether the branch is a stem (no parent) and carries a leaf at its tip.
//! Usage: `cargo run --release --example branch_ends -- DATASET RECONSTRUCTION [PRED_MODEL]`.

use std::path::Path;

use anyhow::{Context, Result};
use frond::traits::accuracy::{TraitComparison, compare_with_truth};
use frond::traits::{PlantOrgans, branch_length};
use nalgebra::Point3;

/// Arc length along `line` of the point nearest `p`, and the distance to it.
fn place_on(line: &[[f64; 3]], p: &Point3<f64>) -> (f64, f64) {
    let mut best = (0.0, f64::INFINITY);
    let mut walked = 0.0;
    for pair in line.windows(2) {
        let (a, b) = (Point3::from(pair[0]), Point3::from(pair[1]));
        let ab = b - a;
        let length = ab.norm();
        let t = if length > 0.0 {
            ((p - a).dot(&ab) / (length * length)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let distance = (p - (a + ab * t)).norm();
        if distance < best.1 {
            best = (walked + t * length, distance);
        }
        walked += length;
    }
    best
}

/// The length of `line` through points taken every `step` of arc length (ends kept): what is
/// left of the length once wiggles shorter than `step` are ironed out.
fn chord_length(line: &[[f64; 3]], step: f64) -> f64 {
    let mut kept: Vec<Point3<f64>> = Vec::new();
    let mut walked = 0.0;
    let mut next = 0.0;
    for (i, p) in line.iter().enumerate() {
        let p = Point3::from(*p);
        if i > 0 {
            walked += (p - Point3::from(line[i - 1])).norm();
        }
        if i == 0 || walked >= next || i + 1 == line.len() {
            kept.push(p);
            next = walked + step;
        }
    }
    kept.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}

fn carries_tip_leaf(organs: &PlantOrgans, branch: u32) -> bool {
    organs
        .leaves
        .iter()
        .any(|l| l.branch.is_some_and(|(b, f)| b == branch && f >= 0.999))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = Path::new(args.get(1).context("dataset")?);
    let out = Path::new(args.get(2).context("reconstruction folder")?);
    let model = args.get(3).map(Path::new);
    let TraitComparison {
        truth,
        prediction: organs,
        accuracy,
    } = compare_with_truth(dataset, out, model)?;
    println!(
        "gt\tpred\tstem\ttip_leaf\tgt_mm\terror_%\tbase_%\ttip_%\tpath_%\tbase_off_mm\ttip_off_mm\tchord10_%\tlateral_mm"
    );
    for pair in &accuracy.branches {
        let (Some(gt), Some(pred)) = (
            truth.branches.iter().find(|b| b.id == pair.gt_branch),
            organs.branches.iter().find(|b| b.id == pair.branch),
        ) else {
            continue;
        };
        let (Some(first), Some(last)) = (pred.centerline.first(), pred.centerline.last()) else {
            continue;
        };
        let gt_length = branch_length(gt);
        let length = branch_length(pred);
        let (s_base, base_off) = place_on(&gt.centerline, &Point3::from(*first));
        let (s_tip, tip_off) = place_on(&gt.centerline, &Point3::from(*last));
        let percent = |x: f64| 100.0 * x / gt_length;
        let chord = chord_length(&pred.centerline, 0.01);
        let mut lateral: Vec<f64> = pred
            .centerline
            .iter()
            .map(|p| place_on(&gt.centerline, &Point3::from(*p)).1)
            .collect();
        lateral.sort_by(f64::total_cmp);
        let lateral_median = lateral.get(lateral.len() / 2).copied().unwrap_or(f64::NAN);
        println!(
            "{}\t{}\t{}\t{}\t{:.1}\t{:+.1}\t{:+.1}\t{:+.1}\t{:+.1}\t{:.1}\t{:.1}\t{:+.1}\t{:.1}",
            gt.id,
            pred.id,
            pred.parent.is_none(),
            carries_tip_leaf(&organs, pred.id),
            1000.0 * gt_length,
            percent(length - gt_length),
            percent(-s_base),
            percent(s_tip - gt_length),
            percent(length - (s_tip - s_base)),
            1000.0 * base_off,
            1000.0 * tip_off,
            percent(chord - gt_length),
            1000.0 * lateral_median,
        );
    }
    Ok(())
}
