//! Leaf borders given back to their leaves after the segmentation.
//!
//! The stem test of [`super::foreground`] judges each point by how its neighbours' normals
//! agree over 20 neighbours. Near a leaf's rim that neighbourhood reaches off the leaf (onto
//! the twig, the petiole or the next leaf), so the rim of a leaf is called stem, and on a small
//! leaf (30–100 points, where 20 neighbours span half of it) that is a third of its points:
//! measured on semi-dense smallleaf plants, 21–32 % of the true leaf points. Fragments the
//! threshold partition cut off a leaf and nothing took are lost the same way (unassigned).
//!
//! Once the leaves are known, such points are given back: a stem-class or unassigned point
//! joins a leaf when it is reached from the leaf's points in steps of at most
//! [`BorderOptions::link_spacings`] median point spacings, no farther than
//! [`BorderOptions::reach_spacings`] along the way (the width of the rim the stem test eats),
//! and it lies on the leaf's sheet: within [`BorderOptions::max_sigmas`] times the leaf's
//! noise (the points' local plane RMS and the sheet's own fit RMS) of the quadratic height
//! field fitted to the leaf. A twig leaves the leaf's sheet within a spacing or two, so only
//! its first points can join. Nearest leaf first (Dijkstra over the path length), so a point
//! between two leaves goes to the one it is reached from first. The points keep their
//! foreground class: for the skeleton they are still candidates, as a rachis or petiole along
//! a leaf's edge lies on the leaf's sheet too.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::graph::neighbours::Neighbours;
use crate::graph::shape::Sheet;

/// How far a leaf reaches back over its rim.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BorderOptions {
    /// Largest step from a leaf point to a point it takes, in median point spacings.
    pub link_spacings: f64,
    /// Longest path from the leaf's own points, in median point spacings: the stem test's
    /// 20-neighbour ball has a radius of about 2.5 spacings.
    pub reach_spacings: f64,
    /// Largest distance from the leaf's sheet, in multiples of its noise.
    pub max_sigmas: f64,
}

impl Default for BorderOptions {
    fn default() -> Self {
        Self {
            link_spacings: 2.0,
            reach_spacings: 3.0,
            max_sigmas: 3.0,
        }
    }
}

/// A leaf as the border step sees it: its sheet and how far from it its points scatter.
#[derive(Clone, Copy, Debug)]
pub struct LeafSheet {
    pub sheet: Sheet,
    /// The leaf's points' noise: their median local plane RMS (world units).
    pub noise: f64,
}

impl LeafSheet {
    /// Largest distance from the sheet a point of this leaf may have.
    fn tolerance(&self, options: &BorderOptions) -> f64 {
        options.max_sigmas * self.noise.hypot(self.sheet.rms)
    }
}

/// The points whose neighbourhood is a piece of sheet: at least `min_elongation` wide for its
/// length (not a twig's line of points) and at most `max_thickness` thick for its width (not
/// wrapped around a stem). `shapes` are the points' neighbourhood shapes.
pub fn on_sheets(
    shapes: &[crate::graph::local_shape::LocalShape],
    min_elongation: f64,
    max_thickness: f64,
) -> Vec<usize> {
    (0..shapes.len())
        .filter(|&i| shapes[i].elongation >= min_elongation && shapes[i].thickness <= max_thickness)
        .collect()
}

/// The groups of `points` (indices into `positions`) that touch: points within `link` of each
/// other are joined. Returns the groups of at least `min_points`, each sorted, in order of
/// their first point.
pub fn touching_groups(
    positions: &[Point3<f64>],
    points: &[usize],
    link: f64,
    min_points: usize,
) -> Vec<Vec<usize>> {
    let Ok(index) = Neighbours::new(points.iter().map(|&i| positions[i])) else {
        return Vec::new();
    };
    let near: Vec<Vec<usize>> = points
        .par_iter()
        .map(|&i| {
            index
                .within_radius_unsorted(&positions[i], link)
                .into_iter()
                .map(|n| n.index)
                .collect()
        })
        .collect();
    let mut sets = crate::util::union_find::UnionFind::new(points.len());
    for (a, neighbours) in near.iter().enumerate() {
        for &b in neighbours {
            sets.union(a, b);
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for (a, &i) in points.iter().enumerate() {
        groups.entry(sets.find(a)).or_default().push(i);
    }
    let mut out: Vec<Vec<usize>> = groups
        .into_values()
        .filter(|g| g.len() >= min_points)
        .map(|mut g| {
            g.sort_unstable();
            g
        })
        .collect();
    out.sort_by_key(|g| g[0]);
    out
}

/// A point reached from a leaf, ordered nearest first (then by point and leaf, so the result
/// does not depend on the heap's order).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Reach {
    distance: f64,
    point: usize,
    leaf: u32,
}

impl Eq for Reach {}

impl Ord for Reach {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .distance
            .total_cmp(&self.distance)
            .then(other.point.cmp(&self.point))
            .then(other.leaf.cmp(&self.leaf))
    }
}

