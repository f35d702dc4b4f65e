//! Side branches the automatic skeleton drew along a leaf's rim: from photos the skeleton's
//! points hold, besides stems and petioles, the edges of leaves that their segments left out,
//! and the skeleton follows them like any other points. A branch is such a rim when nearly all
//! of its axis lies within its radius plus a few point spacings of one and the same leaf's
//! sheet: a petiole meets its leaf at one end, a stem passes many leaves, a rim follows one.
//!
//! Only branches that end the tree are removed (a branch carrying others is kept, whatever its
//! points), and removal is repeated while it uncovers new ends, so a rim that the skeleton
//! split in two goes as a whole.

use std::collections::{HashMap, HashSet};

use nalgebra::Point3;
use serde::Serialize;

use super::BranchTree;
use crate::graph::neighbours::Neighbours;

/// When a side branch is a leaf's rim (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RimTest {
    /// A branch with at least this share of its axis near one leaf runs along its rim.
    pub min_leaf_share: f64,
    /// Near a leaf: within the branch's radius plus this many point spacings of its sheet.
    pub reach_spacings: f64,
}

impl Default for RimTest {
    fn default() -> Self {
        Self {
            min_leaf_share: 0.9,
            reach_spacings: 3.0,
        }
    }
}

/// Leaf sheets to measure branches against: their points and the leaf (segment) of each.
pub struct LeafSheets<'a> {
    pub points: &'a Neighbours,
    pub leaf_of_point: &'a [u32],
}

/// For each branch of `tree`, in its order, the largest share of its axis samples (about one
/// per `spacing`, the skeleton points' median spacing) near one leaf's sheet.
pub fn one_leaf_shares(
    tree: &BranchTree,
    leaves: &LeafSheets,
    spacing: f64,
    test: &RimTest,
) -> Vec<f64> {
    tree.branches
        .iter()
        .map(|branch| {
            let cylinder = &branch.cylinder;
            let count =
                ((cylinder.skeleton.length() / spacing.max(1e-12)).ceil() as usize).clamp(8, 4096);
            let samples = cylinder.skeleton.sample_by_arc_length(count);
            let last = (samples.len().max(2) - 1) as f64;
            let mut near: HashMap<u32, usize> = HashMap::new();
            for (k, (point, _)) in samples.iter().enumerate() {
                let reach = cylinder.radius_at(k as f64 / last) + test.reach_spacings * spacing;
                if let Some(found) = leaves.points.nearest(point)
                    && found.distance() <= reach
                    && let Some(&leaf) = leaves.leaf_of_point.get(found.index)
                {
                    *near.entry(leaf).or_default() += 1;
                }
            }
            near.values().copied().max().unwrap_or(0) as f64 / samples.len().max(1) as f64
        })
        .collect()
}

/// Removes the side branches that run along one leaf's rim (`shares` from
/// [`one_leaf_shares`], in the tree's order) and end the tree, repeatedly (see the module
/// docs). Root branches are never removed. Returns how many branches were removed.
pub fn prune_rims(tree: &mut BranchTree, shares: &[f64], test: &RimTest) -> usize {
    let rims: HashSet<u32> = tree
        .branches
        .iter()
        .zip(shares)
        .filter(|(branch, share)| branch.parent.is_some() && **share >= test.min_leaf_share)
        .map(|(branch, _)| branch.id)
        .collect();
    let mut removed = 0;
    loop {
        let parents: HashSet<u32> = tree.branches.iter().filter_map(|b| b.parent).collect();
        let before = tree.branches.len();
        tree.branches
            .retain(|b| parents.contains(&b.id) || !rims.contains(&b.id));
        let gone = before - tree.branches.len();
        if gone == 0 {
            return removed;
        }
        removed += gone;
    }
}

