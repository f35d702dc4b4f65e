//! One pen-and-ink frame (seed 001 §4): the GPU renders the view-facing foliage primitives (one
//! mesh per shading zone) and the branch tubes and computes the depth-difference buffer; strokes
//! are then extracted on the CPU from what the buffers say is visible:
//! - foliage: each primitive's outline where the primitive is the front-most surface and lies in
//!   front of its neighbours by more than the threshold (three times the threshold in the lit
//!   zone: outline plus little detail);
//! - branches: the analytic silhouettes of the generalized cylinders (at each axis sample, the
//!   two surface points whose normal is perpendicular to the view ray), where not hidden;
//! - cross-hatching by error diffusion of stroke coverage: on a grid over the branch surface
//!   (coherent) or over the frame's pixels (the seed's);
//! - the full-shadow zone as thick outlines, a black area or diagonal hatching.

use image::RgbaImage;
use nalgebra::{Point2, Point3, Vector3};
use serde::Serialize;

use super::plant::{Particle, SketchPlant, Zone, light_direction, shading_zones};
use super::{Hatching, IllustrateError, IllustrateOptions, Primitive, ShadowStyle};
use crate::mesh::TriMesh;
use crate::render::{Lighting, Renderer, ViewCamera};
use crate::util::geometry::any_perpendicular;
use crate::util::rng::Rng;

/// Object ids of the frame's meshes: the foliage zones, then the branches from `BRANCH_ID`.
const ZONE_IDS: [u32; 3] = [1, 2, 3];
const BRANCH_ID: u32 = 16;
const TERRAIN_ID: u32 = 8;
/// Smallest primitive diameter in the first view (pixels).
const MIN_PRIMITIVE_PX: f64 = 8.0;
/// Branches thinner than this in the first view (pixels) are drawn as one line.
const THIN_BRANCH_PX: f64 = 2.0;
/// Darkness (1 − Lambert) below which a branch gets no hatching.
const HATCH_FROM: f64 = 0.3;
/// Ink coverage of the darkest hatched surface.
const MAX_COVERAGE: f64 = 0.35;
/// Darkness (after `HATCH_FROM`) from which a second, crossing layer is hatched.
const CROSS_FROM: f64 = 0.6;
/// The lit zone outlines only larger depth jumps (outline plus little detail).
const LIT_THRESHOLD: f64 = 2.0;
/// Hatching strokes are this many grid cells (or hatch spacings) long.
const STROKE_CELLS: f64 = 1.5;

/// What a stroke belongs to (the SVG's layers).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layer {
    Shadow,
    Branch,
    Hatching,
    Foliage,
}

impl Layer {
    pub const ALL: [Layer; 4] = [
        Layer::Shadow,
        Layer::Branch,
        Layer::Hatching,
        Layer::Foliage,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Layer::Shadow => "shadow",
            Layer::Branch => "branches",
            Layer::Hatching => "hatching",
            Layer::Foliage => "foliage",
        }
    }
}

/// One pen stroke: an open polyline in pixels (COLMAP convention: pixel (i, j) centred at
/// (i + ½, j + ½)), its width, and a key naming what produced it (the same primitive outline
/// run, silhouette run or hatch cell has the same key in every frame).
#[derive(Clone, Debug, PartialEq)]
pub struct Stroke {
    pub layer: Layer,
    pub points_px: Vec<Point2<f64>>,
    pub width_px: f64,
    pub key: u64,
}

/// Counts of one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DrawingStats {
    pub particles: usize,
    /// Particles with at least one outline sample in front.
    pub visible_particles: usize,
    pub particles_by_zone: [usize; 3],
    pub branches_drawn: usize,
    pub strokes: usize,
    pub strokes_by_layer: [usize; 4],
    /// Total stroke length (pixels).
    pub ink_length_px: f64,
    /// Pixels filled black (full shadow).
    pub shadow_pixels: usize,
}

/// One drawn frame: strokes, the black shadow area, and the buffers they came from.
#[derive(Clone, Debug)]
pub struct Drawing {
    pub width: u32,
    pub height: u32,
    pub strokes: Vec<Stroke>,
    /// Row-major; true where the full-shadow zone is filled black.
    pub shadow_fill: Vec<bool>,
    /// Camera-frame depth of the frame's front-most surface (0 = nothing).
    pub depth: Vec<f32>,
    /// The depth-difference buffer (GPU).
    pub depth_difference: Vec<f32>,
    pub camera: ViewCamera,
    pub stats: DrawingStats,
}

/// Per-particle outline shape: ellipse aspect, rotation in the image, outline jitter.
#[derive(Clone, Copy, Debug)]
struct Shape {
    aspect: f64,
    rotation: f64,
    jitter: [(f64, f64); 3],
}

