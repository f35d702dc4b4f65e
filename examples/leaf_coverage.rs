//! Tuning aid: where a leaf's area is lost from photos. For each ground-truth leaf matched to a
//! predicted segment, the share of the true leaf surface (its surface samples) that has, within
//! `r` (1 % of the leaf's length or two point spacings, whichever is larger): any reconstructed point, a point of the matched
//! segment, a point of another leaf segment, and the fitted mesh. Losses at "points" are the
//! stereo step's; between "points" and "segment" the segmentation's; between "segment" and
//! "mesh" the fit's.
//! The other side, where a fitted leaf is too large: the share of the fitted mesh's area (by
//! triangle centroids) within `r` of its own true leaf, of another true leaf, of a stem, pot
//! or floor, or of no true surface at all (backdrop or air).
//! Usage: `cargo run --release --example leaf_coverage -- DATASET RECONSTRUCTION [PRED_MODEL]`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::geometry::{bounding_spheres, distance_to_mesh};
use frond::eval::{EvalOptions, evaluate};
use frond::graph::neighbours::Neighbours;
use nalgebra::Point3;

mod truth;

/// A true leaf sample is covered by what lies within this share of the leaf's length...
const COVER_LENGTH_SHARE: f64 = 0.01;
/// ...or within this many point spacings, whichever is larger.
const COVER_SPACINGS: f64 = 2.0;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let gt_root = Path::new(args.get(1).context("dataset")?);
    let out = Path::new(args.get(2).context("reconstruction folder")?);
    let model = args.get(3).map(Path::new);
    let (truth, pred) = truth::load_aligned(gt_root, out, model)?;
    let report = evaluate(&truth, &pred, None, &EvalOptions::default())?;
    // The GT views and their leaf masks (leaf id + 1 per pixel), to count the views that see
    // a surface sample unoccluded.
    let masks = truth::LeafMasks::load(gt_root)?;
    let views_seeing = |p: &Point3<f64>, leaf: i64| -> usize {
        masks.views_where(p, |label| i64::from(label) == leaf + 1)
    };
    let all = Neighbours::new(pred.points.positions.iter().copied())?;
    // The reconstructed points' spacing (median distance to the nearest other point): a
    // sample nearer a point than two spacings is as covered as the sampling allows.
    let spacing = truth::point_spacing(&all);
    println!(
        "point spacing {:.2} mm; {} views",
        spacing * 1e3,
        masks.len()
    );
    let mut by_segment: BTreeMap<i64, Vec<Point3<f64>>> = BTreeMap::new();
    for (p, &l) in pred.points.positions.iter().zip(&pred.points.leaf_ids) {
        if l >= 0 {
            by_segment.entry(l).or_default().push(*p);
        }
    }
    let trees: BTreeMap<i64, Neighbours> = by_segment
        .into_iter()
        .filter_map(|(l, ps)| Neighbours::new(ps).ok().map(|t| (l, t)))
        .collect();
    // Every true surface sample by part, and each other leaf's, for the fitted meshes' excess.
    let parts = truth.surface_samples.parts.clone().unwrap_or_else(|| {
        vec![frond::synth::scene::Part::Leaf; truth.surface_samples.positions.len()]
    });
    let surface_of = |keep: &dyn Fn(usize) -> bool| -> Option<Neighbours> {
        Neighbours::new(
            (0..truth.surface_samples.positions.len())
                .filter(|&i| keep(i))
                .map(|i| truth.surface_samples.positions[i]),
        )
        .ok()
    };
    let not_leaf = surface_of(&|i| parts[i] != frond::synth::scene::Part::Leaf);
    println!(
        "gt  seg  samples  seen>=2  points  segment  other  mesh  area_ratio  | mesh on: own  other_leaf  not_leaf  nothing"
    );
    let mut excess_sums = [0.0f64; 5];
    let mut sums = [0.0f64; 5];
    let mut count = 0usize;
    for m in &report.leaves.matches {
        let Some((record, _)) = truth.leaves.iter().find(|(r, _)| r.id as i64 == m.gt_leaf) else {
            continue;
        };
        let r = (COVER_LENGTH_SHARE * record.length).max(COVER_SPACINGS * spacing);
        let samples: Vec<Point3<f64>> = truth
            .surface_samples
            .positions
            .iter()
            .zip(&truth.surface_samples.leaf_ids)
            .filter(|&(_, &l)| l == m.gt_leaf)
            .map(|(p, _)| *p)
            .collect();
        if samples.is_empty() {
            continue;
        }
        let mesh = pred.leaf_meshes.get(&m.segment);
        let spheres = mesh.map(bounding_spheres).unwrap_or_default();
        let near =
            |tree: &Neighbours, p: &Point3<f64>| tree.nearest(p).is_some_and(|n| n.distance() <= r);
        let mut hits = [0usize; 5];
        let mut views = Vec::with_capacity(samples.len());
        for p in &samples {
            let v = views_seeing(p, m.gt_leaf);
            views.push(v);
            if v >= 2 {
                hits[4] += 1;
            }
            if near(&all, p) {
                hits[0] += 1;
            }
            if trees.get(&m.segment).is_some_and(|t| near(t, p)) {
                hits[1] += 1;
            }
            if trees.iter().any(|(&l, t)| l != m.segment && near(t, p)) {
                hits[2] += 1;
            }
            if let Some(mesh) = mesh
                && (distance_to_mesh(&p.cast::<f32>(), mesh, &spheres) as f64) <= r
            {
                hits[3] += 1;
            }
        }
        // Where the fitted mesh lies: its triangles' centroids, weighted by area.
        let own = Neighbours::new(samples.iter().copied()).ok();
        let others = surface_of(&|i| {
            parts[i] == frond::synth::scene::Part::Leaf
                && truth.surface_samples.leaf_ids[i] != m.gt_leaf
        });
        let mut on = [0.0f64; 4];
        // The true leaf's plane normal (least principal axis of its samples): a centroid on no
        // true surface is "off in depth" when its offset from the nearest own sample lies
        // along it, "outside the outline" when across it.
        let centre = samples
            .iter()
            .map(|p| p.coords)
            .sum::<nalgebra::Vector3<f64>>()
            / samples.len() as f64;
        let scatter = samples.iter().fold(nalgebra::Matrix3::zeros(), |m, p| {
            let d = p.coords - centre;
            m + d * d.transpose()
        });
        let eigen = scatter.symmetric_eigen();
        let normal = eigen
            .eigenvectors
            .column(eigen.eigenvalues.imin())
            .into_owned();
        let mut depth_off = 0.0f64;
        if let Some(mesh) = mesh {
            for (t, tri) in mesh.triangles.iter().enumerate() {
                let c = tri
                    .iter()
                    .map(|&v| mesh.positions[v as usize].cast::<f64>().coords)
                    .sum::<nalgebra::Vector3<f64>>()
                    / 3.0;
                let c = Point3::from(c);
                let area = mesh.triangle_area(t) as f64;
                let within = |tree: &Option<Neighbours>| {
                    tree.as_ref()
                        .and_then(|t| t.nearest(&c))
                        .is_some_and(|n| n.distance() <= r)
                };
                if !within(&own)
                    && let Some(found) = own.as_ref().and_then(|t| t.nearest(&c))
                {
                    let offset = c - samples[found.index];
                    let across = offset - normal * normal.dot(&offset);
                    if across.norm() <= r {
                        depth_off += area;
                    }
                }
                let k = if within(&own) {
                    0
                } else if within(&others) {
                    1
                } else if within(&not_leaf) {
                    2
                } else {
                    3
                };
                on[k] += area;
            }
        }
        let total: f64 = on.iter().sum::<f64>().max(1e-30);
        let mut shares: Vec<f64> = on.iter().map(|a| a / total).collect();
        shares.push(depth_off / total);
        for (s, v) in excess_sums.iter_mut().zip(&shares) {
            *s += v;
        }
        views.sort_unstable();
        let n = samples.len() as f64;
        let f: Vec<f64> = hits.iter().map(|&h| h as f64 / n).collect();
        let ratio = mesh.map_or(0.0, |mesh| mesh.area() / record.area);
        println!(
            "{:>3} {:>4} {:>8} {:>8.3} {:>7.3} {:>8.3} {:>6.3} {:>5.3} {:>11.3}  | {:.3} {:.3} {:.3} {:.3} (off in depth {:.3})  views p10/p50 {}/{}",
            m.gt_leaf,
            m.segment,
            samples.len(),
            f[4],
            f[0],
            f[1],
            f[2],
            f[3],
            ratio,
            shares[0],
            shares[1],
            shares[2],
            shares[3],
            shares[4],
            views[views.len() / 10],
            views[views.len() / 2]
        );
        for (s, v) in sums.iter_mut().zip(&f) {
            *s += v;
        }
        count += 1;
    }
    if count > 0 {
        let c = count as f64;
        println!(
            "mean: seen>=2 {:.3} points {:.3} segment {:.3} other {:.3} mesh {:.3} ({count} leaves)",
            sums[4] / c,
            sums[0] / c,
            sums[1] / c,
            sums[2] / c,
            sums[3] / c
        );
        println!(
            "mean share of the fitted mesh on: its own leaf {:.3}, another leaf {:.3}, stem/pot/floor {:.3}, nothing {:.3}; off its leaf in depth only (within r of it across the leaf's plane) {:.3}",
            excess_sums[0] / c,
            excess_sums[1] / c,
            excess_sums[2] / c,
            excess_sums[3] / c,
            excess_sums[4] / c
        );
    }
    Ok(())
}
