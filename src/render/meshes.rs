//! Scene data on the GPU: [`GpuScene`] with its [`TextureHandle`]s and [`MeshHandle`]s, texture
//! upload with a box-filtered mip chain (and, for cut-out textures, mip levels that keep the
//! alpha-tested coverage), static and instanced mesh upload and geometry replacement, and the
//! instance transforms ([`InstanceTransform`], [`IDENTITY_INSTANCE`]) as vertex-buffer bytes.

use image::RgbaImage;

use super::{RenderError, Renderer};
use crate::mesh::TriMesh;

/// A handle to a texture uploaded to a [`GpuScene`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureHandle(usize);

/// A handle to a mesh uploaded to a [`GpuScene`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MeshHandle(pub(super) usize);

pub(super) struct GpuMesh {
    /// Vertex and index buffers; `None` for an empty mesh.
    pub(super) buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    pub(super) index_count: u32,
    /// What the id pass writes for it.
    object_id: u32,
    alpha_test: bool,
    /// The object uniform (id, alpha test, unlit), rewritten by [`Renderer::set_shading`].
    object_buffer: wgpu::Buffer,
    pub(super) bind_group: wgpu::BindGroup,
    /// Drawn once, untransformed, by every render (else only through instance batches).
    pub(super) is_static: bool,
    /// Static meshes can be hidden (progressive drawing while a view moves).
    pub(super) visible: bool,
}

