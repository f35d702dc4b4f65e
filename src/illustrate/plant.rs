//! Pen-and-ink preprocessing (seed 001 §4): a plant becomes a skeleton (branches as generalized
//! cylinders: axis, radius, branching order) and foliage particles (position + leaf normal),
//! reduced when there are too many, each in one of the crown's three shading zones.
//!
//! Sources: a `frond reconstruct` folder or a synthetic dataset's ground truth (through the
//! traits readers, which know the branch tree), or any glb, where each branch's axis and radius
//! are recovered from its tube mesh (geodesic level sets) and the tree from where the tubes meet.

use std::collections::BinaryHeap;
use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::IllustrateError;
use crate::branch::plant::SkeletonRecord;
use crate::mesh::TriMesh;
use crate::traits::PlantOrgans;
use crate::util::geometry::any_perpendicular;
use crate::util::rng::Rng;

/// A branch as the drawing sees it: a generalized cylinder (axis polyline from base to tip and
/// a radius per axis point) and its branching order (0 = the main stem).
#[derive(Clone, Debug, PartialEq)]
pub struct SketchBranch {
    pub id: u32,
    pub order: u32,
    pub axis_world: Vec<Point3<f64>>,
    pub radius: Vec<f64>,
}

/// A plant ready to draw: its skeleton, its leaves and its up direction.
#[derive(Clone, Debug)]
pub struct SketchPlant {
    pub up_world: Vector3<f64>,
    pub branches: Vec<SketchBranch>,
    pub leaves: Vec<TriMesh>,
}

/// A foliage particle: where a primitive is drawn, the leaf normal there, and the leaf it
/// stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Particle {
    pub position_world: Point3<f64>,
    pub normal_world: Vector3<f64>,
    pub leaf: usize,
}

/// The crown's shading zones (seed 001 §4.3): in direct light, in half shadow, in full shadow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Zone {
    Lit,
    HalfShadow,
    FullShadow,
}

/// Branch orders from parent links: the number of ancestors (a parent missing from the list, or
/// a loop, ends the chain).
fn orders(parents: &[Option<usize>]) -> Vec<u32> {
    (0..parents.len())
        .map(|i| {
            let mut order = 0;
            let mut at = i;
            while let Some(p) = parents[at] {
                order += 1;
                at = p;
                if order as usize > parents.len() {
                    break;
                }
            }
            order
        })
        .collect()
}

impl SketchPlant {
    /// From the organs the traits code reads (a reconstruction folder or a synthetic ground
    /// truth): branch axes from the skeleton's centrelines, radii interpolated base to tip.
    pub fn from_organs(organs: &PlantOrgans) -> Self {
        let index_of = |id: u32| organs.branches.iter().position(|b| b.id == id);
        let parents: Vec<Option<usize>> = organs
            .branches
            .iter()
            .map(|b| b.parent.and_then(index_of))
            .collect();
        let orders = orders(&parents);
        let branches = organs
            .branches
            .iter()
            .zip(orders)
            .filter_map(|(record, order)| sketch_branch(record, order))
            .collect();
        Self {
            up_world: organs.up_world,
            branches,
            leaves: organs.leaves.iter().map(|l| l.mesh.clone()).collect(),
        }
    }

    /// From a glb: nodes named `leaf_*` (or with a cut-out material) are leaves, every other
    /// mesh is a branch whose axis and radius are recovered from its tube; the up direction is
    /// the glb's `frond_up` or +z.
    pub fn from_glb(path: &Path) -> Result<Self, IllustrateError> {
        let read = |e: &dyn std::fmt::Display| IllustrateError::Input {
            path: path.display().to_string(),
            message: e.to_string(),
        };
        let bytes = std::fs::read(path).map_err(|e| read(&e))?;
        let parts = crate::model::gltf::read_glb_parts(&bytes, path).map_err(|e| read(&e))?;
        let up_world = crate::model::gltf::read_glb_up(&bytes, path)
            .map_err(|e| read(&e))?
            .unwrap_or_else(Vector3::z);
        let mut leaves = Vec::new();
        let mut tubes = Vec::new();
        for part in parts.parts {
            if part.mesh.triangles.is_empty() {
                continue;
            }
            // Merged parts (a scene's masters: all leaves of an atlas page, all branches of a
            // colour in one mesh) come apart into their connected pieces.
            let pieces = part.mesh.connected_components();
            if part.name.starts_with("leaf") || part.alpha_mask {
                leaves.extend(pieces);
            } else {
                tubes.extend(pieces);
            }
        }
        let mut axes: Vec<(Vec<Point3<f64>>, Vec<f64>)> =
            tubes.iter().filter_map(tube_axis).collect();
        let parents = branch_tree(&mut axes, &up_world);
        let orders = orders(&parents);
        let branches = axes
            .into_iter()
            .zip(orders)
            .enumerate()
            .map(|(i, ((axis_world, radius), order))| SketchBranch {
                id: i as u32,
                order,
                axis_world,
                radius,
            })
            .collect();
        Ok(Self {
            up_world: up_world.try_normalize(1e-12).unwrap_or_else(Vector3::z),
            branches,
            leaves,
        })
    }

