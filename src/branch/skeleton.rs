//! An automatic first skeleton from the plant's non-leaf points, so that users edit branches
//! rather than draw them from nothing (seed 004 §7 has the user draw every branch).
//!
//! Geodesic level sets (Verroust & Lazarus 2000; Xu et al. 2007): a kNN graph over the points
//! (components joined across small gaps), Dijkstra distances from the root (the lowest point
//! near the plant's axis; without a pot, the point nearest the soil line under the point the
//! cameras look at, [`PlantBase`]), points binned by distance into levels of a few point
//! spacings, the connected pieces of each level become nodes at their centroids, and each
//! node's parent is the piece its points' shortest paths come from. The node tree is split
//! into branches by the longest-path rule (the deepest child continues the branch; the others
//! start child branches), short spurs are pruned, and each branch gets a spline through its
//! smoothed nodes and a linear radius fitted to the points' distances from its axis. Where
//! many branches leave one crowded place (a rosette's crown), a side branch's wandering base is
//! replaced by its own direction extended back to the parent's axis ([`reanchor_base`]); a
//! branch that split off a neighbour it ran alongside is extended back to their common
//! parent ([`sibling_of`]). Tubes the level sets merged into a neighbour all the way to their
//! tips are found last, in the points no branch explains ([`recover_missed_tubes`]).

use crate::util::geometry::distance_from_axis;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Branch, BranchTree, GeneralizedCylinder, Spline};
use crate::graph::neighbours::{Neighbour, Neighbours};
use crate::graph::shape::Shape;
use crate::util::union_find::UnionFind;

/// Settings of the automatic skeleton.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SkeletonOptions {
    /// Neighbours per point in the kNN graph.
    pub neighbours: usize,
    /// Width of a geodesic level, in median neighbour spacings.
    pub level_width: f64,
    /// Components are joined across gaps up to this many median spacings.
    pub max_gap: f64,
    /// Components with fewer points are ignored.
    pub min_component_points: usize,
    /// Branches shorter than this many level widths are pruned (with their sub-branches).
    pub min_branch_levels: f64,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        Self {
            neighbours: 10,
            level_width: 4.0,
            max_gap: 12.0,
            min_component_points: 12,
            min_branch_levels: 3.0,
        }
    }
}

/// What the skeleton was built from, for reports.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SkeletonStats {
    pub points: usize,
    pub spacing: f64,
    pub level_width: f64,
    pub components: usize,
    pub components_joined: usize,
    pub points_reached: usize,
    pub nodes: usize,
    pub branches: usize,
    pub branches_pruned: usize,
    /// Side branches whose tangled base was replaced by a straight run to their parent.
    pub bases_reanchored: usize,
    /// Branches found in points no other branch explains ([`recover_missed_tubes`]).
    pub branches_recovered: usize,
    /// Main axes split at the top of a stem, where it thins abruptly at a fork ([`stem_top`]).
    #[serde(default)]
    pub stems_ended: usize,
    /// Pieces of tube out of the kNN graph's reach, bridged to the tree ([`bridge_pieces`]).
    #[serde(default)]
    pub pieces_bridged: usize,
    /// Side branches removed as the rims of leaves ([`super::prune`]).
    #[serde(default)]
    pub rims_pruned: usize,
    /// Side branches removed as showing no bar in the photos ([`super::prune::BarTest`]).
    #[serde(default)]
    pub barless_pruned: usize,
    /// Side branches removed as twins of a longer sibling ([`super::prune::TwinTest`]).
    #[serde(default)]
    pub twins_pruned: usize,
    /// Rooted over a soil-line point ([`PlantBase::SoilLine`]: no pot said where the stem
    /// stands), not at a known stem foot.
    #[serde(default)]
    pub rooted_on_soil_line: bool,
}

/// Why no skeleton could be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    #[error("{0} non-leaf points: too few for a skeleton")]
    TooFewPoints(usize),
    #[error("the non-leaf points contain a non-finite coordinate (point {0})")]
    NonFinite(usize),
    /// The main axis found lies flat: it runs around the pot or over the soil.
    #[error(
        "no stem visible: the main axis found rises {rise:.4} over a length of {length:.4} (less than a tenth), so it is the pot or the soil, not a stem; the plant is leaves only"
    )]
    NoStem { rise: f64, length: f64 },
}

/// Non-negative distances ordered by their bits (valid for finite values ≥ 0).
fn key(distance: f64) -> u64 {
    distance.max(0.0).to_bits()
}

/// A node of the level-set tree: a connected piece of one geodesic level.
struct Node {
    centroid: Point3<f64>,
    points: Vec<usize>,
    parent: Option<usize>,
    children: Vec<usize>,
    /// Geodesic distance of the node (mean of its points').
    distance: f64,
}

/// Builds a branch tree from non-leaf plant points (stems, petioles, twigs).
/// `up` is the plant's up direction and `root` the plant's base: a point on its vertical axis
/// at the soil line. The tree grows from the lowest points near that axis; where they do not
/// reach down to `root` (a stem hidden by leaves or the pot), the stem is extended straight to
/// it. Pieces of tube the kNN graph cannot join (petioles whose lower parts the photos never
/// show) get their own skeletons, bridged to the tree ([`bridge_pieces`]).
pub fn automatic_skeleton(
    points: &[Point3<f64>],
    up: &Vector3<f64>,
    root: &Point3<f64>,
    options: &SkeletonOptions,
) -> Result<(BranchTree, SkeletonStats), SkeletonError> {
    automatic_skeleton_from(points, up, &PlantBase::Stem(*root), options)
}

/// Where a plant's skeleton is rooted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlantBase {
    /// Where the stem leaves the soil, known (the soil surface on a pot's axis): the tree
    /// grows from the lowest points near that axis, and the stem is drawn on from its first
    /// node (the centroid of the first level of points) to the point.
    Stem(Point3<f64>),
    /// Only a point of the soil line (no pot to say where the stem stands), on an axis fitted
    /// to the plant's points (`branch::plant::plant_axis`), which need not be where the
    /// cameras look nor upright; the fit can miss the foot of a plant that is not one stem.
    /// The tree grows from the point of the plant nearest this one, and a stem that does not
    /// reach the soil line is drawn straight down to it.
    SoilLine(Point3<f64>),
}

impl PlantBase {
    /// The base point.
    pub fn point(&self) -> Point3<f64> {
        match self {
            PlantBase::Stem(p) | PlantBase::SoilLine(p) => *p,
        }
    }
}

/// [`automatic_skeleton`] rooted as `base` says ([`PlantBase`]).
pub fn automatic_skeleton_from(
    points: &[Point3<f64>],
    up: &Vector3<f64>,
    base: &PlantBase,
    options: &SkeletonOptions,
) -> Result<(BranchTree, SkeletonStats), SkeletonError> {
    let role = match base {
        PlantBase::Stem(_) => Role::Plant,
        PlantBase::SoilLine(_) => Role::PlantOnSoilLine,
    };
    let root = &base.point();
    let connected = connected_skeleton(points, up, root, options, role)?;
    let mut branches = connected.tree.branches;
    let mut stats = connected.stats;
    stats.rooted_on_soil_line = role == Role::PlantOnSoilLine;
    stats.pieces_bridged = bridge_pieces(
        &mut branches,
        points,
        &connected.pieces,
        up,
        root,
        options,
        stats.level_width,
    );
    stats.branches = branches.len();
    Ok((BranchTree { branches }, stats))
}

/// The skeleton of the kNN-connected part of the points around the root, and the point groups
/// (indices) it could not join.
struct Connected {
    tree: BranchTree,
    stats: SkeletonStats,
    pieces: Vec<Vec<usize>>,
}

/// What a level-set skeleton is built for.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    /// The whole plant: the root is the lowest point near the axis, and the stem is drawn on
    /// to the plant's base.
    Plant,
    /// The whole plant over a soil-line point ([`PlantBase::SoilLine`]): the root is the
    /// point nearest it, and the stem is drawn straight down to the soil line when it ends
    /// above it.
    PlantOnSoilLine,
    /// A piece of tube to be bridged to the plant: the root is its point nearest the base.
    Piece,
}