impl Shape {
    /// Offset from the primitive's centre (pixels) at outline angle `phi` for a radius `r_px`.
    fn offset(&self, phi: f64, r_px: f64) -> Vector3<f64> {
        let wobble: f64 = self
            .jitter
            .iter()
            .enumerate()
            .map(|(k, (amplitude, phase))| amplitude * ((k as f64 + 2.0) * phi + phase).sin())
            .sum();
        let rho = r_px * (1.0 + wobble);
        let (x, y) = (rho * phi.cos(), rho * self.aspect * phi.sin());
        let (s, c) = self.rotation.sin_cos();
        Vector3::new(c * x - s * y, s * x + c * y, 0.0)
    }
}

/// A branch ready to draw: axis samples about one hatch cell apart, radius, tangents and
/// parallel-transported normals, and its tube mesh.
#[derive(Clone, Debug)]
struct PreparedBranch {
    samples: Vec<Point3<f64>>,
    radius: Vec<f64>,
    tangents: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    mesh: TriMesh,
    /// Thinner than a couple of pixels in the first view: one line along the axis, no
    /// hatching.
    thin: bool,
}

impl PreparedBranch {
    fn surface(&self, j: usize, theta: f64) -> (Point3<f64>, Vector3<f64>) {
        let n = self.normals[j];
        let b = self.tangents[j].cross(&n);
        let dir = n * theta.cos() + b * theta.sin();
        (self.samples[j] + dir * self.radius[j], dir)
    }
}

/// A hatching stroke on a branch surface (object space).
#[derive(Clone, Debug)]
struct HatchStroke {
    key: u64,
    branch: usize,
    points_world: [Point3<f64>; 3],
    normal_world: Vector3<f64>,
    radius: f64,
}

/// The view-independent part of a drawing: particles, zones, shapes, branches and surface
/// hatching. Made once, drawn from any number of views.
#[derive(Clone, Debug)]
pub struct PreparedSketch {
    pub options: IllustrateOptions,
    pub particles: Vec<Particle>,
    /// Diameter of each particle's primitive (model units).
    pub sizes: Vec<f64>,
    pub zones: Vec<Zone>,
    pub light_world: Vector3<f64>,
    shapes: Vec<Shape>,
    branches: Vec<PreparedBranch>,
    hatch: Vec<HatchStroke>,
    /// Median hatch grid cell (model units).
    pub hatch_cell: f64,
    /// Ground that hides what is behind it (drawn into the depth buffer, never stroked).
    terrain: Option<TriMesh>,
}

/// What a drawing shows: plants in the world frame, the ground, and the up direction that
/// sets the light.
#[derive(Clone, Debug)]
pub struct SketchScene {
    pub plants: Vec<SketchPlant>,
    pub terrain: Option<TriMesh>,
    pub up_world: Vector3<f64>,
}

impl SketchScene {
    pub fn single(plant: SketchPlant) -> Self {
        Self {
            up_world: plant.up_world,
            plants: vec![plant],
            terrain: None,
        }
    }

    /// Every vertex (framing a view).
    pub fn points(&self) -> Vec<Point3<f64>> {
        self.plants.iter().flat_map(|p| p.points()).collect()
    }

    /// Median leaf length over the plants.
    pub fn median_leaf_length(&self) -> f64 {
        crate::util::stats::median(self.plants.iter().map(|p| p.median_leaf_length()))
            .unwrap_or(1.0)
    }
}

fn mean_point(points: &[Point3<f64>]) -> Option<Point3<f64>> {
    (!points.is_empty()).then(|| {
        Point3::from(
            points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / points.len() as f64,
        )
    })
}

