//! Headless interaction tests of the GUI (egui_kittest): open the bundled fixture and check
//! that cameras and images are listed; open a bad folder and check the error is shown.

use std::path::{Path, PathBuf};
use std::time::Duration;

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use frond_ui::FrondApp;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(name)
}

fn harness(path: PathBuf) -> Harness<'static, FrondApp> {
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1200.0, 800.0))
        .build_ui_state(
            |ui, app: &mut FrondApp| app.window_ui(ui),
            FrondApp::new(Some(path)),
        );
    for _ in 0..500 {
        harness.step();
        if !harness.state().is_loading() {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    harness.step();
    harness.step();
    harness
}

#[test]
fn opening_a_colmap_folder_lists_cameras_and_images() {
    let harness = harness(fixture("toy_scene"));
    let loaded = harness.state().loaded().expect("fixture loads");
    assert_eq!(loaded.scene.reconstruction.images().len(), 8);
    harness.get_by_label_contains("Camera 1 · SIMPLE_RADIAL · 240×180");
    harness.get_by_label_contains("Images (8 registered, 8 files present)");
    harness.get_by_label("view_0000.png");
    harness.get_by_label_contains("1500 points");
}

#[test]
fn opening_a_folder_without_a_model_shows_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let harness = harness(dir.path().to_path_buf());
    let error = harness.state().error().expect("load fails").to_owned();
    assert!(error.contains("no COLMAP model found"), "{error}");
    harness.get_by_label("Could not open the scene");
}
