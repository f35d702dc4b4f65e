//! A plant as the LOD and scene code see it: a few parts (one mesh per material: leaves per
//! atlas page, branches per colour) and their textures, made from a [`PlantModel`] or read
//! back from a `plant.glb`.

use std::path::Path;

use image::{Rgba, RgbaImage};
use nalgebra::Point3;

use crate::mesh::TriMesh;
use crate::model::PlantModel;
use crate::model::gltf::{GlbPart, GltfError, read_glb_parts, read_glb_up};
use crate::model::plant::Atlas;

/// One material's geometry.
#[derive(Clone, Debug)]
pub struct AssetPart {
    /// `leaves_N` or `branches_N` (or the glb node name).
    pub name: String,
    pub mesh: TriMesh,
    /// Index into [`PlantAsset::textures`].
    pub texture: usize,
    /// Cut-out texture (leaves, billboards).
    pub alpha_test: bool,
    /// Leaves (double-sided foliage) rather than wood.
    pub is_leaf: bool,
    /// How the render core shades it beyond its texture: unlit (a billboard baked lit;
    /// `KHR_materials_unlit` in a glb), back tiles, baked view elevations.
    pub shading: crate::render::Shading,
}

/// A renderable plant: parts and their textures (sRGB).
#[derive(Clone, Debug, Default)]
pub struct PlantAsset {
    pub parts: Vec<AssetPart>,
    pub textures: Vec<RgbaImage>,
}

/// A linear colour as an sRGB texel.
fn srgb_texel(linear: [f32; 4]) -> Rgba<u8> {
    let encode = |c: f32| crate::util::color::linear_to_srgb(c as f64);
    Rgba([
        encode(linear[0]),
        encode(linear[1]),
        encode(linear[2]),
        (linear[3].clamp(0.0, 1.0) * 255.0).round() as u8,
    ])
}

/// Uploads `textures` for drawing `parts`: one a part drawn with alpha as coverage uses (leaves,
/// a billboard atlas baked with views) with colour and alpha averaged in linear light, another
/// unlit part's (an older billboard) with mips averaged in linear light and its cut-out
/// coverage kept, one another cut-out part uses with coverage-preserving mips, any other as it
/// is.
pub fn upload_textures(
    renderer: &crate::render::Renderer,
    gpu: &mut crate::render::GpuScene,
    textures: &[RgbaImage],
    parts: &[&AssetPart],
) -> Vec<crate::render::TextureHandle> {
    textures
        .iter()
        .enumerate()
        .map(|(i, image)| {
            let users = || parts.iter().filter(|p| p.texture == i);
            let coverage = users().any(|p| p.shading().alpha_coverage);
            // Baked atlases (billboards) are read beyond their quads' uvs (back tiles, view
            // rows); other coverage textures are read only inside their meshes.
            let baked =
                users().any(|p| p.shading.views.is_some() || p.shading.back_uv_offset != 0.0);
            if coverage && !baked {
                let footprint =
                    uv_footprint(image.width(), image.height(), users().map(|p| &p.mesh));
                renderer.add_coverage_texture_on(gpu, image, &footprint)
            } else if coverage {
                renderer.add_coverage_texture(gpu, image)
            } else if users().any(|p| p.shading.unlit) {
                renderer.add_baked_cutout_texture(gpu, image)
            } else if users().any(|p| p.alpha_test) {
                renderer.add_cutout_texture(gpu, image)
            } else {
                renderer.add_texture(gpu, image)
            }
        })
        .collect()
}

