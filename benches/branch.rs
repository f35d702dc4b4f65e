//! Branch speed (issue targets: re-meshing an edited branch < 5 ms; automatic skeleton of a
//! 100k-point plant < 3 s, and of a 500k-point plant < 3 s). The skeleton runs on the non-leaf
//! points of a synthetic medium plant segmented from ~105k and ~500k points; baseline in the
//! same run: the plain 3-NN pairs of the same points (kiddo), which the skeleton's graph
//! construction extends. At 500k the whole step the pipeline runs is timed as well: the
//! skeleton's input (tube test, pot and soil) and the skeleton.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::branch::plant::{
    PlantSkeletonOptions, TubeTest, automatic_plant_skeleton, model_branches, skeleton_points,
};
use frond::branch::skeleton::{SkeletonOptions, automatic_skeleton};
use frond::branch::{CylinderMeshing, GeneralizedCylinder, Spline};
use frond::edit::Session;
use frond::graph::knn_pairs;
use frond::graph::points::PointSet;
use frond::scene::Scene;
use frond::segment::{SegmentOptions, segment_scene};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;
use nalgebra::Point3;

fn branches(c: &mut Criterion) {
    // Re-meshing one edited branch: a curved 12-control-point branch at export resolution.
    let control: Vec<Point3<f64>> = (0..12)
        .map(|k| {
            let t = k as f64 / 11.0;
            Point3::new(0.1 * (3.0 * t).sin(), 0.05 * t * t, 0.4 * t)
        })
        .collect();
    let cylinder = GeneralizedCylinder::new(Spline::new(control).expect("spline"), 0.01, 0.003);
    let meshing = CylinderMeshing {
        radial_segments: 12,
        axial_segments: 64,
        cap_start: false,
        cap_end: true,
    };
    let mut group = c.benchmark_group("branch_remesh");
    group.bench_function("spline_and_mesh_12x64", |b| {
        b.iter(|| {
            let mut moved = cylinder.skeleton.control_points().to_vec();
            moved[5].x += 0.001;
            let edited = GeneralizedCylinder::new(Spline::new(moved).expect("spline"), 0.01, 0.003);
            black_box(edited.mesh(&meshing))
        })
    });
    group.finish();

    skeleton_on_plant(c, "automatic_skeleton_100k_point_plant", 125_000, false);
    skeleton_on_plant(c, "automatic_skeleton_500k_point_plant", 600_000, true);
}

/// The skeleton benchmarks on a synthetic medium plant of `target_points` points.
fn skeleton_on_plant(c: &mut Criterion, name: &str, target_points: usize, whole_step: bool) {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = dir.path().join("plant");
    let options = SynthOptions {
        preset: Preset::Medium,
        seed: 20,
        target_points,
        ..SynthOptions::default()
    };
    write_dataset(&options, &root, &NoProgress).expect("synthetic dataset");
    let scene = Scene::open(&root).expect("scene");
    let segmentation =
        segment_scene(&scene, &SegmentOptions::default(), &NoProgress).expect("segmentation");
    let session = Session::new(scene, segmentation);
    let points = skeleton_points(
        session.segmentation(),
        session.labels(),
        &TubeTest::default(),
    );
    let foreground = &session.segmentation().foreground;
    let (up, centre) = (foreground.up, foreground.plant_center);
    let (tree, stats) =
        automatic_skeleton(&points, &up, &centre, &SkeletonOptions::default()).expect("skeleton");
    eprintln!(
        "{} points in the scene, {} non-leaf points, {} branches ({stats:?})",
        session.segmentation().points.len(),
        points.len(),
        tree.branches.len()
    );
    let point_set = PointSet {
        positions: points.clone(),
        ..PointSet::default()
    };
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    group.bench_function("baseline_knn_pairs_k3", |b| {
        b.iter(|| black_box(knn_pairs(&point_set, 3)))
    });
    group.bench_function("automatic_skeleton", |b| {
        b.iter(|| {
            black_box(
                automatic_skeleton(&points, &up, &centre, &SkeletonOptions::default())
                    .expect("skeleton"),
            )
        })
    });
    if whole_step {
        group.bench_function("skeleton_input_and_skeleton", |b| {
            b.iter(|| {
                black_box(
                    automatic_plant_skeleton(
                        session.segmentation(),
                        session.labels(),
                        &PlantSkeletonOptions::default(),
                    )
                    .expect("skeleton"),
                )
            })
        });
    } else {
        group.bench_function("skeleton_and_meshes", |b| {
            b.iter(|| {
                let (tree, _) =
                    automatic_skeleton(&points, &up, &centre, &SkeletonOptions::default())
                        .expect("skeleton");
                black_box(model_branches(&tree))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, branches);
criterion_main!(benches);
