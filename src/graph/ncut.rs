//! Recursive two-way normalized cuts (Shi & Malik 2000) inside each component of the threshold
//! partition (seed 004 §5.1).
//!
//! A group is split at the sweep cut of its Fiedler vector with the lowest
//! `Ncut(A, B) = cut/vol(A) + cut/vol(B)`. The split is kept only when it separates real parts:
//! - a *boundary*: the cut edges are much weaker than the group's edges on average (the
//!   image term says a colour edge lies between the two sides), or
//! - a *bottleneck*: few edges cross compared with splitting a surface of that size in two
//!   (a petiole or stem junction), or
//! - a *shape* gain: the group is not flat enough to be one leaf and both sides are flatter.
//!
//! Groups smaller than twice the minimum segment are not split.

use std::sync::{Mutex, PoisonError};

use serde::Serialize;

use super::components::Adjacency;
use super::lanczos::{LanczosOptions, fiedler_vector};
use super::local_shape::Neighbourhoods;
use super::shape::Shape;
use nalgebra::{Point3, Vector3};

/// Stop criteria of the recursion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct NcutOptions {
    /// Smallest segment worth keeping (points).
    pub min_segment_points: usize,
    /// Never keep a split whose Ncut value exceeds this.
    pub max_ncut: f64,
    /// Boundary: mean cut-edge weight ≤ this × mean edge weight of the group.
    pub boundary_ratio: f64,
    /// Bottleneck: cut edges ≤ this × √(points on the smaller side).
    pub bottleneck: f64,
    /// Sheet residual (see [`Shape::sheet_residual`]) above which a group is not one smooth
    /// surface and so not a single leaf, before the noise allowance ([`sheet_tolerance`]).
    pub max_sheet_residual: f64,
    /// The residual a sheet may have from the points' noise: this many times the median local
    /// plane RMS of its points, added in quadrature to `max_sheet_residual` × its length. Small
    /// leaves are only a few noise levels long, so a relative bound alone calls them rough.
    #[serde(default = "default_sheet_noise_factor")]
    pub sheet_noise_factor: f64,
    /// Region merging joins two segments whose union is a sheet when at least this many kNN
    /// pairs × √(smaller size) connect them (a shared border, not a touching corner).
    pub min_merge_contact: f64,
}

impl Default for NcutOptions {
    fn default() -> Self {
        Self {
            min_segment_points: 20,
            max_ncut: 0.5,
            boundary_ratio: 0.3,
            bottleneck: 0.35,
            max_sheet_residual: 0.02,
            sheet_noise_factor: default_sheet_noise_factor(),
            min_merge_contact: 0.2,
        }
    }
}

fn default_sheet_noise_factor() -> f64 {
    SHEET_NOISE_FACTOR
}

/// See [`NcutOptions::sheet_noise_factor`].
pub const SHEET_NOISE_FACTOR: f64 = 1.5;

/// The largest sheet residual (relative to the length, as [`Shape::sheet_residual`]) of a
/// group that is still one smooth sheet: `√(r² + (c·σ/L)²)` for the shape allowance
/// `r = max_sheet_residual`, the noise factor `c`, the group's median local plane RMS `σ`
/// ([`crate::graph::PointGraph::plane_rms`]) and its length `L`.
pub fn sheet_tolerance(options: &NcutOptions, shape: &Shape, noise: f64) -> f64 {
    let relative_noise = options.sheet_noise_factor * noise / shape.length().max(1e-12);
    options.max_sheet_residual.hypot(relative_noise)
}

/// Median of the per-node `plane_rms` over `nodes` (0 for none).
pub fn median_noise(plane_rms: &[f64], nodes: impl Iterator<Item = usize>) -> f64 {
    crate::util::stats::median(nodes.filter_map(|n| plane_rms.get(n).copied())).unwrap_or(0.0)
}

