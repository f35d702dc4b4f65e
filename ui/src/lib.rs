//! frond-ui: Frond's interactive GUI (egui/eframe on wgpu).
//!
//! The GUI owns no algorithm: every edit is a library `Command` applied to the editing
//! `Session` (so it is undoable and saved in the project's history), and long work (opening and
//! segmenting, fitting leaves, the automatic skeleton, export) runs on a worker thread with a
//! progress bar and a Cancel button.
//!
//! This file draws the window (menus, tool strip, side panel with segments, branches and
//! history, status bar, dialogs, the central photo / 3D layout) and routes shortcuts, menu
//! choices and panel actions to the library: `Session::{apply, undo, redo}` through
//! `workspace::Workspace`, the reads `Session::{segmentation, segments, branches, history,
//! scene}`, `frond::util::atomic::write_atomic` for the benchmark report and
//! `frond::util::stats::TimingSummary` for its frame-time statistics (the benchmark drives the
//! 3D view and an edit per frame and only records times).

pub mod files;
pub mod image_view;
pub mod jobs;
pub mod native;
pub mod tools;
pub mod view3d;
pub mod workspace;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::{Color32, Key, KeyboardShortcut, Modifiers, RichText};
use egui_extras::{Column, TableBuilder};
use frond::edit::Command;
use frond::scene::ImageFileStatus;
use frond::segment::SegmentLabel;

use files::{ConfigDir, DirEntry, list_dir, recoverable_autosave};
use image_view::{Action, ImagePanel};
use jobs::{Job, JobProgress, Poll};
use tools::{TOOL_GROUPS, Tool};
use view3d::View3d;
use workspace::Workspace;

/// How often unsaved edits are autosaved.
pub const AUTOSAVE_INTERVAL: Duration = Duration::from_secs(30);

/// Height of the filmstrip panel (points).
const FILMSTRIP_HEIGHT: f32 = 104.0;

/// What a finished job hands back.
enum Outcome {
    Opened {
        path: PathBuf,
        result: Result<Box<Workspace>, String>,
    },
    /// Work on the open workspace, which travelled to the worker and comes back.
    Worked {
        workspace: Box<Workspace>,
        result: Result<String, String>,
    },
}

/// A frame-time benchmark: once the scene is open (and the leaves fitted, if asked), the 3D
/// view orbits a little every frame and each frame's time is recorded.
#[derive(Clone, Debug, Default)]
pub struct Benchmark {
    pub frames: usize,
    pub fit_leaves: bool,
    /// Where the result goes (JSON); printed on stdout as well.
    pub out: Option<PathBuf>,
    fit_started: bool,
    /// Per phase (orbiting, still, then editing: a branch radius changed every frame): wall
    /// time between frames (ms, vsync waits included), whole-frame CPU time as eframe
    /// reports it (ms) and UI build time (ms).
    samples: [Vec<[f32; 3]>; 3],
    /// Edits applied in the editing phase.
    edits: usize,
    warmup: usize,
    /// When the orbit stopped (the still phase records once the 3D view has settled).
    stopped_at: Option<Instant>,
}

impl Benchmark {
    pub fn new(frames: usize, fit_leaves: bool, out: Option<PathBuf>) -> Self {
        Self {
            frames,
            fit_leaves,
            out,
            warmup: 10,
            ..Self::default()
        }
    }
}

/// Deletes the workspace's autosave (after a save, or when the user drops the edits); a
/// missing file is fine.
fn remove_autosave(config: &ConfigDir, workspace: &Workspace) {
    let _ = std::fs::remove_file(config.autosave_path(&workspace.input));
}

/// Frames of the benchmark's editing phase (at most).
const EDIT_BENCHMARK_FRAMES: usize = 20;

/// A message in the status bar.
#[derive(Clone, Debug)]
pub struct Status {
    pub text: String,
    pub is_error: bool,
}

/// What the central area shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CentralLayout {
    Photo,
    ThreeD,
    Both,
}

/// The side panel's tabs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SideTab {
    Segments,
    Branches,
    History,
    Scene,
}

enum Dialog {
    Open {
        folder: PathBuf,
        path: String,
        entries: Result<Vec<DirEntry>, String>,
    },
    SaveAs {
        path: String,
    },
    Export {
        path: String,
    },
    /// The window is closing with unsaved edits.
    ConfirmClose,
}

/// Branch support measured for one state of the session (see `FrondApp::branches_ui`).
struct SupportCache {
    /// (history length, applied commands) when measured.
    position: (usize, usize),
    tree: frond::branch::BranchTree,
    support: Vec<frond::branch::plant::BranchSupport>,
}

/// The application state.
pub struct FrondApp {
    config: Option<ConfigDir>,
    recent: Vec<PathBuf>,
    workspace: Option<Box<Workspace>>,
    job: Option<Job<Outcome>>,
    /// Whether the running job holds the workspace.
    workspace_busy: bool,
    /// The error of the last failed open, shown when nothing is open.
    open_error: Option<String>,
    pub panel: ImagePanel,
    pub view3d: View3d,
    /// Whether the render core is installed in the window (a wgpu window, not a test).
    gpu: bool,
    pub layout: CentralLayout,
    pub tool: Tool,
    pub side_tab: SideTab,
    status: Option<Status>,
    dialog: Option<Dialog>,
    /// Close the window once the project is saved (the close prompt's Save without a
    /// project file yet).
    close_after_save: bool,
    /// The user chose to close without saving.
    close_confirmed: bool,
    /// An autosave holding edits the opened work lacks.
    recovery: Option<PathBuf>,
    pub show_help: bool,
    pub show_frame_time: bool,
    pub autosave_interval: Duration,
    last_autosave: Instant,
    /// Recent UI build times (ms).
    frame_times: VecDeque<f32>,
    /// Branch support shown in the branches tab, with the history position and tree it was
    /// measured for (measuring takes a fraction of a second: not every frame).
    support: Option<SupportCache>,
    /// Recent whole-frame CPU times reported by eframe (ms): UI, tessellation, the 3D
    /// panel's render and the window's paint, without waiting for vsync.
    paint_times: VecDeque<f32>,
    /// A frame-time benchmark in progress (`frond-ui --benchmark-frames`).
    pub benchmark: Option<Benchmark>,
    /// Fit the leaves as soon as the scene is open (`frond-ui --fit-leaves`).
    pub fit_leaves_when_open: bool,
    /// When set, new workers wait here before starting (scripts and tests that act on a
    /// running job, e.g. cancel it, whatever the machine's speed).
    pub job_start_gate: Option<Arc<jobs::StartGate>>,
    title: String,
    /// Use the platform's file dialogs (when one is available; see `native`).
    native_dialogs: bool,
    /// The native dialog being shown.
    native: Option<native::NativeDialog>,
}

fn file_status_text(status: &ImageFileStatus) -> String {
    match status {
        ImageFileStatus::Present => "present".into(),
        ImageFileStatus::NoImagesFolder => "no images folder".into(),
        ImageFileStatus::Missing => "missing".into(),
        ImageFileStatus::Unreadable { reason } => format!("unreadable: {reason}"),
        ImageFileStatus::SizeMismatch { file, camera } => format!(
            "size {}×{} ≠ camera {}×{}",
            file.0, file.1, camera.0, camera.1
        ),
    }
}

fn open_dialog(folder: PathBuf) -> Dialog {
    let entries = list_dir(&folder).map_err(|e| format!("{}: {e}", folder.display()));
    Dialog::Open {
        path: folder.display().to_string(),
        folder,
        entries,
    }
}

impl FrondApp {
    /// A new window with the user's configuration folder; starts opening `initial` when given.
    pub fn new(initial: Option<PathBuf>) -> Self {
        let mut app = Self::with_config(initial, ConfigDir::from_env());
        app.native_dialogs = native::available();
        app
    }

