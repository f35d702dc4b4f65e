//! Errors of the scene stage. Every variant names the file and, where there is one, the record
//! and the byte offset or line, so that a user can find the bad data.

use std::fmt;
use std::path::PathBuf;

use super::camera::CameraError;
use super::model::ModelError;

/// Where in a file a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    Byte(u64),
    Line(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Byte(offset) => write!(f, "byte {offset}"),
            Location::Line(line) => write!(f, "line {line}"),
        }
    }
}

/// Errors reading or writing COLMAP models, dense points and images.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A record could not be parsed.
    #[error("{path}: {location}: {record}: {message}")]
    Parse {
        path: PathBuf,
        location: Location,
        record: String,
        message: String,
    },
    /// A camera's intrinsics are invalid.
    #[error("{path}: {location}: camera {camera_id}: {source}")]
    Camera {
        path: PathBuf,
        location: Location,
        camera_id: u32,
        #[source]
        source: CameraError,
    },
    /// The files parse but do not form a consistent model.
    #[error("{path}: {source}")]
    Model {
        path: PathBuf,
        #[source]
        source: ModelError,
    },
    /// No model (or an incomplete one) where one was expected.
    #[error("{path}: {message}")]
    Layout { path: PathBuf, message: String },
    /// An image file is missing, unreadable or does not match its camera.
    #[error("{path}: image {image_id}: {message}")]
    Image {
        path: PathBuf,
        image_id: u32,
        message: String,
    },
}

impl SceneError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn layout(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Layout {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type SceneResult<T> = Result<T, SceneError>;
