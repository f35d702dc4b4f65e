//! Scene input (seed 004 §4): a COLMAP reconstruction (cameras, registered images, 3D points
//! with tracks), the photos, and optionally COLMAP's fused dense points.
//!
//! [`Scene::open`] understands the folder layouts users have: a COLMAP project (`images/` +
//! `sparse/0/` or `sparse/`), an undistorted `dense/0/` workspace, a bare model folder, or an
//! explicit model and images folder. Images are loaded lazily through OpenCV and checked
//! against their camera's size.
//!
//! Takes a folder (or explicit model and images folders); returns a [`Scene`]. Writes COLMAP
//! models in both formats.

pub mod camera;
pub mod dense;
pub mod error;
pub mod io;
pub mod io_binary;
pub mod io_text;
pub mod model;
pub mod ply;
pub mod stats;
pub mod synthetic;
pub mod view;

use std::path::{Path, PathBuf};

use serde::Serialize;

pub use camera::{Camera, CameraId, CameraModelKind};
pub use dense::DensePoints;
pub use error::{SceneError, SceneResult};
pub use io::{ModelFormat, read_model, write_model};
pub use model::{Image, ImageId, Keypoint, Point3D, Point3dId, Reconstruction, TrackElement};
pub use view::{PhotoView, ViewProjection};

/// How a scene's folders were found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LayoutKind {
    /// `PROJECT/images` + `PROJECT/sparse/N` or `PROJECT/sparse`.
    Project,
    /// An undistorted workspace: `DENSE/images` + `DENSE/sparse` (+ `fused.ply`).
    Dense,
    /// The path was the model folder itself.
    ModelFolder,
    /// Model and images given explicitly.
    Explicit,
}

/// Where a scene's model, images and dense points live.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneSource {
    pub layout: LayoutKind,
    pub model_dir: PathBuf,
    pub images_dir: Option<PathBuf>,
    pub fused_ply: Option<PathBuf>,
    /// Other models found beside the chosen one (e.g. `sparse/1`).
    pub other_models: Vec<PathBuf>,
}

fn existing_dir(path: PathBuf) -> Option<PathBuf> {
    path.is_dir().then_some(path)
}

fn existing_file(path: PathBuf) -> Option<PathBuf> {
    path.is_file().then_some(path)
}

/// Numbered model folders `dir/0`, `dir/1`, … that hold a model, in numeric order.
fn numbered_models(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut models: Vec<(u64, PathBuf)> = entries
        .filter_map(Result::ok)
        .filter_map(|e| {
            let n: u64 = e.file_name().to_str()?.parse().ok()?;
            let path = e.path();
            io::detect_format(&path).map(|_| (n, path))
        })
        .collect();
    models.sort();
    models.into_iter().map(|(_, p)| p).collect()
}

impl SceneSource {
    /// Finds the model, images and dense points under `path` (see the module docs).
    pub fn locate(path: &Path) -> SceneResult<Self> {
        if !path.exists() {
            return Err(SceneError::layout(path, "does not exist"));
        }
        if io::detect_format(path).is_some() {
            // A model folder: sparse/N, sparse (dense workspace), or anywhere.
            let parent = path.parent();
            let is_sparse = |p: &Path| p.file_name().is_some_and(|n| n == "sparse");
            let (images_dir, fused_ply) = if is_sparse(path) {
                let root = parent.unwrap_or(Path::new("."));
                (
                    existing_dir(root.join("images")),
                    existing_file(root.join("fused.ply")),
                )
            } else if let Some(sparse) = parent.filter(|p| is_sparse(p)) {
                let root = sparse.parent().unwrap_or(Path::new("."));
                (existing_dir(root.join("images")), None)
            } else {
                (None, None)
            };
            return Ok(Self {
                layout: LayoutKind::ModelFolder,
                model_dir: path.to_path_buf(),
                images_dir,
                fused_ply,
                other_models: Vec::new(),
            });
        }
        let sparse = path.join("sparse");
        let mut numbered = numbered_models(&sparse);
        if !numbered.is_empty() {
            let model_dir = numbered.remove(0);
            return Ok(Self {
                layout: LayoutKind::Project,
                model_dir,
                images_dir: existing_dir(path.join("images")),
                fused_ply: None,
                other_models: numbered,
            });
        }
        if io::detect_format(&sparse).is_some() {
            let fused_ply = existing_file(path.join("fused.ply"));
            return Ok(Self {
                layout: if fused_ply.is_some() || path.join("stereo").is_dir() {
                    LayoutKind::Dense
                } else {
                    LayoutKind::Project
                },
                model_dir: sparse,
                images_dir: existing_dir(path.join("images")),
                fused_ply,
                other_models: Vec::new(),
            });
        }
        let dense = path.join("dense").join("0");
        if io::detect_format(&dense.join("sparse")).is_some() {
            return Ok(Self {
                layout: LayoutKind::Dense,
                model_dir: dense.join("sparse"),
                images_dir: existing_dir(dense.join("images")),
                fused_ply: existing_file(dense.join("fused.ply")),
                other_models: Vec::new(),
            });
        }
        Err(SceneError::layout(
            path,
            "no COLMAP model found: looked for model files in the folder itself, in sparse/0 (and sparse/N), sparse/ and dense/0/sparse/",
        ))
    }