/// Meshes and textures on the GPU, ready to render from any view.
pub struct GpuScene {
    textures: Vec<wgpu::TextureView>,
    pub(super) meshes: Vec<GpuMesh>,
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

/// The identity instance transform.
pub const IDENTITY_INSTANCE: InstanceTransform = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

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

/// Mip chain of an RGBA image (level 0 first), each texel of a level made by `average` from
/// the 2×2 texels under it in the level before (clamped at odd edges).
fn downsampled_chain(
    image: &RgbaImage,
    average: impl Fn([image::Rgba<u8>; 4]) -> image::Rgba<u8>,
) -> Vec<RgbaImage> {
    let mut levels = vec![image.clone()];
    loop {
        let last = levels.last().unwrap_or(image);
        let (w, h) = last.dimensions();
        if w == 1 && h == 1 {
            break;
        }
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let next =
            RgbaImage::from_fn(nw, nh, |x, y| {
                average([(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| {
                    *last.get_pixel((2 * x + dx).min(w - 1), (2 * y + dy).min(h - 1))
                }))
            });
        levels.push(next);
    }
    levels
}

/// Box-filtered mip chain of an RGBA image (the bytes averaged).
fn mip_chain(image: &RgbaImage) -> Vec<RgbaImage> {
    downsampled_chain(image, |texels| {
        let mut sum = [0u32; 4];
        for px in texels {
            for c in 0..4 {
                sum[c] += px[c] as u32;
            }
        }
        image::Rgba(sum.map(|s| ((s + 2) / 4) as u8))
    })
}

/// Mip levels of a texture baked from renders (a billboard atlas), averaged in linear light and
/// weighted by alpha.
fn mip_chain_linear(image: &RgbaImage) -> Vec<RgbaImage> {
    // Averaging sRGB bytes darkens, and transparent texels (black beyond the dilated border)
    // would bleed into the colour of every coarser level: distant billboards came out too
    // dark.
    use crate::util::color::{linear_to_srgb, srgb_to_linear};
    let decode: Vec<f32> = (0..=255u8).map(|v| srgb_to_linear(v) as f32).collect();
    let encode = |c: f32| linear_to_srgb(c as f64);
    downsampled_chain(image, |texels| {
        let (mut weighted, mut plain) = ([0f32; 3], [0f32; 3]);
        let (mut alpha_sum, mut alpha_bytes) = (0f32, 0u32);
        for px in texels {
            let alpha = px[3] as f32 / 255.0;
            for c in 0..3 {
                let linear = decode[px[c] as usize];
                weighted[c] += alpha * linear;
                plain[c] += 0.25 * linear;
            }
            alpha_sum += alpha;
            alpha_bytes += px[3] as u32;
        }
        let colour = if alpha_sum > 0.0 {
            weighted.map(|v| v / alpha_sum)
        } else {
            plain
        };
        image::Rgba([
            encode(colour[0]),
            encode(colour[1]),
            encode(colour[2]),
            ((alpha_bytes + 2) / 4) as u8,
        ])
    })
}

/// Per-texel sums carried down a conditioned mip chain (means over the level-0 texels under a
/// texel): the footprint share `m`, alpha on the footprint `am`, alpha everywhere `a`, and
/// linear colour weighted by each.
#[derive(Clone, Copy, Default)]
struct CoverageMoments {
    m: f32,
    am: f32,
    cam: [f32; 3],
    a: f32,
    ca: [f32; 3],
    c: [f32; 3],
}

/// Mip levels of a coverage texture drawn on meshes that follow its outline (leaves): a coarse
/// texel's alpha is the share covered *of the part of it the meshes cover* (`footprint`, one
/// flag per level-0 texel), not of the whole texel. A plain average also counts the
/// transparent texels outside the mesh's outline, which the mesh's own edge already leaves out:
/// a leaf seen small lost its edges twice (a low broadleaf plant at 55 px, 4 % of its light).
/// Texels off the footprint take their neighbours' values, so that bilinear filtering at a
/// mesh's edge reads no outside alpha. Colour is averaged in linear light weighted by alpha.
/// Level 0 is the image itself.
fn mip_chain_on_footprint(image: &RgbaImage, footprint: &[bool]) -> Vec<RgbaImage> {
    use crate::util::color::{linear_to_srgb, srgb_to_linear};
    let decode: Vec<f32> = (0..=255u8).map(|v| srgb_to_linear(v) as f32).collect();
    let (mut w, mut h) = image.dimensions();
    // Level 0's moments are read from the image as needed (a 2048² page would take 190 MB).
    let level0 = |x: u32, y: u32| {
        let px = image.get_pixel(x, y);
        let a = px[3] as f32 / 255.0;
        let m = if footprint
            .get((y * image.width() + x) as usize)
            .copied()
            .unwrap_or(false)
        {
            1.0
        } else {
            0.0
        };
        let c = [0, 1, 2].map(|k| decode[px[k] as usize]);
        CoverageMoments {
            m,
            am: a * m,
            cam: c.map(|v| v * a * m),
            a,
            ca: c.map(|v| v * a),
            c,
        }
    };
    let mut moments: Vec<CoverageMoments> = Vec::new();
    let mut levels = vec![image.clone()];
    while w > 1 || h > 1 {
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let mut next = vec![CoverageMoments::default(); (nw * nh) as usize];
        for y in 0..nh {
            for x in 0..nw {
                let t = &mut next[(y * nw + x) as usize];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = ((2 * x + dx).min(w - 1), (2 * y + dy).min(h - 1));
                    let s = if moments.is_empty() {
                        level0(sx, sy)
                    } else {
                        moments[(sy * w + sx) as usize]
                    };
                    t.m += 0.25 * s.m;
                    t.am += 0.25 * s.am;
                    t.a += 0.25 * s.a;
                    for k in 0..3 {
                        t.cam[k] += 0.25 * s.cam[k];
                        t.ca[k] += 0.25 * s.ca[k];
                        t.c[k] += 0.25 * s.c[k];
                    }
                }
            }
        }
        let texel = |t: &CoverageMoments| -> Option<(f32, [f32; 3])> {
            (t.m > 1e-6).then(|| {
                let colour = if t.am > 1e-6 {
                    t.cam.map(|v| v / t.am)
                } else {
                    t.c
                };
                (t.am / t.m, colour)
            })
        };
        let level = RgbaImage::from_fn(nw, nh, |x, y| {
            let own = &next[(y * nw + x) as usize];
            let (alpha, colour) = texel(own).unwrap_or_else(|| {
                // Off the footprint: the mean of the neighbours on it, else the plain average.
                let (mut n, mut alpha, mut colour) = (0.0f32, 0.0f32, [0.0f32; 3]);
                for (dx, dy) in [
                    (-1, -1),
                    (0, -1),
                    (1, -1),
                    (-1, 0),
                    (1, 0),
                    (-1, 1),
                    (0, 1),
                    (1, 1),
                ] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= nw as i64 || ny >= nh as i64 {
                        continue;
                    }
                    if let Some((a, c)) = texel(&next[(ny as u32 * nw + nx as u32) as usize]) {
                        n += 1.0;
                        alpha += a;
                        for k in 0..3 {
                            colour[k] += c[k];
                        }
                    }
                }
                if n > 0.0 {
                    (alpha / n, colour.map(|v| v / n))
                } else if own.a > 1e-6 {
                    (own.a, own.ca.map(|v| v / own.a))
                } else {
                    (own.a, own.c)
                }
            });
            let encode = |v: f32| linear_to_srgb(v as f64);
            image::Rgba([
                encode(colour[0]),
                encode(colour[1]),
                encode(colour[2]),
                (alpha.clamp(0.0, 1.0) * 255.0).round() as u8,
            ])
        });
        levels.push(level);
        moments = next;
        (w, h) = (nw, nh);
    }
    levels
}

