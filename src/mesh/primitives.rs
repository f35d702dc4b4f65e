//! Small marker meshes appended to a [`TriMesh`]: octahedra and tetrahedra (points and radius
//! handles), square bars (thick line segments) and camera frusta built from bars. Used by the
//! GUI's 3D panel, which draws thousands of them in one mesh per part.
//!
//! Takes positions and sizes in the world frame (double precision) and one texture
//! coordinate for every vertex of the primitive (a palette texel, so that one texture colours
//! many markers); appends positions, normals, texture coordinates and triangles to the mesh.
//! Octahedra and tetrahedra are closed, every face counter-clockwise seen from outside.

use nalgebra::{Point3, Vector3};

use super::TriMesh;
use crate::util::geometry::any_perpendicular;

impl TriMesh {
    /// Appends a regular octahedron of circumradius `radius_world` about `centre_world`, its
    /// six vertices on the axes with the axis as normal; 6 vertices, 8 triangles.
    pub fn add_octahedron(&mut self, centre_world: &Point3<f64>, radius_world: f64, uv: [f32; 2]) {
        let base = self.positions.len() as u32;
        for axis in [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
            -Vector3::z(),
        ] {
            self.positions
                .push((centre_world + axis * radius_world).cast::<f32>());
            self.normals.push(axis.cast::<f32>());
            self.uvs.push(uv);
        }
        for (a, b, c) in [
            (0, 2, 4),
            (2, 1, 4),
            (1, 3, 4),
            (3, 0, 4),
            (2, 0, 5),
            (1, 2, 5),
            (3, 1, 5),
            (0, 3, 5),
        ] {
            self.triangles.push([base + a, base + b, base + c]);
        }
    }

    /// Appends a regular tetrahedron of circumradius `radius_world` about `centre_world`: half
    /// an octahedron's triangles, for markers drawn where triangle setup dominates the cost
    /// (a software rasteriser); 4 vertices, 4 triangles.
    pub fn add_tetrahedron(&mut self, centre_world: &Point3<f64>, radius_world: f64, uv: [f32; 2]) {
        let base = self.positions.len() as u32;
        for corner in [
            Vector3::new(1.0, 1.0, 1.0),
            Vector3::new(1.0, -1.0, -1.0),
            Vector3::new(-1.0, 1.0, -1.0),
            Vector3::new(-1.0, -1.0, 1.0),
        ] {
            let direction = corner / 3f64.sqrt();
            self.positions
                .push((centre_world + direction * radius_world).cast::<f32>());
            self.normals.push(direction.cast::<f32>());
            self.uvs.push(uv);
        }
        // Counter-clockwise seen from outside, as the octahedron's.
        for (a, b, c) in [(1, 3, 2), (0, 2, 3), (0, 3, 1), (0, 1, 2)] {
            self.triangles.push([base + a, base + b, base + c]);
        }
    }

    /// Appends a square bar of half-width `half_width_world` from `a_world` to `b_world`: four
    /// flat sides, open at the ends, each side's vertices carrying the side's outward
    /// direction as normal; 16 vertices, 8 triangles. Nothing for a degenerate bar (ends
    /// closer than 1e-12).
    pub fn add_bar(
        &mut self,
        a_world: &Point3<f64>,
        b_world: &Point3<f64>,
        half_width_world: f64,
        uv: [f32; 2],
    ) {
        let axis = b_world - a_world;
        if axis.norm() < 1e-12 {
            return;
        }
        let u = any_perpendicular(&axis.normalize());
        let v = axis.normalize().cross(&u);
        let w = half_width_world;
        for (side, across) in [(u, v), (v, -u), (-u, -v), (-v, u)] {
            let base = self.positions.len() as u32;
            let offset_a = side * w + across * w;
            let offset_b = side * w - across * w;
            for p in [
                a_world + offset_a,
                a_world + offset_b,
                b_world + offset_b,
                b_world + offset_a,
            ] {
                self.positions.push(p.cast::<f32>());
                self.normals.push(side.cast::<f32>());
                self.uvs.push(uv);
            }
            self.triangles.push([base, base + 1, base + 2]);
            self.triangles.push([base, base + 2, base + 3]);
        }
    }

    /// Appends a camera frustum drawn with bars of half-width `half_width_world`: one from the
    /// apex (the camera centre) to each corner of the image rectangle, and the rectangle's four
    /// sides (corners in order around it); 8 bars.
    pub fn add_frustum(
        &mut self,
        apex_world: &Point3<f64>,
        corners_world: &[Point3<f64>; 4],
        half_width_world: f64,
        uv: [f32; 2],
    ) {
        for k in 0..4 {
            self.add_bar(apex_world, &corners_world[k], half_width_world, uv);
            self.add_bar(
                &corners_world[k],
                &corners_world[(k + 1) % 4],
                half_width_world,
                uv,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed, every face wound counter-clockwise seen from outside (the renderer's front
    /// faces), every vertex at the radius with its outward direction as normal.
    fn assert_closed_and_outward(mesh: &TriMesh, centre: &Point3<f64>, radius: f64) {
        assert!(mesh.boundary_edges().is_empty());
        assert!(mesh.edge_uses().values().all(|&uses| uses == 2));
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].cast::<f64>());
            let normal = (b - a).cross(&(c - a));
            let outward = Point3::from((a.coords + b.coords + c.coords) / 3.0) - centre;
            assert!(normal.dot(&outward) > 0.0, "{t:?} faces inwards");
        }
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            let from_centre = p.cast::<f64>() - centre;
            assert!((from_centre.norm() - radius).abs() < 1e-5);
            assert!((from_centre.normalize() - n.cast::<f64>()).norm() < 1e-5);
        }
        assert!(mesh.validate().is_ok());
    }

