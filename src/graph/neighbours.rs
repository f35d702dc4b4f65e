//! Neighbourhood queries over 3D points: the one k-d tree (kiddo) behind the kNN graph of seed
//! 004 §5.1, the local shape of each point (PCA of its nearest neighbours, [`super::local_shape`]),
//! the skeleton's graph and gap joins, the floor RANSAC and the evaluation's nearest surface
//! samples.
//!
//! Results are nearest first, with squared distances, in kiddo's order for equally near
//! points; the stages depend on that order, so every query goes through here.

use std::num::NonZero;

use kiddo::kd_tree::ConstructionError;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;

/// A point found near a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    /// Index of the point in the points the [`Neighbours`] were built from.
    pub index: usize,
    /// Squared distance to the query.
    pub distance_squared: f64,
}

impl Neighbour {
    /// Distance to the query.
    pub fn distance(&self) -> f64 {
        self.distance_squared.sqrt()
    }
}

/// A k-d tree over points (one frame, f64 coordinates) answering nearest-neighbour queries.
pub struct Neighbours {
    tree: ImmutableKdTree<f64, 3>,
    coordinates: Vec<[f64; 3]>,
}

impl Neighbours {
    /// The tree over `points`; neighbours are reported by their index in this sequence.
    pub fn new(points: impl IntoIterator<Item = Point3<f64>>) -> Result<Self, ConstructionError> {
        let coordinates: Vec<[f64; 3]> = points.into_iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&coordinates)?;
        Ok(Self { tree, coordinates })
    }

    /// Number of points in the tree.
    pub fn len(&self) -> usize {
        self.coordinates.len()
    }

    pub fn is_empty(&self) -> bool {
        self.coordinates.is_empty()
    }

    /// The tree's point `i`.
    pub fn point(&self, i: usize) -> Point3<f64> {
        Point3::from(self.coordinates[i])
    }

    /// The `k` nearest points to `query`, nearest first (fewer when the tree holds fewer).
    pub fn nearest_k(&self, query: &Point3<f64>, k: NonZero<usize>) -> Vec<Neighbour> {
        self.nearest_k_to(&[query.x, query.y, query.z], k)
    }

    /// The nearest point to `query`: the first of [`Neighbours::nearest_k`] with `k` = 1.
    /// `None` for an empty tree.
    pub fn nearest(&self, query: &Point3<f64>) -> Option<Neighbour> {
        self.nearest_k(query, NonZero::<usize>::MIN)
            .first()
            .copied()
    }

    /// The nearest point to `query` by kiddo's single-nearest search: the same distance as
    /// [`Neighbours::nearest`], but among points exactly as near it may return another one.
    /// Meaningless for an empty tree.
    pub fn nearest_one(&self, query: &Point3<f64>) -> Neighbour {
        let found = self
            .tree
            .query(&[query.x, query.y, query.z])
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        Neighbour {
            index: found.item as usize,
            distance_squared: found.distance,
        }
    }

    /// The `k` nearest neighbours of the tree's point `i` and the point itself (so `k + 1`
    /// points, at most all of them), nearest first. Where other points coincide with `i`,
    /// the point itself need not come first.
    pub fn around(&self, i: usize, k: usize) -> Vec<Neighbour> {
        let wanted = NonZero::new((k + 1).min(self.len())).unwrap_or(NonZero::<usize>::MIN);
        self.nearest_k_to(&self.coordinates[i], wanted)
    }

    /// Every point within `radius` of `query`, nearest first.
    pub fn within_radius(&self, query: &Point3<f64>, radius: f64) -> Vec<Neighbour> {
        self.within(query, radius, true)
    }

    /// The points within `radius` of `query` (inclusive), in no particular order: the same
    /// set as [`Neighbours::within_radius`] without the cost of sorting it.
    pub fn within_radius_unsorted(&self, query: &Point3<f64>, radius: f64) -> Vec<Neighbour> {
        self.within(query, radius, false)
    }

    /// How many points lie within `radius` of `query` (inclusive), and how many of them
    /// `counted` holds (by index): the counts of [`Neighbours::within_radius_unsorted`] without
    /// building its list.
    pub fn count_within(
        &self,
        query: &Point3<f64>,
        radius: f64,
        counted: impl Fn(usize) -> bool,
    ) -> (usize, usize) {
        if self.is_empty() || radius.is_nan() || radius < 0.0 {
            return (0, 0);
        }
        let (mut total, mut held) = (0, 0);
        self.tree
            .query(&[query.x, query.y, query.z])
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .unsorted()
            .visit(|found| {
                total += 1;
                if counted(found.item as usize) {
                    held += 1;
                }
            });
        (total, held)
    }

    fn within(&self, query: &Point3<f64>, radius: f64, sorted: bool) -> Vec<Neighbour> {
        if self.is_empty() || radius.is_nan() || radius < 0.0 {
            return Vec::new();
        }
        let at = [query.x, query.y, query.z];
        let search = self
            .tree
            .query(&at)
            .within::<SquaredEuclidean<f64>>(radius * radius);
        let found = if sorted {
            search.execute()
        } else {
            search.unsorted().execute()
        };
        found
            .into_iter()
            .map(|found| Neighbour {
                index: found.item as usize,
                distance_squared: found.distance,
            })
            .collect()
    }

    fn nearest_k_to(&self, query: &[f64; 3], k: NonZero<usize>) -> Vec<Neighbour> {
        self.tree
            .query(query)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|found| Neighbour {
                index: found.item as usize,
                distance_squared: found.distance,
            })
            .collect()
    }
}

