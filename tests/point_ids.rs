//! `segmentation.ply` joins to its input model by `point_id`: on a sparse COLMAP model and on
//! a dense workspace written by Frond's stereo (whose fused points are the workspace model's
//! point3D ids 1..n), every row's `point_id` names a point of the model at the row's position.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frond::mvs::{DensifyOptions, DensifyReport, FusedPoints, write_workspace};
use frond::pipeline::write_automatic_segmentation;
use frond::scene::ply::read_ply;
use frond::scene::{Reconstruction, Scene, read_model};
use frond::segment::{SegmentOptions, segment_scene};
use frond::synth::{Preset, SynthOptions};
use frond::util::progress::NoProgress;
use tempfile::TempDir;

fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Broadleaf,
            seed: 47,
            views: 8,
            width: 400,
            height: 300,
            target_points: 8_000,
            ..SynthOptions::default()
        },
    )
}

/// Segments the scene at `input`, writes `segmentation.ply` and checks that every row joins
/// to `model` by `point_id` at its own position; returns the rows.
fn assert_rows_join(input: &Path, model: &Reconstruction) -> usize {
    let scene = Scene::open(input).unwrap();
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap();
    let out = tempfile::tempdir().unwrap();
    write_automatic_segmentation(&scene, &segmentation, out.path()).unwrap();
    let ply = read_ply(&out.path().join("segmentation.ply")).unwrap();
    let vertex = ply.element("vertex").unwrap();
    let column = |name: &str| &vertex.column(name).unwrap().values;
    let (x, y, z, ids) = (column("x"), column("y"), column("z"), column("point_id"));
    assert!(vertex.column("fused_index").is_none());
    for row in 0..vertex.count {
        let point = model
            .point(ids[row] as u64)
            .unwrap_or_else(|| panic!("row {row}: point_id {} not in the model", ids[row]));
        let p = point.position_world;
        let distance =
            ((p.x - x[row]).powi(2) + (p.y - y[row]).powi(2) + (p.z - z[row]).powi(2)).sqrt();
        assert!(
            distance < 1e-6,
            "row {row}: {distance} from point {}",
            ids[row]
        );
    }
    vertex.count
}

#[test]
fn segmentation_rows_join_a_sparse_model_by_point_id() {
    let (model, _) = read_model(&dataset().join("sparse/0")).unwrap();
    let rows = assert_rows_join(dataset(), &model);
    assert_eq!(rows, model.points().len());
}

#[test]
fn segmentation_rows_join_a_dense_workspace_by_point_id() {
    // A dense workspace as `frond densify` writes it, with the sparse points as the fused
    // points (the stereo itself is tested in tests/dense.rs).
    let scene = Scene::open(dataset()).unwrap();
    let model = &scene.reconstruction;
    let mut fused = FusedPoints {
        positions_world: Vec::new(),
        colors: Vec::new(),
        views: Vec::new(),
        support: Vec::new(),
        thin_organ: Vec::new(),
        gap_fill: Vec::new(),
    };
    for point in model.points() {
        let mut views: Vec<u32> = point
            .track
            .iter()
            .filter_map(|t| model.image_position(t.image_id).map(|v| v as u32))
            .collect();
        views.sort_unstable();
        views.dedup();
        fused.positions_world.push(point.position_world);
        fused.colors.push(point.color);
        fused.support.push(views.len() as u32);
        fused.views.push(views);
        fused.thin_organ.push(false);
    }
    let workspace = tempfile::tempdir().unwrap();
    let dense = write_workspace(
        &scene,
        &fused,
        &DensifyReport::default(),
        &DensifyOptions::default(),
        workspace.path(),
    )
    .unwrap();
    let rows = assert_rows_join(workspace.path(), &dense);
    assert_eq!(rows, dense.points().len());
    // The rows are the dense points, not the sparse model's: ids 1..n of the workspace.
    assert!(rows > 1000);
}
