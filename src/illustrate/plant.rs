//! Pen-and-ink preprocessing (seed 001 §4): a plant becomes a skeleton (branches as generalized
//! cylinders: axis, radius, branching order) and foliage particles (position + leaf normal),
//! reduced when there are too many, each in one of the crown's three shading zones.
//!
//! Sources: a `frond reconstruct` folder or a synthetic dataset's ground truth (through the
//! traits readers, which know the branch tree), or any glb, where each branch's axis and radius
//! are recovered from its tube mesh (geodesic level sets) and the tree from where the tubes meet.

use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::IllustrateError;
use crate::branch::plant::SkeletonRecord;
use crate::branch::tube::{branch_tree, orders, tube_axis};
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
