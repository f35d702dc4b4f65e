//! Triangle meshes shared by every geometric stage: synthetic plants, fitted leaves, branches,
//! LOD levels and export. Single precision, as the GPU and glTF use.
//!
//! Submodule `primitives` appends small marker meshes (octahedra, tetrahedra, bars, camera
//! frusta) to a [`TriMesh`].
//!
//! Takes and returns [`TriMesh`]es (positions, normals, uvs, triangles).

pub mod primitives;

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::scene::error::{Location, SceneError, SceneResult};
use crate::scene::ply::{self, Column, Element, Ply, ScalarType};
use crate::util::rng::Rng;

/// An indexed triangle mesh with per-vertex normals and texture coordinates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<Point3<f32>>,
    pub normals: Vec<Vector3<f32>>,
    /// Texture coordinates, (0, 0) at the top-left of the texture (glTF convention).
    pub uvs: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
}

/// A point sampled on a mesh surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    pub position: Point3<f32>,
    pub normal: Vector3<f32>,
    pub uv: [f32; 2],
    pub triangle: u32,
}

/// Welding coincident vertices: a position's cell on a fine grid (see [`TriMesh::weld`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weld {
    pub quantum: f64,
}

impl Weld {
    /// The grid cell of a position: equal for positions that count as one vertex.
    pub fn key(&self, p: &Point3<f64>) -> (i64, i64, i64) {
        (
            (p.x / self.quantum).round() as i64,
            (p.y / self.quantum).round() as i64,
            (p.z / self.quantum).round() as i64,
        )
    }
}

impl TriMesh {
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The three corners of triangle `t`.
    pub fn corners(&self, t: usize) -> [Point3<f32>; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Area of triangle `t`.
    pub fn triangle_area(&self, t: usize) -> f32 {
        let [a, b, c] = self.corners(t);
        0.5 * (b - a).cross(&(c - a)).norm()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| self.triangle_area(t) as f64)
            .sum()
    }

