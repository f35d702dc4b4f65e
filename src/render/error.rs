//! Why a render can fail: [`RenderError`], shared by every part of the render core.

use crate::scene::CameraModelKind;

/// Render failures.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("no GPU adapter available (is mesa-vulkan-drivers installed?): {0}")]
    NoAdapter(String),
    #[error("could not create the GPU device: {0}")]
    Device(String),
    #[error(
        "camera {camera_id} uses {model}; the renderer needs a pinhole camera (undistort first)"
    )]
    UnsupportedCamera {
        camera_id: u32,
        model: CameraModelKind,
    },
    #[error("image size {width}x{height} is not renderable (limit {limit})")]
    Size { width: u32, height: u32, limit: u32 },
    #[error("mesh for object {object_id}: {message}")]
    Mesh { object_id: u32, message: String },
    #[error("no mesh with handle {0} in the scene")]
    UnknownMesh(usize),
    #[error("reading the render back failed: {0}")]
    Readback(String),
}
