//! The plant model: leaves (mesh, texture, source segment, fit residuals), branches, and
//! metadata, with its exports: `plant.glb` (glTF 2.0 binary, textures embedded, nodes
//! `leaf_NNN` / `branch_NNN`, world frame) and `plant.obj` + `plant.mtl` + atlas PNGs.
//! Leaf textures are packed into atlas pages of square tiles.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use image::RgbaImage;
use serde::Serialize;

use super::gltf::{ExportNode, UP_KEY, write_glb_with_extras};
use crate::mesh::TriMesh;
use crate::util::atomic::write_atomic;

/// Tiles per atlas side (a page holds `ATLAS_TILES²` leaf textures).
pub const ATLAS_TILES: u32 = 16;

/// A leaf of the model.
#[derive(Clone, Debug)]
pub struct ModelLeaf {
    /// The segment (and `leaf_NNN` number).
    pub id: u32,
    /// World-frame mesh; uvs in the leaf's own [0, 1]² tile.
    pub mesh: TriMesh,
    pub texture: RgbaImage,
}

/// A branch of the model.
#[derive(Clone, Debug)]
pub struct ModelBranch {
    pub id: u32,
    pub mesh: TriMesh,
    pub color: [f32; 4],
}

/// A compound leaf of the model: its rachis (a branch) and its leaflets (leaves). In the glb
/// they are the children of one node named [`CompoundGroup::node_name`].
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct CompoundGroup {
    pub id: u32,
    /// The rachis's branch id.
    pub rachis: u32,
    /// Leaf ids.
    pub leaflets: Vec<u32>,
    /// The branch nodes in the group: the rachis (unless it is the end of a longer branch)
    /// and its petiolules.
    pub branches: Vec<u32>,
}

impl CompoundGroup {
    /// `compound_leaf_NNN`.
    pub fn node_name(&self) -> String {
        format!("compound_leaf_{:03}", self.id)
    }
}

/// A plant ready to export.
#[derive(Clone, Debug, Default)]
pub struct PlantModel {
    pub leaves: Vec<ModelLeaf>,
    pub branches: Vec<ModelBranch>,
    /// Compound leaves: which leaves are leaflets of which rachis.
    pub compound_leaves: Vec<CompoundGroup>,
    /// The plant's up direction in the world frame, when known (written to the glb's
    /// `asset.extras.frond_up`).
    pub up: Option<[f64; 3]>,
}

/// What an export wrote.
#[derive(Clone, Debug, Serialize)]
pub struct ExportReport {
    pub files: Vec<PathBuf>,
    pub leaves: usize,
    pub branches: usize,
    pub atlas_pages: usize,
    pub triangles: usize,
}

/// Leaf textures packed into atlas pages of square tiles.
pub struct Atlas {
    pub pages: Vec<RgbaImage>,
    /// Tile side in texels.
    pub tile: u32,
    /// Per leaf: page, and the texel column and row of its tile.
    pub placements: Vec<(usize, u32, u32)>,
}

impl Atlas {
    /// Packs the leaves' textures (resized to a common tile size) row by row, at most
    /// `ATLAS_TILES × ATLAS_TILES` per page.
    pub fn pack(leaves: &[ModelLeaf]) -> Self {
        let tile = leaves
            .iter()
            .map(|l| l.texture.width().max(l.texture.height()))
            .max()
            .unwrap_or(64)
            .clamp(16, 256);
        let per_page = (ATLAS_TILES * ATLAS_TILES) as usize;
        let mut pages: Vec<RgbaImage> = Vec::new();
        let mut placements = Vec::with_capacity(leaves.len());
        for (i, leaf) in leaves.iter().enumerate() {
            let page = i / per_page;
            let slot = (i % per_page) as u32;
            if page == pages.len() {
                let tiles = (leaves.len() - page * per_page).min(per_page) as u32;
                pages.push(RgbaImage::new(
                    tiles.min(ATLAS_TILES) * tile,
                    tiles.div_ceil(ATLAS_TILES) * tile,
                ));
            }
            let (column, row) = (slot % ATLAS_TILES, slot / ATLAS_TILES);
            let resized = if leaf.texture.dimensions() == (tile, tile) {
                leaf.texture.clone()
            } else {
                image::imageops::resize(
                    &leaf.texture,
                    tile,
                    tile,
                    image::imageops::FilterType::Triangle,
                )
            };
            image::imageops::replace(
                &mut pages[page],
                &resized,
                (column * tile) as i64,
                (row * tile) as i64,
            );
            placements.push((page, column, row));
        }
        Self {
            pages,
            tile,
            placements,
        }
    }

    /// The leaf's mesh with uvs moved into its atlas tile (half a texel inside, so filtering
    /// never bleeds across tiles).
    pub fn remap(&self, index: usize, mesh: &TriMesh) -> TriMesh {
        let (page, column, row) = self.placements[index];
        let (w, h) = self.pages[page].dimensions();
        let (w, h) = (w as f32, h as f32);
        let tile = self.tile as f32;
        let mut out = mesh.clone();
        for uv in &mut out.uvs {
            let u = uv[0].clamp(0.0, 1.0);
            let v = uv[1].clamp(0.0, 1.0);
            *uv = [
                (column as f32 * tile + 0.5 + u * (tile - 1.0)) / w,
                (row as f32 * tile + 0.5 + v * (tile - 1.0)) / h,
            ];
        }
        out
    }
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(format!("{}: {e}", path.display()))
}

impl PlantModel {
    /// The glb group node of a leaf that is a leaflet.
    fn compound_leaf_of_leaf(&self, leaf: u32) -> Option<String> {
        self.compound_leaves
            .iter()
            .find(|c| c.leaflets.contains(&leaf))
            .map(CompoundGroup::node_name)
    }

