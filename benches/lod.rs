//! Simplification speed and quality (issue 9: ≥ 1M triangles/s; our half-edge collapse must
//! beat meshoptimizer on plant silhouettes to earn its place). Baseline in the same run:
//! `meshopt::simplify` (meshoptimizer) on the same mesh and triangle budget, compared by
//! throughput, symmetric Chamfer distance and silhouette IoU of 8 rendered views. The mesh is
//! a synthetic medium plant: every leaf mesh and every branch's generalized cylinder; set
//! `FROND_LOD_BENCH_GLB=a/plant.glb:b/plant.glb` to compare on reconstructed plants as well.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frond::branch::CylinderMeshing;
use frond::eval::geometry::symmetric_chamfer;
use frond::lod::chain::{ChainOptions, build_chain};
use frond::lod::simplify::{SimplifyOptions, simplify, simplify_meshopt};
use frond::mesh::TriMesh;
use frond::render::{Lighting, Renderer, ViewCamera};
use frond::synth::dataset::ring_cameras;
use frond::synth::{Preset, SynthPlant, generate_plant};

fn plant_mesh(plant: &SynthPlant) -> TriMesh {
    let mut mesh = TriMesh::default();
    for leaf in &plant.leaves {
        mesh.append(&leaf.mesh);
    }
    for branch in &plant.branches.branches {
        mesh.append(&branch.cylinder.mesh(&CylinderMeshing::default()));
    }
    mesh
}

/// Silhouettes (covered pixels) of `mesh` from `views`.
fn silhouettes(renderer: &mut Renderer, mesh: &TriMesh, views: &[ViewCamera]) -> Vec<Vec<bool>> {
    let mut gpu = renderer.new_scene();
    let white = image::RgbaImage::from_pixel(1, 1, image::Rgba([255, 255, 255, 255]));
    let texture = renderer.add_texture(&mut gpu, &white);
    renderer
        .add_mesh(&mut gpu, mesh, texture, 1, false)
        .expect("valid mesh");
    views
        .iter()
        .map(|view| {
            let out = renderer
                .render(&gpu, view, &Lighting::default())
                .expect("render");
            out.object_id.iter().map(|&id| id != 0).collect()
        })
        .collect()
}

/// Mean intersection over union of two sets of silhouettes.
fn mean_iou(a: &[Vec<bool>], b: &[Vec<bool>]) -> f64 {
    let ious: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let both = x.iter().zip(y).filter(|(p, q)| **p && **q).count();
            let either = x.iter().zip(y).filter(|(p, q)| **p || **q).count();
            both as f64 / either.max(1) as f64
        })
        .collect();
    ious.iter().sum::<f64>() / ious.len().max(1) as f64
}

fn meshopt_simplify(mesh: &TriMesh, target_triangles: usize) -> TriMesh {
    simplify_meshopt(mesh, target_triangles).expect("valid mesh")
}

/// 8 views around a mesh's bounding sphere (25° above the horizon, 480×360).
fn ring_views(mesh: &TriMesh) -> Vec<ViewCamera> {
    let (lo, hi) = mesh.bounds().expect("a non-empty mesh");
    let center = nalgebra::center(&lo, &hi).cast::<f64>();
    let radius = ((hi - lo).norm() * 0.5) as f64;
    (0..8)
        .map(|k| {
            let azimuth = k as f64 * std::f64::consts::TAU / 8.0;
            let elevation = 25f64.to_radians();
            let direction = nalgebra::Vector3::new(
                azimuth.cos() * elevation.cos(),
                azimuth.sin() * elevation.cos(),
                elevation.sin(),
            );
            let distance = 3.0 * radius;
            ViewCamera {
                width: 480,
                height: 360,
                fx: 160.0 * distance / radius,
                fy: 160.0 * distance / radius,
                cx: 240.0,
                cy: 180.0,
                camera_from_world: frond::scene::synthetic::look_at(
                    center + direction * distance,
                    center,
                ),
                near: 0.1 * radius,
                far: 10.0 * distance,
            }
        })
        .collect()
}

