//! Branches (seed 004 §7): generalized cylinders whose skeleton is a C¹ 3D spline and whose
//! radius is given at each end and interpolated linearly along the arc length; a branch tree
//! records each branch's parent and attachment parameter.
//!
//! Meshing uses rotation-minimising frames (double reflection, Wang et al. 2008), so tubes do
//! not twist or flip along curved skeletons.
//!
//! `handles` projects a tree into a view (a photo or the GUI's 3D camera) as the handles the
//! user drags, and finds the handle under a press. `tube` recovers tubes (axis, radius, tree)
//! from meshes alone, e.g. a glb's branch nodes.
//!
//! Takes spline control points, radii and parents (drawn, or found by [`skeleton`] from the
//! non-leaf points); returns a [`BranchTree`], its meshes ([`plant`]) and the leaves attached to
//! it ([`attach`]).

pub mod attach;
pub mod compound;
pub mod handles;
pub mod plant;
pub mod prune;
pub mod skeleton;
pub mod spline;
pub mod tube;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

pub use spline::{Spline, SplineError};

use crate::mesh::TriMesh;

/// A generalized cylinder: a spline skeleton with linearly varying radius (seed 004 §7).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneralizedCylinder {
    pub skeleton: Spline,
    pub radius_start: f64,
    pub radius_end: f64,
}

/// Mesh resolution and end treatment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CylinderMeshing {
    /// Vertices around each ring.
    pub radial_segments: usize,
    /// Rings along the skeleton minus one.
    pub axial_segments: usize,
    /// Close the start with a disc (false where the branch joins its parent).
    pub cap_start: bool,
    /// Close the end with a disc.
    pub cap_end: bool,
}

impl Default for CylinderMeshing {
    fn default() -> Self {
        Self {
            radial_segments: 12,
            axial_segments: 16,
            cap_start: false,
            cap_end: true,
        }
    }
}

/// A frame along a curve: position, tangent and a normal perpendicular to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub position: Point3<f64>,
    pub tangent: Vector3<f64>,
    pub normal: Vector3<f64>,
}

impl Frame {
    pub fn binormal(&self) -> Vector3<f64> {
        self.tangent.cross(&self.normal)
    }
}

pub use crate::util::geometry::any_perpendicular;

/// Rotation-minimising frames along sampled points with tangents (double reflection method,
/// Wang, Jüttler, Zheng & Liu 2008). The first normal is `initial_normal` projected off the
/// first tangent (or any perpendicular if it is parallel).
pub fn rotation_minimizing_frames(
    samples: &[(Point3<f64>, Vector3<f64>)],
    initial_normal: Option<Vector3<f64>>,
) -> Vec<Frame> {
    let Some(&(p0, t0)) = samples.first() else {
        return Vec::new();
    };
    let mut normal = initial_normal
        .map(|n| n - t0 * t0.dot(&n))
        .and_then(|n| n.try_normalize(1e-9))
        .unwrap_or_else(|| any_perpendicular(&t0));
    let mut frames = Vec::with_capacity(samples.len());
    frames.push(Frame {
        position: p0,
        tangent: t0,
        normal,
    });
    for w in samples.windows(2) {
        let ((x0, t0), (x1, t1)) = (w[0], w[1]);
        let v1 = x1 - x0;
        let c1 = v1.norm_squared();
        if c1 < 1e-24 {
            frames.push(Frame {
                position: x1,
                tangent: t1,
                normal,
            });
            continue;
        }
        let normal_left = normal - v1 * (2.0 / c1 * v1.dot(&normal));
        let tangent_left = t0 - v1 * (2.0 / c1 * v1.dot(&t0));
        let v2 = t1 - tangent_left;
        let c2 = v2.norm_squared();
        normal = if c2 < 1e-24 {
            normal_left
        } else {
            normal_left - v2 * (2.0 / c2 * v2.dot(&normal_left))
        };
        // Re-orthogonalise against drift.
        normal = (normal - t1 * t1.dot(&normal))
            .try_normalize(1e-12)
            .unwrap_or_else(|| any_perpendicular(&t1));
        frames.push(Frame {
            position: x1,
            tangent: t1,
            normal,
        });
    }
    frames
}

