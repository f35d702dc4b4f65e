//! The GUI starts where the user starts: a folder of photos (no COLMAP model) opens through
//! the library's pipeline (COLMAP structure from motion, semi-dense stereo, segmentation) on a
//! worker thread, showing each stage, and reaches the editing workspace. Needs COLMAP (installed
//! by scripts/setup.sh; on CI its absence is a failure).

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;
use frond_ui::FrondApp;
use frond_ui::files::ConfigDir;
use frond_ui::workspace::work_folder;

fn colmap_available() -> bool {
    let found = Command::new("colmap").arg("help").output().is_ok();
    if !found && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("colmap is not on PATH on CI: scripts/setup.sh should have installed it");
    }
    found
}

/// Photos of a synthetic broadleaf plant, alone in a folder: 20 views of 480×360 (with COLMAP's
/// exhaustive matching, fewer or smaller photos registered none; Frond's structure from motion
/// takes about 10 s on them).
fn write_photos(dir: &Path) -> std::path::PathBuf {
    let dataset = dir.join("dataset");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 43,
        views: 20,
        width: 480,
        height: 360,
        with_points: false,
        ..SynthOptions::default()
    };
    write_dataset(&options, &dataset, &NoProgress).unwrap();
    let photos = dir.join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    for entry in std::fs::read_dir(dataset.join("images")).unwrap().flatten() {
        std::fs::copy(entry.path(), photos.join(entry.file_name())).unwrap();
    }
    photos
}

#[test]
fn a_folder_of_photos_opens_into_the_editing_workspace() {
    if !colmap_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let photos = write_photos(dir.path());
    let config = ConfigDir {
        dir: dir.path().join("config"),
    };
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1400.0, 900.0))
        .build_ui_state(
            |ui, app: &mut FrondApp| app.window_ui(ui),
            FrondApp::with_config(Some(photos.clone()), Some(config)),
        );
    // Step until the work ends, noting the stages the progress card showed.
    let deadline = Instant::now() + Duration::from_secs(600);
    let mut seen_sfm = false;
    let mut seen_stereo = false;
    let mut seen_segmentation = false;
    loop {
        harness.step();
        seen_sfm |= harness
            .query_all_by_label_contains("structure from motion")
            .next()
            .is_some();
        seen_stereo |= harness
            .query_all_by_label_contains("stereo matching")
            .next()
            .is_some();
        seen_segmentation |= harness
            .query_all_by_label_contains("normalized cut")
            .next()
            .is_some()
            || harness
                .query_all_by_label_contains("foreground")
                .next()
                .is_some();
        let app = harness.state();
        if !app.is_busy() && app.panel.is_idle() {
            break;
        }
        assert!(Instant::now() < deadline, "still opening after 600 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    harness.step();
    let app = harness.state();
    let workspace = app
        .workspace()
        .unwrap_or_else(|| panic!("no workspace: {:?} {:?}", app.error(), app.status()));
    assert!(seen_sfm, "the progress never showed structure from motion");
    assert!(seen_stereo, "the progress never showed the stereo matching");
    assert!(
        seen_segmentation,
        "the progress never showed the segmentation"
    );
    // The pipeline ran on the photos: SfM and dense points in the work folder beside them.
    let preparation = workspace.preparation.as_ref().expect("a preparation");
    assert!(preparation.sfm, "{preparation:?}");
    let work = work_folder(&photos);
    assert!(work.join("sfm/sparse/0").is_dir());
    assert!(work.join("dense/fused.ply").is_file());
    // The editing workspace: leaf segments to edit and the tools to edit them with.
    let leaves = workspace.segment_counts().0;
    assert!(leaves >= 5, "{leaves} leaf segments");
    assert!(
        harness
            .query_all_by_label_contains("leaf segments")
            .next()
            .is_some()
    );
}
