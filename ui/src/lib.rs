//! frond-ui: Frond's interactive GUI (egui/eframe on wgpu).
//!
//! The GUI owns no algorithm: it calls the `frond` library. This first version opens a COLMAP
//! folder (off the UI thread) and lists its cameras and images with their file status.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, channel};

use egui_extras::{Column, TableBuilder};
use frond::scene::{ImageFileStatus, Scene};

/// A scene ready to show: the model and each image's file status (computed once on load).
pub struct LoadedScene {
    pub scene: Scene,
    pub image_status: Vec<ImageFileStatus>,
}

impl LoadedScene {
    fn load(path: &Path) -> Result<Self, String> {
        let scene = Scene::open(path).map_err(|e| e.to_string())?;
        let image_status = scene
            .reconstruction
            .images()
            .iter()
            .map(|image| scene.image_file_status(image))
            .collect();
        Ok(Self {
            scene,
            image_status,
        })
    }
}

enum LoadState {
    Empty,
    Loading {
        path: PathBuf,
        result: Receiver<Result<LoadedScene, String>>,
    },
    Loaded(Box<LoadedScene>),
    Failed(String),
}

/// The application state.
pub struct FrondApp {
    path_input: String,
    state: LoadState,
    selected_image: Option<usize>,
}

impl FrondApp {
    /// A new window; starts loading `initial` when given.
    pub fn new(initial: Option<PathBuf>) -> Self {
        let mut app = Self {
            path_input: initial
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            state: LoadState::Empty,
            selected_image: None,
        };
        if let Some(path) = initial {
            app.open(path);
        }
        app
    }

    /// Starts loading a COLMAP folder on a worker thread.
    pub fn open(&mut self, path: PathBuf) {
        let (sender, receiver) = channel();
        let worker_path = path.clone();
        std::thread::spawn(move || {
            let _ = sender.send(LoadedScene::load(&worker_path));
        });
        self.selected_image = None;
        self.state = LoadState::Loading {
            path,
            result: receiver,
        };
    }

    /// The loaded scene, if any.
    pub fn loaded(&self) -> Option<&LoadedScene> {
        match &self.state {
            LoadState::Loaded(loaded) => Some(loaded),
            _ => None,
        }
    }

    /// The load error, if the last load failed.
    pub fn error(&self) -> Option<&str> {
        match &self.state {
            LoadState::Failed(message) => Some(message),
            _ => None,
        }
    }

    /// Whether a load is in progress.
    pub fn is_loading(&self) -> bool {
        matches!(self.state, LoadState::Loading { .. })
    }

    fn poll(&mut self, ctx: &egui::Context) {
        if let LoadState::Loading { result, .. } = &self.state {
            match result.try_recv() {
                Ok(Ok(loaded)) => self.state = LoadState::Loaded(Box::new(loaded)),
                Ok(Err(message)) => self.state = LoadState::Failed(message),
                Err(std::sync::mpsc::TryRecvError::Empty) => ctx.request_repaint(),
                Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                    self.state = LoadState::Failed("loading thread stopped unexpectedly".into())
                }
            }
        }
    }

    /// Draws the whole window.
    pub fn window_ui(&mut self, ui: &mut egui::Ui) {
        self.poll(ui.ctx());
        egui::Panel::top("toolbar").show(ui, |ui| self.toolbar_ui(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_ui(ui));
        if let LoadState::Loaded(loaded) = &self.state {
            egui::Panel::left("cameras")
                .default_size(320.0)
                .show(ui, |ui| cameras_ui(ui, loaded));
        }
        egui::CentralPanel::default().show(ui, |ui| self.central_ui(ui));
    }

    fn toolbar_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.strong("Frond");
            ui.separator();
            ui.label("COLMAP folder:");
            let edit = ui.add(
                egui::TextEdit::singleline(&mut self.path_input)
                    .hint_text("project, dense/0 or model folder")
                    .desired_width(ui.available_width() - 80.0),
            );
            let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if (ui.button("Open").clicked() || enter) && !self.path_input.trim().is_empty() {
                self.open(PathBuf::from(self.path_input.trim()));
            }
        });
    }

    fn status_ui(&self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| match &self.state {
            LoadState::Empty => {
                ui.label("Open a COLMAP project (images/ + sparse/0), a dense/0 workspace or a model folder.");
            }
            LoadState::Loading { path, .. } => {
                ui.spinner();
                ui.label(format!("Loading {} …", path.display()));
            }
            LoadState::Loaded(loaded) => {
                let model = &loaded.scene.reconstruction;
                ui.label(format!(
                    "{} cameras · {} images · {} points · {} observations · {} format",
                    model.cameras().len(),
                    model.images().len(),
                    model.points().len(),
                    model.num_observations(),
                    loaded.scene.format
                ));
            }
            LoadState::Failed(_) => {
                ui.colored_label(ui.visuals().error_fg_color, "Loading failed");
            }
        });
    }

    fn central_ui(&mut self, ui: &mut egui::Ui) {
        match &self.state {
            LoadState::Loaded(loaded) => {
                images_ui(ui, loaded, &mut self.selected_image);
            }
            LoadState::Failed(message) => {
                ui.heading("Could not open the scene");
                ui.label(message.as_str());
            }
            LoadState::Loading { .. } => {
                ui.centered_and_justified(|ui| ui.spinner());
            }
            LoadState::Empty => {
                ui.centered_and_justified(|ui| ui.label("No scene open"));
            }
        }
    }
}