impl GeneralizedCylinder {
    pub fn new(skeleton: Spline, radius_start: f64, radius_end: f64) -> Self {
        Self {
            skeleton,
            radius_start: radius_start.max(0.0),
            radius_end: radius_end.max(0.0),
        }
    }

    /// Radius at arc-length fraction `s` ∈ [0, 1] (linear between the ends, seed 004 §7).
    pub fn radius_at(&self, s: f64) -> f64 {
        let s = s.clamp(0.0, 1.0);
        self.radius_start * (1.0 - s) + self.radius_end * s
    }

    /// Length of the skeleton.
    pub fn length(&self) -> f64 {
        self.skeleton.length()
    }

    /// Frames at `n` points equally spaced in arc length.
    pub fn frames(&self, n: usize, initial_normal: Option<Vector3<f64>>) -> Vec<Frame> {
        rotation_minimizing_frames(&self.skeleton.sample_by_arc_length(n), initial_normal)
    }

    /// A tube mesh: rings of `radial_segments` vertices (plus a seam vertex for texture
    /// continuity) at `axial_segments + 1` arc-length stations, optional end caps.
    /// `u` runs around the ring, `v` along the branch in units of its mean circumference.
    pub fn mesh(&self, meshing: &CylinderMeshing) -> TriMesh {
        let radial = meshing.radial_segments.max(3);
        let axial = meshing.axial_segments.max(1);
        let frames = self.frames(axial + 1, None);
        let circumference =
            std::f64::consts::TAU * 0.5 * (self.radius_start + self.radius_end).max(1e-9);
        let length = self.length();
        let mut mesh = TriMesh::default();
        for (k, frame) in frames.iter().enumerate() {
            let s = k as f64 / axial as f64;
            let radius = self.radius_at(s);
            let binormal = frame.binormal();
            for j in 0..=radial {
                let angle = std::f64::consts::TAU * j as f64 / radial as f64;
                let direction = frame.normal * angle.cos() + binormal * angle.sin();
                let p = frame.position + direction * radius;
                mesh.positions.push(p.cast::<f32>());
                mesh.normals.push(direction.cast::<f32>());
                mesh.uvs.push([
                    j as f32 / radial as f32,
                    (s * length / circumference) as f32,
                ]);
            }
        }
        let ring = (radial + 1) as u32;
        for k in 0..axial as u32 {
            for j in 0..radial as u32 {
                let a = k * ring + j;
                let b = a + 1;
                let c = a + ring;
                let d = c + 1;
                // Counter-clockwise seen from outside: (b−a)×(c−a) points along the normal.
                mesh.triangles.push([a, b, c]);
                mesh.triangles.push([b, d, c]);
            }
        }
        let mut cap = |frame: &Frame, radius: f64, outward: Vector3<f64>| {
            let center = mesh.positions.len() as u32;
            mesh.positions.push(frame.position.cast::<f32>());
            mesh.normals.push(outward.cast::<f32>());
            mesh.uvs.push([0.5, 0.5]);
            let binormal = frame.binormal();
            for j in 0..radial {
                let angle = std::f64::consts::TAU * j as f64 / radial as f64;
                let direction = frame.normal * angle.cos() + binormal * angle.sin();
                mesh.positions
                    .push((frame.position + direction * radius).cast::<f32>());
                mesh.normals.push(outward.cast::<f32>());
                mesh.uvs.push([
                    0.5 + 0.5 * angle.cos() as f32,
                    0.5 + 0.5 * angle.sin() as f32,
                ]);
            }
            for j in 0..radial as u32 {
                let a = center + 1 + j;
                let b = center + 1 + (j + 1) % radial as u32;
                // Orient each fan triangle so that its normal points along `outward`.
                let (pa, pb, pc) = (
                    mesh.positions[center as usize],
                    mesh.positions[a as usize],
                    mesh.positions[b as usize],
                );
                let face = (pb - pa).cross(&(pc - pa));
                if face.cast::<f64>().dot(&outward) >= 0.0 {
                    mesh.triangles.push([center, a, b]);
                } else {
                    mesh.triangles.push([center, b, a]);
                }
            }
        };
        if meshing.cap_start
            && let Some(first) = frames.first()
        {
            cap(first, self.radius_start, -first.tangent);
        }
        if meshing.cap_end
            && let Some(last) = frames.last()
        {
            cap(last, self.radius_end, last.tangent);
        }
        mesh
    }
}