    /// The plant moved by a similarity (a scene instance): positions mapped, radii scaled.
    pub fn transformed(&self, world_from_plant: &nalgebra::Similarity3<f64>) -> Self {
        let scale = world_from_plant.scaling();
        let similarity = world_from_plant.cast::<f32>();
        Self {
            up_world: (world_from_plant * self.up_world).normalize(),
            branches: self
                .branches
                .iter()
                .map(|b| SketchBranch {
                    id: b.id,
                    order: b.order,
                    axis_world: b.axis_world.iter().map(|p| world_from_plant * p).collect(),
                    radius: b.radius.iter().map(|r| r * scale).collect(),
                })
                .collect(),
            leaves: self
                .leaves
                .iter()
                .map(|leaf| {
                    let mut moved = leaf.clone();
                    for p in &mut moved.positions {
                        *p = similarity * *p;
                    }
                    for n in &mut moved.normals {
                        *n = (similarity * *n).normalize();
                    }
                    moved
                })
                .collect(),
        }
    }

    /// Every vertex of the plant (framing a view).
    pub fn points(&self) -> Vec<Point3<f64>> {
        let mut points: Vec<Point3<f64>> = self
            .leaves
            .iter()
            .flat_map(|m| m.positions.iter().map(|p| p.cast::<f64>()))
            .collect();
        points.extend(
            self.branches
                .iter()
                .flat_map(|b| b.axis_world.iter().copied()),
        );
        points
    }

    /// Median leaf length (extent along each leaf's main axis); falls back to a tenth of the
    /// plant's size without leaves.
    pub fn median_leaf_length(&self) -> f64 {
        let lengths: Vec<f64> = self.leaves.iter().filter_map(leaf_extent).collect();
        crate::util::stats::median(lengths).unwrap_or_else(|| {
            let points = self.points();
            if points.is_empty() {
                return 1.0;
            }
            let (lo, hi) = crate::util::geometry::bounding_box(points.iter());
            ((hi - lo).norm() / 10.0).max(1e-9)
        })
    }

    /// Foliage particles about `spacing` apart on every leaf (at least one per leaf, at the
    /// sample nearest its centroid). If more than `max_particles` come out, the spacing grows
    /// by 25 % until they fit (the seed's reduction, in units of the particle size: one
    /// particle ends up standing for a whole twig's leaves). Deterministic per `seed`.
    pub fn particles(&self, spacing: f64, max_particles: usize, seed: u64) -> Vec<Particle> {
        let mut spacing = spacing.max(1e-9);
        let mut candidates: Vec<Vec<Particle>> = Vec::with_capacity(self.leaves.len());
        for (i, leaf) in self.leaves.iter().enumerate() {
            let normal = leaf.mean_normal().cast::<f64>();
            let normal = normal.try_normalize(1e-12).unwrap_or(self.up_world);
            // Dense enough for the smallest spacing tried; the thinning below picks from them.
            let count = ((4.0 * leaf.area() / (spacing * spacing)).ceil() as usize).clamp(1, 4096);
            let mut rng = Rng::stream(seed, i as u64);
            let mut samples: Vec<Particle> = leaf
                .sample_surface(count, &mut rng)
                .into_iter()
                .map(|s| Particle {
                    position_world: s.position.cast::<f64>(),
                    normal_world: normal,
                    leaf: i,
                })
                .collect();
            // The sample nearest the centroid first, so a tiny leaf keeps its middle.
            if let Some(centroid) = centroid(samples.iter().map(|p| p.position_world))
                && let Some(best) = (0..samples.len()).min_by(|&a, &b| {
                    (samples[a].position_world - centroid)
                        .norm()
                        .total_cmp(&(samples[b].position_world - centroid).norm())
                })
            {
                samples.swap(0, best);
            }
            candidates.push(samples);
        }
        loop {
            let particles: Vec<Particle> = candidates
                .iter()
                .flat_map(|samples| thin(samples, spacing))
                .collect();
            if particles.len() <= max_particles.max(1) || spacing > 1e12 {
                return particles;
            }
            spacing *= 1.25;
        }
    }
}