/// A candidate split of a group.
#[derive(Clone, Debug)]
pub struct Split {
    /// `true` for the nodes on side A.
    pub side: Vec<bool>,
    pub ncut: f64,
    pub cut_weight: f64,
    pub cut_edges: usize,
    pub smaller_side: usize,
}

/// Why a group was split or left whole (for reports and tuning).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SplitReason {
    Boundary,
    Bottleneck,
    Shape,
}

/// The sweep cut of `order` (nodes sorted by Fiedler value) with the lowest Ncut, both sides
/// having at least `min_side` nodes.
pub fn best_sweep_split(adjacency: &Adjacency, values: &[f64], min_side: usize) -> Option<Split> {
    let n = adjacency.num_nodes();
    if n < 2 * min_side.max(1) {
        return None;
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let degrees = adjacency.degrees();
    let total: f64 = degrees.iter().sum();
    let mut in_a = vec![false; n];
    let mut volume_a = 0.0;
    let mut cut = 0.0;
    let mut cut_edges: isize = 0;
    let mut best: Option<(f64, usize, f64, isize)> = None;
    for (k, &node) in order.iter().enumerate().take(n - 1) {
        in_a[node] = true;
        volume_a += degrees[node];
        for (j, w) in adjacency.row(node) {
            if in_a[j] {
                cut -= w;
                cut_edges -= 1;
            } else {
                cut += w;
                cut_edges += 1;
            }
        }
        let size_a = k + 1;
        if size_a < min_side || n - size_a < min_side {
            continue;
        }
        let volume_b = total - volume_a;
        if volume_a <= 0.0 || volume_b <= 0.0 {
            continue;
        }
        let ncut = cut.max(0.0) / volume_a + cut.max(0.0) / volume_b;
        if best.is_none_or(|b| ncut < b.0) {
            best = Some((ncut, size_a, cut.max(0.0), cut_edges));
        }
    }
    let (ncut, size_a, cut_weight, cut_edges) = best?;
    let mut side = vec![false; n];
    for &node in &order[..size_a] {
        side[node] = true;
    }
    Some(Split {
        side,
        ncut,
        cut_weight,
        cut_edges: cut_edges.max(0) as usize,
        smaller_side: size_a.min(n - size_a),
    })
}

/// Decides whether a split separates real parts (see the module docs).
/// `positions` and `plane_rms` are the group's nodes' (see [`sheet_tolerance`]).
pub fn judge_split(
    adjacency: &Adjacency,
    split: &Split,
    positions: &[Point3<f64>],
    plane_rms: &[f64],
    options: &NcutOptions,
) -> Option<SplitReason> {
    if split.ncut > options.max_ncut {
        return None;
    }
    let edge_count = adjacency.neighbours.len() / 2;
    let mean_weight = adjacency.weights.iter().sum::<f64>() / 2.0 / edge_count.max(1) as f64;
    let mean_cut = split.cut_weight / split.cut_edges.max(1) as f64;
    if split.cut_edges == 0 || mean_cut <= options.boundary_ratio * mean_weight {
        return Some(SplitReason::Boundary);
    }
    if (split.cut_edges as f64) <= options.bottleneck * (split.smaller_side as f64).sqrt() {
        return Some(SplitReason::Bottleneck);
    }
    let residual = |points: &mut dyn Iterator<Item = Point3<f64>>| {
        let points: Vec<Point3<f64>> = points.collect();
        Shape::of(points.iter().copied()).sheet_residual(points.iter().copied())
    };
    let whole = residual(&mut positions.iter().copied());
    let shape = Shape::of(positions.iter().copied());
    let tolerance = sheet_tolerance(options, &shape, median_noise(plane_rms, 0..positions.len()));
    if whole > tolerance {
        let side = |a: bool| {
            positions
                .iter()
                .zip(&split.side)
                .filter(move |(_, s)| **s == a)
                .map(|(p, _)| *p)
        };
        let (ra, rb) = (residual(&mut side(true)), residual(&mut side(false)));
        if ra < whole && rb < whole {
            return Some(SplitReason::Shape);
        }
    }
    None
}

/// The best two-way normalized cut of a group of points by their facing: a graph joins each
/// point to its `neighbours` nearest (read from `around`, searched among `positions`),
/// weighting each pair by how alike their `normals` face,
/// `exp(−(1 − |nᵢ·nⱼ|) / facing_scale)`, so two leaves that touch at an angle are joined by weak
/// edges along a short contact. Returns the lowest-Ncut sweep split with at least `min_side`
/// points a side ([`best_sweep_split`]), or `None` when the group is too small or its graph
/// falls apart (then its parts need no cut).
pub fn facing_bisection(
    positions: &[Point3<f64>],
    normals: &[Vector3<f64>],
    around: &Neighbourhoods,
    neighbours: usize,
    facing_scale: f64,
    min_side: usize,
) -> Option<Split> {
    let n = positions.len();
    if n < 2 * min_side.max(1) || normals.len() != n || around.len() != n || facing_scale <= 0.0 {
        return None;
    }
    let mut pairs: Vec<(u32, u32)> = (0..n)
        .flat_map(|a| {
            around
                .around(a, neighbours)
                .filter(move |&b| b != a)
                .map(move |b| (a.min(b) as u32, a.max(b) as u32))
        })
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let edges: Vec<(u32, u32, f64)> = pairs
        .into_iter()
        .map(|(a, b)| {
            let agree = normals[a as usize].dot(&normals[b as usize]).abs();
            // A floor keeps every degree positive, as the eigensolver needs.
            (a, b, (-(1.0 - agree) / facing_scale).exp().max(1e-9))
        })
        .collect();
    let adjacency = Adjacency::from_edges(n, edges.iter().copied());
    if adjacency.components().count > 1 {
        return None;
    }
    let (_, fiedler) = fiedler_vector(&adjacency, &LanczosOptions::default())?;
    best_sweep_split(&adjacency, &fiedler, min_side)
}

/// Rounds of the two-plane assignment in [`two_sheet_split`].
const TWO_SHEET_ROUNDS: usize = 15;

/// Cuts a group that is no smooth sheet (its sheet residual above [`sheet_tolerance`]) by its
/// two best planes: two leaves that touch along a strong graph connection, which no normalized
/// cut separates (the caller chooses the groups: `segment::automatic::split_stacked_leaves`
/// tries only groups its leaf test calls leaves). The points are assigned to the nearer of two
/// planes and the planes refitted
/// ([`TWO_SHEET_ROUNDS`] rounds, started from the halves across each principal axis, the last
/// being the two sides of the best single plane; the start that ends with the smallest sum of
/// squared distances wins).
/// The split is kept only when each side is a smooth sheet of at least
/// `min_segment_points`; returns the side of each point.
pub fn two_sheet_split(
    positions: &[Point3<f64>],
    plane_rms: &[f64],
    options: &NcutOptions,
) -> Option<Vec<bool>> {
    let n = positions.len();
    if n < 2 * options.min_segment_points {
        return None;
    }
    let tolerance_of = |members: &[usize]| {
        let shape = Shape::of(members.iter().map(|&i| positions[i]));
        let residual = shape.sheet_residual(members.iter().map(|&i| positions[i]));
        let tolerance = sheet_tolerance(
            options,
            &shape,
            median_noise(plane_rms, members.iter().copied()),
        );
        (residual, tolerance)
    };
    let all: Vec<usize> = (0..n).collect();
    let (whole, tolerance) = tolerance_of(&all);
    if whole <= tolerance {
        return None;
    }
    let shape = Shape::of(positions.iter().copied());
    let starts = shape.axes.map(|axis| {
        positions
            .iter()
            .map(|p| (p - shape.centroid).dot(&axis) > 0.0)
            .collect::<Vec<bool>>()
    });
    let plane_of = |side: &[bool], which: bool| {
        let members = positions
            .iter()
            .zip(side)
            .filter(|(_, s)| **s == which)
            .map(|(p, _)| *p);
        let shape = Shape::of(members);
        (shape.count >= 3).then_some((shape.centroid, shape.normal()))
    };
    let mut best: Option<(f64, Vec<bool>)> = None;
    for mut side in starts {
        let mut cost = f64::INFINITY;
        for _ in 0..TWO_SHEET_ROUNDS {
            let (Some(a), Some(b)) = (plane_of(&side, true), plane_of(&side, false)) else {
                break;
            };
            cost = 0.0;
            for (p, s) in positions.iter().zip(side.iter_mut()) {
                let da = (p - a.0).dot(&a.1).abs();
                let db = (p - b.0).dot(&b.1).abs();
                *s = da < db;
                cost += da.min(db).powi(2);
            }
        }
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, side));
        }
    }
    let (_, side) = best?;
    let a: Vec<usize> = (0..n).filter(|&i| side[i]).collect();
    let b: Vec<usize> = (0..n).filter(|&i| !side[i]).collect();
    if a.len() < options.min_segment_points || b.len() < options.min_segment_points {
        return None;
    }
    let sheet = |members: &[usize]| {
        let (residual, tolerance) = tolerance_of(members);
        residual <= tolerance
    };
    (sheet(&a) && sheet(&b)).then_some(side)
}

