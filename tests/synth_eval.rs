//! The synthetic test bed end to end: render a small plant, check what is written, and score
//! predictions made from the ground truth (perfect, two leaves merged, one leaf split).

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frond::eval::{EvalOptions, EvalReport, GroundTruth, Prediction, evaluate};
use frond::mesh::TriMesh;
use frond::model::gltf::{ExportNode, write_glb};
use frond::model::{segmentation_ply, write_segmentation_ply};
use frond::scene::{ModelFormat, read_model};
use frond::synth::{Backdrop, Preset, SynthOptions};
use tempfile::TempDir;

/// One small broadleaf dataset shared by the tests of this file.
fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Broadleaf,
            seed: 3,
            views: 10,
            width: 320,
            height: 240,
            target_points: 12_000,
            ..SynthOptions::default()
        },
    )
}

#[test]
fn synth_writes_a_consistent_colmap_project_and_ground_truth() {
    let root = dataset();
    let (model, format) = read_model(&root.join("sparse/0")).unwrap();
    assert_eq!(format, ModelFormat::Binary);
    assert_eq!(model.images().len(), 10);
    assert!(
        model.points().len() > 5_000,
        "{} points",
        model.points().len()
    );
    assert!(model.points().iter().all(|p| p.track.len() >= 2));
    // Keypoints reproject within the noise (outliers aside).
    let mut errors: Vec<f64> = model.points().iter().map(|p| p.error).collect();
    errors.sort_by(f64::total_cmp);
    assert!(
        errors[errors.len() / 2] < 2.0,
        "median reprojection {}",
        errors[errors.len() / 2]
    );
    for image in model.images() {
        let path = root.join("images").join(&image.name);
        assert_eq!(image::image_dimensions(&path).unwrap(), (320, 240));
        let mask = image::open(root.join("gt/masks").join(&image.name)).unwrap();
        assert!(matches!(mask, image::DynamicImage::ImageLuma16(_)));
    }
    let truth = GroundTruth::load(root).unwrap();
    assert_eq!(truth.points.positions.len(), model.points().len());
    assert!((8..=20).contains(&truth.leaves.len()));
    assert!(!truth.branches.is_empty());
    let leaf_points = truth.points.leaf_ids.iter().filter(|&&l| l >= 0).count();
    assert!(
        leaf_points > model.points().len() / 4,
        "{leaf_points} leaf points"
    );
    // Every ground-truth leaf label is a leaf of the plant.
    assert!(
        truth
            .points
            .leaf_ids
            .iter()
            .all(|&l| l < truth.leaves.len() as i64)
    );
}

#[test]
fn colmap_model_analyzer_reads_the_synthetic_model() {
    if !common::colmap_available() {
        return;
    }
    let root = dataset();
    let (model, _) = read_model(&root.join("sparse/0")).unwrap();
    let stats = common::analyze(&root.join("sparse/0"));
    assert_eq!(stats["Registered images"] as usize, 10);
    assert_eq!(stats["Points"] as usize, model.points().len());
    assert_eq!(stats["Observations"] as usize, model.num_observations());
}

/// Writes a prediction whose segment of each point is `label(gt_leaf_id)` and whose leaf
/// meshes are the GT meshes, then scores it.
fn score_prediction(relabel: impl Fn(usize, i64) -> i64) -> EvalReport {
    let root = dataset();
    let truth = GroundTruth::load(root).unwrap();
    let (model, _) = read_model(&root.join("sparse/0")).unwrap();
    let positions: Vec<_> = model.points().iter().map(|p| p.position_world).collect();
    let colors: Vec<_> = model.points().iter().map(|p| p.color).collect();
    let ids: Vec<u64> = model.points().iter().map(|p| p.id).collect();
    let labels: Vec<i64> = truth
        .points
        .leaf_ids
        .iter()
        .enumerate()
        .map(|(i, &l)| relabel(i, l))
        .collect();
    let out = tempfile::tempdir().unwrap();
    write_segmentation_ply(
        &out.path().join("segmentation.ply"),
        &segmentation_ply(&positions, &colors, ("point_id", &ids), &labels, &labels),
    )
    .unwrap();
    let meshes: Vec<(String, &TriMesh)> = truth
        .leaves
        .iter()
        .map(|(record, mesh)| (format!("leaf_{:03}", record.id), mesh))
        .collect();
    let nodes: Vec<ExportNode> = meshes
        .iter()
        .map(|(name, mesh)| ExportNode {
            name: name.clone(),
            mesh,
            texture: None,
            color: [0.2, 0.6, 0.2, 1.0],
            double_sided: true,
            group: None,
        })
        .collect();
    std::fs::write(out.path().join("plant.glb"), write_glb(&nodes, &[], "test")).unwrap();
    let prediction = Prediction::load(out.path()).unwrap();
    evaluate(&truth, &prediction, None, &EvalOptions::default()).unwrap()
}

