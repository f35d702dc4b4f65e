//! Headless interaction tests of the GUI (egui_kittest) on a synthetic plant: each tool is
//! used through pointer and keyboard events on the image panel, and the library Session's state
//! is checked; saving, autosave recovery, fitting, cancelling and export go through the menus
//! and dialogs.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use egui::{Event, Key, Modifiers, PointerButton, Pos2};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use frond::edit::{Project, Session};
use frond::render::ViewCamera;
use frond::segment::SegmentLabel;
use frond_ui::FrondApp;
use frond_ui::files::ConfigDir;
use frond_ui::tools::Tool;
use nalgebra::Point3;
use tempfile::TempDir;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures")
        .join(name)
}

/// A small synthetic broadleaf plant with its photos (written once per test binary).
fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let root = common::write_synthetic_plant(dir.path());
        (dir, root)
    })
    .1
}

/// The branch a draw added (one more than `before`, with a parent).
fn drawn_branch(harness: &Harness<'static, FrondApp>, before: usize) -> frond::branch::Branch {
    let tree = session(harness).branches();
    assert_eq!(
        tree.branches.len(),
        before + 1,
        "{:?}",
        harness.state().status()
    );
    let drawn = tree.branches.last().unwrap().clone();
    assert!(drawn.parent.is_some());
    drawn
}

fn harness_with(path: PathBuf, config: &Path) -> Harness<'static, FrondApp> {
    let config = ConfigDir {
        dir: config.to_path_buf(),
    };
    let mut harness = Harness::builder()
        .with_size(egui::vec2(1400.0, 900.0))
        .build_ui_state(
            |ui, app: &mut FrondApp| app.window_ui(ui),
            FrondApp::with_config(Some(path), Some(config)),
        );
    settle(&mut harness);
    harness
}