fn centroid(points: impl Iterator<Item = Point3<f64>>) -> Option<Point3<f64>> {
    let (sum, n) = points.fold((Vector3::zeros(), 0usize), |(s, n), p| {
        (s + p.coords, n + 1)
    });
    (n > 0).then(|| Point3::from(sum / n as f64))
}

/// Greedy Poisson-disc thinning in sample order: a sample is kept when no kept one lies within
/// `spacing`.
fn thin(samples: &[Particle], spacing: f64) -> Vec<Particle> {
    let mut kept: Vec<Particle> = Vec::new();
    for s in samples {
        if kept
            .iter()
            .all(|k| (k.position_world - s.position_world).norm() >= spacing)
        {
            kept.push(*s);
        }
    }
    kept
}

/// A leaf's extent along its main axis (principal component of its vertices).
fn leaf_extent(mesh: &TriMesh) -> Option<f64> {
    let points: Vec<Point3<f64>> = mesh.positions.iter().map(|p| p.cast::<f64>()).collect();
    let c = centroid(points.iter().copied())?;
    let mut cov = nalgebra::Matrix3::zeros();
    for p in &points {
        let d = p - c;
        cov += d * d.transpose();
    }
    let eigen = cov.symmetric_eigen();
    let main = eigen
        .eigenvectors
        .column(eigen.eigenvalues.imax())
        .into_owned();
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        let t = (p - c).dot(&main);
        (lo.min(t), hi.max(t))
    });
    (hi > lo).then_some(hi - lo)
}

/// A skeleton record as a sketch branch (`None` without two centreline points).
fn sketch_branch(record: &SkeletonRecord, order: u32) -> Option<SketchBranch> {
    let axis_world: Vec<Point3<f64>> = record.centerline.iter().map(|p| Point3::from(*p)).collect();
    if axis_world.len() < 2 {
        return None;
    }
    let total = crate::util::polyline::length(&axis_world).max(1e-12);
    let mut walked = 0.0;
    let mut radius = Vec::with_capacity(axis_world.len());
    for (i, p) in axis_world.iter().enumerate() {
        if i > 0 {
            walked += (p - axis_world[i - 1]).norm();
        }
        let t = walked / total;
        radius.push(record.radius_start * (1.0 - t) + record.radius_end * t);
    }
    Some(SketchBranch {
        id: record.id,
        order,
        axis_world,
        radius,
    })
}