    /// Area-weighted mean unit normal (zero vector for an empty or degenerate mesh).
    pub fn mean_normal(&self) -> Vector3<f32> {
        let mut sum = Vector3::zeros();
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.corners(t);
            sum += (b - a).cross(&(c - a));
        }
        sum.try_normalize(1e-20).unwrap_or_else(Vector3::zeros)
    }

    /// Axis-aligned bounds `(min, max)`; `None` when there are no vertices.
    pub fn bounds(&self) -> Option<(Point3<f32>, Point3<f32>)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// Recomputes vertex normals as area-weighted sums of face normals.
    pub fn compute_normals(&mut self) {
        let mut normals = vec![Vector3::<f32>::zeros(); self.positions.len()];
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.corners(t);
            let face = (b - a).cross(&(c - a));
            for &v in &self.triangles[t] {
                normals[v as usize] += face;
            }
        }
        self.normals = normals
            .into_iter()
            .map(|n| n.try_normalize(1e-20).unwrap_or_else(Vector3::z))
            .collect();
    }

    /// Applies a rigid transform to positions and normals.
    pub fn transform(&mut self, world_from_local: &Isometry3<f32>) {
        for p in &mut self.positions {
            *p = world_from_local * *p;
        }
        for n in &mut self.normals {
            *n = world_from_local.rotation * *n;
        }
    }

    /// Appends another mesh (indices are offset).
    pub fn append(&mut self, other: &TriMesh) {
        let offset = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.uvs.extend_from_slice(&other.uvs);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + offset, t[1] + offset, t[2] + offset]),
        );
    }

    /// How many triangles use each undirected edge, keyed `(low index, high index)`.
    pub fn edge_uses(&self) -> BTreeMap<(u32, u32), usize> {
        let mut uses = BTreeMap::new();
        for t in &self.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        uses
    }

    /// The boundary edges: those used by exactly one triangle, as `[low index, high index]` in
    /// ascending order. Empty for a closed mesh; the outline of an open sheet such as a leaf.
    pub fn boundary_edges(&self) -> Vec<[u32; 2]> {
        self.edge_uses()
            .into_iter()
            .filter(|&(_, uses)| uses == 1)
            .map(|((a, b), _)| [a, b])
            .collect()
    }

    /// Checks index ranges, attribute lengths and finiteness; the message names the element.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.positions.len();
        if self.normals.len() != n || self.uvs.len() != n {
            return Err(format!(
                "{} positions but {} normals and {} uvs",
                n,
                self.normals.len(),
                self.uvs.len()
            ));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(format!("vertex {i} is not finite"));
        }
        if let Some(t) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&v| v as usize >= n))
        {
            return Err(format!("triangle {t} indexes past the {n} vertices"));
        }
        Ok(())
    }

    /// The grid vertices are welded on: positions within a millionth of the mesh's size are one
    /// vertex.
    pub fn weld(&self) -> Weld {
        let size = self
            .bounds()
            .map(|(lo, hi)| (hi - lo).norm() as f64)
            .unwrap_or(1.0)
            .max(1e-12);
        Weld {
            quantum: size * 1e-6,
        }
    }

    /// The connected pieces of a mesh (vertices that coincide count as one), each with its own
    /// vertices; pieces keep the order of their first triangle.
    pub fn connected_components(&self) -> Vec<TriMesh> {
        let mesh = self;
        let n = mesh.positions.len();
        if n == 0 {
            return Vec::new();
        }
        let weld = mesh.weld();
        let mut sets = crate::util::union_find::UnionFind::new(n);
        let mut first_at = std::collections::HashMap::new();
        for (i, p) in mesh.positions.iter().enumerate() {
            let first = *first_at.entry(weld.key(&p.cast::<f64>())).or_insert(i);
            sets.union(first, i);
        }
        for t in &mesh.triangles {
            sets.union(t[0] as usize, t[1] as usize);
            sets.union(t[0] as usize, t[2] as usize);
        }
        let mut piece_of_root = std::collections::HashMap::new();
        let mut pieces: Vec<(TriMesh, Vec<u32>)> = Vec::new();
        let has_normals = mesh.normals.len() == n;
        for t in &mesh.triangles {
            let root = sets.find(t[0] as usize);
            let k = *piece_of_root.entry(root).or_insert_with(|| {
                pieces.push((TriMesh::default(), vec![u32::MAX; n]));
                pieces.len() - 1
            });
            let (piece, remap) = &mut pieces[k];
            let mut corners = [0u32; 3];
            for (c, &v) in corners.iter_mut().zip(t) {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = piece.positions.len() as u32;
                    piece.positions.push(mesh.positions[v]);
                    piece
                        .uvs
                        .push(mesh.uvs.get(v).copied().unwrap_or([0.0, 0.0]));
                    if has_normals {
                        piece.normals.push(mesh.normals[v]);
                    }
                }
                *c = remap[v];
            }
            piece.triangles.push(corners);
        }
        pieces
            .into_iter()
            .map(|(mut piece, _)| {
                if piece.normals.len() != piece.positions.len() {
                    piece.compute_normals();
                }
                piece
            })
            .collect()
    }

    /// `count` points sampled uniformly over the surface (area-weighted), deterministic per rng.
    pub fn sample_surface(&self, count: usize, rng: &mut Rng) -> Vec<SurfaceSample> {
        let mut cumulative = Vec::with_capacity(self.triangles.len());
        let mut total = 0.0f64;
        for t in 0..self.triangles.len() {
            total += self.triangle_area(t) as f64;
            cumulative.push(total);
        }
        if total <= 0.0 {
            return Vec::new();
        }
        (0..count)
            .map(|_| {
                let target = rng.uniform() * total;
                let t = cumulative
                    .partition_point(|&c| c < target)
                    .min(self.triangles.len() - 1);
                self.sample_triangle(t, rng.uniform() as f32, rng.uniform() as f32)
            })
            .collect()
    }

    /// The point of triangle `t` at uniform square coordinates `(r1, r2)` ∈ [0, 1)².
    pub fn sample_triangle(&self, t: usize, r1: f32, r2: f32) -> SurfaceSample {
        let [ia, ib, ic] = self.triangles[t].map(|v| v as usize);
        let s = r1.sqrt();
        let (wa, wb, wc) = (1.0 - s, s * (1.0 - r2), s * r2);
        let position = Point3::from(
            self.positions[ia].coords * wa
                + self.positions[ib].coords * wb
                + self.positions[ic].coords * wc,
        );
        // Meshes read without normals or texture coordinates (e.g. a PLY of positions only)
        // sample a +z normal and uv (0, 0).
        let normal = match (
            self.normals.get(ia),
            self.normals.get(ib),
            self.normals.get(ic),
        ) {
            (Some(na), Some(nb), Some(nc)) => (na * wa + nb * wb + nc * wc)
                .try_normalize(1e-20)
                .unwrap_or_else(Vector3::z),
            _ => Vector3::z(),
        };
        let uv = match (self.uvs.get(ia), self.uvs.get(ib), self.uvs.get(ic)) {
            (Some(ua), Some(ub), Some(uc)) => [
                ua[0] * wa + ub[0] * wb + uc[0] * wc,
                ua[1] * wa + ub[1] * wb + uc[1] * wc,
            ],
            _ => [0.0, 0.0],
        };
        SurfaceSample {
            position,
            normal,
            uv,
            triangle: t as u32,
        }
    }

    /// The mesh as a PLY (vertices with normals and uvs, faces).
    pub fn to_ply(&self) -> Ply {
        let n = self.positions.len();
        let column = |name: &str, f: &dyn Fn(usize) -> f32| {
            Column::scalar(name, ScalarType::F32, (0..n).map(|i| f(i) as f64).collect())
        };
        let vertex = Element {
            name: "vertex".into(),
            count: n,
            columns: vec![
                column("x", &|i| self.positions[i].x),
                column("y", &|i| self.positions[i].y),
                column("z", &|i| self.positions[i].z),
                column("nx", &|i| self.normals[i].x),
                column("ny", &|i| self.normals[i].y),
                column("nz", &|i| self.normals[i].z),
                column("s", &|i| self.uvs[i][0]),
                column("t", &|i| self.uvs[i][1]),
            ],
        };
        let rows: Vec<Vec<f64>> = self
            .triangles
            .iter()
            .map(|t| t.iter().map(|&v| v as f64).collect())
            .collect();
        let face = Element {
            name: "face".into(),
            count: self.triangles.len(),
            columns: vec![Column::list(
                "vertex_indices",
                ScalarType::U8,
                ScalarType::U32,
                &rows,
            )],
        };
        Ply {
            elements: vec![vertex, face],
            comments: vec!["written by frond".into()],
        }
    }

    /// Reads a triangle mesh from a PLY (normals and uvs optional; polygons fan-triangulated).
    pub fn from_ply(ply: &Ply, path: &Path) -> SceneResult<Self> {
        let err = |message: String| SceneError::Parse {
            path: path.to_path_buf(),
            location: Location::Byte(0),
            record: "mesh".into(),
            message,
        };
        let vertex = ply
            .element("vertex")
            .ok_or_else(|| err("no vertex element".into()))?;
        let get = |name: &str| vertex.column(name).map(|c| &c.values);
        let (Some(x), Some(y), Some(z)) = (get("x"), get("y"), get("z")) else {
            return Err(err("vertex element lacks x, y or z".into()));
        };
        let n = vertex.count;
        let positions: Vec<Point3<f32>> = (0..n)
            .map(|i| Point3::new(x[i] as f32, y[i] as f32, z[i] as f32))
            .collect();
        let uvs = match (get("s").or(get("u")), get("t").or(get("v"))) {
            (Some(s), Some(t)) => (0..n).map(|i| [s[i] as f32, t[i] as f32]).collect(),
            _ => vec![[0.0, 0.0]; n],
        };
        let mut triangles = Vec::new();
        if let Some(face) = ply.element("face") {
            let indices = face
                .column("vertex_indices")
                .or_else(|| face.column("vertex_index"))
                .ok_or_else(|| err("face element has no vertex_indices".into()))?;
            for row in 0..face.count {
                let polygon = indices.list_row(row);
                for k in 1..polygon.len().saturating_sub(1) {
                    let tri = [polygon[0], polygon[k], polygon[k + 1]];
                    if tri.iter().any(|&v| v < 0.0 || v as usize >= n) {
                        return Err(err(format!("face {row} indexes past the {n} vertices")));
                    }
                    triangles.push(tri.map(|v| v as u32));
                }
            }
        }
        let mut mesh = Self {
            positions,
            normals: Vec::new(),
            uvs,
            triangles,
        };
        match (get("nx"), get("ny"), get("nz")) {
            (Some(nx), Some(ny), Some(nz)) => {
                mesh.normals = (0..n)
                    .map(|i| Vector3::new(nx[i] as f32, ny[i] as f32, nz[i] as f32))
                    .collect()
            }
            _ => mesh.compute_normals(),
        }
        mesh.validate().map_err(err)?;
        Ok(mesh)
    }

    /// Writes the mesh as a binary PLY, atomically.
    pub fn write_ply(&self, path: &Path) -> SceneResult<()> {
        crate::util::atomic::write_atomic(path, &ply::encode_ply_binary(&self.to_ply()))
            .map_err(|e| SceneError::io(path, e))
    }

    /// Reads a mesh from a PLY file.
    pub fn read_ply(path: &Path) -> SceneResult<Self> {
        Self::from_ply(&ply::read_ply(path)?, path)
    }
}

