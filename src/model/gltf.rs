//! glTF 2.0 binary (`.glb`) export and import of plant models.
//!
//! Export follows the evaluation contract: one node per part named `leaf_NNN` / `branch_NNN`,
//! identity node transforms, vertex positions in the input model's world frame; textures are
//! embedded as PNG; leaves are double-sided. Import (through the `gltf` crate, an independent
//! implementation) returns each named node's mesh in world coordinates.

use std::path::Path;

use image::RgbaImage;
use nalgebra::{Matrix4, Point3, Vector3};
use serde_json::{Value, json};

use crate::mesh::TriMesh;
use crate::render::{BillboardViews, Shading};

/// A mesh to export, with an optional base-colour texture (an index into the textures given
/// to [`write_glb`], so that leaves can share an atlas page).
pub struct ExportNode<'a> {
    pub name: String,
    pub mesh: &'a TriMesh,
    pub texture: Option<usize>,
    /// Base colour when there is no texture (linear RGBA).
    pub color: [f32; 4],
    pub double_sided: bool,
    /// The group node this node is a child of (e.g. `compound_leaf_002` for a leaflet and its
    /// rachis); `None` for a scene root.
    pub group: Option<String>,
}

/// A mesh read back from a glb, by node name, in world coordinates.
#[derive(Clone, Debug)]
pub struct NamedMesh {
    pub name: String,
    pub mesh: TriMesh,
    /// The name of the node's parent, if it has one.
    pub group: Option<String>,
}

/// glb import failures.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    #[error("{path}: {message}")]
    Invalid { path: String, message: String },
}

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

struct BinaryBuffer {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl BinaryBuffer {
    fn align(&mut self) {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
    }

    fn view(&mut self, data: &[u8], target: Option<u32>) -> usize {
        self.align();
        let offset = self.bytes.len();
        self.bytes.extend_from_slice(data);
        let mut view = json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len()});
        if let Some(target) = target {
            view["target"] = json!(target);
        }
        self.views.push(view);
        self.views.len() - 1
    }

    fn accessor_f32(&mut self, values: &[f32], components: usize, with_bounds: bool) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ARRAY_BUFFER));
        let kind = match components {
            2 => "VEC2",
            3 => "VEC3",
            _ => "SCALAR",
        };
        let count = values.len() / components;
        let mut accessor = json!({
            "bufferView": view, "componentType": FLOAT, "count": count, "type": kind
        });
        if with_bounds && count > 0 {
            let mut lo = vec![f32::INFINITY; components];
            let mut hi = vec![f32::NEG_INFINITY; components];
            for chunk in values.chunks_exact(components) {
                for c in 0..components {
                    lo[c] = lo[c].min(chunk[c]);
                    hi[c] = hi[c].max(chunk[c]);
                }
            }
            accessor["min"] = json!(lo);
            accessor["max"] = json!(hi);
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn accessor_indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = triangles
            .iter()
            .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
            .collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view, "componentType": UNSIGNED_INT,
            "count": triangles.len() * 3, "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }
}

fn png_bytes(image: &RgbaImage) -> Vec<u8> {
    let mut out = Vec::new();
    // Encoding an in-memory RGBA image to PNG cannot fail for valid dimensions.
    let _ = image.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png);
    out
}

/// A triangle primitive to write: a mesh and its material.
pub struct PrimitiveSpec<'a> {
    pub mesh: &'a TriMesh,
    /// Index of a texture added with [`GlbBuilder::add_texture`].
    pub texture: Option<usize>,
    /// Base colour (linear RGBA; multiplied with the texture).
    pub color: [f32; 4],
    pub double_sided: bool,
    /// Cut-out transparency (`alphaMode: MASK`, cutoff ½).
    pub alpha_mask: bool,
    /// Unlit (`KHR_materials_unlit`), a back-face u offset and baked billboard views (the
    /// material's extras, [`BACK_UV_OFFSET_KEY`] and [`BILLBOARD_VIEWS_KEY`]).
    pub shading: Shading,
}