/// The axis (base to tip is decided later) and radius of a tube mesh: vertices welded, geodesic
/// distance along the mesh's edges from one extreme end, and the centroid and mean radius of
/// each band of equal distance. `None` for a mesh too small to have an axis.
pub fn tube_axis(mesh: &TriMesh) -> Option<(Vec<Point3<f64>>, Vec<f64>)> {
    let (points, edges) = welded_graph(mesh);
    if points.len() < 4 {
        return None;
    }
    let bands = 24usize;
    let first = dijkstra(&points, &edges, &[0]);
    let start = argmax(&first)?;
    // Level sets of the distance from one rim vertex are slanted across the tube; from the
    // whole first band (the end ring) they are rings across it. Twice, to settle.
    let mut distance = dijkstra(&points, &edges, &[start]);
    for _ in 0..2 {
        let reach = finite_max(&distance);
        let ring: Vec<usize> = (0..points.len())
            .filter(|&i| distance[i] <= reach / bands as f64)
            .collect();
        distance = dijkstra(&points, &edges, &ring);
    }
    let reach = finite_max(&distance);
    if reach <= 0.0 {
        return None;
    }
    // Per band, the axis point c and radius r that best explain the band's vertices as
    // c + r·n (n the vertex normal): r = Σ(vᵢ − v̄)·(nᵢ − n̄) / Σ|nᵢ − n̄|², c = v̄ − r·n̄. Unlike
    // the centroid this holds when a band cuts a ring of vertices in part.
    let normals = vertex_normals(mesh, &points);
    let band_of = |d: f64| ((d / reach * bands as f64) as usize).min(bands - 1);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); bands];
    for (i, &d) in distance.iter().enumerate() {
        if d.is_finite() {
            members[band_of(d)].push(i);
        }
    }
    let mut axis = Vec::new();
    let mut radius = Vec::new();
    for band in members.iter().filter(|m| m.len() >= 3) {
        let n = band.len() as f64;
        let v_mean = band
            .iter()
            .fold(Vector3::zeros(), |a, &i| a + points[i].coords)
            / n;
        let n_mean = band.iter().fold(Vector3::zeros(), |a, &i| a + normals[i]) / n;
        let (mut num, mut den) = (0.0, 0.0);
        for &i in band {
            let dn = normals[i] - n_mean;
            num += (points[i].coords - v_mean).dot(&dn);
            den += dn.norm_squared();
        }
        let (c, r) = if den > 1e-9 * n && num > 0.0 {
            let r = num / den;
            (Point3::from(v_mean - n_mean * r), r)
        } else {
            let c = Point3::from(v_mean);
            let r = band.iter().map(|&i| (points[i] - c).norm()).sum::<f64>() / n;
            (c, r)
        };
        axis.push(c);
        radius.push(r);
    }
    (axis.len() >= 2).then_some((axis, radius))
}

/// Area-weighted vertex normals of the welded vertices (the mesh's winding decides outward).
fn vertex_normals(mesh: &TriMesh, points: &[Point3<f64>]) -> Vec<Vector3<f64>> {
    let scale = mesh
        .bounds()
        .map(|(lo, hi)| (hi - lo).norm() as f64)
        .unwrap_or(1.0)
        .max(1e-12);
    let quantum = scale * 1e-6;
    let index: std::collections::HashMap<(i64, i64, i64), usize> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (quantize(p, quantum), i))
        .collect();
    let mut normals = vec![Vector3::zeros(); points.len()];
    for t in &mesh.triangles {
        let corners = t.map(|v| mesh.positions[v as usize].cast::<f64>());
        let n = (corners[1] - corners[0]).cross(&(corners[2] - corners[0]));
        for c in corners {
            if let Some(&i) = index.get(&quantize(&c, quantum)) {
                normals[i] += n;
            }
        }
    }
    normals
        .into_iter()
        .map(|n| n.try_normalize(1e-300).unwrap_or_else(Vector3::zeros))
        .collect()
}

fn quantize(p: &Point3<f64>, quantum: f64) -> (i64, i64, i64) {
    (
        (p.x / quantum).round() as i64,
        (p.y / quantum).round() as i64,
        (p.z / quantum).round() as i64,
    )
}

fn argmax(values: &[f64]) -> Option<usize> {
    values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
}

/// Vertices merged where they coincide (tube seams), and the mesh's edges between them.
/// Neighbours of each vertex with the edge length.
type Adjacency = Vec<Vec<(usize, f64)>>;

fn welded_graph(mesh: &TriMesh) -> (Vec<Point3<f64>>, Adjacency) {
    let scale = mesh
        .bounds()
        .map(|(lo, hi)| (hi - lo).norm() as f64)
        .unwrap_or(1.0)
        .max(1e-12);
    let quantum = scale * 1e-6;
    let mut index = std::collections::HashMap::new();
    let mut points = Vec::new();
    let remap: Vec<usize> = mesh
        .positions
        .iter()
        .map(|p| {
            let p = p.cast::<f64>();
            let key = quantize(&p, quantum);
            *index.entry(key).or_insert_with(|| {
                points.push(p);
                points.len() - 1
            })
        })
        .collect();
    let mut edges = vec![Vec::new(); points.len()];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (remap[t[k] as usize], remap[t[(k + 1) % 3] as usize]);
            if a != b {
                let w = (points[a] - points[b]).norm();
                edges[a].push((b, w));
                edges[b].push((a, w));
            }
        }
    }
    (points, edges)
}

