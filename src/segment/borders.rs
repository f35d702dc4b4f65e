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
    // The points that matter: leaves and candidates.
    let involved: Vec<usize> = (0..positions.len())
        .filter(|&i| candidate[i] || leaf_of[i].is_some())
        .collect();
    let Ok(index) = Neighbours::new(involved.iter().map(|&i| positions[i])) else {
        return Vec::new();
    };
    let link = options.link_spacings * spacing;
    let reach = options.reach_spacings * spacing;
    let on_sheet = |point: usize, leaf: u32| {
        let sheet = &leaves[leaf as usize];
        sheet.sheet.distance(&positions[point]) <= sheet.tolerance(options)
    };
    // Every candidate's neighbours within a link (involved points, by position in `positions`).
    let candidates: Vec<usize> = involved
        .iter()
        .copied()
        .filter(|&i| candidate[i] && leaf_of[i].is_none())
        .collect();
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
    let slot_of: std::collections::HashMap<usize, usize> = candidates
        .iter()
        .enumerate()
        .map(|(k, &c)| (c, k))
        .collect();

    let mut heap = BinaryHeap::new();
    for (k, &c) in candidates.iter().enumerate() {
        for &(j, d) in &links[k] {
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
    let mut claimed: Vec<Option<u32>> = vec![None; candidates.len()];
    let mut out = Vec::new();
    while let Some(Reach {
        distance,
        point,
        leaf,
    }) = heap.pop()
    {
        let k = slot_of[&point];
        if claimed[k].is_some() {
            continue;
        }
        claimed[k] = Some(leaf);
        out.push((point, leaf));
        for &(j, d) in &links[k] {
            let Some(&slot) = slot_of.get(&j) else {
                continue;
            };
            let further = distance + d;
            if claimed[slot].is_none() && further <= reach && on_sheet(j, leaf) {
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
}