    #[test]
    fn point_markers_are_closed_and_face_outwards() {
        let centre = Point3::new(0.5, -1.0, 2.0);
        for radius in [0.25, 3.0] {
            let mut octahedron = TriMesh::default();
            octahedron.add_octahedron(&centre, radius, [0.1, 0.2]);
            assert_eq!(octahedron.triangles.len(), 8);
            assert_closed_and_outward(&octahedron, &centre, radius);
            let mut tetrahedron = TriMesh::default();
            tetrahedron.add_tetrahedron(&centre, radius, [0.1, 0.2]);
            assert_eq!(tetrahedron.triangles.len(), 4);
            assert_closed_and_outward(&tetrahedron, &centre, radius);
            assert!(tetrahedron.uvs.iter().all(|uv| *uv == [0.1, 0.2]));
        }
    }

    #[test]
    fn markers_appended_to_a_mesh_keep_what_was_there() {
        let mut mesh = TriMesh::default();
        mesh.add_octahedron(&Point3::origin(), 1.0, [0.0, 0.0]);
        let first = mesh.clone();
        mesh.add_octahedron(&Point3::new(5.0, 0.0, 0.0), 1.0, [0.5, 0.5]);
        assert_eq!(mesh.positions[..6], first.positions[..]);
        assert_eq!(mesh.triangles[..8], first.triangles[..]);
        // The second one indexes only its own vertices and is closed on its own.
        assert!(mesh.triangles[8..].iter().flatten().all(|&i| i >= 6));
        assert!(mesh.boundary_edges().is_empty());
        assert_eq!(mesh.uvs[6], [0.5, 0.5]);
    }

    #[test]
    fn a_bar_surrounds_its_segment_at_its_half_width() {
        let (a, b) = (Point3::new(1.0, 2.0, 3.0), Point3::new(2.0, 0.0, 4.0));
        let w = 0.1;
        let mut mesh = TriMesh::default();
        mesh.add_bar(&a, &b, w, [0.3, 0.7]);
        assert_eq!((mesh.positions.len(), mesh.triangles.len()), (16, 8));
        let axis = (b - a).normalize();
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            let p = p.cast::<f64>();
            let along = (p - a).dot(&axis);
            // Every vertex at an end, at a corner of the square section (√2·w from the axis).
            assert!(along.abs() < 1e-5 || (along - (b - a).norm()).abs() < 1e-5);
            let across = (p - a) - axis * along;
            assert!((across.norm() - w * 2f64.sqrt()).abs() < 1e-5);
            // The normal is the side's direction: across the axis, pointing out of it.
            let n = n.cast::<f64>();
            assert!(n.dot(&axis).abs() < 1e-6 && (n.norm() - 1.0).abs() < 1e-6);
            assert!((across.dot(&n) - w).abs() < 1e-5);
        }
        // The sides share no vertices (each has its own normal): four separate quads, each
        // with its four edges on the boundary and its diagonal shared.
        assert_eq!(mesh.boundary_edges().len(), 4 * 4);
        assert_eq!(mesh.edge_uses().len(), 4 * 5);
        let before = mesh.clone();
        mesh.add_bar(&a, &a, w, [0.0, 0.0]);
        assert_eq!(mesh, before, "a degenerate bar adds nothing");
    }

    #[test]
    fn a_frustum_is_eight_bars_through_its_apex_and_corners() {
        let apex = Point3::origin();
        let corners = [
            Point3::new(-1.0, -1.0, 2.0),
            Point3::new(1.0, -1.0, 2.0),
            Point3::new(1.0, 1.0, 2.0),
            Point3::new(-1.0, 1.0, 2.0),
        ];
        let mut frustum = TriMesh::default();
        frustum.add_frustum(&apex, &corners, 0.01, [0.0, 1.0]);
        assert_eq!(frustum.triangles.len(), 8 * 8);
        // Every bar runs between two of the five points: each vertex lies within √2·w of a
        // segment joining the apex to a corner or two neighbouring corners.
        let segments: Vec<(Point3<f64>, Point3<f64>)> = (0..4)
            .flat_map(|k| [(apex, corners[k]), (corners[k], corners[(k + 1) % 4])])
            .collect();
        for p in &frustum.positions {
            let p = p.cast::<f64>();
            let off = segments
                .iter()
                .map(|(a, b)| {
                    let t = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
                    (p - (a + (b - a) * t)).norm()
                })
                .fold(f64::INFINITY, f64::min);
            assert!(off < 0.01 * 2f64.sqrt() + 1e-5, "{p:?} is {off} off");
        }
        // Its bounds are the corners' and the apex's, widened by the bars.
        let (lo, hi) = frustum.bounds().unwrap();
        assert!((lo - Point3::new(-1.0, -1.0, 0.0)).norm() < 0.05, "{lo:?}");
        assert!((hi - Point3::new(1.0, 1.0, 2.0)).norm() < 0.05, "{hi:?}");
    }
}
