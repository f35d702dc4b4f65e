//! Leaf fitting speed (issue targets: 120 leaves fitted in < 2 s; 1,500 small leaves in
//! < 10 s). Inputs come from synthetic plants: each ground-truth leaf gives a point sample at
//! the density of the synthetic datasets (~400 points per medium leaf), its outline projected
//! into the ring view that sees it most frontally as the image boundary, and an 800x600 photo.
//! Baseline in the same run: the flat fit alone (PCA and scaling, no warp, no deformation).
//! Fits run in parallel over leaves, as `reconstruct_leaves` runs them.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::leaf::template::LeafTemplate;
use frond::leaf::{BoundaryView, LeafFitOptions, PlantContext, fit_leaf};
use frond::scene::Camera;
use frond::synth::dataset::ring_cameras;
use frond::synth::{Preset, generate_plant};
use frond::util::rng::Rng;
use nalgebra::{Isometry3, Point2, Point3, Vector3};
use rayon::prelude::*;

/// Points per square metre of leaf: ~400 points on a 0.09 x 0.04 m medium leaf.
const POINTS_PER_M2: f64 = 400.0 / (0.09 * 0.04 * 0.7);

struct LeafCase {
    points: Vec<Point3<f64>>,
    polygon: Vec<[f64; 2]>,
    view: usize,
}

struct Cases {
    camera: Camera,
    camera_from_world: Vec<Isometry3<f64>>,
    photo: image::RgbImage,
    plant: PlantContext,
    leaves: Vec<LeafCase>,
}

/// `count` leaves from plants of `preset` (seeds 100, 101, … until there are enough).
fn cases(preset: Preset, count: usize) -> Cases {
    let mut rng = Rng::seed_from(7);
    let mut leaves = Vec::new();
    let mut seed = 100;
    let first = generate_plant(preset, seed);
    let (camera, camera_from_world) = ring_cameras(&first, 36, 800, 600);
    let mut plant = first;
    while leaves.len() < count {
        for leaf in &plant.leaves {
            if leaves.len() == count {
                break;
            }
            let geometry = &leaf.geometry;
            let to_world = |p: &Point3<f64>| leaf.world_from_leaf * p;
            let n = ((geometry.flat_area() * POINTS_PER_M2).round() as usize).max(3);
            let points: Vec<Point3<f64>> = (0..n)
                .map(|_| {
                    let t = rng.uniform().sqrt();
                    to_world(&geometry.point(t, rng.range(-1.0, 1.0)))
                })
                .collect();
            let normal = leaf.world_from_leaf.rotation * Vector3::z();
            let centre = to_world(&geometry.point(0.5, 0.0));
            // The ring view that sees the leaf most frontally.
            let Some((view, _)) = camera_from_world
                .iter()
                .enumerate()
                .map(|(v, pose)| {
                    let centre_camera = pose * centre;
                    let ray = centre_camera.coords.normalize();
                    let normal_camera = pose.rotation * normal;
                    (v, ray.dot(&normal_camera).abs())
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
            else {
                continue;
            };
            let [left, right, _] = geometry.polylines(40);
            let outline: Vec<Point3<f64>> =
                left.iter().chain(right.iter().rev()).copied().collect();
            let polygon: Option<Vec<[f64; 2]>> = outline
                .iter()
                .map(|p| {
                    let pixel = camera.project(&(camera_from_world[view] * to_world(p)).coords)?;
                    Some([pixel.x, pixel.y])
                })
                .collect();
            if let Some(polygon) = polygon {
                leaves.push(LeafCase {
                    points,
                    polygon,
                    view,
                });
            }
        }
        seed += 1;
        plant = generate_plant(preset, seed);
    }
    let photo = image::RgbImage::from_fn(800, 600, |x, y| {
        let h = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)) % 97;
        image::Rgb([40 + h as u8, 110 + (h / 2) as u8, 50])
    });
    Cases {
        camera,
        camera_from_world,
        photo,
        plant: PlantContext {
            up: Vector3::z(),
            axis_point: Point3::new(0.0, 0.0, 0.2),
            support: Vec::new(),
        },
        leaves,
    }
}

fn template() -> LeafTemplate {
    let outline: Vec<Point2<f64>> = (0..64)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / 64.0;
            // Ovate: wider toward the base.
            let x = 0.5 - 0.5 * t.cos();
            Point2::new(x, 0.25 * t.sin() * (1.2 - 0.5 * x))
        })
        .collect();
    LeafTemplate::from_outline(&outline, LeafTemplate::plain_texture(64)).expect("template")
}

fn fit_all(cases: &Cases, template: &LeafTemplate, options: &LeafFitOptions) -> usize {
    cases
        .leaves
        .par_iter()
        .filter(|case| {
            let view = BoundaryView {
                polygon: &case.polygon,
                camera: &cases.camera,
                camera_from_world: cases.camera_from_world[case.view],
                image: Some(&cases.photo),
            };
            fit_leaf(&case.points, template, &cases.plant, Some(&view), options).is_ok()
        })
        .count()
}

fn leaf_fitting(c: &mut Criterion) {
    let template = template();
    let flat = LeafFitOptions {
        use_boundary: false,
        deform: false,
        ..LeafFitOptions::default()
    };
    let full = LeafFitOptions::default();
    for (preset, count, name) in [
        (Preset::Medium, 120, "leaf_fit_120_medium"),
        (Preset::Smallleaf, 1500, "leaf_fit_1500_small"),
    ] {
        let cases = cases(preset, count);
        let points: usize = cases.leaves.iter().map(|l| l.points.len()).sum();
        eprintln!(
            "{name}: {} leaves, {:.0} points per leaf",
            cases.leaves.len(),
            points as f64 / cases.leaves.len() as f64
        );
        assert_eq!(fit_all(&cases, &template, &full), cases.leaves.len());
        let mut group = c.benchmark_group(name);
        group.sample_size(10);
        group.bench_function("baseline_flat_fit", |b| {
            b.iter(|| black_box(fit_all(&cases, &template, &flat)))
        });
        group.bench_function("full_fit", |b| {
            b.iter(|| black_box(fit_all(&cases, &template, &full)))
        });
        group.finish();
    }
}

criterion_group!(benches, leaf_fitting);
criterion_main!(benches);
