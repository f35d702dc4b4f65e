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
    // The 3D panel draws through the render core in the same device as the snapshots.
    let render_state = egui_kittest::wgpu::create_render_state(
        egui_kittest::wgpu::default_wgpu_setup(),
        eframe::egui_wgpu::RendererOptions::PREDICTABLE,
    );
    app.install_gpu(&render_state);
    assert!(app.error().is_none() && app.status().is_none_or(|s| !s.is_error));
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .renderer(egui_kittest::wgpu::WgpuTestRenderer::from_render_state(
            render_state,
        ))
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

#[test]
fn the_3d_panel_renders_the_plant_through_the_render_core() {
    let dir = tempfile::tempdir().unwrap();
    let root = common::write_synthetic_plant(dir.path());
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness(Some(root), config.path());
    harness.state_mut().layout = frond_ui::CentralLayout::ThreeD;
    harness.run_steps(3);
    let rect = harness
        .state()
        .view3d
        .rect
        .expect("the 3D panel was laid out");
    let image = harness.render().expect("rendered");
    let ppp = harness.ctx.pixels_per_point();
    // Inside the panel (away from its caption): the background and the plant's colours.
    let (x0, x1) = ((rect.min.x * ppp) as u32, (rect.max.x * ppp) as u32);
    let (y0, y1) = (
        (rect.min.y * ppp) as u32,
        ((rect.max.y - 30.0) * ppp) as u32,
    );
    let background = *image.get_pixel(x0 + 2, y0 + 2);
    let mut plant = 0usize;
    let mut colours = std::collections::HashSet::new();
    for y in y0..y1 {
        for x in x0..x1 {
            let p = image.get_pixel(x, y);
            if p.0
                .iter()
                .zip(background.0)
                .any(|(a, b)| a.abs_diff(b) > 40)
            {
                plant += 1;
                colours.insert([p[0] / 32, p[1] / 32, p[2] / 32]);
            }
        }
    }
    let area = ((x1 - x0) * (y1 - y0)) as usize;
    eprintln!(
        "3D panel {}x{}: {plant} pixels differ from the background ({:.1} %), {} colour bins",
        x1 - x0,
        y1 - y0,
        100.0 * plant as f64 / area as f64,
        colours.len()
    );
    // The plant covers a visible part of the panel in several segment colours (without the
    // renderer the panel shows one grey line of text).
    assert!(plant > area / 100, "{plant} of {area}");
    assert!(colours.len() >= 8, "{}", colours.len());
    harness.snapshot("workspace_3d");
}