/// Steps until no work runs and every photo has been decoded.
fn settle(harness: &mut Harness<'static, FrondApp>) {
    let deadline = Instant::now() + Duration::from_secs(300);
    loop {
        harness.step();
        let app = harness.state();
        if !app.is_busy() && app.panel.is_idle() {
            break;
        }
        assert!(Instant::now() < deadline, "the GUI stayed busy for 300 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    harness.step();
    harness.step();
}

fn session<'h>(harness: &'h Harness<'static, FrondApp>) -> &'h Session {
    &harness
        .state()
        .workspace()
        .expect("a workspace is open")
        .session
}

fn screen(harness: &Harness<'static, FrondApp>, uv: [f64; 2]) -> Pos2 {
    harness
        .state()
        .panel
        .transform
        .expect("the image panel was drawn")
        .screen_from_image(uv)
}

fn press(harness: &mut Harness<'static, FrondApp>, pos: Pos2, pressed: bool) {
    harness.event(Event::PointerButton {
        pos,
        button: PointerButton::Primary,
        pressed,
        modifiers: Modifiers::NONE,
    });
    harness.step();
}

fn click(harness: &mut Harness<'static, FrondApp>, uv: [f64; 2]) {
    let pos = screen(harness, uv);
    click_screen(harness, pos);
}

fn click_screen(harness: &mut Harness<'static, FrondApp>, pos: Pos2) {
    harness.hover_at(pos);
    harness.step();
    press(harness, pos, true);
    press(harness, pos, false);
    harness.step();
}

/// A primary-button drag through image pixels of the photo panel.
fn drag(harness: &mut Harness<'static, FrondApp>, stroke: &[[f64; 2]]) {
    let points: Vec<Pos2> = stroke.iter().map(|&uv| screen(harness, uv)).collect();
    drag_screen(harness, &points);
}

/// A primary-button drag through screen points.
fn drag_screen(harness: &mut Harness<'static, FrondApp>, points: &[Pos2]) {
    harness.hover_at(points[0]);
    harness.step();
    press(harness, points[0], true);
    for &p in &points[1..] {
        harness.hover_at(p);
        harness.step();
    }
    press(harness, points[points.len() - 1], false);
    harness.step();
}

fn key(harness: &mut Harness<'static, FrondApp>, key: Key) {
    harness.key_press(key);
    harness.step();
    harness.step();
}

fn shortcut(harness: &mut Harness<'static, FrondApp>, modifiers: Modifiers, key: Key) {
    harness.key_press_modifiers(modifiers, key);
    harness.step();
    harness.step();
}

fn project(session: &Session, view: usize, p: &Point3<f64>) -> [f64; 2] {
    let model = &session.scene().reconstruction;
    let uv = model.project(&model.images()[view], p).unwrap();
    [uv.x, uv.y]
}

/// Leaf segments seen in view 0, largest first, each with its points' pixels there.
fn leaves_in_view(session: &Session) -> Vec<(u32, Vec<[f64; 2]>)> {
    let points = &session.segmentation().points;
    let mut leaves: Vec<(u32, Vec<[f64; 2]>)> = session
        .leaf_ids()
        .iter()
        .copied()
        .filter(|&id| id >= 0)
        .collect::<std::collections::BTreeSet<i64>>()
        .into_iter()
        .map(|id| {
            let pixels = session
                .members(id as u32)
                .into_iter()
                .filter(|&p| points.views[p as usize].binary_search(&0).is_ok())
                .map(|p| project(session, 0, &points.positions[p as usize]))
                .collect();
            (id as u32, pixels)
        })
        .collect();
    leaves.sort_by_key(|(_, pixels)| std::cmp::Reverse(pixels.len()));
    leaves
}

/// The pixel of a leaf's point nearest its projected centroid.
fn central_pixel(pixels: &[[f64; 2]]) -> [f64; 2] {
    let n = pixels.len() as f64;
    let c = pixels
        .iter()
        .fold([0.0, 0.0], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    *pixels
        .iter()
        .min_by(|a, b| {
            let da = (a[0] - c[0]).hypot(a[1] - c[1]);
            let db = (b[0] - c[0]).hypot(b[1] - c[1]);
            da.total_cmp(&db)
        })
        .unwrap()
}

fn segment_at(session: &Session, view: usize, uv: [f64; 2]) -> u32 {
    let image_id = session.scene().reconstruction.images()[view].id;
    session
        .pick_segment(&frond::edit::PixelRef {
            image_id,
            pixel: uv,
        })
        .unwrap()
}

fn history_len(harness: &Harness<'static, FrondApp>) -> (usize, usize) {
    let (history, position) = session(harness).history();
    (history.len(), position)
}

#[test]
fn segment_tools_edit_the_session_with_undo_and_redo() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    let leaves = leaves_in_view(session(&harness));
    assert!(leaves.len() >= 4, "{} leaves in view 0", leaves.len());
    let a = central_pixel(&leaves[0].1);
    let b = central_pixel(&leaves[1].1);
    let c = central_pixel(&leaves[2].1);
    let segment_a = segment_at(session(&harness), 0, a);
    let segment_b = segment_at(session(&harness), 0, b);
    assert_ne!(segment_a, segment_b);

    // Confirm (the default tool): one click.
    assert_eq!(harness.state().tool, Tool::Confirm);
    click(&mut harness, a);
    let state = session(&harness).segments()[segment_a as usize].unwrap();
    assert!(state.confirmed, "{:?}", harness.state().status());
    assert!(session(&harness).boundary(segment_a, 0).is_some());

    // Merge: two clicks.
    key(&mut harness, Key::M);
    assert_eq!(harness.state().tool, Tool::Merge);
    click(&mut harness, a);
    click(&mut harness, b);
    assert_eq!(
        segment_at(session(&harness), 0, a),
        segment_at(session(&harness), 0, b),
        "{:?}",
        harness.state().status()
    );
    assert_eq!(history_len(&harness), (2, 2));

    // Undo and redo from the keyboard.
    shortcut(&mut harness, Modifiers::COMMAND, Key::Z);
    assert_eq!(history_len(&harness), (2, 1));
    assert_ne!(
        segment_at(session(&harness), 0, a),
        segment_at(session(&harness), 0, b)
    );
    shortcut(&mut harness, Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
    assert_eq!(history_len(&harness), (2, 2));
    shortcut(&mut harness, Modifiers::COMMAND, Key::Z);

    // Split: a stroke across leaf A through its centre, across its narrow extent.
    key(&mut harness, Key::S);
    let pixels = &leaves[0].1;
    let (min_y, max_y) = pixels.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    });
    let (min_x, max_x) = pixels.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[0]), hi.max(p[0]))
    });
    let stroke: Vec<[f64; 2]> = if max_x - min_x >= max_y - min_y {
        // Wide leaf: a vertical stroke.
        (0..=12)
            .map(|k| {
                [
                    a[0],
                    min_y - 15.0 + (max_y - min_y + 30.0) * k as f64 / 12.0,
                ]
            })
            .collect()
    } else {
        (0..=12)
            .map(|k| {
                [
                    min_x - 15.0 + (max_x - min_x + 30.0) * k as f64 / 12.0,
                    a[1],
                ]
            })
            .collect()
    };
    drag(&mut harness, &stroke);
    assert_eq!(
        history_len(&harness),
        (2, 2),
        "{:?}",
        harness.state().status()
    );
    let after: std::collections::BTreeSet<u32> = pixels
        .iter()
        .filter_map(|&uv| {
            let image_id = session(&harness).scene().reconstruction.images()[0].id;
            session(&harness)
                .pick_segment(&frond::edit::PixelRef {
                    image_id,
                    pixel: uv,
                })
                .ok()
        })
        .collect();
    assert!(after.len() >= 2, "leaf A is still one segment: {after:?}");

    // Mark non-leaf, mark leaf, reset.
    key(&mut harness, Key::N);
    click(&mut harness, c);
    let segment_c = segment_at(session(&harness), 0, c);
    assert_eq!(
        session(&harness).segments()[segment_c as usize]
            .unwrap()
            .label,
        SegmentLabel::Stem
    );
    key(&mut harness, Key::L);
    click(&mut harness, c);
    assert_eq!(
        session(&harness).segments()[segment_c as usize]
            .unwrap()
            .label,
        SegmentLabel::Leaf
    );
    key(&mut harness, Key::X);
    click(&mut harness, c);
    assert_eq!(history_len(&harness), (5, 5));

    // Generic leaf: a setting for the next fit, not an edit.
    key(&mut harness, Key::G);
    click(&mut harness, b);
    let pick = harness.state().workspace().unwrap().generic_leaf.unwrap();
    assert_eq!(pick.segment, segment_at(session(&harness), 0, b));
    assert_eq!(pick.view, Some(0));
    assert_eq!(history_len(&harness), (5, 5));

    // The history panel lists the edits; clicking the first row goes back to it.
    harness.get_by_label("History").click();
    harness.step();
    harness.step();
    harness.get_by_label_contains("5 of 5 edits applied");
    harness.get_by_label_contains("1  confirm segment").click();
    harness.step();
    harness.step();
    assert_eq!(history_len(&harness), (5, 1));
    harness
        .get_by_label_contains("Automatic segmentation")
        .click();
    harness.step();
    assert_eq!(history_len(&harness), (5, 0));
    assert!(
        !session(&harness).segments()[segment_a as usize]
            .unwrap()
            .confirmed
    );
}

