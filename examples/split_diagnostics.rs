//! Tuning aid for the normalized-cut stop criteria: on a synthetic dataset, recursively splits
//! every threshold component at its best sweep cut (without judging), and prints one CSV row
//! per proposed split with its features and what the ground truth says it is:
//! `boundary` (the sides are mostly different GT leaves or parts), `within` (same leaf),
//! or `mixed`. Usage: `cargo run --example split_diagnostics -- DATASET [ALPHA]`.

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::{Context, Result};
use frond::eval::GroundTruth;
use frond::graph::components::Adjacency;
use frond::graph::gradient::GradientImage;
use frond::graph::lanczos::{LanczosOptions, fiedler_vector};
use frond::graph::ncut::best_sweep_split;
use frond::graph::points::PointSet;
use frond::graph::shape::Shape;
use frond::graph::{GraphOptions, PointGraph, ViewData};
use frond::scene::Scene;
use frond::segment::foreground::{ForegroundOptions, PointClass, separate_foreground};

fn majority(labels: &[i64]) -> (i64, f64) {
    let mut counts: HashMap<i64, usize> = HashMap::new();
    for &l in labels {
        *counts.entry(l).or_insert(0) += 1;
    }
    let (label, count) = counts
        .into_iter()
        .max_by_key(|&(l, c)| (c, l))
        .unwrap_or((-9, 0));
    (label, count as f64 / labels.len().max(1) as f64)
}