/// Distance from `p` to triangle `abc` (Ericson, Real-Time Collision Detection §5.1.5).
pub fn point_triangle_distance(
    p: &Point3<f32>,
    a: &Point3<f32>,
    b: &Point3<f32>,
    c: &Point3<f32>,
) -> f32 {
    let closest = closest_point_on_triangle(p, a, b, c);
    (p - closest).norm()
}

/// Closest point to `p` on triangle `abc`, by Voronoi-region tests.
pub fn closest_point_on_triangle(
    p: &Point3<f32>,
    a: &Point3<f32>,
    b: &Point3<f32>,
    c: &Point3<f32>,
) -> Point3<f32> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v;
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w;
    }
    let denom = va + vb + vc;
    if denom.abs() < f32::MIN_POSITIVE {
        // Degenerate triangle: fall back to the nearest corner.
        return *[a, b, c]
            .into_iter()
            .min_by(|x, y| (p - *x).norm_squared().total_cmp(&(p - *y).norm_squared()))
            .unwrap_or(a);
    }
    let v = vb / denom;
    let w = vc / denom;
    a + ab * v + ac * w
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn unit_square() -> TriMesh {
        let mut mesh = TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(1.0, 1.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
            ],
            normals: Vec::new(),
            uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        mesh.compute_normals();
        mesh
    }

    #[test]
    fn area_normal_and_bounds() {
        let mesh = unit_square();
        assert!((mesh.area() - 1.0).abs() < 1e-6);
        assert_eq!(mesh.mean_normal(), Vector3::z());
        let (lo, hi) = mesh.bounds().unwrap();
        assert_eq!(lo, Point3::new(0.0, 0.0, 0.0));
        assert_eq!(hi, Point3::new(1.0, 1.0, 0.0));
        assert!(mesh.validate().is_ok());
    }

    #[test]
    fn the_boundary_of_a_sheet_is_its_outline_and_a_closed_mesh_has_none() {
        for n in [1, 3, 8] {
            let sheet = crate::lod::test_meshes::grid(n, |x, y| x * y);
            let boundary = sheet.boundary_edges();
            // The unit square's perimeter, split into n edges a side; every edge on it.
            assert_eq!(boundary.len(), 4 * n);
            let on_rim = |p: &Point3<f32>| [p.x, p.y].iter().any(|c| *c == 0.0 || *c == 1.0);
            let mut length = 0.0;
            for &[a, b] in &boundary {
                assert!(a < b);
                let (pa, pb) = (sheet.positions[a as usize], sheet.positions[b as usize]);
                assert!(on_rim(&pa) && on_rim(&pb), "{pa:?} {pb:?}");
                length += ((pb.x - pa.x).powi(2) + (pb.y - pa.y).powi(2)).sqrt();
            }
            assert!((length - 4.0).abs() < 1e-5, "{length}");
            // Every rim vertex closes the loop: two boundary edges meet there.
            let mut degree = std::collections::HashMap::new();
            for [a, b] in boundary {
                *degree.entry(a).or_insert(0) += 1;
                *degree.entry(b).or_insert(0) += 1;
            }
            assert!(degree.values().all(|&d| d == 2));
            // Glued to its own mirror image (shared vertices, flipped triangles) it is closed.
            let mut closed = sheet.clone();
            closed
                .triangles
                .extend(sheet.triangles.iter().map(|&[a, b, c]| [a, c, b]));
            assert!(closed.boundary_edges().is_empty());
            assert!(closed.edge_uses().values().all(|&uses| uses % 2 == 0));
        }
        assert!(TriMesh::default().boundary_edges().is_empty());
    }

    #[test]
    fn surface_samples_are_uniform_and_on_the_surface() {
        let mesh = unit_square();
        let mut rng = Rng::seed_from(3);
        let samples = mesh.sample_surface(20_000, &mut rng);
        let left = samples.iter().filter(|s| s.position.x < 0.5).count() as f64;
        assert!((left / 20_000.0 - 0.5).abs() < 0.02);
        assert!(samples.iter().all(|s| s.position.z == 0.0));
        // uv follows position on this mesh: u = x, v = 1 - y.
        for s in samples.iter().take(100) {
            assert!((s.uv[0] - s.position.x).abs() < 1e-5);
            assert!((s.uv[1] - (1.0 - s.position.y)).abs() < 1e-5);
        }
    }

    #[test]
    fn ply_round_trip() {
        let mesh = unit_square();
        let back = TriMesh::from_ply(&mesh.to_ply(), Path::new("m.ply")).unwrap();
        assert_eq!(back, mesh);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        mesh.write_ply(&path).unwrap();
        assert_eq!(TriMesh::read_ply(&path).unwrap(), mesh);
    }

    #[test]
    fn point_triangle_distance_regions() {
        let (a, b, c) = (
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        );
        let d = |p: Point3<f32>| point_triangle_distance(&p, &a, &b, &c);
        assert!((d(Point3::new(0.2, 0.2, 2.0)) - 2.0).abs() < 1e-6); // face
        assert!((d(Point3::new(-1.0, -1.0, 0.0)) - 2f32.sqrt()).abs() < 1e-6); // vertex a
        assert!((d(Point3::new(0.5, -1.0, 0.0)) - 1.0).abs() < 1e-6); // edge ab
        assert!((d(Point3::new(1.0, 1.0, 0.0)) - 0.5f32.sqrt()).abs() < 1e-6); // edge bc
    }
}
