//! The photos-to-plant round trip (issue targets): a synthetic broadleaf rendered without
//! points goes through real COLMAP, `frond densify` and `frond reconstruct`, and is scored
//! against the truth after a similarity alignment by the camera centres.
//!
//! Slow (COLMAP exhaustive matching of 36 photos takes minutes on 2 cores), so ignored by
//! default: `scripts/roundtrip.sh` runs the chain and then this test on its output
//! (`FROND_ROUNDTRIP=<dir with dataset/ and run/>`); without that variable the test runs the
//! chain itself in a temporary folder.

mod common;

use std::path::{Path, PathBuf};

use assert_cmd::Command;
use frond::eval::dense::point_accuracy;
use frond::eval::{EvalOptions, GroundTruth, Prediction, align_to_ground_truth, evaluate};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

fn run_chain(root: &Path) {
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 2,
        with_points: false,
        ..SynthOptions::default()
    };
    write_dataset(&options, &root.join("dataset"), &NoProgress).unwrap();
    Command::cargo_bin("frond")
        .unwrap()
        .arg("reconstruct")
        .arg(root.join("dataset/images"))
        .arg("--out")
        .arg(root.join("run"))
        .assert()
        .success();
}

/// The folder holding `dataset/` and `run/`: `FROND_ROUNDTRIP` when set (scripts/roundtrip.sh),
/// else the chain run now in `temp`.
fn round_trip_root(temp: &Path) -> PathBuf {
    match std::env::var_os("FROND_ROUNDTRIP") {
        Some(dir) => PathBuf::from(dir),
        None => {
            run_chain(temp);
            temp.to_path_buf()
        }
    }
}

#[test]
#[ignore = "slow: COLMAP on 36 photos; run scripts/roundtrip.sh"]
fn photos_to_plant_round_trip_meets_the_targets() {
    if !common::colmap_available() {
        return;
    }
    let temp = tempfile::tempdir().unwrap();
    let root = round_trip_root(temp.path());
    let (dataset, run) = (root.join("dataset"), root.join("run"));
    let truth = GroundTruth::load(&dataset).unwrap();

    // Dense points: ≥ 30k on the plant, median error ≤ 0.5 % of the plant height.
    let dense = frond::scene::Scene::open(&run.join("dense")).unwrap();
    let (similarity, alignment) =
        align_to_ground_truth(&dataset, &run.join("dense/sparse")).unwrap();
    let points: Vec<_> = dense
        .dense
        .as_ref()
        .expect("fused.ply")
        .positions_world
        .iter()
        .map(|p| similarity.apply(&p.cast()))
        .collect();
    let accuracy = point_accuracy(&truth, &points, 0.02).unwrap();
    eprintln!("alignment {alignment:?}\ndense {accuracy:?}");
    assert!(accuracy.plant_points >= 30_000, "{accuracy:?}");
    assert!(
        accuracy.median_error_fraction_of_height <= 0.005,
        "{accuracy:?}"
    );

    // Leaves: recall ≥ 0.85, median Chamfer ≤ 4 % of the leaf length.
    let mut prediction = Prediction::load(&run).unwrap();
    prediction.transform(&similarity);
    let report = evaluate(
        &truth,
        &prediction,
        Some(alignment),
        &EvalOptions::default(),
    )
    .unwrap();
    eprintln!("{}", report.to_text());
    assert!(report.leaves.recall >= 0.85, "{:?}", report.leaves);
    let chamfer = report.chamfer_relative.median.expect("matched leaves");
    assert!(chamfer <= 0.04, "median Chamfer {chamfer}");
}

/// Leaf recall of a run against the truth, aligned by the camera centres of its dense model.
fn leaf_recall(dataset: &Path, run: &Path) -> f64 {
    let truth = GroundTruth::load(dataset).unwrap();
    let (similarity, alignment) =
        align_to_ground_truth(dataset, &run.join("dense/sparse")).unwrap();
    let mut prediction = Prediction::load(run).unwrap();
    prediction.transform(&similarity);
    let report = evaluate(
        &truth,
        &prediction,
        Some(alignment),
        &EvalOptions::default(),
    )
    .unwrap();
    report.leaves.recall
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap().flatten() {
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

#[test]
#[ignore = "slow: COLMAP on 36 photos; run scripts/roundtrip.sh"]
fn a_sparse_colmap_project_with_its_photos_is_densified_to_the_same_recall() {
    if !common::colmap_available() {
        return;
    }
    let temp = tempfile::tempdir().unwrap();
    let root = round_trip_root(temp.path());
    let (dataset, run) = (root.join("dataset"), root.join("run"));
    // The sparse COLMAP project the photos gave: sparse/0 beside the photos.
    let project = temp.path().join("sparse_project");
    copy_dir(&run.join("sfm/sparse/0"), &project.join("sparse/0"));
    copy_dir(&dataset.join("images"), &project.join("images"));
    let from_project = temp.path().join("run_sparse");
    Command::cargo_bin("frond")
        .unwrap()
        .arg("reconstruct")
        .arg(&project)
        .arg("--out")
        .arg(&from_project)
        .assert()
        .success();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(from_project.join("report.json")).unwrap()).unwrap();
    let preparation = &report["preparation"];
    eprintln!("{preparation}");
    assert_eq!(preparation["densified"], true, "{preparation}");
    assert!(
        preparation["density"]["spacing_footprints"]
            .as_f64()
            .unwrap()
            > 6.0,
        "{preparation}"
    );
    let (photos, sparse) = (
        leaf_recall(&dataset, &run),
        leaf_recall(&dataset, &from_project),
    );
    eprintln!("leaf recall: from the photos {photos:.3}, from the sparse project {sparse:.3}");
    assert!((photos - sparse).abs() <= 0.05, "{photos} vs {sparse}");
}
