//! Tuning aid: for each ground-truth leaf of a synthetic dataset, which predicted segments hold
//! its points, and for each large predicted leaf segment, what it is made of.
//! Usage: `cargo run --example segment_breakdown -- DATASET PREDICTION`.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::{GroundTruth, read_labelled_points};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let truth = GroundTruth::load(Path::new(args.get(1).context("dataset")?))?;
    let pred = read_labelled_points(
        &Path::new(args.get(2).context("prediction")?).join("segmentation.ply"),
    )?;
    let parts = truth.points.parts.clone().context("parts")?;
    let gt_label = |i: usize| -> String {
        let l = truth.points.leaf_ids[i];
        if l >= 0 {
            format!("leaf{l}")
        } else {
            parts[i].name().to_owned()
        }
    };
    let mut by_gt: BTreeMap<String, HashMap<i64, usize>> = BTreeMap::new();
    let mut by_pred: BTreeMap<i64, HashMap<String, usize>> = BTreeMap::new();
    for i in 0..pred.leaf_ids.len() {
        *by_gt
            .entry(gt_label(i))
            .or_default()
            .entry(pred.leaf_ids[i])
            .or_insert(0) += 1;
        *by_pred
            .entry(pred.leaf_ids[i])
            .or_default()
            .entry(gt_label(i))
            .or_insert(0) += 1;
    }
    println!("== ground truth -> predicted leaf segments (-1 = not a leaf)");
    for (label, segments) in &by_gt {
        let total: usize = segments.values().sum();
        let mut top: Vec<(i64, usize)> = segments.iter().map(|(&s, &c)| (s, c)).collect();
        top.sort_by_key(|&(s, c)| (std::cmp::Reverse(c), s));
        let shown: Vec<String> = top
            .iter()
            .take(6)
            .map(|(s, c)| format!("{s}:{c}"))
            .collect();
        println!("{label:>12} {total:>6}  {}", shown.join("  "));
    }
    println!("== predicted leaf segments with >= 50 points -> ground truth");
    for (segment, labels) in &by_pred {
        let total: usize = labels.values().sum();
        if *segment < 0 || total < 50 {
            continue;
        }
        let mut top: Vec<(&String, &usize)> = labels.iter().collect();
        top.sort_by_key(|&(l, c)| (std::cmp::Reverse(*c), l.clone()));
        let shown: Vec<String> = top
            .iter()
            .take(4)
            .map(|(l, c)| format!("{l}:{c}"))
            .collect();
        println!("{segment:>5} {total:>6}  {}", shown.join("  "));
    }
    Ok(())
}