/// The main stem's skeleton pixel at arc-length fraction `s` in view 0.
fn branch_pixel(session: &Session, branch: u32, s: f64) -> [f64; 2] {
    let branch = session.branches().get(branch).unwrap();
    project(session, 0, &branch.cylinder.skeleton.point_at_fraction(s))
}

/// Leaf at tip (T), then delete (D), each by a click at `pos` on the branch.
fn tip_leaf_then_delete(harness: &mut Harness<'static, FrondApp>, branch: u32, pos: Pos2) {
    key(harness, Key::T);
    click_screen(harness, pos);
    assert!(
        session(harness).branches().get(branch).unwrap().leaf_at_tip,
        "{:?}",
        harness.state().status()
    );
    key(harness, Key::D);
    click_screen(harness, pos);
    assert!(
        session(harness).branches().get(branch).is_none(),
        "{:?}",
        harness.state().status()
    );
}

#[test]
fn branch_tools_edit_the_branch_tree_with_undo() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    let before = session(&harness).branches().branches.len();
    assert!(before >= 1, "the automatic skeleton found no stem");
    let stem = session(&harness).branches().branches[0].id;

    // Draw a branch from the stem's middle, out to the side.
    key(&mut harness, Key::B);
    let start = branch_pixel(session(&harness), stem, 0.5);
    let stroke: Vec<[f64; 2]> = (0..=10)
        .map(|k| [start[0] + 6.0 * k as f64, start[1] - 2.0 * k as f64])
        .collect();
    drag(&mut harness, &stroke);
    let drawn = drawn_branch(&harness, before);

    // Move its last control point 25 px down.
    key(&mut harness, Key::V);
    let last = drawn.cylinder.skeleton.control_points().len() - 1;
    let tip = project(
        session(&harness),
        0,
        &drawn.cylinder.skeleton.control_points()[last],
    );
    drag(
        &mut harness,
        &[
            tip,
            [tip[0], tip[1] + 8.0],
            [tip[0], tip[1] + 16.0],
            [tip[0], tip[1] + 25.0],
        ],
    );
    let moved = session(&harness).branches().get(drawn.id).unwrap().clone();
    let moved_tip = project(
        session(&harness),
        0,
        &moved.cylinder.skeleton.control_points()[last],
    );
    assert!(
        (moved_tip[1] - (tip[1] + 25.0)).abs() < 3.0 && (moved_tip[0] - tip[0]).abs() < 3.0,
        "tip {tip:?} moved to {moved_tip:?}: {:?}",
        harness.state().status()
    );

    // Drag the end's radius out to 16 px.
    key(&mut harness, Key::R);
    let radius_stroke: Vec<[f64; 2]> = (0..=4)
        .map(|k| [moved_tip[0] + 4.0 * k as f64, moved_tip[1]])
        .collect();
    drag(&mut harness, &radius_stroke);
    let widened = session(&harness).branches().get(drawn.id).unwrap().clone();
    assert_ne!(
        widened.cylinder.radius_end,
        moved.cylinder.radius_end,
        "{:?}",
        harness.state().status()
    );
    assert!(widened.cylinder.radius_end > 0.0);

    // Leaf at tip, then delete, by clicking near the branch's outer part.
    let on_branch = screen(&harness, branch_pixel(session(&harness), drawn.id, 0.85));
    tip_leaf_then_delete(&mut harness, drawn.id, on_branch);
    assert_eq!(session(&harness).branches().branches.len(), before);
    assert_eq!(history_len(&harness), (5, 5));

    shortcut(&mut harness, Modifiers::COMMAND, Key::Z);
    assert!(session(&harness).branches().get(drawn.id).is_some());
}