/// Statistics of a recursion, for reports.
#[derive(Clone, Debug, Default, Serialize)]
pub struct NcutStats {
    pub eigen_solves: usize,
    /// The points of every group an eigenproblem was solved on, added up: what the recursion's
    /// course costs (a solve of `n` points costs about `n` times the Lanczos iterations
    /// squared). Cutting leaves one by one off the stem that holds them solves that group once
    /// per leaf.
    pub solved_points: usize,
    /// The largest group an eigenproblem was solved on (points).
    pub largest_solved: usize,
    pub splits_boundary: usize,
    pub splits_bottleneck: usize,
    pub splits_shape: usize,
    pub rejected_splits: usize,
}

/// What one step of the recursion did with a group.
enum Step {
    /// The group is final; `rejected` when its best split was judged no real part.
    Final { group: Vec<u32>, rejected: bool },
    /// The group fell apart into these connected pieces (no eigen solve).
    Pieces(Vec<Vec<u32>>),
    /// The group was split in two for this reason.
    Split {
        reason: SplitReason,
        sides: [Vec<u32>; 2],
    },
}

/// The recursion's inputs, shared by every step.
struct Recursion<'a> {
    adjacency: &'a Adjacency,
    positions: &'a [Point3<f64>],
    plane_rms: &'a [f64],
    options: &'a NcutOptions,
    lanczos: LanczosOptions,
}