/// Bytes per instance transform.
pub(super) const INSTANCE_BYTES: u64 = 64;

pub(super) fn instance_bytes(transforms: &[InstanceTransform]) -> Vec<u8> {
    transforms
        .iter()
        .flat_map(|m| m.iter().flat_map(|v| v.to_le_bytes()))
        .collect()
}

/// Mip levels whose alpha is rescaled so that each passes the ½ alpha test over the same share
/// of texels as `image` (level 0).
fn with_alpha_coverage(image: &RgbaImage, mut levels: Vec<RgbaImage>) -> Vec<RgbaImage> {
    let coverage = alpha_coverage(image, 1.0);
    for level in levels.iter_mut().skip(1) {
        preserve_alpha_coverage(level, coverage);
    }
    levels
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

impl Renderer {
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
        self.upload_texture(scene, with_alpha_coverage(image, mip_chain(image)))
    }

    /// Uploads a cut-out texture baked from renders (a billboard atlas): its mip levels are
    /// averaged in linear light, weighted by alpha (transparent texels add no colour), and
    /// keep the alpha-tested coverage like [`Renderer::add_cutout_texture`]'s.
    pub fn add_baked_cutout_texture(
        &self,
        scene: &mut GpuScene,
        image: &RgbaImage,
    ) -> TextureHandle {
        self.upload_texture(scene, with_alpha_coverage(image, mip_chain_linear(image)))
    }

    /// Uploads a cut-out texture drawn with alpha as coverage ([`Shading::alpha_coverage`]):
    /// its mip levels average colour in linear light weighted by alpha, and alpha itself, so
    /// that a texel's alpha stays the share of it the surface covers (no rescaling for a ½
    /// cut-off).
    pub fn add_coverage_texture(&self, scene: &mut GpuScene, image: &RgbaImage) -> TextureHandle {
        self.upload_texture(scene, mip_chain_linear(image))
    }

    /// Uploads a coverage texture ([`Renderer::add_coverage_texture`]) drawn on meshes that
    /// follow its outline, such as leaves: `footprint` flags the level-0 texels the meshes
    /// cover (row-major), and a coarse level's alpha is the share covered of that footprint,
    /// so that a mesh's edge and the texture's edge are not both counted.
    pub fn add_coverage_texture_on(
        &self,
        scene: &mut GpuScene,
        image: &RgbaImage,
        footprint: &[bool],
    ) -> TextureHandle {
        self.upload_texture(scene, mip_chain_on_footprint(image, footprint))
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
    ///
    /// [`InstanceBatch`]: super::InstanceBatch
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
        let object_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("object"),
                contents: &object_uniform(object_id, alpha_test, Shading::default()),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
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
            alpha_test,
            object_buffer,
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

    /// Sets how a mesh is shaded: unlit (its texture's colour as is, e.g. a billboard whose
    /// atlas was baked under the scene's light, glTF's `KHR_materials_unlit`) or lit, the
    /// offset added to u on back faces (a two-sided billboard's back tiles; 0 = none), and a
    /// billboard's baked view elevations and edge-on fading.
    pub fn set_shading(
        &self,
        scene: &GpuScene,
        handle: MeshHandle,
        shading: Shading,
    ) -> Result<(), RenderError> {
        let mesh = scene
            .meshes
            .get(handle.0)
            .ok_or(RenderError::UnknownMesh(handle.0))?;
        self.queue.write_buffer(
            &mesh.object_buffer,
            0,
            &object_uniform(mesh.object_id, mesh.alpha_test, shading),
        );
        Ok(())
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
}

/// How a mesh is shaded beyond its texture (see [`Renderer::set_shading`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Shading {
    /// The texture's colour as is, without lighting (a billboard baked lit;
    /// `KHR_materials_unlit` in a glb).
    pub unlit: bool,
    /// Added to u on back faces (a two-sided billboard's back tiles beside the front ones);
    /// 0 = none.
    #[serde(default)]
    pub back_uv_offset: f32,
    /// The views a billboard was baked from; `None` for ordinary geometry.
    #[serde(default)]
    pub views: Option<BillboardViews>,
    /// A cut-out's alpha is the share of a texel the surface covers: the colour pass covers
    /// that share of a pixel's samples and the id pass that share of the pixels (dithered),
    /// instead of all or nothing at ½, so that foliage seen small keeps its light (leaves
    /// thinner than a pixel, a billboard's mips). For textures uploaded with
    /// [`Renderer::add_coverage_texture`].
    #[serde(default)]
    pub alpha_coverage: bool,
}

/// A billboard baked from several view elevations, with quads that fade as they turn edge-on.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BillboardViews {
    /// Atlas rows stacked in v: row r (at v + r / rows) holds the plant as seen
    /// `r · elevation_step_rad` above the horizon; a fragment blends the two rows nearest its
    /// view elevation (views above the last row use the last row, views from below the first).
    pub elevation_rows: u32,
    pub elevation_step_rad: f32,
    /// The star's quads, π / `quads` apart about the vertical (0 = every quad always drawn).
    /// Quad k (its normal's azimuth − 90° = k·π / quads) is drawn where it is the nearer of
    /// the two quads facing the viewer most (θ, the angle between its plane's normal and the
    /// horizontal view direction, below half the spacing), and within the middle 30 % of the
    /// spacing the two cross-dissolve by complementary dithers (even and odd k): quads seen
    /// edge-on, which show the plant as baked from elsewhere, give way, and no pixel shows two
    /// overlaid bakes.
    pub quads: u32,
    /// Where the quads meet: the star's vertical axis (x, y in the mesh's frame). Quads that
    /// face a viewer on the axis more than the spacing away are not rasterized at all.
    #[serde(default)]
    pub axis: [f32; 2],
    /// The plant's height range (z in the mesh's frame); the quads reach above and below it
    /// by as much as the highest baked elevation needs, and a vertex stage trims them to what
    /// the view's elevation needs (less to rasterize). Equal values: no trimming.
    #[serde(default)]
    pub plant_z: [f32; 2],
}

