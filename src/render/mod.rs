//! Render core v1: a headless wgpu renderer (software Vulkan "llvmpipe" on CI, a real GPU where
//! there is one) for textured triangle meshes with alpha-tested materials and two-sided
//! Lambert + ambient lighting. Each render returns the colour image (4× MSAA), the camera-frame
//! depth and the object id of every pixel, read back to the CPU.
//!
//! Cameras come from COLMAP intrinsics and extrinsics with COLMAP's pixel convention, so a
//! render lines up with a COLMAP view to the pixel: the rasterizer samples pixel `(i, j)` at
//! `(i + 0.5, j + 0.5)`, which is where COLMAP puts that pixel's centre.

use std::sync::mpsc;

use image::RgbaImage;
use nalgebra::{Isometry3, Matrix4, Point2, Point3, Vector3};
use serde::Serialize;

use crate::mesh::TriMesh;
use crate::scene::{Camera, CameraModelKind};

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

/// Multisampling of the colour pass (unless a renderer is made with another count).
const COLOR_SAMPLES: u32 = 4;
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Background of instanced frames (a pale sky, linear).
const SKY: wgpu::Color = wgpu::Color {
    r: 0.52,
    g: 0.66,
    b: 0.82,
    a: 1.0,
};

/// A pinhole view: intrinsics in pixels (COLMAP convention), pose and clip planes.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewCamera {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub camera_from_world: Isometry3<f64>,
    pub near: f64,
    pub far: f64,
}

impl ViewCamera {
    /// A view from a COLMAP camera (SIMPLE_PINHOLE or PINHOLE) and an image pose.
    pub fn from_colmap(
        camera: &Camera,
        camera_from_world: &Isometry3<f64>,
        near: f64,
        far: f64,
    ) -> Result<Self, RenderError> {
        if !matches!(
            camera.model,
            CameraModelKind::SimplePinhole | CameraModelKind::Pinhole
        ) {
            return Err(RenderError::UnsupportedCamera {
                camera_id: camera.id,
                model: camera.model,
            });
        }
        let (fx, fy, cx, cy) = camera.focal_and_principal_point();
        Ok(Self {
            width: camera.width,
            height: camera.height,
            fx,
            fy,
            cx,
            cy,
            camera_from_world: *camera_from_world,
            near,
            far,
        })
    }

    /// Maps camera coordinates (x right, y down, z forward) to wgpu clip space so that
    /// `ndc = (2u/W − 1, 1 − 2v/H)` for the COLMAP pixel `(u, v)`, and depth 0..1 between the
    /// clip planes.
    pub fn clip_from_camera(&self) -> Matrix4<f64> {
        let (w, h) = (self.width as f64, self.height as f64);
        let (n, f) = (self.near, self.far);
        Matrix4::new(
            2.0 * self.fx / w,
            0.0,
            2.0 * self.cx / w - 1.0,
            0.0,
            0.0,
            -2.0 * self.fy / h,
            1.0 - 2.0 * self.cy / h,
            0.0,
            0.0,
            0.0,
            f / (f - n),
            -f * n / (f - n),
            0.0,
            0.0,
            1.0,
            0.0,
        )
    }

    /// Pixel position (COLMAP convention) and depth of a world point; `None` behind the camera.
    pub fn project(&self, point_world: &Point3<f64>) -> Option<(Point2<f64>, f64)> {
        let p = self.camera_from_world * point_world;
        (p.z > 1e-9).then(|| {
            (
                Point2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy),
                p.z,
            )
        })
    }
}

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

/// Lighting of the colour pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Direction toward the key light, world frame.
    pub direction_world: Vector3<f64>,
    pub ambient: f32,
    pub key: f32,
    pub fill: f32,
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            direction_world: Vector3::new(0.35, -0.45, 1.0),
            ambient: 0.42,
            key: 0.5,
            fill: 0.12,
        }
    }
}

/// A handle to a texture uploaded to a [`GpuScene`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureHandle(usize);

/// A handle to a mesh uploaded to a [`GpuScene`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MeshHandle(usize);

struct GpuMesh {
    /// Vertex and index buffers; `None` for an empty mesh.
    buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    index_count: u32,
    /// What the id pass writes for it.
    object_id: u32,
    bind_group: wgpu::BindGroup,
    /// Drawn once, untransformed, by every render (else only through instance batches).
    is_static: bool,
    /// Static meshes can be hidden (progressive drawing while a view moves).
    visible: bool,
}

/// Meshes and textures on the GPU, ready to render from any view.
pub struct GpuScene {
    textures: Vec<wgpu::TextureView>,
    meshes: Vec<GpuMesh>,
    triangles: usize,
}

impl GpuScene {
    pub fn num_meshes(&self) -> usize {
        self.meshes.len()
    }
    /// Triangles of the static meshes (drawn by every render).
    pub fn num_triangles(&self) -> usize {
        self.triangles
    }
    /// Shows or hides a static mesh in later renders (all are shown when uploaded).
    pub fn set_visible(&mut self, mesh: MeshHandle, visible: bool) {
        if let Some(m) = self.meshes.get_mut(mesh.0) {
            m.visible = visible;
        }
    }