    /// A new window keeping recent files and autosaves in `config`.
    pub fn with_config(initial: Option<PathBuf>, config: Option<ConfigDir>) -> Self {
        let recent = config.as_ref().map(ConfigDir::recent).unwrap_or_default();
        let mut app = Self {
            config,
            recent,
            workspace: None,
            job: None,
            workspace_busy: false,
            open_error: None,
            panel: ImagePanel::default(),
            view3d: View3d::default(),
            gpu: false,
            layout: CentralLayout::Both,
            tool: Tool::Confirm,
            side_tab: SideTab::Segments,
            status: None,
            dialog: None,
            close_after_save: false,
            close_confirmed: false,
            recovery: None,
            show_help: false,
            show_frame_time: true,
            autosave_interval: AUTOSAVE_INTERVAL,
            last_autosave: Instant::now(),
            frame_times: VecDeque::new(),
            support: None,
            paint_times: VecDeque::new(),
            benchmark: None,
            fit_leaves_when_open: false,
            job_start_gate: None,
            title: String::new(),
            native_dialogs: false,
            native: None,
        };
        if let Some(path) = initial {
            app.open(path);
        }
        app
    }

    /// Installs the render core for the 3D panel on the window's wgpu device.
    pub fn install_gpu(&mut self, render_state: &eframe::egui_wgpu::RenderState) {
        match view3d::View3dResources::install(render_state) {
            Ok(()) => self.gpu = true,
            Err(e) => self.fail(format!("the 3D view is unavailable: {e}")),
        }
    }

    /// The open work.
    pub fn workspace(&self) -> Option<&Workspace> {
        self.workspace.as_deref()
    }

    /// Whether long work is running.
    pub fn is_busy(&self) -> bool {
        self.job.is_some()
    }

    /// The last open error, if nothing could be opened.
    pub fn error(&self) -> Option<&str> {
        self.open_error.as_deref()
    }

    /// The status bar's message.
    pub fn status(&self) -> Option<&Status> {
        self.status.as_ref()
    }

    /// Clears the status bar's message.
    pub fn clear_status(&mut self) {
        self.status = None;
    }

    /// The autosave offered for recovery.
    pub fn recovery(&self) -> Option<&Path> {
        self.recovery.as_deref()
    }

    /// Recent files, most recent first.
    pub fn recent(&self) -> &[PathBuf] {
        &self.recent
    }

    /// Asks the running job to stop.
    pub fn cancel_job(&self) {
        if let Some(job) = &self.job {
            job.progress.cancel();
        }
    }

    fn info(&mut self, text: impl Into<String>) {
        self.status = Some(Status {
            text: text.into(),
            is_error: false,
        });
    }

    fn fail(&mut self, text: impl Into<String>) {
        let text = text.into();
        tracing::warn!("{text}");
        self.status = Some(Status {
            text,
            is_error: true,
        });
    }

    /// Starts opening a COLMAP folder or a project file on a worker thread.
    pub fn open(&mut self, path: PathBuf) {
        if self.job.is_some() {
            self.fail("wait for the running work to finish (or cancel it) first");
            return;
        }
        let worker_path = path.clone();
        self.job = Some(Job::spawn_gated(
            format!("Opening {}", path.display()),
            self.job_start_gate.clone(),
            move |progress: &JobProgress| Outcome::Opened {
                result: Workspace::open(&worker_path, progress)
                    .map(Box::new)
                    .map_err(|e| e.to_string()),
                path: worker_path,
            },
        ));
    }

    /// Runs `work` on the open workspace on a worker thread.
    fn run_on_workspace(
        &mut self,
        title: &str,
        work: impl FnOnce(&mut Workspace, &JobProgress) -> Result<String, String> + Send + 'static,
    ) {
        if self.job.is_some() {
            self.fail("wait for the running work to finish (or cancel it) first");
            return;
        }
        // The worker owns the workspace until it hands it back; should it fail hard, the
        // edits are in the autosave.
        self.autosave_now();
        let Some(mut workspace) = self.workspace.take() else {
            self.fail("open a COLMAP folder or a project first");
            return;
        };
        self.panel.cancel_gesture();
        self.workspace_busy = true;
        self.job = Some(Job::spawn_gated(
            title,
            self.job_start_gate.clone(),
            move |progress: &JobProgress| {
                let result = work(&mut workspace, progress);
                Outcome::Worked { workspace, result }
            },
        ));
    }

    /// Fits every leaf segment (seed 004 §6) on a worker thread.
    pub fn fit_leaves(&mut self) {
        self.run_on_workspace("Fitting leaves", |workspace, progress| {
            workspace.fit_leaves(progress).map_err(|e| e.to_string())?;
            let leaves = workspace
                .current_leaves()
                .map_or((0, 0), |l| (l.leaves.len(), l.skipped.len()));
            Ok(format!("{} leaves fitted, {} skipped", leaves.0, leaves.1))
        });
    }

    /// Replaces the branches by the automatic skeleton (an undoable command) on a worker.
    pub fn automatic_skeleton(&mut self) {
        self.run_on_workspace("Automatic skeleton", |workspace, _| {
            workspace
                .apply(Command::AutomaticSkeleton)
                .map_err(|e| e.to_string())?;
            Ok(format!(
                "automatic skeleton: {} branches",
                workspace.session.branches().branches.len()
            ))
        });
    }

    /// Exports glb, OBJ and PLY into `folder` on a worker thread.
    pub fn export(&mut self, folder: PathBuf) {
        self.run_on_workspace("Exporting", move |workspace, progress| {
            let summary = workspace.export(&folder, progress)?;
            Ok(format!(
                "exported {} leaves, {} branches, {} triangles to {}",
                summary.leaves,
                summary.branches,
                summary.triangles,
                summary.folder.display()
            ))
        });
    }

    /// Replaces the session by the offered autosave.
    pub fn recover(&mut self) {
        let Some(autosave) = self.recovery.take() else {
            return;
        };
        self.run_on_workspace("Recovering autosaved edits", move |workspace, progress| {
            workspace
                .recover(&autosave, progress)
                .map_err(|e| e.to_string())?;
            let (_, position) = workspace.session.history();
            Ok(format!("recovered {position} edits from the autosave"))
        });
    }

    /// Deletes the offered autosave.
    pub fn discard_recovery(&mut self) {
        if let Some(autosave) = self.recovery.take()
            && let Err(e) = std::fs::remove_file(&autosave)
        {
            self.fail(format!("could not delete {}: {e}", autosave.display()));
        }
    }

    /// Saves the project at `path` (atomically) and drops the autosave it supersedes.
    pub fn save_as(&mut self, path: PathBuf) {
        let Some(workspace) = self.workspace.as_mut() else {
            return;
        };
        match workspace.save(&path) {
            Ok(()) => {
                if let Some(config) = &self.config {
                    remove_autosave(config, workspace);
                    if let Ok(recent) = config.push_recent(&path) {
                        self.recent = recent;
                    }
                }
                self.info(format!("saved {}", path.display()));
            }
            Err(e) => {
                self.close_after_save = false;
                self.fail(format!("could not save: {e}"));
            }
        }
    }

    /// Whether closing now would lose edits (unsaved, and not yet confirmed by the user).
    pub fn closing_loses_edits(&self) -> bool {
        !self.close_confirmed && self.workspace.as_ref().is_some_and(|w| w.is_dirty())
    }