/// The level-set skeleton of the component holding the root and the components joined to it
/// across small gaps (see the module docs).
fn connected_skeleton(
    points: &[Point3<f64>],
    up: &Vector3<f64>,
    axis_point: &Point3<f64>,
    options: &SkeletonOptions,
    role: Role,
) -> Result<Connected, SkeletonError> {
    let n = points.len();
    let k = options.neighbours.max(2);
    if n < options.min_component_points.max(k + 1) {
        return Err(SkeletonError::TooFewPoints(n));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(SkeletonError::NonFinite(i));
    }
    let mut stats = SkeletonStats {
        points: n,
        ..SkeletonStats::default()
    };
    let neighbours =
        Neighbours::new(points.iter().copied()).map_err(|_| SkeletonError::TooFewPoints(n))?;
    let mut edges: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut nearest = Vec::with_capacity(n);
    // The k-NN lists are found on all cores a block of points at a time (so that they never
    // all wait in memory), then joined in the points' order.
    const KNN_BLOCK: usize = 1 << 16;
    for start in (0..n).step_by(KNN_BLOCK) {
        let lists: Vec<Vec<Neighbour>> = (start..(start + KNN_BLOCK).min(n))
            .into_par_iter()
            .map(|i| neighbours.around(i, k))
            .collect();
        for (i, list) in (start..).zip(lists) {
            let mut first = f64::INFINITY;
            for found in list {
                let j = found.index;
                if j == i {
                    continue;
                }
                let d = found.distance();
                first = first.min(d);
                edges[i].push((j, d));
                edges[j].push((i, d));
            }
            if first.is_finite() {
                nearest.push(first);
            }
        }
    }
    if nearest.is_empty() {
        return Err(SkeletonError::TooFewPoints(n));
    }
    nearest.sort_by(f64::total_cmp);
    let spacing = nearest[nearest.len() / 2].max(1e-9);
    stats.spacing = spacing;
    let level_width = options.level_width * spacing;
    stats.level_width = level_width;
    // Long kNN edges of isolated points would let paths jump: keep edges within a level
    // width (components split by this are joined below across small gaps, nearest first).
    for list in &mut edges {
        list.retain(|&(_, d)| d <= level_width);
    }

    // Components of the kNN graph.
    let mut components = UnionFind::new(n);
    for (i, list) in edges.iter().enumerate() {
        for &(j, _) in list {
            components.union(i, j);
        }
    }
    let mut members: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in 0..n {
        members.entry(components.find(i)).or_default().push(i);
    }
    let mut groups: Vec<Vec<usize>> = members
        .into_values()
        .filter(|m| m.len() >= options.min_component_points)
        .collect();
    groups.sort_by(|a, b| b.len().cmp(&a.len()).then(a[0].cmp(&b[0])));
    stats.components = groups.len();
    if groups.is_empty() {
        return Err(SkeletonError::TooFewPoints(0));
    }

    // Root: over all components, the lowest point among those horizontally nearest the axis
    // (for a piece, its point nearest the base); the other components are joined to the
    // root's. The largest component need not hold the stem: a trunk that stereo samples
    // sparsely falls apart into small components, farther from the crown's than the joins
    // reach (on ten of sixteen broadleaf photo plants the root in the largest component put
    // the stem's first node 65–180 mm above the soil, the stem drawn as one straight line up
    // to it), and the crown is bridged to the trunk.
    // Over a soil-line point the root is the point nearest it among the largest component
    // and those joined to it: that point is itself the lowest of the skeleton points near
    // the plant's axis, and a speck of them below the plant would otherwise hold the root
    // and the stem (the real Arabidopsis, one COLMAP run: a 35-point component 2 mm from
    // the soil-line point, the plant's 88,985 points 23 mm away, and the stem drawn 65 mm
    // along a rosette leaf). The stem is drawn on down to the soil line.
    let horizontal = |p: &Point3<f64>| distance_from_axis(p, axis_point, up);
    let height = |p: &Point3<f64>| up.dot(&(p - axis_point));
    let nearest_to_base = |candidates: &mut dyn Iterator<Item = usize>| {
        candidates.min_by(|&a, &b| {
            (points[a] - axis_point)
                .norm()
                .total_cmp(&(points[b] - axis_point).norm())
                .then(a.cmp(&b))
        })
    };
    let (root_group, lowest) = match role {
        Role::Piece | Role::PlantOnSoilLine => (0, None),
        Role::Plant => {
            let mut all: Vec<usize> = groups.iter().flatten().copied().collect();
            all.sort_unstable();
            let mut by_axis: Vec<f64> = all.iter().map(|&i| horizontal(&points[i])).collect();
            by_axis.sort_by(f64::total_cmp);
            let near_axis = by_axis[(by_axis.len() - 1) / 4];
            let lowest = all
                .iter()
                .copied()
                .filter(|&i| horizontal(&points[i]) <= near_axis)
                .min_by(|&a, &b| {
                    height(&points[a])
                        .total_cmp(&height(&points[b]))
                        .then(a.cmp(&b))
                });
            let group = lowest
                .and_then(|root| groups.iter().position(|g| g.contains(&root)))
                .unwrap_or(0);
            (group, lowest)
        }
    };

    // Join the other components to the root's across small gaps, nearest first.
    let mut connected = vec![false; n];
    for &i in &groups[root_group] {
        connected[i] = true;
    }
    let mut pending: Vec<usize> = (0..groups.len()).filter(|&g| g != root_group).collect();
    let max_gap = options.max_gap * spacing;
    // Each pending point's nearest connected point (distance, index): measured against the
    // connected part once, then against each group as it joins.
    let mut nearest_inside = vec![(f64::INFINITY, usize::MAX); n];
    let inside: Vec<usize> = (0..n).filter(|&i| connected[i]).collect();
    nearer_inside(&mut nearest_inside, &inside, &pending, &groups, points);
    loop {
        let mut best: Option<(f64, usize, usize, usize)> = None;
        for (slot, &g) in pending.iter().enumerate() {
            for &i in &groups[g] {
                let (d, to) = nearest_inside[i];
                if d <= max_gap && best.is_none_or(|b| d < b.0) {
                    best = Some((d, slot, i, to));
                }
            }
        }
        let Some((d, slot, from, to)) = best else {
            break;
        };
        edges[from].push((to, d));
        edges[to].push((from, d));
        let joined = pending.swap_remove(slot);
        for &i in &groups[joined] {
            connected[i] = true;
        }
        nearer_inside(
            &mut nearest_inside,
            &groups[joined],
            &pending,
            &groups,
            points,
        );
        stats.components_joined += 1;
    }
    let root = match role {
        Role::Plant => lowest,
        Role::Piece => nearest_to_base(&mut groups[0].iter().copied()),
        Role::PlantOnSoilLine => nearest_to_base(&mut (0..n).filter(|&i| connected[i])),
    }
    .unwrap_or(groups[root_group][0]);
    tracing::debug!(
        root = ?points[root],
        root_component = groups[root_group].len(),
        largest_component = groups[0].len(),
        components = groups.len(),
        joined = stats.components_joined,
        "skeleton root"
    );

    // Geodesic distances from the root.
    let mut distance = vec![f64::INFINITY; n];
    let mut predecessor = vec![usize::MAX; n];
    distance[root] = 0.0;
    let mut heap = BinaryHeap::new();
    heap.push(Reverse((key(0.0), root)));
    while let Some(Reverse((d_key, i))) = heap.pop() {
        let d = f64::from_bits(d_key);
        if d > distance[i] {
            continue;
        }
        for &(j, w) in &edges[i] {
            let candidate = d + w;
            if candidate < distance[j] {
                distance[j] = candidate;
                predecessor[j] = i;
                heap.push(Reverse((key(candidate), j)));
            }
        }
    }
    let reached: Vec<usize> = (0..n).filter(|&i| distance[i].is_finite()).collect();
    stats.points_reached = reached.len();

    // Level sets and their connected pieces.
    let level = |i: usize| (distance[i] / level_width).floor() as i64;
    let mut pieces = UnionFind::new(n);
    for &i in &reached {
        for &(j, _) in &edges[i] {
            if distance[j].is_finite() && level(i) == level(j) {
                pieces.union(i, j);
            }
        }
    }
    let mut node_of = vec![usize::MAX; n];
    let mut nodes: Vec<Node> = Vec::new();
    let mut index: HashMap<usize, usize> = HashMap::new();
    let mut order = reached.clone();
    order.sort_by(|&a, &b| distance[a].total_cmp(&distance[b]).then(a.cmp(&b)));
    for &i in &order {
        let piece = pieces.find(i);
        let node = *index.entry(piece).or_insert_with(|| {
            nodes.push(Node {
                centroid: Point3::origin(),
                points: Vec::new(),
                parent: None,
                children: Vec::new(),
                distance: 0.0,
            });
            nodes.len() - 1
        });
        node_of[i] = node;
        nodes[node].points.push(i);
    }
    for node in &mut nodes {
        let count = node.points.len() as f64;
        node.centroid = Point3::from(
            node.points
                .iter()
                .fold(Vector3::zeros(), |a, &i| a + points[i].coords)
                / count,
        );
        node.distance = node.points.iter().map(|&i| distance[i]).sum::<f64>() / count;
    }
    // Parent: the node most of the piece's shortest paths come from.
    for v in 0..nodes.len() {
        let mut votes: HashMap<usize, usize> = HashMap::new();
        for &i in &nodes[v].points {
            let p = predecessor[i];
            if p != usize::MAX && node_of[p] != v {
                *votes.entry(node_of[p]).or_insert(0) += 1;
            }
        }
        let parent = votes
            .into_iter()
            .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
            .map(|(p, _)| p);
        nodes[v].parent = parent;
        if let Some(p) = parent {
            nodes[p].children.push(v);
        }
    }
    merge_close_siblings(&mut nodes, points, level_width);
    let mut nodes = compact(nodes);
    stats.nodes = nodes.len();

    // Longest-path decomposition: the deepest child continues a branch.
    let mut depth = vec![0.0f64; nodes.len()];
    let mut by_distance: Vec<usize> = (0..nodes.len()).collect();
    by_distance.sort_by(|&a, &b| nodes[b].distance.total_cmp(&nodes[a].distance));
    for &v in &by_distance {
        depth[v] = nodes[v]
            .children
            .iter()
            .map(|&c| depth[c] + (nodes[c].centroid - nodes[v].centroid).norm())
            .fold(0.0, f64::max);
    }
    let Some(root_node) = nodes.iter().position(|v| v.points.contains(&root)) else {
        return Err(SkeletonError::TooFewPoints(n));
    };
    let mut branches: Vec<Branch> = Vec::new();
    // The main axis's chain and polyline, and where along them its stem ends.
    let mut stem_split: Option<(Vec<usize>, Vec<Point3<f64>>, StemTop)> = None;
    // (first node, parent branch id, attachment node)
    let mut queue: Vec<(usize, Option<u32>, Option<usize>)> = vec![(root_node, None, None)];
    let min_length = options.min_branch_levels * level_width;
    while let Some((start, parent, attachment)) = queue.pop() {
        let mut chain = vec![start];
        let mut current = start;
        let deepest = |v: usize| {
            nodes[v].children.iter().copied().max_by(|&a, &b| {
                let reach = |c: usize| depth[c] + (nodes[c].centroid - nodes[v].centroid).norm();
                reach(a).total_cmp(&reach(b)).then(b.cmp(&a))
            })
        };
        while let Some(next) = deepest(current) {
            chain.push(next);
            current = next;
        }
        let full_chain = chain.clone();
        if parent.is_none() && role != Role::Piece {
            // Only below the first fork a side branch leaves from: above it a level holds
            // the branch's points too.
            let below_fork = chain
                .windows(2)
                .position(|pair| {
                    nodes[pair[0]].children.iter().any(|&c| {
                        c != pair[1]
                            && depth[c] + (nodes[c].centroid - nodes[pair[0]].centroid).norm()
                                >= min_length
                    })
                })
                .unwrap_or(chain.len());
            let centres = ring_centres(&chain[..below_fork], &nodes, points, up);
            for (&v, centre) in chain.iter().zip(centres) {
                nodes[v].centroid = centre;
            }
        }
        let mut parent = parent;
        let mut attachment_point = attachment.map(|a| nodes[a].centroid);
        // Where a side branch leaves its parent (arc fraction on the parent).
        let mut parent_fraction = match (parent, &attachment_point) {
            (Some(p), Some(point)) => Some(attachment_fraction(&branches[p as usize], point)),
            _ => None,
        };
        if let Some(p) = parent
            && let Some(anchor) = reanchor_base(
                &chain,
                attachment_point,
                p,
                &BaseContext {
                    nodes: &nodes,
                    points,
                    neighbours: &neighbours,
                    branches: &branches,
                    level_width,
                },
            )
        {
            chain.drain(..anchor.first_clean);
            parent = Some(anchor.parent);
            attachment_point = Some(anchor.point);
            parent_fraction = Some(anchor.fraction);
            stats.bases_reanchored += 1;
        }
        if parent.is_none() {
            let foot = nodes[chain[0]].centroid;
            match role {
                // The first level's centroid stands most of a level above the points' foot:
                // the stem is drawn on from it to where it leaves the soil.
                Role::Plant if (foot - axis_point).norm() > 0.0 => {
                    attachment_point = Some(*axis_point);
                }
                Role::PlantOnSoilLine => {
                    let above = up.dot(&(foot - axis_point));
                    if above > 0.0 {
                        attachment_point = Some(foot - up * above);
                    }
                }
                _ => {}
            }
        }
        let mut polyline: Vec<Point3<f64>> = Vec::with_capacity(chain.len() + 1);
        polyline.extend(attachment_point);
        polyline.extend(smooth(
            &chain.iter().map(|&v| nodes[v].centroid).collect::<Vec<_>>(),
        ));
        let length = crate::util::polyline::length(&polyline);
        // Spurs: too short, or ending within a few radii of the parent's axis (parts of a
        // thick stem's ring that lag behind in geodesic distance hug its surface).
        let hugs_parent = match (parent, parent_fraction, polyline.last()) {
            (Some(p), Some(fraction), Some(tip)) => {
                let cylinder = &branches[p as usize].cylinder;
                let radius = cylinder
                    .radius_at(fraction)
                    .max(0.5 * (cylinder.radius_start + cylinder.radius_end));
                cylinder.skeleton.distance_to(tip) < 2.5 * radius
            }
            _ => false,
        };
        if parent.is_some() && (chain.len() < 2 || length < min_length || hugs_parent) {
            stats.branches_pruned += 1;
            continue;
        }
        let Some(branch) = branch_from_chain(
            branches.len() as u32,
            parent,
            parent_fraction,
            &polyline,
            &chain,
            &nodes,
            points,
        ) else {
            stats.branches_pruned += 1;
            continue;
        };
        let id = branch.id;
        if parent.is_none()
            && role != Role::Piece
            && let Some(top) = stem_top(&chain, &nodes, points)
        {
            stem_split = Some((chain.clone(), polyline.clone(), top));
        }
        branches.push(branch);
        // Side branches start at each chain node's other children, base first.
        // (A re-anchored base's dropped nodes still pass their other children on.)
        for (position, &v) in full_chain.iter().enumerate().rev() {
            let continuing = full_chain.get(position + 1).copied();
            let mut others: Vec<usize> = nodes[v]
                .children
                .iter()
                .copied()
                .filter(|&c| Some(c) != continuing)
                .collect();
            others.sort_by(|&a, &b| depth[a].total_cmp(&depth[b]).then(a.cmp(&b)));
            for c in others {
                queue.push((c, Some(id), Some(v)));
            }
        }
    }
    if let Some((chain, polyline, top)) = stem_split
        && split_stem(&mut branches, &chain, &polyline, &top, &nodes, points)
    {
        stats.stems_ended += 1;
    }
    stats.branches_recovered = recover_missed_tubes(
        &mut branches,
        &TubeContext {
            points,
            edges: &edges,
            distance: &distance,
            neighbours: &neighbours,
            level_width,
            min_points: options.min_component_points,
            min_length,
        },
    );
    stats.branches = branches.len();
    Ok(Connected {
        tree: BranchTree { branches },
        stats,
        pieces: pending.into_iter().map(|g| groups[g].clone()).collect(),
    })
}

/// Lowers each pending group's points' nearest connected point (`nearest`: distance, index)
/// to the nearest of `joined` (points just connected) where that is strictly nearer.
fn nearer_inside(
    nearest: &mut [(f64, usize)],
    joined: &[usize],
    pending: &[usize],
    groups: &[Vec<usize>],
    points: &[Point3<f64>],
) {
    let Ok(tree) = Neighbours::new(joined.iter().map(|&i| points[i])) else {
        return;
    };
    let queries: Vec<usize> = pending
        .iter()
        .flat_map(|&g| groups[g].iter().copied())
        .collect();
    let found: Vec<Option<(f64, usize)>> = queries
        .par_iter()
        .map(|&i| {
            tree.nearest(&points[i])
                .map(|f| (f.distance(), joined[f.index]))
        })
        .collect();
    for (&i, found) in queries.iter().zip(found) {
        if let Some(found) = found
            && found.0 < nearest[i].0
        {
            nearest[i] = found;
        }
    }
}

/// A group of points is round enough for a piece of tube when its third principal spread is
/// at least this share of its second (`Shape::flatness`): a half-visible ring gives about
/// 0.44, a leaf fragment about 0.1.
const TUBE_ROUNDNESS: f64 = 0.3;

/// Pieces of tube the kNN graph could not join to the tree (a petiole seen only near its
/// leaf, a branch behind foliage) each get their own level-set skeleton, rooted at their end
/// nearest the plant's base, whose main branch is then extended straight back to the tree:
/// to the point of an existing branch axis that is cheapest to reach, as cost the bridge's
/// length times `1 + 8 (1 − cos θ)`, θ its angle to the piece's own backward direction (the
/// chord over its first four level widths), among points within 40° of that direction and
/// within three times the piece's main-branch length. A piece whose own skeleton forks (a
/// crown of petioles seen where they part, joined where they meet) whose main branch finds no
/// such point tries once more along the way its branches converge, from the piece's centroid
/// through its root: its main branch's first levels run along whichever tube it follows,
/// sideways to the tree (from studio photos of broadleaf seed 2, a 4,960-point crown of eight
/// petioles on a 6 cm stem was left out, its way back 69° off the stem). Pieces are taken largest
/// first, so later ones may attach to earlier ones, but not to their bridges, which are
/// drawn where no point is (a bridge onto a bridge compounds two guesses: from photos of
/// medium plants such chains ran 10–20 mm off every true centreline), and only as their
/// continuation: within four level widths of an earlier piece's tip (or of the tip of one of
/// its branches), turning from its way there by less than 40° (an organ interrupted where the
/// photos lose it). A side branch leaving an earlier piece would be hidden at both ends, its
/// junction as well as its own base: from photos of broadleaf plants, where every petiole
/// leaves the stem, 55 pieces bridged onto other pieces had 35 % of their bridges' length on
/// the plant, against 77–78 % for bridges onto the tree, and 46 of the 55 met their piece
/// before the last quarter of its length; on medium plants 9 of 10 such bridges met their
/// piece in its last quarter, 7 of them with at least 80 % of the bridge on the plant. A
/// piece shorter than the shortest kept branch or with no such point is left out. So is a
/// flat piece (less round than [`TUBE_ROUNDNESS`]) whose bridge would be longer than its main
/// branch: stereo smears a petiole into a flat band too, but then beside the tree, while a
/// band of leaf edge or halo hangs off the foliage, far from every axis (from photos of
/// broadleaf seeds 1–3 and 11–13, such pieces were 9 % on the plant, their bridges included).
/// Nor is a piece that hangs: one whose main branch runs downward from its root, so that its
/// backward direction climbs. An
/// organ seen in part rises from the tree it grows out of; what hangs off the foliage with
/// nothing seen between is a leaf edge, a leaf's midrib or stereo's halo below a leaf (from
/// photos of 16 broadleaf plants, 15 % of such pieces' length and 14 % of their bridges' lay
/// on the plant). Returns how many pieces were added.
fn bridge_pieces(
    branches: &mut Vec<Branch>,
    points: &[Point3<f64>],
    pieces: &[Vec<usize>],
    up: &Vector3<f64>,
    root: &Point3<f64>,
    options: &SkeletonOptions,
    level_width: f64,
) -> usize {
    const MAX_ANGLE_DEG: f64 = 40.0;
    const ANGLE_PENALTY: f64 = 8.0;
    const REACH_LENGTHS: f64 = 3.0;
    const TIP_LEVELS: f64 = 4.0;
    if branches.is_empty() {
        return 0;
    }
    let cos_max = MAX_ANGLE_DEG.to_radians().cos();
    let mut pieces: Vec<&Vec<usize>> = pieces.iter().collect();
    pieces.sort_by_key(|g| (Reverse(g.len()), g[0]));
    // Branches from here on are bridged pieces' (and their side branches): joined only as
    // continuations, at their tips.
    let tree_count = branches.len();
    let mut bridged = 0;
    // Per bridged branch: the share of its length, from its base, that is the bridge. A later
    // piece is not bridged onto a bridge: that is drawn where no point is.
    let mut bridge_share: HashMap<u32, f64> = HashMap::new();
    // Each branch's axis samples, in the branches' order (a branch's axis does not change
    // once it is in the tree; bridged pieces append theirs).
    let mut axis_samples: Vec<Vec<(Point3<f64>, Vector3<f64>)>> = Vec::new();
    for piece in pieces {
        let piece_points: Vec<Point3<f64>> = piece.iter().map(|&i| points[i]).collect();
        let left_out = |why: &str| {
            tracing::debug!(points = piece.len(), why, "skeleton piece left out");
        };
        let Ok(sub) = connected_skeleton(&piece_points, up, root, options, Role::Piece) else {
            left_out("no skeleton");
            continue;
        };
        let mut sub_branches = sub.tree.branches;
        let Some(main) = sub_branches.first() else {
            left_out("no branch");
            continue;
        };
        let main_axis = &main.cylinder.skeleton;
        let length = main_axis.length();
        let min_length = options.min_branch_levels * level_width;
        let origin = main_axis.point_at_fraction(0.0);
        let tip = main_axis.point_at_fraction(1.0);
        let left_out = |why: &str| {
            tracing::debug!(
                points = piece.len(),
                ?origin,
                ?tip,
                length,
                why,
                "skeleton piece left out"
            );
        };
        if length < min_length {
            left_out("shorter than the shortest kept branch");
            continue;
        }
        let back_fraction = (4.0 * sub.stats.level_width / length).min(1.0);
        let Some(backward) =
            (origin - main_axis.point_at_fraction(back_fraction)).try_normalize(1e-12)
        else {
            left_out("no backward direction");
            continue;
        };
        if backward.dot(up) > 0.0 {
            left_out("hangs");
            continue;
        }
        let reach = REACH_LENGTHS * length;
        for branch in &branches[axis_samples.len()..] {
            axis_samples.push(branch.cylinder.skeleton.sample_by_arc_length(128));
        }
        // The cheapest axis point in the cone about `way` (the piece's way back to the tree).
        let anchor_along = |way: &Vector3<f64>| {
            let mut best: Option<(f64, u32, f64, Point3<f64>)> = None;
            for (index, (branch, samples)) in branches.iter().zip(&axis_samples).enumerate() {
                let last = (samples.len().max(2) - 1) as f64;
                let drawn = bridge_share.get(&branch.id).copied().unwrap_or(0.0);
                let on_piece = index >= tree_count;
                let from = if on_piece {
                    drawn.max(1.0 - TIP_LEVELS * level_width / branch.cylinder.length().max(1e-12))
                } else {
                    drawn
                };
                for (k, (point, tangent)) in samples.iter().enumerate() {
                    if (k as f64) < from * last {
                        continue;
                    }
                    let offset = point - origin;
                    let distance = offset.norm();
                    if distance > reach || distance < 1e-12 {
                        continue;
                    }
                    // A continuation turns from the piece's way by less than the cone allows.
                    if on_piece && -offset.dot(tangent) < cos_max * distance * tangent.norm() {
                        continue;
                    }
                    let cos = offset.dot(way) / distance;
                    if cos < cos_max {
                        continue;
                    }
                    let cost = distance * (1.0 + ANGLE_PENALTY * (1.0 - cos));
                    if best.is_none_or(|b| cost < b.0) {
                        best = Some((cost, branch.id, k as f64 / last, *point));
                    }
                }
            }
            best
        };
        let mut best = anchor_along(&backward);
        // A piece that forks is a crown of tubes (petioles leaving together, seen where they
        // part): its main branch's first levels run where the tubes meet, along whichever
        // one it follows, and the way back to the tree is where they converge, from the
        // piece's centroid through its root.
        if best.is_none() && sub_branches.len() > 1 {
            let centroid = Shape::of(piece_points.iter().copied()).centroid;
            if let Some(converging) = (origin - centroid).try_normalize(1e-12)
                && converging.dot(up) <= 0.0
            {
                tracing::debug!(?backward, ?converging, "a forked piece's way back");
                best = anchor_along(&converging);
            }
        }
        let Some((_, parent, fraction, anchor)) = best else {
            tracing::debug!(?backward, reach, "the piece's way back to the tree");
            left_out("no axis point in its cone and reach");
            continue;
        };
        if (anchor - origin).norm() > length
            && Shape::of(piece_points.iter().copied()).flatness() < TUBE_ROUNDNESS
        {
            left_out("flat, with a bridge longer than itself");
            continue;
        }
        tracing::debug!(
            points = piece.len(),
            ?origin,
            ?tip,
            length,
            parent,
            bridge = (anchor - origin).norm(),
            "skeleton piece bridged"
        );
        let mut control = vec![anchor];
        control.extend(main_axis.control_points().iter().copied());
        let Some(skeleton) = spline_through(&control) else {
            continue;
        };
        let offset = branches.len() as u32;
        let main = &mut sub_branches[0];
        main.cylinder = GeneralizedCylinder::new(
            skeleton,
            main.cylinder.radius_start,
            main.cylinder.radius_end,
        );
        main.parent = Some(parent);
        main.parent_fraction = fraction;
        bridge_share.insert(main.id + offset, attachment_fraction(main, &origin));
        for branch in &mut sub_branches {
            branch.id += offset;
        }
        for k in 1..sub_branches.len() {
            if let Some(p) = sub_branches[k].parent {
                let start = sub_branches[k].cylinder.skeleton.point_at_fraction(0.0);
                let parent_branch = &sub_branches[p as usize];
                sub_branches[k].parent_fraction = attachment_fraction(parent_branch, &start);
                sub_branches[k].parent = Some(p + offset);
            }
        }
        branches.extend(sub_branches);
        bridged += 1;
    }
    bridged
}

