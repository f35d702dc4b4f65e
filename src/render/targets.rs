//! Render targets: the texture formats and default multisampling of the passes, the targets
//! themselves (multisampled colour and depth, the resolved colour, object ids, camera-frame
//! depth), (re)made when the view size changes, the size check against the adapter's limit,
//! and the resolved colour exposed as a bindable view for the GUI.

use super::{RenderError, Renderer};

/// Multisampling of the colour pass (unless a renderer is made with another count).
pub(super) const COLOR_SAMPLES: u32 = 4;
pub(super) const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

pub(super) struct Targets {
    width: u32,
    height: u32,
    /// The multisampled colour target; `None` with one sample, when the colour pass draws
    /// straight into `color_resolved`.
    pub(super) color_msaa: Option<wgpu::TextureView>,
    pub(super) color_resolved: wgpu::Texture,
    pub(super) color_resolved_view: wgpu::TextureView,
    /// The same texels seen as plain `Rgba8Unorm` (sRGB-encoded bytes, no decoding).
    color_resolved_encoded_view: wgpu::TextureView,
    pub(super) depth_msaa: wgpu::TextureView,
    pub(super) id: wgpu::Texture,
    pub(super) linear_depth: wgpu::Texture,
    pub(super) depth_single: wgpu::TextureView,
}

impl Renderer {
    pub(super) fn ensure_targets(&mut self, width: u32, height: u32) {
        if self
            .targets
            .as_ref()
            .is_some_and(|t| t.width == width && t.height == height)
        {
            return;
        }
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label: &str, format, samples, usage| {
            let encoded = [wgpu::TextureFormat::Rgba8Unorm];
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: if format == COLOR_FORMAT && samples == 1 {
                    &encoded
                } else {
                    &[]
                },
            })
        };
        let attachment = wgpu::TextureUsages::RENDER_ATTACHMENT;
        let readable = attachment | wgpu::TextureUsages::COPY_SRC;
        let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        let samples = self.color_samples;
        let color_msaa =
            (samples > 1).then(|| view(&texture("colour msaa", COLOR_FORMAT, samples, attachment)));
        let depth_msaa = texture("depth msaa", DEPTH_FORMAT, samples, attachment);
        let depth_single = texture("depth", DEPTH_FORMAT, 1, attachment);
        let color_resolved = texture(
            "colour",
            COLOR_FORMAT,
            1,
            readable | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        self.targets = Some(Targets {
            width,
            height,
            color_msaa,
            color_resolved_view: view(&color_resolved),
            color_resolved_encoded_view: color_resolved.create_view(&wgpu::TextureViewDescriptor {
                format: Some(wgpu::TextureFormat::Rgba8Unorm),
                ..Default::default()
            }),
            color_resolved,
            depth_msaa: view(&depth_msaa),
            id: texture("object id", wgpu::TextureFormat::R32Uint, 1, readable),
            linear_depth: texture(
                "linear depth",
                wgpu::TextureFormat::R32Float,
                1,
                readable | wgpu::TextureUsages::TEXTURE_BINDING,
            ),
            depth_single: view(&depth_single),
        });
    }

    pub(super) fn check_size(&self, width: u32, height: u32) -> Result<(), RenderError> {
        if width == 0
            || height == 0
            || width > self.max_texture_side
            || height > self.max_texture_side
        {
            return Err(RenderError::Size {
                width,
                height,
                limit: self.max_texture_side,
            });
        }
        Ok(())
    }

    /// The resolved colour of the last frame (single-sampled, bindable as a texture): as
    /// `Rgba8UnormSrgb` (sampling decodes to linear) or, with `encoded`, as `Rgba8Unorm`
    /// (sampling returns the sRGB-encoded values, what a non-sRGB window target wants).
    pub fn color_view(&self, encoded: bool) -> Option<&wgpu::TextureView> {
        self.targets.as_ref().map(|t| {
            if encoded {
                &t.color_resolved_encoded_view
            } else {
                &t.color_resolved_view
            }
        })
    }
}