/// Key of a material's back-face u offset in its `extras`.
pub const BACK_UV_OFFSET_KEY: &str = "frond_back_uv_offset";
/// Key of a billboard material's baked views ([`crate::render::BillboardViews`]) in its
/// `extras`.
pub const BILLBOARD_VIEWS_KEY: &str = "frond_billboard_views";

impl<'a> PrimitiveSpec<'a> {
    /// A leaf: double-sided, cut-out, its texture's colour.
    pub fn leaf(mesh: &'a TriMesh, texture: Option<usize>) -> Self {
        Self {
            mesh,
            texture,
            color: [1.0; 4],
            double_sided: true,
            alpha_mask: true,
            shading: Shading::default(),
        }
    }

    /// Wood and other solids: one-sided, opaque, lit.
    pub fn solid(mesh: &'a TriMesh, texture: Option<usize>, color: [f32; 4]) -> Self {
        Self {
            mesh,
            texture,
            color,
            double_sided: false,
            alpha_mask: false,
            shading: Shading::default(),
        }
    }
}

/// Builds a glTF 2.0 binary: textures (embedded PNG), meshes of several primitives, nodes
/// (any JSON, e.g. with extensions) and the scene's root nodes.
pub struct GlbBuilder {
    generator: String,
    buffer: BinaryBuffer,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    textures: Vec<Value>,
    images: Vec<Value>,
    nodes: Vec<Value>,
    scene_nodes: Vec<usize>,
    extensions_used: Vec<String>,
    asset_extras: Value,
}

/// Key of the plant's up direction (world frame) in a glb's `asset.extras`.
pub const UP_KEY: &str = "frond_up";

impl GlbBuilder {
    pub fn new(generator: &str) -> Self {
        Self {
            generator: generator.to_owned(),
            buffer: BinaryBuffer {
                bytes: Vec::new(),
                views: Vec::new(),
                accessors: Vec::new(),
            },
            meshes: Vec::new(),
            materials: Vec::new(),
            textures: Vec::new(),
            images: Vec::new(),
            nodes: Vec::new(),
            scene_nodes: Vec::new(),
            extensions_used: Vec::new(),
            asset_extras: Value::Null,
        }
    }

    /// Sets `asset.extras` (e.g. the plant's up direction under [`UP_KEY`]).
    pub fn set_asset_extras(&mut self, extras: Value) {
        self.asset_extras = extras;
    }

    /// Embeds an image as PNG; returns its texture index.
    pub fn add_texture(&mut self, image: &RgbaImage) -> usize {
        let view = self.buffer.view(&png_bytes(image), None);
        self.images
            .push(json!({"bufferView": view, "mimeType": "image/png"}));
        self.textures
            .push(json!({"source": self.images.len() - 1, "sampler": 0}));
        self.textures.len() - 1
    }

