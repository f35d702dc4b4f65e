//! Parametric leaves: an outline given by a half-width profile along the midrib, meshed as a
//! grid in (midrib fraction, across) coordinates, then bent along the midrib and curled across
//! it. The local frame has x along the midrib from the base, y across, z the blade normal.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::mesh::TriMesh;

/// Outline families.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LeafShape {
    /// Egg-shaped, widest below the middle.
    Ovate,
    /// Widest at the middle, symmetric ends.
    Elliptic,
    /// Long and narrow, widest in the lower third, acuminate tip.
    Lanceolate,
    /// Widest above the middle.
    Obovate,
}

impl LeafShape {
    pub const ALL: [LeafShape; 4] = [
        LeafShape::Ovate,
        LeafShape::Elliptic,
        LeafShape::Lanceolate,
        LeafShape::Obovate,
    ];

    /// Half width relative to the maximum, at midrib fraction `t` ∈ [0, 1]: 0 at base and tip.
    /// `sin(π t^p)^q`: `p` places the widest point at `t = 0.5^(1/p)`, `q` sharpens the ends.
    pub fn half_width(self, t: f64) -> f64 {
        let t = t.clamp(0.0, 1.0);
        let (p, q) = match self {
            LeafShape::Ovate => (0.63, 0.75),
            LeafShape::Elliptic => (1.0, 0.7),
            LeafShape::Lanceolate => (0.7, 1.15),
            LeafShape::Obovate => (1.55, 0.7),
        };
        (std::f64::consts::PI * t.powf(p)).sin().max(0.0).powf(q)
    }

    /// Typical width / length ratio.
    pub fn aspect(self) -> f64 {
        match self {
            LeafShape::Ovate => 0.6,
            LeafShape::Elliptic => 0.45,
            LeafShape::Lanceolate => 0.22,
            LeafShape::Obovate => 0.5,
        }
    }
}

/// Geometry of one leaf.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeafGeometry {
    pub shape: LeafShape,
    /// Blade length along the (flat) midrib, metres.
    pub length: f64,
    /// Maximum blade width, metres.
    pub width: f64,
    /// Midrib curvature (1/m); positive droops the tip (toward −z).
    pub bend: f64,
    /// Cross curvature (1/m); positive lifts the margins (a cupped leaf).
    pub curl: f64,
}

/// Mesh resolution of a leaf.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LeafMeshing {
    /// Stations along the midrib (excluding base and tip points).
    pub along: usize,
    /// Vertices across each station (odd, so one lies on the midrib).
    pub across: usize,
}

impl LeafMeshing {
    /// A resolution that keeps triangles about `length / 24` in size, within limits.
    pub fn for_length(length_m: f64) -> Self {
        let along = ((length_m / 0.008).round() as usize).clamp(8, 28);
        Self {
            along,
            across: if along > 14 { 9 } else { 7 },
        }
    }
}

impl LeafGeometry {
    /// Local position of the point at midrib fraction `t` and across fraction `s` ∈ [−1, 1].
    pub fn point(&self, t: f64, s: f64) -> Point3<f64> {
        let x = t * self.length;
        let y = s * 0.5 * self.width * self.shape.half_width(t);
        // Bending along the midrib: the midrib follows a circle of curvature `bend`.
        let (mx, mz) = if self.bend.abs() < 1e-9 {
            (x, 0.0)
        } else {
            let angle = self.bend * x;
            (angle.sin() / self.bend, -(1.0 - angle.cos()) / self.bend)
        };
        // Curl lifts the blade quadratically away from the midrib.
        let z = mz + 0.5 * self.curl * y * y;
        Point3::new(mx, y, z)
    }

    /// Texture coordinates of `(t, s)`: u along the midrib, v across (0.5 on the midrib).
    pub fn uv(t: f64, s: f64) -> [f32; 2] {
        [t as f32, (0.5 + 0.5 * s) as f32]
    }