/// The 3D view's camera as the app draws it now, its rectangle and points per pixel.
fn view_camera(harness: &Harness<'static, FrondApp>) -> (ViewCamera, egui::Rect, f32) {
    let app = harness.state();
    let orbit = app.view3d.orbit.expect("the 3D view framed the plant");
    let rect = app.view3d.rect.expect("the 3D view was drawn");
    let ppp = harness.ctx.pixels_per_point();
    let camera = orbit.view_camera(
        (rect.width() * ppp).round() as u32,
        (rect.height() * ppp).round() as u32,
    );
    (camera, rect, ppp)
}

/// Where a world point appears on the screen in the 3D view.
fn screen_point(camera: &ViewCamera, rect: egui::Rect, ppp: f32, p: &Point3<f64>) -> Pos2 {
    let (uv, _) = camera.project(p).unwrap();
    rect.min + egui::vec2(uv.x as f32, uv.y as f32) / ppp
}

#[test]
fn branches_are_drawn_and_moved_in_the_3d_view() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    harness.state_mut().layout = frond_ui::CentralLayout::ThreeD;
    harness.run_steps(3);
    let before = session(&harness).branches().branches.len();
    let stem = session(&harness).branches().branches[0].clone();
    // The tools' panels change the 3D view's size, and with it the camera: each step projects
    // with the view as it is once its tool is on.
    key(&mut harness, Key::B);
    let (camera, rect, ppp) = view_camera(&harness);
    let screen_of = |p: &Point3<f64>| screen_point(&camera, rect, ppp, p);

    // Draw from the stem's middle out to the side.
    let start = screen_of(&stem.cylinder.skeleton.point_at_fraction(0.5));
    let stroke: Vec<Pos2> = (0..=10)
        .map(|k| start + egui::vec2(5.0 * k as f32, -2.0 * k as f32))
        .collect();
    drag_screen(&mut harness, &stroke);
    let drawn = drawn_branch(&harness, before);
    assert_eq!(history_len(&harness), (1, 1));

    // Move its last control point 20 points down in the view.
    key(&mut harness, Key::V);
    let (camera, rect, ppp) = view_camera(&harness);
    let screen_of = |p: &Point3<f64>| screen_point(&camera, rect, ppp, p);
    let last = drawn.cylinder.skeleton.control_points().len() - 1;
    let tip = screen_of(&drawn.cylinder.skeleton.control_points()[last]);
    let target = tip + egui::vec2(0.0, 20.0);
    drag_screen(&mut harness, &[tip, tip + egui::vec2(0.0, 8.0), target]);
    let moved = session(&harness).branches().get(drawn.id).unwrap().clone();
    let moved_tip = screen_of(&moved.cylinder.skeleton.control_points()[last]);
    assert!(
        (moved_tip - target).length() < 2.0,
        "tip {tip:?} went to {moved_tip:?}, not {target:?}: {:?}",
        harness.state().status()
    );
    assert_eq!(history_len(&harness), (2, 2));

    // Drag the tip's radius out to 12 points from its centre.
    key(&mut harness, Key::R);
    let (camera, rect, ppp) = view_camera(&harness);
    let screen_of = |p: &Point3<f64>| screen_point(&camera, rect, ppp, p);
    let moved_tip = screen_of(&moved.cylinder.skeleton.control_points()[last]);
    let (_, depth) = camera
        .project(&moved.cylinder.skeleton.control_points()[last])
        .unwrap();
    drag_screen(
        &mut harness,
        &[
            moved_tip,
            moved_tip + egui::vec2(6.0, 0.0),
            moved_tip + egui::vec2(12.0, 0.0),
        ],
    );
    let widened = session(&harness).branches().get(drawn.id).unwrap().clone();
    let expected = 12.0 * ppp as f64 * depth / camera.fx;
    assert!(
        (widened.cylinder.radius_end - expected).abs() < 0.02 * expected,
        "radius {} instead of {expected}: {:?}",
        widened.cylinder.radius_end,
        harness.state().status()
    );
    assert_eq!(widened.cylinder.radius_start, moved.cylinder.radius_start);

    // Leaf at tip, then delete, by clicking the branch's outer part in the view.
    let on_branch = screen_of(&widened.cylinder.skeleton.point_at_fraction(0.8));
    tip_leaf_then_delete(&mut harness, drawn.id, on_branch);
    assert_eq!(history_len(&harness), (5, 5));
    // A click on nothing says so and changes nothing.
    click_screen(&mut harness, rect.left_top() + egui::vec2(3.0, 3.0));
    assert_eq!(history_len(&harness), (5, 5));
    assert!(
        harness
            .state()
            .status()
            .is_some_and(|s| s.text.contains("no branch")),
        "{:?}",
        harness.state().status()
    );
}