/// A branch of a plant: its cylinder and where it grows from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Branch {
    pub id: u32,
    /// Index of the parent branch in the tree; `None` for the main stem.
    pub parent: Option<u32>,
    /// Arc-length fraction on the parent where this branch starts.
    pub parent_fraction: f64,
    pub cylinder: GeneralizedCylinder,
    /// A synthesized leaf grows at the tip (seed 004 §7: the average leaf, scaled by the
    /// branch's thickness).
    #[serde(default)]
    pub leaf_at_tip: bool,
}

/// A point on a branch of a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchPoint {
    pub branch: u32,
    /// Arc-length fraction along the branch.
    pub fraction: f64,
    pub position: Point3<f64>,
    pub tangent: Vector3<f64>,
    pub radius: f64,
    /// Distance from the query point.
    pub distance: f64,
}

/// A plant's branches, parents before children.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BranchTree {
    pub branches: Vec<Branch>,
}

impl BranchTree {
    /// The branch with this id.
    pub fn get(&self, id: u32) -> Option<&Branch> {
        self.branches.iter().find(|b| b.id == id)
    }

    fn get_mut(&mut self, id: u32) -> Option<&mut Branch> {
        self.branches.iter_mut().find(|b| b.id == id)
    }

    /// An id no branch has.
    pub fn next_id(&self) -> u32 {
        self.branches.iter().map(|b| b.id + 1).max().unwrap_or(0)
    }

    /// A branch and all its descendants (ids, the branch first).
    pub fn subtree(&self, id: u32) -> Vec<u32> {
        let mut out = vec![id];
        let mut k = 0;
        while k < out.len() {
            let parent = out[k];
            out.extend(
                self.branches
                    .iter()
                    .filter(|b| b.parent == Some(parent))
                    .map(|b| b.id),
            );
            k += 1;
        }
        out
    }

    /// The point at an arc-length fraction of a branch.
    pub fn point_on(&self, id: u32, fraction: f64) -> Option<BranchPoint> {
        let branch = self.get(id)?;
        let skeleton = &branch.cylinder.skeleton;
        let t = skeleton.parameter_at_fraction(fraction);
        Some(BranchPoint {
            branch: id,
            fraction,
            position: skeleton.point(t),
            tangent: skeleton.tangent(t),
            radius: branch.cylinder.radius_at(fraction),
            distance: 0.0,
        })
    }

    /// The closest point of any branch to `p` (`None` for an empty tree).
    pub fn closest(&self, p: &Point3<f64>) -> Option<BranchPoint> {
        self.branches
            .iter()
            .map(|b| (b.id, b.cylinder.skeleton.closest_fraction(p)))
            .min_by(|a, b| a.1.1.total_cmp(&b.1.1).then(a.0.cmp(&b.0)))
            .and_then(|(id, (fraction, distance))| {
                self.point_on(id, fraction)
                    .map(|point| BranchPoint { distance, ..point })
            })
    }