/// The points' indices in Morton (Z-curve) order over their bounding box (ties by index): a
/// run of queries taken in this order visits the same parts of a tree one after the other,
/// which keeps them in cache.
pub fn spatial_order(points: &[Point3<f64>]) -> Vec<usize> {
    const BITS: u32 = 21;
    let finite = |p: &&Point3<f64>| p.iter().all(|c| c.is_finite());
    let (mut low, mut high) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in points.iter().filter(finite) {
        for axis in 0..3 {
            low[axis] = low[axis].min(p[axis]);
            high[axis] = high[axis].max(p[axis]);
        }
    }
    let cells = f64::from(1u32 << BITS);
    let cell = |p: &Point3<f64>, axis: usize| -> u64 {
        let extent = high[axis] - low[axis];
        if extent <= 0.0 || !extent.is_finite() || !p[axis].is_finite() {
            return 0;
        }
        ((p[axis] - low[axis]) / extent * cells).clamp(0.0, cells - 1.0) as u64
    };
    let spread = |mut v: u64| -> u64 {
        // Bit k of v moves to bit 3k.
        v &= 0x1f_ffff;
        v = (v | (v << 32)) & 0x001f_0000_0000_ffff;
        v = (v | (v << 16)) & 0x001f_0000_ff00_00ff;
        v = (v | (v << 8)) & 0x100f_00f0_0f00_f00f;
        v = (v | (v << 4)) & 0x10c3_0c30_c30c_30c3;
        v = (v | (v << 2)) & 0x1249_2492_4924_9249;
        v
    };
    let mut keyed: Vec<(u64, usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let code = spread(cell(p, 0)) | (spread(cell(p, 1)) << 1) | (spread(cell(p, 2)) << 2);
            (code, i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_force(points: &[Point3<f64>], query: &Point3<f64>) -> Vec<f64> {
        let mut distances: Vec<f64> = points.iter().map(|p| (p - query).norm_squared()).collect();
        distances.sort_by(f64::total_cmp);
        distances
    }

    #[test]
    fn nearest_k_matches_a_brute_force_search() {
        let points: Vec<Point3<f64>> = (0..500)
            .map(|i| {
                let t = i as f64;
                Point3::new((t * 0.37).sin(), (t * 0.11).cos(), (t * 0.05).sin() * 0.5)
            })
            .collect();
        let neighbours = Neighbours::new(points.iter().copied()).unwrap();
        assert_eq!(neighbours.len(), points.len());
        let query = Point3::new(0.1, -0.2, 0.05);
        let expected = brute_force(&points, &query);
        let found = neighbours.nearest_k(&query, NonZero::new(12).unwrap());
        assert_eq!(found.len(), 12);
        for (f, e) in found.iter().zip(&expected) {
            assert_eq!(f.distance_squared, *e);
            assert_eq!((points[f.index] - query).norm_squared(), *e);
        }
        let nearest = neighbours.nearest(&query).unwrap();
        assert_eq!(nearest.distance_squared, expected[0]);
        assert_eq!(neighbours.nearest_one(&query).distance_squared, expected[0]);
        assert_eq!(nearest.distance(), expected[0].sqrt());
        // Around a point of the set: the point itself (distance 0) and its k neighbours.
        let around = neighbours.around(7, 5);
        assert_eq!(around.len(), 6);
        assert_eq!(around[0].index, 7);
        assert_eq!(around[0].distance_squared, 0.0);
        assert_eq!(
            around
                .iter()
                .map(|n| n.distance_squared)
                .collect::<Vec<_>>(),
            brute_force(&points, &points[7])[..6]
        );
        // Never more than the tree holds.
        assert_eq!(neighbours.around(0, 10_000).len(), points.len());
        // A radius query finds exactly the points within the radius, nearest first.
        let radius = 0.6;
        let inside: Vec<f64> = expected
            .iter()
            .copied()
            .filter(|d| *d <= radius * radius)
            .collect();
        assert!(inside.len() > 5 && inside.len() < points.len());
        let found = neighbours.within_radius(&query, radius);
        assert_eq!(
            found.iter().map(|n| n.distance_squared).collect::<Vec<_>>(),
            inside
        );
        assert!(neighbours.within_radius(&query, -1.0).is_empty());
        // Unsorted: the same points.
        let mut unsorted: Vec<usize> = neighbours
            .within_radius_unsorted(&query, radius)
            .iter()
            .map(|n| n.index)
            .collect();
        let mut sorted: Vec<usize> = found.iter().map(|n| n.index).collect();
        unsorted.sort_unstable();
        sorted.sort_unstable();
        assert_eq!(unsorted, sorted);
        assert!(neighbours.within_radius_unsorted(&query, -1.0).is_empty());
        // Counting: the radius query's size, and how many of its points a predicate holds
        // (against the brute-force count of even indices within the radius).
        let even_inside = points
            .iter()
            .enumerate()
            .filter(|(i, p)| i % 2 == 0 && (*p - query).norm_squared() <= radius * radius)
            .count();
        assert!(even_inside > 0 && even_inside < inside.len());
        assert_eq!(
            neighbours.count_within(&query, radius, |i| i % 2 == 0),
            (inside.len(), even_inside)
        );
        assert_eq!(neighbours.count_within(&query, -1.0, |_| true), (0, 0));
    }

    #[test]
    fn spatial_order_is_a_permutation_that_keeps_neighbours_together() {
        // A 16 × 16 × 16 grid listed with x fastest, and one point at (16, 16, 16) so that
        // the bounding box's side is a power of two: in Morton order each run of 8 grid points
        // is one 2 × 2 × 2 cell, and the far corner comes last.
        let mut points = Vec::new();
        for z in 0..16 {
            for y in 0..16 {
                for x in 0..16 {
                    points.push(Point3::new(f64::from(x), f64::from(y), f64::from(z)));
                }
            }
        }
        points.push(Point3::new(16.0, 16.0, 16.0));
        let order = spatial_order(&points);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..points.len()).collect::<Vec<_>>());
        assert_eq!(order.last(), Some(&4096));
        for cell in order[..4096].chunks(8) {
            let corner = points[cell[0]];
            assert!(corner.iter().all(|c| c % 2.0 == 0.0), "{corner:?}");
            for &i in cell {
                let offset = points[i] - corner;
                assert!(offset.iter().all(|&c| c == 0.0 || c == 1.0), "{offset:?}");
            }
        }
        // Degenerate input: no extent, non-finite coordinates, nothing.
        let flat = vec![Point3::new(1.0, 2.0, 3.0); 3];
        assert_eq!(spatial_order(&flat), vec![0, 1, 2]);
        let odd = vec![Point3::new(f64::NAN, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0)];
        assert_eq!(spatial_order(&odd).len(), 2);
        assert!(spatial_order(&[]).is_empty());
    }
}