/// A well-mixed 64-bit key from parts.
fn key(parts: &[u64]) -> u64 {
    let mut h: u64 = 0x9E37_79B9_7F4A_7C15;
    for &p in parts {
        h ^= p
            .wrapping_add(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(h << 6)
            .wrapping_add(h >> 2);
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 31;
    }
    h
}

/// Model units per pixel at camera depth `z`.
fn footprint(camera: &ViewCamera, z: f64) -> f64 {
    z / camera.fx.max(1e-12)
}

impl PreparedSketch {
    /// Preprocesses `scene` for drawing. `first_view` fixes what depends on distance, so that
    /// a fly-through stays coherent: each plant's particles are at least three pixels apart and
    /// each branch's hatch grid is the hatch spacing, both as seen from that view.
    pub fn new(
        scene: &SketchScene,
        options: &IllustrateOptions,
        first_view: &ViewCamera,
    ) -> Result<Self, IllustrateError> {
        options.validate()?;
        if scene
            .plants
            .iter()
            .all(|p| p.leaves.is_empty() && p.branches.is_empty())
        {
            return Err(IllustrateError::Empty(
                "the plant has neither leaves nor branches".into(),
            ));
        }
        let depth_of = |p: &Point3<f64>| {
            let z = (first_view.camera_from_world * p).z;
            z.max(first_view.near)
        };
        let base_spacing = 0.6 * options.size;
        let budget = (options.max_particles / scene.plants.len().max(1)).max(1);
        let mut particles = Vec::new();
        let mut spacings = Vec::new();
        let mut leaf_offset = 0;
        let mut sizes = Vec::new();
        for (k, plant) in scene.plants.iter().enumerate() {
            let points = plant.points();
            let Some(centre) = mean_point(&points) else {
                continue;
            };
            // A primitive is never smaller than MIN_PRIMITIVE_PX in the first view: far plants
            // get fewer, larger primitives (the seed's particle reduction by distance).
            let size = options
                .size
                .max(MIN_PRIMITIVE_PX * footprint(first_view, depth_of(&centre)));
            let spacing = base_spacing * size / options.size;
            for mut particle in plant.particles(spacing, budget, options.seed ^ k as u64) {
                particle.leaf += leaf_offset;
                particles.push(particle);
                spacings.push(spacing);
                sizes.push(size);
            }
            leaf_offset += plant.leaves.len();
        }
        let light_world = light_direction(
            &scene.up_world,
            options.light_elevation_deg,
            options.light_azimuth_deg,
        );
        let zones = if options.shadow == ShadowStyle::None {
            vec![Zone::HalfShadow; particles.len()]
        } else {
            let spacing =
                crate::util::stats::median(spacings.iter().copied()).unwrap_or(base_spacing);
            let size = crate::util::stats::median(sizes.iter().copied()).unwrap_or(options.size);
            shading_zones(
                &particles,
                &light_world,
                0.5 * size,
                spacing,
                options.full_shadow_layers,
            )
        };
        let shapes = (0..particles.len())
            .map(|i| {
                let mut rng = Rng::stream(options.seed ^ 0x5eed, i as u64);
                match options.primitive {
                    Primitive::Disc => Shape {
                        aspect: 1.0,
                        rotation: 0.0,
                        jitter: [(0.0, 0.0); 3],
                    },
                    Primitive::Ellipse | Primitive::LowerHalf => Shape {
                        aspect: rng.range(0.45, 0.9),
                        rotation: rng.range(0.0, std::f64::consts::PI),
                        jitter: [
                            (rng.range(0.0, 0.06), rng.range(0.0, std::f64::consts::TAU)),
                            (rng.range(0.0, 0.04), rng.range(0.0, std::f64::consts::TAU)),
                            (rng.range(0.0, 0.03), rng.range(0.0, std::f64::consts::TAU)),
                        ],
                    },
                }
            })
            .collect();
        let pen_share = options.pen_px / options.hatch_spacing_px;
        let mut branches = Vec::new();
        let mut hatch = Vec::new();
        let mut cells = Vec::new();
        for plant in &scene.plants {
            for b in plant
                .branches
                .iter()
                .filter(|b| b.order <= options.max_branch_order)
            {
                let Some(middle) = b.axis_world.get(b.axis_world.len() / 2) else {
                    continue;
                };
                let cell = options.hatch_spacing_px * footprint(first_view, depth_of(middle));
                let Some(mut prepared) = prepare_branch(&b.axis_world, &b.radius, cell) else {
                    continue;
                };
                let mean_radius = b.radius.iter().sum::<f64>() / b.radius.len().max(1) as f64;
                prepared.thin =
                    2.0 * mean_radius < THIN_BRANCH_PX * footprint(first_view, depth_of(middle));
                if prepared.thin {
                    branches.push(prepared);
                    cells.push(cell);
                    continue;
                }
                hatch.extend(surface_hatching(
                    branches.len(),
                    &prepared,
                    &light_world,
                    cell,
                    pen_share,
                ));
                branches.push(prepared);
                cells.push(cell);
            }
        }
        let hatch_cell = crate::util::stats::median(cells).unwrap_or(0.0);
        Ok(Self {
            options: options.clone(),
            sizes,
            terrain: scene.terrain.clone(),
            particles,
            zones,
            light_world,
            shapes,
            branches,
            hatch,
            hatch_cell,
        })
    }

    /// Draws one frame from `camera`.
    pub fn draw(
        &self,
        renderer: &mut Renderer,
        camera: &ViewCamera,
    ) -> Result<Drawing, IllustrateError> {
        let options = &self.options;
        let (width, height) = (camera.width, camera.height);
        let world_from_camera = camera.camera_from_world.inverse();
        // Foliage primitives: view-facing polygons (parallel to the image plane at the
        // particle's depth, so the whole primitive has the particle's depth).
        let mut zone_meshes = [TriMesh::default(), TriMesh::default(), TriMesh::default()];
        let mut projected: Vec<Option<(Point2<f64>, f64, f64)>> =
            Vec::with_capacity(self.particles.len());
        for (i, particle) in self.particles.iter().enumerate() {
            let Some((c, z)) = camera.project(&particle.position_world) else {
                projected.push(None);
                continue;
            };
            if z <= camera.near {
                projected.push(None);
                continue;
            }
            let r_px = 0.5 * self.sizes[i] * camera.fx / z;
            projected.push(Some((c, z, r_px)));
            let corners = ((std::f64::consts::TAU * r_px / 3.0).round() as usize).clamp(8, 48);
            let mesh = &mut zone_meshes[self.zones[i] as usize];
            let first = mesh.positions.len() as u32;
            let to_world = |u: f64, v: f64| {
                let p_camera = Point3::new(
                    (u - camera.cx) / camera.fx * z,
                    (v - camera.cy) / camera.fy * z,
                    z,
                );
                (world_from_camera * p_camera).cast::<f32>()
            };
            mesh.positions.push(to_world(c.x, c.y));
            for k in 0..corners {
                let phi = std::f64::consts::TAU * k as f64 / corners as f64;
                let o = self.shapes[i].offset(phi, r_px);
                mesh.positions.push(to_world(c.x + o.x, c.y + o.y));
            }
            for k in 0..corners as u32 {
                mesh.triangles
                    .push([first, first + 1 + k, first + 1 + (k + 1) % corners as u32]);
            }
        }
        let mut scene = renderer.new_scene();
        let white = renderer.add_texture(
            &mut scene,
            &RgbaImage::from_pixel(1, 1, image::Rgba([255; 4])),
        );
        for (mesh, id) in zone_meshes.iter_mut().zip(ZONE_IDS) {
            if mesh.triangles.is_empty() {
                continue;
            }
            mesh.uvs = vec![[0.5, 0.5]; mesh.positions.len()];
            mesh.compute_normals();
            renderer.add_mesh(&mut scene, mesh, white, id, false)?;
        }
        for (i, branch) in self.branches.iter().enumerate() {
            renderer.add_mesh(&mut scene, &branch.mesh, white, BRANCH_ID + i as u32, false)?;
        }
        if let Some(terrain) = &self.terrain {
            renderer.add_mesh(&mut scene, terrain, white, TERRAIN_ID, false)?;
        }
        let lighting = Lighting {
            direction_world: self.light_world,
            ambient: 0.0,
            key: 1.0,
            fill: 0.0,
        };
        let (output, difference) =
            renderer.render_with_depth_difference(&scene, camera, &lighting, camera.far as f32)?;
        let buffers = Buffers {
            width,
            height,
            depth: &output.depth,
            id: &output.object_id,
            difference: &difference,
        };
        let mut stats = DrawingStats {
            particles: self.particles.len(),
            ..Default::default()
        };
        for z in &self.zones {
            stats.particles_by_zone[*z as usize] += 1;
        }
        let mut strokes = Vec::new();
        self.foliage_strokes(&buffers, &projected, &mut strokes, &mut stats);
        let eye = world_from_camera * Point3::origin();
        self.silhouette_strokes(&buffers, camera, &eye, &mut strokes);
        stats.branches_drawn = self.branches.len();
        match options.hatching {
            Hatching::Surface => self.surface_hatch_strokes(&buffers, camera, &eye, &mut strokes),
            Hatching::Screen => {
                self.screen_hatch_strokes(&buffers, camera, &output.color, &mut strokes)
            }
        }
        let full_shadow: Vec<bool> = output
            .object_id
            .iter()
            .map(|&id| id == ZONE_IDS[2])
            .collect();
        let shadow_fill = match options.shadow {
            ShadowStyle::Black => full_shadow,
            ShadowStyle::Hatch => {
                shadow_hatching(&full_shadow, width, height, options, &mut strokes);
                vec![false; full_shadow.len()]
            }
            ShadowStyle::Thick | ShadowStyle::None => vec![false; full_shadow.len()],
        };
        stats.shadow_pixels = shadow_fill.iter().filter(|&&b| b).count();
        stats.strokes = strokes.len();
        for s in &strokes {
            stats.strokes_by_layer[s.layer as usize] += 1;
            stats.ink_length_px += crate::util::polyline::length(&s.points_px);
        }
        Ok(Drawing {
            width,
            height,
            strokes,
            shadow_fill,
            depth: output.depth,
            depth_difference: difference,
            camera: camera.clone(),
            stats,
        })
    }

    fn foliage_strokes(
        &self,
        buffers: &Buffers<'_>,
        projected: &[Option<(Point2<f64>, f64, f64)>],
        strokes: &mut Vec<Stroke>,
        stats: &mut DrawingStats,
    ) {
        let options = &self.options;
        for (i, projection) in projected.iter().enumerate() {
            let Some((c, z, r_px)) = *projection else {
                continue;
            };
            if r_px < 0.75 {
                continue;
            }
            let zone = self.zones[i];
            let threshold = if zone == Zone::Lit && options.shadow != ShadowStyle::None {
                LIT_THRESHOLD * options.threshold
            } else {
                options.threshold
            };
            let width_px = if zone == Zone::FullShadow && options.shadow == ShadowStyle::Thick {
                2.0 * options.pen_px
            } else {
                options.pen_px
            };
            let samples = ((std::f64::consts::TAU * r_px).round() as usize).clamp(12, 512);
            let tolerance = (1e-4 * z + 1e-9) as f32;
            let mut front_any = false;
            let flags: Vec<(Point2<f64>, bool)> = (0..samples)
                .map(|k| {
                    let phi = std::f64::consts::TAU * k as f64 / samples as f64;
                    let o = self.shapes[i].offset(phi, r_px);
                    let length = o.norm().max(1e-9);
                    let q = Point2::new(c.x + o.x, c.y + o.y);
                    let lower = options.primitive != Primitive::LowerHalf || o.y > 0.0;
                    // The pixels just inside the outline (a pixel's centre can sit up to
                    // ~0.7 px from the point that picked it, so three depths in): the outline
                    // is drawn where one of them shows this primitive in front of a neighbour
                    // by more than the threshold.
                    let mut on = false;
                    for inset in [0.25, 0.75, 1.25] {
                        let inward = ((length - inset) / length).max(0.0);
                        let test = Point2::new(c.x + o.x * inward, c.y + o.y * inward);
                        let Some(at) = buffers.index(&test) else {
                            continue;
                        };
                        let front = (buffers.depth[at] - z as f32).abs() <= tolerance;
                        front_any |= front;
                        on |= front && buffers.difference[at] as f64 > threshold;
                    }
                    (q, on && lower)
                })
                .collect();
            if front_any {
                stats.visible_particles += 1;
            }
            for (start, run) in runs(&flags, true) {
                strokes.push(Stroke {
                    layer: Layer::Foliage,
                    points_px: run,
                    width_px,
                    key: key(&[1, i as u64, start as u64]),
                });
            }
        }
    }

    fn silhouette_strokes(
        &self,
        buffers: &Buffers<'_>,
        camera: &ViewCamera,
        eye: &Point3<f64>,
        strokes: &mut Vec<Stroke>,
    ) {
        for (b, branch) in self.branches.iter().enumerate() {
            let sides: &[f64] = if branch.thin { &[0.0] } else { &[-1.0, 1.0] };
            for &side in sides {
                let flags: Vec<(Point2<f64>, bool)> = (0..branch.samples.len())
                    .filter_map(|j| {
                        let c = branch.samples[j];
                        let d = branch.tangents[j].cross(&(c - eye)).try_normalize(1e-12)?;
                        let s = c + d * (side * branch.radius[j]);
                        let (p, z_s) = camera.project(&s)?;
                        let (pc, _) = camera.project(&c)?;
                        let toward = (pc - p)
                            .try_normalize(1e-9)
                            .unwrap_or_else(nalgebra::Vector2::zeros);
                        let test = p + toward * 0.8;
                        let visible = buffers.index(&test).is_some_and(|at| {
                            let depth = buffers.depth[at] as f64;
                            depth <= 0.0
                                || depth >= z_s - branch.radius[j] - 2.0 * footprint(camera, z_s)
                        });
                        Some((p, visible))
                    })
                    .collect();
                for (start, run) in runs(&flags, false) {
                    strokes.push(Stroke {
                        layer: Layer::Branch,
                        points_px: run,
                        width_px: self.options.pen_px * 1.25,
                        key: key(&[2, b as u64, (side + 1.0) as u64, start as u64]),
                    });
                }
            }
        }
    }

    fn surface_hatch_strokes(
        &self,
        buffers: &Buffers<'_>,
        camera: &ViewCamera,
        eye: &Point3<f64>,
        strokes: &mut Vec<Stroke>,
    ) {
        for hatch in &self.hatch {
            let centre = hatch.points_world[1];
            if hatch.normal_world.dot(&(eye - centre)) <= 0.0 {
                continue;
            }
            let id = BRANCH_ID + hatch.branch as u32;
            let flags: Vec<(Point2<f64>, bool)> = hatch
                .points_world
                .iter()
                .filter_map(|p| {
                    let (q, z) = camera.project(p)?;
                    let visible = buffers.index(&q).is_some_and(|at| {
                        buffers.id[at] == id
                            && (buffers.depth[at] as f64 - z).abs()
                                <= hatch.radius + 2.0 * footprint(camera, z)
                    });
                    Some((q, visible))
                })
                .collect();
            for (_, run) in runs(&flags, false) {
                strokes.push(Stroke {
                    layer: Layer::Hatching,
                    points_px: run,
                    width_px: self.options.pen_px,
                    key: hatch.key,
                });
            }
        }
    }

    /// The seed's hatching: error diffusion of stroke coverage over the frame's branch pixels
    /// (darkness from the Lambert shading of the rendered tubes), strokes along the stem's
    /// projected direction, and a crossing layer where it is darkest.
    fn screen_hatch_strokes(
        &self,
        buffers: &Buffers<'_>,
        camera: &ViewCamera,
        color: &RgbaImage,
        strokes: &mut Vec<Stroke>,
    ) {
        let (w, h) = (buffers.width as usize, buffers.height as usize);
        let branch_of = |at: usize| {
            let id = buffers.id[at];
            (id >= BRANCH_ID && ((id - BRANCH_ID) as usize) < self.branches.len())
                .then(|| (id - BRANCH_ID) as usize)
        };
        // Projected axis samples and directions per branch.
        let axes: Vec<Vec<(Point2<f64>, nalgebra::Vector2<f64>)>> = self
            .branches
            .iter()
            .map(|b| {
                b.samples
                    .iter()
                    .zip(&b.tangents)
                    .filter_map(|(p, t)| {
                        let (a, _) = camera.project(p)?;
                        let (c, _) = camera.project(&(p + t * self.hatch_cell))?;
                        Some((a, (c - a).try_normalize(1e-12)?))
                    })
                    .collect()
            })
            .collect();
        let spacing = self.options.hatch_spacing_px;
        let length_px = STROKE_CELLS * spacing;
        // Pixels of ink one stroke lays down; a pixel's darkness asks for darkness ×
        // MAX_COVERAGE of a pixel.
        let ink = length_px * self.options.pen_px;
        for layer in 0..2 {
            let mut error = vec![0.0f64; w * h];
            for y in 0..h {
                for x in 0..w {
                    let at = y * w + x;
                    let Some(branch) = branch_of(at) else {
                        continue;
                    };
                    let shade =
                        crate::util::color::srgb_to_linear(color.get_pixel(x as u32, y as u32)[0]);
                    let dark = ((1.0 - shade - HATCH_FROM) / (1.0 - HATCH_FROM)).clamp(0.0, 1.0);
                    let g = if layer == 0 {
                        dark
                    } else {
                        ((dark - CROSS_FROM) / (1.0 - CROSS_FROM)).max(0.0)
                    };
                    let value = g * MAX_COVERAGE + error[at];
                    let placed = value >= 0.5 * ink;
                    let residual = if placed { value - ink } else { value };
                    if placed {
                        let centre = Point2::new(x as f64 + 0.5, y as f64 + 0.5);
                        let direction = axes[branch]
                            .iter()
                            .min_by(|a, b| (a.0 - centre).norm().total_cmp(&(b.0 - centre).norm()))
                            .map(|(_, d)| *d)
                            .unwrap_or_else(|| nalgebra::Vector2::new(0.0, 1.0));
                        let direction = if layer == 0 {
                            direction
                        } else {
                            nalgebra::Vector2::new(-direction.y, direction.x)
                        };
                        let flags: Vec<(Point2<f64>, bool)> = (0..5)
                            .map(|k| {
                                let q = centre + direction * (length_px * (k as f64 / 4.0 - 0.5));
                                (q, buffers.index(&q).and_then(branch_of) == Some(branch))
                            })
                            .collect();
                        for (_, run) in runs(&flags, false) {
                            strokes.push(Stroke {
                                layer: Layer::Hatching,
                                points_px: run,
                                width_px: self.options.pen_px,
                                key: key(&[4, layer, x as u64, y as u64]),
                            });
                        }
                    }
                    // Floyd–Steinberg, kept within the branch pixels.
                    for (dx, dy, weight) in
                        [(1i64, 0i64, 7.0), (-1, 1, 3.0), (0, 1, 5.0), (1, 1, 1.0)]
                    {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx < 0 || nx >= w as i64 || ny >= h as i64 {
                            continue;
                        }
                        let n = ny as usize * w + nx as usize;
                        if branch_of(n).is_some() {
                            error[n] += residual * weight / 16.0;
                        }
                    }
                }
            }
        }
    }
}

/// The frame's buffers.
struct Buffers<'a> {
    width: u32,
    height: u32,
    depth: &'a [f32],
    id: &'a [u32],
    difference: &'a [f32],
}

