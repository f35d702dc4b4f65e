//! Convex hulls for plant traits: the volume of a 3D point set's convex hull (incremental
//! hull, Clarkson–Shor style with a horizon walk) and the diameter of a 2D point set.

use nalgebra::{Point2, Point3, Vector3};

/// A hull face: three point indices, counter-clockwise seen from outside.
#[derive(Clone, Copy)]
struct Face {
    v: [usize; 3],
    normal: Vector3<f64>,
    offset: f64,
    alive: bool,
}

/// A face through three points. A degenerate face (collinear points) keeps a zero normal:
/// it is never seen from a point, and it closes the surface without enclosing anything.
fn face(points: &[Point3<f64>], v: [usize; 3]) -> Face {
    let normal = (points[v[1]] - points[v[0]])
        .cross(&(points[v[2]] - points[v[0]]))
        .try_normalize(1e-300)
        .unwrap_or_else(Vector3::zeros);
    Face {
        v,
        normal,
        offset: normal.dot(&points[v[0]].coords),
        alive: true,
    }
}

/// The volume of the convex hull of `points` (0 when they are fewer than four or flat).
/// `O(n·h)`: callers pass a few thousand points at most.
pub fn hull_volume(points: &[Point3<f64>]) -> f64 {
    // Exact duplicates (shared mesh vertices) would only add degenerate faces.
    let mut unique: Vec<Point3<f64>> = points
        .iter()
        .filter(|p| p.coords.iter().all(|c| c.is_finite()))
        .copied()
        .collect();
    unique.sort_by(|a, b| {
        a.x.total_cmp(&b.x)
            .then(a.y.total_cmp(&b.y))
            .then(a.z.total_cmp(&b.z))
    });
    unique.dedup();
    // Leaf meshes are planar patches: coplanar points make the visible region of a new point
    // ambiguous. Each point is moved by at most 1e-7 of the bounding diagonal, by a hash of
    // its coordinates (so the result does not depend on the order of the points), which puts
    // them in general position at a volume error far below any measurement's.
    if initial_tetrahedron(&unique).is_none() {
        return 0.0;
    }
    let scale = bounding_diagonal(&unique);
    let jittered: Vec<Point3<f64>> = unique
        .iter()
        .map(|p| {
            let mut rng = crate::util::rng::Rng::seed_from(
                p.x.to_bits() ^ p.y.to_bits().rotate_left(21) ^ p.z.to_bits().rotate_left(42),
            );
            let mut offset = [0.0; 3];
            for o in &mut offset {
                *o = (rng.uniform() - 0.5) * 2e-7 * scale;
            }
            p + Vector3::from(offset)
        })
        .collect();
    let points = jittered.as_slice();
    let Some(start) = initial_tetrahedron(points) else {
        return 0.0;
    };
    let eps = 1e-13 * scale.max(f64::MIN_POSITIVE);
    let interior = Point3::from(
        start
            .iter()
            .map(|&i| points[i].coords)
            .sum::<Vector3<f64>>()
            / 4.0,
    );
    let mut faces: Vec<Face> = Vec::new();
    let [a, b, c, d] = start;
    for v in [[a, b, c], [a, b, d], [a, c, d], [b, c, d]] {
        let mut f = face(points, v);
        if f.normal.dot(&interior.coords) - f.offset > 0.0 {
            f = face(points, [v[0], v[2], v[1]]);
        }
        faces.push(f);
    }
    for (p, point) in points.iter().enumerate() {
        if start.contains(&p) {
            continue;
        }
        let visible: Vec<usize> = faces
            .iter()
            .enumerate()
            .filter(|(_, f)| f.alive && f.normal.dot(&point.coords) - f.offset > eps)
            .map(|(k, _)| k)
            .collect();
        if visible.is_empty() {
            continue;
        }
        // Horizon: directed edges of visible faces whose reverse is not on a visible face.
        let mut edges = std::collections::BTreeSet::new();
        for &k in &visible {
            let v = faces[k].v;
            for e in 0..3 {
                edges.insert((v[e], v[(e + 1) % 3]));
            }
        }
        let horizon: Vec<(usize, usize)> = edges
            .iter()
            .filter(|(x, y)| !edges.contains(&(*y, *x)))
            .copied()
            .collect();
        for &k in &visible {
            faces[k].alive = false;
        }
        for (x, y) in horizon {
            faces.push(face(points, [x, y, p]));
        }
        if faces.len() > 64 && faces.iter().filter(|f| f.alive).count() * 2 < faces.len() {
            faces.retain(|f| f.alive);
        }
    }
    faces
        .iter()
        .filter(|f| f.alive)
        .map(|f| {
            let [p0, p1, p2] = f.v.map(|i| points[i] - interior);
            p0.dot(&p1.cross(&p2)) / 6.0
        })
        .sum::<f64>()
        .abs()
}

fn bounding_diagonal(points: &[Point3<f64>]) -> f64 {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    (hi - lo).norm()
}

/// Four points spanning a tetrahedron of non-negligible volume, if any.
fn initial_tetrahedron(points: &[Point3<f64>]) -> Option<[usize; 4]> {
    if points.len() < 4 {
        return None;
    }
    let scale = bounding_diagonal(points);
    if !positive(scale) || !scale.is_finite() {
        return None;
    }
    let a = 0;
    let b = (0..points.len()).max_by(|&i, &j| {
        let di = (points[i] - points[a]).norm();
        let dj = (points[j] - points[a]).norm();
        di.total_cmp(&dj)
    })?;
    let ab = points[b] - points[a];
    let c = (0..points.len()).max_by(|&i, &j| {
        let di = ab.cross(&(points[i] - points[a])).norm();
        let dj = ab.cross(&(points[j] - points[a])).norm();
        di.total_cmp(&dj)
    })?;
    let n = ab.cross(&(points[c] - points[a]));
    if n.norm() <= 1e-12 * scale * scale {
        return None;
    }
    let d = (0..points.len()).max_by(|&i, &j| {
        let di = n.dot(&(points[i] - points[a])).abs();
        let dj = n.dot(&(points[j] - points[a])).abs();
        di.total_cmp(&dj)
    })?;
    // Flatter than a millionth of the size (well above the jitter below) counts as flat.
    if n.dot(&(points[d] - points[a])).abs() <= 1e-6 * scale * scale * scale {
        return None;
    }
    Some([a, b, c, d])
}

