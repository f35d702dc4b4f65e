//! Tubes as generalized cylinders, recovered from meshes alone (a glb's branch nodes, a scene
//! master's merged wood): each tube's axis and radius from geodesic level sets, and the tree
//! they form (which tube grows from which, base to tip, branching order).

use std::collections::BinaryHeap;

use nalgebra::{Point3, Vector3};

use crate::mesh::TriMesh;

/// Branch orders from parent links: the number of ancestors (a parent missing from the list, or
/// a loop, ends the chain).
pub fn orders(parents: &[Option<usize>]) -> Vec<u32> {
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
    let weld = mesh.weld();
    let index: std::collections::HashMap<(i64, i64, i64), usize> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (weld.key(p), i))
        .collect();
    let mut normals = vec![Vector3::zeros(); points.len()];
    for t in &mesh.triangles {
        let corners = t.map(|v| mesh.positions[v as usize].cast::<f64>());
        let n = (corners[1] - corners[0]).cross(&(corners[2] - corners[0]));
        for c in corners {
            if let Some(&i) = index.get(&weld.key(&c)) {
                normals[i] += n;
            }
        }
    }
    normals
        .into_iter()
        .map(|n| n.try_normalize(1e-300).unwrap_or_else(Vector3::zeros))
        .collect()
}

fn argmax(values: &[f64]) -> Option<usize> {
    values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
}

/// Neighbours of each vertex with the edge length.
type Adjacency = Vec<Vec<(usize, f64)>>;

/// Vertices merged where they coincide (tube seams), and the mesh's edges between them.
fn welded_graph(mesh: &TriMesh) -> (Vec<Point3<f64>>, Adjacency) {
    let weld = mesh.weld();
    let mut index = std::collections::HashMap::new();
    let mut points = Vec::new();
    let remap: Vec<usize> = mesh
        .positions
        .iter()
        .map(|p| {
            let p = p.cast::<f64>();
            let key = weld.key(&p);
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

pub fn distance_to_polyline(p: &Point3<f64>, polyline: &[Point3<f64>]) -> f64 {
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
pub fn branch_tree(
    axes: &mut [(Vec<Point3<f64>>, Vec<f64>)],
    up: &Vector3<f64>,
) -> Vec<Option<usize>> {
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
}