impl Buffers<'_> {
    /// Index of the pixel containing `p` (COLMAP convention), if inside the frame.
    fn index(&self, p: &Point2<f64>) -> Option<usize> {
        if !(p.x >= 0.0 && p.y >= 0.0) {
            return None;
        }
        let (x, y) = (p.x.floor() as u64, p.y.floor() as u64);
        (x < self.width as u64 && y < self.height as u64)
            .then(|| (y * self.width as u64 + x) as usize)
    }
}

/// Runs of consecutive `true` flags as polylines (at least two points), with the index of their
/// first point; `cyclic` joins a run that wraps past the end.
fn runs(flags: &[(Point2<f64>, bool)], cyclic: bool) -> Vec<(usize, Vec<Point2<f64>>)> {
    let n = flags.len();
    if n == 0 {
        return Vec::new();
    }
    if flags.iter().all(|f| f.1) {
        let mut points: Vec<Point2<f64>> = flags.iter().map(|f| f.0).collect();
        if cyclic {
            points.push(flags[0].0);
        }
        return if points.len() >= 2 {
            vec![(0, points)]
        } else {
            Vec::new()
        };
    }
    // Start after a false flag so that a cyclic run is never split.
    let offset = if cyclic {
        flags.iter().position(|f| !f.1).map(|i| i + 1).unwrap_or(0)
    } else {
        0
    };
    let mut out = Vec::new();
    let mut current: Option<(usize, Vec<Point2<f64>>)> = None;
    for step in 0..n {
        let i = (offset + step) % n;
        if flags[i].1 {
            current
                .get_or_insert_with(|| (i, Vec::new()))
                .1
                .push(flags[i].0);
        } else if let Some(run) = current.take()
            && run.1.len() >= 2
        {
            out.push(run);
        }
    }
    if let Some(run) = current.take()
        && run.1.len() >= 2
    {
        out.push(run);
    }
    out
}