#[test]
fn saving_autosave_and_crash_recovery_keep_the_edits() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    let leaves = leaves_in_view(session(&harness));
    click(&mut harness, central_pixel(&leaves[0].1));
    assert_eq!(history_len(&harness), (1, 1));
    assert!(harness.state().workspace().unwrap().is_dirty());
    harness.get_by_label("• unsaved");

    // Autosave, then "crash" (drop the window without saving).
    harness.state_mut().autosave_interval = Duration::ZERO;
    harness.step();
    let autosave = ConfigDir {
        dir: config.path().to_path_buf(),
    }
    .autosave_path(dataset());
    assert!(autosave.is_file(), "no autosave at {}", autosave.display());
    drop(harness);

    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    assert_eq!(harness.state().recovery(), Some(autosave.as_path()));
    assert_eq!(history_len(&harness), (0, 0));
    harness.get_by_label("Recover").click();
    settle(&mut harness);
    assert_eq!(history_len(&harness), (1, 1));
    assert!(harness.state().workspace().unwrap().is_dirty());

    // Save through the Save-as dialog (Ctrl+S on unsaved work asks where).
    shortcut(&mut harness, Modifiers::COMMAND, Key::S);
    harness.get_by_label("Save project as");
    harness.get_by_label("Save").click();
    harness.step();
    harness.step();
    let project_path = dataset().parent().unwrap().join("plant.frond");
    let project = Project::read(&project_path).unwrap();
    assert_eq!((project.history.len(), project.position), (1, 1));
    assert!(!harness.state().workspace().unwrap().is_dirty());
    assert!(!autosave.exists(), "the autosave outlived the save");
    assert_eq!(
        harness.state().recent()[0],
        project_path.canonicalize().unwrap()
    );
    drop(harness);

    // Reopening the project replays its history; nothing to recover.
    let harness = harness_with(project_path.clone(), config.path());
    assert_eq!(history_len(&harness), (1, 1));
    assert_eq!(harness.state().recovery(), None);
    assert!(!harness.state().workspace().unwrap().is_dirty());
    std::fs::remove_file(project_path).unwrap();
}

