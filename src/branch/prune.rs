//! Side branches the automatic skeleton drew along a leaf's rim: from photos the skeleton's
//! points hold, besides stems and petioles, the edges of leaves that their segments left out,
//! and the skeleton follows them like any other points. A branch is such a rim when nearly all
//! of its axis lies within its radius plus a few point spacings of one and the same leaf's
//! sheet: a petiole meets its leaf at one end, a stem passes many leaves, a rim follows one.
//! Where the skeleton bridged a gap to reach the rim (a straight run with no points), the rim
//! is judged by the part of its axis the points support: a bridge shows nothing of what the
//! branch is.
//!
//! Side branches the photos show no bar along ([`BarTest`]): where the points say which ones
//! `frond densify`'s thin-organ sweep found, a petiole's points are such points at about the
//! plant's rate, while a leaf's edge or the stereo halo beside a leaf has next to none.
//!
//! Only branches that end the tree are removed (a branch carrying others is kept, whatever its
//! points), and removal is repeated while it uncovers new ends, so a rim that the skeleton
//! split in two goes as a whole.

use std::collections::{HashMap, HashSet};

use nalgebra::Point3;
use serde::Serialize;

use super::{BranchTree, GeneralizedCylinder};
use crate::graph::neighbours::Neighbours;

/// When a side branch is a leaf's rim (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RimTest {
    /// A branch with at least this share of its axis near one leaf runs along its rim.
    pub min_leaf_share: f64,
    /// Near a leaf: within the branch's radius plus this many point spacings of its sheet.
    pub reach_spacings: f64,
    /// Supported by the points: a skeleton point within the branch's radius plus this many
    /// point spacings (as [`crate::branch::plant::plant_branch_support`] measures support).
    pub support_spacings: f64,
}

impl Default for RimTest {
    fn default() -> Self {
        Self {
            min_leaf_share: 0.9,
            reach_spacings: 3.0,
            support_spacings: 2.0,
        }
    }
}

/// Leaf sheets to measure branches against: their points and the leaf (segment) of each.
pub struct LeafSheets<'a> {
    pub points: &'a Neighbours,
    pub leaf_of_point: &'a [u32],
}

/// A branch's axis sampled about once per `spacing` (8 to 4,096 samples): each sample and the
/// branch's radius there.
fn axis_samples(cylinder: &GeneralizedCylinder, spacing: f64) -> Vec<(Point3<f64>, f64)> {
    let count = ((cylinder.skeleton.length() / spacing.max(1e-12)).ceil() as usize).clamp(8, 4096);
    let samples = cylinder.skeleton.sample_by_arc_length(count);
    let last = (samples.len().max(2) - 1) as f64;
    samples
        .iter()
        .enumerate()
        .map(|(k, (point, _))| (*point, cylinder.radius_at(k as f64 / last)))
        .collect()
}

/// Fewest axis samples the points must support before a branch is judged by its supported
/// part alone (see [`one_leaf_shares`]).
const MIN_SUPPORTED_SAMPLES: usize = 8;

