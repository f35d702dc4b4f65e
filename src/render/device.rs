//! The [`Renderer`] itself and how it is made: adapter and device creation (headless, or on a
//! device the caller already has), the shader, bind-group layouts, vertex and instance layouts,
//! the colour and id-and-depth pipelines, the texture sampler and the identity instance.

use super::RenderError;
use super::depth_difference::DepthDifferencePipeline;
use super::meshes::{IDENTITY_INSTANCE, INSTANCE_BYTES, instance_bytes};
use super::targets::{COLOR_FORMAT, COLOR_SAMPLES, DEPTH_FORMAT, Targets};

/// The headless renderer: device, pipelines and render targets of the last size used.
pub struct Renderer {
    pub(super) device: wgpu::Device,
    pub(super) queue: wgpu::Queue,
    adapter_info: wgpu::AdapterInfo,
    pub(super) view_layout: wgpu::BindGroupLayout,
    pub(super) object_layout: wgpu::BindGroupLayout,
    pub(super) sampler: wgpu::Sampler,
    pub(super) color_pipeline: wgpu::RenderPipeline,
    pub(super) id_pipeline: wgpu::RenderPipeline,
    /// The depth-difference compute pass (pen-and-ink outlines).
    pub(super) depth_difference: DepthDifferencePipeline,
    pub(super) max_texture_side: u32,
    /// Samples per pixel of the colour pass.
    pub(super) color_samples: u32,
    pub(super) targets: Option<Targets>,
    /// One identity transform, bound for static meshes.
    pub(super) identity_instance: wgpu::Buffer,
    /// Per-frame instance transforms, grown on demand.
    pub(super) instance_buffer: Option<wgpu::Buffer>,
}

impl Renderer {
    /// Creates a headless renderer on the best available adapter (a real GPU if present,
    /// else software Vulkan).
    pub fn new() -> Result<Self, RenderError> {
        Self::new_with_samples(COLOR_SAMPLES)
    }

    /// A headless renderer whose colour pass takes `color_samples` (1 or 4) per pixel.
    pub fn new_with_samples(color_samples: u32) -> Result<Self, RenderError> {
        // Vulkan/Metal/DX12 unless WGPU_BACKEND says otherwise (probing GL on a headless
        // machine only produces EGL errors).
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            descriptor.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let adapter_info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("frond renderer"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| RenderError::Device(e.to_string()))?;
        tracing::info!(adapter = %adapter_info.name, backend = ?adapter_info.backend, "renderer ready");
        Self::with_device(device, queue, adapter_info, color_samples)
    }

    /// A renderer on an existing device (the GUI's, so its frames can be drawn into the
    /// window's render pass), with `color_samples` samples per pixel in the colour pass (1 or
    /// 4: 1 suits software rasterisers, where every sample costs).
    pub fn with_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter_info: wgpu::AdapterInfo,
        color_samples: u32,
    ) -> Result<Self, RenderError> {
        if !matches!(color_samples, 1 | 4) {
            return Err(RenderError::Device(format!(
                "{color_samples} colour samples: 1 or 4 are supported"
            )));
        }
        let limits = device.limits();

        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("frond shader"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let view_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let object_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    // The vertex stage culls a star billboard's quads that give way.
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("frond pipeline layout"),
            bind_group_layouts: &[Some(&view_layout), Some(&object_layout)],
            immediate_size: 0,
        });
        let vertex_layout = wgpu::VertexBufferLayout {
            array_stride: 32,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &[
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x3,
                    offset: 0,
                    shader_location: 0,
                },
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x3,
                    offset: 12,
                    shader_location: 1,
                },
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x2,
                    offset: 24,
                    shader_location: 2,
                },
            ],
        };
        let instance_layout = wgpu::VertexBufferLayout {
            array_stride: INSTANCE_BYTES,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &[
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x4,
                    offset: 0,
                    shader_location: 3,
                },
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x4,
                    offset: 16,
                    shader_location: 4,
                },
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x4,
                    offset: 32,
                    shader_location: 5,
                },
                wgpu::VertexAttribute {
                    format: wgpu::VertexFormat::Float32x4,
                    offset: 48,
                    shader_location: 6,
                },
            ],
        };
        let primitive = wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: None,
            ..Default::default()
        };
        let depth_stencil = wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        };
        let make_pipeline =
            |label: &str, entry: &str, targets: &[Option<wgpu::ColorTargetState>], samples: u32| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(label),
                    layout: Some(&layout),
                    vertex: wgpu::VertexState {
                        module: &shader,
                        entry_point: Some("vs_main"),
                        compilation_options: Default::default(),
                        buffers: &[Some(vertex_layout.clone()), Some(instance_layout.clone())],
                    },
                    primitive,
                    depth_stencil: Some(depth_stencil.clone()),
                    multisample: wgpu::MultisampleState {
                        count: samples,
                        mask: !0,
                        alpha_to_coverage_enabled: false,
                    },
                    fragment: Some(wgpu::FragmentState {
                        module: &shader,
                        entry_point: Some(entry),
                        compilation_options: Default::default(),
                        targets,
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
        let color_pipeline = make_pipeline(
            "colour",
            "fs_color",
            &[Some(wgpu::ColorTargetState {
                format: COLOR_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
            color_samples,
        );
        let id_pipeline = make_pipeline(
            "id and depth",
            "fs_id",
            &[
                Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::R32Uint,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
                Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::R32Float,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
            ],
            1,
        );
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("repeat linear"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            address_mode_w: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            // Anisotropic filtering costs 10× render time on llvmpipe; trilinear filtering
            // keeps renders identical in kind on CPU and GPU adapters.
            anisotropy_clamp: 1,
            ..Default::default()
        });
        let identity_instance = {
            use wgpu::util::DeviceExt;
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("identity instance"),
                contents: &instance_bytes(&[IDENTITY_INSTANCE]),
                usage: wgpu::BufferUsages::VERTEX,
            })
        };
        let depth_difference = DepthDifferencePipeline::new(&device);
        Ok(Self {
            depth_difference,
            identity_instance,
            instance_buffer: None,
            max_texture_side: limits.max_texture_dimension_2d,
            color_samples,
            device,
            queue,
            adapter_info,
            view_layout,
            object_layout,
            sampler,
            color_pipeline,
            id_pipeline,
            targets: None,
        })
    }

    /// Name and backend of the adapter in use (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
    pub fn adapter_description(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type
        )
    }
}
