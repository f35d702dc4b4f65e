//! Leaf segmentation end to end on a small synthetic plant, and its failure modes.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frond::eval::{EvalOptions, GroundTruth, Prediction, evaluate};
use frond::pipeline::write_automatic_segmentation;
use frond::scene::{ModelFormat, Scene, SceneSource, read_model, write_model};
use frond::segment::{SegmentError, SegmentOptions, segment_scene};
use frond::synth::{Preset, SynthOptions};
use frond::util::progress::NoProgress;
use tempfile::TempDir;

/// A small broadleaf capture (seed not used for tuning).
fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Broadleaf,
            seed: 41,
            views: 16,
            width: 480,
            height: 360,
            target_points: 25_000,
            ..SynthOptions::default()
        },
    )
}

#[test]
fn broadleaf_leaves_are_recovered() {
    let scene = Scene::open(dataset()).unwrap();
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap();
    let out = tempfile::tempdir().unwrap();
    write_automatic_segmentation(&scene, &segmentation, out.path()).unwrap();
    let truth = GroundTruth::load(dataset()).unwrap();
    let prediction = Prediction::load(out.path()).unwrap();
    let report = evaluate(&truth, &prediction, None, &EvalOptions::default()).unwrap();
    assert!(
        report.leaves.recall >= 0.9,
        "recall {} ({}/{})",
        report.leaves.recall,
        report.leaves.matched,
        report.leaves.gt_leaves
    );
    assert!(report.ari_plant > 0.8, "ARI {}", report.ari_plant);
    // Floor and background never end up in a leaf.
    let parts = truth.points.parts.as_ref().unwrap();
    let misplaced = prediction
        .points
        .leaf_ids
        .iter()
        .zip(parts)
        .filter(|(l, p)| {
            **l >= 0
                && matches!(
                    p,
                    frond::synth::Part::Floor | frond::synth::Part::Background
                )
        })
        .count();
    assert!(
        misplaced * 200 < prediction.points.leaf_ids.len(),
        "{misplaced} floor/background points in leaves"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("segments.json")).unwrap())
            .unwrap();
    assert_eq!(
        json["leaves"].as_u64().unwrap() as usize,
        segmentation.num_leaves()
    );
}

#[test]
fn segmentation_is_deterministic() {
    let scene = Scene::open(dataset()).unwrap();
    let a = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap();
    let b = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap();
    assert_eq!(a.leaf_ids(), b.leaf_ids());
}

#[test]
fn the_image_term_needs_images_and_alpha_zero_does_not() {
    let (model, _) = read_model(&dataset().join("sparse/0")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_model(&dir.path().join("sparse/0"), &model, ModelFormat::Binary).unwrap();
    let scene = Scene::from_source(SceneSource::locate(dir.path()).unwrap()).unwrap();
    let err = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap_err();
    assert!(matches!(err, SegmentError::NoImages { .. }), "{err}");
    assert!(err.to_string().contains("--alpha 0"), "{err}");
    let mut options = SegmentOptions::default();
    options.graph.alpha = 0.0;
    let segmentation = segment_scene(&scene, &options, &NoProgress).unwrap();
    assert!(segmentation.num_leaves() > 0);
}

#[test]
fn points_without_tracks_are_refused() {
    let (model, _) = read_model(&dataset().join("sparse/0")).unwrap();
    let images: Vec<_> = model
        .images()
        .iter()
        .map(|image| frond::scene::Image {
            keypoints: image
                .keypoints
                .iter()
                .map(|k| frond::scene::Keypoint {
                    point3d_id: None,
                    ..*k
                })
                .collect(),
            ..image.clone()
        })
        .collect();
    let points: Vec<_> = model
        .points()
        .iter()
        .map(|p| frond::scene::Point3D {
            track: Vec::new(),
            ..p.clone()
        })
        .collect();
    let stripped =
        frond::scene::Reconstruction::from_parts(model.cameras().to_vec(), images, points).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_model(&dir.path().join("sparse/0"), &stripped, ModelFormat::Binary).unwrap();
    let scene = Scene::open(dir.path()).unwrap();
    let err = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap_err();
    assert!(matches!(err, SegmentError::NoTracks(_)), "{err}");
}