/// The texels (row-major, `width` × `height`) whose centre lies in the uv image of a triangle
/// of `meshes` (uv (0, 0) at the image's top-left corner): where the meshes read a texture.
pub fn uv_footprint<'a>(
    width: u32,
    height: u32,
    meshes: impl Iterator<Item = &'a crate::mesh::TriMesh>,
) -> Vec<bool> {
    let mut inside = vec![false; (width * height) as usize];
    let (w, h) = (width as f32, height as f32);
    for mesh in meshes {
        for tri in &mesh.triangles {
            let Some(corners) = tri
                .iter()
                .map(|&i| mesh.uvs.get(i as usize).map(|uv| [uv[0] * w, uv[1] * h]))
                .collect::<Option<Vec<[f32; 2]>>>()
            else {
                continue;
            };
            let [a, b, c] = [corners[0], corners[1], corners[2]];
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if area.abs() < 1e-12 {
                continue;
            }
            let lo = |k: usize| a[k].min(b[k]).min(c[k]).floor().max(0.0) as u32;
            let hi = |k: usize, n: u32| (a[k].max(b[k]).max(c[k]).ceil().max(0.0) as u32).min(n);
            let edge = |p: [f32; 2], q: [f32; 2], x: f32, y: f32| {
                ((q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0])) / area
            };
            for y in lo(1)..hi(1, height) {
                for x in lo(0)..hi(0, width) {
                    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                    if edge(a, b, px, py) >= -1e-6
                        && edge(b, c, px, py) >= -1e-6
                        && edge(c, a, px, py) >= -1e-6
                    {
                        inside[(y * width + x) as usize] = true;
                    }
                }
            }
        }
    }
    inside
}

impl AssetPart {
    /// How the render core shades it. Cut-out leaves and billboards baked with views draw their alpha as coverage, so that a
    /// plant seen small keeps its light (all-or-nothing alpha lost 44 % of a broadleaf
    /// plant's light at 55 px) and its billboard matches it.
    pub fn shading(&self) -> crate::render::Shading {
        crate::render::Shading {
            alpha_coverage: self.alpha_test && (self.is_leaf || self.shading.views.is_some()),
            ..self.shading
        }
    }
}

impl PlantAsset {
    /// Leaves merged per atlas page (cut-out), branches merged per colour (a 1×1 texture).
    pub fn from_model(model: &PlantModel) -> Self {
        let mut asset = Self::default();
        let atlas = Atlas::pack(&model.leaves);
        for (page, image) in atlas.pages.iter().enumerate() {
            let mut mesh = TriMesh::default();
            for (i, leaf) in model.leaves.iter().enumerate() {
                if atlas.placements[i].0 == page {
                    mesh.append(&atlas.remap(i, &leaf.mesh));
                }
            }
            asset.textures.push(image.clone());
            asset.parts.push(AssetPart {
                name: format!("leaves_{page}"),
                mesh,
                texture: asset.textures.len() - 1,
                alpha_test: true,
                is_leaf: true,
                shading: Default::default(),
            });
        }
        // (colour, part index) of each branch colour seen so far.
        let mut wood: Vec<([f32; 4], usize)> = Vec::new();
        for branch in &model.branches {
            let index = match wood.iter().find(|(c, _)| *c == branch.color) {
                Some(&(_, index)) => index,
                None => {
                    asset
                        .textures
                        .push(RgbaImage::from_pixel(1, 1, srgb_texel(branch.color)));
                    asset.parts.push(AssetPart {
                        name: format!("branches_{}", wood.len()),
                        mesh: TriMesh::default(),
                        texture: asset.textures.len() - 1,
                        alpha_test: false,
                        is_leaf: false,
                        shading: Default::default(),
                    });
                    wood.push((branch.color, asset.parts.len() - 1));
                    asset.parts.len() - 1
                }
            };
            asset.parts[index].mesh.append(&branch.mesh);
        }
        asset.parts.retain(|p| !p.mesh.is_empty());
        asset
    }