    /// Adds a mesh of the non-empty primitives; `None` when all are empty.
    pub fn add_mesh(&mut self, name: &str, primitives: &[PrimitiveSpec<'_>]) -> Option<usize> {
        let mut written = Vec::new();
        for (k, primitive) in primitives.iter().enumerate() {
            let mesh = primitive.mesh;
            if mesh.is_empty() {
                continue;
            }
            let positions: Vec<f32> = mesh
                .positions
                .iter()
                .flat_map(|p| [p.x, p.y, p.z])
                .collect();
            let normals: Vec<f32> = mesh.normals.iter().flat_map(|n| [n.x, n.y, n.z]).collect();
            let uvs: Vec<f32> = mesh.uvs.iter().flat_map(|uv| [uv[0], uv[1]]).collect();
            let position = self.buffer.accessor_f32(&positions, 3, true);
            let normal = self.buffer.accessor_f32(&normals, 3, false);
            let uv = self.buffer.accessor_f32(&uvs, 2, false);
            let indices = self.buffer.accessor_indices(&mesh.triangles);
            let material_name = if primitives.len() == 1 {
                format!("{name}_material")
            } else {
                format!("{name}_material_{k}")
            };
            let mut material = json!({
                "name": material_name,
                "doubleSided": primitive.double_sided,
                "pbrMetallicRoughness": {
                    "baseColorFactor": primitive.color,
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.85
                }
            });
            if let Some(texture) = primitive.texture.filter(|&t| t < self.textures.len()) {
                material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": texture});
            }
            if primitive.alpha_mask {
                material["alphaMode"] = json!("MASK");
                material["alphaCutoff"] = json!(0.5);
            }
            let shading = &primitive.shading;
            if shading.unlit {
                material["extensions"] = json!({"KHR_materials_unlit": {}});
                self.use_extension("KHR_materials_unlit");
            }
            if shading.back_uv_offset != 0.0 {
                material["extras"][BACK_UV_OFFSET_KEY] = json!(shading.back_uv_offset);
            }
            if let Some(views) = &shading.views {
                material["extras"][BILLBOARD_VIEWS_KEY] = json!(views);
            }
            self.materials.push(material);
            written.push(json!({
                "attributes": {"POSITION": position, "NORMAL": normal, "TEXCOORD_0": uv},
                "indices": indices,
                "material": self.materials.len() - 1,
                "mode": 4
            }));
        }
        if written.is_empty() {
            return None;
        }
        self.meshes
            .push(json!({"name": name, "primitives": written}));
        Some(self.meshes.len() - 1)
    }

    /// Adds a node (a JSON object: name, mesh, extensions, extras …); returns its index.
    pub fn add_node(&mut self, node: Value) -> usize {
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    /// Replaces node `index` (e.g. to add extensions that name nodes added after it).
    pub fn replace_node(&mut self, index: usize, node: Value) {
        if let Some(slot) = self.nodes.get_mut(index) {
            *slot = node;
        }
    }

    /// Makes `node` a root of the scene.
    pub fn add_to_scene(&mut self, node: usize) {
        self.scene_nodes.push(node);
    }

    /// Declares an extension in `extensionsUsed`.
    pub fn use_extension(&mut self, name: &str) {
        if !self.extensions_used.iter().any(|e| e == name) {
            self.extensions_used.push(name.to_owned());
        }
    }

    /// The glb bytes.
    pub fn finish(mut self) -> Vec<u8> {
        self.buffer.align();
        let mut document = json!({
            "asset": {"version": "2.0", "generator": self.generator},
            "scene": 0,
            "scenes": [{"name": "plant", "nodes": self.scene_nodes}],
            "nodes": self.nodes,
        });
        if !self.extensions_used.is_empty() {
            document["extensionsUsed"] = json!(self.extensions_used);
        }
        if !self.asset_extras.is_null() {
            document["asset"]["extras"] = self.asset_extras.clone();
        }
        if !self.meshes.is_empty() {
            document["meshes"] = json!(self.meshes);
            document["materials"] = json!(self.materials);
            document["accessors"] = json!(self.buffer.accessors);
        }
        if !self.buffer.bytes.is_empty() {
            document["bufferViews"] = json!(self.buffer.views);
            document["buffers"] = json!([{"byteLength": self.buffer.bytes.len()}]);
        }
        if !self.textures.is_empty() {
            document["textures"] = json!(self.textures);
            document["images"] = json!(self.images);
            document["samplers"] =
                json!([{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]);
        }
        let mut json_bytes = serde_json::to_vec(&document).unwrap_or_default();
        while !json_bytes.len().is_multiple_of(4) {
            json_bytes.push(b' ');
        }
        let bin = &self.buffer.bytes;
        let has_bin = !bin.is_empty();
        let total = 12 + 8 + json_bytes.len() + if has_bin { 8 + bin.len() } else { 0 };
        let mut out = Vec::with_capacity(total);
        for v in [
            GLB_MAGIC,
            2,
            total as u32,
            json_bytes.len() as u32,
            CHUNK_JSON,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&json_bytes);
        if has_bin {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
            out.extend_from_slice(bin);
        }
        out
    }
}

/// Encodes nodes as a glb (one single-primitive mesh per node; a node is a scene root, or a
/// child of its group's node, which is a scene root without a mesh); `textures` are embedded
/// once each as PNG.
pub fn write_glb(nodes: &[ExportNode<'_>], textures: &[&RgbaImage], generator: &str) -> Vec<u8> {
    write_glb_with_extras(nodes, textures, generator, Value::Null)
}

/// [`write_glb`] with `asset.extras`.
pub fn write_glb_with_extras(
    nodes: &[ExportNode<'_>],
    textures: &[&RgbaImage],
    generator: &str,
    asset_extras: Value,
) -> Vec<u8> {
    let mut builder = GlbBuilder::new(generator);
    builder.set_asset_extras(asset_extras);
    let texture_ids: Vec<usize> = textures.iter().map(|t| builder.add_texture(t)).collect();
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for node in nodes {
        let texture = node.texture.and_then(|t| texture_ids.get(t).copied());
        let primitive = PrimitiveSpec {
            mesh: node.mesh,
            texture,
            color: if texture.is_some() {
                [1.0; 4]
            } else {
                node.color
            },
            double_sided: node.double_sided,
            alpha_mask: false,
            shading: Shading::default(),
        };
        let Some(mesh) = builder.add_mesh(&node.name, &[primitive]) else {
            continue;
        };
        let index = builder.add_node(json!({"name": node.name, "mesh": mesh}));
        match &node.group {
            Some(group) => match groups.iter_mut().find(|(name, _)| name == group) {
                Some((_, children)) => children.push(index),
                None => groups.push((group.clone(), vec![index])),
            },
            None => builder.add_to_scene(index),
        }
    }
    for (name, children) in groups {
        let index = builder.add_node(json!({"name": name, "children": children}));
        builder.add_to_scene(index);
    }
    builder.finish()
}

/// One triangle primitive read from a glb, in world coordinates, with its material.
#[derive(Clone, Debug)]
pub struct GlbPart {
    /// The node's name (`node_N` when unnamed).
    pub name: String,
    pub mesh: TriMesh,
    /// Index into [`GlbParts::images`] of the base-colour texture.
    pub image: Option<usize>,
    /// Base colour factor (linear RGBA).
    pub color: [f32; 4],
    pub alpha_mask: bool,
    /// The material's `KHR_materials_unlit`, back-face u offset and billboard views (its
    /// extras' [`BACK_UV_OFFSET_KEY`] and [`BILLBOARD_VIEWS_KEY`]).
    pub shading: Shading,
}

/// The primitives and decoded images of a glb.
#[derive(Clone, Debug, Default)]
pub struct GlbParts {
    pub parts: Vec<GlbPart>,
    pub images: Vec<RgbaImage>,
}

fn parse_glb(bytes: &[u8], path: &Path) -> Result<gltf::Gltf, GltfError> {
    gltf::Gltf::from_slice(bytes).map_err(|e| GltfError::Invalid {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// A triangle primitive reachable from the default scene.
struct ScenePrimitive<'a> {
    /// The node's name (`node_N` when unnamed).
    name: String,
    /// The node's parent's name, if it has a parent.
    group: Option<String>,
    world: Matrix4<f32>,
    primitive: gltf::Primitive<'a>,
}

fn node_name(node: &gltf::Node) -> String {
    node.name()
        .or(node.mesh().and_then(|m| m.name()))
        .map(str::to_owned)
        .unwrap_or_else(|| format!("node_{}", node.index()))
}

/// Every triangle primitive reachable from the default scene.
fn scene_primitives(gltf: &gltf::Gltf) -> Vec<ScenePrimitive<'_>> {
    let mut out = Vec::new();
    let Some(scene) = gltf.default_scene().or_else(|| gltf.scenes().next()) else {
        return out;
    };
    let mut stack: Vec<(gltf::Node, Matrix4<f32>, Option<String>)> = scene
        .nodes()
        .map(|n| (n, Matrix4::identity(), None))
        .collect();
    while let Some((node, parent, group)) = stack.pop() {
        let local = Matrix4::from_column_slice(&node.transform().matrix().concat());
        let world = parent * local;
        for child in node.children() {
            stack.push((child, world, Some(node_name(&node))));
        }
        let Some(mesh) = node.mesh() else { continue };
        let name = node_name(&node);
        for primitive in mesh.primitives() {
            if primitive.mode() == gltf::mesh::Mode::Triangles {
                out.push(ScenePrimitive {
                    name: name.clone(),
                    group: group.clone(),
                    world,
                    primitive,
                });
            }
        }
    }
    out
}

/// A primitive's triangles in world coordinates.
fn primitive_mesh(
    primitive: &gltf::Primitive<'_>,
    world: &Matrix4<f32>,
    blob: Option<&[u8]>,
    name: &str,
    path: &Path,
) -> Result<TriMesh, GltfError> {
    let invalid = |message: String| GltfError::Invalid {
        path: path.display().to_string(),
        message,
    };
    let normal_matrix = world
        .fixed_view::<3, 3>(0, 0)
        .try_inverse()
        .map(|m| m.transpose())
        .unwrap_or_else(nalgebra::Matrix3::identity);
    let reader = primitive.reader(|buffer| match buffer.source() {
        gltf::buffer::Source::Bin => blob,
        gltf::buffer::Source::Uri(_) => None,
    });
    let positions: Vec<Point3<f32>> = reader
        .read_positions()
        .ok_or_else(|| invalid(format!("node '{name}' has no positions")))?
        .map(|p| {
            let h = world * nalgebra::Vector4::new(p[0], p[1], p[2], 1.0);
            Point3::new(h.x, h.y, h.z)
        })
        .collect();
    let n = positions.len();
    let normals: Option<Vec<Vector3<f32>>> = reader.read_normals().map(|it| {
        it.map(|v| (normal_matrix * Vector3::new(v[0], v[1], v[2])).normalize())
            .collect()
    });
    let uvs: Vec<[f32; 2]> = reader
        .read_tex_coords(0)
        .map(|t| t.into_f32().collect())
        .unwrap_or_else(|| vec![[0.0, 0.0]; n]);
    let indices: Vec<u32> = match reader.read_indices() {
        Some(indices) => indices.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if indices.iter().any(|&i| i as usize >= n) || uvs.len() != n {
        return Err(invalid(format!("node '{name}' has out-of-range indices")));
    }
    if positions
        .iter()
        .any(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(invalid(format!("node '{name}' has non-finite positions")));
    }
    let mut part = TriMesh {
        positions,
        normals: normals.unwrap_or_default(),
        uvs,
        triangles: indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
    };
    if part.normals.len() != n {
        part.compute_normals();
    }
    Ok(part)
}

/// Reads every named node's triangle mesh from glb bytes, transformed to world coordinates.
pub fn read_glb_meshes(bytes: &[u8], path: &Path) -> Result<Vec<NamedMesh>, GltfError> {
    let gltf = parse_glb(bytes, path)?;
    let blob = gltf.blob.as_deref();
    let mut out: Vec<NamedMesh> = Vec::new();
    for ScenePrimitive {
        name,
        group,
        world,
        primitive,
    } in scene_primitives(&gltf)
    {
        let part = primitive_mesh(&primitive, &world, blob, &name, path)?;
        match out.last_mut().filter(|m| m.name == name) {
            Some(last) => last.mesh.append(&part),
            None => out.push(NamedMesh {
                name,
                mesh: part,
                group,
            }),
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Decodes the glb's embedded images (PNG or JPEG).
fn decode_images(gltf: &gltf::Gltf, path: &Path) -> Result<Vec<RgbaImage>, GltfError> {
    let blob = gltf.blob.as_deref();
    let invalid = |message: String| GltfError::Invalid {
        path: path.display().to_string(),
        message,
    };
    let mut images = Vec::new();
    for image in gltf.images() {
        let gltf::image::Source::View { view, .. } = image.source() else {
            return Err(invalid(format!(
                "image {} is an external file; only embedded images are read",
                image.index()
            )));
        };
        let data = blob
            .and_then(|b| b.get(view.offset()..view.offset() + view.length()))
            .ok_or_else(|| {
                invalid(format!(
                    "image {} lies outside the binary chunk",
                    image.index()
                ))
            })?;
        let decoded = image::load_from_memory(data)
            .map_err(|e| invalid(format!("image {}: {e}", image.index())))?;
        images.push(decoded.to_rgba8());
    }
    Ok(images)
}

/// A primitive with its material as a [`GlbPart`].
fn glb_part(
    gltf: &gltf::Gltf,
    name: String,
    world: &Matrix4<f32>,
    primitive: &gltf::Primitive<'_>,
    image_count: usize,
    path: &Path,
) -> Result<GlbPart, GltfError> {
    let mesh = primitive_mesh(primitive, world, gltf.blob.as_deref(), &name, path)?;
    let material = primitive.material();
    let pbr = material.pbr_metallic_roughness();
    Ok(GlbPart {
        name,
        mesh,
        image: pbr
            .base_color_texture()
            .map(|info| info.texture().source().index())
            .filter(|&i| i < image_count),
        color: pbr.base_color_factor(),
        alpha_mask: material.alpha_mode() == gltf::material::AlphaMode::Mask,
        shading: material_shading(&material),
    })
}

/// A material's shading: `KHR_materials_unlit` and what its extras say (a value that is not
/// one is ignored, as a viewer that does not know the key would).
fn material_shading(material: &gltf::Material) -> Shading {
    let extras = material
        .extras()
        .as_ref()
        .and_then(|raw| serde_json::from_str::<Value>(raw.get()).ok());
    let extra = |key: &str| extras.as_ref().and_then(|e| e.get(key)).cloned();
    Shading {
        unlit: material.unlit(),
        back_uv_offset: extra(BACK_UV_OFFSET_KEY)
            .and_then(|v| v.as_f64())
            .filter(|v| v.is_finite())
            .unwrap_or(0.0) as f32,
        views: extra(BILLBOARD_VIEWS_KEY)
            .and_then(|v| serde_json::from_value::<BillboardViews>(v).ok())
            .filter(|v| v.elevation_step_rad.is_finite()),
        // A render-time choice (`lod::asset::AssetPart::shading` makes it), not stored.
        alpha_coverage: false,
    }
}

/// Reads every triangle primitive of the default scene with its material, and decodes the
/// embedded images (PNG or JPEG).
pub fn read_glb_parts(bytes: &[u8], path: &Path) -> Result<GlbParts, GltfError> {
    let gltf = parse_glb(bytes, path)?;
    let images = decode_images(&gltf, path)?;
    let mut parts = Vec::new();
    for scene_primitive in scene_primitives(&gltf) {
        parts.push(glb_part(
            &gltf,
            scene_primitive.name,
            &scene_primitive.world,
            &scene_primitive.primitive,
            images.len(),
            path,
        )?);
    }
    Ok(GlbParts { parts, images })
}

/// Discrete levels of detail of a glb: the `MSFT_lod` chain of the first scene root that has
/// one (its own mesh, then the meshes of the nodes in `ids`), or the whole scene as one level.
#[derive(Clone, Debug, Default)]
pub struct GlbLod {
    /// Parts of each level, finest first (node transforms applied).
    pub levels: Vec<Vec<GlbPart>>,
    pub images: Vec<RgbaImage>,
    /// The root node's `extras` (e.g. `MSFT_screencoverage`), `null` when absent.
    pub extras: Value,
}

/// The JSON chunk of a glb.
fn glb_json(bytes: &[u8], path: &Path) -> Result<Value, GltfError> {
    let invalid = |message: &str| GltfError::Invalid {
        path: path.display().to_string(),
        message: message.to_owned(),
    };
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    if word(0) != Some(GLB_MAGIC) || word(16) != Some(CHUNK_JSON) {
        return Err(invalid("not a binary glTF (glb) file"));
    }
    let length = word(12).ok_or_else(|| invalid("truncated header"))? as usize;
    let chunk = bytes
        .get(20..20 + length)
        .ok_or_else(|| invalid("truncated JSON chunk"))?;
    serde_json::from_slice(chunk).map_err(|e| invalid(&format!("JSON chunk: {e}")))
}

/// The plant's up direction recorded under `asset.extras.frond_up` (unit, world frame), if
/// any; a glb without it is taken as z-up by the LOD and scene code.
pub fn read_glb_up(bytes: &[u8], path: &Path) -> Result<Option<Vector3<f64>>, GltfError> {
    let json = glb_json(bytes, path)?;
    let Some(values) = json["asset"]["extras"][UP_KEY].as_array() else {
        return Ok(None);
    };
    let components: Vec<f64> = values.iter().filter_map(Value::as_f64).collect();
    match components.as_slice() {
        [x, y, z] => Ok(Vector3::new(*x, *y, *z)
            .try_normalize(1e-12)
            .filter(|v| v.iter().all(|c| c.is_finite()))),
        _ => Err(GltfError::Invalid {
            path: path.display().to_string(),
            message: format!("asset.extras.{UP_KEY} is not three numbers"),
        }),
    }
}

/// Reads the levels of detail of a glb (see [`GlbLod`]).
pub fn read_glb_lod(bytes: &[u8], path: &Path) -> Result<GlbLod, GltfError> {
    let gltf = parse_glb(bytes, path)?;
    let json = glb_json(bytes, path)?;
    let images = decode_images(&gltf, path)?;
    let invalid = |message: String| GltfError::Invalid {
        path: path.display().to_string(),
        message,
    };
    let roots: Vec<gltf::Node<'_>> = gltf
        .default_scene()
        .or_else(|| gltf.scenes().next())
        .map(|scene| scene.nodes().collect())
        .unwrap_or_default();
    let lod_root = roots.iter().find_map(|node| {
        let ids = json["nodes"][node.index()]["extensions"]["MSFT_lod"]["ids"].as_array()?;
        Some((node.clone(), ids.clone()))
    });
    let Some((root, ids)) = lod_root else {
        return Ok(GlbLod {
            levels: vec![read_glb_parts(bytes, path)?.parts],
            images,
            extras: Value::Null,
        });
    };
    let mut level_nodes = vec![root.clone()];
    for id in &ids {
        let node = id
            .as_u64()
            .and_then(|i| gltf.nodes().nth(i as usize))
            .ok_or_else(|| invalid(format!("MSFT_lod id {id} is not a node")))?;
        level_nodes.push(node);
    }
    let root_world = Matrix4::from_column_slice(&root.transform().matrix().concat());
    let mut levels = Vec::with_capacity(level_nodes.len());
    for node in level_nodes {
        let name = node
            .name()
            .map(str::to_owned)
            .unwrap_or_else(|| format!("node_{}", node.index()));
        let mut parts = Vec::new();
        if let Some(mesh) = node.mesh() {
            for primitive in mesh.primitives() {
                if primitive.mode() == gltf::mesh::Mode::Triangles {
                    parts.push(glb_part(
                        &gltf,
                        name.clone(),
                        &root_world,
                        &primitive,
                        images.len(),
                        path,
                    )?);
                }
            }
        }
        levels.push(parts);
    }
    Ok(GlbLod {
        levels,
        images,
        extras: json["nodes"][root.index()]["extras"].clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle() -> TriMesh {
        let mut mesh = TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.5),
                Point3::new(0.0, 2.0, 0.0),
            ],
            normals: Vec::new(),
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            triangles: vec![[0, 1, 2]],
        };
        mesh.compute_normals();
        mesh
    }

    #[test]
    fn glb_round_trips_through_the_gltf_crate() {
        let mesh = triangle();
        let texture = RgbaImage::from_pixel(4, 4, image::Rgba([10, 200, 30, 255]));
        let nodes = vec![
            ExportNode {
                name: "leaf_000".into(),
                mesh: &mesh,
                texture: Some(0),
                color: [1.0; 4],
                double_sided: true,
                group: Some("compound_leaf_000".into()),
            },
            ExportNode {
                name: "branch_003".into(),
                mesh: &mesh,
                texture: None,
                color: [0.4, 0.3, 0.2, 1.0],
                double_sided: false,
                group: None,
            },
        ];
        let bytes = write_glb(&nodes, &[&texture], "frond test");
        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
            bytes.len()
        );
        let back = read_glb_meshes(&bytes, Path::new("t.glb")).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].name, "branch_003");
        assert_eq!(back[1].name, "leaf_000");
        assert_eq!(back[0].group, None);
        assert_eq!(back[1].group.as_deref(), Some("compound_leaf_000"));
        assert_eq!(back[1].mesh.positions, mesh.positions);
        assert_eq!(back[1].mesh.triangles, mesh.triangles);
        assert_eq!(back[1].mesh.uvs, mesh.uvs);
    }

    #[test]
    fn garbage_is_an_error() {
        assert!(read_glb_meshes(b"not a glb", Path::new("x.glb")).is_err());
    }
}