/// Axis samples about `cell` apart with tangents, parallel-transported normals and a tube mesh.
fn prepare_branch(axis: &[Point3<f64>], radius: &[f64], cell: f64) -> Option<PreparedBranch> {
    if axis.len() < 2 || radius.len() != axis.len() {
        return None;
    }
    let length = crate::util::polyline::length(axis);
    if length <= 0.0 {
        return None;
    }
    let count = ((length / cell.max(1e-12)).ceil() as usize + 1).clamp(2, 4000);
    let samples = crate::util::polyline::resample(axis, count);
    // Radius by arc length.
    let mut cumulative = vec![0.0];
    for w in axis.windows(2) {
        cumulative.push(cumulative.last().copied().unwrap_or(0.0) + (w[1] - w[0]).norm());
    }
    let radius_at = |s: f64| {
        let k = cumulative
            .partition_point(|&c| c < s)
            .clamp(1, axis.len() - 1);
        let span = (cumulative[k] - cumulative[k - 1]).max(1e-300);
        let t = ((s - cumulative[k - 1]) / span).clamp(0.0, 1.0);
        radius[k - 1] * (1.0 - t) + radius[k] * t
    };
    let radii: Vec<f64> = (0..count)
        .map(|i| radius_at(length * i as f64 / (count - 1) as f64).max(0.0))
        .collect();
    let tangents: Vec<Vector3<f64>> = (0..count)
        .map(|i| {
            let (a, b) = (
                samples[i.saturating_sub(1)],
                samples[(i + 1).min(count - 1)],
            );
            (b - a).try_normalize(1e-15).unwrap_or_else(Vector3::z)
        })
        .collect();
    let mut normals = Vec::with_capacity(count);
    let mut n = any_perpendicular(&tangents[0]).normalize();
    for (i, tangent) in tangents.iter().enumerate() {
        if i > 0 {
            // Parallel transport: remove the component along the new tangent.
            n = (n - tangent * n.dot(tangent))
                .try_normalize(1e-12)
                .unwrap_or_else(|| any_perpendicular(tangent).normalize());
        }
        normals.push(n);
    }
    let mut branch = PreparedBranch {
        samples,
        radius: radii,
        tangents,
        normals,
        mesh: TriMesh::default(),
        thin: false,
    };
    let sides = 16usize;
    let mut mesh = TriMesh::default();
    for j in 0..count {
        for k in 0..sides {
            let (p, normal) = branch.surface(j, std::f64::consts::TAU * k as f64 / sides as f64);
            mesh.positions.push(p.cast::<f32>());
            mesh.normals.push(normal.cast::<f32>());
            mesh.uvs.push([0.5, 0.5]);
        }
    }
    for j in 0..count - 1 {
        for k in 0..sides {
            let a = (j * sides + k) as u32;
            let b = (j * sides + (k + 1) % sides) as u32;
            let (c, d) = (a + sides as u32, b + sides as u32);
            mesh.triangles.push([a, b, d]);
            mesh.triangles.push([a, d, c]);
        }
    }
    branch.mesh = mesh;
    Some(branch)
}