    /// Reads a `plant.glb` into the plant's upright frame (a glb that records its up
    /// direction, as `frond reconstruct`'s does, is rotated about the origin so that up is
    /// +z; one that does not is taken as z-up). Every primitive of the default scene becomes a
    /// part; a part
    /// without a texture gets a 1×1 texture of its base colour. Parts named `leaf_*` (or
    /// with cut-out materials) count as leaves.
    pub fn read_glb(path: &Path) -> Result<Self, GltfError> {
        let bytes = std::fs::read(path).map_err(|e| GltfError::Invalid {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        let glb = read_glb_parts(&bytes, path)?;
        let mut textures = glb.images;
        let mut parts = parts_from_glb(glb.parts, &mut textures);
        if let Some(up) = read_glb_up(&bytes, path)? {
            rotate_upright(&mut parts, &up);
        }
        Ok(Self { parts, textures })
    }

    /// Parts of glb primitives whose textures are in `textures` (the glb's images; colour
    /// textures and tinted copies are appended), merged by material.
    pub fn from_glb_parts(parts: Vec<GlbPart>, textures: &mut Vec<RgbaImage>) -> Self {
        Self {
            parts: parts_from_glb(parts, textures),
            textures: Vec::new(),
        }
    }
    pub fn triangles(&self) -> usize {
        self.parts.iter().map(|p| p.mesh.triangles.len()).sum()
    }

    /// All parts in one mesh.
    pub fn merged(&self) -> TriMesh {
        let mut mesh = TriMesh::default();
        for part in &self.parts {
            mesh.append(&part.mesh);
        }
        mesh
    }

    /// Axis-aligned bounds of all parts.
    pub fn bounds(&self) -> Option<(Point3<f32>, Point3<f32>)> {
        self.parts
            .iter()
            .filter_map(|p| p.mesh.bounds())
            .reduce(|(lo, hi), (a, b)| (lo.inf(&a), hi.sup(&b)))
    }

    /// The plant's vertical axis (through the centre of its bounds, z up) and the largest
    /// horizontal distance of a vertex from it.
    pub fn vertical_axis_and_reach(&self) -> Option<(nalgebra::Point2<f32>, f32)> {
        let (lo, hi) = self.bounds()?;
        let axis = nalgebra::Point2::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y));
        let reach = self
            .parts
            .iter()
            .flat_map(|p| p.mesh.positions.iter())
            .map(|p| (nalgebra::Point2::new(p.x, p.y) - axis).norm())
            .fold(0.0f32, f32::max);
        Some((axis, reach))
    }

    /// Bounding sphere (centre of the bounds, farthest vertex).
    pub fn bounding_sphere(&self) -> Option<(Point3<f32>, f32)> {
        let (lo, hi) = self.bounds()?;
        let center = nalgebra::center(&lo, &hi);
        let radius = self
            .parts
            .iter()
            .flat_map(|p| p.mesh.positions.iter())
            .map(|p| (p - center).norm())
            .fold(0.0f32, f32::max);
        Some((center, radius))
    }
}

/// Rotates `parts` about the origin so that `up` becomes +z (positions and normals).
pub fn rotate_upright(parts: &mut [AssetPart], up: &nalgebra::Vector3<f64>) {
    let rotation = nalgebra::UnitQuaternion::rotation_between(up, &nalgebra::Vector3::z())
        .unwrap_or_else(|| {
            // Exactly upside down: half a turn about x.
            nalgebra::UnitQuaternion::from_axis_angle(
                &nalgebra::Vector3::x_axis(),
                std::f64::consts::PI,
            )
        })
        .cast::<f32>();
    if rotation.angle() == 0.0 {
        return;
    }
    for part in parts {
        for p in &mut part.mesh.positions {
            *p = rotation * *p;
        }
        for n in &mut part.mesh.normals {
            *n = rotation * *n;
        }
    }
}