/// The largest distance between two of `points` (0 for fewer than two): the 2D convex hull
/// (monotone chain), then every pair of hull vertices.
pub fn diameter_2d(points: &[Point2<f64>]) -> f64 {
    let hull = hull_2d(points);
    let mut best = 0.0f64;
    for (i, p) in hull.iter().enumerate() {
        for q in &hull[i + 1..] {
            best = best.max((q - p).norm());
        }
    }
    best
}

/// The convex hull of 2D points, counter-clockwise (Andrew's monotone chain).
pub fn hull_2d(points: &[Point2<f64>]) -> Vec<Point2<f64>> {
    let mut sorted: Vec<Point2<f64>> = points
        .iter()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .copied()
        .collect();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return sorted;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * sorted.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Point2<f64>>> = if pass == 0 {
            Box::new(sorted.iter())
        } else {
            Box::new(sorted.iter().rev())
        };
        for p in iter {
            while hull.len() >= start + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(*p);
        }
        hull.pop();
    }
    hull
}

/// `true` for a positive number (not NaN).
fn positive(x: f64) -> bool {
    x > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn the_hull_of_a_cube_with_inner_points_has_the_cube_volume() {
        let mut points = Vec::new();
        for x in [0.0, 2.0] {
            for y in [0.0, 3.0] {
                for z in [0.0, 0.5] {
                    points.push(Point3::new(x, y, z));
                }
            }
        }
        let mut rng = Rng::seed_from(4);
        for _ in 0..500 {
            points.push(Point3::new(
                2.0 * rng.uniform(),
                3.0 * rng.uniform(),
                0.5 * rng.uniform(),
            ));
        }
        // Shuffled, so the extreme points do not come first.
        points.reverse();
        let volume = hull_volume(&points);
        // Within the general-position jitter (1e-7 of the size).
        assert!((volume - 3.0).abs() < 1e-5, "{volume}");
    }

    #[test]
    fn the_hull_of_points_on_a_sphere_approaches_the_ball() {
        let mut rng = Rng::seed_from(9);
        let points: Vec<Point3<f64>> = (0..3000)
            .map(|_| {
                let v = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                Point3::from(v * 2.0 + Vector3::new(5.0, -1.0, 3.0))
            })
            .collect();
        let ball = 4.0 / 3.0 * std::f64::consts::PI * 8.0;
        let volume = hull_volume(&points);
        // An inscribed polytope: slightly smaller than the ball, never larger.
        assert!(volume < ball && volume > 0.97 * ball, "{volume} vs {ball}");
    }

    /// Planar patches with shared (duplicate) vertices, as leaf meshes give: the volume does
    /// not depend on the order of the points and stays inside the bounding box.
    #[test]
    fn coplanar_patches_and_duplicates_give_an_order_independent_volume() {
        let mut rng = Rng::seed_from(11);
        for round in 0..20 {
            let mut points = Vec::new();
            for _ in 0..8 {
                let origin = Vector3::new(rng.normal(), rng.normal(), rng.normal());
                let u = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                let v = u
                    .cross(&Vector3::new(rng.normal(), rng.normal(), rng.normal()))
                    .normalize();
                for i in 0..=10 {
                    for j in 0..=6 {
                        let p = origin + u * (0.05 * i as f64) + v * (0.03 * j as f64);
                        points.push(Point3::from(p.map(|c| c as f32 as f64)));
                        if (i + j) % 3 == 0 {
                            points.push(points[points.len() - 1]);
                        }
                    }
                }
            }
            let volume = hull_volume(&points);
            // Bit for bit the same on every call (batch outputs are compared byte for byte).
            assert_eq!(hull_volume(&points).to_bits(), volume.to_bits());
            let mut lo = Vector3::repeat(f64::INFINITY);
            let mut hi = Vector3::repeat(f64::NEG_INFINITY);
            for p in &points {
                lo = lo.inf(&p.coords);
                hi = hi.sup(&p.coords);
            }
            let bbox = (hi - lo).product();
            assert!(
                volume > 0.0 && volume <= bbox,
                "round {round}: {volume} vs box {bbox}"
            );
            let mut shuffled = points.clone();
            rng.shuffle(&mut shuffled);
            let again = hull_volume(&shuffled);
            assert!(
                (again - volume).abs() <= 1e-9 * bbox,
                "round {round}: {again} vs {volume}"
            );
        }
    }

    #[test]
    fn flat_or_too_few_points_have_no_volume() {
        let flat: Vec<Point3<f64>> = (0..20)
            .map(|k| Point3::new(k as f64, (k * k % 7) as f64, 1.0))
            .collect();
        assert_eq!(hull_volume(&flat), 0.0);
        assert_eq!(hull_volume(&flat[..3]), 0.0);
    }

    #[test]
    fn the_diameter_of_a_square_is_its_diagonal() {
        let mut points = vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ];
        points.push(Point2::new(0.5, 0.5));
        points.push(Point2::new(0.2, 0.9));
        assert!((diameter_2d(&points) - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(hull_2d(&points).len(), 4);
        assert_eq!(diameter_2d(&points[..1]), 0.0);
    }
}