    /// Moves the first control point of every child of `id` (and, recursively, of theirs)
    /// onto its attachment point, after `id` changed shape.
    pub fn reattach_children(&mut self, id: u32) -> Result<(), SplineError> {
        let mut pending = vec![id];
        while let Some(parent) = pending.pop() {
            let children: Vec<(u32, f64)> = self
                .branches
                .iter()
                .filter(|b| b.parent == Some(parent))
                .map(|b| (b.id, b.parent_fraction))
                .collect();
            for (child, fraction) in children {
                let Some(anchor) = self.point_on(parent, fraction) else {
                    continue;
                };
                if let Some(branch) = self.get_mut(child) {
                    let mut points = branch.cylinder.skeleton.control_points().to_vec();
                    points[0] = anchor.position;
                    branch.cylinder.skeleton = Spline::new(points)?;
                }
                pending.push(child);
            }
        }
        Ok(())
    }

    /// One mesh for all branches.
    pub fn mesh(&self, meshing: &CylinderMeshing) -> TriMesh {
        let mut mesh = TriMesh::default();
        for branch in &self.branches {
            mesh.append(&branch.cylinder.mesh(meshing));
        }
        mesh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curved() -> GeneralizedCylinder {
        let skeleton = Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(0.5, 0.3, 1.8),
            Point3::new(1.5, 0.5, 2.0),
        ])
        .unwrap();
        GeneralizedCylinder::new(skeleton, 0.1, 0.02)
    }

    #[test]
    fn frames_stay_orthonormal_and_do_not_flip() {
        let cylinder = curved();
        let frames = cylinder.frames(200, Some(Vector3::x()));
        for w in frames.windows(2) {
            for f in w {
                assert!((f.normal.norm() - 1.0).abs() < 1e-9);
                assert!(f.normal.dot(&f.tangent).abs() < 1e-6);
            }
            // Consecutive normals change little: no flips.
            assert!(w[0].normal.dot(&w[1].normal) > 0.99);
        }
    }

    #[test]
    fn frames_of_a_planar_curve_keep_the_plane_normal() {
        // A curve in the xz plane: the RMF normal started along y stays along y.
        let skeleton = Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 1.0),
            Point3::new(2.0, 0.0, 0.0),
        ])
        .unwrap();
        let frames =
            rotation_minimizing_frames(&skeleton.sample_by_arc_length(100), Some(Vector3::y()));
        for f in frames {
            assert!((f.normal - Vector3::y()).norm() < 1e-6, "{:?}", f.normal);
        }
    }

    #[test]
    fn tube_mesh_has_the_right_radius_and_outward_normals() {
        let cylinder = curved();
        let meshing = CylinderMeshing {
            radial_segments: 16,
            axial_segments: 40,
            cap_start: true,
            cap_end: true,
        };
        let mesh = cylinder.mesh(&meshing);
        assert!(mesh.validate().is_ok());
        let frames = cylinder.frames(41, None);
        let ring = 17;
        for (k, frame) in frames.iter().enumerate() {
            let expected = cylinder.radius_at(k as f64 / 40.0);
            for j in 0..ring {
                let p = mesh.positions[k * ring + j].cast::<f64>();
                let r = (p - frame.position).norm();
                assert!((r - expected).abs() < 1e-5, "ring {k}: {r} vs {expected}");
            }
        }
        // Every face normal points away from the skeleton (side) or along ±tangent (caps).
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t);
            let face = (b - a).cross(&(c - a));
            let vertex_normal = mesh.normals[mesh.triangles[t][0] as usize];
            assert!(
                face.dot(&vertex_normal) >= -1e-9,
                "triangle {t} faces inward"
            );
        }
        // The side area is close to the analytic truncated-cone area 2π·mean radius·length.
        let side_area = std::f64::consts::TAU * 0.06 * cylinder.length();
        let cap_area = std::f64::consts::PI * (0.1f64.powi(2) + 0.02f64.powi(2));
        let relative = (mesh.area() - side_area - cap_area).abs() / side_area;
        assert!(relative < 0.02, "area off by {relative}");
    }
}