    /// Triangles of one mesh.
    pub fn mesh_triangles(&self, mesh: MeshHandle) -> usize {
        self.meshes
            .get(mesh.0)
            .map_or(0, |m| m.index_count as usize / 3)
    }
}

/// Model-to-world transform of one instance: a column-major 4×4 matrix (rotation, uniform
/// scale and translation; normals are transformed by its upper 3×3 and renormalised).
pub type InstanceTransform = [f32; 16];

/// One instanced draw: `mesh` drawn once per transform in `instances` (a range into the
/// transforms given to [`Renderer::render_instanced`]).
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceBatch {
    pub mesh: MeshHandle,
    pub instances: std::ops::Range<u32>,
}

/// What one instanced frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    pub draw_calls: usize,
    pub instances: usize,
    pub triangles: usize,
    /// Wall-clock seconds from encoding to the GPU finishing the frame.
    pub seconds: f64,
}

/// The identity instance transform.
pub const IDENTITY_INSTANCE: InstanceTransform = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

/// The headless renderer: device, pipelines and render targets of the last size used.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter_info: wgpu::AdapterInfo,
    view_layout: wgpu::BindGroupLayout,
    object_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    color_pipeline: wgpu::RenderPipeline,
    id_pipeline: wgpu::RenderPipeline,
    max_texture_side: u32,
    /// Samples per pixel of the colour pass.
    color_samples: u32,
    targets: Option<Targets>,
    /// One identity transform, bound for static meshes.
    identity_instance: wgpu::Buffer,
    /// Per-frame instance transforms, grown on demand.
    instance_buffer: Option<wgpu::Buffer>,
}

struct Targets {
    width: u32,
    height: u32,
    /// The multisampled colour target; `None` with one sample, when the colour pass draws
    /// straight into `color_resolved`.
    color_msaa: Option<wgpu::TextureView>,
    color_resolved: wgpu::Texture,
    color_resolved_view: wgpu::TextureView,
    /// The same texels seen as plain `Rgba8Unorm` (sRGB-encoded bytes, no decoding).
    color_resolved_encoded_view: wgpu::TextureView,
    depth_msaa: wgpu::TextureView,
    id: wgpu::Texture,
    linear_depth: wgpu::Texture,
    depth_single: wgpu::TextureView,
}

fn vertex_bytes(mesh: &TriMesh) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(mesh.positions.len() * 32);
    for i in 0..mesh.positions.len() {
        let p = mesh.positions[i];
        let n = mesh.normals[i];
        let uv = mesh.uvs[i];
        for v in [p.x, p.y, p.z, n.x, n.y, n.z, uv[0], uv[1]] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

/// Box-filtered mip chain of an RGBA image (level 0 first).
fn mip_chain(image: &RgbaImage) -> Vec<RgbaImage> {
    let mut levels = vec![image.clone()];
    loop {
        let last = levels.last().unwrap_or(image);
        let (w, h) = last.dimensions();
        if w == 1 && h == 1 {
            break;
        }
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let next = RgbaImage::from_fn(nw, nh, |x, y| {
            let mut sum = [0u32; 4];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let px = last.get_pixel((2 * x + dx).min(w - 1), (2 * y + dy).min(h - 1));
                for c in 0..4 {
                    sum[c] += px[c] as u32;
                }
            }
            image::Rgba(sum.map(|s| ((s + 2) / 4) as u8))
        });
        levels.push(next);
    }
    levels
}

/// Bytes per instance transform.
const INSTANCE_BYTES: u64 = 64;

