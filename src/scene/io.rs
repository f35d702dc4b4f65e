//! Reading and writing whole COLMAP sparse models from a model folder, in either format.
//! Binary wins when both exist (as in COLMAP). Writes are atomic per file.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::{SceneError, SceneResult};
use super::model::{Reconstruction, compose_rig_poses};
use super::{io_binary, io_text};
use crate::util::atomic::write_atomic;

/// On-disk format of a COLMAP model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelFormat {
    Binary,
    Text,
}

impl ModelFormat {
    fn extension(self) -> &'static str {
        match self {
            ModelFormat::Binary => "bin",
            ModelFormat::Text => "txt",
        }
    }
}

impl std::fmt::Display for ModelFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelFormat::Binary => "binary",
            ModelFormat::Text => "text",
        })
    }
}

const CORE_FILES: [&str; 3] = ["cameras", "images", "points3D"];

/// Which complete model a folder holds: binary if all three `.bin` files exist, else text if
/// all three `.txt` files do; `None` otherwise.
pub fn detect_format(dir: &Path) -> Option<ModelFormat> {
    [ModelFormat::Binary, ModelFormat::Text]
        .into_iter()
        .find(|format| {
            CORE_FILES
                .iter()
                .all(|stem| dir.join(format!("{stem}.{}", format.extension())).is_file())
        })
}

/// Describes what model files a folder has, for error messages.
fn describe_missing(dir: &Path) -> String {
    let present: Vec<String> = CORE_FILES
        .iter()
        .flat_map(|stem| ["bin", "txt"].map(|ext| format!("{stem}.{ext}")))
        .filter(|name| dir.join(name).is_file())
        .collect();
    if present.is_empty() {
        "no COLMAP model files (cameras, images, points3D as .bin or .txt)".to_owned()
    } else {
        format!(
            "incomplete COLMAP model: found only {} (need cameras, images and points3D in one format)",
            present.join(", ")
        )
    }
}

fn read_file(path: &Path) -> SceneResult<Vec<u8>> {
    std::fs::read(path).map_err(|e| SceneError::io(path, e))
}

fn read_text(path: &Path) -> SceneResult<String> {
    let bytes = read_file(path)?;
    String::from_utf8(bytes).map_err(|e| SceneError::Parse {
        path: path.to_path_buf(),
        location: super::error::Location::Byte(e.utf8_error().valid_up_to() as u64),
        record: "file".to_owned(),
        message: "not valid UTF-8 text".to_owned(),
    })
}

/// Reads the complete model in `dir` and validates it.
pub fn read_model(dir: &Path) -> SceneResult<(Reconstruction, ModelFormat)> {
    let format =
        detect_format(dir).ok_or_else(|| SceneError::layout(dir, describe_missing(dir)))?;
    let model = read_model_with_format(dir, format)?;
    Ok((model, format))
}

/// Reads a model in the given format from `dir`.
pub fn read_model_with_format(dir: &Path, format: ModelFormat) -> SceneResult<Reconstruction> {
    let file = |stem: &str| -> PathBuf { dir.join(format!("{stem}.{}", format.extension())) };
    let (cameras_path, images_path, points_path) =
        (file("cameras"), file("images"), file("points3D"));
    let (rigs_path, frames_path) = (file("rigs"), file("frames"));
    // The three core files are read and parsed concurrently.
    let ((cameras, images), points) = match format {
        ModelFormat::Binary => rayon::join(
            || {
                rayon::join(
                    || io_binary::parse_cameras(&read_file(&cameras_path)?, &cameras_path),
                    || io_binary::parse_images(&read_file(&images_path)?, &images_path),
                )
            },
            || io_binary::parse_points(&read_file(&points_path)?, &points_path),
        ),
        ModelFormat::Text => rayon::join(
            || {
                rayon::join(
                    || io_text::parse_cameras(&read_text(&cameras_path)?, &cameras_path),
                    || io_text::parse_images(&read_text(&images_path)?, &images_path),
                )
            },
            || io_text::parse_points(&read_text(&points_path)?, &points_path),
        ),
    };
    let (cameras, mut images, points) = (cameras?, images?, points?);
    let rigs = if rigs_path.is_file() {
        match format {
            ModelFormat::Binary => io_binary::parse_rigs(&read_file(&rigs_path)?, &rigs_path)?,
            ModelFormat::Text => io_text::parse_rigs(&read_text(&rigs_path)?, &rigs_path)?,
        }
    } else {
        Vec::new()
    };
    let frames = if frames_path.is_file() {
        match format {
            ModelFormat::Binary => {
                io_binary::parse_frames(&read_file(&frames_path)?, &frames_path)?
            }
            ModelFormat::Text => io_text::parse_frames(&read_text(&frames_path)?, &frames_path)?,
        }
    } else {
        Vec::new()
    };
    // COLMAP ≥ 3.12 ignores the pose stored in images.* when frames exist; so do we.
    compose_rig_poses(&mut images, &rigs, &frames).map_err(|source| SceneError::Model {
        path: frames_path.clone(),
        source,
    })?;
    Reconstruction::from_parts_with_rigs(cameras, images, points, rigs, frames).map_err(|source| {
        SceneError::Model {
            path: dir.to_path_buf(),
            source,
        }
    })
}

/// Writes `model` into `dir` (created if needed) in `format`, each file atomically.
pub fn write_model(dir: &Path, model: &Reconstruction, format: ModelFormat) -> SceneResult<()> {
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    let files = match format {
        ModelFormat::Binary => io_binary::encode_model(model),
        ModelFormat::Text => io_text::encode_model(model),
    };
    for (name, bytes) in files {
        let path = dir.join(name);
        write_atomic(&path, &bytes).map_err(|e| SceneError::io(&path, e))?;
    }
    Ok(())
}