/// What [`recover_missed_tubes`] looks at.
struct TubeContext<'a> {
    points: &'a [Point3<f64>],
    /// kNN edges within a level width.
    edges: &'a [Vec<(usize, f64)>],
    /// Geodesic distance from the root (infinite where not reached).
    distance: &'a [f64],
    /// The points' neighbours.
    neighbours: &'a Neighbours,
    level_width: f64,
    min_points: usize,
    min_length: f64,
}

/// Where two tubes run side by side to their tips (petioles leaving a crown together), the
/// level sets hold both at once and the skeleton follows one, or runs between them. The points
/// no branch explains (farther than its radius plus a level width from every axis: a level's
/// centroid may sit up to about half a level off the axis, and the radius fit is rough) are
/// grouped by the kNN graph. A group shaped like a piece of tube becomes a branch: as long
/// as the shortest kept branch, its spread across its principal axis no more than the
/// branches' median radius, and round rather than flat (the third principal spread at least
/// [`TUBE_ROUNDNESS`] of the second). The
/// branch is the group's centroids along that axis (one per level width), extended from the
/// end nearer the root (in geodesic distance) straight back, at most twice the group's length,
/// to an axis it meets within 3 of its radii, crossing it at 5° or more, the axis nearest the
/// tree's root first; it is kept only where the points support the extension (as in
/// [`reanchor_base`]). Returns how many branches were added.
fn recover_missed_tubes(branches: &mut Vec<Branch>, context: &TubeContext) -> usize {
    let TubeContext {
        points,
        edges,
        distance,
        neighbours,
        level_width,
        min_points,
        min_length,
    } = *context;
    if branches.is_empty() {
        return 0;
    }
    // Axis samples about every half level width, with their radii, branches and tangents.
    let mut samples: Vec<AxisSample> = Vec::new();
    for branch in branches.iter() {
        let cylinder = &branch.cylinder;
        let count =
            ((cylinder.skeleton.length() / (0.5 * level_width)).ceil() as usize).clamp(2, 2000);
        for (k, (p, tangent)) in cylinder
            .skeleton
            .sample_by_arc_length(count)
            .iter()
            .enumerate()
        {
            let fraction = k as f64 / (count - 1) as f64;
            samples.push(AxisSample {
                point: *p,
                radius: cylinder.radius_at(fraction),
                branch: branch.id,
                tangent: *tangent,
            });
        }
    }
    let Ok(axis_neighbours) = Neighbours::new(samples.iter().map(|s| s.point)) else {
        return 0;
    };
    let unexplained: Vec<bool> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if !distance[i].is_finite() {
                return false;
            }
            axis_neighbours
                .nearest(p)
                .is_some_and(|f| f.distance() > samples[f.index].radius + level_width)
        })
        .collect();
    let mut groups = UnionFind::new(points.len());
    for (i, list) in edges.iter().enumerate() {
        if unexplained[i] {
            for &(j, _) in list {
                if unexplained[j] {
                    groups.union(i, j);
                }
            }
        }
    }
    let mut members: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in (0..points.len()).filter(|&i| unexplained[i]) {
        members.entry(groups.find(i)).or_default().push(i);
    }
    let mut radii: Vec<f64> = branches
        .iter()
        .map(|b| 0.5 * (b.cylinder.radius_start + b.cylinder.radius_end))
        .collect();
    radii.sort_by(f64::total_cmp);
    let tube_spread = radii[radii.len() / 2];
    let depth = |branches: &[Branch], mut id: u32| {
        let mut depth = 0usize;
        while let Some(parent) = branches[id as usize].parent {
            depth += 1;
            id = parent;
            if depth > branches.len() {
                break;
            }
        }
        depth
    };
    let mut added = 0;
    let mut groups: Vec<Vec<usize>> = members.into_values().collect();
    groups.sort_by_key(|g| (std::cmp::Reverse(g.len()), g[0]));
    for group in groups.into_iter().filter(|g| g.len() >= min_points) {
        let shape = Shape::of(group.iter().map(|&i| points[i]));
        let across = shape.eigenvalues[1].sqrt();
        let along: Vec<f64> = group
            .iter()
            .map(|&i| (points[i] - shape.centroid).dot(&shape.axes[0]))
            .collect();
        let (low, high) = along
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &a| {
                (l.min(a), h.max(a))
            });
        let length = high - low;
        if length < min_length || across > tube_spread || shape.flatness() < TUBE_ROUNDNESS {
            continue;
        }
        // Centroids per level width along the axis, from the end nearer the root.
        let bins = ((length / level_width).ceil() as usize).max(1);
        let mut sums = vec![(Vector3::zeros(), 0usize, 0.0f64); bins];
        for (k, &i) in group.iter().enumerate() {
            let bin = (((along[k] - low) / level_width) as usize).min(bins - 1);
            sums[bin].0 += points[i].coords;
            sums[bin].1 += 1;
            sums[bin].2 += distance[i];
        }
        let mut polyline: Vec<Point3<f64>> = Vec::with_capacity(bins + 1);
        let mut geodesic: Vec<f64> = Vec::with_capacity(bins);
        for (sum, n, d) in &sums {
            if *n > 0 {
                polyline.push(Point3::from(sum / *n as f64));
                geodesic.push(d / *n as f64);
            }
        }
        if polyline.len() < 3 {
            continue;
        }
        if geodesic[0] > geodesic[geodesic.len() - 1] {
            polyline.reverse();
        }
        let polyline = smooth(&polyline);
        if runs_beside_an_axis(&polyline, &samples, &axis_neighbours, level_width) {
            continue;
        }
        let origin = polyline[0];
        let Some(backward) = (origin - polyline[polyline.len().min(4) - 1]).try_normalize(1e-12)
        else {
            continue;
        };
        // The axis nearest the tree's root first, then the closest crossing.
        let Some((_, parent, crossing)) = branches
            .iter()
            .filter_map(|branch| {
                let crossing = closest_crossing(branch, &origin, &backward, 2.0 * length)?;
                Some((depth(branches, branch.id), branch.id, crossing))
            })
            .min_by(|a, b| a.0.cmp(&b.0).then(a.2.miss.total_cmp(&b.2.miss)))
        else {
            continue;
        };
        let (fraction, anchor) = (crossing.fraction, crossing.point);
        let parent_radius = branches[parent as usize].cylinder.radius_at(fraction);
        let extension = [anchor, origin];
        let supported = support(
            neighbours,
            &extension,
            1.5 * parent_radius,
            0.5 * level_width,
            across + 0.5 * level_width,
        )
        .unwrap_or(1.0);
        if supported < 0.8 {
            continue;
        }
        let mut control = vec![anchor];
        control.extend(polyline.iter().copied());
        let Some(skeleton) = spline_through(&control) else {
            continue;
        };
        let mut distances: Vec<f64> = group
            .iter()
            .map(|&i| skeleton.closest_fraction(&points[i]).1)
            .collect();
        distances.sort_by(f64::total_cmp);
        let radius = distances[distances.len() / 2].max(1e-6);
        branches.push(Branch {
            id: branches.len() as u32,
            parent: Some(parent),
            parent_fraction: fraction,
            cylinder: GeneralizedCylinder::new(skeleton, radius, radius),
            leaf_at_tip: false,
        });
        added += 1;
    }
    added
}

/// A point of a branch axis, as [`recover_missed_tubes`] looks it up.
#[derive(Clone, Copy)]
struct AxisSample {
    point: Point3<f64>,
    radius: f64,
    branch: u32,
    tangent: Vector3<f64>,
}

/// A tube found beside an existing branch and parallel to it along most of its length is
/// that branch's twin, not an organ of its own: stereo smears a thin organ across the
/// viewing direction into a band wider than its fitted radius, and the band's far edge is
/// left unexplained. Two real organs that leave a node together (petioles at a crown) diverge
/// toward their tips. Twin: at 75 % or more of the polyline's vertices the nearest axis is one
/// and the same branch, within twice (its radius + a level width), and the polyline's
/// direction there is within 25° of that axis.
fn runs_beside_an_axis(
    polyline: &[Point3<f64>],
    samples: &[AxisSample],
    axis_neighbours: &Neighbours,
    level_width: f64,
) -> bool {
    const SHARE: f64 = 0.75;
    const MAX_ANGLE_DEG: f64 = 25.0;
    let cos_max = MAX_ANGLE_DEG.to_radians().cos();
    if polyline.len() < 2 {
        return false;
    }
    let mut beside: std::collections::BTreeMap<u32, usize> = Default::default();
    for (k, p) in polyline.iter().enumerate() {
        let (a, b) = (
            polyline[k.saturating_sub(1)],
            polyline[(k + 1).min(polyline.len() - 1)],
        );
        let Some(direction) = (b - a).try_normalize(1e-12) else {
            continue;
        };
        let Some(nearest) = axis_neighbours.nearest(p) else {
            continue;
        };
        let AxisSample {
            branch,
            tangent,
            radius,
            ..
        } = samples[nearest.index];
        if nearest.distance() <= 2.0 * (radius + level_width)
            && direction.dot(&tangent).abs() >= cos_max
        {
            *beside.entry(branch).or_default() += 1;
        }
    }
    beside
        .values()
        .any(|&n| n as f64 >= SHARE * polyline.len() as f64)
}

/// Joins sibling pieces of a level that nearly touch (closest points less than a level width
/// apart): sparse sampling splits a tube's ring into arcs, which are one cross-section.
/// Nodes are visited by increasing distance, so merged children pass their children on.
fn merge_close_siblings(nodes: &mut [Node], points: &[Point3<f64>], level_width: f64) {
    let mut order: Vec<usize> = (0..nodes.len()).collect();
    order.sort_by(|&a, &b| {
        nodes[a]
            .distance
            .total_cmp(&nodes[b].distance)
            .then(a.cmp(&b))
    });
    let gap = |a: &Node, b: &Node| {
        let mut best = f64::INFINITY;
        for &i in &a.points {
            for &j in &b.points {
                best = best.min((points[i] - points[j]).norm_squared());
            }
        }
        best.sqrt()
    };
    for v in order {
        if nodes[v].points.is_empty() {
            continue;
        }
        let mut children = std::mem::take(&mut nodes[v].children);
        children.sort_unstable();
        children.dedup();
        children.retain(|&c| !nodes[c].points.is_empty());
        let mut k = 0;
        while k < children.len() {
            let a = children[k];
            let mut m = k + 1;
            while m < children.len() {
                let b = children[m];
                if gap(&nodes[a], &nodes[b]) < level_width {
                    let moved = std::mem::take(&mut nodes[b].points);
                    let grandchildren = std::mem::take(&mut nodes[b].children);
                    for &g in &grandchildren {
                        nodes[g].parent = Some(a);
                    }
                    let (na, nb) = (nodes[a].points.len() as f64, moved.len() as f64);
                    let centroid_b = moved
                        .iter()
                        .fold(Vector3::zeros(), |s, &i| s + points[i].coords)
                        / nb;
                    let distance_b = nodes[b].distance;
                    let node = &mut nodes[a];
                    node.centroid =
                        Point3::from((node.centroid.coords * na + centroid_b * nb) / (na + nb));
                    node.distance = (node.distance * na + distance_b * nb) / (na + nb);
                    node.points.extend(moved);
                    node.children.extend(grandchildren);
                    children.swap_remove(m);
                    // The grown piece may now reach siblings it did not before.
                    m = k + 1;
                } else {
                    m += 1;
                }
            }
            k += 1;
        }
        nodes[v].children = children;
    }
}

/// Drops emptied nodes and renumbers parents and children.
fn compact(nodes: Vec<Node>) -> Vec<Node> {
    let mut new_index = vec![usize::MAX; nodes.len()];
    let mut next = 0;
    for (i, node) in nodes.iter().enumerate() {
        if !node.points.is_empty() {
            new_index[i] = next;
            next += 1;
        }
    }
    nodes
        .into_iter()
        .filter(|node| !node.points.is_empty())
        .map(|mut node| {
            node.parent = node
                .parent
                .map(|p| new_index[p])
                .filter(|&p| p != usize::MAX);
            node.children = node
                .children
                .iter()
                .map(|&c| new_index[c])
                .filter(|&c| c != usize::MAX)
                .collect();
            node
        })
        .collect()
}

/// A stem level's fitted circle is trusted where its radius is within this factor of the median
/// radius of the next [`RING_AGREEMENT_LEVELS`] levels' circles.
const RING_RADIUS_AGREEMENT: f64 = 1.5;

