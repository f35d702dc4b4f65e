//! Half-edge-collapse simplification with quadric error and visual importance (seed 000
//! §4.2, eqs. 10–12).
//!
//! Collapsing the half-edge u→v moves vertex u onto the existing vertex v (no new positions,
//! so every kept vertex keeps its normal and texture coordinates). Its cost is u's quadric
//! error at v's position (Garland–Heckbert: the area-weighted squared distances to the
//! planes of u's triangles, accumulated over earlier collapses) times u's visual importance
//! IMP_u = 1 + w·(1 − cos of the largest angle between u's face normals) (eq. 11 read as
//! 1 + ‖k‖, k a curvature-like feature degree). Open borders — leaf margins, and UV seams,
//! which are split vertices and so borders of the index topology — carry extra quadrics of
//! planes through each border edge perpendicular to its face, so silhouettes and margins
//! survive; a border vertex only slides along its border. Collapses that would flip a face,
//! make it degenerate or break manifoldness (the link condition) are refused.

use nalgebra::{Point3, Vector3};
use serde::Serialize;

use crate::mesh::TriMesh;

/// Settings of [`simplify`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SimplifyOptions {
    /// Stop once this many triangles remain.
    pub target_triangles: usize,
    /// Weight of the border-plane quadrics relative to the face quadrics.
    pub border_weight: f64,
    /// w in IMP = 1 + w·(1 − cos θ_max).
    pub importance_weight: f64,
}

impl SimplifyOptions {
    pub fn to_triangles(target_triangles: usize) -> Self {
        Self {
            target_triangles,
            border_weight: 10.0,
            importance_weight: 2.0,
        }
    }
}

/// Why a mesh cannot be simplified.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimplifyError {
    #[error("triangle {triangle} refers to vertex {vertex}, but the mesh has {count} vertices")]
    BadIndex {
        triangle: usize,
        vertex: u32,
        count: usize,
    },
    #[error("vertex {0} has a non-finite position")]
    NonFinite(usize),
}

/// A simplified mesh and what the simplification did.
#[derive(Clone, Debug)]
pub struct Simplified {
    pub mesh: TriMesh,
    pub collapses: usize,
    /// Collapses refused (flip, degeneracy, link condition, border).
    pub refused: usize,
}

/// Symmetric 4×4 quadric [a², ab, ac, ad, b², bc, bd, c², cd, d²] of planes ax+by+cz+d=0.
#[derive(Clone, Copy, Debug, Default)]
struct Quadric([f64; 10]);

impl Quadric {
    fn plane(normal: &Vector3<f64>, point: &Point3<f64>, weight: f64) -> Self {
        let (a, b, c) = (normal.x, normal.y, normal.z);
        let d = -normal.dot(&point.coords);
        Quadric(
            [
                a * a,
                a * b,
                a * c,
                a * d,
                b * b,
                b * c,
                b * d,
                c * c,
                c * d,
                d * d,
            ]
            .map(|v| v * weight),
        )
    }

    fn add(&mut self, other: &Quadric) {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
    }

    fn error(&self, p: &Point3<f64>) -> f64 {
        let q = &self.0;
        let (x, y, z) = (p.x, p.y, p.z);
        (q[0] * x * x
            + q[4] * y * y
            + q[7] * z * z
            + 2.0 * (q[1] * x * y + q[2] * x * z + q[5] * y * z)
            + 2.0 * (q[3] * x + q[6] * y + q[8] * z)
            + q[9])
            .max(0.0)
    }
}

/// Mesh state during simplification.
struct Work {
    positions: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    alive: Vec<bool>,
    /// Alive triangles around each vertex.
    around: Vec<Vec<u32>>,
    quadrics: Vec<Quadric>,
    importance: Vec<f64>,
    /// Vertices on an open border (fixed: half-edge collapses keep the mesh manifold).
    border: Vec<bool>,
}