impl Recursion<'_> {
    /// One step on one group: a pure function of the group (its members and their order), so
    /// the steps may run in any order and on any thread.
    /// Returns the step and the number of points it solved an eigenproblem on (0: none).
    fn step(&self, group: Vec<u32>) -> (Step, usize) {
        let options = self.options;
        let unsplit = |group| Step::Final {
            group,
            rejected: false,
        };
        if group.len() < 2 * options.min_segment_points {
            return (unsplit(group), 0);
        }
        let sub = self.adjacency.induced(&group);
        // A group may have fallen apart after a split: handle each piece on its own.
        let components = sub.components();
        if components.count > 1 {
            let pieces = components
                .groups()
                .into_iter()
                .map(|piece| piece.iter().map(|&i| group[i as usize]).collect())
                .collect();
            return (Step::Pieces(pieces), 0);
        }
        let solved = group.len();
        let Some((_, fiedler)) = fiedler_vector(&sub, &self.lanczos) else {
            return (unsplit(group), solved);
        };
        let Some(split) = best_sweep_split(&sub, &fiedler, options.min_segment_points) else {
            return (unsplit(group), solved);
        };
        let local_positions: Vec<Point3<f64>> =
            group.iter().map(|&g| self.positions[g as usize]).collect();
        let local_noise: Vec<f64> = group
            .iter()
            .map(|&g| self.plane_rms.get(g as usize).copied().unwrap_or(0.0))
            .collect();
        let step = match judge_split(&sub, &split, &local_positions, &local_noise, options) {
            Some(reason) => {
                let mut a = Vec::new();
                let mut b = Vec::new();
                for (i, &g) in group.iter().enumerate() {
                    if split.side[i] {
                        a.push(g);
                    } else {
                        b.push(g);
                    }
                }
                Step::Split {
                    reason,
                    sides: [a, b],
                }
            }
            None => Step::Final {
                group,
                rejected: true,
            },
        };
        (step, solved)
    }
}