/// Error diffusion of stroke coverage on a branch's surface grid (cells `cell` long along the
/// axis and about as wide around it): darkness from the Lambert term of each cell's normal,
/// strokes along the stem, a crossing layer around it where darkest. `ink_per_cell` is the pen
/// width over the cell size, so a stroke `STROKE_CELLS` long covers `STROKE_CELLS ×
/// ink_per_cell` of a cell.
fn surface_hatching(
    index: usize,
    branch: &PreparedBranch,
    light: &Vector3<f64>,
    cell: f64,
    ink_per_cell: f64,
) -> Vec<HatchStroke> {
    let rows = branch.samples.len();
    let mean_radius = branch.radius.iter().sum::<f64>() / rows.max(1) as f64;
    let columns = ((std::f64::consts::TAU * mean_radius / cell.max(1e-12)).round() as usize).max(4);
    let ink = STROKE_CELLS * ink_per_cell;
    let mut out = Vec::new();
    for layer in 0..2u64 {
        let mut error = vec![0.0f64; rows * columns];
        for j in 0..rows {
            for k in 0..columns {
                let theta = std::f64::consts::TAU * k as f64 / columns as f64;
                let (p, normal) = branch.surface(j, theta);
                let shade = normal.dot(light).max(0.0);
                let dark = ((1.0 - shade - HATCH_FROM) / (1.0 - HATCH_FROM)).clamp(0.0, 1.0);
                let g = if layer == 0 {
                    dark
                } else {
                    ((dark - CROSS_FROM) / (1.0 - CROSS_FROM)).max(0.0)
                };
                let at = j * columns + k;
                let value = g * MAX_COVERAGE + error[at];
                let placed = value >= 0.5 * ink;
                let residual = if placed { value - ink } else { value };
                if placed {
                    let half = 0.5 * STROKE_CELLS * cell;
                    let points_world = if layer == 0 {
                        let (a, _) = branch.surface(j, theta);
                        let along = branch.tangents[j] * half;
                        [a - along, a, a + along]
                    } else {
                        let dtheta = half / branch.radius[j].max(1e-12);
                        let (a, _) = branch.surface(j, theta - dtheta.min(1.0));
                        let (b, _) = branch.surface(j, theta + dtheta.min(1.0));
                        [a, p, b]
                    };
                    out.push(HatchStroke {
                        key: key(&[3, index as u64, layer, j as u64, k as u64]),
                        branch: index,
                        points_world,
                        normal_world: normal,
                        radius: branch.radius[j],
                    });
                }
                // Floyd–Steinberg on the cylinder (around wraps).
                let right = j * columns + (k + 1) % columns;
                error[right] += residual * 7.0 / 16.0;
                if j + 1 < rows {
                    let below = (j + 1) * columns;
                    error[below + (k + columns - 1) % columns] += residual * 3.0 / 16.0;
                    error[below + k] += residual * 5.0 / 16.0;
                    error[below + (k + 1) % columns] += residual * 1.0 / 16.0;
                }
            }
        }
    }
    out
}