/// Parts of glb primitives (see [`PlantAsset::from_glb_parts`]). A part without a texture gets
/// a 1×1 texture of its base colour; parts named `leaf_*` (or with cut-out materials) count as
/// leaves. Parts sharing a texture and flags are merged (a `plant.glb` has one node per leaf,
/// all on the same atlas page).
fn parts_from_glb(glb_parts: Vec<GlbPart>, textures: &mut Vec<RgbaImage>) -> Vec<AssetPart> {
    let mut merged: Vec<AssetPart> = Vec::new();
    // One texture per distinct colour (a plant.glb has a material per branch).
    let mut colour_textures: Vec<([f32; 4], Option<usize>, usize)> = Vec::new();
    for part in glb_parts {
        let image = part.image.filter(|&i| i < textures.len());
        let texture = match (image, part.color == [1.0; 4]) {
            (Some(image), true) => image,
            _ => match colour_textures
                .iter()
                .find(|(c, i, _)| *c == part.color && *i == image)
            {
                Some(&(_, _, texture)) => texture,
                None => {
                    // A colour alone, or a colour factor folded into a copy of the texture.
                    textures.push(match image {
                        Some(image) => tint(&textures[image], part.color),
                        None => RgbaImage::from_pixel(1, 1, srgb_texel(part.color)),
                    });
                    colour_textures.push((part.color, image, textures.len() - 1));
                    textures.len() - 1
                }
            },
        };
        let is_leaf = part.name.starts_with("leaf") || part.alpha_mask;
        let alpha_test = part.alpha_mask || (is_leaf && part.image.is_some());
        match merged.iter_mut().find(|m| {
            m.texture == texture
                && m.alpha_test == alpha_test
                && m.is_leaf == is_leaf
                && m.shading == part.shading
        }) {
            Some(existing) => existing.mesh.append(&part.mesh),
            None => {
                let name = if is_leaf {
                    format!("leaves_{}", merged.len())
                } else {
                    format!("branches_{}", merged.len())
                };
                merged.push(AssetPart {
                    name,
                    mesh: part.mesh,
                    texture,
                    alpha_test,
                    is_leaf,
                    shading: part.shading,
                });
            }
        }
    }
    merged
}