/// Asks the window to close (the title bar's close button).
fn request_close(harness: &mut Harness<'static, FrondApp>) {
    harness
        .input_mut()
        .viewports
        .entry(egui::ViewportId::ROOT)
        .or_default()
        .events
        .push(egui::ViewportEvent::Close);
    harness.step();
}

/// Steps once more (a new modal is laid out invisibly in its first frame).
fn show_prompt(harness: &mut Harness<'static, FrondApp>) {
    harness.step();
}

/// The commands the last frame sent to the window.
fn window_commands(harness: &Harness<'static, FrondApp>) -> Vec<egui::ViewportCommand> {
    harness
        .output()
        .viewport_output
        .get(&egui::ViewportId::ROOT)
        .map_or_else(Vec::new, |v| v.commands.clone())
}

#[test]
fn closing_with_unsaved_edits_asks_and_saves_or_discards() {
    let config = tempfile::tempdir().unwrap();
    let project_dir = tempfile::tempdir().unwrap();
    let project_path = project_dir.path().join("closing.frond");
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    let leaves = leaves_in_view(session(&harness));

    // Nothing unsaved: a close request goes through.
    request_close(&mut harness);
    assert!(!window_commands(&harness).contains(&egui::ViewportCommand::CancelClose));
    assert!(harness.query_by_label("Close without saving").is_none());

    // Saved once, then edited again: the close is held and the prompt's Save saves.
    click(&mut harness, central_pixel(&leaves[0].1));
    harness.state_mut().save_as(project_path.clone());
    click(&mut harness, central_pixel(&leaves[1].1));
    assert!(harness.state().closing_loses_edits());
    request_close(&mut harness);
    assert!(window_commands(&harness).contains(&egui::ViewportCommand::CancelClose));
    show_prompt(&mut harness);
    harness.get_by_label("Unsaved edits");
    harness.get_by_label("Save").click();
    harness.run_steps(2);
    assert!(
        window_commands(&harness).contains(&egui::ViewportCommand::Close),
        "{:?}",
        harness.state().status()
    );
    let project = Project::read(&project_path).unwrap();
    assert_eq!((project.history.len(), project.position), (2, 2));

    // Edited and autosaved, then closed without saving: the autosave goes too.
    let mut harness = harness_with(project_path.clone(), config.path());
    click(&mut harness, central_pixel(&leaves[2].1));
    harness.state_mut().autosave_interval = Duration::ZERO;
    harness.step();
    let autosave = ConfigDir {
        dir: config.path().to_path_buf(),
    }
    .autosave_path(&project_path);
    assert!(autosave.is_file(), "no autosave at {}", autosave.display());
    request_close(&mut harness);
    assert!(window_commands(&harness).contains(&egui::ViewportCommand::CancelClose));
    show_prompt(&mut harness);
    harness.get_by_label("Close without saving").click();
    harness.step();
    assert!(window_commands(&harness).contains(&egui::ViewportCommand::Close));
    assert!(!autosave.exists());
    assert_eq!(Project::read(&project_path).unwrap().history.len(), 2);
}