#[derive(PartialEq)]
struct Visit(f64, usize);
impl Eq for Visit {}
impl PartialOrd for Visit {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Visit {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

fn finite_max(values: &[f64]) -> f64 {
    values
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max)
}

/// Shortest distances along the edges from the nearest of `sources`.
fn dijkstra(points: &[Point3<f64>], edges: &[Vec<(usize, f64)>], sources: &[usize]) -> Vec<f64> {
    let mut distance = vec![f64::INFINITY; points.len()];
    let mut heap = BinaryHeap::new();
    for &source in sources {
        distance[source] = 0.0;
        heap.push(Visit(0.0, source));
    }
    while let Some(Visit(d, v)) = heap.pop() {
        if d > distance[v] {
            continue;
        }
        for &(u, w) in &edges[v] {
            if d + w < distance[u] {
                distance[u] = d + w;
                heap.push(Visit(d + w, u));
            }
        }
    }
    distance
}

fn distance_to_polyline(p: &Point3<f64>, polyline: &[Point3<f64>]) -> f64 {
    polyline
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let t = ((p - w[0]).dot(&d) / d.norm_squared().max(1e-300)).clamp(0.0, 1.0);
            (p - (w[0] + d * t)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Orients recovered tubes base-to-tip and links each to the tube it grows from: the root is
/// the thickest tube among those reaching lowest along `up` (its lower end is its base); every
/// other tube starts at the end nearer another tube and hangs from the nearest one. Returns the
/// parent index of each tube.
fn branch_tree(axes: &mut [(Vec<Point3<f64>>, Vec<f64>)], up: &Vector3<f64>) -> Vec<Option<usize>> {
    let n = axes.len();
    if n == 0 {
        return Vec::new();
    }
    let height = |p: &Point3<f64>| p.coords.dot(up);
    let lowest = axes
        .iter()
        .map(|(a, _)| a.iter().map(height).fold(f64::INFINITY, f64::min))
        .fold(f64::INFINITY, f64::min);
    let extent = axes
        .iter()
        .flat_map(|(a, _)| a.iter().map(height))
        .fold(f64::MIN, f64::max)
        - lowest;
    let mean_radius = |r: &[f64]| r.iter().sum::<f64>() / r.len().max(1) as f64;
    let root = (0..n)
        .filter(|&i| {
            let low = axes[i].0.iter().map(height).fold(f64::INFINITY, f64::min);
            low <= lowest + 0.05 * extent.max(0.0)
        })
        .max_by(|&a, &b| mean_radius(&axes[a].1).total_cmp(&mean_radius(&axes[b].1)))
        .unwrap_or(0);
    // The root grows upwards.
    {
        let (axis, radius) = &mut axes[root];
        if let (Some(first), Some(last)) = (axis.first(), axis.last())
            && height(first) > height(last)
        {
            axis.reverse();
            radius.reverse();
        }
    }
    let mut parents = vec![None; n];
    for i in 0..n {
        if i == root {
            continue;
        }
        let near = |p: &Point3<f64>| {
            (0..n)
                .filter(|&j| j != i)
                .map(|j| (distance_to_polyline(p, &axes[j].0), j))
                .min_by(|a, b| a.0.total_cmp(&b.0))
        };
        let (Some(first), Some(last)) = (axes[i].0.first().copied(), axes[i].0.last().copied())
        else {
            continue;
        };
        let (from_first, from_last) = (near(&first), near(&last));
        let base_is_last = match (from_first, from_last) {
            (Some(f), Some(l)) => l.0 < f.0,
            _ => false,
        };
        if base_is_last {
            axes[i].0.reverse();
            axes[i].1.reverse();
        }
        parents[i] = if base_is_last { from_last } else { from_first }.map(|(_, j)| j);
    }
    // Loops (two tubes each nearest the other) are cut: whatever does not reach the root hangs
    // from it.
    for i in 0..n {
        let mut at = i;
        let mut steps = 0;
        while let Some(p) = parents[at] {
            at = p;
            steps += 1;
            if steps > n {
                break;
            }
        }
        if at != root && i != root {
            parents[i] = Some(root);
        }
    }
    parents
}

/// Unit direction toward the light from an elevation above the horizon and an azimuth about
/// `up` (both degrees).
pub fn light_direction(up: &Vector3<f64>, elevation_deg: f64, azimuth_deg: f64) -> Vector3<f64> {
    let up = up.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let e1 = any_perpendicular(&up).normalize();
    let e2 = up.cross(&e1);
    let (el, az) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    ((e1 * az.cos() + e2 * az.sin()) * el.cos() + up * el.sin()).normalize()
}

/// The shading zone of every particle from how many leaf layers lie between it and the light:
/// particles whose ray toward the light passes within `radius` of other particles' centres count
/// those as occluders; with particles `spacing` apart one layer of leaves puts about
/// π·radius²/spacing² of them on the ray. Fewer than half a layer is lit, fewer than
/// `full_shadow_layers` is half shadow, more is full shadow.
pub fn shading_zones(
    particles: &[Particle],
    light_world: &Vector3<f64>,
    radius: f64,
    spacing: f64,
    full_shadow_layers: f64,
) -> Vec<Zone> {
    let per_layer =
        (std::f64::consts::PI * radius * radius / (spacing * spacing).max(1e-300)).max(1.0);
    particles
        .iter()
        .map(|p| {
            let occluders = particles
                .iter()
                .filter(|q| {
                    let d = q.position_world - p.position_world;
                    let along = d.dot(light_world);
                    along > 0.5 * radius && (d - light_world * along).norm() < radius
                })
                .count();
            let layers = occluders as f64 / per_layer;
            if layers < 0.5 {
                Zone::Lit
            } else if layers < full_shadow_layers {
                Zone::HalfShadow
            } else {
                Zone::FullShadow
            }
        })
        .collect()
}

/// Reads what `frond illustrate` is given: a glb file, a `frond reconstruct` folder or a
/// synthetic dataset (its ground truth).
pub fn read_sketch_plant(path: &Path) -> Result<SketchPlant, IllustrateError> {
    let input = |message: String| IllustrateError::Input {
        path: path.display().to_string(),
        message,
    };
    if path.is_file() {
        return SketchPlant::from_glb(path);
    }
    if !path.is_dir() {
        return Err(input("no such file or folder".into()));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if path.join("skeleton.json").is_file() && path.join("plant.glb").is_file() {
        let organs = crate::traits::io::read_reconstruction(path, &name)
            .map_err(|e| input(e.to_string()))?;
        return Ok(SketchPlant::from_organs(&organs));
    }
    if path.join("gt").join("branches.json").is_file() {
        let organs =
            crate::traits::io::read_ground_truth(path, &name).map_err(|e| input(e.to_string()))?;
        return Ok(SketchPlant::from_organs(&organs));
    }
    if path.join("plant.glb").is_file() {
        return SketchPlant::from_glb(&path.join("plant.glb"));
    }
    Err(input(
        "neither a glb, a reconstruction folder (plant.glb + skeleton.json) nor a synthetic \
         dataset (gt/branches.json)"
            .into(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::branch::{CylinderMeshing, GeneralizedCylinder};

    #[test]
    fn tube_axis_recovers_a_bent_cylinder() {
        let skeleton = crate::branch::spline::Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.0, 0.1, 0.5),
            Point3::new(0.3, 0.2, 1.0),
        ])
        .expect("spline");
        let cylinder = GeneralizedCylinder::new(skeleton.clone(), 0.05, 0.02);
        let mesh = cylinder.mesh(&CylinderMeshing::default());
        let (axis, radius) = tube_axis(&mesh).expect("axis");
        // Every recovered axis point lies near the true centreline.
        let truth: Vec<Point3<f64>> = (0..=200)
            .map(|i| skeleton.point(i as f64 / 200.0))
            .collect();
        for p in &axis {
            let d = distance_to_polyline(p, &truth);
            assert!(d < 0.03, "axis point {p:?} is {d} from the centreline");
        }
        let length = crate::util::polyline::length(&axis);
        assert!(
            (length - cylinder.length()).abs() < 0.2 * cylinder.length(),
            "{length}"
        );
        let thick = radius[..3].iter().sum::<f64>() / 3.0;
        let thin = radius[radius.len() - 3..].iter().sum::<f64>() / 3.0;
        assert!(
            (thick - thin).abs() > 0.01,
            "radius should taper: {thick} vs {thin}"
        );
    }

    #[test]
    fn merged_meshes_come_apart() {
        let skeleton = |x: f64| {
            crate::branch::spline::Spline::new(vec![
                Point3::new(x, 0.0, 0.0),
                Point3::new(x, 0.0, 1.0),
            ])
            .expect("spline")
        };
        let mut merged =
            GeneralizedCylinder::new(skeleton(0.0), 0.05, 0.05).mesh(&CylinderMeshing::default());
        merged.append(
            &GeneralizedCylinder::new(skeleton(1.0), 0.05, 0.05).mesh(&CylinderMeshing::default()),
        );
        let pieces = merged.connected_components();
        assert_eq!(pieces.len(), 2);
        let triangles: usize = pieces.iter().map(|p| p.triangles.len()).sum();
        assert_eq!(triangles, merged.triangles.len());
        for p in &pieces {
            p.validate().expect("valid piece");
        }
        assert!(TriMesh::default().connected_components().is_empty());
    }

    #[test]
    fn orders_follow_parent_links_and_survive_loops() {
        assert_eq!(orders(&[None, Some(0), Some(1), Some(0)]), vec![0, 1, 2, 1]);
        let looped = orders(&[Some(1), Some(0)]);
        assert!(looped.iter().all(|&o| o > 0));
    }

    #[test]
    fn branch_tree_orients_tubes_from_their_parent() {
        let line = |a: [f64; 3], b: [f64; 3]| {
            let (a, b) = (Point3::from(a), Point3::from(b));
            (
                (0..=10).map(|i| a + (b - a) * (i as f64 / 10.0)).collect(),
                vec![0.01; 11],
            )
        };
        // A stem along z and a side branch drawn tip-first.
        let mut axes = vec![
            line([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            line([0.5, 0.0, 0.8], [0.0, 0.0, 0.5]),
        ];
        axes[0].1 = vec![0.03; 11];
        let parents = branch_tree(&mut axes, &Vector3::z());
        assert_eq!(parents, vec![None, Some(0)]);
        assert!(
            axes[1].0[0].x.abs() < 1e-9,
            "the side branch starts at the stem"
        );
    }

    #[test]
    fn particle_reduction_respects_the_budget_and_keeps_every_leaf() {
        let mut leaves = Vec::new();
        for k in 0..5 {
            let mut mesh = TriMesh::default();
            let z = k as f32 * 0.2;
            mesh.positions = vec![
                Point3::new(0.0, 0.0, z),
                Point3::new(1.0, 0.0, z),
                Point3::new(1.0, 1.0, z),
                Point3::new(0.0, 1.0, z),
            ];
            mesh.uvs = vec![[0.0, 0.0]; 4];
            mesh.triangles = vec![[0, 1, 2], [0, 2, 3]];
            mesh.compute_normals();
            leaves.push(mesh);
        }
        let plant = SketchPlant {
            up_world: Vector3::z(),
            branches: Vec::new(),
            leaves,
        };
        let dense = plant.particles(0.1, 100_000, 7);
        assert!(dense.len() > 200, "{}", dense.len());
        let reduced = plant.particles(0.1, 60, 7);
        assert!(
            reduced.len() <= 60 && reduced.len() >= 5,
            "{}",
            reduced.len()
        );
        for leaf in 0..5 {
            assert!(reduced.iter().any(|p| p.leaf == leaf));
        }
        assert_eq!(
            reduced,
            plant.particles(0.1, 60, 7),
            "deterministic per seed"
        );
        // Stacked leaves: the top one is lit, the bottom one in shadow.
        let light = Vector3::z();
        let zones = shading_zones(&dense, &light, 0.1, 0.1, 1.5);
        let top = dense.iter().zip(&zones).filter(|(p, _)| p.leaf == 4);
        assert!(top.clone().filter(|(_, z)| **z == Zone::Lit).count() * 10 > top.count() * 8);
        let bottom: Vec<Zone> = dense
            .iter()
            .zip(&zones)
            .filter(|(p, _)| p.leaf == 0)
            .map(|(_, z)| *z)
            .collect();
        let full = bottom.iter().filter(|z| **z == Zone::FullShadow).count();
        assert!(full * 10 > bottom.len() * 8, "{full} of {}", bottom.len());
    }
}