impl Work {
    fn normal(&self, t: usize, moved: Option<(u32, &Point3<f64>)>) -> Vector3<f64> {
        let p = |v: u32| match moved {
            Some((from, to)) if from == v => *to,
            _ => self.positions[v as usize],
        };
        let [a, b, c] = self.triangles[t];
        (p(b) - p(a)).cross(&(p(c) - p(a)))
    }

    /// Vertices sharing an alive triangle with `v` (sorted, without `v`).
    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut out: Vec<u32> = self.around[v as usize]
            .iter()
            .flat_map(|&t| self.triangles[t as usize])
            .filter(|&w| w != v)
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    fn edge_triangles(&self, u: u32, v: u32) -> usize {
        self.around[u as usize]
            .iter()
            .filter(|&&t| self.triangles[t as usize].contains(&v))
            .count()
    }

    /// Whether u→v may collapse.
    fn can_collapse(&self, u: u32, v: u32) -> bool {
        let shared = self.edge_triangles(u, v);
        if shared == 0 || shared > 2 {
            return false;
        }
        // A border vertex only slides along its border.
        if self.border[u as usize] && shared != 1 {
            return false;
        }
        // Link condition: the common neighbours are exactly the edge's opposite corners.
        let adjacent_to_v = |w: u32| {
            self.around[v as usize]
                .iter()
                .any(|&t| self.triangles[t as usize].contains(&w))
        };
        let mut common = [u32::MAX; 3];
        let mut common_count = 0;
        for &t in &self.around[u as usize] {
            for w in self.triangles[t as usize] {
                if w == u || w == v || common[..common_count].contains(&w) || !adjacent_to_v(w) {
                    continue;
                }
                if common_count == shared {
                    return false;
                }
                common[common_count] = w;
                common_count += 1;
            }
        }
        if common_count != shared {
            return false;
        }
        // No face may flip or collapse to a sliver.
        let target = self.positions[v as usize];
        for &t in &self.around[u as usize] {
            if self.triangles[t as usize].contains(&v) {
                continue;
            }
            let before = self.normal(t as usize, None);
            let after = self.normal(t as usize, Some((u, &target)));
            let (lb, la) = (before.norm(), after.norm());
            if la <= 1e-12 * (1.0 + lb) || before.dot(&after) <= 0.2 * lb * la {
                return false;
            }
        }
        true
    }

    fn cost(&self, u: u32, v: u32) -> f64 {
        self.quadrics[u as usize].error(&self.positions[v as usize]) * self.importance[u as usize]
    }

    fn collapse(&mut self, u: u32, v: u32) {
        let triangles = std::mem::take(&mut self.around[u as usize]);
        for t in triangles {
            let corners = self.triangles[t as usize];
            if corners.contains(&v) {
                self.alive[t as usize] = false;
                for w in corners {
                    if w != u {
                        self.around[w as usize].retain(|&x| x != t);
                    }
                }
            } else {
                for w in &mut self.triangles[t as usize] {
                    if *w == u {
                        *w = v;
                    }
                }
                self.around[v as usize].push(t);
            }
        }
        let moved = self.quadrics[u as usize];
        self.quadrics[v as usize].add(&moved);
        self.importance[v as usize] = self.importance[v as usize].max(self.importance[u as usize]);
    }
}

/// Each vertex's cheapest collapse, in an indexed binary min-heap (updated in place, so no
/// stale entries): ordered by (cost, vertex).
struct CollapseQueue {
    heap: Vec<u32>,
    /// Position of each vertex in `heap`, or `ABSENT`.
    position: Vec<u32>,
    cost: Vec<f64>,
    target: Vec<u32>,
}

const ABSENT: u32 = u32::MAX;

impl CollapseQueue {
    fn new(count: usize) -> Self {
        Self {
            heap: Vec::with_capacity(count),
            position: vec![ABSENT; count],
            cost: vec![0.0; count],
            target: vec![0; count],
        }
    }

    fn less(&self, a: u32, b: u32) -> bool {
        self.cost[a as usize]
            .total_cmp(&self.cost[b as usize])
            .then(a.cmp(&b))
            .is_lt()
    }