/// How many levels above a stem level its circle is compared with (at least two of them must
/// have a circle).
const RING_AGREEMENT_LEVELS: usize = 3;

/// Fewest points of a level a circle is fitted to.
const MIN_RING_POINTS: usize = 8;

/// The main stem's chain positions re-centred on the stem's axis: each level's centroid
/// replaced by the centre of the circle fitted to its points across `up`
/// ([`circle_across`]), from the base up while the fitted radius agrees with the next levels'
/// ([`RING_RADIUS_AGREEMENT`]); a first level whose circle does not agree (a short arc about
/// the root) takes the second's centre at its own height. The geodesic levels from a root on
/// the side of a thick stem are rings tilted toward that side, so their centroids stand off
/// the axis for several levels and the stem was drawn with a sideways jog at its base (on
/// semi-dense broadleaf 11 and 13 the first centroids stood 13–15 mm off the axis of a 12–14
/// mm stem; a circle fitted across up to the same points 0–1.8 mm from the second level on).
/// The levels themselves do not move, only where the chain passes through them.
fn ring_centres(
    chain: &[usize],
    nodes: &[Node],
    points: &[Point3<f64>],
    up: &Vector3<f64>,
) -> Vec<Point3<f64>> {
    let mut centres: Vec<Point3<f64>> = chain.iter().map(|&v| nodes[v].centroid).collect();
    let fits: Vec<Option<(Point3<f64>, f64)>> = chain
        .iter()
        .map(|&v| circle_across(&nodes[v], points, up))
        .collect();
    let trusted = |k: usize| -> Option<Point3<f64>> {
        let (centre, radius) = fits[k]?;
        let next: Vec<f64> = fits
            .iter()
            .skip(k + 1)
            .take(RING_AGREEMENT_LEVELS)
            .flatten()
            .map(|f| f.1)
            .collect();
        if next.len() < 2 {
            return None;
        }
        let median = crate::util::stats::median(next.iter().copied())?;
        (radius <= RING_RADIUS_AGREEMENT * median && median <= RING_RADIUS_AGREEMENT * radius)
            .then_some(centre)
    };
    if chain.is_empty() {
        return centres;
    }
    let first = trusted(0);
    for (k, slot) in centres.iter_mut().enumerate().skip(1) {
        match trusted(k) {
            Some(centre) => *slot = centre,
            None => break,
        }
    }
    match first {
        Some(centre) => centres[0] = centre,
        None if chain.len() > 1 && trusted(1).is_some() => {
            let above = centres[1];
            centres[0] = above + up * up.dot(&(centres[0] - above));
        }
        None => {}
    }
    centres
}

/// The circle fitted across the unit `up` to a level's points (Kåsa's algebraic fit,
/// [`crate::util::geometry::concentric_circle_centre`], in the plane through its centroid
/// square to `up`): its centre, at the centroid's height, and radius (for Kåsa's fit the root
/// mean square distance of the points from the centre). `None` for fewer than
/// [`MIN_RING_POINTS`] points or a degenerate fit (points on a line).
fn circle_across(
    node: &Node,
    points: &[Point3<f64>],
    up: &Vector3<f64>,
) -> Option<(Point3<f64>, f64)> {
    if node.points.len() < MIN_RING_POINTS {
        return None;
    }
    let e1 = crate::util::geometry::any_perpendicular(up);
    let e2 = up.cross(&e1);
    let planar: Vec<(f64, f64, usize)> = node
        .points
        .iter()
        .map(|&i| {
            let d = points[i] - node.centroid;
            (d.dot(&e1), d.dot(&e2), 0)
        })
        .collect();
    let (a, b) = crate::util::geometry::concentric_circle_centre(&planar, 1)?;
    let squared = planar
        .iter()
        .map(|&(x, y, _)| (x - a).powi(2) + (y - b).powi(2))
        .sum::<f64>()
        / planar.len() as f64;
    (squared.is_finite() && squared > 0.0)
        .then(|| (node.centroid + e1 * a + e2 * b, squared.sqrt()))
}

/// Moving average over three nodes (ends kept).
fn smooth(polyline: &[Point3<f64>]) -> Vec<Point3<f64>> {
    if polyline.len() < 3 {
        return polyline.to_vec();
    }
    let mut out = polyline.to_vec();
    for i in 1..polyline.len() - 1 {
        out[i] = Point3::from(
            (polyline[i - 1].coords + polyline[i].coords + polyline[i + 1].coords) / 3.0,
        );
    }
    out
}

/// Where a side branch's tangled base is replaced by a straight run to its parent.
struct Anchor {
    /// Chain nodes before this one are dropped.
    first_clean: usize,
    /// The branch the extrapolated base meets (the parent or one of its ancestors).
    parent: u32,
    /// Arc fraction and point on that branch's axis.
    fraction: f64,
    point: Point3<f64>,
}

/// A stem ends at a fork only if the chain beyond it has fewer forks (nodes with two or more
/// children) than this share of the chain's forks up to it ([`stem_top`]). Where stems ended on
/// 7 synthetic plants (photos of medium 3 and 4; semi-dense compound 11, broadleaf 2 and 3,
/// smallleaf 1) 0–4 forks lay beyond the fork for 4–20 up to it (at most 0.2 of them); on a
/// COLMAP run of the real Arabidopsis the stem "ended" 55 % up its inflorescence where its
/// stereo halo thins, with 49 forks beyond for 67 up to it (0.73): its upper half, bearing
/// fruits, was cut off the main stem as a side branch (stop 79).
const MAX_FORK_SHARE_ABOVE_TOP: f64 = 0.5;

/// Where a main axis stops being the stem: the first fork (a node with two or more children)
/// past the chain's fourth node after which the tube is clearly thinner, so that a stem under
/// a crown of petioles (a rosette, the generator's broadleaf plants: a 6 cm stem of radius
/// 14 mm under 13–30 cm petioles) is measured as the stem, and the petiole the longest path
/// runs on into is a branch of its own. Radii are each node's median distance from the chain's
/// local axis; at the fork, the median over the next four nodes is less than half of both
/// the chain's median up to the fork and the median of the last four nodes up to it (a
/// gradual taper does not end a stem), and none of the next eight reaches the chain's median
/// (sparse points split a ring into arcs that read thin for a level or two). And what the chain
/// runs on into bears fewer forks than [`MAX_FORK_SHARE_ABOVE_TOP`] of those up to the fork: a
/// petiole above a crown bears none, an axis that goes on bearing organs is the stem going on.
fn stem_top(chain: &[usize], nodes: &[Node], points: &[Point3<f64>]) -> Option<StemTop> {
    const STEM_NODES: usize = 4;
    const AHEAD: usize = 4;
    const CONFIRM: usize = 8;
    const RATIO: f64 = 0.5;
    if chain.len() < STEM_NODES + AHEAD {
        return None;
    }
    let radii = chain_radii(chain, nodes, points);
    let median = |range: &[f64]| crate::util::stats::median(range.iter().copied());
    (STEM_NODES - 1..chain.len() - AHEAD).find_map(|k| {
        if nodes[chain[k]].children.len() < 2 {
            return None;
        }
        let behind = median(&radii[..=k])?;
        let local = median(&radii[k + 1 - STEM_NODES..=k])?;
        let ahead = median(&radii[k + 1..k + 1 + AHEAD])?;
        let confirm = &radii[k + 1..(k + 1 + CONFIRM).min(chain.len())];
        let forks = |range: &[usize]| {
            range
                .iter()
                .filter(|&&v| nodes[v].children.len() >= 2)
                .count()
        };
        (ahead < RATIO * behind.min(local)
            && confirm.iter().all(|&r| r < behind)
            && (forks(&chain[k + 1..]) as f64)
                < MAX_FORK_SHARE_ABOVE_TOP * forks(&chain[..=k]) as f64)
            .then_some(StemTop {
                fork: k,
                radius: behind,
            })
    })
}

/// Where a stem ends ([`stem_top`]).
struct StemTop {
    /// The fork's position in the main axis's chain.
    fork: usize,
    /// The median of the stem's levels' radii up to the fork: its first levels are arcs of
    /// its ring, too thin, and its last the crown's knot, too wide (a linear fit went from 8
    /// to 30 mm on a 14 mm stem).
    radius: f64,
}

/// Each chain node's median distance from the chain's local axis (through its neighbours'
/// centroids): about the radius of the tube the node is a slice of.
fn chain_radii(chain: &[usize], nodes: &[Node], points: &[Point3<f64>]) -> Vec<f64> {
    let centroids: Vec<Point3<f64>> = chain.iter().map(|&v| nodes[v].centroid).collect();
    (0..chain.len())
        .map(|k| {
            let before = centroids[k.saturating_sub(1)];
            let after = centroids[(k + 1).min(chain.len() - 1)];
            let Some(tangent) = (after - before).try_normalize(1e-12) else {
                return 0.0;
            };
            crate::util::stats::median(nodes[chain[k]].points.iter().map(|&p| {
                let d = points[p] - centroids[k];
                (d - tangent * tangent.dot(&d)).norm()
            }))
            .unwrap_or(0.0)
        })
        .collect()
}

/// Splits the main axis (branch 0, built from `chain` through `polyline`) at the top of its
/// stem ([`stem_top`]): the stem ends at the fork, with one radius ([`StemTop::radius`]), and
/// the rest of the axis becomes a branch of its own from the stem's tip, through the same
/// nodes, its radii fitted without the fork's level (the crown's knot). Side branches keep
/// their geometry and move to whichever part they leave from. Returns whether it split.
fn split_stem(
    branches: &mut Vec<Branch>,
    chain: &[usize],
    polyline: &[Point3<f64>],
    top: &StemTop,
    nodes: &[Node],
    points: &[Point3<f64>],
) -> bool {
    let fork = top.fork;
    let Some(offset) = polyline.len().checked_sub(chain.len()) else {
        return false;
    };
    let cut = fork + offset;
    if branches.is_empty() || cut < 1 || cut + 3 > polyline.len() || top.radius <= 0.0 {
        return false;
    }
    let continuation_id = branches.len() as u32;
    let (Some(stem_axis), Some(continuation_axis), Some(beyond)) = (
        spline_through(&polyline[..=cut]),
        spline_through(&polyline[cut..]),
        branch_from_chain(
            continuation_id,
            Some(0),
            Some(1.0),
            &polyline[cut + 1..],
            &chain[fork + 1..],
            nodes,
            points,
        ),
    ) else {
        return false;
    };
    let split_fraction = attachment_fraction(&branches[0], &polyline[cut]);
    let stem = Branch {
        id: 0,
        parent: None,
        parent_fraction: branches[0].parent_fraction,
        cylinder: GeneralizedCylinder::new(stem_axis, top.radius, top.radius),
        leaf_at_tip: false,
    };
    let continuation = Branch {
        id: continuation_id,
        parent: Some(0),
        parent_fraction: 1.0,
        cylinder: GeneralizedCylinder::new(
            continuation_axis,
            beyond.cylinder.radius_start,
            beyond.cylinder.radius_end,
        ),
        leaf_at_tip: branches[0].leaf_at_tip,
    };
    for branch in branches.iter_mut().filter(|b| b.parent == Some(0)) {
        let start = branch.cylinder.skeleton.point_at_fraction(0.0);
        if branch.parent_fraction > split_fraction {
            branch.parent = Some(continuation_id);
            branch.parent_fraction = attachment_fraction(&continuation, &start);
        } else {
            branch.parent_fraction = attachment_fraction(&stem, &start);
        }
    }
    branches[0] = stem;
    branches.push(continuation);
    true
}

/// RMS distance of a node's points from its centroid.
fn spread(node: &Node, points: &[Point3<f64>]) -> f64 {
    let sum: f64 = node
        .points
        .iter()
        .map(|&i| (points[i] - node.centroid).norm_squared())
        .sum();
    (sum / node.points.len().max(1) as f64).sqrt()
}

/// How far past its base (in level widths) a side branch's line is fitted to its nodes when
/// it is extended back to the axis it grows out of ([`reanchor_base`]).
const DIRECTION_LEVELS: f64 = 8.0;

/// The least-squares line through `points`: their centroid and main principal axis
/// ([`Shape`]); `None` when they coincide (or are fewer than two).
fn fit_line(points: &[Point3<f64>]) -> Option<(Point3<f64>, Vector3<f64>)> {
    let shape = Shape::of(points.iter().copied());
    (shape.eigenvalues[0] > 0.0 && shape.eigenvalues[0].is_finite())
        .then_some((shape.centroid, shape.axes[0]))
}