/// Ours against meshopt at 50 / 10 / 3 % of `mesh`: time, Chamfer error and silhouette IoU.
fn compare(label: &str, mesh: &TriMesh, views: &[ViewCamera], renderer: &mut Renderer) {
    let triangles = mesh.triangles.len();
    let extent = mesh
        .bounds()
        .map(|(lo, hi)| (hi - lo).norm() as f64)
        .unwrap_or(1.0);
    println!(
        "{label}: {triangles} triangles, {} vertices, diagonal {extent:.3} m",
        mesh.positions.len()
    );
    let full_silhouettes = silhouettes(renderer, mesh, views);
    for ratio in [0.5, 0.1, 0.03] {
        let target = (triangles as f64 * ratio) as usize;
        let started = Instant::now();
        let simplified = simplify(mesh, &SimplifyOptions::to_triangles(target)).expect("simplify");
        let ours = simplified.mesh;
        let ours_time = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let theirs = meshopt_simplify(mesh, target);
        let theirs_time = started.elapsed().as_secs_f64();
        println!(
            "{label} ratio {ratio}: {} collapses, {} refused",
            simplified.collapses, simplified.refused
        );
        let chamfer = |m: &TriMesh| symmetric_chamfer(mesh, m, 4000, 7).unwrap_or(f64::NAN);
        let ours_iou = mean_iou(&full_silhouettes, &silhouettes(renderer, &ours, views));
        let theirs_iou = mean_iou(&full_silhouettes, &silhouettes(renderer, &theirs, views));
        println!(
            "{label} ratio {ratio}: silhouette IoU against the full mesh (8 views, 480x360): ours {ours_iou:.4}, meshopt {theirs_iou:.4}"
        );
        println!(
            "{label} ratio {ratio}: ours {} triangles in {ours_time:.3} s ({:.2} M tri/s), Chamfer {:.3e} m ({:.3} % of diagonal); meshopt {} triangles in {theirs_time:.3} s ({:.2} M tri/s), Chamfer {:.3e} m ({:.3} %)",
            ours.triangles.len(),
            triangles as f64 / ours_time / 1e6,
            chamfer(&ours),
            100.0 * chamfer(&ours) / extent,
            theirs.triangles.len(),
            triangles as f64 / theirs_time / 1e6,
            chamfer(&theirs),
            100.0 * chamfer(&theirs) / extent,
        );
    }
}

fn simplification(c: &mut Criterion) {
    let plant = generate_plant(Preset::Medium, 1);
    let mesh = plant_mesh(&plant);
    let triangles = mesh.triangles.len();
    // Silhouettes from 8 ring views at 480×360 (the plant fills most of the frame).
    let (camera, poses) = ring_cameras(&plant, 8, 480, 360);
    let views: Vec<ViewCamera> = poses
        .iter()
        .map(|pose| ViewCamera::from_colmap(&camera, pose, 0.02, 10.0).expect("pinhole"))
        .collect();
    let mut renderer = Renderer::new().expect("a GPU adapter (llvmpipe)");
    compare("synthetic medium plant", &mesh, &views, &mut renderer);
    // Reconstructed plants (`frond reconstruct`'s plant.glb), when given.
    if let Some(paths) = std::env::var_os("FROND_LOD_BENCH_GLB") {
        for path in std::env::split_paths(&paths) {
            let asset = frond::lod::asset::PlantAsset::read_glb(&path).expect("a plant glb");
            let mesh = asset.merged();
            compare(
                &path.display().to_string(),
                &mesh,
                &ring_views(&mesh),
                &mut renderer,
            );
        }
    }

    let started = Instant::now();
    let chain = build_chain(&mesh, &ChainOptions::default()).expect("chain");
    println!(
        "LOD chain in {:.3} s: {}",
        started.elapsed().as_secs_f64(),
        chain
            .iter()
            .map(|l| format!("{} triangles, μ {:.2e} m", l.triangles, l.error_world))
            .collect::<Vec<_>>()
            .join("; ")
    );

    let mut group = c.benchmark_group("simplify_plant_to_10_percent");
    group.throughput(Throughput::Elements(triangles as u64));
    group.sample_size(10);
    let target = triangles / 10;
    group.bench_function("frond_half_edge_collapse", |b| {
        b.iter(|| black_box(simplify(&mesh, &SimplifyOptions::to_triangles(target))))
    });
    group.bench_function("meshopt_baseline", |b| {
        b.iter(|| black_box(meshopt_simplify(&mesh, target)))
    });
    group.finish();
}

criterion_group!(benches, simplification);
criterion_main!(benches);