    fn swap(&mut self, i: usize, j: usize) {
        self.heap.swap(i, j);
        self.position[self.heap[i] as usize] = i as u32;
        self.position[self.heap[j] as usize] = j as u32;
    }

    fn sift_up(&mut self, mut i: usize) {
        while i > 0 {
            let parent = (i - 1) / 2;
            if !self.less(self.heap[i], self.heap[parent]) {
                break;
            }
            self.swap(i, parent);
            i = parent;
        }
    }

    fn sift_down(&mut self, mut i: usize) {
        loop {
            let (left, right) = (2 * i + 1, 2 * i + 2);
            let mut smallest = i;
            if left < self.heap.len() && self.less(self.heap[left], self.heap[smallest]) {
                smallest = left;
            }
            if right < self.heap.len() && self.less(self.heap[right], self.heap[smallest]) {
                smallest = right;
            }
            if smallest == i {
                break;
            }
            self.swap(i, smallest);
            i = smallest;
        }
    }

    /// Inserts or updates vertex `u`'s collapse.
    fn set(&mut self, u: u32, cost: f64, target: u32) {
        self.cost[u as usize] = cost;
        self.target[u as usize] = target;
        let at = self.position[u as usize];
        if at == ABSENT {
            self.heap.push(u);
            let last = self.heap.len() - 1;
            self.position[u as usize] = last as u32;
            self.sift_up(last);
        } else {
            self.sift_up(at as usize);
            self.sift_down(self.position[u as usize] as usize);
        }
    }

    fn remove(&mut self, u: u32) {
        let at = self.position[u as usize];
        if at == ABSENT {
            return;
        }
        let at = at as usize;
        let last = self.heap.len() - 1;
        self.swap(at, last);
        self.heap.pop();
        self.position[u as usize] = ABSENT;
        if at < self.heap.len() {
            self.sift_up(at);
            self.sift_down(self.position[self.heap[at] as usize] as usize);
        }
    }

    /// The cheapest collapse (u, v), left in the queue.
    fn peek(&self) -> Option<(u32, u32)> {
        self.heap.first().map(|&u| (u, self.target[u as usize]))
    }
}

/// Sets u's cheapest collapse target not in `skip` (validity is checked when it comes up),
/// or removes u when it has none.
fn queue_best(work: &Work, u: u32, skip: &[u32], queue: &mut CollapseQueue) {
    // Around an interior vertex each neighbour follows u in exactly one triangle; a border
    // vertex also needs the corners before it (no allocation either way).
    let border = work.border[u as usize];
    let best = work.around[u as usize]
        .iter()
        .flat_map(|&t| {
            let tri = work.triangles[t as usize];
            let k = tri.iter().position(|&w| w == u).unwrap_or(0);
            let next = tri[(k + 1) % 3];
            let previous = tri[(k + 2) % 3];
            [Some(next), border.then_some(previous)]
        })
        .flatten()
        .filter(|&v| v != u && !skip.contains(&v))
        .map(|v| (work.cost(u, v), v))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    match best {
        Some((cost, v)) => queue.set(u, cost, v),
        None => queue.remove(u),
    }
}

/// Every index in range and every position finite.
fn check_input(mesh: &TriMesh) -> Result<(), SimplifyError> {
    let count = mesh.positions.len();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&vertex) = tri.iter().find(|&&v| v as usize >= count) {
            return Err(SimplifyError::BadIndex {
                triangle: t,
                vertex,
                count,
            });
        }
    }
    match mesh
        .positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        Some(i) => Err(SimplifyError::NonFinite(i)),
        None => Ok(()),
    }
}

