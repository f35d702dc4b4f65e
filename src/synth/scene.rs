//! The synthetic scene around a plant: pot with soil, a floor and a backdrop (patterned, or the
//! plain dark cloth of a phenotyping cabin), with an object id per surface and the part each id
//! belongs to.

use image::RgbaImage;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::plant::{Pot, SynthPlant};
use super::texture;
use crate::branch::CylinderMeshing;
use crate::mesh::TriMesh;
use crate::util::rng::Rng;

/// What a surface is. Stored as `u8` in ground-truth files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[repr(u8)]
pub enum Part {
    Leaf = 0,
    Stem = 1,
    Pot = 2,
    Floor = 3,
    Background = 4,
}

impl Part {
    pub const ALL: [Part; 5] = [
        Part::Leaf,
        Part::Stem,
        Part::Pot,
        Part::Floor,
        Part::Background,
    ];

    pub fn from_code(code: u8) -> Option<Part> {
        Self::ALL.get(code as usize).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Part::Leaf => "leaf",
            Part::Stem => "stem",
            Part::Pot => "pot",
            Part::Floor => "floor",
            Part::Background => "background",
        }
    }

    /// Whether the part belongs to the plant itself.
    pub fn is_plant(self) -> bool {
        matches!(self, Part::Leaf | Part::Stem)
    }
}

/// What surrounds the plant on the floor and behind it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backdrop {
    /// A terrazzo floor and a patterned wall: texture everywhere, so stereo matches the
    /// background behind every thin organ.
    #[default]
    Patterned,
    /// A phenotyping cabin: dark matte cloth on the floor and the wall (as in ROMI's scanner).
    /// Nothing behind a stem for stereo to match, the case where semi-global matching smears
    /// the stem's depth into a halo beside it.
    Studio,
}

impl Backdrop {
    pub const ALL: [Backdrop; 2] = [Backdrop::Patterned, Backdrop::Studio];

    pub fn name(self) -> &'static str {
        match self {
            Backdrop::Patterned => "patterned",
            Backdrop::Studio => "studio",
        }
    }
}

impl std::str::FromStr for Backdrop {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Backdrop::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| format!("unknown backdrop '{s}' (patterned, studio)"))
    }
}

impl std::fmt::Display for Backdrop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One renderable surface with its identity.
pub struct SceneObject {
    /// Non-zero id written by the renderer's id pass.
    pub object_id: u32,
    pub part: Part,
    /// Leaf id for leaves, `-1` otherwise.
    pub leaf_id: i32,
    /// Branch id for stems, `-1` otherwise.
    pub branch_id: i32,
    pub mesh: TriMesh,
    /// Index into [`SynthScene::textures`].
    pub texture: usize,
}

/// All surfaces of a synthetic capture.
pub struct SynthScene {
    pub objects: Vec<SceneObject>,
    pub textures: Vec<RgbaImage>,
    /// Radius of the cylindrical backdrop.
    pub backdrop_radius: f64,
}

/// Object id of leaf `leaf_id`.
pub fn leaf_object_id(leaf_id: u32) -> u32 {
    1 + leaf_id
}

/// Object id of branch `branch_id`.
pub fn branch_object_id(branch_id: u32) -> u32 {
    100_000 + branch_id
}

/// A surface of revolution about the z axis through a polyline of `(radius, z)` points.
/// `u` runs around (repeating `u_repeat` times), `v` along the profile in metres × `v_scale`.
pub fn revolve(profile: &[(f64, f64)], segments: usize, u_repeat: f32, v_scale: f32) -> TriMesh {
    let segments = segments.max(3);
    let mut mesh = TriMesh::default();
    let mut v = 0.0f64;
    for (k, &(r, z)) in profile.iter().enumerate() {
        if k > 0 {
            let (r0, z0) = profile[k - 1];
            v += ((r - r0).powi(2) + (z - z0).powi(2)).sqrt();
        }
        for j in 0..=segments {
            let angle = std::f64::consts::TAU * j as f64 / segments as f64;
            mesh.positions
                .push(Point3::new(r * angle.cos(), r * angle.sin(), z).cast::<f32>());
            mesh.uvs
                .push([u_repeat * j as f32 / segments as f32, v as f32 * v_scale]);
        }
    }
    let ring = (segments + 1) as u32;
    for k in 0..profile.len().saturating_sub(1) as u32 {
        for j in 0..segments as u32 {
            let a = k * ring + j;
            let (b, c, d) = (a + 1, a + ring, a + ring + 1);
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([b, d, c]);
        }
    }
    mesh.compute_normals();
    mesh
}