fn main() -> Result<()> {
    let root = PathBuf::from(std::env::args().nth(1).context("dataset path")?);
    let alpha: f64 = std::env::args().nth(2).map_or(Ok(0.5), |a| a.parse())?;
    let scene = Scene::open(&root)?;
    let truth = GroundTruth::load(&root)?;
    let points = PointSet::from_scene(&scene);
    let foreground = separate_foreground(
        &points,
        &scene.reconstruction,
        &ForegroundOptions::default(),
    )?;
    let plant: Vec<usize> = (0..points.len())
        .filter(|&i| foreground.class[i] == PointClass::Plant)
        .collect();
    let plant_points = points.subset(&plant);
    // GT label per plant point: leaf id, or −2 stem, −3 pot, −4 other.
    let parts = truth.points.parts.clone().context("parts")?;
    let gt: Vec<i64> = plant
        .iter()
        .map(|&i| {
            let leaf = truth.points.leaf_ids[i];
            if leaf >= 0 {
                leaf
            } else {
                -2 - (parts[i] as i64).min(2)
            }
        })
        .collect();
    let model = &scene.reconstruction;
    let gradients: Vec<Option<GradientImage>> = model
        .images()
        .iter()
        .map(|image| GradientImage::for_image(&scene, image).ok())
        .collect();
    let views: Vec<ViewData> = model
        .images()
        .iter()
        .enumerate()
        .map(|(v, image)| ViewData {
            camera: model.camera_of(image),
            camera_from_world: image.camera_from_world,
            gradient: gradients[v].as_ref(),
        })
        .collect();
    let graph = PointGraph::build(
        &plant_points,
        &views,
        GraphOptions {
            alpha,
            ..Default::default()
        },
    );
    // Edge statistics by ground-truth relation.
    for (name, relation) in [("leaf-same", 0), ("stem/pot-same", 1), ("cross", 2)] {
        let edges: Vec<_> = graph
            .edges
            .iter()
            .filter(|e| {
                let (a, b) = (gt[e.a as usize], gt[e.b as usize]);
                match relation {
                    0 => a == b && a >= 0,
                    1 => a == b && a < 0,
                    _ => a != b,
                }
            })
            .collect();
        let same = name;
        let n = edges.len().max(1) as f64;
        let cut3 = edges
            .iter()
            .filter(|e| e.d3d as f64 >= 3.0 * graph.sigma_3d)
            .count() as f64
            / n;
        let cut2 = edges
            .iter()
            .filter(|e| e.d2d as f64 >= 3.0 * graph.sigma_2d)
            .count() as f64
            / n;
        let mut ratio: Vec<f64> = edges
            .iter()
            .map(|e| e.d2d as f64 / graph.sigma_2d)
            .collect();
        ratio.sort_by(f64::total_cmp);
        let q = |p: f64| {
            ratio
                .get((p * ratio.len() as f64) as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        eprintln!(
            "{} edges: {}  cut by 3D {:.3}  cut by 2D {:.3}  d2D/σ2D p25 {:.2} p50 {:.2} p75 {:.2} p90 {:.2}",
            same,
            edges.len(),
            cut3,
            cut2,
            q(0.25),
            q(0.5),
            q(0.75),
            q(0.9)
        );
    }
    // Draw the cut same-leaf edges (red) and kept ones (green) over view 3.
    if let Some(image) = model.images().get(3) {
        let mut canvas = image::open(scene.image_path(image).context("image")?)?.to_rgb8();
        let camera = model.camera_of(image);
        for e in &graph.edges {
            let (a, b) = (gt[e.a as usize], gt[e.b as usize]);
            if a != b || a < 0 {
                continue;
            }
            let cut = e.d2d as f64 >= 3.0 * graph.sigma_2d;
            let project = |i: u32| {
                camera
                    .project(&(image.camera_from_world * plant_points.positions[i as usize]).coords)
            };
            if let (Some(pa), Some(pb)) = (project(e.a), project(e.b)) {
                for k in 0..=8 {
                    let p = pa + (pb - pa) * (k as f64 / 8.0);
                    let (x, y) = (p.x as u32, p.y as u32);
                    if x < canvas.width() && y < canvas.height() {
                        canvas.put_pixel(
                            x,
                            y,
                            if cut {
                                image::Rgb([255, 0, 0])
                            } else {
                                image::Rgb([0, 255, 0])
                            },
                        );
                    }
                }
            }
        }
        canvas.save("/tmp/edges_view3.png")?;
    }
    let adjacency: Adjacency = graph.adjacency();
    let components = adjacency.components();
    println!(
        "kind,size,smaller,ncut,cut_ratio,bottleneck,flat_whole,flat_a,flat_b,purity_a,purity_b,lambda"
    );
    let mut queue = components.groups();
    while let Some(group) = queue.pop() {
        if group.len() < 40 {
            continue;
        }
        let sub = adjacency.induced(&group);
        let pieces = sub.components();
        if pieces.count > 1 {
            for piece in pieces.groups() {
                queue.push(piece.iter().map(|&i| group[i as usize]).collect());
            }
            continue;
        }
        let Some((lambda, fiedler)) = fiedler_vector(&sub, &LanczosOptions::default()) else {
            continue;
        };
        let Some(split) = best_sweep_split(&sub, &fiedler, 20) else {
            continue;
        };
        let mean_weight = sub.weights.iter().sum::<f64>() / sub.weights.len().max(1) as f64;
        let mean_cut = split.cut_weight / split.cut_edges.max(1) as f64;
        let side = |a: bool| -> Vec<u32> {
            group
                .iter()
                .zip(&split.side)
                .filter(|(_, s)| **s == a)
                .map(|(g, _)| *g)
                .collect()
        };
        let (a, b) = (side(true), side(false));
        let labels = |nodes: &[u32]| nodes.iter().map(|&n| gt[n as usize]).collect::<Vec<_>>();
        let ((la, pa), (lb, pb)) = (majority(&labels(&a)), majority(&labels(&b)));
        let kind = if la == lb {
            "within"
        } else if pa > 0.7 && pb > 0.7 {
            "boundary"
        } else {
            "mixed"
        };
        let shape =
            |nodes: &[u32]| Shape::of(nodes.iter().map(|&n| plant_points.positions[n as usize]));
        println!(
            "{kind},{},{},{:.5},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.6}",
            group.len(),
            split.smaller_side,
            split.ncut,
            mean_cut / mean_weight,
            split.cut_edges as f64 / (split.smaller_side as f64).sqrt(),
            shape(&group).flatness(),
            shape(&a).flatness(),
            shape(&b).flatness(),
            pa,
            pb,
            lambda
        );
        queue.push(a);
        queue.push(b);
    }
    eprintln!(
        "sigma3d {:.5} sigma2d {:.3} edges {} kept {} components {}",
        graph.sigma_3d,
        graph.sigma_2d,
        graph.edges.len(),
        graph.edges.iter().filter(|e| e.weight > 0.0).count(),
        components.count
    );
    Ok(())
}