/// Where side branches leave a crowded base (a rosette's crown, a whorl), one geodesic level
/// holds several branches at once: its pieces are wide and their centroids lie between the
/// branches, so the chain wanders there, or it follows a neighbouring branch and leaves it
/// with a kink. Looked for among the chain's inner-half nodes within 5 parent radii of the
/// parent's axis: the base is cut after the last wide node (wider than 1.5× the median spread
/// of the chain's outer half) or kink (a step turning more than 45° from the direction of the
/// nodes beyond it; the step from the attachment point counts too). The branch's line past the
/// cut (least squares through its nodes over [`DIRECTION_LEVELS`] level widths, or its inner
/// half where shorter: a short organ curves over its length; a chord over three levels put
/// the bases of sixteen broadleaf photo plants' side branches a median 19.9 mm off in height,
/// the line 15.1 mm) is extended backwards to the axis it passes closest to, in that axis's
/// radii: the parent's or an ancestor's, within 3 radii, at most the branch's kept length
/// away and crossing it at 5° or more (AdTree-like straight connection). A branch that left
/// its parent as a sibling ([`sibling_of`]) is extended past the parent, as far as needed,
/// to the grandparent or above, even with a clean base or none near the parent. A clean base
/// (no wide node, no kink) is extended the same way from its first node: the level sets part
/// a side branch from a bundle of them only where the branches have moved apart, so its chain
/// starts on the parent's axis a level or two above the true insertion (semi-dense broadleaf
/// seeds 1–3 and 21–23: a median 14 mm along the true centreline, and the branch's length
/// short by as much; extended, the median branch length error went 5.5 → 4.4 %). The
/// straight base is kept only where the points support it (see the end of the function).
/// `None` when no axis qualifies or the points do not support the new base.
fn reanchor_base(
    chain: &[usize],
    attachment: Option<Point3<f64>>,
    parent: u32,
    context: &BaseContext,
) -> Option<Anchor> {
    let BaseContext {
        nodes,
        points,
        neighbours,
        branches,
        level_width,
    } = *context;
    const WIDE: f64 = 1.5;
    const DIRECTION_NODES: usize = 4;
    const CROWD_RADII: f64 = 5.0;
    let kink_cosine = 45f64.to_radians().cos();
    if chain.len() <= DIRECTION_NODES {
        return None;
    }
    // The crowded base lies near the parent: only nodes in the chain's inner half and
    // within CROWD_RADII parent radii of the parent's axis are looked at.
    let parent_axis = &branches[parent as usize].cylinder;
    let crowd = CROWD_RADII * parent_axis.radius_start.max(parent_axis.radius_end);
    let inner = (0..chain.len() / 2)
        .take_while(|&k| parent_axis.skeleton.distance_to(&nodes[chain[k]].centroid) <= crowd)
        .count();
    let spreads: Vec<f64> = chain.iter().map(|&v| spread(&nodes[v], points)).collect();
    let mut outer = spreads[chain.len() / 2..].to_vec();
    outer.sort_by(f64::total_cmp);
    let reference = outer[outer.len() / 2];
    if reference.is_nan() || reference <= 0.0 {
        return None;
    }
    let wide = (0..inner)
        .rev()
        .find(|&k| spreads[k] > WIDE * reference)
        .map_or(0, |k| k + 1);
    // Path positions: the attachment point (if any) then the chain's centroids.
    let mut path: Vec<Point3<f64>> = Vec::with_capacity(chain.len() + 1);
    path.extend(attachment);
    let offset = path.len();
    path.extend(chain.iter().map(|&v| nodes[v].centroid));
    // A kink at chain node k: the step to it turns away from the nodes beyond it.
    let is_kink = |k: usize| {
        let here = k + offset;
        if here == 0 {
            return false;
        }
        let ahead = path[here] - path[(here + DIRECTION_NODES - 1).min(path.len() - 1)];
        let back = path[here - 1] - path[here];
        match (ahead.try_normalize(1e-12), back.try_normalize(1e-12)) {
            (Some(a), Some(b)) => a.dot(&b) < kink_cosine,
            _ => false,
        }
    };
    let kinked = (0..inner).rev().find(|&k| is_kink(k));
    let first_clean = wide.max(kinked.unwrap_or(0));
    let kept = &path[first_clean + offset..];
    if kept.len() < DIRECTION_NODES {
        return None;
    }
    // The branch's line: fitted to its nodes over DIRECTION_LEVELS level widths past the cut
    // or half its kept length (DIRECTION_NODES at least), through their mean; a chord over
    // the first few nodes turns with every centroid's noise, and the base is that line
    // extended tens of millimetres.
    let window = (DIRECTION_LEVELS * level_width).min(0.5 * crate::util::polyline::length(kept));
    let mut run = 0.0;
    let fitted = 1 + kept
        .windows(2)
        .take_while(|w| {
            run += (w[1] - w[0]).norm();
            run <= window
        })
        .count();
    let (centre, axis) = fit_line(&kept[..fitted.max(DIRECTION_NODES)])?;
    // Pointing back, from the far nodes towards the cut.
    let direction = if axis.dot(&(kept[0] - kept[DIRECTION_NODES - 1])) >= 0.0 {
        axis
    } else {
        -axis
    };
    let origin = centre + direction * (kept[0] - centre).dot(&direction);
    let grandparent = sibling_of(
        &branches[parent as usize],
        attachment,
        &-direction,
        (kept[DIRECTION_NODES - 1] - origin).norm(),
    );
    // A sibling's base runs alongside its partner all the way to their common parent.
    let mut candidate = grandparent.or(Some(parent));
    let kept_length = match grandparent {
        Some(_) => f64::INFINITY,
        None => crate::util::polyline::length(kept),
    };
    let mut best: Option<(f64, Anchor)> = None;
    while let Some(id) = candidate {
        let branch = &branches[id as usize];
        if let Some(crossing) = closest_crossing(branch, &origin, &direction, kept_length)
            && best.as_ref().is_none_or(|b| crossing.miss < b.0)
        {
            best = Some((
                crossing.miss,
                Anchor {
                    first_clean,
                    parent: id,
                    fraction: crossing.fraction,
                    point: crossing.point,
                },
            ));
        }
        candidate = branch.parent;
    }
    let (_, anchor) = best?;
    // Keep the new base only where the points support it (a chord cutting a curved base
    // does not): ≥ 80 % of its samples, and no fewer (within 0.05) than along the path it
    // replaces; in a dense crown both are fully supported and the straight base wins.
    let parent_radius = branches[anchor.parent as usize]
        .cylinder
        .radius_at(anchor.fraction);
    let tolerance = reference + 0.5 * level_width;
    let step = 0.5 * level_width;
    let new_base = [anchor.point, origin];
    let new_support = support(neighbours, &new_base, 1.5 * parent_radius, step, tolerance)?;
    let old_base = &path[..=first_clean + offset];
    let old_support =
        support(neighbours, old_base, 1.5 * parent_radius, step, tolerance).unwrap_or(0.0);
    (new_support >= 0.8 && new_support + 0.05 >= old_support).then_some(anchor)
}

/// Where a line from `origin` running `direction` passes an axis (see [`closest_crossing`]).
struct Crossing {
    /// Distance between the line and the axis sample, in the axis's radii.
    miss: f64,
    /// Arc fraction and point on the axis.
    fraction: f64,
    point: Point3<f64>,
}

/// The sample of a branch's axis (128 by arc length) that the line from `origin` along
/// `direction` passes closest, in the axis's radii: among samples at most `reach` along the
/// line and crossing it at 5° or more, within 3 radii; `None` when no sample qualifies.
fn closest_crossing(
    branch: &Branch,
    origin: &Point3<f64>,
    direction: &Vector3<f64>,
    reach: f64,
) -> Option<Crossing> {
    const REACH_RADII: f64 = 3.0;
    let crossing_sine = 5f64.to_radians().sin();
    let samples = branch.cylinder.skeleton.sample_by_arc_length(128);
    let last = (samples.len().max(2) - 1) as f64;
    // The best crossing and the index of its sample.
    let mut best: Option<(Crossing, usize)> = None;
    for (i, (point, tangent)) in samples.iter().enumerate() {
        let along = (point - origin).dot(direction);
        if along < 0.0 || along > reach || direction.cross(tangent).norm() < crossing_sine {
            continue;
        }
        let fraction = i as f64 / last;
        let miss = (point - (origin + direction * along)).norm()
            / branch.cylinder.radius_at(fraction).max(1e-12);
        if miss <= REACH_RADII && best.as_ref().is_none_or(|b| miss < b.0.miss) {
            let crossing = Crossing {
                miss,
                fraction,
                point: *point,
            };
            best = Some((crossing, i));
        }
    }
    // Between samples: where the line passes closest to the axis polyline next to the best
    // sample (samples are 1/127 of the axis apart, too coarse for insertion heights).
    let (mut b, i) = best?;
    let refined = [
        i.checked_sub(1).map(|h| (h, i)),
        (i + 1 < samples.len()).then_some((i, i + 1)),
    ]
    .into_iter()
    .flatten()
    .map(|(h, k)| {
        let (u, distance) = line_segment_closest(origin, direction, &samples[h].0, &samples[k].0);
        (h, u, distance)
    })
    .min_by(|x, y| x.2.total_cmp(&y.2));
    if let Some((h, u, _)) = refined {
        b.fraction = ((h as f64 + u) / last).clamp(0.0, 1.0);
        b.point = samples[h].0 + (samples[h + 1].0 - samples[h].0) * u;
    }
    Some(b)
}

/// The closest approach of the line `origin + s·direction` and the segment `ab`: the
/// segment's parameter `u` ∈ [0, 1] and the distance there.
fn line_segment_closest(
    origin: &Point3<f64>,
    direction: &Vector3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
) -> (f64, f64) {
    let d = direction
        .try_normalize(1e-15)
        .unwrap_or_else(Vector3::zeros);
    let e = b - a;
    let w = a - origin;
    // Minimise |w + u·e − s·d|² over s and u: the normal equations of the 2×2 system.
    let (dd, de, ee) = (d.dot(&d), d.dot(&e), e.dot(&e));
    let (dw, ew) = (d.dot(&w), e.dot(&w));
    let denominator = dd * ee - de * de;
    let u = if denominator.abs() < 1e-18 * ee.max(1e-300) {
        0.0
    } else {
        ((de * dw - dd * ew) / denominator).clamp(0.0, 1.0)
    };
    let q = a + e * u;
    let off_line = (q - origin) - d * (q - origin).dot(&d);
    (u, off_line.norm())
}

/// Branches leaving a common parent together (petioles from a crown, twigs from a whorl)
/// share the geodesic levels near it: one of them becomes the other's child, splitting off
/// its partner at a small angle far from the real base. Such a branch is taken for a sibling
/// of its parent when its `outward` direction (at the kept base, over `length`) lies within
/// 30° of the parent's chord from its own base to the split (`attachment`); the chord, not
/// the tangent at the split, because the parent's centroids bend where its partner leaves.
/// Returns the parent's parent, where the sibling's base is looked for.
fn sibling_of(
    parent: &Branch,
    attachment: Option<Point3<f64>>,
    outward: &Vector3<f64>,
    length: f64,
) -> Option<u32> {
    const SIBLING_DEG: f64 = 30.0;
    let grandparent = parent.parent?;
    let axis = &parent.cylinder.skeleton;
    let fraction = attachment.map_or(0.0, |a| attachment_fraction(parent, &a));
    let split = attachment.unwrap_or_else(|| axis.point_at_fraction(0.0));
    let chord = split - axis.point_at_fraction(0.0);
    let direction = if chord.norm() >= length {
        chord.normalize()
    } else {
        axis.tangent(axis.parameter_at_fraction(fraction))
    };
    (outward.dot(&direction) >= SIBLING_DEG.to_radians().cos()).then_some(grandparent)
}

/// What [`reanchor_base`] looks at.
#[derive(Clone, Copy)]
struct BaseContext<'a> {
    nodes: &'a [Node],
    points: &'a [Point3<f64>],
    /// The points' neighbours.
    neighbours: &'a Neighbours,
    branches: &'a [Branch],
    level_width: f64,
}

/// Fraction of samples (every `step` along `line`, those within `skip` of its start left
/// out: inside the parent) that have a point within `tolerance`; `None` without samples.
fn support(
    neighbours: &Neighbours,
    line: &[Point3<f64>],
    skip: f64,
    step: f64,
    tolerance: f64,
) -> Option<f64> {
    let start = *line.first()?;
    let (mut supported, mut total) = (0usize, 0usize);
    for w in line.windows(2) {
        let length = (w[1] - w[0]).norm();
        let count = (length / step).ceil().max(1.0) as usize;
        for i in 0..count {
            let p = w[0] + (w[1] - w[0]) * (i as f64 / count as f64);
            if (p - start).norm() < skip {
                continue;
            }
            total += 1;
            if neighbours
                .nearest(&p)
                .is_some_and(|f| f.distance() <= tolerance)
            {
                supported += 1;
            }
        }
    }
    (total > 0).then(|| supported as f64 / total as f64)
}

/// Arc-length fraction of the point of a branch's skeleton nearest to `p`: the foot of the
/// perpendicular on the curve's dense arc-length polyline, not the nearest of a few samples
/// (64 samples put every insertion on a 1/63 grid of the parent: 6.9 mm on a 44 cm stem,
/// larger than the internodes phyllotaxis measures).
fn attachment_fraction(branch: &Branch, p: &Point3<f64>) -> f64 {
    branch.cylinder.skeleton.closest_fraction(p).0
}

/// A branch through `polyline` (attachment point first for side branches), its radius fitted
/// to the distances of the chain nodes' points from the local axis (linear in arc length).
fn branch_from_chain(
    id: u32,
    parent: Option<u32>,
    parent_fraction: Option<f64>,
    polyline: &[Point3<f64>],
    chain: &[usize],
    nodes: &[Node],
    points: &[Point3<f64>],
) -> Option<Branch> {
    let skeleton = spline_through(polyline)?;
    // (arc fraction, radius) per chain node: median distance from the local axis.
    let offset = polyline.len() - chain.len();
    let mut arc = vec![0.0; polyline.len()];
    for i in 1..polyline.len() {
        arc[i] = arc[i - 1] + (polyline[i] - polyline[i - 1]).norm();
    }
    let total = arc.last().copied().unwrap_or(0.0).max(1e-12);
    let samples: Vec<(f64, f64)> = chain
        .iter()
        .enumerate()
        .filter_map(|(k, &v)| {
            let i = k + offset;
            let before = polyline[i.saturating_sub(1)];
            let after = polyline[(i + 1).min(polyline.len() - 1)];
            let tangent = (after - before).try_normalize(1e-12)?;
            let centre = polyline[i];
            let mut distances: Vec<f64> = nodes[v]
                .points
                .iter()
                .map(|&p| {
                    let d = points[p] - centre;
                    (d - tangent * tangent.dot(&d)).norm()
                })
                .collect();
            if distances.len() < 3 {
                return None;
            }
            distances.sort_by(f64::total_cmp);
            Some((arc[i] / total, distances[distances.len() / 2]))
        })
        .collect();
    let (radius_start, radius_end) = fit_linear(&samples);
    Some(Branch {
        id,
        parent,
        parent_fraction: parent_fraction.unwrap_or(0.0),
        cylinder: GeneralizedCylinder::new(skeleton, radius_start, radius_end),
        leaf_at_tip: false,
    })
}

/// A spline through a polyline's points, consecutive near-duplicates dropped (a spline needs
/// distinct consecutive points); `None` with fewer than two distinct points.
fn spline_through(polyline: &[Point3<f64>]) -> Option<Spline> {
    let mut control: Vec<Point3<f64>> = Vec::with_capacity(polyline.len());
    for p in polyline {
        if control
            .last()
            .is_none_or(|q: &Point3<f64>| (p - q).norm() > 1e-6)
        {
            control.push(*p);
        }
    }
    if control.len() < 2 {
        return None;
    }
    Spline::new(control).ok()
}