/// The rims of leaves among `tree`'s side branches, removed ([`one_leaf_shares`],
/// [`prune_rims`]); `sheets` are the points of leaf sheets with their leaves. Returns how many
/// branches were removed.
pub fn remove_leaf_rims(
    tree: &mut BranchTree,
    sheets: &[(Point3<f64>, u32)],
    spacing: f64,
    test: &RimTest,
) -> usize {
    let Ok(points) = Neighbours::new(sheets.iter().map(|(p, _)| *p)) else {
        return 0;
    };
    if points.is_empty() {
        return 0;
    }
    let leaf_of_point: Vec<u32> = sheets.iter().map(|(_, leaf)| *leaf).collect();
    let leaves = LeafSheets {
        points: &points,
        leaf_of_point: &leaf_of_point,
    };
    let shares = one_leaf_shares(tree, &leaves, spacing, test);
    prune_rims(tree, &shares, test)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::branch::{Branch, GeneralizedCylinder, Spline};

    const SPACING: f64 = 0.001;

    fn branch(id: u32, parent: Option<u32>, a: [f64; 3], b: [f64; 3], radius: f64) -> Branch {
        let (a, b) = (Point3::from(a), Point3::from(b));
        Branch {
            id,
            parent,
            parent_fraction: 1.0,
            cylinder: GeneralizedCylinder::new(Spline::new(vec![a, b]).unwrap(), radius, radius),
            leaf_at_tip: false,
        }
    }

    /// A flat leaf over x0..x1 × y0..y1 at height z, points a spacing apart.
    fn leaf(x: (f64, f64), y: (f64, f64), z: f64, id: u32) -> Vec<(Point3<f64>, u32)> {
        let (nx, ny) = (
            ((x.1 - x.0) / SPACING) as usize,
            ((y.1 - y.0) / SPACING) as usize,
        );
        (0..=nx)
            .flat_map(|i| (0..=ny).map(move |j| (i, j)))
            .map(|(i, j)| {
                let p = Point3::new(x.0 + i as f64 * SPACING, y.0 + j as f64 * SPACING, z);
                (p, id)
            })
            .collect()
    }

    #[test]
    fn a_rim_along_one_leaf_is_pruned_and_a_petiole_or_a_stem_among_leaves_is_not() {
        // Stem 0 rises past leaves 10 and 11 (on either side, one after the other); petiole 1
        // ends at leaf 12's base; rim 2 follows leaf 12's edge; rim 3 follows leaf 13's edge
        // and carries the twig 4.
        let tree = BranchTree {
            branches: vec![
                branch(0, None, [0.0, 0.0, 0.0], [0.0, 0.0, 0.1], 0.004),
                branch(1, Some(0), [0.0, 0.0, 0.1], [0.1, 0.0, 0.15], 0.003),
                branch(2, Some(1), [0.1, 0.033, 0.15], [0.2, 0.033, 0.15], 0.002),
                branch(3, Some(0), [0.0, -0.033, 0.05], [-0.1, -0.033, 0.05], 0.002),
                branch(4, Some(3), [-0.1, -0.033, 0.05], [-0.1, -0.033, 0.1], 0.002),
            ],
        };
        // Leaves 10 and 11 stand upright beside the stem, one above the other.
        let upright = |x: (f64, f64), z: (f64, f64), id: u32| -> Vec<(Point3<f64>, u32)> {
            leaf(x, z, 0.0, id)
                .into_iter()
                .map(|(p, id)| (Point3::new(p.x, 0.0, p.y), id))
                .collect()
        };
        let mut sheets = upright((0.005, 0.05), (0.0, 0.05), 10);
        sheets.extend(upright((-0.05, -0.005), (0.05, 0.1), 11));
        sheets.extend(leaf((0.1, 0.2), (-0.03, 0.03), 0.15, 12));
        sheets.extend(leaf((-0.1, -0.003), (-0.03, 0.03), 0.05, 13));
        let points = Neighbours::new(sheets.iter().map(|(p, _)| *p)).unwrap();
        let leaf_of_point: Vec<u32> = sheets.iter().map(|(_, id)| *id).collect();
        let leaves = LeafSheets {
            points: &points,
            leaf_of_point: &leaf_of_point,
        };
        let test = RimTest::default();
        let shares = one_leaf_shares(&tree, &leaves, SPACING, &test);
        // The stem is near some leaf all along, but near each one along about half of it.
        assert!(shares[0] > 0.4 && shares[0] < 0.7, "{shares:?}");
        assert!(shares[1] < 0.2, "{shares:?}");
        assert!(shares[2] > 0.95 && shares[3] > 0.95, "{shares:?}");

        let mut pruned = tree.clone();
        assert_eq!(remove_leaf_rims(&mut pruned, &sheets, SPACING, &test), 1);
        let kept: Vec<u32> = pruned.branches.iter().map(|b| b.id).collect();
        assert_eq!(kept, vec![0, 1, 3, 4]);

        // A twig that is a rim too goes, and then the rim it hung from.
        let mut all = shares.clone();
        all[4] = 1.0;
        let mut pruned = tree.clone();
        assert_eq!(prune_rims(&mut pruned, &all, &test), 3);
        assert_eq!(
            pruned.branches.iter().map(|b| b.id).collect::<Vec<_>>(),
            vec![0, 1]
        );
        // The stem is never removed, and no sheets remove nothing.
        let mut stem = tree.clone();
        assert_eq!(prune_rims(&mut stem, &[1.0; 5], &test), 4);
        assert_eq!(stem.branches.len(), 1);
        assert_eq!(remove_leaf_rims(&mut tree.clone(), &[], SPACING, &test), 0);
    }
}
