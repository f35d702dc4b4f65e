//! `frond sfm` and `frond densify` end to end with the installed COLMAP: a small synthetic
//! broadleaf rendered without points goes through COLMAP on the CPU (about a minute on 2
//! cores), its undistorted workspace is densified, and the dense points are scored against the
//! true surface after a similarity alignment by the camera centres.

mod common;

use frond::eval::GroundTruth;
use frond::eval::align_to_ground_truth;
use frond::eval::dense::point_accuracy;
use frond::mvs::{DensifyOptions, densify, write_workspace};
use frond::scene::Scene;
use frond::sfm::{SfmOptions, run_sfm};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

#[test]
fn colmap_then_densify_recovers_the_plant_surface() {
    if !common::colmap_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let dataset = dir.path().join("dataset");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 3,
        views: 24,
        width: 640,
        height: 480,
        with_points: false,
        ..SynthOptions::default()
    };
    write_dataset(&options, &dataset, &NoProgress).unwrap();
    let out = dir.path().join("sfm");
    // One thread: COLMAP's multithreaded matching and mapping are not reproducible, and a
    // test must see the same model on every run.
    let sfm_options = SfmOptions {
        threads: 1,
        ..SfmOptions::default()
    };
    let report = run_sfm(&dataset.join("images"), &out, &sfm_options, &NoProgress).unwrap();
    eprintln!("{report:?}");
    assert_eq!(report.photos, 24);
    assert!(report.registered >= 20, "{report:?}");
    assert!(out.join("sparse/0/points3D.bin").is_file());
    assert!(out.join("sfm.json").is_file());
    assert!(out.join("colmap.log").is_file());

    // The undistorted workspace densifies; its points lie on the true surface.
    let scene = Scene::open(&out.join("dense")).unwrap();
    assert_eq!(scene.reconstruction.images().len(), report.registered);
    let options = DensifyOptions::default();
    let (fused, dense_report) = densify(&scene, &options, &NoProgress).unwrap();
    eprintln!("{dense_report:?}");
    // COLMAP itself reads the dense workspace's model, tracks and all.
    let workspace = dir.path().join("dense");
    let dense = write_workspace(&scene, &fused, &dense_report, &options, &workspace).unwrap();
    let stats = common::analyze(&workspace.join("sparse"));
    assert_eq!(stats["Points"] as usize, dense.points().len());
    assert_eq!(stats["Registered images"] as usize, report.registered);
    let (similarity, alignment) =
        align_to_ground_truth(&dataset, &out.join("dense/sparse")).unwrap();
    assert!(alignment.rms_camera_residual < 0.005, "{alignment:?}");
    let aligned: Vec<_> = fused
        .positions_world
        .iter()
        .map(|p| similarity.apply(p))
        .collect();
    let truth = GroundTruth::load(&dataset).unwrap();
    let accuracy = point_accuracy(&truth, &aligned, 0.02).unwrap();
    eprintln!("{accuracy:?}");
    assert!(accuracy.plant_points >= 10_000, "{accuracy:?}");
    assert!(
        accuracy.median_error_fraction_of_height <= 0.005,
        "{accuracy:?}"
    );
}