/// For each branch of `tree`, in its order, the largest share of its axis samples (about one
/// per `spacing`, the skeleton points' median spacing) near one leaf's sheet. With the
/// skeleton's points (`support`), the larger of that share over the whole axis and over the
/// samples the points support (a skeleton point within the radius plus
/// [`RimTest::support_spacings`]), when at least [`MIN_SUPPORTED_SAMPLES`] are.
pub fn one_leaf_shares(
    tree: &BranchTree,
    leaves: &LeafSheets,
    support: Option<&Neighbours>,
    spacing: f64,
    test: &RimTest,
) -> Vec<f64> {
    tree.branches
        .iter()
        .map(|branch| {
            let samples = axis_samples(&branch.cylinder, spacing);
            let mut near: HashMap<u32, usize> = HashMap::new();
            let mut near_supported: HashMap<u32, usize> = HashMap::new();
            let mut supported = 0usize;
            for (point, radius) in &samples {
                let seen = support.is_some_and(|points| {
                    points.nearest(point).is_some_and(|found| {
                        found.distance() <= radius + test.support_spacings * spacing
                    })
                });
                supported += usize::from(seen);
                let reach = radius + test.reach_spacings * spacing;
                if let Some(found) = leaves.points.nearest(point)
                    && found.distance() <= reach
                    && let Some(&leaf) = leaves.leaf_of_point.get(found.index)
                {
                    *near.entry(leaf).or_default() += 1;
                    if seen {
                        *near_supported.entry(leaf).or_default() += 1;
                    }
                }
            }
            let share = |counts: &HashMap<u32, usize>, of: usize| {
                counts.values().copied().max().unwrap_or(0) as f64 / of.max(1) as f64
            };
            let whole = share(&near, samples.len());
            if supported >= MIN_SUPPORTED_SAMPLES {
                whole.max(share(&near_supported, supported))
            } else {
                whole
            }
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
    prune_ends(tree, &rims)
}

/// Removes the `marked` branches that end the tree, repeatedly while that uncovers marked
/// ends. Returns how many branches were removed.
fn prune_ends(tree: &mut BranchTree, marked: &HashSet<u32>) -> usize {
    let mut removed = 0;
    loop {
        let parents: HashSet<u32> = tree.branches.iter().filter_map(|b| b.parent).collect();
        let before = tree.branches.len();
        tree.branches
            .retain(|b| parents.contains(&b.id) || !marked.contains(&b.id));
        let gone = before - tree.branches.len();
        if gone == 0 {
            return removed;
        }
        removed += gone;
    }
}

/// When a side branch is no organ the photos show as a bar (see the module docs): its points
/// are thin-organ points at well under the plant's rate, and a rate that low is unlikely by
/// chance. From photos of broadleaf seeds 1, 2, 3 and 13 (simulated on their skeletons, then
/// measured; unpruned: petiole recall 0.681, length precision 0.630): 0.15 of the plant's
/// rate removed leaf edges and halo (0.676 and 0.683), where 0.2–0.35 gave 0.668–0.654 and
/// 0.686–0.698.
/// The test is calibrated on the stem: when the longest root branch, plant by construction,
/// fails it too, the sweep does not see this plant's organs as bars (medium plants from
/// photos: 0–3.5 % of the stem's points against 2.4–7.6 % of all branches'), and no branch
/// is removed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BarTest {
    /// A branch whose share of thin-organ points is below this share of the plant's is a
    /// candidate for removal.
    pub max_rate_share: f64,
    /// ... and is removed when so few thin-organ points among its points are less likely
    /// than this (binomial lower tail at the plant's rate).
    pub max_tail_probability: f64,
    /// A branch's points: within its radius plus this many point spacings of its axis.
    pub reach_spacings: f64,
}

impl Default for BarTest {
    fn default() -> Self {
        Self {
            max_rate_share: 0.15,
            max_tail_probability: 1e-3,
            reach_spacings: 1.5,
        }
    }
}

impl BarTest {
    /// Whether a branch with `seen` thin-organ points among `points` shows no bar, on a plant
    /// whose branches' points are thin-organ points at `rate`.
    fn barless(&self, seen: usize, points: usize, rate: f64) -> bool {
        points > 0
            && (seen as f64) < self.max_rate_share * rate * points as f64
            && binomial_lower_tail(seen, points, rate) < self.max_tail_probability
    }
}

/// Probability that a binomial variable with `trials` trials of success rate `rate` is at
/// most `successes` (computed in log space: the terms are tiny for long branches).
fn binomial_lower_tail(successes: usize, trials: usize, rate: f64) -> f64 {
    if successes >= trials || rate <= 0.0 {
        return 1.0;
    }
    if rate >= 1.0 {
        return 0.0;
    }
    let (log_rate, log_miss) = (rate.ln(), (-rate).ln_1p());
    // log C(n, 0) p^0 q^n, then each term from the one before.
    let mut log_term = trials as f64 * log_miss;
    let mut log_terms = vec![log_term];
    for i in 0..successes {
        log_term += ((trials - i) as f64 / (i + 1) as f64).ln() + log_rate - log_miss;
        log_terms.push(log_term);
    }
    let top = log_terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sum: f64 = log_terms.iter().map(|t| (t - top).exp()).sum();
    (top + sum.ln()).exp().min(1.0)
}

/// Removes the side branches that end the tree and that the photos show no bar along
/// ([`BarTest`]): `points` are the skeleton's points and `thin_organ` says which ones the
/// thin-organ sweep found (nothing is removed when it is empty or has no such point);
/// `spacing` is the points' median spacing. Returns how many branches were removed.
pub fn remove_barless_ends(
    tree: &mut BranchTree,
    points: &[Point3<f64>],
    thin_organ: &[bool],
    spacing: f64,
    test: &BarTest,
) -> usize {
    if thin_organ.len() != points.len() || !thin_organ.contains(&true) {
        return 0;
    }
    let Ok(index) = Neighbours::new(points.iter().copied()) else {
        return 0;
    };
    // Each branch's points, and the plant's rate over the points of all branches.
    let near: Vec<HashSet<usize>> = tree
        .branches
        .iter()
        .map(|branch| {
            let mut found = HashSet::new();
            for (point, radius) in axis_samples(&branch.cylinder, spacing) {
                let reach = radius + test.reach_spacings * spacing;
                found.extend(
                    index
                        .within_radius_unsorted(&point, reach)
                        .into_iter()
                        .map(|f| f.index),
                );
            }
            found
        })
        .collect();
    let all: HashSet<usize> = near.iter().flatten().copied().collect();
    if all.is_empty() {
        return 0;
    }
    let rate = all.iter().filter(|&&i| thin_organ[i]).count() as f64 / all.len() as f64;
    let seen = |found: &HashSet<usize>| found.iter().filter(|&&i| thin_organ[i]).count();
    let stem = tree
        .branches
        .iter()
        .zip(&near)
        .filter(|(branch, _)| branch.parent.is_none())
        .max_by(|a, b| {
            let length = |branch: &super::Branch| branch.cylinder.skeleton.length();
            length(a.0).total_cmp(&length(b.0))
        });
    if let Some((_, found)) = stem
        && test.barless(seen(found), found.len(), rate)
    {
        return 0;
    }
    let barless: HashSet<u32> = tree
        .branches
        .iter()
        .zip(&near)
        .filter(|(branch, found)| {
            branch.parent.is_some() && test.barless(seen(found), found.len(), rate)
        })
        .map(|(branch, _)| branch.id)
        .collect();
    prune_ends(tree, &barless)
}

/// The rims of leaves among `tree`'s side branches, removed ([`one_leaf_shares`],
/// [`prune_rims`]); `sheets` are the points of leaf sheets with their leaves,
/// `skeleton_points` the points the skeleton was built from. Returns how many branches were
/// removed.
pub fn remove_leaf_rims(
    tree: &mut BranchTree,
    sheets: &[(Point3<f64>, u32)],
    skeleton_points: &[Point3<f64>],
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
    let support = Neighbours::new(skeleton_points.iter().copied()).ok();
    let shares = one_leaf_shares(tree, &leaves, support.as_ref(), spacing, test);
    prune_rims(tree, &shares, test)
}

/// When a side branch is a twin of a sibling: the stereo halo along a thin organ (a band a few
/// millimetres wide beside a 1 mm fruit) is split by the level sets into two parallel tubes
/// that leave their parent at one place and run side by side, one organ drawn twice. Lengths
/// are in the skeleton's level widths, so the test follows the points' spacing.
/// On the real Arabidopsis (the only plant it was set on) the twins ran 1.1–1.9 level widths
/// apart (median distance of the shorter's axis to the longer's), distinct organs leaving
/// within two level widths of each other 2.4 and more.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TwinTest {
    /// Siblings leaving their parent at most this many level widths apart along it.
    pub max_insertion_levels: f64,
    /// The shorter's axis, where it is farther than this many level widths from the parent's,
    /// lies within this many level widths of the longer's axis ...
    pub reach_levels: f64,
    /// ... along at least this share of those samples.
    pub min_share: f64,
    /// Samples the points show: a skeleton point within the radius plus this many point
    /// spacings (as [`RimTest::support_spacings`]).
    pub support_spacings: f64,
}