fn instance_bytes(transforms: &[InstanceTransform]) -> Vec<u8> {
    transforms
        .iter()
        .flat_map(|m| m.iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

/// Fraction of texels whose alpha, scaled by `scale`, passes the ½ alpha test.
fn alpha_coverage(image: &RgbaImage, scale: f32) -> f64 {
    let passing = image
        .pixels()
        .filter(|p| (p[3] as f32 * scale).round().min(255.0) >= 128.0)
        .count();
    passing as f64 / (image.width() * image.height()).max(1) as f64
}

/// Scales a mip level's alpha so that its alpha-tested coverage matches `target` (bisection
/// on the scale; Castaño's coverage-preserving mipmaps).
fn preserve_alpha_coverage(level: &mut RgbaImage, target: f64) {
    let (mut lo, mut hi) = (0.0f32, 16.0f32);
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if alpha_coverage(level, mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // `hi` reaches the target; texels are rounded as `alpha_coverage` counts them.
    let scale = hi;
    for p in level.pixels_mut() {
        p[3] = (p[3] as f32 * scale).round().min(255.0) as u8;
    }
}

fn padded_bytes_per_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let unpadded = width * bytes_per_pixel;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
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
                    visibility: wgpu::ShaderStages::FRAGMENT,
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
        Ok(Self {
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

    /// An empty scene bound to this renderer's device.
    pub fn new_scene(&self) -> GpuScene {
        GpuScene {
            textures: Vec::new(),
            meshes: Vec::new(),
            triangles: 0,
        }
    }

    /// Uploads an sRGB texture with its mip chain.
    pub fn add_texture(&self, scene: &mut GpuScene, image: &RgbaImage) -> TextureHandle {
        self.upload_texture(scene, mip_chain(image))
    }

    /// Uploads a cut-out texture (alpha-tested at ½) whose mip levels keep the alpha-tested
    /// coverage of level 0, so that foliage and billboards do not thin out with distance.
    pub fn add_cutout_texture(&self, scene: &mut GpuScene, image: &RgbaImage) -> TextureHandle {
        let mut levels = mip_chain(image);
        let coverage = alpha_coverage(image, 1.0);
        for level in levels.iter_mut().skip(1) {
            preserve_alpha_coverage(level, coverage);
        }
        self.upload_texture(scene, levels)
    }

    fn upload_texture(&self, scene: &mut GpuScene, levels: Vec<RgbaImage>) -> TextureHandle {
        let (w, h) = levels.first().map_or((1, 1), |l| l.dimensions());
        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("base colour"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: levels.len() as u32,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8UnormSrgb,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        for (level, mip) in levels.iter().enumerate() {
            let (mw, mh) = mip.dimensions();
            self.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &texture,
                    mip_level: level as u32,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                mip.as_raw(),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * mw),
                    rows_per_image: Some(mh),
                },
                wgpu::Extent3d {
                    width: mw,
                    height: mh,
                    depth_or_array_layers: 1,
                },
            );
        }
        scene
            .textures
            .push(texture.create_view(&wgpu::TextureViewDescriptor::default()));
        TextureHandle(scene.textures.len() - 1)
    }

    /// Uploads a static mesh drawn with `texture` by every render; `object_id` (non-zero) is
    /// what the id pass writes. `alpha_test` discards texels with alpha below ½ (cut-out
    /// leaves, billboards).
    pub fn add_mesh(
        &self,
        scene: &mut GpuScene,
        mesh: &TriMesh,
        texture: TextureHandle,
        object_id: u32,
        alpha_test: bool,
    ) -> Result<MeshHandle, RenderError> {
        self.upload_mesh(scene, mesh, texture, object_id, alpha_test, true)
    }

    /// Uploads a mesh drawn only through [`InstanceBatch`]es of [`Renderer::render_instanced`].
    pub fn add_instanced_mesh(
        &self,
        scene: &mut GpuScene,
        mesh: &TriMesh,
        texture: TextureHandle,
        object_id: u32,
        alpha_test: bool,
    ) -> Result<MeshHandle, RenderError> {
        self.upload_mesh(scene, mesh, texture, object_id, alpha_test, false)
    }

    fn upload_mesh(
        &self,
        scene: &mut GpuScene,
        mesh: &TriMesh,
        texture: TextureHandle,
        object_id: u32,
        alpha_test: bool,
        is_static: bool,
    ) -> Result<MeshHandle, RenderError> {
        use wgpu::util::DeviceExt;
        if object_id == 0 {
            return Err(RenderError::Mesh {
                object_id,
                message: "object id 0 is reserved for empty pixels".into(),
            });
        }
        mesh.validate()
            .map_err(|message| RenderError::Mesh { object_id, message })?;
        let texture_view = scene
            .textures
            .get(texture.0)
            .ok_or_else(|| RenderError::Mesh {
                object_id,
                message: format!("unknown texture handle {}", texture.0),
            })?;
        let buffers = self.mesh_buffers(mesh);
        let mut uniform = Vec::with_capacity(16);
        for v in [object_id, alpha_test as u32, 0, 0] {
            uniform.extend_from_slice(&v.to_le_bytes());
        }
        let object_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("object"),
                contents: &uniform,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("object"),
            layout: &self.object_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: object_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(texture_view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
            ],
        });
        if is_static {
            scene.triangles += mesh.triangles.len();
        }
        scene.meshes.push(GpuMesh {
            buffers,
            index_count: (mesh.triangles.len() * 3) as u32,
            object_id,
            bind_group,
            is_static,
            visible: true,
        });
        Ok(MeshHandle(scene.meshes.len() - 1))
    }

    /// Vertex and index buffers of a mesh; `None` for an empty mesh.
    fn mesh_buffers(&self, mesh: &TriMesh) -> Option<(wgpu::Buffer, wgpu::Buffer)> {
        use wgpu::util::DeviceExt;
        (!mesh.is_empty()).then(|| {
            let vertices = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("vertices"),
                    contents: &vertex_bytes(mesh),
                    usage: wgpu::BufferUsages::VERTEX,
                });
            let index_data: Vec<u8> = mesh
                .triangles
                .iter()
                .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
                .collect();
            let indices = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("indices"),
                    contents: &index_data,
                    usage: wgpu::BufferUsages::INDEX,
                });
            (vertices, indices)
        })
    }

    /// Replaces the geometry of an uploaded mesh, keeping its texture, object id, alpha test
    /// and visibility: an edited part of a scene is re-uploaded without the rest (an editor
    /// changing its points or branches keeps its textured leaves on the GPU).
    pub fn replace_mesh_geometry(
        &self,
        scene: &mut GpuScene,
        handle: MeshHandle,
        mesh: &TriMesh,
    ) -> Result<(), RenderError> {
        let Some(old) = scene.meshes.get(handle.0) else {
            return Err(RenderError::UnknownMesh(handle.0));
        };
        mesh.validate().map_err(|message| RenderError::Mesh {
            object_id: old.object_id,
            message,
        })?;
        if old.is_static {
            scene.triangles = scene.triangles - old.index_count as usize / 3 + mesh.triangles.len();
        }
        let buffers = self.mesh_buffers(mesh);
        let slot = &mut scene.meshes[handle.0];
        slot.buffers = buffers;
        slot.index_count = (mesh.triangles.len() * 3) as u32;
        Ok(())
    }

    fn ensure_targets(&mut self, width: u32, height: u32) {
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
            linear_depth: texture("linear depth", wgpu::TextureFormat::R32Float, 1, readable),
            depth_single: view(&depth_single),
        });
    }

    /// The view uniforms (clip transform, camera depth row, lighting) as a bind group.
    fn view_bind_group(&self, camera: &ViewCamera, lighting: &Lighting) -> wgpu::BindGroup {
        use wgpu::util::DeviceExt;
        let clip_from_world = camera.clip_from_camera() * camera.camera_from_world.to_homogeneous();
        let camera_matrix = camera.camera_from_world.to_homogeneous();
        let light = lighting.direction_world.normalize();
        let mut uniform: Vec<f32> = Vec::with_capacity(28);
        // Column-major, as WGSL expects.
        uniform.extend(clip_from_world.iter().map(|v| *v as f32));
        uniform.extend((0..4).map(|c| camera_matrix[(2, c)] as f32));
        uniform.extend([light.x as f32, light.y as f32, light.z as f32, 0.0]);
        uniform.extend([lighting.ambient, lighting.key, lighting.fill, 0.0]);
        let uniform_bytes: Vec<u8> = uniform.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("view"),
                contents: &uniform_bytes,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &self.view_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: view_buffer.as_entire_binding(),
            }],
        })
    }

    fn check_size(&self, width: u32, height: u32) -> Result<(), RenderError> {
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

    /// Copies 4-byte-per-pixel `textures` into mapped buffers, submits `encoder` and returns
    /// each texture's rows without padding.
    fn submit_and_read(
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

    /// Renders one colour frame of the static meshes plus instance `batches` (ranges into
    /// `transforms`), waits for the GPU to finish and reports what was drawn and how long it
    /// took. With `read_color` the frame is also read back (not included in the time).
    pub fn render_instanced(
        &mut self,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
        transforms: &[InstanceTransform],
        batches: &[InstanceBatch],
        read_color: bool,
    ) -> Result<(FrameStats, Option<RgbaImage>), RenderError> {
        let (width, height) = (camera.width, camera.height);
        self.check_size(width, height)?;
        if let Some(batch) = batches.iter().find(|b| {
            b.instances.end as usize > transforms.len() || b.instances.start > b.instances.end
        }) {
            return Err(RenderError::Mesh {
                object_id: 0,
                message: format!(
                    "instance range {:?} outside the {} transforms",
                    batch.instances,
                    transforms.len()
                ),
            });
        }
        self.ensure_targets(width, height);
        let start = std::time::Instant::now();
        let needed = (transforms.len().max(1) as u64) * INSTANCE_BYTES;
        if self
            .instance_buffer
            .as_ref()
            .is_none_or(|b| b.size() < needed)
        {
            self.instance_buffer = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("instances"),
                size: needed.next_power_of_two(),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let (Some(targets), Some(instance_buffer)) =
            (self.targets.as_ref(), self.instance_buffer.as_ref())
        else {
            return Err(RenderError::Readback("render targets missing".into()));
        };
        if !transforms.is_empty() {
            self.queue
                .write_buffer(instance_buffer, 0, &instance_bytes(transforms));
        }
        let view_group = self.view_bind_group(camera, lighting);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("instanced frame"),
            });
        let mut stats = FrameStats::default();
        {
            let mut pass = begin_color_pass(&mut encoder, targets, SKY);
            let (draws, triangles) = draw_meshes(
                &mut pass,
                &self.color_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
            let (batch_draws, instances, batch_triangles) =
                draw_batches(&mut pass, scene, instance_buffer, batches);
            stats.draw_calls = draws + batch_draws;
            stats.instances = instances;
            stats.triangles = triangles + batch_triangles;
        }
        self.queue.submit([encoder.finish()]);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        stats.seconds = start.elapsed().as_secs_f64();
        if !read_color {
            return Ok((stats, None));
        }
        let encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame readback"),
            });
        let mut bytes = self.submit_and_read(encoder, &[&targets.color_resolved], width, height)?;
        let color = RgbaImage::from_raw(width, height, bytes.pop().unwrap_or_default())
            .ok_or_else(|| RenderError::Readback("colour buffer has the wrong size".into()))?;
        Ok((stats, Some(color)))
    }

    /// Encodes a colour frame of the static meshes into `encoder` without submitting it (the
    /// GUI's 3D panel: the caller submits with its own work, then samples
    /// [`Renderer::color_view`]). Returns the draw calls and triangles encoded.
    pub fn encode_color_frame(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
        background: [f64; 4],
    ) -> Result<(usize, usize), RenderError> {
        self.check_size(camera.width, camera.height)?;
        self.ensure_targets(camera.width, camera.height);
        let view_group = self.view_bind_group(camera, lighting);
        let Some(targets) = self.targets.as_ref() else {
            return Err(RenderError::Readback("render targets missing".into()));
        };
        let [r, g, b, a] = background;
        let mut pass = begin_color_pass(encoder, targets, wgpu::Color { r, g, b, a });
        Ok(draw_meshes(
            &mut pass,
            &self.color_pipeline,
            &view_group,
            scene,
            &self.identity_instance,
        ))
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

    /// Renders `scene` from `camera`: colour, depth and object ids.
    pub fn render(
        &mut self,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
    ) -> Result<RenderOutput, RenderError> {
        let (width, height) = (camera.width, camera.height);
        self.check_size(width, height)?;
        self.ensure_targets(width, height);
        let Some(targets) = self.targets.as_ref() else {
            return Err(RenderError::Readback("render targets missing".into()));
        };

        let view_group = self.view_bind_group(camera, lighting);

        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("render"),
            });
        {
            let mut pass = begin_color_pass(&mut encoder, targets, wgpu::Color::BLACK);
            draw_meshes(
                &mut pass,
                &self.color_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
        }
        let id_view = targets
            .id
            .create_view(&wgpu::TextureViewDescriptor::default());
        let depth_view = targets
            .linear_depth
            .create_view(&wgpu::TextureViewDescriptor::default());
        {
            let clear = |store| wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store,
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("id and depth"),
                color_attachments: &[
                    Some(wgpu::RenderPassColorAttachment {
                        view: &id_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear(wgpu::StoreOp::Store),
                    }),
                    Some(wgpu::RenderPassColorAttachment {
                        view: &depth_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear(wgpu::StoreOp::Store),
                    }),
                ],
                depth_stencil_attachment: Some(cleared_depth(&targets.depth_single)),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            draw_meshes(
                &mut pass,
                &self.id_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
        }
        let mut unpadded = self.submit_and_read(
            encoder,
            &[&targets.color_resolved, &targets.id, &targets.linear_depth],
            width,
            height,
        )?;
        let depth_bytes = unpadded.pop().unwrap_or_default();
        let id_bytes = unpadded.pop().unwrap_or_default();
        let color_bytes = unpadded.pop().unwrap_or_default();
        let color = RgbaImage::from_raw(width, height, color_bytes)
            .ok_or_else(|| RenderError::Readback("colour buffer has the wrong size".into()))?;
        let object_id = id_bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let depth = depth_bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Ok(RenderOutput {
            width,
            height,
            color,
            depth,
            object_id,
        })
    }
}

