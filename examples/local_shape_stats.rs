//! Tuning aid: distribution of local shape features (PCA of each point's k nearest neighbours)
//! per ground-truth part, to separate stems (thin cylinders) from leaves (sheets).
//! Usage: `cargo run --example local_shape_stats -- DATASET [K]`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::GroundTruth;
use frond::graph::local_shape::{local_shapes, normal_coherence};
use frond::graph::points::PointSet;
use frond::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = Path::new(args.get(1).context("dataset")?);
    let k: usize = args.get(2).map_or(Ok(20), |a| a.parse())?;
    let scene = Scene::open(root)?;
    let truth = GroundTruth::load(root)?;
    let points = PointSet::from_scene(&scene);
    let shapes = local_shapes(&points, k);
    let small: Vec<_> = local_shapes(&points, 8).iter().map(|s| s.normal).collect();
    let coherence = normal_coherence(&points, &small, k);
    let parts = truth.points.parts.clone().context("parts")?;
    let mut by_part: BTreeMap<&str, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for (i, s) in shapes.iter().enumerate() {
        let entry = by_part.entry(parts[i].name()).or_default();
        entry.0.push(s.thickness);
        entry.1.push(coherence[i]);
    }
    for (part, (mut thick, mut elong)) in by_part {
        thick.sort_by(f64::total_cmp);
        elong.sort_by(f64::total_cmp);
        let q = |v: &[f64], p: f64| v[((v.len() - 1) as f64 * p) as usize];
        println!(
            "{part:>10} n={:6} thickness p10 {:.3} p50 {:.3} p90 {:.3} | coherence p10 {:.3} p50 {:.3} p90 {:.3}",
            thick.len(),
            q(&thick, 0.1),
            q(&thick, 0.5),
            q(&thick, 0.9),
            q(&elong, 0.1),
            q(&elong, 0.5),
            q(&elong, 0.9)
        );
    }
    Ok(())
}