/// Least-squares line r(s) = a + b s through (s, r) samples, as (r(0), r(1)), kept positive;
/// the mean when the samples cannot define a slope.
fn fit_linear(samples: &[(f64, f64)]) -> (f64, f64) {
    if samples.is_empty() {
        return (0.001, 0.001);
    }
    let n = samples.len() as f64;
    let mean_s = samples.iter().map(|s| s.0).sum::<f64>() / n;
    let mean_r = samples.iter().map(|s| s.1).sum::<f64>() / n;
    let var_s = samples.iter().map(|s| (s.0 - mean_s).powi(2)).sum::<f64>();
    if samples.len() < 3 || var_s < 1e-9 {
        return (mean_r, mean_r);
    }
    let slope = samples
        .iter()
        .map(|s| (s.0 - mean_s) * (s.1 - mean_r))
        .sum::<f64>()
        / var_s;
    let floor = 0.2 * mean_r;
    let start = (mean_r - slope * mean_s).max(floor);
    let end = (mean_r + slope * (1.0 - mean_s)).max(floor);
    (start, end)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    /// Points on the surface of a tube around a polyline.
    fn tube(axis: &[Point3<f64>], radius: f64, per_metre: f64, rng: &mut Rng) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        for w in axis.windows(2) {
            let d = w[1] - w[0];
            let t = d.normalize();
            let a = crate::branch::any_perpendicular(&t);
            let b = t.cross(&a);
            let count = (d.norm() * per_metre).round() as usize;
            for _ in 0..count {
                let s = rng.uniform();
                let angle = rng.range(0.0, std::f64::consts::TAU);
                out.push(w[0] + d * s + (a * angle.cos() + b * angle.sin()) * radius);
            }
        }
        out
    }

    /// A vertical stem branch (id 0) from the origin up to `top`, of one radius, and its axis.
    fn vertical_stem(top: f64, radius: f64) -> ([Point3<f64>; 2], Branch) {
        let axis = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, top)];
        let stem = Branch {
            id: 0,
            parent: None,
            parent_fraction: 0.0,
            cylinder: GeneralizedCylinder::new(Spline::new(axis.to_vec()).unwrap(), radius, radius),
            leaf_at_tip: false,
        };
        (axis, stem)
    }

    #[test]
    fn insertions_are_placed_between_the_parents_samples() {
        // A 0.44 m stem: its 64 samples are 6.98 mm apart; insertions 1 mm apart must come
        // out 1 mm apart, from a point beside the axis and from a line crossing it.
        let (_, stem) = vertical_stem(0.44, 0.002);
        for k in 0..20 {
            let height = 0.2 + 0.001 * k as f64;
            let beside = Point3::new(0.004, -0.001, height);
            let fraction = attachment_fraction(&stem, &beside);
            assert!((fraction * 0.44 - height).abs() < 1e-5, "{k}: {fraction}");
            // A branch whose base lies 10 mm out, pointing back at the stem 30° downwards.
            let origin = Point3::new(0.01, 0.0, height + 0.01 * 30f64.to_radians().tan());
            let direction = Vector3::new(-1.0, 0.0, -(30f64.to_radians().tan())).normalize();
            let crossing = closest_crossing(&stem, &origin, &direction, 0.05)
                .expect("the line passes through the axis");
            assert!(
                (crossing.fraction * 0.44 - height).abs() < 1e-5,
                "{k}: {}",
                crossing.fraction
            );
            assert!((crossing.point.z - height).abs() < 1e-5);
        }
    }

    #[test]
    fn the_closest_approach_of_a_line_and_a_segment() {
        let a = Point3::new(0.0, 0.0, 0.0);
        let b = Point3::new(0.0, 0.0, 2.0);
        // A horizontal line 0.5 off the segment's axis, at height 1.5.
        let (u, distance) = line_segment_closest(
            &Point3::new(-3.0, 0.5, 1.5),
            &Vector3::new(2.0, 0.0, 0.0),
            &a,
            &b,
        );
        assert!((u - 0.75).abs() < 1e-12 && (distance - 0.5).abs() < 1e-12);
        // Passing above the segment's end: clamped to it.
        let (u, distance) =
            line_segment_closest(&Point3::new(-3.0, 0.0, 3.0), &Vector3::x(), &a, &b);
        assert!((u - 1.0).abs() < 1e-12 && (distance - 1.0).abs() < 1e-12);
    }

    /// The branch whose axis passes nearest `point` (a tree has at least its stem).
    fn nearest_branch<'a>(tree: &'a BranchTree, point: &Point3<f64>) -> &'a Branch {
        tree.branches
            .iter()
            .min_by(|a, b| {
                let near = |b: &Branch| b.cylinder.skeleton.distance_to(point);
                near(a).total_cmp(&near(b))
            })
            .expect("branches")
    }

    /// The default skeleton of points around a vertical axis through the origin.
    fn skeleton_z_up(points: &[Point3<f64>]) -> (BranchTree, SkeletonStats) {
        automatic_skeleton(
            points,
            &Vector3::z(),
            &Point3::origin(),
            &SkeletonOptions::default(),
        )
        .unwrap()
    }

    /// A stem whose foot stands 0.3 off the cameras' axis and that leans in toward it (its
    /// top on the axis), with two side branches: the points nearest the axis are its top.
    fn leaning_stem(rng: &mut Rng) -> Vec<Point3<f64>> {
        let stem = [
            Point3::new(0.3, 0.0, 0.05),
            Point3::new(0.2, 0.0, 0.4),
            Point3::new(0.0, 0.0, 1.0),
        ];
        let low = [Point3::new(0.25, 0.0, 0.225), Point3::new(0.25, 0.2, 0.35)];
        let high = [Point3::new(0.1, 0.0, 0.7), Point3::new(0.1, -0.2, 0.8)];
        let mut points = tube(&stem, 0.01, 10_000.0, rng);
        points.extend(tube(&low, 0.006, 5_000.0, rng));
        points.extend(tube(&high, 0.006, 5_000.0, rng));
        points
    }

    /// Every twentieth of `branch`'s axis lies within `tolerance` of the polyline `truth`.
    fn assert_follows(
        branch: &Branch,
        truth: &[Point3<f64>],
        tolerance: f64,
        stats: &SkeletonStats,
    ) {
        for k in 0..=20 {
            let p = branch.cylinder.skeleton.point_at_fraction(k as f64 / 20.0);
            let off = truth
                .windows(2)
                .map(|w| crate::branch::spline::point_segment_distance(&p, &w[0], &w[1]))
                .fold(f64::INFINITY, f64::min);
            assert!(
                off < tolerance,
                "point {p} of branch {} is {off} off its truth; {stats:?}",
                branch.id
            );
        }
    }

    #[test]
    fn a_stem_off_the_cameras_axis_is_rooted_at_its_foot_over_a_soil_line() {
        let mut rng = Rng::seed_from(11);
        let points = leaning_stem(&mut rng);
        let soil = PlantBase::SoilLine(Point3::origin());
        let (tree, stats) =
            automatic_skeleton_from(&points, &Vector3::z(), &soil, &SkeletonOptions::default())
                .unwrap();
        assert!(stats.rooted_on_soil_line);
        let main = &tree.branches[0];
        assert!(main.parent.is_none());
        // The stem runs from the soil line straight under its foot to its top.
        let start = main.cylinder.skeleton.point_at_fraction(0.0);
        let end = main.cylinder.skeleton.point_at_fraction(1.0);
        assert!(
            start.z.abs() < 1e-9 && (start.x - 0.3).abs() < 0.02,
            "{start}"
        );
        assert!(end.z > 0.95 && end.x.hypot(end.y) < 0.03, "{end}");
        // Along the way it follows the stem (its foot drawn straight down to the soil line).
        let truth = [
            Point3::new(0.3, 0.0, 0.0),
            Point3::new(0.3, 0.0, 0.05),
            Point3::new(0.2, 0.0, 0.4),
            Point3::new(0.0, 0.0, 1.0),
        ];
        assert_follows(main, &truth, 0.02, &stats);
        // Both side branches hang from it (besides spurs of its ring).
        let sides = tree
            .branches
            .iter()
            .filter(|b| b.parent == Some(main.id) && b.cylinder.skeleton.length() > 0.2);
        assert_eq!(sides.count(), 2, "{stats:?}");
    }

    #[test]
    fn a_speck_by_the_soil_line_point_does_not_hold_the_plants_root() {
        // A stem whose foot stands 50 mm from the soil-line point (beyond the joins' reach)
        // and a speck of 40 points 3 mm from it: the plant grows from its own points, its
        // stem drawn from the soil line to the foot and on up, not from the speck.
        let mut rng = Rng::seed_from(23);
        let foot = Point3::new(0.05, 0.0, 0.0);
        let top = Point3::new(0.05, 0.0, 0.4);
        let mut points = tube(&[foot, top], 0.005, 10_000.0, &mut rng);
        for (height, azimuth) in [(0.2f64, 0.3f64), (0.3, 2.4)] {
            let start = Point3::new(0.05, 0.0, height);
            let tip = start + Vector3::new(azimuth.cos(), azimuth.sin(), 0.8) * 0.1;
            points.extend(tube(&[start, tip], 0.003, 8_000.0, &mut rng));
        }
        for _ in 0..40 {
            let offset = Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) * 0.001;
            points.push(Point3::new(0.0, 0.0, 0.003) + offset);
        }
        let soil = PlantBase::SoilLine(Point3::origin());
        let (tree, stats) =
            automatic_skeleton_from(&points, &Vector3::z(), &soil, &SkeletonOptions::default())
                .unwrap();
        assert!(stats.rooted_on_soil_line);
        assert!(
            stats.spacing * SkeletonOptions::default().max_gap < 0.045,
            "the speck must be out of the joins' reach: {stats:?}"
        );
        let main = &tree.branches[0];
        let end = main.cylinder.skeleton.point_at_fraction(1.0);
        assert!(
            end.z > 0.35 && (end.x - 0.05).hypot(end.y) < 0.01,
            "the stem ends at {end}; {stats:?}"
        );
        // From the soil line to the foot, then up the stem.
        let truth = [Point3::origin(), foot, top];
        assert_follows(main, &truth, 0.01, &stats);
        // Both side branches hang from it.
        let sides = tree
            .branches
            .iter()
            .filter(|b| b.parent == Some(main.id) && b.cylinder.skeleton.length() > 0.08);
        assert_eq!(sides.count(), 2, "{stats:?}");
    }

    #[test]
    fn a_stem_off_the_axis_is_rooted_on_the_axis_at_a_known_base() {
        // The same points with the stem's foot taken to be on the axis (a pot's rim centre):
        // the tree grows from the lowest points near the axis, the stem's top, so its main
        // branch does not run from the soil up to the top.
        let mut rng = Rng::seed_from(11);
        let points = leaning_stem(&mut rng);
        let (tree, stats) = skeleton_z_up(&points);
        assert!(!stats.rooted_on_soil_line);
        let main = &tree.branches[0];
        let end = main.cylinder.skeleton.point_at_fraction(1.0);
        let start = main.cylinder.skeleton.point_at_fraction(0.0);
        assert!(start.x.hypot(start.y) < 1e-9, "{start}");
        assert!(end.z < 0.9, "{end}");
    }

    #[test]
    fn a_stem_is_drawn_on_to_its_base_from_its_first_level() {
        // A stem standing on its base: the tree's first node, the centroid of the first level
        // of points, stands most of a level above it. The stem starts at the base, where it
        // leaves the soil, not at that node.
        let mut rng = Rng::seed_from(4);
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.4)];
        let points = tube(&stem, 0.001, 3_000.0, &mut rng);
        let (tree, stats) = skeleton_z_up(&points);
        let main = &tree.branches[0];
        let start = main.cylinder.skeleton.point_at_fraction(0.0);
        assert!(start.coords.norm() < 1e-9, "{start} {stats:?}");
        // The tube from there on: the first level's centroid within a level of the base.
        let next = main.cylinder.skeleton.point_at_fraction(0.01);
        assert!(next.x.hypot(next.y) < 0.001 && next.z < 0.01, "{next}");
    }

    #[test]
    fn a_stem_with_two_side_branches() {
        let mut rng = Rng::seed_from(3);
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.4)];
        let left = [Point3::new(0.0, 0.0, 0.15), Point3::new(-0.15, 0.0, 0.3)];
        let right = [Point3::new(0.0, 0.0, 0.25), Point3::new(0.0, 0.15, 0.35)];
        let mut points = tube(&stem, 0.01, 10_000.0, &mut rng);
        points.extend(tube(&left, 0.004, 4_000.0, &mut rng));
        points.extend(tube(&right, 0.004, 4_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(tree.branches.len(), 3, "{stats:?}");
        let main = &tree.branches[0];
        assert!(main.parent.is_none());
        // The stem runs along z from near the bottom to near the top.
        let start = main.cylinder.skeleton.point_at_fraction(0.0);
        let end = main.cylinder.skeleton.point_at_fraction(1.0);
        assert!(start.z < 0.02 && end.z > 0.37, "{start} {end}");
        for s in 0..=20 {
            let p = main.cylinder.skeleton.point_at_fraction(s as f64 / 20.0);
            assert!(p.x.hypot(p.y) < 0.01, "stem point {p} off axis");
        }
        assert!((main.cylinder.radius_at(0.5) - 0.01).abs() < 0.004);
        // Side branches attach to the stem at about their true heights and follow their axes.
        for (truth, attach_height) in [(&left, 0.15), (&right, 0.25)] {
            let branch = tree
                .branches
                .iter()
                .skip(1)
                .min_by(|a, b| {
                    let far =
                        |x: &Branch| (x.cylinder.skeleton.point_at_fraction(1.0) - truth[1]).norm();
                    far(a).total_cmp(&far(b))
                })
                .unwrap();
            assert_eq!(branch.parent, Some(0));
            let fraction_height = 0.4 * branch.parent_fraction;
            assert!(
                (fraction_height - attach_height).abs() < 0.04,
                "{fraction_height}"
            );
            let tip = branch.cylinder.skeleton.point_at_fraction(1.0);
            assert!((tip - truth[1]).norm() < 0.03, "tip {tip}");
            assert!((branch.cylinder.radius_at(0.6) - 0.004).abs() < 0.003);
        }
    }

    /// The best fraction of a true axis that one skeleton branch passes within `tolerance`.
    fn best_coverage(tree: &BranchTree, axis: &[Point3<f64>], tolerance: f64) -> f64 {
        let samples: Vec<Point3<f64>> = axis
            .windows(2)
            .flat_map(|w| (0..20).map(move |i| w[0] + (w[1] - w[0]) * (i as f64 / 20.0)))
            .collect();
        tree.branches
            .iter()
            .map(|b| {
                let close = samples
                    .iter()
                    .filter(|p| b.cylinder.skeleton.distance_to(p) <= tolerance)
                    .count();
                close as f64 / samples.len() as f64
            })
            .fold(0.0, f64::max)
    }

    /// [`best_coverage`] of each axis from `skip` past its start (outside the stem) on.
    fn coverage_outside(
        tree: &BranchTree,
        axes: &[Vec<Point3<f64>>],
        skip: f64,
        tolerance: f64,
    ) -> Vec<f64> {
        axes.iter()
            .map(|axis| {
                let start = axis[0] + (axis[1] - axis[0]).normalize() * skip;
                let outside: Vec<Point3<f64>> = std::iter::once(start)
                    .chain(axis[1..].iter().copied())
                    .collect();
                best_coverage(tree, &outside, tolerance)
            })
            .collect()
    }

    #[test]
    fn a_thick_knot_on_a_thin_stem_does_not_end_it() {
        // A 3 mm stem, 0.3 m tall, with a 12 mm knot around it at 5-8 cm (a rosette's base,
        // a smeared bud) and a side branch leaving just above the knot: the chain below the
        // fork is mostly thin, so the stem goes on through it.
        let mut rng = Rng::seed_from(8);
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.3)];
        let knot = [Point3::new(0.0, 0.0, 0.05), Point3::new(0.0, 0.0, 0.08)];
        let side = [Point3::new(0.0, 0.0, 0.082), Point3::new(0.12, 0.0, 0.17)];
        let mut points = tube(&stem, 0.003, 6000.0, &mut rng);
        points.extend(tube(&knot, 0.012, 60_000.0, &mut rng));
        points.extend(tube(&side, 0.003, 6000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.stems_ended, 0, "{stats:?}");
        let top = tree.branches[0].cylinder.skeleton.point_at_fraction(1.0);
        assert!(top.z > 0.27, "the stem stopped at {top}: {stats:?}");
    }

    #[test]
    fn a_stems_levels_are_recentred_on_its_axis_up_to_a_level_that_disagrees() {
        // A 6 mm stem about (20 mm, 0): levels 1-4, 6 and 7 hold 200° arcs on the side the
        // root stands (centroids off the axis), level 0 a 2 mm arc about the root, level 5 a
        // 20 mm ring (a side branch's points in the level).
        let axis = Point3::new(0.02, 0.0, 0.0);
        let up = Vector3::z();
        let mut points = Vec::new();
        let mut nodes = Vec::new();
        for k in 0..8usize {
            let z = 0.01 * k as f64;
            let (centre, radius, from, span) = match k {
                0 => (Point3::new(0.026, 0.0, z), 0.002, -0.5, 1.0),
                5 => (Point3::new(0.02, 0.0, z), 0.02, 0.0, std::f64::consts::TAU),
                _ => (Point3::new(0.02, 0.0, z), 0.006, -1.75, 3.5),
            };
            let first = points.len();
            points.extend((0..12).map(|j| {
                let a = from + span * j as f64 / 12.0;
                centre + Vector3::new(radius * a.cos(), radius * a.sin(), 0.0)
            }));
            let centroid = Point3::from(
                points[first..]
                    .iter()
                    .map(|p| p.coords)
                    .sum::<Vector3<f64>>()
                    / 12.0,
            );
            nodes.push(Node {
                centroid,
                points: (first..points.len()).collect(),
                parent: k.checked_sub(1),
                children: if k < 7 { vec![k + 1] } else { Vec::new() },
                distance: z,
            });
        }
        let chain: Vec<usize> = (0..8).collect();
        let centres = ring_centres(&chain, &nodes, &points, &up);
        for (k, centre) in centres.iter().enumerate().take(5) {
            let off = ((centre.x - axis.x).powi(2) + (centre.y - axis.y).powi(2)).sqrt();
            assert!(off < 1e-6, "level {k}: {off} off the axis");
            assert!(
                (centre.z - nodes[k].centroid.z).abs() < 1e-12,
                "level {k} moved up"
            );
        }
        assert!(
            nodes[1].centroid.x > 0.022,
            "the arcs' centroids stand off the axis"
        );
        for k in 5..8 {
            assert_eq!(centres[k], nodes[k].centroid, "level {k} is kept");
        }
        assert_eq!(ring_centres(&[], &nodes, &points, &up), Vec::new());
    }

    #[test]
    fn a_stem_that_goes_on_bearing_organs_above_a_thinning_does_not_end_there() {
        // A main axis of 30 level nodes 1 cm apart, rings of 8 points: radius 6 mm up to node
        // 9 (a smeared lower stem), 2 mm above. Side branches (a second child, outside the
        // chain) leave at nodes 3, 6 and 9 (the fork where it thins), and at `above` nodes
        // beyond it.
        let chain_of = |above: &[usize]| {
            let mut points = Vec::new();
            let mut nodes = Vec::new();
            for k in 0..30usize {
                let radius = if k <= 9 { 0.006 } else { 0.002 };
                let z = 0.01 * k as f64;
                let first = points.len();
                points.extend((0..8).map(|j| {
                    let a = std::f64::consts::TAU * j as f64 / 8.0;
                    Point3::new(radius * a.cos(), radius * a.sin(), z)
                }));
                let mut children = if k < 29 { vec![k + 1] } else { Vec::new() };
                if k == 3 || k == 6 || k == 9 || above.contains(&k) {
                    children.push(1000 + k);
                }
                nodes.push(Node {
                    centroid: Point3::new(0.0, 0.0, z),
                    points: (first..points.len()).collect(),
                    parent: k.checked_sub(1),
                    children,
                    distance: z,
                });
            }
            (nodes, points)
        };
        let chain: Vec<usize> = (0..30).collect();
        // Bare above the thinning (a petiole over a crown): the stem ends at the fork.
        let (nodes, points) = chain_of(&[]);
        let top = stem_top(&chain, &nodes, &points).expect("the stem ends");
        assert_eq!(top.fork, 9);
        assert!((top.radius - 0.006).abs() < 1e-9, "{}", top.radius);
        // One side branch beyond it (fewer than half the three up to it): still ends.
        let (nodes, points) = chain_of(&[20]);
        assert_eq!(stem_top(&chain, &nodes, &points).map(|t| t.fork), Some(9));
        // Bearing as many side branches beyond it as up to it, as an inflorescence bears its
        // fruits: the stem goes on (the old rule ended it at node 9).
        let (nodes, points) = chain_of(&[14, 20, 25]);
        assert!(stem_top(&chain, &nodes, &points).is_none());
    }

    #[test]
    fn petioles_leaving_a_crowded_crown_start_on_the_stem() {
        const PETIOLES: usize = 10;
        const SPREAD: f64 = 0.03;
        const DENSITY: f64 = 8000.0;
        // A short thick stem with ten petioles leaving near its top: the geodesic
        // levels around the crown hold several petioles at once.
        let mut rng = Rng::seed_from(11);
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.07)];
        let mut points = tube(&stem, 0.012, 30_000.0, &mut rng);
        let mut petioles = Vec::new();
        for i in 0..PETIOLES {
            let azimuth = i as f64 * std::f64::consts::TAU / PETIOLES as f64;
            let (c, s) = (azimuth.cos(), azimuth.sin());
            let base = Point3::new(0.0, 0.0, 0.05 + 0.001 * i as f64);
            let axis = vec![
                base,
                base + Vector3::new(SPREAD * c, SPREAD * s, 0.06),
                base + Vector3::new(0.1 * c, 0.1 * s, 0.12),
            ];
            points.extend(tube(&axis, 0.0035, DENSITY, &mut rng));
            petioles.push(axis);
        }
        let (tree, stats) = skeleton_z_up(&points);
        // Outside the stem (radius 12 mm), how much of each petiole one branch follows to
        // within 2 of its radii (the eval's tolerance for such a branch).
        let covered = coverage_outside(&tree, &petioles, 0.015, 0.007);
        let mean = covered.iter().sum::<f64>() / covered.len() as f64;
        // Measured: mean 0.92 with re-anchored bases, 0.87 when the chains' wandering bases
        // are kept (each petiole's base then follows a neighbour's through the crown).
        assert!(stats.bases_reanchored >= 3, "{stats:?}");
        assert!(mean >= 0.9, "{covered:?} {stats:?}");
        assert!(covered.iter().all(|&c| c >= 0.7), "{covered:?} {stats:?}");
    }

    #[test]
    fn a_clean_base_that_starts_late_is_extended_to_where_it_leaves_the_stem() {
        let mut rng = Rng::seed_from(21);
        let (stem_axis, stem) = vertical_stem(0.2, 0.006);
        let mut points = tube(&stem_axis, 0.006, 12_000.0, &mut rng);
        // A straight petiole leaving the stem's axis at 60 mm, 30° from the vertical. The
        // level sets parted it from the stem 20 mm along it: its chain starts there, straight
        // and clean (no wide node, no kink), attached to the stem's axis at that height.
        let direction = Vector3::new(30f64.to_radians().sin(), 0.0, 30f64.to_radians().cos());
        let base = Point3::new(0.0, 0.0, 0.06);
        let petiole_start = points.len();
        points.extend(tube(
            &[base, base + direction * 0.12],
            0.0025,
            8_000.0,
            &mut rng,
        ));
        let level_width = 0.004;
        let nodes: Vec<Node> = (0..25)
            .map(|k| {
                let along = 0.02 + level_width * k as f64;
                let members: Vec<usize> = (petiole_start..points.len())
                    .filter(|&i| ((points[i] - base).dot(&direction) - along).abs() <= 0.002)
                    .collect();
                let centroid = members.iter().fold(Point3::origin(), |c, &i| {
                    c + points[i].coords / members.len() as f64
                });
                Node {
                    centroid,
                    points: members,
                    parent: None,
                    children: Vec::new(),
                    distance: along,
                }
            })
            .collect();
        let chain: Vec<usize> = (0..nodes.len()).collect();
        // The split node on the stem's axis, a little below the chain's first centroid (the
        // step from it is no kink: 33° off the petiole's direction).
        let split = Point3::new(0.0, 0.0, nodes[0].centroid.z - 0.005);
        let neighbours = Neighbours::new(points.iter().copied()).unwrap();
        let branches = vec![stem];
        let context = BaseContext {
            nodes: &nodes,
            points: &points,
            neighbours: &neighbours,
            branches: &branches,
            level_width,
        };
        let anchor = reanchor_base(&chain, Some(split), 0, &context).expect("a new base");
        assert_eq!((anchor.parent, anchor.first_clean), (0, 0));
        // It meets the stem where the petiole leaves it (60 mm), not at the split (72 mm).
        assert!((anchor.point.z - 0.06).abs() < 0.004, "{:?}", anchor.point);
        assert!(split.z > 0.07, "{split}");
    }

    #[test]
    fn petioles_running_side_by_side_start_on_the_stem() {
        const PAIRS: usize = 4;
        // Pairs of petioles leave a stem together, 12° apart in azimuth: near the stem each
        // pair is one tube in the geodesic levels, so one petiole of each pair splits off
        // its partner at a small angle, far from the stem.
        let mut rng = Rng::seed_from(5);
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.1)];
        let mut points = tube(&stem, 0.006, 6_000.0, &mut rng);
        let mut petioles = Vec::new();
        for pair in 0..PAIRS {
            for side in [-0.5, 0.5] {
                let azimuth = (pair as f64 * 90.0 + side * 12.0).to_radians();
                let direction = Vector3::new(
                    azimuth.cos() * 35f64.to_radians().sin(),
                    azimuth.sin() * 35f64.to_radians().sin(),
                    35f64.to_radians().cos(),
                );
                let base = Point3::new(0.0, 0.0, 0.06 + 0.012 * pair as f64);
                let axis = vec![base, base + direction * 0.16];
                points.extend(tube(&axis, 0.003, 3_000.0, &mut rng));
                petioles.push(axis);
            }
        }
        let (tree, stats) = skeleton_z_up(&points);
        // Outside the stem, how much of each petiole one branch follows to within 2 of its
        // radii (the eval's tolerance).
        let covered = coverage_outside(&tree, &petioles, 0.01, 0.006);
        let on_stem = tree.branches.iter().filter(|b| b.parent == Some(0)).count();
        let mean = covered.iter().sum::<f64>() / covered.len() as f64;
        // Measured: 7 side branches start on the stem (one of them recovered from unexplained
        // points), mean coverage 0.81; without the sibling rule 5 (one of each pair starts on
        // its partner) and 0.73. The stem itself runs on into one petiole, so that one's
        // partner stays its child.
        assert!(on_stem >= 6, "{on_stem} on the stem, {covered:?} {stats:?}");
        assert!(mean >= 0.78, "{covered:?} {stats:?}");
    }

    /// Runs [`recover_missed_tubes`] on `points` against `branches`, with brute-force edges
    /// (within a level width of 4 mm) and the distance from the lowest point for geodesic.
    fn recover(branches: &mut Vec<Branch>, points: &[Point3<f64>]) -> usize {
        let level_width = 0.004;
        let edges: Vec<Vec<(usize, f64)>> = points
            .iter()
            .map(|p| {
                points
                    .iter()
                    .enumerate()
                    .map(|(j, q)| (j, (p - q).norm()))
                    .filter(|&(_, d)| d > 0.0 && d <= level_width)
                    .collect()
            })
            .collect();
        let root = points
            .iter()
            .min_by(|a, b| a.z.total_cmp(&b.z))
            .copied()
            .unwrap();
        let distance: Vec<f64> = points.iter().map(|p| (p - root).norm()).collect();
        let neighbours = Neighbours::new(points.iter().copied()).unwrap();
        recover_missed_tubes(
            branches,
            &TubeContext {
                points,
                edges: &edges,
                distance: &distance,
                neighbours: &neighbours,
                level_width,
                min_points: 12,
                min_length: 3.0 * level_width,
            },
        )
    }

    #[test]
    fn a_tube_no_branch_explains_becomes_a_branch_from_the_stem() {
        let mut rng = Rng::seed_from(8);
        let (stem_axis, stem) = vertical_stem(0.12, 0.005);
        let mut points = tube(&stem_axis, 0.005, 6_000.0, &mut rng);
        // A petiole from the stem at 60 mm, 40° from vertical; its first 25 mm hug the
        // stem's own points, the rest is unexplained.
        let direction = Vector3::new(40f64.to_radians().sin(), 0.0, 40f64.to_radians().cos());
        let base = Point3::new(0.0, 0.0, 0.06);
        let petiole = [base, base + direction * 0.1];
        points.extend(tube(&petiole, 0.0025, 3_000.0, &mut rng));
        // A flat strip (a leaf fragment) and a tube floating away from every axis: neither
        // is a branch.
        for _ in 0..600 {
            let (u, v) = (rng.uniform(), rng.uniform());
            points.push(Point3::new(
                -0.02 - 0.06 * u,
                0.01 * v,
                0.05 + 0.001 * rng.uniform(),
            ));
        }
        let floating = [Point3::new(0.0, 0.06, 0.05), Point3::new(0.0, 0.12, 0.05)];
        points.extend(tube(&floating, 0.0025, 3_000.0, &mut rng));

        let mut branches = vec![stem];
        assert_eq!(recover(&mut branches, &points), 1);
        let found = &branches[1];
        assert_eq!(found.parent, Some(0));
        let height = 0.12 * found.parent_fraction;
        assert!((height - 0.06).abs() < 0.01, "attached at {height}");
        // Outside the stem, it follows the petiole.
        for s in 0..=10 {
            let p = found.cylinder.skeleton.point_at_fraction(s as f64 / 10.0);
            if p.x.hypot(p.y) < 0.005 {
                continue;
            }
            let miss = crate::branch::spline::point_segment_distance(&p, &petiole[0], &petiole[1]);
            assert!(miss < 0.004, "{p} is {miss} from the petiole's axis");
        }
        let tip = found.cylinder.skeleton.point_at_fraction(1.0);
        assert!((tip - petiole[1]).norm() < 0.01, "tip {tip}");
        assert!((found.cylinder.radius_at(0.5) - 0.0025).abs() < 0.0015);
        // Once it is found, nothing is left to recover.
        assert_eq!(recover(&mut branches, &points), 0);
    }

    #[test]
    fn the_far_edge_of_a_smeared_organ_is_no_organ_of_its_own() {
        let mut rng = Rng::seed_from(21);
        let straight = |a: Point3<f64>, b: Point3<f64>, radius: f64| Branch {
            id: 0,
            parent: None,
            parent_fraction: 0.0,
            cylinder: GeneralizedCylinder::new(Spline::new(vec![a, b]).unwrap(), radius, radius),
            leaf_at_tip: false,
        };
        let stem_axis = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.12)];
        let mut points = tube(&stem_axis, 0.004, 6_000.0, &mut rng);
        // A fruit from the stem at 50 mm, 40° from vertical, fitted with its own radius;
        // stereo smeared it sideways: a second band of points 8 mm beside it, parallel to
        // it over its whole length (the fitted branch explains only 3 mm + a level width).
        let direction = Vector3::new(40f64.to_radians().sin(), 0.0, 40f64.to_radians().cos());
        let base = Point3::new(0.0, 0.0, 0.05);
        let fruit = [base, base + direction * 0.1];
        points.extend(tube(&fruit, 0.003, 3_000.0, &mut rng));
        let aside = Vector3::new(0.0, 0.008, 0.0);
        let smear = [fruit[0] + aside, fruit[1] + aside];
        points.extend(tube(&smear, 0.002, 3_000.0, &mut rng));
        let mut branches = vec![straight(stem_axis[0], stem_axis[1], 0.004)];
        let mut fitted = straight(fruit[0], fruit[1], 0.003);
        fitted.id = 1;
        fitted.parent = Some(0);
        fitted.parent_fraction = 0.05 / 0.12;
        branches.push(fitted.clone());
        assert_eq!(
            recover(&mut branches, &points),
            0,
            "the twin became a branch"
        );
        // A second fruit from the same node that turns away from the first one is an organ.
        let away = Vector3::new(0.0, -50f64.to_radians().sin(), 50f64.to_radians().cos());
        let sibling = [base, base + away * 0.1];
        points.extend(tube(&sibling, 0.0025, 3_000.0, &mut rng));
        let mut branches = vec![straight(stem_axis[0], stem_axis[1], 0.004), fitted];
        assert_eq!(recover(&mut branches, &points), 1);
        let tip = branches[2].cylinder.skeleton.point_at_fraction(1.0);
        assert!((tip - sibling[1]).norm() < 0.01, "tip {tip}");
    }

    /// A 0.3 stem with 10,000 points per metre and a petiole leaving it at 0.2 for (0.2, 0,
    /// 0.35), seen only beyond `hidden` of its length (photos miss its base behind the leaves):
    /// the points, the petiole's base and its tip.
    fn stem_and_petiole_seen_from(
        hidden: f64,
        rng: &mut Rng,
    ) -> (Vec<Point3<f64>>, Point3<f64>, Point3<f64>) {
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.3)];
        let mut points = tube(&stem, 0.004, 10_000.0, rng);
        let base = Point3::new(0.0, 0.0, 0.2);
        let tip = Point3::new(0.2, 0.0, 0.35);
        points.extend(tube(
            &[base + (tip - base) * hidden, tip],
            0.002,
            5_000.0,
            rng,
        ));
        (points, base, tip)
    }

    #[test]
    fn a_petiole_seen_only_near_its_leaf_is_bridged_to_the_stem() {
        let mut rng = Rng::seed_from(11);
        // The petiole leaves the stem at 0.2 m; only its outer 60 % has points (the photos
        // never see its base behind the leaves).
        let (mut points, base, tip) = stem_and_petiole_seen_from(0.4, &mut rng);
        // A piece of tube low down beside the plant, running across the way to the stem: no
        // plausible bridge starts from it.
        let stray = [
            Point3::new(0.25, -0.05, 0.02),
            Point3::new(0.25, 0.05, 0.02),
        ];
        points.extend(tube(&stray, 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        // The whole petiole is drawn, its hidden base straight back to the stem.
        let coverage = best_coverage(&tree, &[base, tip], 0.01);
        assert!(coverage > 0.9, "petiole coverage {coverage}");
        let petiole = nearest_branch(&tree, &tip);
        assert_eq!(petiole.parent, Some(0));
        let start = petiole.cylinder.skeleton.point_at_fraction(0.0);
        assert!((start - base).norm() < 0.02, "petiole starts at {start:?}");
        // Nothing is drawn along the stray piece.
        let stray_coverage = best_coverage(&tree, &stray, 0.01);
        assert!(stray_coverage < 0.2, "stray coverage {stray_coverage}");
    }

    #[test]
    fn a_noisy_side_branch_meets_its_stem_where_its_fitted_line_does() {
        // A side branch leaving a 16 mm stem at 0.1 m, 35° from it, its points jittered by
        // 1 mm (stereo noise): its level sets part from the stem's a few centimetres out and
        // the base is its line extended back. Over sixteen samplings the fitted line puts it
        // a median 0.8 mm from the junction in height (15 within 4 mm); the chord over the
        // first three levels put it a median 4.2 mm off (7 within 4 mm).
        let mut off = Vec::new();
        for seed in 0..16 {
            let mut rng = Rng::seed_from(seed);
            let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.3)];
            let mut points = tube(&stem, 0.008, 20_000.0, &mut rng);
            let junction = Point3::new(0.0, 0.0, 0.1);
            let angle = 35f64.to_radians();
            let tip = junction + Vector3::new(angle.sin(), 0.0, angle.cos()) * 0.2;
            points.extend(tube(&[junction, tip], 0.003, 8_000.0, &mut rng));
            for p in &mut points {
                *p += Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.001;
            }
            let (tree, _) = skeleton_z_up(&points);
            let branch = nearest_branch(&tree, &tip);
            assert_eq!(branch.parent, Some(0), "seed {seed}");
            off.push((branch.cylinder.skeleton.point_at_fraction(0.0).z - junction.z).abs());
        }
        off.sort_by(f64::total_cmp);
        let within = off.iter().filter(|&&d| d < 0.004).count();
        assert!(off[off.len() / 2] < 0.002 && within >= 14, "{off:?}");
    }

    #[test]
    fn a_sparse_trunk_apart_from_the_crown_is_where_the_plant_grows_from() {
        // A stem's foot stereo sampled sparsely (its own component, out of the joins' reach of
        // the crown's) and a denser crown above it: the plant grows from the foot, not from the
        // crown's lowest point with one straight line up to it.
        let mut rng = Rng::seed_from(17);
        let mut points = tube(
            &[Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.06)],
            0.005,
            6_000.0,
            &mut rng,
        );
        let foot = points.len();
        let stem = [Point3::new(0.0, 0.0, 0.1), Point3::new(0.0, 0.0, 0.3)];
        points.extend(tube(&stem, 0.005, 12_000.0, &mut rng));
        for (height, azimuth) in [(0.15f64, 0.5f64), (0.22, 2.6), (0.27, 4.4)] {
            let start = Point3::new(0.0, 0.0, height);
            let tip = start + Vector3::new(azimuth.cos(), azimuth.sin(), 1.0) * 0.08;
            points.extend(tube(&[start, tip], 0.003, 12_000.0, &mut rng));
        }
        assert!(points.len() - foot > 2 * foot);
        let (tree, stats) = skeleton_z_up(&points);
        // The crown is out of the joins' reach of the foot: a piece bridged to it.
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        let stem = &tree.branches[0];
        let first = stem.cylinder.skeleton.control_points()[1];
        assert!(
            first.z < 0.02,
            "the stem's first node is at {first}; {stats:?}"
        );
        // The crown hangs from the foot's stem.
        let top = nearest_branch(&tree, &Point3::new(0.0, 0.0, 0.25));
        let mut ancestor = top;
        for _ in 0..tree.branches.len() {
            match ancestor.parent {
                Some(p) => ancestor = &tree.branches[p as usize],
                None => break,
            }
        }
        assert_eq!(
            ancestor.id, 0,
            "the crown's branch {} hangs from no stem",
            top.id
        );
        assert!(
            top.cylinder
                .skeleton
                .distance_to(&Point3::new(0.0, 0.0, 0.25))
                < 0.005
        );
    }

    #[test]
    fn a_line_is_fitted_through_noisy_points_and_not_through_one_place() {
        let mut rng = Rng::seed_from(31);
        let direction = Vector3::new(1.0, 2.0, -2.0) / 3.0;
        let start = Point3::new(0.1, -0.2, 0.3);
        let points: Vec<Point3<f64>> = (0..40)
            .map(|i| {
                let jitter = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.002;
                start + direction * (0.005 * i as f64) + jitter
            })
            .collect();
        let (centre, axis) = fit_line(&points).expect("a line");
        assert!(axis.dot(&direction).abs() > 0.995, "axis {axis:?}");
        let off_line = (centre - start) - direction * (centre - start).dot(&direction);
        assert!(
            off_line.norm() < 0.002,
            "the line misses its points by {off_line:?}"
        );
        assert!(fit_line(&[start; 5]).is_none());
        assert!(fit_line(&[start]).is_none());
    }

    #[test]
    fn a_piece_is_not_bridged_onto_another_pieces_bridge() {
        let mut rng = Rng::seed_from(13);
        // A petiole seen in its outer 60 %, bridged to the stem through (0.04, 0, 0.23).
        let (mut points, _, _) = stem_and_petiole_seen_from(0.4, &mut rng);
        // A shorter piece pointing straight at the middle of that bridge (6 cm off), with the
        // stem 35° off its way back: the bridge is drawn where no point is, so the piece goes
        // to the stem.
        let (from, to) = (Point3::new(0.04, 0.06, 0.23), Point3::new(0.04, 0.16, 0.25));
        points.extend(tube(&[from, to], 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 2, "{stats:?}");
        assert_starts_on_the_stem(nearest_branch(&tree, &to));
    }

    /// A branch hangs from the stem (id 0) and starts within 1 cm of its axis.
    fn assert_starts_on_the_stem(branch: &Branch) {
        assert_eq!(branch.parent, Some(0), "{:?}", branch.parent);
        let start = branch.cylinder.skeleton.point_at_fraction(0.0);
        assert!(start.coords.xy().norm() < 0.01, "starts at {start:?}");
    }

    #[test]
    fn a_piece_is_not_bridged_onto_the_middle_of_another_piece() {
        let mut rng = Rng::seed_from(15);
        // A petiole seen in its outer 60 %, bridged to the stem.
        let (mut points, base, tip) = stem_and_petiole_seen_from(0.4, &mut rng);
        // Beside it, 6 cm off, a piece whose way back passes 6° from the middle of that
        // petiole, with the stem 37° off it: a branch out of the petiole's middle would be
        // hidden at its junction as well as at its base, so the piece goes to the stem.
        let (from, to) = (Point3::new(0.18, 0.06, 0.33), Point3::new(0.24, 0.15, 0.36));
        points.extend(tube(&[from, to], 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 2, "{stats:?}");
        let petiole = nearest_branch(&tree, &(base + (tip - base) * 0.7));
        let piece = nearest_branch(&tree, &(from + (to - from) * 0.5));
        assert_ne!(piece.id, petiole.id);
        assert_starts_on_the_stem(piece);
    }

    #[test]
    fn a_piece_beyond_another_pieces_tip_continues_it() {
        let mut rng = Rng::seed_from(16);
        // A petiole seen from 40 % to 75 % of its length and again from 85 % to its end: the
        // outer piece is bridged across the gap to the inner one's tip, not to the stem
        // along the same line, which would draw the middle of the petiole twice.
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.3)];
        let mut points = tube(&stem, 0.004, 10_000.0, &mut rng);
        let base = Point3::new(0.0, 0.0, 0.2);
        let tip = Point3::new(0.2, 0.0, 0.35);
        let at = |s: f64| base + (tip - base) * s;
        points.extend(tube(&[at(0.4), at(0.75)], 0.002, 5_000.0, &mut rng));
        points.extend(tube(&[at(0.85), tip], 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 2, "{stats:?}");
        let inner = nearest_branch(&tree, &at(0.6));
        let outer = nearest_branch(&tree, &at(0.95));
        assert_ne!(inner.id, outer.id);
        assert_eq!(inner.parent, Some(0), "{:?}", inner.parent);
        assert_eq!(outer.parent, Some(inner.id), "{:?}", outer.parent);
        let start = outer.cylinder.skeleton.point_at_fraction(0.0);
        assert!((start - at(0.75)).norm() < 0.02, "starts at {start:?}");
    }

    #[test]
    fn a_piece_at_a_right_angle_to_another_pieces_tip_does_not_continue_it() {
        let mut rng = Rng::seed_from(17);
        // A petiole seen in its outer 60 %, bridged to the stem.
        let (mut points, base, tip) = stem_and_petiole_seen_from(0.4, &mut rng);
        // 3 cm beside its tip, a piece pointing straight back at that tip, but leaving it at
        // a right angle to the petiole's way: no continuation of it, and no other axis lies
        // within 40° of its way back, so it is left out.
        let (from, to) = (
            tip + Vector3::new(0.0, 0.03, 0.0),
            tip + Vector3::new(0.0, 0.13, 0.03),
        );
        points.extend(tube(&[from, to], 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        let petiole = best_coverage(&tree, &[base, tip], 0.01);
        assert!(petiole > 0.9, "petiole coverage {petiole}");
        let beside = best_coverage(&tree, &[from, to], 0.01);
        assert!(
            beside < 0.2,
            "coverage of the piece beside the tip {beside}"
        );
    }

    #[test]
    fn a_crown_of_petioles_seen_apart_from_a_short_stem_is_bridged_where_they_converge() {
        let mut rng = Rng::seed_from(18);
        // A short stem (0.15 m, as a rosette plant's) and, 7 cm above its top and 3 cm off
        // its axis, two petioles seen from where they meet (`hub`) outward, rising at 50°
        // on either side (azimuths 80° and 280°). Each one's own way back passes 48° from
        // the stem, outside the 40° cone; the way they converge on the hub (from their
        // centroid: nearly straight down) passes 31° from it.
        let stem = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.15)];
        let mut points = tube(&stem, 0.004, 10_000.0, &mut rng);
        let hub = Point3::new(-0.03, 0.0, 0.22);
        let rise = 50f64.to_radians();
        let tips: Vec<Point3<f64>> = [(80f64, 0.2), (280.0, 0.15)]
            .iter()
            .map(|&(azimuth, length): &(f64, f64)| {
                let a = azimuth.to_radians();
                hub + Vector3::new(a.cos() * rise.cos(), a.sin() * rise.cos(), rise.sin()) * length
            })
            .collect();
        for tip in &tips {
            points.extend(tube(&[hub, *tip], 0.002, 5_000.0, &mut rng));
        }
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        for tip in &tips {
            let coverage = best_coverage(&tree, &[hub, *tip], 0.01);
            assert!(coverage > 0.8, "petiole to {tip:?}: coverage {coverage}");
            // Each hangs from the stem, through the crown's bridge.
            let mut ancestor = nearest_branch(&tree, tip);
            for _ in 0..tree.branches.len() {
                match ancestor.parent {
                    Some(p) => ancestor = &tree.branches[p as usize],
                    None => break,
                }
            }
            assert_eq!(ancestor.id, 0, "the petiole to {tip:?} hangs from no stem");
        }
    }

    #[test]
    fn a_piece_hanging_from_its_end_nearest_the_root_is_not_bridged() {
        let mut rng = Rng::seed_from(14);
        // A rising petiole seen in its outer 60 %: bridged to the stem.
        let (mut points, base, tip) = stem_and_petiole_seen_from(0.4, &mut rng);
        // On the other side, a tube as round and as long, 0.1 m off the stem, that runs
        // outward and down from its end nearest the root (20° below the horizontal): its way
        // back to the stem climbs, nothing is seen between, so no bridge is drawn.
        let (from, to) = (Point3::new(-0.1, 0.0, 0.26), Point3::new(-0.25, 0.0, 0.205));
        points.extend(tube(&[from, to], 0.002, 5_000.0, &mut rng));
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        let petiole = best_coverage(&tree, &[base, tip], 0.01);
        assert!(petiole > 0.9, "petiole coverage {petiole}");
        let hanging = best_coverage(&tree, &[from, to], 0.01);
        assert!(hanging < 0.2, "hanging piece coverage {hanging}");
    }

    #[test]
    fn a_flat_band_far_from_the_tree_is_not_bridged() {
        let mut rng = Rng::seed_from(12);
        // A petiole seen only in its outer 40 %: a round piece whose bridge (0.15 m) is longer
        // than itself (0.1 m), drawn because it is a tube.
        let (mut points, base, tip) = stem_and_petiole_seen_from(0.6, &mut rng);
        // On the other side, a band 8 mm wide and 0.1 m long with no thickness to speak of
        // (a leaf's edge, stereo's halo beside a leaf), pointing at the stem from 0.15 m away.
        let (from, to) = (Point3::new(-0.12, 0.0, 0.29), Point3::new(-0.2, 0.0, 0.35));
        let across = Vector3::y();
        for _ in 0..500 {
            let s = rng.uniform();
            let w = rng.range(-0.004, 0.004);
            let thickness = rng.range(-0.0002, 0.0002);
            let normal = (to - from).normalize().cross(&across);
            points.push(from + (to - from) * s + across * w + normal * thickness);
        }
        let (tree, stats) = skeleton_z_up(&points);
        assert_eq!(stats.pieces_bridged, 1, "{stats:?}");
        let petiole = best_coverage(&tree, &[base, tip], 0.01);
        assert!(petiole > 0.9, "petiole coverage {petiole}");
        let band = best_coverage(&tree, &[from, to], 0.01);
        assert!(band < 0.2, "band coverage {band}");
    }

    #[test]
    fn support_tells_observed_from_bridged_length() {
        let mut rng = Rng::seed_from(2);
        let axis = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 0.4)];
        let tree = BranchTree {
            branches: vec![Branch {
                id: 0,
                parent: None,
                parent_fraction: 0.0,
                cylinder: GeneralizedCylinder::new(
                    Spline::new(axis.to_vec()).expect("spline"),
                    0.004,
                    0.004,
                ),
                leaf_at_tip: false,
            }],
        };
        // Points on the lower quarter only.
        let points = tube(
            &[axis[0], Point3::new(0.0, 0.0, 0.1)],
            0.004,
            10_000.0,
            &mut rng,
        );
        let support = crate::branch::plant::branch_support(&tree, &points, 0.002, 0.002);
        assert_eq!(support.len(), 1);
        let s = support[0];
        assert!((s.observed_length - 0.1).abs() < 0.01, "{s:?}");
        assert!((s.bridged_length - 0.3).abs() < 0.01, "{s:?}");
        assert!((s.observed_fraction() - 0.25).abs() < 0.03);
        let none = crate::branch::plant::branch_support(&tree, &[], 0.002, 0.002);
        assert_eq!(none[0].observed_length, 0.0);
    }

    #[test]
    fn degenerate_input_is_an_error() {
        let few = vec![Point3::new(0.0, 0.0, 0.0); 5];
        assert!(matches!(
            automatic_skeleton(
                &few,
                &Vector3::z(),
                &Point3::origin(),
                &SkeletonOptions::default()
            ),
            Err(SkeletonError::TooFewPoints(5))
        ));
        let mut nan: Vec<Point3<f64>> = (0..50).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        nan[7].y = f64::NAN;
        assert_eq!(
            automatic_skeleton(
                &nan,
                &Vector3::z(),
                &Point3::origin(),
                &SkeletonOptions::default()
            )
            .unwrap_err(),
            SkeletonError::NonFinite(7)
        );
    }
}