    /// The glb group node of a branch that is a rachis or a petiolule.
    fn compound_leaf_of_rachis(&self, branch: u32) -> Option<String> {
        self.compound_leaves
            .iter()
            .find(|c| c.branches.contains(&branch))
            .map(CompoundGroup::node_name)
    }

    /// The glb of the model (the evaluation contract).
    pub fn to_glb(&self) -> Vec<u8> {
        let atlas = Atlas::pack(&self.leaves);
        let leaf_meshes: Vec<TriMesh> = (0..self.leaves.len())
            .map(|i| atlas.remap(i, &self.leaves[i].mesh))
            .collect();
        let mut nodes: Vec<ExportNode> = self
            .leaves
            .iter()
            .zip(&leaf_meshes)
            .enumerate()
            .map(|(i, (leaf, mesh))| ExportNode {
                name: format!("leaf_{:03}", leaf.id),
                mesh,
                texture: Some(atlas.placements[i].0),
                color: [1.0; 4],
                double_sided: true,
                group: self.compound_leaf_of_leaf(leaf.id),
            })
            .collect();
        for branch in &self.branches {
            nodes.push(ExportNode {
                name: format!("branch_{:03}", branch.id),
                mesh: &branch.mesh,
                texture: None,
                color: branch.color,
                double_sided: false,
                group: self.compound_leaf_of_rachis(branch.id),
            });
        }
        let pages: Vec<&RgbaImage> = atlas.pages.iter().collect();
        write_glb_with_extras(
            &nodes,
            &pages,
            &format!("frond {}", env!("CARGO_PKG_VERSION")),
            match self.up {
                Some(up) => serde_json::json!({ UP_KEY: up }),
                None => serde_json::Value::Null,
            },
        )
    }

    /// Writes `plant.glb`, `plant.obj`, `plant.mtl` and the atlas pages into `out`, each
    /// atomically.
    pub fn export(&self, out: &Path) -> std::io::Result<ExportReport> {
        std::fs::create_dir_all(out)?;
        let mut files = Vec::new();
        let glb = out.join("plant.glb");
        write_atomic(&glb, &self.to_glb()).map_err(|e| io_error(&glb, e))?;
        files.push(glb);

        let atlas = Atlas::pack(&self.leaves);
        let mut mtl = String::from("# frond plant materials\n");
        for (page, image) in atlas.pages.iter().enumerate() {
            let name = format!("plant_atlas_{page}.png");
            let path = out.join(&name);
            let mut png = Vec::new();
            image
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .map_err(|e| io_error(&path, e))?;
            write_atomic(&path, &png).map_err(|e| io_error(&path, e))?;
            files.push(path);
            let _ = writeln!(
                mtl,
                "newmtl leaf_atlas_{page}\nKd 1 1 1\nKa 0 0 0\nKs 0 0 0\nmap_Kd {name}\n"
            );
        }
        let _ = writeln!(mtl, "newmtl branch\nKd 0.35 0.28 0.2\nKa 0 0 0\nKs 0 0 0\n");
        let mtl_path = out.join("plant.mtl");
        write_atomic(&mtl_path, mtl.as_bytes()).map_err(|e| io_error(&mtl_path, e))?;
        files.push(mtl_path);

        let mut obj = String::from(
            "# frond plant model (world frame of the input reconstruction)\nmtllib plant.mtl\n",
        );
        let mut offset = 1usize;
        // A leaflet or rachis is also in its compound leaf's group (`g compound_leaf_NNN`).
        let mut write_mesh = |obj: &mut String,
                              name: &str,
                              group: Option<String>,
                              material: &str,
                              mesh: &TriMesh| {
            let _ = writeln!(obj, "o {name}");
            if let Some(group) = group {
                let _ = writeln!(obj, "g {group}");
            }
            let _ = writeln!(obj, "usemtl {material}");
            for p in &mesh.positions {
                let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
            }
            for uv in &mesh.uvs {
                // OBJ texture coordinates start at the bottom-left.
                let _ = writeln!(obj, "vt {} {}", uv[0], 1.0 - uv[1]);
            }
            for n in &mesh.normals {
                let _ = writeln!(obj, "vn {} {} {}", n.x, n.y, n.z);
            }
            for t in &mesh.triangles {
                let [a, b, c] = t.map(|i| i as usize + offset);
                let _ = writeln!(obj, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}");
            }
            offset += mesh.positions.len();
        };
        for (i, leaf) in self.leaves.iter().enumerate() {
            let mesh = atlas.remap(i, &leaf.mesh);
            write_mesh(
                &mut obj,
                &format!("leaf_{:03}", leaf.id),
                self.compound_leaf_of_leaf(leaf.id),
                &format!("leaf_atlas_{}", atlas.placements[i].0),
                &mesh,
            );
        }
        for branch in &self.branches {
            write_mesh(
                &mut obj,
                &format!("branch_{:03}", branch.id),
                self.compound_leaf_of_rachis(branch.id),
                "branch",
                &branch.mesh,
            );
        }
        let obj_path = out.join("plant.obj");
        write_atomic(&obj_path, obj.as_bytes()).map_err(|e| io_error(&obj_path, e))?;
        files.push(obj_path);
        Ok(ExportReport {
            files,
            leaves: self.leaves.len(),
            branches: self.branches.len(),
            atlas_pages: atlas.pages.len(),
            triangles: self
                .leaves
                .iter()
                .map(|l| l.mesh.triangles.len())
                .sum::<usize>()
                + self
                    .branches
                    .iter()
                    .map(|b| b.mesh.triangles.len())
                    .sum::<usize>(),
        })
    }
}