    /// Holds a close request while there are unsaved edits and asks what to do with them;
    /// closes once a save asked for by that prompt has succeeded.
    fn confirm_close(&mut self, ctx: &egui::Context) {
        if self.close_after_save && !self.closing_loses_edits() && self.dialog.is_none() {
            self.close_after_save = false;
            self.close_confirmed = true;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        if ctx.input(|i| i.viewport().close_requested()) && self.closing_loses_edits() {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.dialog = Some(Dialog::ConfirmClose);
        }
    }

    /// Saves to the project file, or asks where when there is none yet.
    pub fn save(&mut self) {
        match self.workspace.as_ref().map(|w| w.project_path.clone()) {
            Some(Some(path)) => self.save_as(path),
            Some(None) => self.show_save_as_dialog(),
            None => {}
        }
    }

    fn save_as_dialog(&self) -> Dialog {
        let path = self.workspace.as_ref().map_or_else(String::new, |w| {
            w.project_path
                .clone()
                .unwrap_or_else(|| {
                    let folder = w.input.parent().unwrap_or(Path::new("."));
                    folder.join(format!("{}.frond", w.name()))
                })
                .display()
                .to_string()
        });
        Dialog::SaveAs { path }
    }

    /// Applies an edit, reporting a refusal in the status bar.
    pub fn apply(&mut self, command: Command) {
        let Some(workspace) = self.workspace.as_mut() else {
            return;
        };
        let description = command.describe();
        match workspace.apply(command) {
            Ok(()) => self.info(description),
            Err(e) => self.fail(format!("{description}: {e}")),
        }
    }

    pub fn undo(&mut self) {
        if let Some(workspace) = self.workspace.as_mut() {
            self.panel.cancel_gesture();
            if workspace.undo() {
                self.info("undone");
            }
        }
    }

    pub fn redo(&mut self) {
        if let Some(workspace) = self.workspace.as_mut()
            && workspace.redo()
        {
            self.info("redone");
        }
    }

    fn poll_job(&mut self, ctx: &egui::Context) {
        let Some(job) = &self.job else {
            return;
        };
        let outcome = match job.poll() {
            Poll::Running => {
                ctx.request_repaint_after(Duration::from_millis(50));
                return;
            }
            Poll::Lost => {
                self.job = None;
                let held_workspace = std::mem::take(&mut self.workspace_busy);
                self.fail(if held_workspace {
                    "the worker stopped unexpectedly; reopen the input to recover the autosaved edits"
                } else {
                    "the worker stopped unexpectedly"
                });
                return;
            }
            Poll::Done(outcome) => outcome,
        };
        let seconds = job.started.elapsed().as_secs_f64();
        self.job = None;
        self.workspace_busy = false;
        match outcome {
            Outcome::Opened { path, result } => match result {
                Ok(workspace) => {
                    self.recovery = self.config.as_ref().and_then(|config| {
                        recoverable_autosave(
                            config,
                            &workspace.input,
                            workspace.project_path.as_deref(),
                        )
                    });
                    if let Some(config) = &self.config
                        && let Ok(recent) = config.push_recent(&path)
                    {
                        self.recent = recent;
                    }
                    let (leaves, _, _) = workspace.segment_counts();
                    self.panel.reset();
                    self.view3d.reset();
                    self.workspace = Some(workspace);
                    self.open_error = None;
                    self.last_autosave = Instant::now();
                    self.info(format!(
                        "opened {} in {seconds:.1} s: {leaves} leaf segments",
                        path.display()
                    ));
                    if std::mem::take(&mut self.fit_leaves_when_open) {
                        self.fit_leaves();
                    }
                }
                Err(message) => {
                    self.fail(format!("could not open {}: {message}", path.display()));
                    if self.workspace.is_none() {
                        self.open_error = Some(message);
                    }
                }
            },
            Outcome::Worked { workspace, result } => {
                self.workspace = Some(workspace);
                match result {
                    Ok(message) => self.info(format!("{message} ({seconds:.1} s)")),
                    Err(message) => self.fail(message),
                }
            }
        }
    }

    fn autosave_tick(&mut self) {
        if self.last_autosave.elapsed() >= self.autosave_interval {
            self.autosave_now();
        }
    }

    /// Writes the autosave now if there are edits it lacks.
    fn autosave_now(&mut self) {
        self.last_autosave = Instant::now();
        let (Some(workspace), Some(config)) = (self.workspace.as_mut(), &self.config) else {
            return;
        };
        let path = config.autosave_path(&workspace.input);
        match workspace.autosave(&path) {
            Ok(true) => tracing::info!("autosaved to {}", path.display()),
            Ok(false) => {}
            Err(e) => self.fail(format!("autosave failed: {e}")),
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        let command = Modifiers::COMMAND;
        let shift_command = Modifiers::COMMAND | Modifiers::SHIFT;
        let shortcut = |modifiers, key| KeyboardShortcut::new(modifiers, key);
        let pressed = |s: KeyboardShortcut| ctx.input_mut(|i| i.consume_shortcut(&s));
        // Longer combinations first: Ctrl+Z also matches Ctrl+Shift+Z logically.
        if pressed(shortcut(shift_command, Key::Z)) || pressed(shortcut(command, Key::Y)) {
            self.redo();
        } else if pressed(shortcut(command, Key::Z)) {
            self.undo();
        }
        if pressed(shortcut(shift_command, Key::S)) {
            self.show_save_as_dialog();
        } else if pressed(shortcut(command, Key::S)) {
            self.save();
        }
        if pressed(shortcut(command, Key::O)) {
            self.show_open_dialog();
        }
        if pressed(shortcut(command, Key::E)) && self.workspace.is_some() {
            self.show_export_dialog();
        }
        if pressed(shortcut(Modifiers::NONE, Key::F1)) {
            self.show_help = !self.show_help;
        }
        if pressed(shortcut(Modifiers::NONE, Key::F12)) {
            self.show_frame_time = !self.show_frame_time;
        }
        if ctx.egui_wants_keyboard_input() || self.dialog.is_some() {
            return;
        }
        let plain = |key| ctx.input_mut(|i| i.consume_key(Modifiers::NONE, key));
        if plain(Key::Escape) {
            self.panel.cancel_gesture();
        }
        if plain(Key::F) {
            self.panel.fit();
        }
        if let Some(workspace) = &self.workspace {
            let views = workspace.session.scene().reconstruction.images().len();
            if plain(Key::ArrowRight) && views > 0 {
                self.panel.select_view((self.panel.view + 1) % views);
            }
            if plain(Key::ArrowLeft) && views > 0 {
                self.panel
                    .select_view((self.panel.view + views - 1) % views);
            }
        }
        for tool in Tool::all() {
            if plain(tool.shortcut()) {
                self.select_tool(tool);
            }
        }
    }

    /// Makes `tool` the active tool.
    pub fn select_tool(&mut self, tool: Tool) {
        if tool != self.tool {
            self.panel.cancel_gesture();
            self.tool = tool;
        }
    }

    fn open_folder(&self) -> PathBuf {
        self.workspace
            .as_ref()
            .and_then(|w| w.input.parent().map(Path::to_path_buf))
            .or_else(|| std::env::current_dir().ok())
            .unwrap_or_else(|| PathBuf::from("/"))
    }

    /// The platform's dialog for `pick` when there is one (and none is showing); false when
    /// the built-in dialog should be shown instead.
    fn show_native(&mut self, pick: native::Pick, start: &Path) -> bool {
        if !self.native_dialogs {
            return false;
        }
        if self.native.is_none() {
            self.native = Some(native::NativeDialog::show(pick, start));
        }
        true
    }

    /// Acts on the native dialog's answer once it comes.
    fn poll_native(&mut self, ctx: &egui::Context) {
        let Some(dialog) = &self.native else {
            return;
        };
        let Some(answer) = dialog.poll() else {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
            return;
        };
        let pick = dialog.pick;
        self.native = None;
        let Some(path) = answer else {
            return;
        };
        match pick {
            native::Pick::OpenFolder | native::Pick::OpenProject => self.open(path),
            native::Pick::SaveProject => {
                let mut file = path;
                if file.extension().is_none_or(|e| e != "frond") {
                    file.set_extension("frond");
                }
                self.save_as(file);
            }
            native::Pick::ExportFolder => self.export(path),
        }
    }

    fn show_open_dialog(&mut self) {
        let folder = self.open_folder();
        if !self.show_native(native::Pick::OpenFolder, &folder) {
            self.show_builtin_open_dialog();
        }
    }

    /// The built-in browser (photos, COLMAP folders and project files alike).
    fn show_builtin_open_dialog(&mut self) {
        self.dialog = Some(open_dialog(self.open_folder()));
    }

    fn show_save_as_dialog(&mut self) {
        let dialog = self.save_as_dialog();
        if let Dialog::SaveAs { path } = &dialog
            && self.show_native(native::Pick::SaveProject, Path::new(path))
        {
            return;
        }
        self.dialog = Some(dialog);
    }

    fn show_export_dialog(&mut self) {
        let path = self.workspace.as_ref().map_or_else(String::new, |w| {
            let base = w.project_path.as_deref().unwrap_or(&w.input);
            let folder = base.parent().unwrap_or(Path::new("."));
            folder
                .join(format!("{}_export", w.name().trim_end_matches(".frond")))
                .display()
                .to_string()
        });
        let start = Path::new(&path)
            .parent()
            .unwrap_or(Path::new("."))
            .to_path_buf();
        if !self.show_native(native::Pick::ExportFolder, &start) {
            self.dialog = Some(Dialog::Export { path });
        }
    }

    /// Draws the whole window.
    pub fn window_ui(&mut self, ui: &mut egui::Ui) {
        let started = Instant::now();
        let ctx = ui.ctx().clone();
        self.confirm_close(&ctx);
        self.poll_job(&ctx);
        self.poll_native(&ctx);
        self.shortcuts(&ctx);
        self.autosave_tick();
        self.update_title(&ctx);

        // No panel paints a background: the window is cleared to the panel colour (see
        // `clear_color`), so a fill would only add overdraw, which a software rasteriser pays
        // for per pixel (the central panel's fill alone cost 28 ms a frame on llvmpipe).
        let bare = egui::Frame::side_top_panel(ui.style()).fill(Color32::TRANSPARENT);
        egui::Panel::top("menu")
            .frame(bare)
            .show(ui, |ui| self.menu_ui(ui));
        egui::Panel::bottom("status")
            .frame(bare)
            .show(ui, |ui| self.status_ui(ui));
        // While work holds the workspace the panels stay (disabled), so nothing jumps.
        if self.workspace.is_some() || self.workspace_busy {
            let enabled = self.workspace.is_some();
            egui::Panel::left("tools")
                .frame(bare)
                .resizable(false)
                .exact_size(150.0)
                .show(ui, |ui| ui.add_enabled_ui(enabled, |ui| self.tools_ui(ui)));
            egui::Panel::right("side")
                .frame(bare)
                .default_size(320.0)
                .show(ui, |ui| {
                    if enabled {
                        self.side_ui(ui);
                    } else {
                        ui.add_space(8.0);
                        ui.weak("Working…");
                    }
                });
            egui::Panel::bottom("filmstrip")
                .frame(bare)
                .resizable(false)
                .exact_size(FILMSTRIP_HEIGHT)
                .show(ui, |ui| {
                    if let Some(workspace) = self.workspace.as_deref() {
                        self.panel.filmstrip_ui(ui, workspace);
                    }
                });
        }
        let frame = egui::Frame::central_panel(ui.style()).fill(Color32::TRANSPARENT);
        egui::CentralPanel::default()
            .frame(frame)
            .show(ui, |ui| self.central_ui(ui));
        self.dialog_ui(&ctx);
        if self.show_help {
            self.help_ui(&ctx);
        }
        let ms = started.elapsed().as_secs_f32() * 1000.0;
        self.frame_times.push_back(ms);
        if self.frame_times.len() > 60 {
            self.frame_times.pop_front();
        }
        self.benchmark_step(&ctx, ms);
    }

    /// Records whole-frame CPU time as eframe reports it (for the previous frame).
    pub fn report_frame_time(&mut self, seconds: Option<f32>) {
        if let Some(seconds) = seconds {
            self.paint_times.push_back(seconds * 1000.0);
            if self.paint_times.len() > 60 {
                self.paint_times.pop_front();
            }
        }
    }

    /// Mean whole-frame CPU time over the last frames (ms), when running in a window.
    pub fn mean_paint_ms(&self) -> Option<f32> {
        (!self.paint_times.is_empty())
            .then(|| self.paint_times.iter().sum::<f32>() / self.paint_times.len() as f32)
    }

    fn frame_time_text(&self) -> String {
        match self.mean_paint_ms() {
            Some(frame) => format!("frame {frame:.1} ms · UI {:.1} ms", self.mean_frame_ms()),
            None => format!("UI {:.1} ms", self.mean_frame_ms()),
        }
    }

    /// The last rebuilds after a change (edits, view, overlays), for the debug overlay.
    fn rebuild_text(&self) -> String {
        let mut parts = Vec::new();
        if let Some(ms) = self.panel.last_compose_ms {
            parts.push(format!("photo composed in {ms:.0} ms"));
        }
        if let Some(ms) = self.view3d.last_build_ms {
            parts.push(format!("3D built in {ms:.0} ms"));
        }
        parts.join(" · ")
    }

    fn benchmark_step(&mut self, ctx: &egui::Context, ui_ms: f32) {
        let Some(mut benchmark) = self.benchmark.take() else {
            return;
        };
        ctx.request_repaint();
        // With nothing to open the empty window is measured (the baseline).
        let nothing_to_open = self.workspace.is_none() && self.open_error.is_none();
        let ready = self.job.is_none()
            && (self.workspace.is_some() || nothing_to_open)
            && self.panel.is_idle();
        if !ready {
            if self.job.is_none() && self.workspace.is_none() && self.open_error.is_some() {
                eprintln!("benchmark: nothing opened");
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                return;
            }
            self.benchmark = Some(benchmark);
            return;
        }
        if benchmark.fit_leaves && !benchmark.fit_started {
            benchmark.fit_started = true;
            self.benchmark = Some(benchmark);
            self.fit_leaves();
            return;
        }
        let phase = if benchmark.samples[0].len() < benchmark.frames {
            0
        } else if benchmark.samples[1].len() < benchmark.frames {
            1
        } else {
            2
        };
        if phase == 0 {
            if let Some(orbit) = self.view3d.orbit.as_mut() {
                orbit.rotate(4.0, 0.0);
            }
        } else if phase == 1
            && benchmark
                .stopped_at
                .get_or_insert_with(Instant::now)
                .elapsed()
                < Duration::from_millis(500)
        {
            self.benchmark = Some(benchmark);
            return;
        }
        if benchmark.warmup > 0 {
            benchmark.warmup -= 1;
            self.benchmark = Some(benchmark);
            return;
        }
        // In the editing phase an interval counts once an edit came before it.
        if let Some(&paint) = self.paint_times.back()
            && (phase < 2 || benchmark.edits > 0)
        {
            let interval = ctx.input(|i| i.unstable_dt) * 1000.0;
            benchmark.samples[phase].push([interval, paint, ui_ms]);
        }
        let edit_frames = benchmark.frames.min(EDIT_BENCHMARK_FRAMES);
        let first_branch = self
            .workspace
            .as_ref()
            .and_then(|w| w.session.branches().branches.first())
            .map(|b| (b.id, b.cylinder.radius_end));
        if benchmark.samples[1].len() < benchmark.frames {
            self.benchmark = Some(benchmark);
            return;
        }
        if let Some((branch, radius)) = first_branch
            && benchmark.samples[2].len() < edit_frames
        {
            // Widen and narrow the first branch's tip in turn: each edit rebuilds the 3D
            // points and branches and recomposes the photo, as any edit does.
            let factor = if benchmark.edits % 2 == 0 {
                1.05
            } else {
                1.0 / 1.05
            };
            benchmark.edits += 1;
            self.benchmark = Some(benchmark);
            self.apply(Command::SetRadius {
                branch,
                end: frond::edit::BranchEnd::End,
                radius: radius * factor,
            });
            return;
        }
        let (points, leaves) = self.workspace.as_ref().map_or((0, 0), |w| {
            (
                w.session.segmentation().points.len(),
                w.leaves.as_ref().map_or(0, |(_, l)| l.leaves.len()),
            )
        });
        let stats = |samples: &[[f32; 3]], k: usize| {
            let values: Vec<f32> = samples.iter().map(|s| s[k]).collect();
            let summary = frond::util::stats::TimingSummary::of(&values);
            serde_json::json!({
                "mean": summary.mean,
                "median": summary.median,
                "p95": summary.p95,
            })
        };
        let phase_report = |samples: &[[f32; 3]]| {
            serde_json::json!({
                "frames": samples.len(),
                "interval_ms": stats(samples, 0),
                "eframe_cpu_ms": stats(samples, 1),
                "ui_ms": stats(samples, 2),
            })
        };
        let report = serde_json::json!({
            "points": points,
            "textured_leaves": leaves,
            "layout": format!("{:?}", self.layout),
            "window": [ctx.content_rect().width(), ctx.content_rect().height()],
            "photo_compose_ms": self.panel.last_compose_ms,
            "build_3d_ms": self.view3d.last_build_ms,
            "triangles_3d": self.view3d.triangle_counts().map(|[moving, still, branches, handles, leaves]| {
                serde_json::json!({
                    "points_while_moving": moving,
                    "points_when_still": still,
                    "branches": branches,
                    "handles_and_frusta": handles,
                    "leaves": leaves,
                })
            }),
            "orbiting": phase_report(&benchmark.samples[0]),
            "still": phase_report(&benchmark.samples[1]),
            "editing": phase_report(&benchmark.samples[2]),
        });
        let text = serde_json::to_string_pretty(&report).unwrap_or_default();
        println!("{text}");
        if let Some(out) = &benchmark.out
            && let Err(e) = frond::util::atomic::write_atomic(out, text.as_bytes())
        {
            eprintln!("benchmark: could not write {}: {e}", out.display());
        }
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// Mean UI build time over the last frames (ms).
    pub fn mean_frame_ms(&self) -> f32 {
        if self.frame_times.is_empty() {
            return 0.0;
        }
        self.frame_times.iter().sum::<f32>() / self.frame_times.len() as f32
    }

    fn update_title(&mut self, ctx: &egui::Context) {
        let title = match &self.workspace {
            Some(w) => format!(
                "{}{} — Frond",
                if w.is_dirty() { "• " } else { "" },
                w.name()
            ),
            None => "Frond".to_owned(),
        };
        if title != self.title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }
    }

    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui
                    .add(egui::Button::new("Open…").shortcut_text("Ctrl+O"))
                    .clicked()
                {
                    self.show_open_dialog();
                }
                if self.native_dialogs {
                    if ui.button("Open project…").clicked() {
                        let folder = self.open_folder();
                        self.show_native(native::Pick::OpenProject, &folder);
                    }
                    if ui.button("Open with the built-in browser…").clicked() {
                        self.show_builtin_open_dialog();
                    }
                }
                ui.menu_button("Open recent", |ui| {
                    if self.recent.is_empty() {
                        ui.label("No recent files");
                    }
                    for path in self.recent.clone() {
                        if ui.button(path.display().to_string()).clicked() {
                            self.open(path);
                        }
                    }
                });
                ui.separator();
                let open = self.workspace.is_some();
                if ui
                    .add_enabled(open, egui::Button::new("Save").shortcut_text("Ctrl+S"))
                    .clicked()
                {
                    self.save();
                }
                if ui
                    .add_enabled(
                        open,
                        egui::Button::new("Save as…").shortcut_text("Ctrl+Shift+S"),
                    )
                    .clicked()
                {
                    self.show_save_as_dialog();
                }
                if ui
                    .add_enabled(
                        open,
                        egui::Button::new("Export glb / OBJ / PLY…").shortcut_text("Ctrl+E"),
                    )
                    .clicked()
                {
                    self.show_export_dialog();
                }
                ui.separator();
                if ui.button("Quit").clicked() {
                    ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                }
            });
            ui.menu_button("Edit", |ui| {
                let (can_undo, can_redo) = self.workspace.as_ref().map_or((false, false), |w| {
                    (w.session.can_undo(), w.session.can_redo())
                });
                if ui
                    .add_enabled(can_undo, egui::Button::new("Undo").shortcut_text("Ctrl+Z"))
                    .clicked()
                {
                    self.undo();
                }
                if ui
                    .add_enabled(
                        can_redo,
                        egui::Button::new("Redo").shortcut_text("Ctrl+Shift+Z"),
                    )
                    .clicked()
                {
                    self.redo();
                }
                ui.separator();
                let ready = self.workspace.is_some() && self.job.is_none();
                if ui
                    .add_enabled(ready, egui::Button::new("Fit leaves"))
                    .clicked()
                {
                    self.fit_leaves();
                }
                if ui
                    .add_enabled(ready, egui::Button::new("Automatic skeleton"))
                    .clicked()
                {
                    self.automatic_skeleton();
                }
            });
            ui.menu_button("View", |ui| {
                for (name, on) in self.panel.overlays.toggles() {
                    ui.checkbox(on, name);
                }
                ui.separator();
                for (name, on) in self.view3d.show.toggles() {
                    ui.checkbox(on, name);
                }
                ui.separator();
                if ui
                    .add(egui::Button::new("Fit photo").shortcut_text("F"))
                    .clicked()
                {
                    self.panel.fit();
                }
                ui.checkbox(&mut self.show_frame_time, "Frame time (F12)");
            });
            ui.menu_button("Tools", |ui| {
                for tool in Tool::all() {
                    let text = format!("{}  {}", tool.icon(), tool.label());
                    if ui
                        .add(
                            egui::Button::selectable(self.tool == tool, text)
                                .shortcut_text(tool.shortcut().name()),
                        )
                        .clicked()
                    {
                        self.select_tool(tool);
                    }
                }
            });
            ui.menu_button("Help", |ui| {
                if ui
                    .add(egui::Button::new("Shortcuts").shortcut_text("F1"))
                    .clicked()
                {
                    self.show_help = true;
                }
            });
            ui.separator();
            let (can_undo, can_redo) = self.workspace.as_ref().map_or((false, false), |w| {
                (w.session.can_undo(), w.session.can_redo())
            });
            if ui
                .add_enabled(can_undo, egui::Button::new("⟲ Undo"))
                .on_hover_text("Undo (Ctrl+Z)")
                .clicked()
            {
                self.undo();
            }
            if ui
                .add_enabled(can_redo, egui::Button::new("⟳ Redo"))
                .on_hover_text("Redo (Ctrl+Shift+Z)")
                .clicked()
            {
                self.redo();
            }
        });
    }

    fn tools_ui(&mut self, ui: &mut egui::Ui) {
        ui.add_space(4.0);
        for (group, tools) in TOOL_GROUPS {
            ui.label(RichText::new(group).small().strong());
            for &tool in tools {
                let text = format!("{}  {}", tool.icon(), tool.label());
                let button = egui::Button::selectable(self.tool == tool, text)
                    .min_size(egui::vec2(ui.available_width(), 24.0));
                if ui
                    .add(button)
                    .on_hover_text(format!("{} ({})", tool.hint(), tool.shortcut().name()))
                    .clicked()
                {
                    self.select_tool(tool);
                }
            }
            ui.add_space(6.0);
        }
    }

    fn side_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            for (tab, name) in [
                (SideTab::Segments, "Segments"),
                (SideTab::Branches, "Branches"),
                (SideTab::History, "History"),
                (SideTab::Scene, "Scene"),
            ] {
                ui.selectable_value(&mut self.side_tab, tab, name);
            }
        });
        ui.separator();
        match self.side_tab {
            SideTab::Segments => self.segments_ui(ui),
            SideTab::Branches => self.branches_ui(ui),
            SideTab::History => self.history_ui(ui),
            SideTab::Scene => {
                if let Some(workspace) = self.workspace.as_deref() {
                    scene_ui(ui, workspace, &mut self.panel);
                }
            }
        }
    }

    fn segments_ui(&mut self, ui: &mut egui::Ui) {
        let Some(workspace) = self.workspace.as_deref_mut() else {
            return;
        };
        let (leaves, confirmed, other) = workspace.segment_counts();
        let points = workspace.session.segmentation().points.len();
        egui::Grid::new("segment_counts")
            .num_columns(2)
            .show(ui, |ui| {
                ui.label("Points");
                ui.label(points.to_string());
                ui.end_row();
                ui.label("Leaf segments");
                ui.label(format!("{leaves} ({confirmed} confirmed)"));
                ui.end_row();
                ui.label("Non-leaf segments");
                ui.label(other.to_string());
                ui.end_row();
            });
        ui.separator();
        ui.horizontal(|ui| {
            let caption = ui.label("Mark non-leaf as");
            egui::ComboBox::from_id_salt("non_leaf_label")
                .selected_text(format!("{:?}", self.panel.non_leaf_label))
                .show_ui(ui, |ui| {
                    for label in [SegmentLabel::Stem, SegmentLabel::Pot, SegmentLabel::Other] {
                        ui.selectable_value(
                            &mut self.panel.non_leaf_label,
                            label,
                            format!("{label:?}"),
                        );
                    }
                })
                .response
                .labelled_by(caption.id);
        });
        ui.separator();
        ui.strong("Generic leaf");
        match workspace.generic_leaf {
            Some(pick) => {
                ui.horizontal(|ui| {
                    let view = pick.view.map_or_else(
                        || "best view".to_owned(),
                        |v| {
                            workspace.session.scene().reconstruction.images()[v]
                                .name
                                .clone()
                        },
                    );
                    ui.label(format!("segment {} in {view}", pick.segment));
                    if ui.small_button("Automatic").clicked() {
                        workspace.generic_leaf = None;
                    }
                });
            }
            None => {
                ui.label("automatic (the most frontal, whole, large leaf)");
            }
        }
        ui.separator();
        let up_to_date = workspace.current_leaves().is_some();
        let fit_summary = workspace.leaves.as_ref().map(|(_, l)| {
            (
                l.leaves.len(),
                l.skipped.len(),
                l.template_source.map(|t| t.segment),
            )
        });
        let busy = self.job.is_some();
        if ui
            .add_enabled(!busy, egui::Button::new("🍃  Fit leaves"))
            .on_hover_text("Reconstruct every leaf segment: PCA plane, ICP to the image boundary, deformation, texture")
            .clicked()
        {
            self.fit_leaves();
        }
        match fit_summary {
            Some((fitted, skipped, template)) => {
                ui.label(format!(
                    "{fitted} leaves fitted, {skipped} skipped{}{}",
                    template
                        .map_or_else(String::new, |t| format!("; generic leaf from segment {t}")),
                    if up_to_date {
                        ""
                    } else {
                        " — outdated by later edits"
                    }
                ));
            }
            None => {
                ui.label("Leaves not fitted yet.");
            }
        }
    }

    fn branches_ui(&mut self, ui: &mut egui::Ui) {
        let busy = self.job.is_some();
        let Some(workspace) = self.workspace.as_deref() else {
            return;
        };
        let tree = workspace.session.branches();
        let (history, cursor) = workspace.session.history();
        let position = (history.len(), cursor);
        let fresh = self
            .support
            .as_ref()
            .is_some_and(|c| c.position == position && c.tree == *tree);
        if !fresh && !busy {
            self.support = Some(SupportCache {
                position,
                tree: tree.clone(),
                support: workspace.session.branch_support(),
            });
        }
        let support = self.support.as_ref().filter(|c| c.tree == *tree);
        if let Some(cache) = support {
            let summary = frond::pipeline::SupportSummary::new(&cache.support);
            let total = summary.observed_length + summary.bridged_length;
            if total > 0.0 {
                ui.label(format!(
                    "Observed {:.0} % of the branch length; {} mostly bridged",
                    100.0 * summary.observed_length / total,
                    summary.mostly_bridged.len()
                ))
                .on_hover_text(
                    "Observed: points lie along the branch. Bridged: drawn across a gap or \
                     an occlusion where no point is; check those branches in the photos.",
                );
            }
        }
        let initial = workspace.session.initial_skeleton();
        ui.label(format!("{} branches", tree.branches.len()));
        if let Some(error) = &initial.error {
            ui.colored_label(
                ui.visuals().warn_fg_color,
                format!("No automatic skeleton: {error}"),
            );
        }
        let mut run_skeleton = false;
        if ui
            .add_enabled(!busy, egui::Button::new("🌳  Automatic skeleton"))
            .on_hover_text("Replace the branches by the skeleton of the non-leaf points (undoable)")
            .clicked()
        {
            run_skeleton = true;
        }
        ui.separator();
        TableBuilder::new(ui)
            .striped(true)
            .column(Column::auto().at_least(28.0))
            .column(Column::auto().at_least(44.0))
            .column(Column::auto().at_least(64.0))
            .column(Column::auto().at_least(90.0))
            .column(Column::auto().at_least(64.0))
            .column(Column::remainder())
            .header(20.0, |mut header| {
                for title in ["Id", "Parent", "Length", "Radius", "Observed", "Tip leaf"] {
                    header.col(|ui| {
                        ui.strong(title);
                    });
                }
            })
            .body(|body| {
                body.rows(18.0, tree.branches.len(), |mut row| {
                    let branch = &tree.branches[row.index()];
                    row.col(|ui| {
                        ui.label(branch.id.to_string());
                    });
                    row.col(|ui| {
                        ui.label(branch.parent.map_or("—".into(), |p| p.to_string()));
                    });
                    row.col(|ui| {
                        ui.label(format!("{:.1} mm", branch.cylinder.length() * 1e3));
                    });
                    row.col(|ui| {
                        ui.label(format!(
                            "{:.2}–{:.2} mm",
                            branch.cylinder.radius_start * 1e3,
                            branch.cylinder.radius_end * 1e3
                        ));
                    });
                    row.col(|ui| {
                        let observed = support
                            .and_then(|c| c.support.iter().find(|s| s.id == branch.id))
                            .map(|s| s.observed_fraction());
                        match observed {
                            Some(f) if f < 0.5 => {
                                ui.colored_label(
                                    ui.visuals().warn_fg_color,
                                    format!("{:.0} %", 100.0 * f),
                                );
                            }
                            Some(f) => {
                                ui.label(format!("{:.0} %", 100.0 * f));
                            }
                            None => {
                                ui.label("…");
                            }
                        }
                    });
                    row.col(|ui| {
                        ui.label(if branch.leaf_at_tip { "yes" } else { "" });
                    });
                });
            });
        if run_skeleton {
            self.automatic_skeleton();
        }
    }

    fn history_ui(&mut self, ui: &mut egui::Ui) {
        let Some(workspace) = self.workspace.as_deref_mut() else {
            return;
        };
        let (entries, position) = {
            let (history, position) = workspace.session.history();
            let entries: Vec<String> = history.iter().map(|c| c.describe()).collect();
            (entries, position)
        };
        ui.label(format!("{position} of {} edits applied", entries.len()));
        ui.separator();
        let mut go_to = None;
        egui::ScrollArea::vertical().show(ui, |ui| {
            if ui
                .add(egui::Button::selectable(
                    position == 0,
                    "⏺  Automatic segmentation",
                ))
                .clicked()
            {
                go_to = Some(0);
            }
            for (index, text) in entries.iter().enumerate() {
                let applied = index < position;
                let label = format!("{:>3}  {text}", index + 1);
                let rich = if applied {
                    RichText::new(label)
                } else {
                    RichText::new(label).weak().italics()
                };
                if ui
                    .add(egui::Button::selectable(index + 1 == position, rich))
                    .clicked()
                {
                    go_to = Some(index + 1);
                }
            }
        });
        if let Some(target) = go_to {
            self.panel.cancel_gesture();
            workspace.go_to(target);
        }
    }

    fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if let Some(job) = &self.job {
                let (stage, fraction) = job.progress.snapshot();
                ui.spinner();
                ui.label(format!("{} — {stage}", job.title));
                let bar = match fraction {
                    Some(f) => egui::ProgressBar::new(f).show_percentage(),
                    None => egui::ProgressBar::new(0.0).animate(true),
                };
                ui.add(bar.desired_width(200.0));
                if ui.button("Cancel").clicked() {
                    job.progress.cancel();
                }
            } else if let Some(status) = &self.status {
                if status.is_error {
                    ui.colored_label(ui.visuals().error_fg_color, format!("⚠ {}", status.text));
                } else {
                    ui.label(&status.text);
                }
            } else if self.workspace.is_none() {
                ui.label("Open a folder of photos, a COLMAP folder (images/ + sparse/0, dense/0 or a model folder) or a .frond project.");
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                if self.show_frame_time {
                    ui.monospace(self.frame_time_text());
                }
                if let Some(workspace) = &self.workspace {
                    if workspace.is_dirty() {
                        ui.colored_label(ui.visuals().warn_fg_color, "• unsaved");
                    } else if workspace.project_path.is_some() {
                        ui.label("saved");
                    } else {
                        ui.weak("no edits");
                    }
                }
            });
        });
    }

    fn central_ui(&mut self, ui: &mut egui::Ui) {
        if let Some(autosave) = self.recovery.clone() {
            egui::Frame::group(ui.style())
                .fill(ui.visuals().faint_bg_color)
                .show(ui, |ui| {
                    ui.horizontal(|ui| {
                        ui.label(format!(
                            "Edits from an earlier session that were not saved are in the autosave {}.",
                            autosave.display()
                        ));
                        if ui.button("Recover").clicked() {
                            self.recover();
                        }
                        if ui.button("Discard").clicked() {
                            self.discard_recovery();
                        }
                    });
                });
        }
        let Some(workspace) = self.workspace.as_deref() else {
            if let Some(job) = &self.job {
                job_card(ui, job);
            } else if let Some(message) = &self.open_error {
                ui.heading("Could not open the scene");
                ui.label(message.as_str());
            } else {
                self.welcome_ui(ui);
            }
            return;
        };
        ui.horizontal(|ui| {
            for (layout, name) in [
                (CentralLayout::Photo, "Photo"),
                (CentralLayout::ThreeD, "3D"),
                (CentralLayout::Both, "Photo + 3D"),
            ] {
                ui.selectable_value(&mut self.layout, layout, name);
            }
            ui.separator();
            ui.label(
                RichText::new(format!("{}  {}", self.tool.icon(), self.tool.label())).strong(),
            );
            ui.label(RichText::new(self.tool.hint()).weak());
        });
        let mut actions = Vec::new();
        match self.layout {
            CentralLayout::Photo => actions = self.panel.ui(ui, workspace, self.tool),
            CentralLayout::ThreeD => actions = self.view3d.ui(ui, workspace, self.gpu, self.tool),
            CentralLayout::Both => {
                let (panel, view3d, tool, gpu) =
                    (&mut self.panel, &mut self.view3d, self.tool, self.gpu);
                ui.columns(2, |columns| {
                    actions = panel.ui(&mut columns[0], workspace, tool);
                    actions.extend(view3d.ui(&mut columns[1], workspace, gpu, tool));
                });
            }
        }
        if self.show_frame_time {
            let points = workspace.session.segmentation().points.len();
            let rect = ui.min_rect();
            ui.painter().text(
                rect.right_top() + egui::vec2(-10.0, 28.0),
                egui::Align2::RIGHT_TOP,
                format!(
                    "{} · {points} points\n{}",
                    self.frame_time_text(),
                    self.rebuild_text()
                ),
                egui::FontId::monospace(12.0),
                Color32::from_gray(200),
            );
        }
        for action in actions {
            match action {
                Action::Apply(command) => self.apply(command),
                Action::SetGenericLeaf(pick) => {
                    if let Some(workspace) = self.workspace.as_deref_mut() {
                        workspace.generic_leaf = Some(pick);
                    }
                    self.info(format!("generic leaf: segment {}", pick.segment));
                }
                Action::Message(text) => self.info(text),
            }
        }
    }

    fn welcome_ui(&mut self, ui: &mut egui::Ui) {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.25);
            ui.heading("Frond");
            ui.label("Image-based plant modeling: from photos of a plant to an editable 3D model.");
            ui.add_space(12.0);
            if ui
                .button("📂  Open photos, a COLMAP folder or a project…")
                .clicked()
            {
                self.show_open_dialog();
            }
            if !self.recent.is_empty() {
                ui.add_space(12.0);
                ui.strong("Recent");
                for path in self.recent.clone() {
                    if ui.link(path.display().to_string()).clicked() {
                        self.open(path);
                    }
                }
            }
        });
    }

    fn dialog_ui(&mut self, ctx: &egui::Context) {
        let Some(mut dialog) = self.dialog.take() else {
            return;
        };
        let mut keep = true;
        let mut open = None;
        let mut save = None;
        let mut export = None;
        let mut close = None;
        let modal = egui::Modal::new(egui::Id::unique("frond_dialog")).show(ctx, |ui| {
            ui.set_width(560.0);
            match &mut dialog {
                Dialog::Open {
                    folder,
                    path,
                    entries,
                } => {
                    ui.heading("Open");
                    ui.label("A folder of photos (COLMAP and stereo run first, into a _frond folder beside it), a COLMAP project (images/ + sparse/0), a dense/0 workspace, a model folder, or a .frond project.");
                    let mut navigate = None;
                    ui.horizontal(|ui| {
                        if ui.button("⬆").on_hover_text("Parent folder").clicked()
                            && let Some(parent) = folder.parent()
                        {
                            navigate = Some(parent.to_path_buf());
                        }
                        ui.label(folder.display().to_string());
                    });
                    egui::ScrollArea::vertical().max_height(280.0).show(ui, |ui| {
                        match entries {
                            Ok(entries) => {
                                for entry in entries.iter() {
                                    let icon = if entry.is_dir { "📁" } else { "🌿" };
                                    let response = ui.selectable_label(
                                        *path == entry.path.display().to_string(),
                                        format!("{icon} {}", entry.name),
                                    );
                                    if response.clicked() {
                                        *path = entry.path.display().to_string();
                                    }
                                    if response.double_clicked() {
                                        if entry.is_dir {
                                            navigate = Some(entry.path.clone());
                                        } else {
                                            open = Some(entry.path.clone());
                                        }
                                    }
                                }
                            }
                            Err(message) => {
                                ui.colored_label(ui.visuals().error_fg_color, message.as_str());
                            }
                        }
                    });
                    if let Some(next) = navigate {
                        dialog = open_dialog(next);
                        return;
                    }
                    ui.add(egui::TextEdit::singleline(path).desired_width(f32::INFINITY));
                    ui.horizontal(|ui| {
                        if ui.button("Open").clicked() && !path.trim().is_empty() {
                            open = Some(PathBuf::from(path.trim()));
                        }
                        if ui.button("Cancel").clicked() {
                            keep = false;
                        }
                    });
                }
                Dialog::SaveAs { path } => {
                    ui.heading("Save project as");
                    ui.add(egui::TextEdit::singleline(path).desired_width(f32::INFINITY));
                    ui.horizontal(|ui| {
                        if ui.button("Save").clicked() && !path.trim().is_empty() {
                            let mut file = PathBuf::from(path.trim());
                            if file.extension().is_none_or(|e| e != "frond") {
                                file.set_extension("frond");
                            }
                            save = Some(file);
                        }
                        if ui.button("Cancel").clicked() {
                            keep = false;
                        }
                    });
                }
                Dialog::ConfirmClose => {
                    let name = self.workspace.as_ref().map_or_else(String::new, |w| w.name());
                    ui.heading("Unsaved edits");
                    ui.label(format!(
                        "Save the edits to {name} before closing? Without saving they are lost."
                    ));
                    ui.horizontal(|ui| {
                        if ui.button("Save").clicked() {
                            close = Some(true);
                        }
                        if ui.button("Close without saving").clicked() {
                            close = Some(false);
                        }
                        if ui.button("Cancel").clicked() {
                            keep = false;
                        }
                    });
                }
                Dialog::Export { path } => {
                    ui.heading("Export");
                    ui.label("Writes plant.glb, plant.obj (+ materials and texture atlas), segmentation.ply, segments.json, skeleton.json and report.json into the folder, as frond reconstruct does; leaves are fitted first if needed.");
                    ui.add(egui::TextEdit::singleline(path).desired_width(f32::INFINITY));
                    ui.horizontal(|ui| {
                        if ui.button("Export").clicked() && !path.trim().is_empty() {
                            export = Some(PathBuf::from(path.trim()));
                        }
                        if ui.button("Cancel").clicked() {
                            keep = false;
                        }
                    });
                }
            }
        });
        if modal.should_close() {
            keep = false;
        }
        if let Some(path) = open {
            self.open(path);
            keep = false;
        }
        let saved = save.is_some();
        if let Some(path) = save {
            self.save_as(path);
            keep = false;
        }
        if let Some(folder) = export {
            self.export(folder);
            keep = false;
        }
        match close {
            Some(true) => {
                keep = false;
                self.close_after_save = true;
                self.save();
            }
            Some(false) => {
                keep = false;
                self.close_confirmed = true;
                if let (Some(config), Some(workspace)) = (&self.config, &self.workspace) {
                    remove_autosave(config, workspace);
                }
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            None => {}
        }
        // A save-as dialog the close prompt opened and the user cancelled: stay open.
        if !keep && !saved && matches!(dialog, Dialog::SaveAs { .. }) {
            self.close_after_save = false;
        }
        if keep {
            self.dialog = Some(dialog);
        }
    }

    fn help_ui(&mut self, ctx: &egui::Context) {
        let mut open = self.show_help;
        egui::Window::new("Shortcuts")
            .open(&mut open)
            .resizable(false)
            .pivot(egui::Align2::CENTER_CENTER)
            .default_pos(ctx.content_rect().center())
            .show(ctx, |ui| {
                egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                    let general = [
                        ("Ctrl+O", "Open a COLMAP folder or project"),
                        ("Ctrl+S / Ctrl+Shift+S", "Save / save as"),
                        ("Ctrl+E", "Export glb, OBJ, PLY"),
                        ("Ctrl+Z / Ctrl+Shift+Z", "Undo / redo"),
                        ("Left / Right", "Previous / next photo"),
                        ("F", "Fit the photo to the panel"),
                        ("Scroll, middle or right drag", "Zoom, pan"),
                        ("Esc", "Cancel the stroke or first click"),
                        ("F1", "This help"),
                        ("F12", "Frame time"),
                    ];
                    for (keys, what) in general {
                        ui.monospace(keys);
                        ui.label(what);
                        ui.end_row();
                    }
                    for tool in Tool::all() {
                        ui.monospace(tool.shortcut().name());
                        ui.label(format!("{}: {}", tool.label(), tool.hint()));
                        ui.end_row();
                    }
                });
            });
        self.show_help = open;
    }
}