/// The multisampled colour pass (resolved into the readable colour target), cleared to
/// `clear`.
fn begin_color_pass<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    targets: &'a Targets,
    clear: wgpu::Color,
) -> wgpu::RenderPass<'a> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("colour"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: targets
                .color_msaa
                .as_ref()
                .unwrap_or(&targets.color_resolved_view),
            depth_slice: None,
            resolve_target: targets
                .color_msaa
                .as_ref()
                .map(|_| &targets.color_resolved_view),
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(clear),
                // Multisampled samples are resolved and dropped; a single-sample target is
                // the result.
                store: if targets.color_msaa.is_some() {
                    wgpu::StoreOp::Discard
                } else {
                    wgpu::StoreOp::Store
                },
            },
        })],
        depth_stencil_attachment: Some(cleared_depth(&targets.depth_msaa)),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A depth attachment cleared to the far plane and not kept after the pass.
fn cleared_depth(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations {
            load: wgpu::LoadOp::Clear(1.0),
            store: wgpu::StoreOp::Discard,
        }),
        stencil_ops: None,
    }
}

/// Draws every static mesh of the scene with one pipeline and the view's bind group; returns
/// the draw calls and triangles submitted.
fn draw_meshes(
    pass: &mut wgpu::RenderPass<'_>,
    pipeline: &wgpu::RenderPipeline,
    view_group: &wgpu::BindGroup,
    scene: &GpuScene,
    identity_instance: &wgpu::Buffer,
) -> (usize, usize) {
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, view_group, &[]);
    pass.set_vertex_buffer(1, identity_instance.slice(..));
    let mut draws = (0, 0);
    for mesh in scene.meshes.iter().filter(|m| m.is_static && m.visible) {
        let Some((vertices, indices)) = &mesh.buffers else {
            continue;
        };
        pass.set_bind_group(1, &mesh.bind_group, &[]);
        pass.set_vertex_buffer(0, vertices.slice(..));
        pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.index_count, 0, 0..1);
        draws.0 += 1;
        draws.1 += mesh.index_count as usize / 3;
    }
    draws
}