#[test]
fn prediction_from_the_truth_scores_perfectly() {
    let report = score_prediction(|_, l| l);
    assert_eq!(report.pairing, "point_id");
    assert_eq!(report.leaves.recall, 1.0);
    assert_eq!(report.leaves.precision, 1.0);
    assert_eq!(report.leaves.over_segmented, 0);
    assert_eq!(report.leaves.under_segmented, 0);
    assert!((report.ari_plant - 1.0).abs() < 1e-12);
    assert_eq!(report.chamfer_relative.count, report.leaves.matched);
    assert!(report.chamfer_relative.median.unwrap() < 1e-5);
    assert!(report.area_relative_error.median.unwrap() < 1e-9);
    assert!(report.normal_angle_deg.median.unwrap() < 0.01);
}

/// The two largest scored GT leaves (by point count), largest first.
fn two_largest_leaves() -> (i64, i64, usize) {
    let truth = GroundTruth::load(dataset()).unwrap();
    let mut counts = std::collections::BTreeMap::new();
    for &l in &truth.points.leaf_ids {
        if l >= 0 {
            *counts.entry(l).or_insert(0usize) += 1;
        }
    }
    let mut by_size: Vec<(usize, i64)> = counts.iter().map(|(&l, &n)| (n, l)).collect();
    by_size.sort_unstable_by(|a, b| b.cmp(a));
    let eligible = by_size.iter().filter(|(n, _)| *n >= 20).count();
    (by_size[0].1, by_size[1].1, eligible)
}

#[test]
fn merging_two_leaves_loses_exactly_one() {
    let (large, small, eligible) = two_largest_leaves();
    let report = score_prediction(|_, l| if l == small { large } else { l });
    assert_eq!(report.leaves.gt_leaves, eligible);
    assert_eq!(report.leaves.matched, eligible - 1);
    assert!((report.leaves.recall - (eligible - 1) as f64 / eligible as f64).abs() < 1e-12);
    assert_eq!(report.leaves.under_segmented, 1);
    assert!(report.ari_plant < 1.0);
}

#[test]
fn splitting_a_leaf_in_three_loses_it_and_counts_one_over_segmentation() {
    let (large, _, eligible) = two_largest_leaves();
    let report = score_prediction(|i, l| if l == large { 1000 + (i % 3) as i64 } else { l });
    assert_eq!(report.leaves.matched, eligible - 1);
    assert_eq!(report.leaves.over_segmented, 1);
    assert_eq!(report.leaves.predicted_segments, eligible + 2);
    assert!(report.ari_plant < 1.0);
}

/// The studio backdrop renders what a phenotyping cabin's photos show around the plant: dark,
/// nearly textureless cloth where the patterned backdrop gives stereo texture; the plant, its
/// ground truth and the cameras are the same.
#[test]
fn the_studio_backdrop_is_dark_plain_cloth_around_the_same_plant() {
    let dir = tempfile::tempdir().unwrap();
    let render = |backdrop: Backdrop| {
        let root = dir.path().join(backdrop.name());
        let options = SynthOptions {
            preset: Preset::Broadleaf,
            seed: 7,
            views: 4,
            width: 200,
            height: 150,
            with_points: false,
            backdrop,
            ..SynthOptions::default()
        };
        frond::synth::write_dataset(&options, &root, &frond::util::progress::NoProgress).unwrap();
        root
    };
    let (patterned, studio) = (render(Backdrop::Patterned), render(Backdrop::Studio));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(studio.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["options"]["backdrop"], "studio");
    // Pixels outside every leaf in the top fifth of each photo: wall or floor, never the pot.
    let background = |root: &Path, view: &str| {
        let photo = image::open(root.join("images").join(view))
            .unwrap()
            .to_luma8();
        let mask = image::open(root.join("gt/masks").join(view))
            .unwrap()
            .to_luma16();
        let (w, h) = photo.dimensions();
        let (mut sum, mut detail, mut n) = (0.0, 0.0, 0usize);
        for y in 0..h / 5 {
            for x in 1..w {
                if mask.get_pixel(x, y)[0] == 0 && mask.get_pixel(x - 1, y)[0] == 0 {
                    let (a, b) = (
                        photo.get_pixel(x, y)[0] as f64,
                        photo.get_pixel(x - 1, y)[0] as f64,
                    );
                    sum += a;
                    detail += (a - b).abs();
                    n += 1;
                }
            }
        }
        assert!(n > 1000, "{n} background pixels in {view}");
        (sum / n as f64, detail / n as f64)
    };
    for k in 0..4 {
        let view = format!("view_{k:04}.png");
        let (studio_mean, studio_detail) = background(&studio, &view);
        let (patterned_mean, patterned_detail) = background(&patterned, &view);
        assert!(
            studio_mean < 50.0 && studio_mean < 0.5 * patterned_mean,
            "{view}: {studio_mean} vs {patterned_mean}"
        );
        assert!(
            studio_detail < 0.2 * patterned_detail,
            "{view}: {studio_detail} vs {patterned_detail}"
        );
    }
    // The same plant and cameras: identical ground truth and poses.
    for file in [
        "gt/leaves.json",
        "gt/branches.json",
        "sparse/0/images.bin",
        "sparse/0/cameras.bin",
    ] {
        assert_eq!(
            std::fs::read(patterned.join(file)).unwrap(),
            std::fs::read(studio.join(file)).unwrap(),
            "{file}"
        );
    }
}