fn job_card(ui: &mut egui::Ui, job: &Job<Outcome>) {
    ui.vertical_centered(|ui| {
        ui.add_space(ui.available_height() * 0.3);
        ui.heading(&job.title);
        let (stage, fraction) = job.progress.snapshot();
        ui.label(format!(
            "{stage} · {:.0} s",
            job.started.elapsed().as_secs_f64()
        ));
        let bar = match fraction {
            Some(f) => egui::ProgressBar::new(f).show_percentage(),
            None => egui::ProgressBar::new(0.0).animate(true),
        };
        ui.add(bar.desired_width(360.0));
        if ui.button("Cancel").clicked() {
            job.progress.cancel();
        }
    });
}

fn scene_ui(ui: &mut egui::Ui, workspace: &Workspace, panel: &mut ImagePanel) {
    let scene = workspace.session.scene();
    let model = &scene.reconstruction;
    ui.label(format!(
        "{} cameras · {} images · {} points · {} observations · {} format",
        model.cameras().len(),
        model.images().len(),
        model.points().len(),
        model.num_observations(),
        scene.format
    ));
    ui.separator();
    for camera in model.cameras() {
        egui::CollapsingHeader::new(format!(
            "Camera {} · {} · {}×{}",
            camera.id, camera.model, camera.width, camera.height
        ))
        .id_salt(("camera", camera.id))
        .show(ui, |ui| {
            egui::Grid::new(("camera_params", camera.id))
                .striped(true)
                .show(ui, |ui| {
                    for (name, value) in camera.model.param_names().split(", ").zip(camera.params())
                    {
                        ui.label(name);
                        ui.monospace(format!("{value:.6}"));
                        ui.end_row();
                    }
                });
        });
    }
    ui.separator();
    TableBuilder::new(ui)
        .striped(true)
        .resizable(true)
        .column(Column::auto().at_least(36.0))
        .column(Column::initial(140.0).at_least(60.0))
        .column(Column::auto().at_least(60.0))
        .column(Column::remainder())
        .header(20.0, |mut header| {
            for title in ["Id", "Name", "Points", "File"] {
                header.col(|ui| {
                    ui.strong(title);
                });
            }
        })
        .body(|body| {
            body.rows(18.0, model.images().len(), |mut row| {
                let index = row.index();
                let image = &model.images()[index];
                row.set_selected(panel.view == index);
                row.col(|ui| {
                    ui.label(image.id.to_string());
                });
                row.col(|ui| {
                    ui.label(&image.name);
                });
                row.col(|ui| {
                    ui.label(image.num_observations().to_string());
                });
                row.col(|ui| {
                    let status = &workspace.image_status[index];
                    let text = file_status_text(status);
                    if *status == ImageFileStatus::Present {
                        ui.label(text);
                    } else {
                        ui.colored_label(ui.visuals().warn_fg_color, text);
                    }
                });
                if row.response().clicked() {
                    panel.select_view(index);
                }
            });
        });
}

impl eframe::App for FrondApp {
    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        visuals.panel_fill.to_normalized_gamma_f32()
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        self.report_frame_time(frame.info().cpu_usage);
        self.window_ui(ui);
    }
}