/// What the recursion has finished so far.
#[derive(Default)]
struct Finished {
    groups: Vec<Vec<u32>>,
    stats: NcutStats,
}

/// Runs one step on `group` and queues what it leaves to split on `scope`, so that the
/// groups are worked on by every thread of the pool (work stealing, no deep call stacks).
fn split_in_scope<'s>(
    scope: &rayon::Scope<'s>,
    recursion: &'s Recursion<'s>,
    finished: &'s Mutex<Finished>,
    group: Vec<u32>,
) {
    let (step, solved) = recursion.step(group);
    let more = {
        // A poisoned lock only means another step panicked; its panic is re-raised by the
        // scope, so the tally here may go on.
        let mut finished = finished.lock().unwrap_or_else(PoisonError::into_inner);
        finished.stats.eigen_solves += usize::from(solved > 0);
        finished.stats.solved_points += solved;
        finished.stats.largest_solved = finished.stats.largest_solved.max(solved);
        match step {
            Step::Final { group, rejected } => {
                finished.stats.rejected_splits += usize::from(rejected);
                finished.groups.push(group);
                Vec::new()
            }
            Step::Pieces(pieces) => pieces,
            Step::Split { reason, sides } => {
                match reason {
                    SplitReason::Boundary => finished.stats.splits_boundary += 1,
                    SplitReason::Bottleneck => finished.stats.splits_bottleneck += 1,
                    SplitReason::Shape => finished.stats.splits_shape += 1,
                }
                sides.into()
            }
        }
    };
    for group in more {
        scope.spawn(move |scope| split_in_scope(scope, recursion, finished, group));
    }
}

