//! Reading a large COLMAP binary model: 1M points, 200 images (issue target: under 1 s).
//! Baseline in the same run: reading the same files' bytes from disk without parsing.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::scene::synthetic::{SyntheticModelSpec, generate};
use frond::scene::{CameraModelKind, ModelFormat, read_model, write_model};

fn large_model_read(c: &mut Criterion) {
    let model = generate(&SyntheticModelSpec {
        num_points: 1_000_000,
        num_images: 200,
        width: 1600,
        height: 1200,
        camera_model: CameraModelKind::OpenCv,
        shared_camera: false,
        max_track_length: 8,
        unmatched_keypoints_per_image: 2_000,
        ..Default::default()
    });
    let dir = tempfile::tempdir().expect("temp dir");
    write_model(dir.path(), &model, ModelFormat::Binary).expect("write model");
    let bytes: u64 = ["cameras.bin", "images.bin", "points3D.bin"]
        .iter()
        .map(|f| {
            std::fs::metadata(dir.path().join(f))
                .map(|m| m.len())
                .unwrap_or(0)
        })
        .sum();
    eprintln!(
        "model: {} points, {} images, {} observations, {:.1} MB on disk",
        model.points().len(),
        model.images().len(),
        model.num_observations(),
        bytes as f64 / 1e6
    );

    let mut group = c.benchmark_group("colmap_binary_1M_points_200_images");
    group.sample_size(10);
    group.bench_function("baseline_read_bytes", |b| {
        b.iter(|| {
            for f in ["cameras.bin", "images.bin", "points3D.bin"] {
                black_box(std::fs::read(dir.path().join(f)).expect("read"));
            }
        })
    });
    group.bench_function("read_model", |b| {
        b.iter(|| black_box(read_model(dir.path()).expect("read model")))
    });
    group.finish();
}

fn text_model_read(c: &mut Criterion) {
    let model = generate(&SyntheticModelSpec {
        num_points: 100_000,
        num_images: 36,
        width: 800,
        height: 600,
        ..Default::default()
    });
    let dir = tempfile::tempdir().expect("temp dir");
    write_model(dir.path(), &model, ModelFormat::Text).expect("write model");
    let mut group = c.benchmark_group("colmap_text_100k_points_36_images");
    group.sample_size(10);
    group.bench_function("read_model", |b| {
        b.iter(|| black_box(read_model(dir.path()).expect("read model")))
    });
    group.finish();
}

criterion_group!(benches, large_model_read, text_model_read);
criterion_main!(benches);