fn cameras_ui(ui: &mut egui::Ui, loaded: &LoadedScene) {
    let model = &loaded.scene.reconstruction;
    ui.heading(format!("Cameras ({})", model.cameras().len()));
    ui.separator();
    egui::ScrollArea::vertical().show(ui, |ui| {
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
                        for (name, value) in
                            camera.model.param_names().split(", ").zip(camera.params())
                        {
                            ui.label(name);
                            ui.monospace(format!("{value:.6}"));
                            ui.end_row();
                        }
                    });
            });
        }
    });
}

fn status_text(status: &ImageFileStatus) -> String {
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

fn images_ui(ui: &mut egui::Ui, loaded: &LoadedScene, selected: &mut Option<usize>) {
    let model = &loaded.scene.reconstruction;
    let present = loaded
        .image_status
        .iter()
        .filter(|s| **s == ImageFileStatus::Present)
        .count();
    ui.heading(format!(
        "Images ({} registered, {present} files present)",
        model.images().len()
    ));
    ui.separator();
    TableBuilder::new(ui)
        .striped(true)
        .resizable(true)
        .column(Column::auto().at_least(50.0))
        .column(Column::initial(220.0).at_least(80.0))
        .column(Column::auto().at_least(60.0))
        .column(Column::auto().at_least(80.0))
        .column(Column::auto().at_least(90.0))
        .column(Column::remainder())
        .header(22.0, |mut header| {
            for title in ["Id", "Name", "Camera", "Keypoints", "Observations", "File"] {
                header.col(|ui| {
                    ui.strong(title);
                });
            }
        })
        .body(|body| {
            body.rows(20.0, model.images().len(), |mut row| {
                let index = row.index();
                let image = &model.images()[index];
                row.set_selected(*selected == Some(index));
                row.col(|ui| {
                    ui.label(image.id.to_string());
                });
                row.col(|ui| {
                    ui.label(&image.name);
                });
                row.col(|ui| {
                    ui.label(image.camera_id.to_string());
                });
                row.col(|ui| {
                    ui.label(image.keypoints.len().to_string());
                });
                row.col(|ui| {
                    ui.label(image.num_observations().to_string());
                });
                row.col(|ui| {
                    let status = &loaded.image_status[index];
                    let text = status_text(status);
                    if *status == ImageFileStatus::Present {
                        ui.label(text);
                    } else {
                        ui.colored_label(ui.visuals().warn_fg_color, text);
                    }
                });
                if row.response().clicked() {
                    *selected = Some(index);
                }
            });
        });
}

impl eframe::App for FrondApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.window_ui(ui);
    }
}