impl PartialOrd for Reach {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The cells of a cubic grid of side `side` that lie beside (or hold) a given point's cell: a
/// point within `side` of a given point lies in one of them.
struct CellSet {
    side: f64,
    cells: std::collections::HashSet<[i64; 3]>,
}

impl CellSet {
    fn cell(side: f64, point: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|a| (point[a] / side).floor() as i64)
    }

    fn around<'a>(points: impl Iterator<Item = &'a Point3<f64>>, side: f64) -> Self {
        let occupied: std::collections::BTreeSet<[i64; 3]> =
            points.map(|p| Self::cell(side, p)).collect();
        let mut cells = std::collections::HashSet::new();
        for c in occupied {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        cells.insert([c[0] + dx, c[1] + dy, c[2] + dz]);
                    }
                }
            }
        }
        Self { side, cells }
    }

    fn holds(&self, point: &Point3<f64>) -> bool {
        self.cells.contains(&Self::cell(self.side, point))
    }
}

/// The points to give back: `(point, leaf)` pairs, sorted by point. `positions` are all
/// points; `leaf_of` the leaf (index into `leaves`) of each point on one; `candidate` marks
/// the points that may join a leaf (stem class or unassigned); `spacing` is the median point
/// spacing.
pub fn reclaim_borders(
    positions: &[Point3<f64>],
    leaf_of: &[Option<u32>],
    candidate: &[bool],
    leaves: &[LeafSheet],
    spacing: f64,
    options: &BorderOptions,
) -> Vec<(usize, u32)> {
    if spacing.is_nan() || spacing <= 0.0 || leaves.is_empty() {
        return Vec::new();
    }
    let link = options.link_spacings * spacing;
    let reach = options.reach_spacings * spacing;
    // A candidate is claimed along a path from a leaf point no longer than `reach` (its first
    // step no longer than `link`), so it lies within the larger of the two of one: only
    // candidates in a cell of that size (a hair larger, against rounding) beside a leaf
    // point's cell can be claimed, and the search needs only them and the leaves' points.
    let near_leaves = CellSet::around(
        (0..positions.len())
            .filter(|&i| leaf_of[i].is_some())
            .map(|i| &positions[i]),
        link.max(reach) * (1.0 + 1e-6),
    );
    let involved: Vec<usize> = (0..positions.len())
        .filter(|&i| leaf_of[i].is_some() || (candidate[i] && near_leaves.holds(&positions[i])))
        .collect();
    let candidates: Vec<usize> = involved
        .iter()
        .copied()
        .filter(|&i| leaf_of[i].is_none())
        .collect();
    let Ok(index) = Neighbours::new(involved.iter().map(|&i| positions[i])) else {
        return Vec::new();
    };
    let on_sheet = |point: usize, leaf: u32| {
        let sheet = &leaves[leaf as usize];
        sheet.sheet.distance(&positions[point]) <= sheet.tolerance(options)
    };
    // Every candidate's neighbours within a link (involved points, by position in `positions`).
    let links: Vec<Vec<(usize, f64)>> = candidates
        .par_iter()
        .map(|&c| {
            index
                .within_radius_unsorted(&positions[c], link)
                .into_iter()
                .map(|n| (involved[n.index], n.distance()))
                .filter(|&(j, _)| j != c)
                .collect()
        })
        .collect();
    let mut slot_of: Vec<Option<u32>> = vec![None; positions.len()];
    for (k, &c) in candidates.iter().enumerate() {
        slot_of[c] = Some(k as u32);
    }

    // Nearest leaf first (Dijkstra). Each candidate keeps its best offer so far, nearest then
    // lowest leaf, the order in which offers are taken: an offer no better than the one it
    // holds would be taken after it and dropped, so it is never queued.
    let better = |offer: (f64, u32), held: Option<(f64, u32)>| {
        held.is_none_or(|held| {
            offer
                .0
                .total_cmp(&held.0)
                .then(offer.1.cmp(&held.1))
                .is_lt()
        })
    };
    let mut best: Vec<Option<(f64, u32)>> = candidates
        .par_iter()
        .zip(&links)
        .map(|(&c, links)| {
            links.iter().fold(None, |held, &(j, d)| match leaf_of[j] {
                Some(leaf) if better((d, leaf), held) && on_sheet(c, leaf) => Some((d, leaf)),
                _ => held,
            })
        })
        .collect();
    let mut heap: BinaryHeap<Reach> = candidates
        .iter()
        .zip(&best)
        .filter_map(|(&point, offer)| {
            offer.map(|(distance, leaf)| Reach {
                distance,
                point,
                leaf,
            })
        })
        .collect();
    let mut claimed: Vec<Option<u32>> = vec![None; candidates.len()];
    let mut out = Vec::new();
    while let Some(Reach {
        distance,
        point,
        leaf,
    }) = heap.pop()
    {
        let Some(k) = slot_of[point].map(|k| k as usize) else {
            continue;
        };
        if claimed[k].is_some() {
            continue;
        }
        claimed[k] = Some(leaf);
        out.push((point, leaf));
        for &(j, d) in &links[k] {
            let Some(slot) = slot_of[j].map(|k| k as usize) else {
                continue;
            };
            let further = distance + d;
            if claimed[slot].is_none()
                && further <= reach
                && better((further, leaf), best[slot])
                && on_sheet(j, leaf)
            {
                best[slot] = Some((further, leaf));
                heap.push(Reach {
                    distance: further,
                    point: j,
                    leaf,
                });
            }
        }
    }
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::shape::Shape;

    /// A grid sheet `z = curvature · x²` with `step` spacing over `[x0, x1] × [0, width]`.
    fn sheet(x0: f64, x1: f64, width: f64, step: f64, curvature: f64) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        let mut x = x0;
        while x <= x1 + 1e-9 {
            let mut y = 0.0;
            while y <= width + 1e-9 {
                out.push(Point3::new(x, y, curvature * x * x));
                y += step;
            }
            x += step;
        }
        out
    }

    fn leaf_sheet(points: &[Point3<f64>], noise: f64) -> LeafSheet {
        let shape = Shape::of(points.iter().copied());
        LeafSheet {
            sheet: shape.quadratic_sheet(points.iter().copied()).unwrap(),
            noise,
        }
    }

    #[test]
    fn a_rim_called_stem_goes_back_to_its_leaf_and_a_twig_does_not() {
        let step = 0.001;
        // The leaf's kept part, x in [0, 0.02]; its rim, x in (0.02, 0.022], was called stem.
        let kept = sheet(0.0, 0.02, 0.01, step, 2.0);
        let rim: Vec<Point3<f64>> = sheet(0.021, 0.022, 0.01, step, 2.0);
        // Farther along the same sheet, beyond the reach: stays where it is.
        let far: Vec<Point3<f64>> = sheet(0.027, 0.030, 0.01, step, 2.0);
        // A twig leaving the leaf's base at right angles to its sheet.
        let twig: Vec<Point3<f64>> = (1..=15)
            .map(|k| Point3::new(0.0, 0.005, -(k as f64) * step))
            .collect();
        let mut positions = kept.clone();
        positions.extend(&rim);
        positions.extend(&far);
        positions.extend(&twig);
        let n = positions.len();
        let leaf_of: Vec<Option<u32>> = (0..n).map(|i| (i < kept.len()).then_some(0)).collect();
        let candidate: Vec<bool> = (0..n).map(|i| i >= kept.len()).collect();
        let leaves = [leaf_sheet(&kept, 0.0001)];
        let claimed = reclaim_borders(
            &positions,
            &leaf_of,
            &candidate,
            &leaves,
            step,
            &BorderOptions::default(),
        );
        let rim_range = kept.len()..kept.len() + rim.len();
        let far_range = rim_range.end..rim_range.end + far.len();
        let twig_range = far_range.end..n;
        let count = |range: &std::ops::Range<usize>| {
            claimed.iter().filter(|(p, _)| range.contains(p)).count()
        };
        assert_eq!(count(&rim_range), rim.len(), "the whole rim comes back");
        assert_eq!(count(&far_range), 0, "nothing beyond the reach");
        assert!(
            count(&twig_range) <= 1,
            "{} twig points",
            count(&twig_range)
        );
        assert!(claimed.iter().all(|&(_, leaf)| leaf == 0));
    }

    #[test]
    fn touching_points_form_groups_and_small_groups_are_dropped() {
        let mut positions: Vec<Point3<f64>> = sheet(0.0, 0.01, 0.004, 0.001, 0.0);
        let first = positions.len();
        positions.extend(sheet(0.05, 0.06, 0.004, 0.001, 0.0));
        let second = positions.len();
        positions.extend([Point3::new(0.2, 0.0, 0.0), Point3::new(0.2005, 0.0, 0.0)]);
        let all: Vec<usize> = (0..positions.len()).collect();
        let groups = touching_groups(&positions, &all, 0.0015, 3);
        assert_eq!(groups.len(), 2);
        assert_eq!(groups[0], (0..first).collect::<Vec<_>>());
        assert_eq!(groups[1], (first..second).collect::<Vec<_>>());
        assert!(touching_groups(&positions, &[], 0.0015, 1).is_empty());
    }

    #[test]
    fn a_point_between_two_leaves_goes_to_the_nearer_one() {
        let step = 0.001;
        // Two coplanar leaves side by side with a stem-class strip between them.
        let left = sheet(0.0, 0.01, 0.01, step, 0.0);
        let right = sheet(0.016, 0.026, 0.01, step, 0.0);
        let strip = sheet(0.012, 0.014, 0.01, step, 0.0);
        let mut positions = left.clone();
        positions.extend(&right);
        positions.extend(&strip);
        let n = positions.len();
        let leaf_of: Vec<Option<u32>> = (0..n)
            .map(|i| {
                if i < left.len() {
                    Some(0)
                } else if i < left.len() + right.len() {
                    Some(1)
                } else {
                    None
                }
            })
            .collect();
        let candidate: Vec<bool> = leaf_of.iter().map(Option::is_none).collect();
        let leaves = [leaf_sheet(&left, 0.0001), leaf_sheet(&right, 0.0001)];
        let claimed = reclaim_borders(
            &positions,
            &leaf_of,
            &candidate,
            &leaves,
            step,
            &BorderOptions::default(),
        );
        assert_eq!(claimed.len(), strip.len());
        for (p, leaf) in claimed {
            let x = positions[p].x;
            let expected = if x < 0.013 - 1e-9 {
                0
            } else if x > 0.013 + 1e-9 {
                1
            } else {
                leaf
            };
            assert_eq!(leaf, expected, "x = {x}");
        }
        // Deterministic, and nothing without leaves or spacing.
        assert!(
            reclaim_borders(
                &positions,
                &leaf_of,
                &candidate,
                &[],
                step,
                &BorderOptions::default()
            )
            .is_empty()
        );
        assert!(
            reclaim_borders(
                &positions,
                &leaf_of,
                &candidate,
                &leaves,
                0.0,
                &BorderOptions::default()
            )
            .is_empty()
        );
    }

    /// The search as first written: every candidate and every offer queued, nearest (then
    /// lowest point, then lowest leaf) taken first, with neighbours found by brute force.
    fn reclaim_by_every_offer(
        positions: &[Point3<f64>],
        leaf_of: &[Option<u32>],
        candidate: &[bool],
        leaves: &[LeafSheet],
        spacing: f64,
        options: &BorderOptions,
    ) -> Vec<(usize, u32)> {
        let link = options.link_spacings * spacing;
        let reach = options.reach_spacings * spacing;
        let on_sheet = |point: usize, leaf: u32| {
            let sheet = &leaves[leaf as usize];
            sheet.sheet.distance(&positions[point]) <= sheet.tolerance(options)
        };
        let distance = |a: usize, b: usize| {
            let d = positions[a] - positions[b];
            (d.x * d.x + d.y * d.y + d.z * d.z).sqrt()
        };
        let is_candidate = |i: usize| candidate[i] && leaf_of[i].is_none();
        let links = |c: usize| {
            (0..positions.len())
                .filter(move |&j| {
                    j != c && (candidate[j] || leaf_of[j].is_some()) && distance(c, j) <= link
                })
                .map(move |j| (j, distance(c, j)))
        };
        let mut heap = BinaryHeap::new();
        for c in (0..positions.len()).filter(|&c| is_candidate(c)) {
            for (j, d) in links(c) {
                if let Some(leaf) = leaf_of[j]
                    && on_sheet(c, leaf)
                {
                    heap.push(Reach {
                        distance: d,
                        point: c,
                        leaf,
                    });
                }
            }
        }
        let mut claimed = vec![false; positions.len()];
        let mut out = Vec::new();
        while let Some(Reach {
            distance: reached,
            point,
            leaf,
        }) = heap.pop()
        {
            if claimed[point] {
                continue;
            }
            claimed[point] = true;
            out.push((point, leaf));
            for (j, d) in links(point) {
                if is_candidate(j) && !claimed[j] && reached + d <= reach && on_sheet(j, leaf) {
                    heap.push(Reach {
                        distance: reached + d,
                        point: j,
                        leaf,
                    });
                }
            }
        }
        out.sort_unstable();
        out
    }

    #[test]
    fn the_search_gives_what_queueing_every_offer_everywhere_gives() {
        // Noisy tilted leaves at several heights, their rims and a scatter of stem points and
        // other points over and between them; the pruned search (candidates near a leaf only,
        // each candidate's best offer only) must claim exactly what the plain one claims.
        let mut rng = crate::util::rng::Rng::seed_from(5);
        let step = 0.001;
        for trial in 0..12 {
            let mut positions = Vec::new();
            let mut leaf_of = Vec::new();
            let mut candidate = Vec::new();
            let mut leaves = Vec::new();
            for leaf in 0..3u32 {
                let (x0, z0) = (
                    0.012 * leaf as f64,
                    0.002 * (trial % 4) as f64 * leaf as f64,
                );
                let tilt = 0.3 * (rng.uniform() - 0.5);
                let mut kept = Vec::new();
                for k in 0..260 {
                    let (u, v) = (rng.uniform() * 0.014, rng.uniform() * 0.01);
                    let p = Point3::new(x0 + u, v, z0 + tilt * u + 3.0 * u * u)
                        + 0.0002 * nalgebra::Vector3::new(0.0, 0.0, rng.normal());
                    positions.push(p);
                    // Some of each leaf's points, most on its far side, were called stem.
                    let rim = u > 0.011 || k % 9 == 0;
                    leaf_of.push((!rim).then_some(leaf));
                    candidate.push(rim);
                    if !rim {
                        kept.push(p);
                    }
                }
                leaves.push(leaf_sheet(&kept, 0.0002));
            }
            for k in 0..300 {
                positions.push(Point3::new(
                    rng.uniform() * 0.05 - 0.005,
                    rng.uniform() * 0.015 - 0.0025,
                    rng.uniform() * 0.02 - 0.005,
                ));
                leaf_of.push(None);
                candidate.push(k % 5 != 0);
            }
            let options = BorderOptions {
                link_spacings: 1.5 + 0.25 * (trial % 3) as f64,
                reach_spacings: 2.0 + 0.5 * (trial % 5) as f64,
                max_sigmas: 3.0,
            };
            let claimed =
                reclaim_borders(&positions, &leaf_of, &candidate, &leaves, step, &options);
            let plain =
                reclaim_by_every_offer(&positions, &leaf_of, &candidate, &leaves, step, &options);
            assert!(
                claimed.len() > 20,
                "trial {trial}: {} claimed",
                claimed.len()
            );
            assert_eq!(claimed, plain, "trial {trial}");
        }
    }
}