    /// Triangle mesh of the blade in the local frame (base and tip are single vertices).
    pub fn mesh(&self, meshing: &LeafMeshing) -> TriMesh {
        let along = meshing.along.max(2);
        let across = (meshing.across.max(3) | 1) as u32;
        let mut mesh = TriMesh::default();
        let push = |t: f64, s: f64, mesh: &mut TriMesh| {
            mesh.positions.push(self.point(t, s).cast::<f32>());
            mesh.uvs.push(Self::uv(t, s));
        };
        push(0.0, 0.0, &mut mesh);
        for i in 1..=along {
            let t = i as f64 / (along + 1) as f64;
            for j in 0..across {
                let s = -1.0 + 2.0 * j as f64 / (across - 1) as f64;
                push(t, s, &mut mesh);
            }
        }
        push(1.0, 0.0, &mut mesh);
        let base = 0u32;
        let tip = mesh.positions.len() as u32 - 1;
        let row = |i: u32| 1 + (i - 1) * across;
        // Base fan and tip fan; quads between stations. Counter-clockwise seen from +z.
        for j in 0..across - 1 {
            mesh.triangles.push([base, row(1) + j, row(1) + j + 1]);
            let last = row(along as u32);
            mesh.triangles.push([tip, last + j + 1, last + j]);
        }
        for i in 1..along as u32 {
            for j in 0..across - 1 {
                let a = row(i) + j;
                let b = a + 1;
                let c = row(i + 1) + j;
                let d = c + 1;
                mesh.triangles.push([a, c, b]);
                mesh.triangles.push([b, c, d]);
            }
        }
        mesh.compute_normals();
        mesh
    }

    /// The outline as two margin polylines and the midrib (`n` points each, base to tip),
    /// the generic leaf model's three polylines (seed 004 §6.1).
    pub fn polylines(&self, n: usize) -> [Vec<Point3<f64>>; 3] {
        let n = n.max(2);
        let line = |s: f64| {
            (0..n)
                .map(|k| self.point(k as f64 / (n - 1) as f64, s))
                .collect()
        };
        [line(-1.0), line(1.0), line(0.0)]
    }

    /// Arc length of the (possibly bent) midrib.
    pub fn midrib_length(&self) -> f64 {
        let [_, _, midrib] = self.polylines(200);
        crate::util::polyline::length(&midrib)
    }

    /// Area of the flat blade, ∫ width(t) dt.
    pub fn flat_area(&self) -> f64 {
        let n = 2000;
        (0..n)
            .map(|k| {
                let t = (k as f64 + 0.5) / n as f64;
                self.width * self.shape.half_width(t) * self.length / n as f64
            })
            .sum()
    }

    /// Unit normal of the flat blade in the local frame.
    pub fn local_normal() -> Vector3<f64> {
        Vector3::z()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_vanish_at_the_ends_and_peak_where_expected() {
        for shape in LeafShape::ALL {
            assert!(shape.half_width(0.0).abs() < 1e-9);
            assert!(shape.half_width(1.0).abs() < 1e-6);
            let peak = (1..100)
                .map(|k| k as f64 / 100.0)
                .max_by(|a, b| shape.half_width(*a).total_cmp(&shape.half_width(*b)))
                .unwrap();
            let expected = match shape {
                LeafShape::Ovate => 0.33,
                LeafShape::Elliptic => 0.5,
                LeafShape::Lanceolate => 0.37,
                LeafShape::Obovate => 0.64,
            };
            assert!((peak - expected).abs() < 0.03, "{shape:?} peaks at {peak}");
        }
    }

    #[test]
    fn flat_mesh_area_matches_the_outline_integral() {
        for shape in LeafShape::ALL {
            let leaf = LeafGeometry {
                shape,
                length: 0.2,
                width: 0.2 * shape.aspect(),
                bend: 0.0,
                curl: 0.0,
            };
            let mesh = leaf.mesh(&LeafMeshing {
                along: 60,
                across: 11,
            });
            assert!(mesh.validate().is_ok());
            let relative = (mesh.area() - leaf.flat_area()).abs() / leaf.flat_area();
            assert!(relative < 0.03, "{shape:?}: {relative}");
            // Counter-clockwise from +z: every face normal points up.
            for t in 0..mesh.triangles.len() {
                let [a, b, c] = mesh.corners(t);
                assert!((b - a).cross(&(c - a)).z >= 0.0, "{shape:?} triangle {t}");
            }
        }
    }

    #[test]
    fn bending_preserves_midrib_length_and_droops_the_tip() {
        let leaf = LeafGeometry {
            shape: LeafShape::Elliptic,
            length: 0.2,
            width: 0.08,
            bend: 4.0,
            curl: 10.0,
        };
        assert!((leaf.midrib_length() - 0.2).abs() < 1e-4);
        assert!(leaf.point(1.0, 0.0).z < -0.01);
        // Curl lifts the margins above the midrib.
        assert!(leaf.point(0.4, 1.0).z > leaf.point(0.4, 0.0).z);
    }
}
