//! Interop with the real COLMAP: what Frond writes, `colmap model_analyzer` and
//! `colmap model_converter` read with the same counts, and what COLMAP writes back, Frond reads
//! as the same model. Runs when `colmap` is on PATH; on CI (CI=true) a missing COLMAP fails.

mod common;

use std::path::Path;

use common::{analyze, colmap_available, run_colmap};

use frond::scene::synthetic::{SyntheticModelSpec, generate};
use frond::scene::{CameraModelKind, ModelFormat, Reconstruction, read_model, write_model};

fn check_analyzer_counts(dir: &Path, model: &Reconstruction) {
    let stats = analyze(dir);
    assert_eq!(
        stats["Cameras"] as usize,
        model.cameras().len(),
        "{stats:?}"
    );
    assert_eq!(stats["Images"] as usize, model.images().len());
    assert_eq!(stats["Registered images"] as usize, model.images().len());
    assert_eq!(stats["Points"] as usize, model.points().len());
    assert_eq!(stats["Observations"] as usize, model.num_observations());
    let mean_track = model.num_observations() as f64 / model.points().len() as f64;
    assert!((stats["Mean track length"] - mean_track).abs() < 1e-5);
    let mean_error =
        model.points().iter().map(|p| p.error).sum::<f64>() / model.points().len() as f64;
    assert!(
        (stats["Mean reprojection error"] - mean_error).abs() < 1e-5,
        "colmap {} vs frond {mean_error}",
        stats["Mean reprojection error"]
    );
}

/// Every camera model COLMAP 3.8 knows (RAD_TAN_THIN_PRISM_FISHEYE came later).
fn colmap_38_models() -> impl Iterator<Item = CameraModelKind> {
    CameraModelKind::ALL
        .into_iter()
        .filter(|k| *k != CameraModelKind::RadTanThinPrismFisheye)
}

#[test]
fn colmap_reads_what_frond_writes_for_every_camera_model() {
    if !colmap_available() {
        return;
    }
    for camera_model in colmap_38_models() {
        let model = generate(&SyntheticModelSpec {
            num_points: 400,
            num_images: 6,
            camera_model,
            shared_camera: false,
            seed: camera_model.id() as u64,
            ..Default::default()
        });
        let root = tempfile::tempdir().unwrap();
        for format in [ModelFormat::Binary, ModelFormat::Text] {
            let ours = root.path().join(format!("frond_{format}"));
            write_model(&ours, &model, format).unwrap();
            check_analyzer_counts(&ours, &model);

            // COLMAP converts our model to the other format; we read COLMAP's output back.
            let (other, output_type) = match format {
                ModelFormat::Binary => (ModelFormat::Text, "TXT"),
                ModelFormat::Text => (ModelFormat::Binary, "BIN"),
            };
            let theirs = root.path().join(format!("colmap_{other}"));
            std::fs::create_dir_all(&theirs).unwrap();
            run_colmap(&[
                "model_converter",
                "--input_path",
                ours.to_str().unwrap(),
                "--output_path",
                theirs.to_str().unwrap(),
                "--output_type",
                output_type,
            ]);
            let (back, detected) = read_model(&theirs).unwrap();
            assert_eq!(detected, other);
            assert_models_equal(&back, &model, camera_model);
        }
    }
}

/// COLMAP sorts records by id and writes text with 17 significant digits: compare by id, with
/// exact equality for binary round trips and last-bit tolerance otherwise.
fn assert_models_equal(a: &Reconstruction, b: &Reconstruction, kind: CameraModelKind) {
    assert_eq!(a.cameras().len(), b.cameras().len(), "{kind}");
    for camera in b.cameras() {
        let other = a.camera(camera.id).expect("camera present");
        assert_eq!(other.model, camera.model);
        assert_eq!((other.width, other.height), (camera.width, camera.height));
        for (x, y) in other.params().iter().zip(camera.params()) {
            assert!(
                (x - y).abs() <= 1e-15 * y.abs().max(1.0),
                "{kind}: {x} vs {y}"
            );
        }
    }
    assert_eq!(a.images().len(), b.images().len());
    for image in b.images() {
        let other = a.image(image.id).expect("image present");
        assert_eq!(other.name, image.name);
        assert_eq!(other.camera_id, image.camera_id);
        let delta = other.camera_from_world.inverse() * image.camera_from_world;
        assert!(delta.translation.vector.norm() < 1e-12);
        assert!(delta.rotation.angle() < 1e-12);
        assert_eq!(other.keypoints.len(), image.keypoints.len());
        for (k, l) in other.keypoints.iter().zip(&image.keypoints) {
            assert_eq!(k.point3d_id, l.point3d_id);
            assert!((k.uv_image - l.uv_image).norm() < 1e-9);
        }
    }
    assert_eq!(a.points().len(), b.points().len());
    for point in b.points() {
        let other = a.point(point.id).expect("point present");
        assert_eq!(other.color, point.color);
        assert!((other.position_world - point.position_world).norm() < 1e-12);
        assert!((other.error - point.error).abs() < 1e-12);
        let mut t1 = other.track.clone();
        let mut t2 = point.track.clone();
        t1.sort_by_key(|t| (t.image_id, t.keypoint_index));
        t2.sort_by_key(|t| (t.image_id, t.keypoint_index));
        assert_eq!(t1, t2);
    }
}

#[test]
fn frond_reads_a_real_colmap_model_converted_to_text_like_the_binary() {
    if !colmap_available() {
        return;
    }
    let input =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/colmap_figurine/sparse/0");
    let out = tempfile::tempdir().unwrap();
    run_colmap(&[
        "model_converter",
        "--input_path",
        input.to_str().unwrap(),
        "--output_path",
        out.path().to_str().unwrap(),
        "--output_type",
        "TXT",
    ]);
    let (binary, _) = read_model(&input).unwrap();
    let (text, format) = read_model(out.path()).unwrap();
    assert_eq!(format, ModelFormat::Text);
    assert_models_equal(&text, &binary, CameraModelKind::SimpleRadial);
}