fn pot_meshes(pot: &Pot) -> (TriMesh, TriMesh) {
    let radius_at =
        |z: f64| pot.radius_bottom + (pot.radius_top - pot.radius_bottom) * z / pot.height;
    let wall = 0.008;
    let outer: Vec<(f64, f64)> = (0..=8)
        .map(|k| {
            let z = pot.height * k as f64 / 8.0;
            (radius_at(z), z)
        })
        .collect();
    let mut profile = outer;
    profile.push((pot.radius_top - wall, pot.height));
    profile.push((radius_at(pot.soil_height) - wall, pot.soil_height));
    let pot_mesh = revolve(&profile, 64, 4.0, 6.0);
    let soil_radius = radius_at(pot.soil_height) - wall;
    let soil = revolve(
        &[(0.0, pot.soil_height), (soil_radius, pot.soil_height)],
        64,
        1.0,
        8.0,
    );
    (pot_mesh, soil)
}

/// A flat rectangle `[x0, x1] × [y0, y1]` at height `z`, facing +z, subdivided into `n × n`
/// quads so that no triangle is huge (keeps interpolated depth accurate), with texture
/// coordinates `uv_of(x, y)`.
fn flat_grid(
    (x0, x1): (f32, f32),
    (y0, y1): (f32, f32),
    z: f32,
    n: u32,
    uv_of: impl Fn(f32, f32) -> [f32; 2],
) -> TriMesh {
    let mut mesh = TriMesh::default();
    for j in 0..=n {
        for i in 0..=n {
            let x = x0 + (x1 - x0) * i as f32 / n as f32;
            let y = y0 + (y1 - y0) * j as f32 / n as f32;
            mesh.positions.push(Point3::new(x, y, z));
            mesh.normals.push(Vector3::z());
            mesh.uvs.push(uv_of(x, y));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([b, d, c]);
        }
    }
    mesh
}

/// A square floor of side `2 · half_size` at z = 0, with the texture repeating every
/// `metres_per_texture`.
fn floor_mesh(half_size: f64, metres_per_texture: f64) -> TriMesh {
    let h = half_size as f32;
    let repeat = metres_per_texture as f32;
    flat_grid((-h, h), (-h, h), 0.0, 16, |x, y| [x / repeat, -y / repeat])
}

/// Squares of the printed checkerboard a capture may show as a scale reference (so 8 × 6
/// inner corners), with a one-square white margin around them.
pub const CHECKERBOARD_SQUARES: (u32, u32) = (9, 7);

/// Where the checkerboard lies: flat on the floor beside the pot, its squares along x and y,
/// centred at the returned (x, y), clear of the pot by one square.
pub fn checkerboard_centre(plant: &SynthPlant, square: f64) -> [f64; 2] {
    let half_x = 0.5 * (CHECKERBOARD_SQUARES.0 + 2) as f64 * square;
    [
        plant.pot.radius_bottom.max(plant.pot.radius_top) + square + half_x,
        0.0,
    ]
}

/// The checkerboard as a textured quad just above the floor and its texture.
fn checkerboard(plant: &SynthPlant, square: f64) -> (TriMesh, RgbaImage) {
    let (nx, ny) = (CHECKERBOARD_SQUARES.0 + 2, CHECKERBOARD_SQUARES.1 + 2);
    let [cx, cy] = checkerboard_centre(plant, square);
    let (hx, hy) = (0.5 * nx as f64 * square, 0.5 * ny as f64 * square);
    let (x0, y0) = ((cx - hx) as f32, (cy - hy) as f32);
    let (w, h) = ((2.0 * hx) as f32, (2.0 * hy) as f32);
    // Just above the floor; the texture's top row at +y.
    let mesh = flat_grid((x0, x0 + w), (y0, y0 + h), 0.0005, 8, |x, y| {
        [(x - x0) / w, 1.0 - (y - y0) / h]
    });
    let px = 48u32;
    let texture = RgbaImage::from_fn(nx * px, ny * px, |x, y| {
        let (i, j) = (x / px, y / px);
        let inside = i >= 1 && j >= 1 && i <= CHECKERBOARD_SQUARES.0 && j <= CHECKERBOARD_SQUARES.1;
        let dark = inside && (i + j) % 2 == 0;
        let level = if dark { 20 } else { 235 };
        image::Rgba([level, level, level, 255])
    });
    (mesh, texture)
}