/// Diagonal hatching (45°, the hatch spacing apart) over the full-shadow mask.
fn shadow_hatching(
    mask: &[bool],
    width: u32,
    height: u32,
    options: &IllustrateOptions,
    strokes: &mut Vec<Stroke>,
) {
    let (w, h) = (width as i64, height as i64);
    let spacing = options.hatch_spacing_px.max(1.0) * 0.75;
    let lines = ((w + h) as f64 / spacing).ceil() as i64;
    for line in 0..lines {
        let offset = line as f64 * spacing;
        // Points on x + y = offset, one per pixel row.
        let flags: Vec<(Point2<f64>, bool)> = (0..h)
            .filter_map(|y| {
                let x = offset - y as f64;
                (x >= 0.0 && x < w as f64).then(|| {
                    let p = Point2::new(x, y as f64 + 0.5);
                    let at = (y * w + x.floor() as i64) as usize;
                    (p, mask[at])
                })
            })
            .collect();
        for (start, run) in runs(&flags, false) {
            strokes.push(Stroke {
                layer: Layer::Shadow,
                points_px: run,
                width_px: options.pen_px,
                key: key(&[5, line as u64, start as u64]),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_split_on_hidden_samples_and_join_across_the_seam() {
        let p = |i: usize| Point2::new(i as f64, 0.0);
        let flags: Vec<(Point2<f64>, bool)> = [true, true, false, true, true, true, false, true]
            .iter()
            .enumerate()
            .map(|(i, &f)| (p(i), f))
            .collect();
        let open = runs(&flags, false);
        assert_eq!(open.len(), 2, "the last single point is no stroke");
        assert_eq!(open[0].1, vec![p(0), p(1)]);
        let cyclic = runs(&flags, true);
        assert_eq!(cyclic.len(), 2);
        assert!(
            cyclic.iter().any(|(_, r)| r == &vec![p(7), p(0), p(1)]),
            "{cyclic:?}"
        );
        let all: Vec<(Point2<f64>, bool)> = (0..4).map(|i| (p(i), true)).collect();
        assert_eq!(runs(&all, true)[0].1.len(), 5, "a closed outline");
    }

    #[test]
    fn surface_hatching_darkens_away_from_the_light() {
        let axis: Vec<Point3<f64>> = (0..=10)
            .map(|i| Point3::new(0.0, 0.0, i as f64 * 0.1))
            .collect();
        let branch = prepare_branch(&axis, &[0.05; 11], 0.01).expect("branch");
        let light = Vector3::x();
        let strokes = surface_hatching(0, &branch, &light, 0.01, 0.25);
        let lit = strokes
            .iter()
            .filter(|s| s.normal_world.dot(&light) > 0.5)
            .count();
        let dark = strokes
            .iter()
            .filter(|s| s.normal_world.dot(&light) < -0.5)
            .count();
        assert!(
            dark > 5 * lit.max(1),
            "dark side {dark} strokes, lit side {lit}"
        );
        // Stroke coverage follows darkness: where the darkness is 1 both layers cover
        // MAX_COVERAGE of every cell, up to the diffusion's rounding.
        let columns = ((std::f64::consts::TAU * 0.05 / 0.01).round() as usize).max(4);
        let full_dark_cells = (0..columns)
            .filter(|k| {
                let theta = std::f64::consts::TAU * *k as f64 / columns as f64;
                branch.surface(0, theta).1.dot(&light) < -0.8
            })
            .count()
            * branch.samples.len();
        let in_dark = strokes
            .iter()
            .filter(|s| s.normal_world.dot(&light) < -0.8)
            .count();
        let coverage = in_dark as f64 * STROKE_CELLS * 0.25 / full_dark_cells as f64;
        assert!(
            (coverage - 2.0 * MAX_COVERAGE).abs() < 0.3 * 2.0 * MAX_COVERAGE,
            "coverage {coverage} over {full_dark_cells} darkest cells"
        );
    }
}