/// Draws instance batches (the instance transforms bound at slot 1); returns the draw calls,
/// instances and triangles submitted.
fn draw_batches(
    pass: &mut wgpu::RenderPass<'_>,
    scene: &GpuScene,
    instance_buffer: &wgpu::Buffer,
    batches: &[InstanceBatch],
) -> (usize, usize, usize) {
    pass.set_vertex_buffer(1, instance_buffer.slice(..));
    let mut totals = (0, 0, 0);
    for batch in batches {
        let Some(mesh) = scene.meshes.get(batch.mesh.0) else {
            continue;
        };
        let Some((vertices, indices)) = &mesh.buffers else {
            continue;
        };
        if batch.instances.is_empty() {
            continue;
        }
        pass.set_bind_group(1, &mesh.bind_group, &[]);
        pass.set_vertex_buffer(0, vertices.slice(..));
        pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.index_count, 0, batch.instances.clone());
        let count = batch.instances.len();
        totals.0 += 1;
        totals.1 += count;
        totals.2 += count * mesh.index_count as usize / 3;
    }
    totals
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::synthetic::look_at;

    fn renderer() -> Renderer {
        Renderer::new().expect("a GPU adapter (llvmpipe on CI)")
    }

    /// An empty scene and a white texture in it.
    fn white_scene(renderer: &Renderer) -> (GpuScene, TextureHandle) {
        let mut scene = renderer.new_scene();
        let white = RgbaImage::from_pixel(4, 4, image::Rgba([255, 255, 255, 255]));
        let texture = renderer.add_texture(&mut scene, &white);
        (scene, texture)
    }

    fn square_at(center: Point3<f32>, half: f32) -> TriMesh {
        let mut mesh = TriMesh {
            positions: vec![
                center + Vector3::new(-half, -half, 0.0),
                center + Vector3::new(half, -half, 0.0),
                center + Vector3::new(half, half, 0.0),
                center + Vector3::new(-half, half, 0.0),
            ],
            normals: Vec::new(),
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        mesh.compute_normals();
        mesh
    }

    /// A square 0.4 wide at `x` on the plane z = 0, uploaded with `object_id`.
    fn add_square(
        renderer: &Renderer,
        scene: &mut GpuScene,
        texture: TextureHandle,
        x: f32,
        object_id: u32,
    ) -> MeshHandle {
        renderer
            .add_mesh(
                scene,
                &square_at(Point3::new(x, 0.0, 0.0), 0.2),
                texture,
                object_id,
                false,
            )
            .unwrap()
    }

    fn camera(width: u32, height: u32) -> ViewCamera {
        ViewCamera {
            width,
            height,
            fx: 180.0,
            fy: 175.0,
            cx: 0.5 * width as f64 + 3.25,
            cy: 0.5 * height as f64 - 1.75,
            camera_from_world: look_at(Point3::new(0.3, -2.0, 1.5), Point3::new(0.1, 0.05, 0.0)),
            near: 0.05,
            far: 20.0,
        }
    }

    #[test]
    fn projected_square_covers_exactly_the_pixels_whose_centres_it_contains() {
        let mut renderer = renderer();
        let (mut scene, texture) = white_scene(&renderer);
        let square = square_at(Point3::new(0.1, 0.05, 0.0), 0.3);
        renderer
            .add_mesh(&mut scene, &square, texture, 7, false)
            .unwrap();
        let view = camera(160, 120);
        let out = renderer
            .render(&scene, &view, &Lighting::default())
            .unwrap();
        // Project the corners; a pixel is covered iff its centre (i+½, j+½) is inside.
        let corners: Vec<Point2<f64>> = square
            .positions
            .iter()
            .map(|p| view.project(&p.cast::<f64>()).unwrap().0)
            .collect();
        let inside = |p: Point2<f64>| {
            (0..4).all(|k| {
                let a = corners[k];
                let b = corners[(k + 1) % 4];
                let cross = (b - a).perp(&(p - a));
                cross.abs() > 1e-3
                    && cross.signum()
                        == (corners[1] - corners[0])
                            .perp(&(corners[2] - corners[0]))
                            .signum()
            })
        };
        let mut disagreements = 0;
        let mut covered = 0;
        for y in 0..view.height {
            for x in 0..view.width {
                let centre = Point2::new(x as f64 + 0.5, y as f64 + 0.5);
                let drawn = out.id_at(x, y) == 7;
                covered += drawn as usize;
                // Pixels within 1e-3 px of an edge may go either way (tie rules).
                let near_edge = (0..4).any(|k| {
                    let a = corners[k];
                    let b = corners[(k + 1) % 4];
                    ((b - a).perp(&(centre - a)) / (b - a).norm()).abs() < 1e-3
                });
                if !near_edge && drawn != inside(centre) {
                    disagreements += 1;
                }
            }
        }
        assert!(covered > 500, "square too small: {covered} pixels");
        assert_eq!(disagreements, 0, "rasterizer and projection disagree");
    }

    #[test]
    fn a_single_sample_colour_pass_covers_exactly_the_id_pass_pixels() {
        let mut renderer = Renderer::new_with_samples(1).unwrap();
        let (mut scene, texture) = white_scene(&renderer);
        renderer
            .add_mesh(
                &mut scene,
                &square_at(Point3::new(0.1, 0.05, 0.0), 0.3),
                texture,
                7,
                false,
            )
            .unwrap();
        let out = renderer
            .render(&scene, &camera(160, 120), &Lighting::default())
            .unwrap();
        let mut covered = 0;
        for (pixel, id) in out.color.pixels().zip(&out.object_id) {
            let lit = pixel.0[..3].iter().any(|&c| c > 0);
            assert_eq!(lit, *id != 0);
            covered += lit as usize;
        }
        assert!(covered > 100, "{covered}");
        assert!(Renderer::new_with_samples(2).is_err());
    }

    #[test]
    fn hidden_meshes_are_not_drawn_until_shown_again() {
        let mut renderer = renderer();
        let (mut scene, texture) = white_scene(&renderer);
        let left = add_square(&renderer, &mut scene, texture, -0.3, 3);
        add_square(&renderer, &mut scene, texture, 0.3, 4);
        let view = camera(160, 120);
        let ids = |renderer: &mut Renderer, scene: &GpuScene| {
            let out = renderer.render(scene, &view, &Lighting::default()).unwrap();
            let mut ids: Vec<u32> = out.object_id.into_iter().filter(|&i| i != 0).collect();
            ids.sort_unstable();
            ids.dedup();
            ids
        };
        assert_eq!(ids(&mut renderer, &scene), [3, 4]);
        scene.set_visible(left, false);
        assert_eq!(ids(&mut renderer, &scene), [4]);
        scene.set_visible(left, true);
        assert_eq!(ids(&mut renderer, &scene), [3, 4]);
    }

    #[test]
    fn replaced_geometry_is_drawn_with_the_same_id_and_texture() {
        let mut renderer = renderer();
        let (mut scene, texture) = white_scene(&renderer);
        let mesh = add_square(&renderer, &mut scene, texture, -0.3, 7);
        let view = camera(160, 120);
        // Mean column of the pixels showing id 7, and how many there are.
        let where_drawn = |renderer: &mut Renderer, scene: &GpuScene| {
            let out = renderer.render(scene, &view, &Lighting::default()).unwrap();
            let columns: Vec<usize> = out
                .object_id
                .iter()
                .enumerate()
                .filter(|(_, id)| **id == 7)
                .map(|(k, _)| k % 160)
                .collect();
            let mean = columns.iter().sum::<usize>() as f64 / columns.len().max(1) as f64;
            (mean, columns.len())
        };
        let (left, count) = where_drawn(&mut renderer, &scene);
        assert!(left < 80.0 && count > 100, "{left} {count}");
        let moved = square_at(Point3::new(0.3, 0.0, 0.0), 0.2);
        renderer
            .replace_mesh_geometry(&mut scene, mesh, &moved)
            .unwrap();
        let (right, count_after) = where_drawn(&mut renderer, &scene);
        assert!(right > 80.0, "{right}");
        assert!(
            count_after.abs_diff(count) < count / 10,
            "{count} {count_after}"
        );
        assert_eq!(scene.num_triangles(), 2);
        // An empty mesh draws nothing; bad input is refused and changes nothing.
        let mut bad = moved.clone();
        bad.positions[0].x = f32::NAN;
        assert!(matches!(
            renderer.replace_mesh_geometry(&mut scene, mesh, &bad),
            Err(RenderError::Mesh { object_id: 7, .. })
        ));
        assert!(matches!(
            renderer.replace_mesh_geometry(&mut scene, MeshHandle(9), &moved),
            Err(RenderError::UnknownMesh(9))
        ));
        assert_eq!(where_drawn(&mut renderer, &scene).1, count_after);
        renderer
            .replace_mesh_geometry(&mut scene, mesh, &TriMesh::default())
            .unwrap();
        assert_eq!(where_drawn(&mut renderer, &scene).1, 0);
        assert_eq!(scene.num_triangles(), 0);
    }

    #[test]
    fn projected_vertex_lands_where_the_rasterizer_drew_it() {
        let mut renderer = renderer();
        let (mut scene, texture) = white_scene(&renderer);
        let view = camera(200, 150);
        // Tiny squares around several world points: each must appear at the pixel its centre
        // projects to, with the right depth.
        for (k, p) in [
            Point3::new(0.1f32, 0.05, 0.0),
            Point3::new(0.5, -0.2, 0.1),
            Point3::new(-0.4, 0.3, -0.2),
        ]
        .iter()
        .enumerate()
        {
            renderer
                .add_mesh(
                    &mut scene,
                    &square_at(*p, 0.03),
                    texture,
                    10 + k as u32,
                    false,
                )
                .unwrap();
        }
        let out = renderer
            .render(&scene, &view, &Lighting::default())
            .unwrap();
        for (k, p) in [
            Point3::new(0.1f64, 0.05, 0.0),
            Point3::new(0.5, -0.2, 0.1),
            Point3::new(-0.4, 0.3, -0.2),
        ]
        .iter()
        .enumerate()
        {
            let (uv, depth) = view.project(p).unwrap();
            let (x, y) = (uv.x.floor() as u32, uv.y.floor() as u32);
            assert_eq!(out.id_at(x, y), 10 + k as u32, "point {k} at {uv:?}");
            let d = out.depth_at(x, y) as f64;
            assert!((d - depth).abs() < 0.01, "depth {d} vs {depth}");
        }
        // Background stays empty.
        assert_eq!(out.id_at(0, 0), 0);
        assert_eq!(out.depth_at(0, 0), 0.0);
    }

    #[test]
    fn colour_pass_shades_and_textures() {
        let mut renderer = renderer();
        let mut scene = renderer.new_scene();
        let red = RgbaImage::from_pixel(8, 8, image::Rgba([200, 20, 20, 255]));
        let texture = renderer.add_texture(&mut scene, &red);
        renderer
            .add_mesh(
                &mut scene,
                &square_at(Point3::new(0.1, 0.05, 0.0), 0.3),
                texture,
                1,
                false,
            )
            .unwrap();
        let view = camera(120, 90);
        let out = renderer
            .render(&scene, &view, &Lighting::default())
            .unwrap();
        let (uv, _) = view.project(&Point3::new(0.1, 0.05, 0.0)).unwrap();
        let pixel = out.color.get_pixel(uv.x as u32, uv.y as u32);
        assert!(
            pixel[0] > 100 && pixel[1] < 40 && pixel[2] < 40,
            "{pixel:?}"
        );
        assert_eq!(out.color.get_pixel(0, 0)[0], 0);
    }

    /// Column-major transform: uniform `scale`, rotation about z by `yaw`, then `offset`.
    fn instance(offset: Vector3<f32>, yaw: f32, scale: f32) -> InstanceTransform {
        let m = nalgebra::Similarity3::new(offset, Vector3::z() * yaw, scale).to_homogeneous();
        let mut out = [0.0; 16];
        out.copy_from_slice(m.as_slice());
        out
    }

    #[test]
    fn an_instance_draws_what_the_transformed_static_mesh_draws() {
        let mut renderer = renderer();
        let view = camera(160, 120);
        let texture_image = RgbaImage::from_fn(8, 8, |x, y| {
            image::Rgba([30 * x as u8, 30 * y as u8, 90, 255])
        });
        let (offset, yaw, scale) = (Vector3::new(0.15f32, -0.05, 0.1), 0.6f32, 1.3f32);
        let local = square_at(Point3::origin(), 0.25);
        let transform = instance(offset, yaw, scale);
        let mut placed = local.clone();
        let similarity = nalgebra::Similarity3::new(offset, Vector3::z() * yaw, scale);
        for p in &mut placed.positions {
            *p = similarity.transform_point(p);
        }
        placed.compute_normals();

        let mut static_scene = renderer.new_scene();
        let t = renderer.add_texture(&mut static_scene, &texture_image);
        renderer
            .add_mesh(&mut static_scene, &placed, t, 1, false)
            .unwrap();
        let (static_stats, static_color) = renderer
            .render_instanced(&static_scene, &view, &Lighting::default(), &[], &[], true)
            .unwrap();
        assert_eq!((static_stats.draw_calls, static_stats.triangles), (1, 2));

        let mut instanced_scene = renderer.new_scene();
        let t = renderer.add_texture(&mut instanced_scene, &texture_image);
        let mesh = renderer
            .add_instanced_mesh(&mut instanced_scene, &local, t, 1, false)
            .unwrap();
        // A second instance far behind the camera draws nothing visible.
        let transforms = [transform, instance(Vector3::new(0.0, -50.0, 0.0), 0.0, 1.0)];
        let batches = [InstanceBatch {
            mesh,
            instances: 0..2,
        }];
        let (stats, color) = renderer
            .render_instanced(
                &instanced_scene,
                &view,
                &Lighting::default(),
                &transforms,
                &batches,
                true,
            )
            .unwrap();
        assert_eq!(
            (stats.draw_calls, stats.instances, stats.triangles),
            (1, 2, 4)
        );
        let (a, b) = (static_color.unwrap(), color.unwrap());
        let sky = *a.get_pixel(0, 0);
        let covered = a.pixels().filter(|p| **p != sky).count();
        let differing = a
            .pixels()
            .zip(b.pixels())
            .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 8))
            .count();
        assert!(covered > 1000, "square covers {covered} pixels");
        assert!(
            differing * 100 < covered,
            "{differing} of {covered} pixels differ"
        );

        let bad = [InstanceBatch {
            mesh,
            instances: 1..3,
        }];
        assert!(
            renderer
                .render_instanced(
                    &instanced_scene,
                    &view,
                    &Lighting::default(),
                    &transforms,
                    &bad,
                    false
                )
                .is_err()
        );
    }

    #[test]
    fn cutout_mips_keep_the_alpha_tested_coverage() {
        // Opaque discs on a transparent page: box filtering halves edge alpha, and a level
        // whose texels sit exactly at ½ must still pass the test.
        let page = RgbaImage::from_fn(64, 64, |x, y| {
            let (dx, dy) = (x as f32 - 20.0, y as f32 - 24.0);
            let alpha = if dx * dx + dy * dy < 100.0 || (x >= 40 && y >= 40) {
                255
            } else {
                0
            };
            image::Rgba([40, 160, 40, alpha])
        });
        let target = alpha_coverage(&page, 1.0);
        let mut levels = mip_chain(&page);
        for level in levels.iter_mut().skip(1) {
            preserve_alpha_coverage(level, target);
            let passing = level.pixels().filter(|p| p[3] >= 128).count() as f64
                / (level.width() * level.height()) as f64;
            let texel = 1.0 / (level.width() * level.height()) as f64;
            assert!(
                passing >= target - 1e-9 || passing + texel >= target,
                "{passing} vs {target}"
            );
        }
        // A uniformly opaque tile stays opaque at every level.
        let mut solid = mip_chain(&RgbaImage::from_pixel(8, 8, image::Rgba([1, 2, 3, 255])));
        for level in solid.iter_mut().skip(1) {
            preserve_alpha_coverage(level, 1.0);
            assert!(level.pixels().all(|p| p[3] >= 128));
        }
    }

    #[test]
    fn distorted_cameras_are_refused() {
        let camera = crate::scene::synthetic::example_camera(CameraModelKind::OpenCv, 3, 64, 48);
        let err = ViewCamera::from_colmap(&camera, &Isometry3::identity(), 0.1, 10.0).unwrap_err();
        assert!(err.to_string().contains("OPENCV"), "{err}");
    }
}