/// Builds the scene of a plant: its leaves and branches, the pot, floor and backdrop (of the
/// kind `backdrop`), and a checkerboard of `checkerboard` metre squares beside the pot when
/// asked.
pub fn build_scene(
    plant: &SynthPlant,
    backdrop_radius: f64,
    seed: u64,
    checkerboard_square: Option<f64>,
    backdrop: Backdrop,
) -> SynthScene {
    let mut rng = Rng::seed_from(seed ^ 0x7e57_u64);
    let mut textures = Vec::new();
    let mut objects = Vec::new();
    let leaf_texture_size = if plant.leaves.len() > 200 { 64 } else { 256 };
    for leaf in &plant.leaves {
        let mut leaf_rng = Rng::stream(seed, leaf.id as u64);
        textures.push(texture::leaf_texture(
            &leaf.look,
            leaf_texture_size,
            &mut leaf_rng,
        ));
        objects.push(SceneObject {
            object_id: leaf_object_id(leaf.id),
            part: Part::Leaf,
            leaf_id: leaf.id as i32,
            branch_id: -1,
            mesh: leaf.mesh.clone(),
            texture: textures.len() - 1,
        });
    }
    textures.push(texture::bark_texture(
        128,
        rng.range(70.0, 100.0) as f32,
        &mut rng,
    ));
    let bark = textures.len() - 1;
    for branch in &plant.branches.branches {
        let meshing = CylinderMeshing {
            radial_segments: if branch.cylinder.radius_start > 0.004 {
                12
            } else {
                8
            },
            axial_segments: (branch.cylinder.length() / 0.01).clamp(4.0, 48.0) as usize,
            cap_start: branch.parent.is_none(),
            cap_end: true,
        };
        objects.push(SceneObject {
            object_id: branch_object_id(branch.id),
            part: Part::Stem,
            leaf_id: -1,
            branch_id: branch.id as i32,
            mesh: branch.cylinder.mesh(&meshing),
            texture: bark,
        });
    }
    let (pot_mesh, soil_mesh) = pot_meshes(&plant.pot);
    textures.push(texture::pot_texture(256, &mut rng));
    objects.push(SceneObject {
        object_id: 200_001,
        part: Part::Pot,
        leaf_id: -1,
        branch_id: -1,
        mesh: pot_mesh,
        texture: textures.len() - 1,
    });
    textures.push(texture::soil_texture(256, &mut rng));
    objects.push(SceneObject {
        object_id: 200_002,
        part: Part::Pot,
        leaf_id: -1,
        branch_id: -1,
        mesh: soil_mesh,
        texture: textures.len() - 1,
    });
    // The floor and backdrop textures each cover their surface once (no repetition), with
    // texels about as large as a pixel at the cameras' distance.
    textures.push(match backdrop {
        Backdrop::Patterned => texture::floor_texture(2048, &mut rng),
        Backdrop::Studio => texture::cloth_texture(2048, 2048, &mut rng),
    });
    objects.push(SceneObject {
        object_id: 200_003,
        part: Part::Floor,
        leaf_id: -1,
        branch_id: -1,
        mesh: floor_mesh(backdrop_radius, 2.0 * backdrop_radius),
        texture: textures.len() - 1,
    });
    if let Some(square) = checkerboard_square {
        let (mesh, board) = checkerboard(plant, square);
        textures.push(board);
        objects.push(SceneObject {
            object_id: 200_006,
            part: Part::Floor,
            leaf_id: -1,
            branch_id: -1,
            mesh,
            texture: textures.len() - 1,
        });
    }
    textures.push(match backdrop {
        Backdrop::Patterned => texture::backdrop_texture(4096, 1024, &mut rng),
        Backdrop::Studio => texture::cloth_texture(4096, 1024, &mut rng),
    });
    let wall_height = 1.6 * backdrop_radius;
    let backdrop = revolve(
        &[(backdrop_radius, 0.0), (backdrop_radius, wall_height)],
        128,
        1.0,
        (1.0 / wall_height) as f32,
    );
    objects.push(SceneObject {
        object_id: 200_004,
        part: Part::Background,
        leaf_id: -1,
        branch_id: -1,
        mesh: backdrop,
        texture: textures.len() - 1,
    });
    SynthScene {
        objects,
        textures,
        backdrop_radius,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::plant::{Preset, generate_plant};

    #[test]
    fn revolve_makes_a_cylinder_of_the_right_area() {
        let mesh = revolve(&[(1.0, 0.0), (1.0, 2.0)], 256, 1.0, 1.0);
        let expected = std::f64::consts::TAU * 2.0;
        assert!((mesh.area() - expected).abs() / expected < 1e-3);
    }

    #[test]
    fn scene_ids_are_unique_and_parts_consistent() {
        let plant = generate_plant(Preset::Broadleaf, 1);
        let scene = build_scene(&plant, 2.0, 1, None, Backdrop::Patterned);
        let mut ids: Vec<u32> = scene.objects.iter().map(|o| o.object_id).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), scene.objects.len());
        assert!(ids.iter().all(|&id| id != 0));
        let leaves = scene
            .objects
            .iter()
            .filter(|o| o.part == Part::Leaf)
            .count();
        assert_eq!(leaves, plant.leaves.len());
        for o in &scene.objects {
            assert_eq!(o.leaf_id >= 0, o.part == Part::Leaf);
            assert!(o.mesh.validate().is_ok());
            assert!(o.texture < scene.textures.len());
        }
    }
}
