//! Scale from a printed checkerboard in the photos: a synthetic plant with a board of known
//! squares beside its pot, in a metric world, must come out at 1 metre per model unit.

use frond::scene::Scene;
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::traits::marker::checkerboard_scale;
use frond::util::progress::NoProgress;

fn dataset(dir: &std::path::Path, checkerboard: Option<f64>) -> std::path::PathBuf {
    let out = dir.join("plant");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 4,
        views: 24,
        width: 640,
        height: 480,
        target_points: 5_000,
        checkerboard,
        ..SynthOptions::default()
    };
    write_dataset(&options, &out, &NoProgress).unwrap();
    out
}

#[test]
fn a_checkerboard_in_the_photos_gives_the_metric_scale() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::open(&dataset(dir.path(), Some(0.03))).unwrap();
    let (scale, report) = checkerboard_scale(&scene, (8, 6), 0.03).unwrap();
    eprintln!("{report:?}");
    assert!(report.views.len() >= 2, "{report:?}");
    assert!((scale.metres_per_unit - 1.0).abs() < 0.002, "{scale:?}");
    assert!(scale.source.contains("checkerboard"), "{scale:?}");
    // The wrong board (other corner counts) is not found, and says so.
    let err = checkerboard_scale(&scene, (7, 5), 0.03)
        .unwrap_err()
        .to_string();
    assert!(err.contains("found whole in 0 of 24 photos"), "{err}");
    let err = checkerboard_scale(&scene, (1, 5), 0.03)
        .unwrap_err()
        .to_string();
    assert!(err.contains("at least 2×2"), "{err}");
}

#[test]
fn no_checkerboard_no_scale_and_the_truth_measured_in_metres() {
    let dir = tempfile::tempdir().unwrap();
    let plant = dataset(dir.path(), None);
    let scene = Scene::open(&plant).unwrap();
    let err = checkerboard_scale(&scene, (8, 6), 0.02)
        .unwrap_err()
        .to_string();
    assert!(err.contains("found whole in 0 of 24 photos"), "{err}");
}