/// The object uniform: id, alpha test, unlit, back-face u offset, elevation rows and step,
/// star quads and axis, alpha as coverage, the plant's height range.
fn object_uniform(object_id: u32, alpha_test: bool, shading: Shading) -> Vec<u8> {
    let views = shading.views.unwrap_or(BillboardViews {
        elevation_rows: 1,
        elevation_step_rad: 0.0,
        quads: 0,
        axis: [0.0; 2],
        plant_z: [0.0; 2],
    });
    [
        object_id,
        alpha_test as u32,
        shading.unlit as u32,
        shading.back_uv_offset.to_bits(),
        views.elevation_rows.max(1),
        views.elevation_step_rad.to_bits(),
        views.quads,
        views.axis[0].to_bits(),
        views.axis[1].to_bits(),
        shading.alpha_coverage as u32,
        views.plant_z[0].to_bits(),
        views.plant_z[1].to_bits(),
    ]
    .iter()
    .flat_map(|v| v.to_le_bytes())
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn coverage_mips_on_a_footprint_count_only_the_meshes_texels() {
        // An opaque disc on a transparent page, drawn on a mesh that follows its outline.
        let inside = |x: u32, y: u32| {
            let (dx, dy) = (x as f32 + 0.5 - 32.0, y as f32 + 0.5 - 32.0);
            dx * dx + dy * dy < 20.0 * 20.0
        };
        let page = RgbaImage::from_fn(64, 64, |x, y| {
            image::Rgba([40, 160, 40, if inside(x, y) { 255 } else { 0 }])
        });
        let disc: Vec<bool> = (0..64 * 64).map(|i| inside(i % 64, i / 64)).collect();
        let plain = mip_chain_linear(&page);
        let on_disc = mip_chain_on_footprint(&page, &disc);
        assert_eq!(plain.len(), on_disc.len());
        assert_eq!(on_disc[0], page);
        // At 8×8 texels per texel the disc's edge texels are partly transparent on average,
        // but wholly opaque where the mesh is; every texel near the disc reads opaque.
        let (p3, d3) = (&plain[3], &on_disc[3]);
        let edge = (0..64u32)
            .map(|i| (i % 8, i / 8))
            .filter(|&(x, y)| (1..255).contains(&p3.get_pixel(x, y)[3]))
            .count();
        assert!(edge >= 8, "{edge} edge texels");
        for y in 0..8 {
            for x in 0..8 {
                let (cx, cy) = (x as f32 * 8.0 + 4.0 - 32.0, y as f32 * 8.0 + 4.0 - 32.0);
                if (cx * cx + cy * cy).sqrt() < 20.0 + 8.0 {
                    assert_eq!(d3.get_pixel(x, y)[3], 255, "texel {x},{y}");
                }
                // The colour is the disc's, never darkened by the transparent texels.
                assert!(d3.get_pixel(x, y)[1] >= 158, "texel {x},{y}");
            }
        }
        // Over a footprint that covers the whole page alpha is the plain average.
        let all = vec![true; 64 * 64];
        for (a, b) in mip_chain_on_footprint(&page, &all).iter().zip(&plain) {
            for (p, q) in a.pixels().zip(b.pixels()) {
                assert!((p[3] as i32 - q[3] as i32).abs() <= 1, "{p:?} {q:?}");
            }
        }
    }
}
