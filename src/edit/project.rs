//! Project files (`*.frond`): versioned JSON with the input's location, the segmentation
//! parameters and the command history with the undo position. Written atomically (a temporary
//! file renamed over the old one): a crash during a save leaves the previous file. Reopening
//! replays the history on a fresh automatic segmentation, which is deterministic, so the state
//! is the same.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::command::Command;
use super::session::{EditError, Session};
use crate::scene::{Scene, SceneError, SceneSource};
use crate::segment::{SegmentError, SegmentOptions, segment_scene};
use crate::util::atomic::write_atomic;
use crate::util::progress::Progress;

/// The file format's name and current version.
pub const PROJECT_FORMAT: &str = "frond project";
pub const PROJECT_VERSION: u32 = 1;

/// Where the project's input lives. Relative paths are relative to the project file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProjectInput {
    pub model: PathBuf,
    #[serde(default)]
    pub images: Option<PathBuf>,
}

/// The contents of a project file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Project {
    pub format: String,
    pub version: u32,
    pub input: ProjectInput,
    pub segmentation: SegmentOptions,
    pub history: Vec<Command>,
    /// Commands before this index are applied; those after it can be redone.
    pub position: usize,
}

/// Project failures, each naming the file.
#[derive(Debug, thiserror::Error)]
pub enum ProjectError {
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Segment(#[from] SegmentError),
    #[error("{path}: command {index} ({description}) no longer applies: {source}")]
    Replay {
        path: PathBuf,
        index: usize,
        description: String,
        #[source]
        source: EditError,
    },
}

fn file_error(path: &Path, message: impl Into<String>) -> ProjectError {
    ProjectError::File {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// `path` relative to `base` when it lies under it, else absolute.
fn relative_to(path: &Path, base: &Path) -> PathBuf {
    let absolute = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
    let base = base.canonicalize().unwrap_or_else(|_| base.to_path_buf());
    absolute
        .strip_prefix(&base)
        .map(Path::to_path_buf)
        .unwrap_or(absolute)
}

impl Project {
    /// Reads and checks a project file.
    pub fn read(path: &Path) -> Result<Self, ProjectError> {
        let text = std::fs::read_to_string(path).map_err(|e| file_error(path, e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| file_error(path, format!("not JSON: {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(PROJECT_FORMAT) {
            return Err(file_error(path, "not a Frond project file"));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if version == 0 || version > PROJECT_VERSION as u64 {
            return Err(file_error(
                path,
                format!(
                    "project version {version} is not supported (this Frond reads up to {PROJECT_VERSION})"
                ),
            ));
        }
        let project: Project = serde_json::from_value(value)
            .map_err(|e| file_error(path, format!("malformed project: {e}")))?;
        if project.position > project.history.len() {
            return Err(file_error(
                path,
                format!(
                    "undo position {} beyond the {} commands",
                    project.position,
                    project.history.len()
                ),
            ));
        }
        Ok(project)
    }

    /// The project of a session, with input paths relative to `project_path`'s folder.
    pub fn of_session(session: &Session, project_path: &Path) -> Self {
        let base = project_path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let source = &session.scene().source;
        let (history, position) = session.history();
        Self {
            format: PROJECT_FORMAT.to_owned(),
            version: PROJECT_VERSION,
            input: ProjectInput {
                model: relative_to(&source.model_dir, base),
                images: source.images_dir.as_ref().map(|p| relative_to(p, base)),
            },
            segmentation: session.segmentation().options,
            history: history.into_iter().cloned().collect(),
            position,
        }
    }

    /// Writes the project atomically.
    pub fn write(&self, path: &Path) -> Result<(), ProjectError> {
        let text =
            serde_json::to_string_pretty(self).map_err(|e| file_error(path, e.to_string()))?;
        write_atomic(path, text.as_bytes()).map_err(|e| file_error(path, e.to_string()))
    }

    /// Loads the input, segments it and replays the history: the session as it was saved.
    pub fn open(
        &self,
        project_path: &Path,
        progress: &dyn Progress,
    ) -> Result<Session, ProjectError> {
        let base = project_path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let resolve = |p: &Path| {
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                base.join(p)
            }
        };
        let model = resolve(&self.input.model);
        let images = self.input.images.as_deref().map(resolve);
        let source = SceneSource::explicit(&model, images.as_deref())?;
        let scene = Scene::from_source(source)?;
        let segmentation = segment_scene(&scene, &self.segmentation, progress)?;
        let mut session = Session::new(scene, segmentation);
        progress.stage("replaying edits", self.history.len() as u64);
        for (index, command) in self.history.iter().enumerate() {
            session
                .apply(command.clone())
                .map_err(|source| ProjectError::Replay {
                    path: project_path.to_path_buf(),
                    index,
                    description: command.describe(),
                    source,
                })?;
            progress.advance(1);
        }
        for _ in self.position..self.history.len() {
            session.undo();
        }
        Ok(session)
    }
}

/// Saves a session as a project file.
pub fn save_session(session: &Session, path: &Path) -> Result<(), ProjectError> {
    Project::of_session(session, path).write(path)
}

/// Opens a project file into a session.
pub fn open_project(path: &Path, progress: &dyn Progress) -> Result<Session, ProjectError> {
    Project::read(path)?.open(path, progress)
}
