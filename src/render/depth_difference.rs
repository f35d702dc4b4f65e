//! The depth-difference buffer of seed 001 (Deussen 2003, §4.3) on the GPU: for every pixel,
//! the largest positive difference between its 8 neighbours' camera-frame depth and its own
//! (how far it lies in front of them), computed by a compute shader straight from the
//! renderer's depth target ([`Renderer::render_with_depth_difference`]) or from a depth image
//! the caller has ([`Renderer::depth_difference`]). Pen-and-ink outlines are drawn where it
//! exceeds a threshold. [`depth_difference_cpu`] is the reference the GPU result is tested
//! against.

use super::{Lighting, RenderError, RenderOutput, Renderer};
use crate::render::GpuScene;
use crate::render::ViewCamera;

/// The compute pipeline and its bind-group layout.
pub(super) struct DepthDifferencePipeline {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl DepthDifferencePipeline {
    pub(super) fn new(device: &wgpu::Device) -> Self {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth difference"),
            source: wgpu::ShaderSource::Wgsl(include_str!("depth_difference.wgsl").into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth difference"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::R32Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("depth difference"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("depth difference"),
            layout: Some(&pipeline_layout),
            module: &shader,
            entry_point: Some("depth_difference"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { pipeline, layout }
    }
}

/// The depth-difference buffer computed on the CPU, the reference for the GPU pass: same
/// neighbourhood (8 pixels), same background rule (depth ≤ 0 is empty and reads as
/// `background` for its neighbours), same frame rule (pixels outside the image are skipped).
pub fn depth_difference_cpu(depth: &[f32], width: u32, height: u32, background: f32) -> Vec<f32> {
    let (w, h) = (width as i64, height as i64);
    let at = |x: i64, y: i64| {
        let d = depth[(y * w + x) as usize];
        if d <= 0.0 { background } else { d }
    };
    let mut out = vec![0.0f32; depth.len()];
    for y in 0..h {
        for x in 0..w {
            let own = depth[(y * w + x) as usize];
            if own <= 0.0 {
                continue;
            }
            let mut largest = 0.0f32;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx < 0 || qy < 0 || qx >= w || qy >= h {
                        continue;
                    }
                    largest = largest.max(at(qx, qy) - own);
                }
            }
            out[(y * w + x) as usize] = largest;
        }
    }
    out
}

impl Renderer {
    /// Encodes the compute pass reading `depth` (an `R32Float` texture bindable as a texture)
    /// and writing the difference into a new storage texture, which it returns.
    fn encode_depth_difference(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        depth: &wgpu::Texture,
        width: u32,
        height: u32,
        background: f32,
    ) -> wgpu::Texture {
        use wgpu::util::DeviceExt;
        let output = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("depth difference"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let params: Vec<u8> = [background, 0.0, 0.0, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let params = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("depth difference params"),
                contents: &params,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        let (depth_view, output_view) = (view(depth), view(&output));
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth difference"),
            layout: &self.depth_difference.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&depth_view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&output_view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: params.as_entire_binding(),
                },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("depth difference"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.depth_difference.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
        drop(pass);
        output
    }

    /// The depth-difference buffer of a camera-frame depth image (row-major, `width × height`,
    /// 0 = nothing drawn), computed on the GPU.
    pub fn depth_difference(
        &self,
        depth: &[f32],
        width: u32,
        height: u32,
        background: f32,
    ) -> Result<Vec<f32>, RenderError> {
        self.check_size(width, height)?;
        if depth.len() != (width * height) as usize {
            return Err(RenderError::Readback(format!(
                "depth image has {} values for {width}x{height}",
                depth.len()
            )));
        }
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let input = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("depth input"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let bytes: Vec<u8> = depth.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &input,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 4),
                rows_per_image: Some(height),
            },
            size,
        );
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("depth difference"),
            });
        let output = self.encode_depth_difference(&mut encoder, &input, width, height, background);
        let mut read = self.submit_and_read(encoder, &[&output], width, height)?;
        Ok(floats(&read.pop().unwrap_or_default()))
    }

    /// [`Renderer::render`] plus the depth-difference buffer of its depth, computed on the GPU
    /// from the depth target before anything leaves the device.
    pub fn render_with_depth_difference(
        &mut self,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
        background: f32,
    ) -> Result<(RenderOutput, Vec<f32>), RenderError> {
        let output = self.render(scene, camera, lighting)?;
        let Some(targets) = self.targets.as_ref() else {
            return Err(RenderError::Readback("render targets missing".into()));
        };
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("depth difference"),
            });
        let difference = self.encode_depth_difference(
            &mut encoder,
            &targets.linear_depth,
            camera.width,
            camera.height,
            background,
        );
        let mut read =
            self.submit_and_read(encoder, &[&difference], camera.width, camera.height)?;
        Ok((output, floats(&read.pop().unwrap_or_default())))
    }
}

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}