impl Default for TwinTest {
    fn default() -> Self {
        Self {
            max_insertion_levels: 2.0,
            reach_levels: 2.0,
            min_share: 0.5,
            support_spacings: 2.0,
        }
    }
}

/// The share of `short`'s samples away from the parent (farther than `reach` from `parent`'s
/// samples) and shown by the points (`supported`) that lie within `reach` of `long`'s samples;
/// `None` when fewer than [`MIN_SUPPORTED_SAMPLES`] samples are both.
fn share_beside(
    short: &[(Point3<f64>, f64)],
    long: &[(Point3<f64>, f64)],
    parent: &[(Point3<f64>, f64)],
    reach: f64,
    supported: impl Fn(&Point3<f64>, f64) -> bool,
) -> Option<f64> {
    let near = |p: &Point3<f64>, axis: &[(Point3<f64>, f64)]| {
        axis.iter()
            .any(|(q, _)| (p - q).norm_squared() <= reach * reach)
    };
    let away: Vec<&Point3<f64>> = short
        .iter()
        .filter(|(p, radius)| !near(p, parent) && supported(p, *radius))
        .map(|(p, _)| p)
        .collect();
    if away.len() < MIN_SUPPORTED_SAMPLES {
        return None;
    }
    let beside = away.iter().filter(|p| near(p, long)).count();
    Some(beside as f64 / away.len() as f64)
}