/// `image` multiplied by a linear colour factor (in sRGB texels, approximately).
fn tint(image: &RgbaImage, color: [f32; 4]) -> RgbaImage {
    let factor = srgb_texel(color);
    RgbaImage::from_fn(image.width(), image.height(), |x, y| {
        let p = image.get_pixel(x, y);
        Rgba(std::array::from_fn(|c| {
            ((p[c] as u32 * factor[c] as u32 + 127) / 255) as u8
        }))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uv_footprint_holds_the_texels_whose_centres_a_triangle_covers() {
        // The lower-left half of a 4×4 page (the diagonal through texel centres counts).
        let mut mesh = crate::mesh::TriMesh {
            positions: vec![nalgebra::Point3::origin(); 3],
            normals: vec![nalgebra::Vector3::z(); 3],
            uvs: vec![[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            triangles: vec![[0, 1, 2]],
        };
        let inside = uv_footprint(4, 4, std::iter::once(&mesh));
        for y in 0..4 {
            for x in 0..4 {
                assert_eq!(inside[y * 4 + x], x <= y, "texel {x},{y}");
            }
        }
        // Either winding; uvs beyond the page are clipped.
        mesh.uvs = vec![[-1.0, -1.0], [2.0, -1.0], [-1.0, 2.0]];
        mesh.triangles = vec![[0, 2, 1]];
        assert_eq!(
            uv_footprint(4, 4, std::iter::once(&mesh)),
            (0..16).map(|i| i % 4 + i / 4 <= 3).collect::<Vec<_>>()
        );
    }
    use crate::synth::{Preset, generate_plant};

    #[test]
    fn a_synthetic_plant_survives_the_glb_round_trip_as_an_asset() {
        let plant = generate_plant(Preset::Broadleaf, 3);
        let model = crate::synth::plant_model(&plant, 64);
        let asset = PlantAsset::from_model(&model);
        assert!(asset.parts.iter().any(|p| p.is_leaf && p.alpha_test));
        assert!(asset.parts.iter().any(|p| !p.is_leaf));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plant.glb");
        std::fs::write(&path, model.to_glb()).unwrap();
        let read = PlantAsset::read_glb(&path).unwrap();
        assert_eq!(read.triangles(), asset.triangles());
        assert_eq!(
            read.parts.iter().filter(|p| p.is_leaf).count(),
            asset.parts.iter().filter(|p| p.is_leaf).count()
        );
        let (c0, r0) = asset.bounding_sphere().unwrap();
        let (c1, r1) = read.bounding_sphere().unwrap();
        assert!((c0 - c1).norm() < 1e-5 && (r0 - r1).abs() < 1e-5);
        // Branch colour survives as a texel.
        let wood = read.parts.iter().find(|p| !p.is_leaf).unwrap();
        assert_eq!(read.textures[wood.texture].dimensions(), (1, 1));
    }

    /// Renders `asset` from a side view: colour and coverage.
    fn side_view(asset: &PlantAsset) -> crate::render::RenderOutput {
        let mut renderer = crate::render::Renderer::new().unwrap();
        let mut gpu = renderer.new_scene();
        for part in &asset.parts {
            let texture = renderer.add_texture(&mut gpu, &asset.textures[part.texture]);
            renderer
                .add_mesh(&mut gpu, &part.mesh, texture, 1, part.alpha_test)
                .unwrap();
        }
        let (center, radius) = asset.bounding_sphere().unwrap();
        let center = center.cast::<f64>();
        let eye = center + nalgebra::Vector3::new(0.3, -1.0, 0.5).normalize() * 4.0 * radius as f64;
        let camera = crate::render::ViewCamera {
            width: 160,
            height: 120,
            fx: 200.0,
            fy: 200.0,
            cx: 80.0,
            cy: 60.0,
            camera_from_world: crate::scene::synthetic::look_at(eye, center),
            near: 0.01,
            far: 10.0,
        };
        renderer
            .render(&gpu, &camera, &crate::render::Lighting::default())
            .unwrap()
    }

    #[test]
    fn a_glb_read_asset_renders_like_the_model_it_was_written_from() {
        let plant = generate_plant(Preset::Medium, 6);
        let model = crate::synth::plant_model(&plant, 32);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plant.glb");
        std::fs::write(&path, model.to_glb()).unwrap();
        let (a, b) = (
            side_view(&PlantAsset::from_model(&model)),
            side_view(&PlantAsset::read_glb(&path).unwrap()),
        );
        let covered = a.object_id.iter().filter(|&&id| id != 0).count();
        let same_coverage = a
            .object_id
            .iter()
            .zip(&b.object_id)
            .filter(|(x, y)| x == y)
            .count();
        let differing = a
            .color
            .pixels()
            .zip(b.color.pixels())
            .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 12))
            .count();
        assert!(covered > 500, "{covered}");
        assert!(same_coverage as f64 > 0.995 * a.object_id.len() as f64);
        assert!(
            (differing as f64) < 0.02 * covered as f64,
            "{differing} of {covered}"
        );
    }

    #[test]
    fn a_plant_recorded_with_a_tilted_up_is_read_upright() {
        let plant = generate_plant(Preset::Broadleaf, 8);
        let mut model = crate::synth::plant_model(&plant, 16);
        let upright = PlantAsset::from_model(&model);
        // The same plant in a COLMAP-like frame: tilted, with its up recorded.
        let tilt = nalgebra::UnitQuaternion::from_euler_angles(1.1, -0.4, 2.0);
        for leaf in &mut model.leaves {
            leaf.mesh.transform(&nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::identity(),
                tilt.cast::<f32>(),
            ));
        }
        for branch in &mut model.branches {
            branch.mesh.transform(&nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::identity(),
                tilt.cast::<f32>(),
            ));
        }
        model.up = Some((tilt * nalgebra::Vector3::z()).into());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plant.glb");
        std::fs::write(&path, model.to_glb()).unwrap();
        let read = PlantAsset::read_glb(&path).unwrap();
        let ((lo0, hi0), (lo1, hi1)) = (upright.bounds().unwrap(), read.bounds().unwrap());
        // Upright again up to a turn about z: the height range is the original one.
        assert!(
            (lo0.z - lo1.z).abs() < 1e-4 && (hi0.z - hi1.z).abs() < 1e-4,
            "{lo1:?} {hi1:?}"
        );
        // Every vertex keeps its height (the heights, sorted, agree).
        let heights = |asset: &PlantAsset| {
            let mut z: Vec<f32> = asset
                .parts
                .iter()
                .flat_map(|p| p.mesh.positions.iter().map(|q| q.z))
                .collect();
            z.sort_by(f32::total_cmp);
            z
        };
        let (z0, z1) = (heights(&upright), heights(&read));
        assert_eq!(z0.len(), z1.len());
        assert!(z0.iter().zip(&z1).all(|(a, b)| (a - b).abs() < 1e-4));
    }

    #[test]
    fn srgb_encoding_matches_the_standard_curve() {
        assert_eq!(srgb_texel([0.0, 1.0, 0.5, 1.0]).0, [0, 255, 188, 255]);
    }
}