/// `triangles` (indices into `mesh`) over only the vertices they use, attributes carried over.
pub fn compact(mesh: &TriMesh, triangles: &[[u32; 3]]) -> TriMesh {
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    let mut out = TriMesh::default();
    for tri in triangles {
        let mut corners = [0u32; 3];
        for (k, &v) in tri.iter().enumerate() {
            if new_index[v as usize] == u32::MAX {
                new_index[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
                if let Some(n) = mesh.normals.get(v as usize) {
                    out.normals.push(*n);
                }
                out.uvs
                    .push(mesh.uvs.get(v as usize).copied().unwrap_or([0.0, 0.0]));
            }
            corners[k] = new_index[v as usize];
        }
        out.triangles.push(corners);
    }
    if out.normals.len() != out.positions.len() {
        out.compute_normals();
    }
    out
}

/// meshoptimizer's edge-collapse simplifier (through the `meshopt` crate) to about
/// `target_triangles`: about 4× faster than [`simplify`], with larger errors on plant
/// silhouettes (`benches/lod.rs`). Indices must be in range (checked).
pub fn simplify_meshopt(mesh: &TriMesh, target_triangles: usize) -> Result<TriMesh, SimplifyError> {
    check_input(mesh)?;
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| [p.x, p.y, p.z]).collect();
    let Ok(adapter) = meshopt::VertexDataAdapter::new(meshopt::typed_to_bytes(&positions), 12, 0)
    else {
        return Ok(mesh.clone());
    };
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let kept = meshopt::simplify(
        &indices,
        &adapter,
        target_triangles * 3,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    let triangles: Vec<[u32; 3]> = kept.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Ok(compact(mesh, &triangles))
}

/// Simplifies `mesh` to about `options.target_triangles` triangles by half-edge collapses
/// (fewer collapses if every remaining one is refused). Deterministic.
pub fn simplify(mesh: &TriMesh, options: &SimplifyOptions) -> Result<Simplified, SimplifyError> {
    let count = mesh.positions.len();
    check_input(mesh)?;
    let positions: Vec<Point3<f64>> = mesh.positions.iter().map(|p| p.cast()).collect();
    let mut work = Work {
        triangles: mesh.triangles.clone(),
        alive: mesh
            .triangles
            .iter()
            .map(|&[a, b, c]| a != b && b != c && a != c)
            .collect(),
        around: vec![Vec::new(); count],
        quadrics: vec![Quadric::default(); count],
        importance: vec![1.0; count],
        border: vec![false; count],
        positions,
    };
    for (t, tri) in work.triangles.iter().enumerate() {
        if work.alive[t] {
            for &v in tri {
                work.around[v as usize].push(t as u32);
            }
        }
    }
    // Face quadrics (area-weighted) and the largest normal deviation around each vertex.
    let normals: Vec<Vector3<f64>> = (0..work.triangles.len())
        .map(|t| work.normal(t, None))
        .collect();
    for (t, tri) in work.triangles.iter().enumerate() {
        if !work.alive[t] {
            continue;
        }
        let doubled_area = normals[t].norm();
        let Some(unit) = normals[t].try_normalize(1e-30) else {
            continue;
        };
        let plane = Quadric::plane(&unit, &work.positions[tri[0] as usize], 0.5 * doubled_area);
        for &v in tri {
            work.quadrics[v as usize].add(&plane);
        }
    }
    for v in 0..count {
        let units: Vec<Vector3<f64>> = work.around[v]
            .iter()
            .filter_map(|&t| normals[t as usize].try_normalize(1e-30))
            .collect();
        let mut min_cos = 1.0f64;
        for (i, a) in units.iter().enumerate() {
            for b in &units[i + 1..] {
                min_cos = min_cos.min(a.dot(b));
            }
        }
        work.importance[v] = 1.0 + options.importance_weight * (1.0 - min_cos);
    }
    // Border planes: through each border edge, perpendicular to its face.
    for (t, tri) in work.triangles.iter().enumerate() {
        if !work.alive[t] {
            continue;
        }
        let Some(unit) = normals[t].try_normalize(1e-30) else {
            continue;
        };
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if work.edge_triangles(a, b) != 1 {
                continue;
            }
            work.border[a as usize] = true;
            work.border[b as usize] = true;
            let (pa, pb) = (work.positions[a as usize], work.positions[b as usize]);
            let edge = pb - pa;
            let Some(across) = edge.cross(&unit).try_normalize(1e-30) else {
                continue;
            };
            let plane = Quadric::plane(&across, &pa, options.border_weight * edge.norm_squared());
            work.quadrics[a as usize].add(&plane);
            work.quadrics[b as usize].add(&plane);
        }
    }

    let mut remaining = work.alive.iter().filter(|&&a| a).count();
    let mut queue = CollapseQueue::new(count);
    let (mut collapses, mut refused) = (0usize, 0usize);
    // Targets refused for each vertex since its neighbourhood last changed.
    let mut skip: Vec<Vec<u32>> = vec![Vec::new(); count];
    for u in 0..count as u32 {
        queue_best(&work, u, &[], &mut queue);
    }
    while remaining > options.target_triangles {
        let Some((u, v)) = queue.peek() else {
            break;
        };
        if !work.can_collapse(u, v) {
            refused += 1;
            skip[u as usize].push(v);
            queue_best(&work, u, &skip[u as usize], &mut queue);
            continue;
        }
        remaining -= work.edge_triangles(u, v);
        // Only u's ring changes: v's quadric grows and u's other neighbours lose u and gain v
        // (the rest of v's ring keeps its candidates and their costs).
        let ring = work.neighbours(u);
        work.collapse(u, v);
        queue.remove(u);
        collapses += 1;
        for w in ring {
            let wi = w as usize;
            let queued = queue.position[wi] != ABSENT;
            if w == v || !queued || queue.target[wi] == u || !skip[wi].is_empty() {
                skip[wi].clear();
                queue_best(&work, w, &[], &mut queue);
            } else {
                // w's other candidates and their costs are unchanged: only u left and v (now a
                // neighbour) joined, so the best is the old best or v — the same choice a full
                // re-evaluation makes.
                let cost = work.cost(w, v);
                if cost
                    .total_cmp(&queue.cost[wi])
                    .then(v.cmp(&queue.target[wi]))
                    .is_lt()
                {
                    queue.set(w, cost, v);
                }
            }
        }
    }

    let kept: Vec<[u32; 3]> = work
        .triangles
        .iter()
        .zip(&work.alive)
        .filter(|(_, alive)| **alive)
        .map(|(tri, _)| *tri)
        .collect();
    let out = compact(mesh, &kept);
    Ok(Simplified {
        mesh: out,
        collapses,
        refused,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::geometry::{bounding_spheres, distance_to_mesh};
    use crate::lod::test_meshes::grid;
    use std::collections::HashMap;

    /// Each undirected edge's triangle count.
    fn edge_uses(mesh: &TriMesh) -> HashMap<(u32, u32), usize> {
        let mut uses = HashMap::new();
        for tri in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        uses
    }

    /// Largest distance from `from`'s vertices to `to`'s surface.
    fn one_sided_hausdorff(from: &TriMesh, to: &TriMesh) -> f32 {
        let bounds = bounding_spheres(to);
        from.positions
            .iter()
            .map(|p| distance_to_mesh(p, to, &bounds))
            .fold(0.0, f32::max)
    }

    #[test]
    fn a_flat_sheet_collapses_to_its_outline_and_keeps_its_area() {
        let mesh = grid(16, |_, _| 0.0);
        let simplified = simplify(&mesh, &SimplifyOptions::to_triangles(8)).unwrap();
        let out = &simplified.mesh;
        assert!(out.triangles.len() <= 8, "{}", out.triangles.len());
        assert!((out.area() - 1.0).abs() < 1e-5, "area {}", out.area());
        // The four corners survive, and every kept vertex keeps its texture coordinates.
        for corner in [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]] {
            assert!(out.uvs.contains(&corner), "corner {corner:?} lost");
        }
        for (p, uv) in out.positions.iter().zip(&out.uvs) {
            assert!((p.x - uv[0]).abs() < 1e-6 && (p.y - uv[1]).abs() < 1e-6);
        }
        out.validate().unwrap();
    }

    #[test]
    fn a_curved_sheet_keeps_its_shape_and_stays_manifold() {
        let mesh = grid(40, |x, y| 0.15 * (3.0 * x).sin() * (2.0 * y).cos());
        let before = mesh.triangles.len();
        let simplified = simplify(&mesh, &SimplifyOptions::to_triangles(before / 8)).unwrap();
        let out = &simplified.mesh;
        assert!(out.triangles.len() <= before / 8 + 1);
        out.validate().unwrap();
        // Manifold with border: no edge used by more than two triangles.
        assert!(edge_uses(out).values().all(|&n| n <= 2));
        // Half-edge collapse: every kept vertex is an original one.
        for p in &out.positions {
            assert!(mesh.positions.contains(p));
        }
        // No face flipped against the surface it approximates (normals point up here).
        for t in 0..out.triangles.len() {
            let [a, b, c] = out.corners(t);
            assert!((b - a).cross(&(c - a)).z > 0.0, "triangle {t} flipped");
        }
        // An eighth of the triangles stays within 1 % of the sheet's size.
        let deviation = one_sided_hausdorff(&mesh, out).max(one_sided_hausdorff(out, &mesh));
        assert!(deviation < 0.01, "deviation {deviation}");
        // The border (the silhouette seen from above) is kept exactly: a flat outline.
        assert!((out.area() - mesh.area()).abs() / mesh.area() < 0.02);
    }

    #[test]
    fn importance_keeps_creases_sharper_than_plain_quadrics() {
        // A sheet folded along x = 0.5 (a midrib crease) with gentle noise elsewhere.
        let mesh = grid(32, |x, y| {
            0.3 * (x - 0.5).abs() + 0.004 * ((37.0 * x).sin() + (29.0 * y).cos())
        });
        let target = SimplifyOptions::to_triangles(mesh.triangles.len() / 10);
        let with = simplify(&mesh, &target).unwrap().mesh;
        let plain = simplify(
            &mesh,
            &SimplifyOptions {
                importance_weight: 0.0,
                ..target
            },
        )
        .unwrap()
        .mesh;
        // Crease vertices (x = 0.5) kept.
        let on_crease = |m: &TriMesh| {
            m.positions
                .iter()
                .filter(|p| (p.x - 0.5).abs() < 1e-6)
                .count()
        };
        // Measured: 10 of the crease's 33 vertices kept with importance, 8 without.
        assert!(
            on_crease(&with) > on_crease(&plain),
            "{} {}",
            on_crease(&with),
            on_crease(&plain)
        );
    }

    #[test]
    fn deterministic_and_errors_name_the_element() {
        let mesh = grid(12, |x, y| 0.1 * (x * y).sin());
        let a = simplify(&mesh, &SimplifyOptions::to_triangles(40)).unwrap();
        let b = simplify(&mesh, &SimplifyOptions::to_triangles(40)).unwrap();
        assert_eq!(a.mesh, b.mesh);
        let mut bad = mesh.clone();
        bad.triangles[5][1] = 10_000;
        assert_eq!(
            simplify(&bad, &SimplifyOptions::to_triangles(4)).unwrap_err(),
            SimplifyError::BadIndex {
                triangle: 5,
                vertex: 10_000,
                count: mesh.positions.len()
            }
        );
        let mut nan = mesh.clone();
        nan.positions[3].z = f32::NAN;
        assert_eq!(
            simplify(&nan, &SimplifyOptions::to_triangles(4)).unwrap_err(),
            SimplifyError::NonFinite(3)
        );
        // Asking for more triangles than there are changes nothing.
        let same = simplify(&mesh, &SimplifyOptions::to_triangles(10_000)).unwrap();
        assert_eq!(same.collapses, 0);
        assert_eq!(same.mesh.triangles.len(), mesh.triangles.len());
    }
}