    /// An explicit model folder and optional images folder.
    pub fn explicit(model_dir: &Path, images_dir: Option<&Path>) -> SceneResult<Self> {
        if io::detect_format(model_dir).is_none() {
            return Err(SceneError::layout(
                model_dir,
                "no complete COLMAP model (cameras, images, points3D in .bin or .txt)",
            ));
        }
        if let Some(images) = images_dir
            && !images.is_dir()
        {
            return Err(SceneError::layout(images, "images folder does not exist"));
        }
        Ok(Self {
            layout: LayoutKind::Explicit,
            model_dir: model_dir.to_path_buf(),
            images_dir: images_dir.map(Path::to_path_buf),
            fused_ply: None,
            other_models: Vec::new(),
        })
    }
}

/// A loaded scene: the model, where it came from, and optional dense points.
#[derive(Clone, Debug)]
pub struct Scene {
    pub source: SceneSource,
    pub format: ModelFormat,
    pub reconstruction: Reconstruction,
    pub dense: Option<DensePoints>,
}

/// Whether an image file exists and matches its camera.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "status")]
pub enum ImageFileStatus {
    Present,
    NoImagesFolder,
    Missing,
    Unreadable {
        reason: String,
    },
    SizeMismatch {
        file: (u32, u32),
        camera: (u32, u32),
    },
}

impl Scene {
    /// Opens the scene under `path` (any supported layout).
    pub fn open(path: &Path) -> SceneResult<Self> {
        Self::from_source(SceneSource::locate(path)?)
    }

    /// Loads the model (and dense points, if any) of a located source.
    pub fn from_source(source: SceneSource) -> SceneResult<Self> {
        let (reconstruction, format) = io::read_model(&source.model_dir)?;
        let dense = match &source.fused_ply {
            Some(ply) => Some(dense::read_fused(ply, &reconstruction)?),
            None => None,
        };
        tracing::info!(
            model = %source.model_dir.display(),
            %format,
            cameras = reconstruction.cameras().len(),
            images = reconstruction.images().len(),
            points = reconstruction.points().len(),
            "loaded COLMAP model"
        );
        Ok(Self {
            source,
            format,
            reconstruction,
            dense,
        })
    }

    /// The file of a registered image, if the scene has an images folder.
    pub fn image_path(&self, image: &Image) -> Option<PathBuf> {
        self.source
            .images_dir
            .as_ref()
            .map(|dir| dir.join(&image.name))
    }

    /// Checks an image file's presence and size (reads only the file header).
    pub fn image_file_status(&self, image: &Image) -> ImageFileStatus {
        let Some(path) = self.image_path(image) else {
            return ImageFileStatus::NoImagesFolder;
        };
        if !path.is_file() {
            return ImageFileStatus::Missing;
        }
        let camera = self.reconstruction.camera_of(image);
        match ::image::image_dimensions(&path) {
            Ok(size) if size == (camera.width, camera.height) => ImageFileStatus::Present,
            Ok(size) => ImageFileStatus::SizeMismatch {
                file: size,
                camera: (camera.width, camera.height),
            },
            Err(e) => ImageFileStatus::Unreadable {
                reason: e.to_string(),
            },
        }
    }

    /// Loads an image through OpenCV as 8-bit BGR, checking its size against its camera.
    pub fn load_image(&self, image: &Image) -> SceneResult<opencv::core::Mat> {
        use opencv::prelude::*;
        let image_error = |path: &Path, message: String| SceneError::Image {
            path: path.to_path_buf(),
            image_id: image.id,
            message,
        };
        let path = self.image_path(image).ok_or_else(|| {
            image_error(
                &self.source.model_dir,
                format!("no images folder for '{}'", image.name),
            )
        })?;
        if !path.is_file() {
            return Err(image_error(&path, "file is missing".to_owned()));
        }
        let path_str = path
            .to_str()
            .ok_or_else(|| image_error(&path, "path is not UTF-8".to_owned()))?;
        let mat = opencv::imgcodecs::imread(path_str, opencv::imgcodecs::IMREAD_COLOR)
            .map_err(|e| image_error(&path, format!("OpenCV could not read it: {e}")))?;
        if mat.empty() {
            return Err(image_error(
                &path,
                "OpenCV could not decode the file".to_owned(),
            ));
        }
        let camera = self.reconstruction.camera_of(image);
        let size = (mat.cols() as u32, mat.rows() as u32);
        if size != (camera.width, camera.height) {
            return Err(image_error(
                &path,
                format!(
                    "image is {}x{} but camera {} is {}x{}",
                    size.0, size.1, camera.id, camera.width, camera.height
                ),
            ));
        }
        Ok(mat)
    }
}