/// Splits every group recursively. `adjacency` is the whole graph (global node ids),
/// `positions` the node positions and `plane_rms` their local plane RMS (see
/// [`sheet_tolerance`]). Returns the final groups (global ids, ordered by their smallest id)
/// and statistics.
///
/// Each group's fate depends on that group alone, so the groups are split on all threads of
/// rayon's pool; the result is the same for any number of threads.
pub fn recursive_ncut(
    adjacency: &Adjacency,
    groups: Vec<Vec<u32>>,
    positions: &[Point3<f64>],
    plane_rms: &[f64],
    options: &NcutOptions,
) -> (Vec<Vec<u32>>, NcutStats) {
    let recursion = Recursion {
        adjacency,
        positions,
        plane_rms,
        options,
        lanczos: LanczosOptions::default(),
    };
    let finished = Mutex::new(Finished::default());
    rayon::scope(|scope| {
        for group in groups {
            let (recursion, finished) = (&recursion, &finished);
            scope.spawn(move |scope| split_in_scope(scope, recursion, finished, group));
        }
    });
    let Finished { mut groups, stats } = finished
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner);
    groups.sort_by_key(|g| g.iter().copied().min());
    (groups, stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two square grids of points side by side, joined along their touching edge by edges of
    /// weight `joint` (1 inside each grid).
    fn two_patches(side: usize, joint: f64) -> (Adjacency, Vec<Point3<f64>>) {
        patch_row(side, &[joint])
    }

    /// Two square patches of `side` × `side` points 1 apart, the second folded up by `fold`
    /// radians about the line where they meet; each point with its patch's normal.
    fn folded_patches(side: usize, fold: f64) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>, usize) {
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        let (c, s) = (fold.cos(), fold.sin());
        for i in 0..side {
            for j in 0..side {
                positions.push(Point3::new(j as f64, i as f64, 0.0));
                normals.push(Vector3::z());
            }
        }
        for i in 0..side {
            for j in 1..=side {
                let along = j as f64;
                positions.push(Point3::new(
                    side as f64 - 1.0 + along * c,
                    i as f64,
                    along * s,
                ));
                normals.push(Vector3::new(-s, 0.0, c));
            }
        }
        (positions, normals, side * side)
    }

    #[test]
    fn a_fold_between_two_facings_is_cut_and_a_flat_sheet_costs_more_to_cut() {
        let (positions, normals, first) = folded_patches(10, 50f64.to_radians());
        let facing_scale = 0.1;
        let around =
            |positions: &[Point3<f64>]| Neighbourhoods::of_positions(positions, 8).unwrap();
        let folded = facing_bisection(
            &positions,
            &normals,
            &around(&positions),
            8,
            facing_scale,
            20,
        )
        .unwrap();
        let side_of_first = folded.side[0];
        for (i, side) in folded.side.iter().enumerate() {
            assert_eq!(*side == side_of_first, i < first, "point {i}");
        }
        let (flat, flat_normals, _) = folded_patches(10, 0.0);
        let whole =
            facing_bisection(&flat, &flat_normals, &around(&flat), 8, facing_scale, 20).unwrap();
        assert!(
            folded.ncut < 0.25 * whole.ncut,
            "folded {:.4} flat {:.4}",
            folded.ncut,
            whole.ncut
        );
        // Too few points for two sides of 20.
        let few = &positions[..39];
        assert!(facing_bisection(few, &normals[..39], &around(few), 8, facing_scale, 20).is_none());
        // Neighbourhoods of other points than these are refused.
        assert!(
            facing_bisection(&positions, &normals, &around(few), 8, facing_scale, 20).is_none()
        );
    }

    #[test]
    fn weak_boundary_is_split_and_a_uniform_patch_is_not() {
        let (adjacency, positions) = two_patches(12, 0.05);
        let all: Vec<u32> = (0..adjacency.num_nodes() as u32).collect();
        let (groups, stats) = recursive_ncut(
            &adjacency,
            vec![all],
            &positions,
            &[],
            &NcutOptions::default(),
        );
        assert_eq!(groups.len(), 2, "{stats:?}");
        assert_eq!(stats.splits_boundary, 1);
        // The whole (288 points) was solved, then each side (144) to find it is one patch.
        assert_eq!(stats.eigen_solves, 3, "{stats:?}");
        assert_eq!(stats.solved_points, 288 + 2 * 144);
        assert_eq!(stats.largest_solved, 288);
        for g in &groups {
            assert_eq!(g.len(), 144);
            let first = positions[g[0] as usize].x < 12.0;
            assert!(g.iter().all(|&i| (positions[i as usize].x < 12.0) == first));
        }
        // Joined as strongly as inside: one flat patch, kept whole.
        let (adjacency, positions) = two_patches(12, 1.0);
        let all: Vec<u32> = (0..adjacency.num_nodes() as u32).collect();
        let (groups, _) = recursive_ncut(
            &adjacency,
            vec![all],
            &positions,
            &[],
            &NcutOptions::default(),
        );
        assert_eq!(groups.len(), 1);
    }

    /// `joints.len() + 1` square patches of `side` × `side` points in a row, each joined to
    /// the next along a side by edges of that joint's weight (1 inside a patch).
    fn patch_row(side: usize, joints: &[f64]) -> (Adjacency, Vec<Point3<f64>>) {
        let patches = joints.len() + 1;
        let index = |patch: usize, i: usize, j: usize| (patch * side * side + i * side + j) as u32;
        let mut edges = Vec::new();
        let mut positions = Vec::new();
        for patch in 0..patches {
            for i in 0..side {
                for j in 0..side {
                    positions.push(Point3::new((patch * side + j) as f64, i as f64, 0.0));
                    if j + 1 < side {
                        edges.push((index(patch, i, j), index(patch, i, j + 1), 1.0));
                    }
                    if i + 1 < side {
                        edges.push((index(patch, i, j), index(patch, i + 1, j), 1.0));
                    }
                }
            }
        }
        for (patch, &joint) in joints.iter().enumerate() {
            for i in 0..side {
                edges.push((index(patch, i, side - 1), index(patch + 1, i, 0), joint));
            }
        }
        (
            Adjacency::from_edges(patches * side * side, edges.into_iter()),
            positions,
        )
    }

    #[test]
    fn the_recursion_gives_the_same_groups_on_one_thread_and_on_many() {
        // Eight patches joined by weak seams of different strengths, and the same row again
        // as a second starting group (its ids offset), so that groups wait on both threads.
        let joints = [0.05, 0.02, 0.08, 0.03, 0.06, 0.01, 0.04];
        let (row, row_positions) = patch_row(10, &joints);
        let n = row.num_nodes() as u32;
        let mut edges = Vec::new();
        for a in 0..n {
            for (b, w) in row.row(a as usize) {
                if (a as usize) < b {
                    edges.push((a, b as u32, w));
                    edges.push((a + n, b as u32 + n, w));
                }
            }
        }
        let adjacency = Adjacency::from_edges(2 * n as usize, edges.into_iter());
        let mut positions = row_positions.clone();
        positions.extend(
            row_positions
                .iter()
                .map(|p| p + Vector3::new(0.0, 50.0, 0.0)),
        );
        let starts = vec![(0..n).collect::<Vec<u32>>(), (n..2 * n).collect()];
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                recursive_ncut(
                    &adjacency,
                    starts.clone(),
                    &positions,
                    &[],
                    &NcutOptions::default(),
                )
            })
        };
        let (one, one_stats) = run(1);
        // Every patch on its own, each found once per row.
        assert_eq!(one.len(), 16, "{one_stats:?}");
        assert!(one.iter().all(|g| g.len() == 100));
        assert_eq!(one_stats.splits_boundary, 14);
        for threads in [2, 4] {
            let (many, many_stats) = run(threads);
            assert_eq!(many, one, "{threads} threads");
            assert_eq!(
                serde_json::to_string(&many_stats).unwrap(),
                serde_json::to_string(&one_stats).unwrap()
            );
        }
    }

    #[test]
    fn narrow_bridge_is_a_bottleneck() {
        let (adjacency, positions) = two_patches(14, 1.0);
        // Keep only one of the joining edges at full weight.
        let side = 14;
        let mut edges = Vec::new();
        for i in 0..adjacency.num_nodes() {
            for (j, w) in adjacency.row(i) {
                let crossing = (i < side * side) != (j < side * side);
                if i < j && (!crossing || i == side - 1) {
                    edges.push((i as u32, j as u32, w));
                }
            }
        }
        let bridged = Adjacency::from_edges(adjacency.num_nodes(), edges.into_iter());
        let all: Vec<u32> = (0..bridged.num_nodes() as u32).collect();
        let (groups, stats) = recursive_ncut(
            &bridged,
            vec![all],
            &positions,
            &[],
            &NcutOptions::default(),
        );
        assert_eq!(groups.len(), 2, "{stats:?}");
        assert_eq!(stats.splits_bottleneck, 1);
    }

    #[test]
    fn a_small_noisy_leaf_is_a_sheet_within_the_noise_allowance_and_a_fold_is_not() {
        // A flat 2 cm × 1 cm leaf sampled every 1.5 mm with 0.6 mm noise: its residual relative
        // to its length is above the shape allowance alone, within the noise allowance.
        let mut rng = crate::util::rng::Rng::seed_from(7);
        let mut leaf = Vec::new();
        for i in 0..14 {
            for j in 0..7 {
                leaf.push(Point3::new(
                    i as f64 * 0.0015 + rng.normal() * 0.0006,
                    j as f64 * 0.0015 + rng.normal() * 0.0006,
                    rng.normal() * 0.0006,
                ));
            }
        }
        let shape = Shape::of(leaf.iter().copied());
        let residual = shape.cubic_sheet_residual(leaf.iter().copied());
        let options = NcutOptions::default();
        let noise = 0.6 * 0.0006; // about what the local plane RMS measures at this noise
        assert!(residual > options.max_sheet_residual, "{residual}");
        assert!(
            residual <= sheet_tolerance(&options, &shape, noise),
            "{residual}"
        );
        // Without noise the tolerance is the shape allowance itself.
        assert_eq!(
            sheet_tolerance(&options, &shape, 0.0),
            options.max_sheet_residual
        );
        // Two such leaves folded at a right angle are not one sheet, noise allowed.
        let folded: Vec<Point3<f64>> = leaf
            .iter()
            .map(|p| {
                if p.x > 0.01 {
                    Point3::new(0.01 + p.z, p.y, p.x - 0.01)
                } else {
                    *p
                }
            })
            .collect();
        let shape = Shape::of(folded.iter().copied());
        let residual = shape.cubic_sheet_residual(folded.iter().copied());
        assert!(
            residual > sheet_tolerance(&options, &shape, noise),
            "{residual}"
        );
    }

    #[test]
    fn the_median_noise_reads_the_nodes_given() {
        let rms = [0.1, 0.5, 0.2, 0.9];
        assert_eq!(median_noise(&rms, [0usize, 2, 3].into_iter()), 0.2);
        assert_eq!(median_noise(&rms, std::iter::empty()), 0.0);
        assert_eq!(median_noise(&[], [0usize].into_iter()), 0.0);
    }

    /// A leaf lying on another: a flat leaf 10 × 5 cm and a second one, tilted 35° about
    /// the first one's width, resting with its base on the first one's middle, both with a
    /// little noise.
    fn leaf_on_a_leaf() -> (Vec<Point3<f64>>, usize) {
        let mut rng = crate::util::rng::Rng::seed_from(8);
        let mut positions = Vec::new();
        for _ in 0..1500 {
            let (u, v) = (rng.range(0.0, 0.1), rng.range(-0.025, 0.025));
            positions.push(Point3::new(u, v, rng.range(-0.0003, 0.0003)));
        }
        let first = positions.len();
        let (c, s) = (35f64.to_radians().cos(), 35f64.to_radians().sin());
        for _ in 0..1000 {
            let (u, v) = (rng.range(0.0, 0.08), rng.range(-0.02, 0.02));
            positions.push(Point3::new(
                0.05 + u * c,
                v + 0.01,
                u * s + rng.range(-0.0003, 0.0003),
            ));
        }
        (positions, first)
    }

    #[test]
    fn a_leaf_lying_on_another_is_cut_by_their_planes_and_one_bent_leaf_is_not() {
        let options = NcutOptions::default();
        let (positions, first) = leaf_on_a_leaf();
        let noise = vec![0.0003; positions.len()];
        let Some(side) = two_sheet_split(&positions, &noise, &options) else {
            panic!("two leaves at 35° are no single sheet");
        };
        let in_first = side[0];
        let wrong = (0..positions.len())
            .filter(|&i| side[i] != (in_first == (i < first)))
            .count();
        // Points where the two leaves meet lie on both planes.
        assert!(
            wrong < positions.len() / 50,
            "{wrong} of {} on the wrong side",
            positions.len()
        );
        // One leaf bent along its midrib (a quadratic sheet) is left whole.
        let mut rng = crate::util::rng::Rng::seed_from(9);
        let bent: Vec<Point3<f64>> = (0..2000)
            .map(|_| {
                let (u, v) = (rng.range(0.0, 0.1), rng.range(-0.025, 0.025));
                Point3::new(u, v, 0.3 * u * u + 4.0 * v * v + rng.range(-0.0003, 0.0003))
            })
            .collect();
        assert_eq!(
            two_sheet_split(&bent, &vec![0.0003; bent.len()], &options),
            None
        );
    }
}