/// Removes the side branches that end the tree and are twins of a longer sibling
/// ([`TwinTest`]); `points` are the skeleton's points, `level_width` its level width,
/// `spacing` the points' median spacing (the axes are sampled at it). Only the part of the
/// shorter branch the points show is compared: a bridge drawn where none are shows nothing of
/// the organ, and bridges to one crown converge. Returns how many branches were removed.
pub fn remove_twin_siblings(
    tree: &mut BranchTree,
    points: &[Point3<f64>],
    level_width: f64,
    spacing: f64,
    test: &TwinTest,
) -> usize {
    if !(level_width > 0.0 && spacing > 0.0) {
        return 0;
    }
    let Ok(index) = Neighbours::new(points.iter().copied()) else {
        return 0;
    };
    let supported = |p: &Point3<f64>, radius: f64| {
        index
            .nearest(p)
            .is_some_and(|n| n.distance_squared.sqrt() <= radius + test.support_spacings * spacing)
    };
    let reach = test.reach_levels * level_width;
    let max_gap = test.max_insertion_levels * level_width;
    let samples: HashMap<u32, Vec<(Point3<f64>, f64)>> = tree
        .branches
        .iter()
        .map(|b| (b.id, axis_samples(&b.cylinder, spacing)))
        .collect();
    let mut by_parent: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, b) in tree.branches.iter().enumerate() {
        if let Some(parent) = b.parent {
            by_parent.entry(parent).or_default().push(k);
        }
    }
    let mut twins: HashSet<u32> = HashSet::new();
    let mut parents: Vec<u32> = by_parent.keys().copied().collect();
    parents.sort_unstable();
    for parent_id in parents {
        let (Some(parent), Some(parent_samples)) = (tree.get(parent_id), samples.get(&parent_id))
        else {
            continue;
        };
        let parent_length = parent.cylinder.skeleton.length();
        let children = &by_parent[&parent_id];
        for (i, &a) in children.iter().enumerate() {
            for &b in &children[i + 1..] {
                let (ba, bb) = (&tree.branches[a], &tree.branches[b]);
                if (ba.parent_fraction - bb.parent_fraction).abs() * parent_length > max_gap {
                    continue;
                }
                let (la, lb) = (ba.cylinder.skeleton.length(), bb.cylinder.skeleton.length());
                // The shorter one goes (ties: the later id), the longer one stays.
                let (short, long) = if la < lb || (la == lb && ba.id > bb.id) {
                    (ba, bb)
                } else {
                    (bb, ba)
                };
                let (Some(s), Some(l)) = (samples.get(&short.id), samples.get(&long.id)) else {
                    continue;
                };
                if share_beside(s, l, parent_samples, reach, supported)
                    .is_some_and(|x| x >= test.min_share)
                {
                    twins.insert(short.id);
                }
            }
        }
    }
    prune_ends(tree, &twins)
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

    /// [`one_leaf_shares`] of `tree` against `sheets` under the default [`RimTest`].
    fn rim_shares(
        tree: &BranchTree,
        sheets: &[(Point3<f64>, u32)],
        support: Option<&Neighbours>,
    ) -> Vec<f64> {
        let points = Neighbours::new(sheets.iter().map(|(p, _)| *p)).unwrap();
        let leaf_of_point: Vec<u32> = sheets.iter().map(|(_, id)| *id).collect();
        let leaves = LeafSheets {
            points: &points,
            leaf_of_point: &leaf_of_point,
        };
        one_leaf_shares(tree, &leaves, support, SPACING, &RimTest::default())
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
        let test = RimTest::default();
        let shares = rim_shares(&tree, &sheets, None);
        // The stem is near some leaf all along, but near each one along about half of it.
        assert!(shares[0] > 0.4 && shares[0] < 0.7, "{shares:?}");
        assert!(shares[1] < 0.2, "{shares:?}");
        assert!(shares[2] > 0.95 && shares[3] > 0.95, "{shares:?}");

        let mut pruned = tree.clone();
        assert_eq!(
            remove_leaf_rims(&mut pruned, &sheets, &[], SPACING, &test),
            1
        );
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
        assert_eq!(
            remove_leaf_rims(&mut tree.clone(), &[], &[], SPACING, &test),
            0
        );
    }

    #[test]
    fn a_rim_reached_by_a_bridge_is_judged_by_its_supported_part() {
        // Branch 1 leaves the stem as a straight bridge with no points and then follows leaf
        // 20's edge; petiole 2 is seen only over its last 30 mm, up to leaf 21's base.
        let rim_path: Vec<Point3<f64>> = std::iter::once(Point3::new(0.0, 0.0, 0.06))
            .chain((0..=10).map(|k| Point3::new(0.1 + 0.01 * k as f64, 0.031, 0.1)))
            .collect();
        let tree = BranchTree {
            branches: vec![
                branch(0, None, [0.0, 0.0, 0.0], [0.0, 0.0, 0.12], 0.004),
                Branch {
                    id: 1,
                    parent: Some(0),
                    parent_fraction: 0.5,
                    cylinder: GeneralizedCylinder::new(
                        Spline::new(rim_path).unwrap(),
                        0.002,
                        0.002,
                    ),
                    leaf_at_tip: false,
                },
                branch(2, Some(0), [0.0, 0.0, 0.1], [-0.1, 0.0, 0.2], 0.002),
            ],
        };
        let mut sheets = leaf((0.1, 0.2), (-0.03, 0.03), 0.1, 20);
        sheets.extend(leaf((-0.2, -0.1), (-0.03, 0.03), 0.2, 21));
        let mut skeleton_points = line([0.0, 0.0, 0.0], [0.0, 0.0, 0.12], 0).0;
        skeleton_points.extend(line([0.1, 0.031, 0.1], [0.2, 0.031, 0.1], 0).0);
        let petiole_seen = 0.03 / 0.1f64.hypot(0.1);
        skeleton_points.extend(
            line(
                [-0.1 * (1.0 - petiole_seen), 0.0, 0.2 - 0.1 * petiole_seen],
                [-0.1, 0.0, 0.2],
                0,
            )
            .0,
        );
        let test = RimTest::default();
        let whole = rim_shares(&tree, &sheets, None);
        assert!(whole[1] > 0.3 && whole[1] < 0.7, "{whole:?}");
        let support = Neighbours::new(skeleton_points.iter().copied()).unwrap();
        let supported = rim_shares(&tree, &sheets, Some(&support));
        assert!(supported[1] > 0.95, "{supported:?}");
        assert!(supported[2] < 0.5, "{supported:?}");
        // Without the skeleton's points the bridged rim stays; with them it goes, alone.
        assert_eq!(
            remove_leaf_rims(&mut tree.clone(), &sheets, &[], SPACING, &test),
            0
        );
        let mut pruned = tree.clone();
        assert_eq!(
            remove_leaf_rims(&mut pruned, &sheets, &skeleton_points, SPACING, &test),
            1
        );
        let kept: Vec<u32> = pruned.branches.iter().map(|b| b.id).collect();
        assert_eq!(kept, vec![0, 2]);
    }

    #[test]
    fn the_binomial_lower_tail_matches_its_sum() {
        // Ten fair coins: no head 1/1024, at most one 11/1024, at most five 638/1024.
        assert!((binomial_lower_tail(0, 10, 0.5) - 1.0 / 1024.0).abs() < 1e-12);
        assert!((binomial_lower_tail(1, 10, 0.5) - 11.0 / 1024.0).abs() < 1e-12);
        assert!((binomial_lower_tail(5, 10, 0.5) - 638.0 / 1024.0).abs() < 1e-12);
        assert_eq!(binomial_lower_tail(10, 10, 0.5), 1.0);
        // Long branches: tiny but no underflow to a wrong answer, and the edge rates.
        let tail = binomial_lower_tail(3, 2000, 0.4);
        assert!((0.0..1e-300).contains(&tail), "{tail}");
        assert_eq!(binomial_lower_tail(0, 50, 0.0), 1.0);
        assert_eq!(binomial_lower_tail(3, 50, 1.0), 0.0);
    }

    /// Points every `SPACING` along a segment, every `every`-th one a thin-organ point
    /// (`every` = 0: none).
    fn line(a: [f64; 3], b: [f64; 3], every: usize) -> (Vec<Point3<f64>>, Vec<bool>) {
        let (a, b) = (Point3::from(a), Point3::from(b));
        let count = ((b - a).norm() / SPACING) as usize;
        (0..=count)
            .map(|k| {
                let p = a + (b - a) * (k as f64 / count as f64);
                (p, every > 0 && k % every == 0)
            })
            .unzip()
    }

    #[test]
    fn a_side_branch_without_bars_is_pruned_where_the_stem_shows_them() {
        // Stem 0 and petiole 1 are half thin-organ points; branch 2 (a leaf's edge) has none,
        // and carries twig 3, which has none either.
        let tree = BranchTree {
            branches: vec![
                branch(0, None, [0.0, 0.0, 0.0], [0.0, 0.0, 0.1], 0.002),
                branch(1, Some(0), [0.0, 0.0, 0.1], [0.1, 0.0, 0.1], 0.001),
                branch(2, Some(0), [0.0, 0.0, 0.05], [0.0, 0.1, 0.05], 0.001),
                branch(3, Some(2), [0.0, 0.1, 0.05], [0.0, 0.1, 0.1], 0.001),
            ],
        };
        let build = |stem_every: usize| {
            let mut points = Vec::new();
            let mut thin = Vec::new();
            for (a, b, every) in [
                ([0.0, 0.0, 0.0], [0.0, 0.0, 0.1], stem_every),
                ([0.0, 0.0, 0.1], [0.1, 0.0, 0.1], 2),
                ([0.0, 0.0, 0.05], [0.0, 0.1, 0.05], 0),
                ([0.0, 0.1, 0.05], [0.0, 0.1, 0.1], 0),
            ] {
                let (p, t) = line(a, b, every);
                points.extend(p);
                thin.extend(t);
            }
            (points, thin)
        };
        let test = BarTest::default();
        let (points, thin) = build(2);
        let mut pruned = tree.clone();
        assert_eq!(
            remove_barless_ends(&mut pruned, &points, &thin, SPACING, &test),
            2
        );
        let ids: Vec<u32> = pruned.branches.iter().map(|b| b.id).collect();
        assert_eq!(ids, vec![0, 1]);
        // Without the sweep's flags, or where the stem shows no bars either (the sweep does
        // not see this plant's organs), nothing goes.
        assert_eq!(
            remove_barless_ends(&mut tree.clone(), &points, &[], SPACING, &test),
            0
        );
        let (points, thin) = build(0);
        assert_eq!(
            remove_barless_ends(&mut tree.clone(), &points, &thin, SPACING, &test),
            0
        );
    }

    /// A side branch of `stem` (0 → (0, 0, 0.3)) leaving it at height `z` along `run`.
    fn side(id: u32, z: f64, run: [f64; 3], parent: u32) -> Branch {
        let a = [0.0, 0.0, z];
        let b = [run[0], run[1], z + run[2]];
        let mut branch = branch(id, Some(parent), a, b, 0.0005);
        branch.parent_fraction = z / 0.3;
        branch
    }

    #[test]
    fn a_twin_running_beside_its_sibling_goes_and_distinct_organs_stay() {
        // Level width 2.5 mm. Stem 0; at 0.1 fruit 1 (35 mm) and its halo twin 2 (leaving
        // 1 mm higher, then running 4 mm beside it); at 0.15 two organs leaving one place
        // 90° apart (3, 4); at 0.2 two parallel organs leaving 6 mm apart along the stem
        // (5, 6: more than two level widths).
        let level = 0.0025;
        let stem = branch(0, None, [0.0; 3], [0.0, 0.0, 0.3], 0.0015);
        let mut twin = side(2, 0.101, [0.017, 0.004, 0.017], 0);
        twin.cylinder = GeneralizedCylinder::new(
            Spline::new(vec![
                Point3::new(0.0, 0.0, 0.101),
                Point3::new(0.003, 0.004, 0.104),
                Point3::new(0.02, 0.004, 0.121),
            ])
            .unwrap(),
            0.0005,
            0.0005,
        );
        let mut tree = BranchTree {
            branches: vec![
                stem,
                side(1, 0.1, [0.025, 0.0, 0.025], 0),
                twin,
                side(3, 0.15, [0.025, 0.0, 0.01], 0),
                side(4, 0.15, [0.0, 0.025, 0.01], 0),
                side(5, 0.2, [0.025, 0.0, 0.01], 0),
                side(6, 0.206, [0.025, 0.0, 0.01], 0),
            ],
        };
        // The points: a sample every millimetre of each branch's axis, except `unseen`'s.
        let points_of = |tree: &BranchTree, unseen: u32| -> Vec<Point3<f64>> {
            tree.branches
                .iter()
                .filter(|b| b.id != unseen)
                .flat_map(|b| {
                    axis_samples(&b.cylinder, SPACING)
                        .into_iter()
                        .map(|(p, _)| p)
                })
                .collect()
        };
        let points = points_of(&tree, u32::MAX);
        let test = TwinTest::default();
        let mut pruned = tree.clone();
        assert_eq!(
            remove_twin_siblings(&mut pruned, &points, level, SPACING, &test),
            1
        );
        let ids: Vec<u32> = pruned.branches.iter().map(|b| b.id).collect();
        assert_eq!(ids, vec![0, 1, 3, 4, 5, 6]);
        // A twin the points do not show (a bridge drawn through air) is not judged.
        let unseen = points_of(&tree, 2);
        assert_eq!(
            remove_twin_siblings(&mut tree.clone(), &unseen, level, SPACING, &test),
            0
        );
        // A twin carrying a branch of its own stays (only ends are removed).
        tree.branches.push(branch(
            7,
            Some(2),
            [0.02, 0.004, 0.121],
            [0.025, 0.01, 0.13],
            0.0005,
        ));
        assert_eq!(
            remove_twin_siblings(&mut tree, &points, level, SPACING, &test),
            0
        );
        // Nothing is measured without a level width.
        assert_eq!(
            remove_twin_siblings(&mut pruned, &points, 0.0, SPACING, &test),
            0
        );
    }
}
