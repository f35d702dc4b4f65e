//! Render core v1: a headless wgpu renderer (software Vulkan "llvmpipe" on CI, a real GPU where
//! there is one) for textured triangle meshes with alpha-tested materials and two-sided
//! Lambert + ambient lighting. Each render returns the colour image (4× MSAA), the camera-frame
//! depth and the object id of every pixel, read back to the CPU.
//!
//! Cameras come from COLMAP intrinsics and extrinsics with COLMAP's pixel convention, so a
//! render lines up with a COLMAP view to the pixel: the rasterizer samples pixel `(i, j)` at
//! `(i + 0.5, j + 0.5)`, which is where COLMAP puts that pixel's centre.
//!
//! What it takes: triangle meshes ([`TriMesh`](crate::mesh::TriMesh)) and RGBA textures,
//! uploaded once into a [`GpuScene`] (static meshes drawn by every render, or instanced meshes
//! drawn through [`InstanceBatch`]es of [`InstanceTransform`]s), then a [`ViewCamera`] (a
//! pinhole view, e.g. from a COLMAP camera and image pose) and [`Lighting`] per frame.
//!
//! What it returns: [`Renderer::render`] gives a [`RenderOutput`] (sRGB colour, camera-frame
//! depth and object id per pixel); [`Renderer::render_instanced`] gives the [`FrameStats`] of a
//! colour frame and, on request, its colour image; [`Renderer::encode_color_frame`] encodes a
//! colour frame into the caller's command encoder (the GUI), to be sampled through
//! [`Renderer::color_view`]. Failures are [`RenderError`]s.
//!
//! Submodules (all private; their public items are re-exported here):
//! - `error`: [`RenderError`].
//! - `device`: [`Renderer`] and its construction: adapter and device, shader, bind-group
//!   layouts, pipelines, sampler.
//! - `camera`: [`ViewCamera`]: COLMAP intrinsics and pose, the clip-space matrix, projection of
//!   world points to pixels.
//! - `targets`: texture formats, default multisampling, the render targets (made for the view
//!   size), the size check and the resolved colour view.
//! - `meshes`: [`GpuScene`], [`TextureHandle`], [`MeshHandle`], texture upload with mip chains
//!   (coverage-preserving for cut-outs), mesh upload and geometry replacement, instance
//!   transforms ([`InstanceTransform`], [`IDENTITY_INSTANCE`]).
//! - `passes`: [`Lighting`] and the view uniforms, the colour and id-and-depth passes, drawing
//!   static meshes and instance batches, and the frames [`Renderer::render`],
//!   [`Renderer::render_instanced`] ([`InstanceBatch`], [`FrameStats`]) and
//!   [`Renderer::encode_color_frame`].
//! - `depth_difference`: the depth-difference buffer of pen-and-ink outlines (seed 001 §4.3)
//!   as a compute pass ([`Renderer::depth_difference`],
//!   [`Renderer::render_with_depth_difference`]) and its CPU reference
//!   [`depth_difference_cpu`].
//! - `readback`: [`RenderOutput`] and copying textures back to the CPU (padded rows).

mod camera;
mod depth_difference;
mod device;
mod error;
mod meshes;
mod orbit;
mod passes;
mod readback;
mod targets;

#[cfg(test)]
mod tests;

pub use camera::ViewCamera;
pub use depth_difference::depth_difference_cpu;
pub use device::Renderer;
pub use error::RenderError;
pub use meshes::{
    BillboardViews, GpuScene, IDENTITY_INSTANCE, InstanceTransform, MeshHandle, Shading,
    TextureHandle,
};
pub use orbit::{FIELD_OF_VIEW_DEG, Orbit};
pub use passes::{FrameStats, InstanceBatch, Lighting};
pub use readback::RenderOutput;