#[test]
fn fitting_runs_off_thread_can_be_cancelled_and_exports() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(dataset().to_path_buf(), config.path());
    let edits = history_len(&harness);

    // Cancel while it runs: the session comes back untouched, without leaves. The gate holds
    // the worker until the cancel, so a fast machine cannot finish the fit first.
    let gate = std::sync::Arc::new(frond_ui::jobs::StartGate::default());
    harness.state_mut().job_start_gate = Some(std::sync::Arc::clone(&gate));
    harness.get_by_label("🍃  Fit leaves").click();
    harness.step();
    harness.step();
    assert!(harness.state().is_busy());
    // One in the status bar, one on the work's card.
    assert_eq!(harness.get_all_by_label("Cancel").count(), 2);
    harness.get_all_by_label("Cancel").next().unwrap().click();
    settle(&mut harness);
    let status = harness.state().status().unwrap().clone();
    assert!(
        status.is_error && status.text.contains("cancelled"),
        "{status:?}"
    );
    assert!(harness.state().workspace().unwrap().leaves.is_none());
    assert_eq!(history_len(&harness), edits);
    gate.open();

    // Export fits first, then writes every format.
    let out = tempfile::tempdir().unwrap();
    let folder = out.path().join("export");
    harness.state_mut().export(folder.clone());
    settle(&mut harness);
    let status = harness.state().status().unwrap().clone();
    assert!(!status.is_error, "{status:?}");
    let workspace = harness.state().workspace().unwrap();
    let fitted = workspace.current_leaves().expect("fitted").leaves.len();
    assert!(fitted >= 3, "{fitted} leaves fitted");
    for file in [
        "plant.glb",
        "plant.obj",
        "plant.mtl",
        "segmentation.ply",
        "segments.json",
    ] {
        assert!(folder.join(file).is_file(), "{file} missing: {status:?}");
    }
    // The side panel reports the fit.
    harness.get_by_label_contains(&format!("{fitted} leaves fitted"));

    // The 3D panel's content: every fitted leaf textured, the branches, a radius sphere per
    // branch end and a frustum per photo.
    let data = frond_ui::view3d::SceneData::build(workspace, 0.3);
    assert_eq!(data.leaves.len(), fitted);
    assert!(
        data.leaves
            .iter()
            .all(|(mesh, texture)| { !mesh.triangles.is_empty() && texture.width() > 0 })
    );
    let [moving, points, branches, handles] = &data.palette_meshes[..] else {
        panic!("four palette meshes expected");
    };
    // Every point an octahedron once still; about a quarter of them, as tetrahedra, while
    // the view moves.
    assert_eq!(points.positions.len(), 6 * data.points);
    let share = moving.positions.len() as f64 / (4 * data.points) as f64;
    assert!((0.2..0.3).contains(&share), "{share}");
    assert!(data.points > 1000, "{} points", data.points);
    assert!(!branches.triangles.is_empty());
    let ends = 2 * workspace.session.branches().branches.len();
    let photos = workspace.session.scene().reconstruction.images().len();
    // Octahedra (8 triangles) at the ends, 8 bars (8 triangles) per frustum.
    assert_eq!(handles.triangles.len(), 8 * ends + 64 * photos);
    assert!(
        handles
            .positions
            .iter()
            .all(|p| p.coords.iter().all(|v| v.is_finite()))
    );
}

#[test]
fn the_scene_tab_lists_cameras_and_images_of_a_colmap_fixture() {
    let config = tempfile::tempdir().unwrap();
    let mut harness = harness_with(fixture("toy_scene"), config.path());
    if let Some(error) = harness.state().error() {
        panic!("the fixture did not open: {error}");
    }
    harness.get_by_label("Scene").click();
    harness.step();
    harness.step();
    harness.get_by_label_contains("Camera 1 · SIMPLE_RADIAL · 240×180");
    // In the filmstrip and in the table.
    assert!(harness.get_all_by_label("view_0000.png").count() >= 2);
    harness.get_by_label_contains("1500 points");
}

#[test]
fn opening_a_folder_without_a_model_shows_the_error() {
    let config = tempfile::tempdir().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let harness = harness_with(dir.path().to_path_buf(), config.path());
    let error = harness.state().error().expect("load fails").to_owned();
    assert!(error.contains("no COLMAP model found"), "{error}");
    harness.get_by_label("Could not open the scene");
}
