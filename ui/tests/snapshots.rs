//! Snapshot tests of the main screens, rendered with wgpu (lavapipe on machines without a GPU)
//! and compared with the images in `tests/snapshots/` (`UPDATE_SNAPSHOTS=1` rewrites them after
//! an intended change; look at the new images before committing them).

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use egui_kittest::Harness;
use frond_ui::FrondApp;
use frond_ui::files::ConfigDir;

fn harness(path: Option<PathBuf>, config: &Path) -> Harness<'static, FrondApp> {
    let mut app = FrondApp::with_config(
        path,
        Some(ConfigDir {
            dir: config.to_path_buf(),
        }),
    );
    // Timings differ from run to run.
    app.show_frame_time = false;
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut FrondApp| app.window_ui(ui), app);
    let deadline = Instant::now() + Duration::from_secs(300);
    loop {
        harness.step();
        if !harness.state().is_busy() && harness.state().panel.is_idle() {
            break;
        }
        assert!(Instant::now() < deadline, "the GUI stayed busy for 300 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    harness.state_mut().clear_status();
    harness.run_steps(3);
    harness
}

#[test]
fn the_welcome_screen_and_the_shortcuts_match_their_snapshots() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness(None, config.path());
    harness.snapshot("welcome");
    harness.state_mut().show_help = true;
    harness.run_steps(3);
    harness.snapshot("shortcuts");
}

#[test]
fn the_editing_workspace_matches_its_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let root = common::write_synthetic_plant(dir.path());
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness(Some(root), config.path());
    assert!(harness.state().workspace().is_some());
    harness.snapshot("workspace");
}
