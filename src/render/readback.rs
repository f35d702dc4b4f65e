//! Reading render targets back to the CPU: [`RenderOutput`] (colour, depth and object id per
//! pixel), and the copy of textures into mapped buffers with rows padded to wgpu's copy
//! alignment, unpadded again on the way out.

use std::sync::mpsc;

use image::RgbaImage;

use super::{RenderError, Renderer};

/// What one render produces.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    pub width: u32,
    pub height: u32,
    /// sRGB colour, 4× multisampled.
    pub color: RgbaImage,
    /// Camera-frame depth (z) per pixel, row-major; 0 where nothing was drawn.
    pub depth: Vec<f32>,
    /// Object id per pixel, row-major; 0 where nothing was drawn.
    pub object_id: Vec<u32>,
}

impl RenderOutput {
    /// Object id at pixel `(x, y)` (integer pixel indices).
    pub fn id_at(&self, x: u32, y: u32) -> u32 {
        self.object_id[(y * self.width + x) as usize]
    }

    /// Depth at pixel `(x, y)`.
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth[(y * self.width + x) as usize]
    }
}

fn padded_bytes_per_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let unpadded = width * bytes_per_pixel;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
}

impl Renderer {
    /// Copies 4-byte-per-pixel `textures` into mapped buffers, submits `encoder` and returns
    /// each texture's rows without padding.
    pub(super) fn submit_and_read(
        &self,
        mut encoder: wgpu::CommandEncoder,
        textures: &[&wgpu::Texture],
        width: u32,
        height: u32,
    ) -> Result<Vec<Vec<u8>>, RenderError> {
        let row = padded_bytes_per_row(width, 4);
        let buffers: Vec<wgpu::Buffer> = textures
            .iter()
            .map(|texture| {
                let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size: (row * height) as u64,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                    mapped_at_creation: false,
                });
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d::ZERO,
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer: &buffer,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(height),
                        },
                    },
                    wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                );
                buffer
            })
            .collect();
        self.queue.submit([encoder.finish()]);
        let mut unpadded = Vec::with_capacity(buffers.len());
        for buffer in &buffers {
            let (sender, receiver) = mpsc::channel();
            buffer.map_async(wgpu::MapMode::Read, .., move |result| {
                let _ = sender.send(result);
            });
            self.device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| RenderError::Readback(e.to_string()))?;
            receiver
                .recv()
                .map_err(|e| RenderError::Readback(e.to_string()))?
                .map_err(|e| RenderError::Readback(e.to_string()))?;
            let data = buffer
                .get_mapped_range(..)
                .map_err(|e| RenderError::Readback(format!("{e:?}")))?;
            let mut out = Vec::with_capacity((width * height * 4) as usize);
            for y in 0..height as usize {
                let start = y * row as usize;
                out.extend_from_slice(&data[start..start + (width * 4) as usize]);
            }
            drop(data);
            buffer.unmap();
            unpadded.push(out);
        }
        Ok(unpadded)
    }
}
