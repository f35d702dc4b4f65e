//! The automatic leaf segmentation (seed 004 §5.1): foreground → kNN graph with joint 3D/2D
//! weights → threshold partition → recursive normalized cut → leaf / stem / pot / other labels.
//! Takes a scene; returns a [`Segmentation`] (the files are written by [`crate::pipeline`]).

use std::collections::BTreeMap;
use std::time::Instant;

use nalgebra::Point3;
use rayon::prelude::*;
use serde::Serialize;

use super::borders::{BorderOptions, LeafSheet, on_sheets, reclaim_borders, touching_groups};
use super::colour::OrganColours;
use super::foreground::{
    Foreground, ForegroundError, ForegroundOptions, PointClass, separate_foreground,
};
use super::photometric::PhotometricOptions;
use crate::graph::components::Adjacency;
use crate::graph::gradient::GradientImage;
use crate::graph::local_shape::{self, FlatSheet, PLANE_NEIGHBOURS};
use crate::graph::ncut::{
    NcutOptions, NcutStats, Split, median_noise, recursive_ncut, sheet_tolerance, two_sheet_split,
};
use crate::graph::neighbours::Neighbours;
use crate::graph::points::PointSet;
use crate::graph::shape::Shape;
use crate::graph::{GraphOptions, PointGraph, ViewData};
use crate::scene::{Scene, SceneError};
use crate::util::geometry::distance_from_axis;
use crate::util::progress::Progress;
use crate::util::stats::median;

/// All parameters of the automatic segmentation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct SegmentOptions {
    pub graph: GraphOptions,
    pub ncut: NcutOptions,
    pub foreground: ForegroundOptions,
    /// How far a leaf takes back its rim from the stem test ([`super::borders`]).
    #[serde(default)]
    pub borders: BorderOptions,
    /// The photometric leaf test ([`super::photometric`]).
    #[serde(default)]
    pub photometric: PhotometricOptions,
}

/// What a segment is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SegmentLabel {
    Leaf,
    Stem,
    Pot,
    Other,
}

/// A segment of the plant's points.
#[derive(Clone, Debug, Serialize)]
pub struct Segment {
    pub id: u32,
    pub label: SegmentLabel,
    /// Leaf number for leaf segments (the `leaf_id` written to segmentation.ply).
    pub leaf_id: Option<u32>,
    /// Indices into the point set.
    #[serde(skip)]
    pub points: Vec<u32>,
    pub num_points: usize,
    pub shape: Shape,
}

/// Segmentation failures.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Foreground(#[from] ForegroundError),
    #[error("the model's {0} points have no tracks: nothing ties them to the images")]
    NoTracks(usize),
    #[error(
        "the image term (alpha = {alpha}) needs the photos, but no view has its image file (images folder: {folder}); run with --alpha 0 to use 3D distances only"
    )]
    NoImages { alpha: f64, folder: String },
    #[error("segmentation cancelled")]
    Cancelled,
}

/// Seconds per stage.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SegmentTimings {
    pub foreground: f64,
    pub gradients: f64,
    pub graph: f64,
    pub partition: f64,
    pub total: f64,
}

/// The result of the automatic segmentation.
#[derive(Clone, Debug, Serialize)]
pub struct Segmentation {
    #[serde(skip)]
    pub points: PointSet,
    #[serde(skip)]
    pub foreground: Foreground,
    /// Segment index per point (`None` for points outside the plant or in no segment).
    #[serde(skip)]
    pub point_segment: Vec<Option<u32>>,
    pub segments: Vec<Segment>,
    pub sigma_3d: f64,
    pub sigma_2d: f64,
    pub edges_total: usize,
    pub edges_kept: usize,
    pub edges_dropped_not_covisible: usize,
    pub threshold_components: usize,
    /// Segments joined by region merging (see `merge_sheets`).
    pub sheet_merges: usize,
    /// Leaf segments relabelled other by the photometric test ([`super::photometric`]).
    #[serde(default)]
    pub photo_inconsistent: usize,
    /// Small leaf segments joined to another across a gap as pieces of one leaf
    /// ([`super::pieces`]).
    #[serde(default)]
    pub pieces_joined: usize,
    pub views_with_images: usize,
    pub ncut: NcutStats,
    pub timings: SegmentTimings,
    pub options: SegmentOptions,
    /// The weighted graph over the plant points (the interactive edits re-cut it).
    #[serde(skip)]
    pub graph: PointGraph,
    /// Graph node → index in `points`.
    #[serde(skip)]
    pub graph_points: Vec<usize>,
    /// The input's gap fills ([`PointSet::gap_fill`]), left out of `points` and every step
    /// here; the leaf stage and the skeleton label them from the segments
    /// ([`crate::leaf::gap_fill`]).
    #[serde(skip)]
    pub gap_fills: PointSet,
}

impl Segmentation {
    /// `leaf_id` per point (−1 when the point is not on a leaf segment).
    pub fn leaf_ids(&self) -> Vec<i64> {
        self.point_segment
            .iter()
            .map(|s| {
                s.and_then(|s| self.segments[s as usize].leaf_id)
                    .map_or(-1, |l| l as i64)
            })
            .collect()
    }

    /// Number of points per foreground class.
    pub fn class_counts(&self) -> BTreeMap<String, usize> {
        let mut counts = BTreeMap::new();
        for c in &self.foreground.class {
            let name = serde_json::to_value(c)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default();
            *counts.entry(name).or_insert(0) += 1;
        }
        counts
    }

    pub fn num_leaves(&self) -> usize {
        self.segments
            .iter()
            .filter(|s| s.label == SegmentLabel::Leaf)
            .count()
    }
}

/// Computes gradient images for every view whose image file exists (in parallel).
fn gradient_images(scene: &Scene, progress: &dyn Progress) -> Vec<Option<GradientImage>> {
    let images = scene.reconstruction.images();
    progress.stage("gradient images", images.len() as u64);
    images
        .par_iter()
        .map(|image| {
            if progress.is_cancelled() {
                return None;
            }
            let result = GradientImage::for_image(scene, image);
            progress.advance(1);
            match result {
                Ok(g) => Some(g),
                Err(e) => {
                    tracing::warn!("view {} skipped for the image term: {e}", image.name);
                    None
                }
            }
        })
        .collect()
}

/// Attaches segments smaller than the minimum to the neighbouring segment they share the most
/// kNN edges with (edges within the 3D threshold). Fragments that touch no segment but each
/// other (a small leaf the threshold partition cut into pieces) are joined, and kept as a
/// segment when together they reach the minimum; the rest stay unassigned.
fn absorb_fragments(
    groups: Vec<Vec<u32>>,
    graph: &PointGraph,
    min_points: usize,
) -> (Vec<Vec<u32>>, Vec<Option<u32>>) {
    let n = graph.num_nodes;
    let mut owner: Vec<Option<u32>> = vec![None; n];
    let (large, small): (Vec<Vec<u32>>, Vec<Vec<u32>>) =
        groups.into_iter().partition(|g| g.len() >= min_points);
    for (s, group) in large.iter().enumerate() {
        for &node in group {
            owner[node as usize] = Some(s as u32);
        }
    }
    let limit = (graph.options.k * graph.sigma_3d) as f32;
    let spatial = Adjacency::from_edges(
        n,
        graph
            .edges
            .iter()
            .filter(|e| e.d3d < limit)
            .map(|e| (e.a, e.b, 1.0)),
    );
    let mut groups = large;
    // Repeat so that fragments touching fragments can reach a large segment.
    let mut pending = small;
    for _ in 0..3 {
        let mut still = Vec::new();
        for fragment in pending {
            let mut votes: BTreeMap<u32, usize> = BTreeMap::new();
            for &node in &fragment {
                for (j, _) in spatial.row(node as usize) {
                    if let Some(s) = owner[j] {
                        *votes.entry(s).or_insert(0) += 1;
                    }
                }
            }
            match votes
                .into_iter()
                .max_by_key(|&(s, v)| (v, std::cmp::Reverse(s)))
            {
                Some((s, _)) => {
                    for &node in &fragment {
                        owner[node as usize] = Some(s);
                    }
                    groups[s as usize].extend_from_slice(&fragment);
                }
                None => still.push(fragment),
            }
        }
        pending = still;
    }
    // Join the remaining fragments that touch: connected components of the fragment graph.
    let mut fragment_of = vec![usize::MAX; n];
    for (f, fragment) in pending.iter().enumerate() {
        for &node in fragment {
            fragment_of[node as usize] = f;
        }
    }
    let mut union = crate::util::union_find::UnionFind::new(pending.len());
    for (f, fragment) in pending.iter().enumerate() {
        for &node in fragment {
            for (j, _) in spatial.row(node as usize) {
                let g = fragment_of[j];
                if g != usize::MAX && g != f {
                    union.union(f, g);
                }
            }
        }
    }
    let mut joined: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
    for (f, fragment) in pending.into_iter().enumerate() {
        joined.entry(union.find(f)).or_default().extend(fragment);
    }
    for (_, group) in joined {
        if group.len() >= min_points {
            let s = groups.len() as u32;
            for &node in &group {
                owner[node as usize] = Some(s);
            }
            groups.push(group);
        }
    }
    (groups, owner)
}

/// Region merging after the cuts: two segments are joined when they share a long border in
/// the kNN graph (contact edges within the 3D threshold ≥ `min_contact` × √(smaller size)) and
/// their union is still one smooth sheet. This repairs leaves whose rim or a vein was cut off by
/// the 2D threshold, without joining different leaves (which touch along short borders, or
/// whose union is not one sheet).
fn merge_sheets(
    mut groups: Vec<Vec<u32>>,
    graph: &PointGraph,
    positions: &[Point3<f64>],
    options: &NcutOptions,
    min_contact: f64,
) -> (Vec<Vec<u32>>, usize) {
    let limit = (graph.options.k * graph.sigma_3d) as f32;
    let mut merges = 0;
    // Pairs whose union was no sheet, by their groups' contents: a group only grows, so its
    // first node and its size name what it holds. Such a pair is not tested again until one
    // of its groups has grown (the test depends on the two groups alone).
    let mut refused: std::collections::HashSet<[(u32, usize); 2]> = Default::default();
    let (mut rounds, mut tests, mut skipped) = (0usize, 0usize, 0usize);
    loop {
        rounds += 1;
        let mut owner = vec![usize::MAX; graph.num_nodes];
        for (g, group) in groups.iter().enumerate() {
            for &node in group {
                owner[node as usize] = g;
            }
        }
        let mut contact: BTreeMap<(usize, usize), usize> = BTreeMap::new();
        for e in graph.edges.iter().filter(|e| e.d3d < limit) {
            let (a, b) = (owner[e.a as usize], owner[e.b as usize]);
            if a != b && a != usize::MAX && b != usize::MAX {
                *contact.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        // Whether the nodes form one smooth sheet (within the noise allowance).
        let sheet = |nodes: &[u32]| {
            let points: Vec<Point3<f64>> = nodes.iter().map(|&n| positions[n as usize]).collect();
            let shape = Shape::of(points.iter().copied());
            let noise = median_noise(&graph.plane_rms, nodes.iter().map(|&n| n as usize));
            shape.sheet_residual(points.iter().copied()) <= sheet_tolerance(options, &shape, noise)
        };
        let mut candidates: Vec<(f64, usize, usize)> = contact
            .iter()
            .filter_map(|(&(a, b), &count)| {
                let smaller = groups[a].len().min(groups[b].len()) as f64;
                let ratio = count as f64 / smaller.sqrt();
                (ratio >= min_contact).then_some((ratio, a, b))
            })
            .collect();
        candidates.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
        let mut merged = vec![false; groups.len()];
        let mut any = false;
        for (_, a, b) in candidates {
            if merged[a] || merged[b] {
                continue;
            }
            let contents = |g: usize| {
                (
                    groups[g].first().copied().unwrap_or(u32::MAX),
                    groups[g].len(),
                )
            };
            let pair = [contents(a), contents(b)];
            if refused.contains(&pair) {
                skipped += 1;
                continue;
            }
            tests += 1;
            let union: Vec<u32> = groups[a].iter().chain(&groups[b]).copied().collect();
            if !sheet(&union) {
                refused.insert(pair);
            } else {
                let taken = std::mem::take(&mut groups[b]);
                groups[a].extend(taken);
                merged[a] = true;
                merged[b] = true;
                merges += 1;
                any = true;
            }
        }
        groups.retain(|g| !g.is_empty());
        if !any {
            tracing::debug!(rounds, tests, retests_saved = skipped, "sheet merging");
            return (groups, merges);
        }
    }
}

/// Mean `|n_i · n̄|` a leaf's point normals keep with its plane normal, with clean normals: a
/// leaf bent evenly by θ along its midrib averages `sin(θ/2)/(θ/2)` (0.93 at the 75° the
/// synthetic leaves reach), cupping across the blade lowers it a little; a piece of stem
/// surface averages `2/π ≈ 0.64` all round and 0.83–0.89 on the 95–110° arcs the cameras see
/// of a thick stem. Noisy normals lower every facing: the threshold is this times what a flat
/// sheet with the points' spacing and noise keeps ([`FlatSheet::facing`]).
const MIN_LEAF_FACING: f64 = 0.88;

/// A segment narrower than this (its [`Shape::width_ratio`], width over length) is a stem.
pub(crate) const MIN_LEAF_WIDTH_RATIO: f64 = 0.15;

/// The facing ([`MIN_LEAF_FACING`]) a leaf found among the stem test's points must keep, as a
/// share of a flat sheet's: that of a leaf bent by 75° (0.93), above the 0.83–0.89 of the arcs
/// of thick stems the cameras see, which the stem test has sent there too.
const MIN_FOUND_LEAF_FACING: f64 = 0.93;

/// A leaf found among the stem test's points has a free edge: at most this share of its points
/// has another point of the plant within two spacings. A patch of a thick stem's surface is
/// bounded all round by the rest of the stem (semi-dense smallleaf seeds 1–2, the groups the
/// leaf test accepted: 11 stem patches at 0.52–1.00, 6 of them above 0.95; 29 leaves at
/// 0.05–0.90). On groups of 20–60 points most points are within two spacings of the group's
/// edge, so the share stands for the edge; a much larger patch would need its edge measured.
const MAX_FOUND_LEAF_BOUNDED_SHARE: f64 = 0.95;

/// A group of sheet points among the stem test's points that fails the found-leaf test is
/// often a small leaf joined to a patch of a thick stem, whose surface is locally as flat as a
/// sheet at the scale of the sheet test: on semi-dense smallleaf seed 2, groups of 280–970
/// points, 75–90 % stem, each with one to ten leaves on it. Such a group is peeled: its points
/// are joined again only where neighbours' normals (within the group) turn by at most this many
/// times the mean `1 − |n · n̄|` of a flat sheet's at the plant's spacing and noise
/// ([`FlatSheet::facing`]; the scale of [`TOUCHING_LEAVES_FACING_SCALE`]). A leaf meets the stem
/// at a crease and comes away whole; the stem's surface, turning a little at every step, stays
/// in pieces that the found-leaf test and [`MAX_PEELED_BOUNDED_SHARE`] reject. Chosen on
/// smallleaf seeds 1–3 from 5 / 10 / 20 (with the bounded share at 0.5): recall 0.814 / 0.814
/// / 0.809, 0.724 / 0.721 / 0.714, 0.689 / 0.691 / 0.689.
const PEEL_TURN_SCALE: f64 = 10.0;

/// A part peeled from a group ([`PEEL_TURN_SCALE`]) is a leaf only where at most this share of
/// its points has another point within two spacings: a leaf touches the stem it was joined to
/// at its base, a piece of the stem's surface has the rest of the stem along its sides. Parts
/// that passed the found-leaf test, semi-dense smallleaf seeds 1–3: leaves at 0.09–0.46 (28 of
/// 34), stem pieces at 0.57–0.95 (76, three under 0.7). Seeds 1–3 with 0.4 / 0.5 / 0.6: recall
/// 0.812 / 0.814 / 0.814, 0.721 / 0.721 / 0.721, 0.689 / 0.691 / 0.691; precision 0.912 /
/// 0.912 / 0.912, 0.915 / 0.913 / 0.913, 0.916 / 0.916 / 0.913; without it (0.95) precision
/// fell to 0.834 / 0.839 / 0.846.
const MAX_PEELED_BOUNDED_SHARE: f64 = 0.5;

/// Two small leaves that touch (at their bases by the twig, or where one overlaps the other)
/// make one leaf segment when the graph's weights give no edge between them. Such a segment
/// is cut in two where its best facing-weighted normalized cut
/// ([`crate::graph::ncut::facing_bisection`]) is at most this share of what cutting a flat
/// sheet of its own shape across its width costs. In Ncut that cost goes as `√(w / n)` for `n`
/// points and a width ratio `w` ([`Shape::width_ratio`]): the cut edges grow with the sheet's
/// width, `√(n·w)` spacings, the volumes with `n`. So the measure is `Ncut · √(n / w)`, for
/// leaves of any point count and shape; without `w`, narrow leaflets (compound seed 12) were
/// cut as readily as touching leaves. Measured on the segmentation before this step, leaf
/// segments with two sides of ≥ 20 points: where a segment held two leaves of ≥ 20 points
/// the cut separated them (semi-dense smallleaf seeds 1 and 2: 29 and 45 segments, median
/// measure 0.48 and 0.50) and where it halved one leaf the measure was larger (161 and 135
/// segments, median 1.43 and 1.46, tenth percentile 0.87 and 0.83; compound seed 12: 113
/// segments, median 1.14; medium seed 1: 70, median 1.32). Chosen on smallleaf seeds 1–3 from
/// 0.5 / 0.6 / 0.7 (seed 2 recall 0.643 / 0.654 / 0.659, precision 0.906 / 0.910 / 0.894).
const MAX_TOUCHING_LEAVES_CUT: f64 = 0.6;

/// Only leaf segments of at least this share of the points of the plant's typical leaf
/// ([`typical_leaf_points`]) are tried for touching leaves: a segment that holds two leaves is
/// rarely smaller than one typical leaf, and cutting smaller segments (a leaf found in part,
/// the noisier leaves of photos) made pieces. Photos of medium seeds 3, 5, 7, 8 and broadleaf 4
/// with 0 / 1.0 / 1.5: leaf precision 0.841 / 0.857 / 0.857, 0.849 / 0.865 / 0.882, 0.820 /
/// 0.833 / 0.833, 0.770 / 0.800 / 0.800 and 0.818 / 0.909 / 0.909 (before this step 0.878,
/// 0.880, 0.845, 0.800, 0.909); semi-dense smallleaf seed 2 recall 0.654 / 0.657 / 0.606.
const MIN_TOUCHING_SHARE_OF_TYPICAL_LEAF: f64 = 1.0;

/// The facing weights of [`MAX_TOUCHING_LEAVES_CUT`]'s graph fall off over this many times the
/// mean `1 − |n · n̄|` that noise alone gives a flat sheet's normals at the plant's spacing
/// ([`FlatSheet::facing`]): at semi-dense smallleaf seed 2's noise, neighbours on one leaf keep
/// weights near 1 and two leaves 30° apart about 1/e. Measured with an earlier form of the
/// cut rule (raw Ncut ≤ 0.05, every leaf segment) on smallleaf seeds 1–3: 5 gave the same
/// recall and 2–5 points less precision, 20 up to 1.4 points less recall.
const TOUCHING_LEAVES_FACING_SCALE: f64 = 10.0;

/// A leaf found among the stem test's points holds at least this share of the points of the
/// plant's typical leaf ([`typical_leaf_points`]): the stem test takes leaves whole only where
/// they are small against its neighbourhoods, i.e. where the plant's leaves are small. True
/// leaves vary about twofold in length around the typical one (a quarter of its points), and
/// the group of sheet points that finds such a leaf holds about two thirds of it (semi-dense
/// smallleaf seed 2: median 0.67 over the 30 pure groups of 8–19 points), so a sixth of the
/// typical leaf. On plants of large leaves the sheets among the stem points are more often arcs
/// of stems than leaves, and this keeps them out. Chosen on smallleaf seeds 1–3 with
/// [`MIN_FOUND_LEAF_POINTS`] from 0.10 / 0.15 / 0.25: recall 0.806 / 0.806 / 0.783, 0.703 /
/// 0.703 / 0.700, 0.673 / 0.678 / 0.646.
const MIN_FOUND_SHARE_OF_TYPICAL_LEAF: f64 = 0.15;

/// A leaf found among the stem test's points (or a segment called other judged a leaf again)
/// holds at least one sheet neighbourhood ([`SHEET_SHAPE_NEIGHBOURS`]) as well: its normals are
/// taken within it. The normalized cut's smallest segment (20 points) was the floor before; on
/// semi-dense smallleaf seed 2 the stem test had taken 15 leaves of 20–37 points whose groups
/// held 9–18 points, pure and flat (facing 0.97–1.00 against the 0.92 needed), and failed on
/// their size alone. Groups of 8–19 points that pass the leaf test and have a free edge there:
/// 30 on one true leaf, 3 on stems.
const MIN_FOUND_LEAF_POINTS: usize = SHEET_SHAPE_NEIGHBOURS;

/// A leaf segment holds at least this share of the points of the plant's typical leaf
/// ([`typical_leaf_points`]): a leaf 4.5 times shorter than the typical one, or one mostly
/// hidden. Sheets smaller than that are crumbs: on photos of a broadleaf plant (leaves of
/// 1,800–8,300 densified points) 40 sheets of 20–180 points from stems, pot and the stereo halo.
pub(crate) const MIN_SHARE_OF_TYPICAL_LEAF: f64 = 0.05;

/// The size of a typical leaf of the plant: the point count of the leaf-labelled segment that
/// holds the median leaf point (a size-weighted median, so many small crumbs do not pull it
/// down); 0 without leaf segments.
pub(crate) fn typical_leaf_points(segments: &[Segment]) -> f64 {
    let mut sizes: Vec<usize> = segments
        .iter()
        .filter(|s| s.label == SegmentLabel::Leaf)
        .map(|s| s.num_points)
        .collect();
    sizes.sort_unstable();
    let total: usize = sizes.iter().sum();
    let mut seen = 0;
    for size in sizes {
        seen += size;
        if 2 * seen >= total {
            return size as f64;
        }
    }
    0.0
}

/// What the leaf test allows for the points' noise.
#[derive(Clone, Copy, Debug)]
struct SheetScale {
    /// Median local plane RMS of the segment's points (model units; [`sheet_tolerance`]).
    noise: f64,
    /// Least mean facing of a leaf ([`MIN_LEAF_FACING`] scaled for the noise).
    min_facing: f64,
    /// Fewest points of a leaf.
    min_points: usize,
}

/// Below this quantile of the plant points' heights lies its ground where the foreground found
/// no floor ([`PlantHeights`]): stray points under the plant stay out.
const GROUND_QUANTILE: f64 = 0.02;

/// Above this quantile of the plant points' heights lies only its top's stray points.
const TOP_QUANTILE: f64 = 0.98;

/// Heights along the plant's up direction for the pot test of [`classify`] (a pot is low):
/// above the floor where the foreground found one; otherwise above the plant's ground, its
/// points' [`GROUND_QUANTILE`] height. The point the cameras look at, which the heights were
/// once measured from without a floor, is mid-plant: on the real Arabidopsis (no floor in its
/// points) every segment in the lower two thirds of its 34 cm height counted as low, and
/// pieces of the stem's halo were labelled pot.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PlantHeights {
    /// Without a floor: the ground's height above the point the cameras look at.
    ground: f64,
    /// The plant's top ([`TOP_QUANTILE`] of its points) above the floor or the ground.
    top: f64,
}

impl PlantHeights {
    /// The heights of the plant's `positions` (see the type's docs); `top` is at least 1e-9.
    fn of(positions: &[Point3<f64>], foreground: &Foreground) -> Self {
        let mut heights: Vec<f64> = positions
            .iter()
            .map(|p| match &foreground.floor {
                Some(floor) => floor.signed_distance(p),
                None => foreground.up.dot(&(p - foreground.plant_center)),
            })
            .collect();
        heights.sort_by(f64::total_cmp);
        let at = |q: f64| {
            heights
                .get((heights.len() as f64 * q) as usize)
                .copied()
                .unwrap_or(0.0)
        };
        let ground = match foreground.floor {
            Some(_) => 0.0,
            None => at(GROUND_QUANTILE),
        };
        Self {
            ground,
            top: (at(TOP_QUANTILE) - ground).max(1e-9),
        }
    }

    /// A point's height above the floor or the plant's ground.
    fn of_point(&self, p: &Point3<f64>, foreground: &Foreground) -> f64 {
        match &foreground.floor {
            Some(floor) => floor.signed_distance(p),
            None => foreground.up.dot(&(p - foreground.plant_center)) - self.ground,
        }
    }
}

/// What [`classify`] needs besides a group's own points: the graph's points, normals and noise,
/// and the plant's place and size.
struct LeafTest<'a> {
    positions: &'a [Point3<f64>],
    graph: &'a PointGraph,
    min_facing: f64,
    foreground: &'a Foreground,
    heights: PlantHeights,
    options: &'a NcutOptions,
}

impl LeafTest<'_> {
    /// A group's shape, its median noise and its label ([`classify`]).
    fn label(&self, group: &[u32]) -> (Shape, f64, SegmentLabel) {
        let positions: Vec<Point3<f64>> =
            group.iter().map(|&i| self.positions[i as usize]).collect();
        let shape = Shape::of(positions.iter().copied());
        let normals: Vec<nalgebra::Vector3<f64>> = group
            .iter()
            .map(|&i| self.graph.normals[i as usize])
            .collect();
        let noise = median_noise(&self.graph.plane_rms, group.iter().map(|&i| i as usize));
        let label = classify(
            &shape,
            &positions,
            &normals,
            SheetScale {
                noise,
                min_facing: self.min_facing,
                min_points: self.options.min_segment_points,
            },
            self.foreground,
            self.heights,
            self.options,
        );
        (shape, noise, label)
    }
}

/// Two leaves that touch along a strong graph connection (one lying on the other, or going on
/// from its edge at an angle) can come out of the normalized cuts as one group: no sweep of
/// the Fiedler vector separates them, and the leaf test's cubic height field still bends over
/// both (photos of broadleaf seed 11: two leaves of 7,900 and 3,700 points in one segment).
/// A group the leaf test calls a leaf but which is no single quadratic sheet is cut by the two
/// planes that fit it best ([`two_sheet_split`]); the cut is kept when both sides are leaves by
/// the leaf test, and each side's connected pieces are looked at again. Groups that are not
/// leaves (stem junctions, pieces of a tube seen from one side) are left alone: two planes fit
/// those too, and cutting them made stem pieces into leaves on photos of medium plants.
/// Returns the groups and how many were cut.
fn split_stacked_leaves(
    groups: Vec<Vec<u32>>,
    adjacency: &Adjacency,
    test: &LeafTest,
) -> (Vec<Vec<u32>>, usize) {
    let mut out = Vec::with_capacity(groups.len());
    let mut split = 0;
    let mut queue = groups;
    while let Some(group) = queue.pop() {
        if test.label(&group).2 != SegmentLabel::Leaf {
            out.push(group);
            continue;
        }
        let positions: Vec<Point3<f64>> =
            group.iter().map(|&i| test.positions[i as usize]).collect();
        let noise: Vec<f64> = group
            .iter()
            .map(|&i| test.graph.plane_rms.get(i as usize).copied().unwrap_or(0.0))
            .collect();
        let Some(side) = two_sheet_split(&positions, &noise, test.options) else {
            out.push(group);
            continue;
        };
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (&node, &first) in group.iter().zip(&side) {
            if first {
                a.push(node);
            } else {
                b.push(node);
            }
        }
        if test.label(&a).2 != SegmentLabel::Leaf || test.label(&b).2 != SegmentLabel::Leaf {
            out.push(group);
            continue;
        }
        split += 1;
        // Each side goes back as its connected pieces (a plane takes a few points of the
        // other leaf where they meet); the pieces are looked at again, and fragments are
        // absorbed and sheets merged afterwards.
        for half in [a, b] {
            let pieces = adjacency.induced(&half).components();
            for piece in pieces.groups() {
                queue.push(piece.iter().map(|&i| half[i as usize]).collect());
            }
        }
    }
    out.sort_by_key(|g| g.iter().copied().min());
    (out, split)
}

/// Labels a segment from its shape and place: a *stem* is long and thin; the *pot* is a low
/// surface of revolution about the plant's vertical axis (nearly constant distance from it);
/// a *leaf* is one smooth sheet; anything else is *other*.
fn classify(
    shape: &Shape,
    points: &[Point3<f64>],
    normals: &[nalgebra::Vector3<f64>],
    sheet: SheetScale,
    foreground: &Foreground,
    heights: PlantHeights,
    options: &NcutOptions,
) -> SegmentLabel {
    if shape.count < sheet.min_points {
        return SegmentLabel::Other;
    }
    if shape.width_ratio() < MIN_LEAF_WIDTH_RATIO {
        return SegmentLabel::Stem;
    }
    let up = foreground.up;
    let (mean_radius, spread) =
        super::pot::radial_mean_and_spread(points, &foreground.plant_center, &up);
    // Which twelfths of the circle around the axis the segment covers: a leaf never wraps
    // around the plant's axis, the pot and the soil do.
    let reference = crate::util::geometry::any_perpendicular(&up);
    let other = up.cross(&reference);
    let mut covered = [false; 12];
    for p in points {
        let d = p - foreground.plant_center;
        let angle = d.dot(&other).atan2(d.dot(&reference));
        let bin = ((angle + std::f64::consts::PI) / std::f64::consts::TAU * 12.0) as usize;
        covered[bin.min(11)] = true;
    }
    let wraps = covered.iter().filter(|c| **c).count() >= 9;
    // A piece of the pot's wall or rim lies at one distance from the axis and reaches around
    // it; a blob at one distance from the axis only because it is small beside that distance
    // (a piece of the lower stem or of a rosette leaf) is not a piece of a pot.
    let around = || {
        spread
            < MAX_POT_RADIAL_TO_TANGENTIAL_SPREAD
                * super::pot::tangential_spread(points, &foreground.plant_center, &up)
    };
    if heights.of_point(&shape.centroid, foreground) < 0.35 * heights.top
        && ((spread < 0.1 * mean_radius && around()) || wraps)
    {
        return SegmentLabel::Pot;
    }
    // A leaf is one smooth sheet (a cubic height field also follows leaves whose bend
    // varies) that faces one way: its points' normals stay near the mean normal, where a piece
    // of stem turns its normals around the stem's axis.
    let facing = normals
        .iter()
        .map(|n| n.dot(&shape.normal()).abs())
        .sum::<f64>()
        / normals.len().max(1) as f64;
    if facing >= sheet.min_facing
        && shape.cubic_sheet_residual(points.iter().copied())
            <= sheet_tolerance(options, shape, sheet.noise)
    {
        return SegmentLabel::Leaf;
    }
    SegmentLabel::Other
}

/// A low segment at one distance from the cameras' axis is a piece of the pot only if that
/// distance spreads less than this share of how far the segment reaches around the axis
/// ([`super::pot::tangential_spread`]): about 1 for a blob beside the axis; on photos of
/// broadleaf 1 and 22 and medium 3 and semi-dense medium 13 the pot pieces' medians were
/// 0.31–0.56, on the real Arabidopsis the pieces of its lower stem and rosette that the
/// distance alone took for pot 0.94 (stop 79).
const MAX_POT_RADIAL_TO_TANGENTIAL_SPREAD: f64 = 0.5;

/// The plant's horizontal reach from its axis: this quantile of its points' distances from
/// the vertical through the point the cameras look at.
const PLANT_REACH_QUANTILE: f64 = 0.95;

/// Labels other the leaf segments whose points the photos do not show alike
/// ([`super::photometric`]), judging more strictly those that stand upright by the plant's
/// axis, as the stereo halo along its main stem does ([`super::photometric::stands_by_the_axis`];
/// the axis is the vertical through `foreground.plant_center`, the plant's horizontal reach
/// from it the [`PLANT_REACH_QUANTILE`] of its `plant_positions`' distances). Returns how many.
fn label_photo_inconsistent(
    scene: &Scene,
    points: &PointSet,
    plant_positions: &[Point3<f64>],
    foreground: &Foreground,
    segments: &mut [Segment],
    options: &PhotometricOptions,
) -> usize {
    if options.max_spread_ratio <= 0.0 {
        return 0;
    }
    let reach = plant_reach(plant_positions, foreground);
    let leaves: Vec<usize> = (0..segments.len())
        .filter(|&s| segments[s].label == SegmentLabel::Leaf)
        .collect();
    let members: Vec<Vec<u32>> = leaves.iter().map(|&s| segments[s].points.clone()).collect();
    let spreads =
        super::photometric::brightness_spread(scene, points, &members, options.samples_per_segment);
    let upright: Vec<bool> = leaves
        .iter()
        .map(|&s| {
            super::photometric::stands_by_the_axis(
                &segments[s].shape,
                &foreground.plant_center,
                &foreground.up,
                reach,
                options,
            )
        })
        .collect();
    let failed = super::photometric::inconsistent(&spreads, &upright, options);
    let mut relabelled = 0;
    for (&s, &fails) in leaves.iter().zip(&failed) {
        if fails {
            segments[s].label = SegmentLabel::Other;
            relabelled += 1;
        }
    }
    relabelled
}

/// The plant's horizontal reach from its axis (the vertical through `foreground.plant_center`):
/// the [`PLANT_REACH_QUANTILE`] of its points' distances from that axis.
fn plant_reach(plant_positions: &[Point3<f64>], foreground: &Foreground) -> f64 {
    let mut reaches: Vec<f64> = plant_positions
        .iter()
        .map(|p| distance_from_axis(p, &foreground.plant_center, &foreground.up))
        .collect();
    crate::util::stats::quantile(&mut reaches, PLANT_REACH_QUANTILE)
}

/// A leaf segment whose plane stands within this of vertical (the up component of its normal at
/// most sin 20°) and whose centroid lies by the plant's axis ([`BY_THE_AXIS_SHARE`]) is a piece of
/// the main stem's surface seen from one side, not a leaf. Found on photos of medium 3 and 4 (stop
/// 81): the unmatched "leaves" by the axis stood 1–15° from vertical (up components of their
/// normals 0.02–0.25, 45–246 points), the one matched leaf by the axis lay 8° from horizontal, and
/// the steepest matched leaves anywhere stood 61–63° from horizontal (normal up components
/// 0.46–0.48), about 0.6 plant reaches out. A leaf joins the stem at its base and reaches out from
/// it, so its centroid stands a leaf's half-length away; one standing upright beside the stem (a
/// sheathing or a young folded leaf) is what this rule gives up. Not tuned on: photos of medium 5
/// and 6, semi-dense smallleaf 1, medium 14 and broadleaf 43, where every segment the rule relabels
/// was unmatched to a true leaf.
const MAX_EDGE_ON_NORMAL_UP: f64 = 0.34;

/// By the plant's axis: a centroid within this share of the plant's horizontal reach from its
/// axis ([`plant_reach`]); the share the photometric test calls near the axis
/// ([`PhotometricOptions::max_upright_axis_share`]'s default).
const BY_THE_AXIS_SHARE: f64 = 0.3;

/// Labels other the leaf segments that stand edge-on by the plant's axis
/// ([`MAX_EDGE_ON_NORMAL_UP`], [`BY_THE_AXIS_SHARE`]): pieces of the main stem's surface, which
/// a densified capture samples as a narrow vertical strip on the side each camera pair sees.
/// Returns how many.
fn label_edge_on_by_the_axis(
    segments: &mut [Segment],
    plant_positions: &[Point3<f64>],
    foreground: &Foreground,
) -> usize {
    let reach = plant_reach(plant_positions, foreground);
    if reach.is_nan() || reach <= 0.0 {
        return 0;
    }
    let mut relabelled = 0;
    for segment in segments
        .iter_mut()
        .filter(|s| s.label == SegmentLabel::Leaf)
    {
        let normal_up = segment.shape.normal().dot(&foreground.up).abs();
        if normal_up > MAX_EDGE_ON_NORMAL_UP {
            continue;
        }
        let axis_share = distance_from_axis(
            &segment.shape.centroid,
            &foreground.plant_center,
            &foreground.up,
        ) / reach;
        tracing::trace!(
            segment = segment.id,
            normal_up,
            axis_share,
            "an edge-on leaf segment"
        );
        if axis_share <= BY_THE_AXIS_SHARE {
            segment.label = SegmentLabel::Other;
            relabelled += 1;
        }
    }
    relabelled
}

/// Labels pot the leaf and other segments that lie on the pot's wall ([`super::pot::on_the_wall`]),
/// the pot found from the segments labelled pot and the foreground's plant points (see
/// [`super::pot::pot_from_points`]); the segmentation's own pot test measures distances from the
/// cameras' axis, which passes 1–8 cm from a pot's axis on synthetic photos, so a piece of the
/// wall seen from one side can pass as a leaf. Nothing is relabelled where the leaves that
/// are not on the wall do not stand above the rim ([`super::pot::leaves_above_the_rim`]).
/// Returns how many segments it relabelled.
fn label_pot_wall(
    segments: &mut [Segment],
    positions: &[Point3<f64>],
    foreground: &Foreground,
) -> usize {
    let pot_points: Vec<Point3<f64>> = segments
        .iter()
        .filter(|s| s.label == SegmentLabel::Pot)
        .flat_map(|s| s.points.iter().map(|&i| positions[i as usize]))
        .collect();
    let Some(pot) = super::pot::pot_from_points(
        &pot_points,
        &super::pot::wall_voters(positions, foreground),
        &foreground.up,
        &foreground.plant_center,
    ) else {
        return 0;
    };
    let on_the_wall: Vec<bool> = segments
        .iter()
        .map(|segment| {
            matches!(segment.label, SegmentLabel::Leaf | SegmentLabel::Other) && {
                let members: Vec<Point3<f64>> = segment
                    .points
                    .iter()
                    .map(|&i| positions[i as usize])
                    .collect();
                super::pot::on_the_wall(&members, &pot, &foreground.up)
            }
        })
        .collect();
    // The leaves that stay leaves must stand above the pot's rim, or it is no pot.
    let leaves: Vec<Point3<f64>> = segments
        .iter()
        .zip(&on_the_wall)
        .filter(|(s, wall)| s.label == SegmentLabel::Leaf && !**wall)
        .flat_map(|(s, _)| s.points.iter().map(|&i| positions[i as usize]))
        .collect();
    if !super::pot::leaves_above_the_rim(&pot, &leaves, &foreground.up) {
        return 0;
    }
    let mut relabelled = 0;
    for (segment, wall) in segments.iter_mut().zip(on_the_wall) {
        if wall {
            segment.label = SegmentLabel::Pot;
            relabelled += 1;
        }
    }
    relabelled
}

/// The segmentation's results while the leaves take back what the stem test took from them
/// ([`super::borders`]).
struct LeafParts<'a> {
    positions: &'a [Point3<f64>],
    foreground: &'a mut Foreground,
    point_segment: &'a mut [Option<u32>],
    segments: &'a mut Vec<Segment>,
    /// Median local plane RMS of each segment's points.
    noise_of_segment: &'a mut Vec<f64>,
    /// Median point spacing of the plant.
    spacing: f64,
}

/// How a group of points outside the leaf segments is judged a leaf: a small leaf the stem test
/// took whole ([`LeafParts::find_missed_leaves`]), a segment the leaf test called other
/// ([`LeafParts::rejudge_other_segments`]) or a side cut from one
/// ([`LeafParts::split_touching_leaves`]). Such a group is a leaf where it has at least
/// `min_points` (found leaves' [`MIN_FOUND_SHARE_OF_TYPICAL_LEAF`] of the typical leaf: among a
/// plant of large leaves such small sheets are crumbs of stem or pot; at least
/// [`MIN_FOUND_LEAF_POINTS`]), a free edge
/// ([`MAX_FOUND_LEAF_BOUNDED_SHARE`]) and passes the leaf test with normals from each point's
/// neighbours within the group, facing at least [`MIN_FOUND_LEAF_FACING`] × a flat sheet's.
struct FoundLeafJudge<'o> {
    min_points: usize,
    /// The facing of a flat sheet with the plant's spacing and noise ([`FlatSheet::facing`]).
    flat_facing: f64,
    heights: PlantHeights,
    options: &'o NcutOptions,
    /// All the points, indexed for the bounded share; built at the first group that needs it
    /// (`None` where the index could not be built: then no group is judged a leaf).
    all_points: std::sync::OnceLock<Option<Neighbours>>,
}

/// Neighbours of the local shapes [`LeafParts::find_missed_leaves`] tells sheets by (as the
/// stem test's normals).
const SHEET_SHAPE_NEIGHBOURS: usize = 8;
/// The share of a flat sheet's points, sampled like the plant's, whose neighbourhoods the
/// sheet test may call line-like or thick.
const SHEET_SHAPE_SHARE: f64 = 0.05;

impl LeafParts<'_> {
    /// Points that may join a leaf: stem-class or plant points in no segment.
    fn candidates(&self) -> Vec<bool> {
        (0..self.positions.len())
            .map(|i| {
                matches!(
                    self.foreground.class[i],
                    PointClass::Stem | PointClass::Plant
                ) && self.point_segment[i].is_none()
            })
            .collect()
    }

    /// Puts `point` in segment `s`. Its foreground class stays what the stem test said: the
    /// skeleton still takes a leaf's stem-class points for candidates (a rachis or petiole
    /// running along a leaf's edge lies on the leaf's sheet too).
    fn assign(&mut self, point: usize, s: usize) {
        self.segments[s].points.push(point as u32);
        self.point_segment[point] = Some(s as u32);
    }

    /// Updates a segment's count and shape after points joined it.
    fn refresh(&mut self, s: usize) {
        let positions = self.positions;
        let segment = &mut self.segments[s];
        segment.points.sort_unstable();
        segment.num_points = segment.points.len();
        segment.shape = Shape::of(segment.points.iter().map(|&p| positions[p as usize]));
    }

    /// Gives each leaf segment of `which` the stem-class and unassigned points of its rim (a
    /// leaf that took back its rim once does not grow again).
    fn give_back_borders(&mut self, which: &[usize], options: &BorderOptions) {
        let mut leaf_segments = Vec::new();
        let mut sheets = Vec::new();
        for &s in which {
            let segment = &self.segments[s];
            if segment.label != SegmentLabel::Leaf {
                continue;
            }
            let members = segment.points.iter().map(|&p| self.positions[p as usize]);
            if let Some(sheet) = segment.shape.quadratic_sheet(members) {
                leaf_segments.push(s);
                sheets.push(LeafSheet {
                    sheet,
                    noise: self.noise_of_segment[s],
                });
            }
        }
        let mut leaf_of = vec![None; self.positions.len()];
        for (leaf, &s) in leaf_segments.iter().enumerate() {
            for &p in &self.segments[s].points {
                leaf_of[p as usize] = Some(leaf as u32);
            }
        }
        let candidate = self.candidates();
        let claimed = reclaim_borders(
            self.positions,
            &leaf_of,
            &candidate,
            &sheets,
            self.spacing,
            options,
        );
        tracing::debug!(points = claimed.len(), "leaf rim points given back");
        let mut grown = std::collections::BTreeSet::new();
        for (point, leaf) in claimed {
            let s = leaf_segments[leaf as usize];
            self.assign(point, s);
            grown.insert(s);
        }
        for s in grown {
            self.refresh(s);
        }
    }

    /// The judge of found leaves on this plant ([`FoundLeafJudge`]), with groups of at least
    /// `min_points` (and [`MIN_FOUND_LEAF_POINTS`]); `None` where no flat sheet can be modelled at
    /// the plant's spacing and `plane_rms`.
    fn found_leaf_judge<'o>(
        &self,
        plane_rms: f64,
        min_points: usize,
        heights: PlantHeights,
        options: &'o NcutOptions,
    ) -> Option<FoundLeafJudge<'o>> {
        let flat = FlatSheet::like(self.spacing, plane_rms)?;
        Some(FoundLeafJudge {
            min_points: min_points.max(MIN_FOUND_LEAF_POINTS),
            flat_facing: flat.facing(SHEET_SHAPE_NEIGHBOURS),
            heights,
            options,
            all_points: std::sync::OnceLock::new(),
        })
    }

    /// Whether `group` (sorted), whose points' median local plane RMS is `noise`, is judged a
    /// leaf by `judge`: its size, its free edge (at most `max_bounded_share` of its points
    /// bounded: [`MAX_FOUND_LEAF_BOUNDED_SHARE`], or [`MAX_PEELED_BOUNDED_SHARE`] for a part
    /// peeled from a group), then the leaf test ([`LeafParts::passes_found_leaf_test`]; the
    /// dearest, last).
    fn is_found_leaf(
        &self,
        judge: &FoundLeafJudge,
        points: &PointSet,
        group: &[usize],
        noise: f64,
        max_bounded_share: f64,
    ) -> bool {
        group.len() >= judge.min_points
            && self.has_free_edge(judge, group, max_bounded_share)
            && self.passes_found_leaf_test(judge, points, group, noise, judge.min_points)
    }

    /// Whether at most `max_bounded_share` of `group`'s points (sorted) have a point outside
    /// the group within two spacings ([`LeafParts::bounded_share`]).
    fn has_free_edge(
        &self,
        judge: &FoundLeafJudge,
        group: &[usize],
        max_bounded_share: f64,
    ) -> bool {
        judge
            .all_points
            .get_or_init(|| Neighbours::new(self.positions.iter().copied()).ok())
            .as_ref()
            .is_some_and(|all| self.bounded_share(group, all) <= max_bounded_share)
    }

    /// Whether `group` (sorted), which failed the found-leaf test, is a leaf by its colour
    /// ([`OrganColours::is_leaf_coloured`]) where its shape does not say otherwise: at least
    /// `judge`'s fewest points and fewer than `max_points`, not a stem's width
    /// ([`MIN_LEAF_WIDTH_RATIO`]) and a free edge ([`MAX_FOUND_LEAF_BOUNDED_SHARE`]).
    fn is_leaf_coloured_piece(
        &self,
        judge: &FoundLeafJudge,
        points: &PointSet,
        group: &[usize],
        colours: &OrganColours,
        max_points: f64,
    ) -> bool {
        group.len() >= judge.min_points
            && (group.len() as f64) < max_points
            && Shape::of(group.iter().map(|&i| self.positions[i])).width_ratio()
                >= MIN_LEAF_WIDTH_RATIO
            && colours.is_leaf_coloured(&points.colors, group)
            && self.has_free_edge(judge, group, MAX_FOUND_LEAF_BOUNDED_SHARE)
    }

    /// The plant's leaf and stem colours ([`OrganColours`]): the leaf colour from the points of
    /// the segments labelled leaf, the stem colour from the stem test's points in none.
    fn organ_colours(&self, points: &PointSet) -> Option<OrganColours> {
        let is_leaf = |i: usize| {
            self.point_segment[i]
                .is_some_and(|s| self.segments[s as usize].label == SegmentLabel::Leaf)
        };
        OrganColours::measure_split(&points.colors, self.positions.len(), is_leaf, |i| {
            self.foreground.class[i] == PointClass::Stem
        })
    }

    /// The parts of `group` (sorted) whose points are joined where they lie within two
    /// spacings and their normals (from [`SHEET_SHAPE_NEIGHBOURS`] within the group) turn by
    /// at most `max_turn` (`1 − |n₁ · n₂|`); each sorted, in the order of their first point.
    fn peel(&self, points: &PointSet, group: &[usize], max_turn: f64) -> Vec<Vec<usize>> {
        let normals: Vec<nalgebra::Vector3<f64>> =
            local_shape::local_shapes(&points.subset(group), SHEET_SHAPE_NEIGHBOURS)
                .iter()
                .map(|shape| shape.normal)
                .collect();
        let Ok(index) = Neighbours::new(group.iter().map(|&i| self.positions[i])) else {
            return Vec::new();
        };
        let mut sets = crate::util::union_find::UnionFind::new(group.len());
        for (a, &i) in group.iter().enumerate() {
            for n in index.within_radius_unsorted(&self.positions[i], 2.0 * self.spacing) {
                if 1.0 - normals[a].dot(&normals[n.index]).abs() <= max_turn {
                    sets.union(a, n.index);
                }
            }
        }
        let mut parts: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (a, &i) in group.iter().enumerate() {
            parts.entry(sets.find(a)).or_default().push(i);
        }
        let mut parts: Vec<Vec<usize>> = parts.into_values().collect();
        parts.sort_by_key(|part| part[0]);
        parts
    }

    /// Whether `group` passes the leaf test of found leaves: [`classify`] with each point's
    /// normal from its [`SHEET_SHAPE_NEIGHBOURS`] nearest within the group (normals over all
    /// plant points mix in a small leaf's twig and neighbours), against `judge`'s facing, the
    /// group's `noise` and a leaf's fewest points `min_points`.
    fn passes_found_leaf_test(
        &self,
        judge: &FoundLeafJudge,
        points: &PointSet,
        group: &[usize],
        noise: f64,
        min_points: usize,
    ) -> bool {
        let positions: Vec<Point3<f64>> = group.iter().map(|&i| self.positions[i]).collect();
        let normals: Vec<nalgebra::Vector3<f64>> =
            local_shape::local_shapes(&points.subset(group), SHEET_SHAPE_NEIGHBOURS)
                .iter()
                .map(|shape| shape.normal)
                .collect();
        classify(
            &Shape::of(positions.iter().copied()),
            &positions,
            &normals,
            SheetScale {
                noise,
                min_facing: MIN_FOUND_LEAF_FACING * judge.flat_facing,
                min_points,
            },
            self.foreground,
            judge.heights,
            judge.options,
        ) == SegmentLabel::Leaf
    }

    /// The share of `group`'s points (sorted) with a point outside the group within two
    /// spacings; `all_points` indexes all the points.
    fn bounded_share(&self, group: &[usize], all_points: &Neighbours) -> f64 {
        let bounded = group
            .iter()
            .filter(|&&i| {
                all_points
                    .within_radius_unsorted(&self.positions[i], 2.0 * self.spacing)
                    .iter()
                    .any(|n| group.binary_search(&n.index).is_err())
            })
            .count();
        bounded as f64 / group.len().max(1) as f64
    }

    /// The touching groups of `sheet_points` (within two spacings) of at least one sheet
    /// neighbourhood, each with the rim it takes back from the `candidate` points
    /// ([`reclaim_borders`] with each group's quadratic sheet and its points' median noise from
    /// `noise_of`, as far as `borders` lets a leaf reach), in two passes: each group as the
    /// first pass left it and as a second pass, from the sheet refitted to the group and its
    /// first rim, left it (the reach a found leaf gets when it takes back its rim again); each
    /// sorted.
    fn sheet_groups_with_rims(
        &self,
        sheet_points: &[usize],
        candidate: &[bool],
        noise_of: &std::collections::HashMap<usize, f64>,
        borders: &BorderOptions,
    ) -> Vec<(Vec<usize>, Vec<usize>)> {
        let seeds = touching_groups(
            self.positions,
            sheet_points,
            2.0 * self.spacing,
            SHEET_SHAPE_NEIGHBOURS,
        );
        let mut leaf_of = vec![None; self.positions.len()];
        let mut sheets = Vec::new();
        let mut groups = Vec::new();
        for group in seeds {
            let positions = group.iter().map(|&i| self.positions[i]);
            let Some(sheet) = Shape::of(positions.clone()).quadratic_sheet(positions) else {
                continue;
            };
            let noise = median(group.iter().filter_map(|i| noise_of.get(i).copied()));
            for &i in &group {
                leaf_of[i] = Some(sheets.len() as u32);
            }
            sheets.push(LeafSheet {
                sheet,
                noise: noise.unwrap_or(0.0),
            });
            groups.push(group);
        }
        let mut first_pass = Vec::new();
        for pass in 0..2 {
            if pass > 0 {
                first_pass = groups.clone();
                for (group, sheet) in groups.iter().zip(sheets.iter_mut()) {
                    let positions = group.iter().map(|&i| self.positions[i]);
                    if let Some(refit) = Shape::of(positions.clone()).quadratic_sheet(positions) {
                        sheet.sheet = refit;
                    }
                }
            }
            let rims = reclaim_borders(
                self.positions,
                &leaf_of,
                candidate,
                &sheets,
                self.spacing,
                borders,
            );
            for (point, group) in rims {
                groups[group as usize].push(point);
                leaf_of[point] = Some(group);
            }
        }
        for group in groups.iter_mut().chain(first_pass.iter_mut()) {
            group.sort_unstable();
        }
        first_pass.into_iter().zip(groups).collect()
    }

    /// Cuts leaf segments that hold touching leaves ([`MAX_TOUCHING_LEAVES_CUT`]; segments of
    /// at least [`MIN_TOUCHING_SHARE_OF_TYPICAL_LEAF`] of the typical leaf). A cut is
    /// kept when at least one side passes the leaf test that found leaves pass (the facing of
    /// its points' normals within the side against [`MIN_FOUND_LEAF_FACING`] × a flat sheet's,
    /// and its sheet residual); the other side stays a leaf segment as the whole was (it may
    /// hold another leaf with a piece of twig) and, like the first, is tried again. Sides have
    /// at least the smallest segment's points.
    ///
    /// Segments the leaf test called other are cut the same way: two small leaves that touch
    /// (or a leaf with a neighbour's edge) make a segment whose normals, over the whole, face
    /// no one way. There a side becomes a leaf only where it is judged as a leaf found among
    /// the stem points is ([`LeafParts::find_missed_leaves`]): it passes the leaf test, has a
    /// free edge ([`MAX_FOUND_LEAF_BOUNDED_SHARE`]) and at least
    /// [`MIN_FOUND_SHARE_OF_TYPICAL_LEAF`] of the typical leaf's points (the sides cut from
    /// stems on plants of large leaves are far smaller than their leaves); a side that does
    /// not stays other. On semi-dense smallleaf seed 2, of the 104 leaves missed with most of
    /// their points outside leaf segments, 28 lay in segments called other, 20 of them sharing
    /// it with a neighbouring leaf or a twig. Returns how many cuts were made.
    fn split_touching_leaves(
        &mut self,
        points: &PointSet,
        plane_rms: f64,
        heights: PlantHeights,
        options: &SegmentOptions,
    ) -> usize {
        let typical = typical_leaf_points(self.segments);
        let min_found_points = (MIN_FOUND_SHARE_OF_TYPICAL_LEAF * typical).ceil() as usize;
        let Some(judge) =
            self.found_leaf_judge(plane_rms, min_found_points, heights, &options.ncut)
        else {
            return 0;
        };
        let facing_scale = TOUCHING_LEAVES_FACING_SCALE * (1.0 - judge.flat_facing).max(1e-3);
        let min_side = options.ncut.min_segment_points;
        let mut queue: Vec<usize> = (0..self.segments.len())
            .rev()
            .filter(|&s| {
                matches!(
                    self.segments[s].label,
                    SegmentLabel::Leaf | SegmentLabel::Other
                )
            })
            .collect();
        let mut cuts = 0;
        let min_points = MIN_TOUCHING_SHARE_OF_TYPICAL_LEAF * typical;
        let members_of = |segment: &Segment| -> Option<Vec<usize>> {
            let members: Vec<usize> = segment.points.iter().map(|&p| p as usize).collect();
            ((members.len() as f64) >= min_points).then_some(members)
        };
        // One neighbour search gives the points' normals and the bisection's graph.
        let bisect = |members: &[usize]| {
            let positions: Vec<Point3<f64>> = members.iter().map(|&i| self.positions[i]).collect();
            let around =
                local_shape::Neighbourhoods::of_positions(&positions, SHEET_SHAPE_NEIGHBOURS)?;
            let normals: Vec<nalgebra::Vector3<f64>> = around
                .shapes_at(&positions, SHEET_SHAPE_NEIGHBOURS)
                .iter()
                .map(|shape| shape.normal)
                .collect();
            crate::graph::ncut::facing_bisection(
                &positions,
                &normals,
                &around,
                SHEET_SHAPE_NEIGHBOURS,
                facing_scale,
                min_side,
            )
        };
        // Each queued segment's bisection depends on its points alone: those of the segments
        // as they are now are found on all cores first. A segment's points change only when it
        // is cut, and then it is queued again and bisected anew.
        let mut first_bisection: BTreeMap<usize, Option<Split>> = queue
            .par_iter()
            .filter_map(|&s| members_of(&self.segments[s]).map(|m| (s, bisect(&m))))
            .collect();
        while let Some(s) = queue.pop() {
            let Some(members) = members_of(&self.segments[s]) else {
                continue;
            };
            let split = match first_bisection.remove(&s) {
                Some(split) => split,
                None => bisect(&members),
            };
            let Some(split) = split else {
                continue;
            };
            let width_ratio = self.segments[s].shape.width_ratio().max(1e-3);
            if split.ncut * (members.len() as f64 / width_ratio).sqrt() > MAX_TOUCHING_LEAVES_CUT {
                continue;
            }
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (&i, &side) in members.iter().zip(&split.side) {
                if side { a.push(i) } else { b.push(i) }
            }
            a.sort_unstable();
            b.sort_unstable();
            let noise = self.noise_of_segment[s];
            let was_other = self.segments[s].label == SegmentLabel::Other;
            let is_leaf = |part: &[usize]| {
                if was_other {
                    self.is_found_leaf(&judge, points, part, noise, MAX_FOUND_LEAF_BOUNDED_SHARE)
                } else {
                    self.passes_found_leaf_test(&judge, points, part, noise, min_side)
                }
            };
            let (leaf_a, leaf_b) = (is_leaf(&a), is_leaf(&b));
            if !leaf_a && !leaf_b {
                continue;
            }
            // A leaf segment's sides both stay leaves; a segment called other keeps that label
            // on a side that is no leaf.
            let label_of = |is_leaf: bool| {
                if is_leaf || !was_other {
                    SegmentLabel::Leaf
                } else {
                    SegmentLabel::Other
                }
            };
            let t = self.segments.len();
            self.segments[s].points = a.iter().map(|&i| i as u32).collect();
            self.segments[s].label = label_of(leaf_a);
            self.segments.push(Segment {
                id: t as u32,
                label: label_of(leaf_b),
                leaf_id: None,
                points: Vec::new(),
                num_points: 0,
                shape: self.segments[s].shape,
            });
            self.noise_of_segment.push(noise);
            for &i in &b {
                self.assign(i, t);
            }
            self.refresh(s);
            self.refresh(t);
            queue.push(t);
            queue.push(s);
            cuts += 1;
        }
        cuts
    }

    /// Relabels as leaves the segments the leaf test called other that pass the test a leaf
    /// found among the stem points passes ([`LeafParts::find_missed_leaves`]): normals from
    /// each point's neighbours within the segment face one way (at least
    /// [`MIN_FOUND_LEAF_FACING`] × a flat sheet's facing), its sheet residual is within the
    /// tolerance, it has a free edge ([`MAX_FOUND_LEAF_BOUNDED_SHARE`]), and it has at least
    /// `min_points` (found leaves' [`MIN_FOUND_SHARE_OF_TYPICAL_LEAF`]: among a plant of
    /// large leaves such small sheets are crumbs of stem or pot). The main test's
    /// normals come from neighbours among all plant points, and on a leaf of a few dozen points
    /// they mix in the twig's and the neighbouring leaves': on semi-dense smallleaf seed 2, of
    /// the six segments called other that hold at least 95 % of one true leaf, four failed on
    /// that facing alone (0.51–0.87), two on the sheet residual. After the second rim pass of
    /// found leaves, semi-dense smallleaf seeds 1–3: recall 0.765 / 0.675 / 0.625 → 0.768 /
    /// 0.682 / 0.639 (with their rims given back), precision 0.917 / 0.927 / 0.898 → 0.911 /
    /// 0.925 / 0.903; seeds 4–5 (held out): recall 0.712 / 0.668 → 0.715 / 0.668, precision
    /// 0.852 / 0.876 → 0.846 / 0.876.
    ///
    /// A segment that fails that test is still relabelled where its colour is the plant's leaf
    /// colour ([`OrganColours`], on plants whose leaves and stems differ in colour) and its
    /// shape does not say otherwise: at least `min_points`, fewer than the typical leaf's
    /// points (a larger segment called other holds several leaves, which the touching-leaves
    /// cut separates: relabelling it first merged three leaves of semi-dense medium seed 1),
    /// not a stem's width ([`MIN_LEAF_WIDTH_RATIO`]) and a free edge. Small leaves curled or
    /// mixed with a few twig points fail the facing test (0.31–0.91 against 0.92 on semi-dense
    /// smallleaf seed 3) where their colour is the leaves' (0.5–1.2 but for one on the line
    /// from the stem colour at 0 to the leaf colour at 1); the segments called other of stem
    /// points alone lie at 0.21 or below on smallleaf, medium, broadleaf and compound plants.
    /// Returns the relabelled segments.
    fn rejudge_other_segments(
        &mut self,
        points: &PointSet,
        plane_rms: f64,
        min_points: usize,
        heights: PlantHeights,
        options: &SegmentOptions,
    ) -> Vec<usize> {
        let Some(judge) = self.found_leaf_judge(plane_rms, min_points, heights, &options.ncut)
        else {
            return Vec::new();
        };
        let colours = self.organ_colours(points);
        let max_coloured_points =
            MIN_TOUCHING_SHARE_OF_TYPICAL_LEAF * typical_leaf_points(self.segments);
        let mut relabelled = Vec::new();
        for s in 0..self.segments.len() {
            if self.segments[s].label != SegmentLabel::Other {
                continue;
            }
            let mut group: Vec<usize> = self.segments[s]
                .points
                .iter()
                .map(|&p| p as usize)
                .collect();
            group.sort_unstable();
            let noise = self.noise_of_segment[s];
            let leaf =
                self.is_found_leaf(&judge, points, &group, noise, MAX_FOUND_LEAF_BOUNDED_SHARE)
                    || colours.as_ref().is_some_and(|colours| {
                        self.is_leaf_coloured_piece(
                            &judge,
                            points,
                            &group,
                            colours,
                            max_coloured_points,
                        )
                    });
            if leaf {
                self.segments[s].label = SegmentLabel::Leaf;
                relabelled.push(s);
            }
        }
        relabelled
    }

    /// Small leaves the stem test took whole (on a leaf of a few dozen points its 20-point
    /// neighbourhoods reach over the whole leaf and onto its twig). Among the stem-class and
    /// unassigned points, those whose own neighbourhood is a piece of sheet (as wide and as
    /// thin as a flat sheet's, sampled with the plant's spacing and noise, is in all but 5 % of
    /// its points: a twig's points lie on a line, a stem's wrap around it) are joined where they
    /// lie within two spacings of each other. Joining touching sheet points did better than
    /// segmenting them again with the kNN graph and normalized cuts (semi-dense smallleaf seeds
    /// 1–3: recall 0.728 / 0.588 / 0.594 against 0.725 / 0.576 / 0.583, precision 0.90–0.94
    /// against 0.88–0.90).
    ///
    /// On a leaf of 20–40 points only half of its points pass the sheet test (its rim's
    /// neighbourhoods reach onto the twig), too few to make a group. So every group of at least
    /// one sheet neighbourhood ([`SHEET_SHAPE_NEIGHBOURS`] points) first takes back its rim the
    /// way a leaf does ([`reclaim_borders`]), and then the groups of at least `min_points` the
    /// leaf test accepts become leaf segments. The test's facing uses normals from each point's
    /// neighbours within the group (normals over all candidate points mixed in the twig's and
    /// the neighbouring leaves' and failed pure leaves at 0.88–0.92), against a flat sheet's
    /// facing with the same neighbourhood. Semi-dense smallleaf seeds 1 and 2 (looked at):
    /// recall 0.716 / 0.574 → 0.728 / 0.597, precision 0.936 / 0.922 → 0.916 / 0.899; seeds
    /// 3–5 (held out): recall 0.562 / 0.628 / 0.614 → 0.591 / 0.653 / 0.646, precision 0.895 /
    /// 0.871 / 0.924 → 0.896 / 0.841 / 0.879. A third of the groups this accepted were patches
    /// of thick stems, which the in-group normals no longer tell from a leaf; a group bounded
    /// all round by other points ([`MAX_FOUND_LEAF_BOUNDED_SHARE`]) is not a leaf: precision
    /// 0.926 / 0.909 on seeds 1–2, 0.907 / 0.851 / 0.891 on 3–5, recall unchanged. Semi-dense
    /// broadleaf 1–3, medium 1 and compound 11–12 and the photos of broadleaf 1, 3, 4, 13 and
    /// medium 3, 5, 7–9 are unchanged.
    ///
    /// A found leaf later takes back its rim once more, from its whole sheet; a group smaller
    /// than `min_points` after the first pass is judged at the size that second pass gives it
    /// ([`LeafParts::sheet_groups_with_rims`]). On the leaves of 20–33 points that were missed
    /// because their group stayed under 20 points (28 on semi-dense smallleaf seed 2) the rest
    /// of the leaf lay 2–5 spacings from the group's sheet points, on their sheet but beyond
    /// one pass's reach. Seeds 1–3 (looked at): recall 0.762 / 0.657 / 0.625 → 0.765 / 0.675 /
    /// 0.625, precision 0.926 / 0.928 / 0.908 → 0.917 / 0.927 / 0.898; seeds 4–5 (held out):
    /// 0.700 / 0.661 → 0.712 / 0.668, precision 0.859 / 0.886 → 0.852 / 0.876. Judging every
    /// group after both passes did worse (0.754 / 0.668 / 0.617): the larger groups that passed
    /// after one took in twig and neighbours.
    ///
    /// Groups are judged from [`MIN_FOUND_LEAF_POINTS`] (one sheet neighbourhood) and a sixth
    /// of the typical leaf ([`MIN_FOUND_SHARE_OF_TYPICAL_LEAF`]) on; before, from 20 points and
    /// a quarter. Semi-dense smallleaf seeds 1–3 (looked at): recall 0.768 / 0.694 / 0.646 →
    /// 0.806 / 0.703 / 0.678, precision 0.901 / 0.915 / 0.901 → 0.914 / 0.916 / 0.921.
    /// Returns how many.
    fn find_missed_leaves(
        &mut self,
        points: &PointSet,
        plane_rms: f64,
        min_points: usize,
        heights: PlantHeights,
        options: &SegmentOptions,
    ) -> usize {
        let Some(flat) = FlatSheet::like(self.spacing, plane_rms) else {
            return 0;
        };
        let (min_elongation, max_thickness) =
            flat.local_shape_bounds(SHEET_SHAPE_NEIGHBOURS, SHEET_SHAPE_SHARE);
        let candidate = self.candidates();
        let left: Vec<usize> = (0..self.positions.len())
            .filter(|&i| candidate[i])
            .collect();
        // One neighbour search serves the shapes and the planes.
        let left_points = points.subset(&left);
        let Some(around) = local_shape::Neighbourhoods::of(
            &left_points,
            SHEET_SHAPE_NEIGHBOURS.max(PLANE_NEIGHBOURS),
        ) else {
            return 0;
        };
        let shapes = around.shapes(&left_points, SHEET_SHAPE_NEIGHBOURS);
        let on_sheet = on_sheets(&shapes, min_elongation, max_thickness);
        let sheet_points: Vec<usize> = on_sheet.iter().map(|&k| left[k]).collect();
        if sheet_points.len() < options.ncut.min_segment_points {
            return 0;
        }
        // The points' noise (local plane RMS) is read only for the points of the groups
        // found: measured for the sheet points the groups grow from, then for their rims.
        // `local` indexes `left`.
        let noise_at = |local: &[usize]| -> Vec<(usize, f64)> {
            let planes = around.planes_of(&left_points, local, PLANE_NEIGHBOURS);
            local
                .iter()
                .zip(planes)
                .map(|(&k, plane)| (left[k], plane.rms))
                .collect()
        };
        let mut noise_of: std::collections::HashMap<usize, f64> =
            noise_at(&on_sheet).into_iter().collect();
        let groups =
            self.sheet_groups_with_rims(&sheet_points, &candidate, &noise_of, &options.borders);
        let rims: std::collections::BTreeSet<usize> = groups
            .iter()
            .flat_map(|(first, second)| first.iter().chain(second))
            .filter(|i| !noise_of.contains_key(i))
            .filter_map(|i| left.binary_search(i).ok())
            .collect();
        noise_of.extend(noise_at(&rims.into_iter().collect::<Vec<_>>()));
        let Some(judge) = self.found_leaf_judge(plane_rms, min_points, heights, &options.ncut)
        else {
            return 0;
        };
        let mut found = 0;
        let groups = groups.into_iter().filter_map(|(first, second)| {
            if first.len() >= judge.min_points {
                Some(first)
            } else if second.len() >= judge.min_points {
                Some(second)
            } else {
                None
            }
        });
        let max_turn = PEEL_TURN_SCALE * (1.0 - judge.flat_facing).max(1e-3);
        let noise_of_group =
            |group: &[usize]| median(group.iter().filter_map(|i| noise_of.get(i).copied()));
        // Each group is judged on its own: on all cores, the leaves kept in the groups' order.
        let groups: Vec<Vec<usize>> = groups.collect();
        let this = &*self;
        let leaves: Vec<(Vec<usize>, f64)> = groups
            .into_par_iter()
            .flat_map_iter(|group| {
                let noise = noise_of_group(&group).unwrap_or(0.0);
                if this.is_found_leaf(&judge, points, &group, noise, MAX_FOUND_LEAF_BOUNDED_SHARE) {
                    return vec![(group, noise)];
                }
                if group.len() < 2 * judge.min_points {
                    return Vec::new();
                }
                this.peel(points, &group, max_turn)
                    .into_iter()
                    .filter_map(|part| {
                        let noise = noise_of_group(&part).unwrap_or(0.0);
                        this.is_found_leaf(&judge, points, &part, noise, MAX_PEELED_BOUNDED_SHARE)
                            .then_some((part, noise))
                    })
                    .collect()
            })
            .collect();
        for (group, noise) in leaves {
            let shape = Shape::of(group.iter().map(|&i| self.positions[i]));
            let s = self.segments.len();
            self.segments.push(Segment {
                id: s as u32,
                label: SegmentLabel::Leaf,
                leaf_id: None,
                points: Vec::new(),
                num_points: 0,
                shape,
            });
            self.noise_of_segment.push(noise);
            for &i in &group {
                self.assign(i, s);
            }
            self.refresh(s);
            found += 1;
        }
        found
    }
}

/// Plant points the thin-organ sweep found ([`crate::mvs::thin`]) are stem candidates: the
/// sweep only keeps points on a bar's centreline where stereo left the surface sparse, so they
/// are stems and petioles (or a leaf's rim, which [`crate::segment::borders`] gives back),
/// never a leaf's sheet. In the leaf graph they joined touching leaves and made extra leaf
/// segments; as stem points they go to the skeleton. Photos of broadleaf seeds 1–5 and 11–13
/// (the same points, reconstructed with and without this rule): mean petiole length recall
/// 0.735 → 0.772, leaf precision 0.916 → 0.919, leaf recall unchanged; medium seeds 3–5: mean
/// leaf recall 0.754 → 0.767, leaf precision 0.727 → 0.716, branch recall 0.344 → 0.343.
fn thin_organs_are_stem_points(points: &PointSet, class: &mut [PointClass]) {
    for (i, class) in class.iter_mut().enumerate() {
        if *class == PointClass::Plant && points.is_thin_organ(i) {
            *class = PointClass::Stem;
        }
    }
}

/// Runs the automatic segmentation on a scene's points.
pub fn segment_scene(
    scene: &Scene,
    options: &SegmentOptions,
    progress: &dyn Progress,
) -> Result<Segmentation, SegmentError> {
    let start = Instant::now();
    let mut timings = SegmentTimings::default();
    let (points, gap_fills) = PointSet::from_scene(scene).split_gap_fills();
    if points.is_empty() {
        return Err(ForegroundError::NoPoints.into());
    }
    let with_tracks = points.views.iter().filter(|v| !v.is_empty()).count();
    if with_tracks == 0 {
        return Err(SegmentError::NoTracks(points.len()));
    }
    progress.stage("foreground", 0);
    let clock = Instant::now();
    let mut foreground = separate_foreground(&points, &scene.reconstruction, &options.foreground)?;
    for (i, views) in points.views.iter().enumerate() {
        if views.is_empty() {
            foreground.class[i] = PointClass::Outlier;
        }
    }
    thin_organs_are_stem_points(&points, &mut foreground.class);
    timings.foreground = clock.elapsed().as_secs_f64();
    let check_cancelled = || {
        if progress.is_cancelled() {
            Err(SegmentError::Cancelled)
        } else {
            Ok(())
        }
    };
    check_cancelled()?;

    let clock = Instant::now();
    let gradients = if options.graph.alpha > 0.0 {
        let gradients = gradient_images(scene, progress);
        check_cancelled()?;
        if gradients.iter().all(Option::is_none) {
            return Err(SegmentError::NoImages {
                alpha: options.graph.alpha,
                folder: scene
                    .source
                    .images_dir
                    .as_ref()
                    .map_or_else(|| "none found".to_owned(), |p| p.display().to_string()),
            });
        }
        gradients
    } else {
        Vec::new()
    };
    let views_with_images = gradients.iter().filter(|g| g.is_some()).count();
    timings.gradients = clock.elapsed().as_secs_f64();

    progress.stage("graph", 0);
    let clock = Instant::now();
    // Leaves are segmented among the non-stem plant points.
    let plant: Vec<usize> = (0..points.len())
        .filter(|&i| foreground.class[i] == PointClass::Plant)
        .collect();
    let plant_points = points.subset(&plant);
    let model = &scene.reconstruction;
    let views: Vec<ViewData> = model
        .images()
        .iter()
        .enumerate()
        .map(|(v, image)| ViewData {
            camera: model.camera_of(image),
            camera_from_world: image.camera_from_world,
            gradient: gradients.get(v).and_then(Option::as_ref),
        })
        .collect();
    let graph = PointGraph::build(&plant_points, &views, options.graph);
    timings.graph = clock.elapsed().as_secs_f64();
    check_cancelled()?;

    progress.stage("normalized cuts", 0);
    let clock = Instant::now();
    let adjacency = graph.adjacency();
    let components = adjacency.components();
    let phase = Instant::now();
    let (groups, ncut_stats) = recursive_ncut(
        &adjacency,
        components.groups(),
        &plant_points.positions,
        &graph.plane_rms,
        &options.ncut,
    );
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        eigen_solves = ncut_stats.eigen_solves,
        solved_points = ncut_stats.solved_points,
        largest_solved = ncut_stats.largest_solved,
        "normalized cuts"
    );
    // The plant's heights, for pot detection.
    let heights = PlantHeights::of(&plant_points.positions, &foreground);

    // Noise lowers a leaf's facing: compare with a flat sheet sampled like these points.
    let spacing = graph.median_spacing;
    let plane_rms = median(graph.plane_rms.iter().copied()).unwrap_or(0.0);
    let flat_facing =
        FlatSheet::like(spacing, plane_rms).map_or(1.0, |sheet| sheet.facing(PLANE_NEIGHBOURS));
    let min_facing = MIN_LEAF_FACING * flat_facing;
    tracing::debug!(flat_facing, min_facing, "leaf facing threshold");
    let leaf_test = LeafTest {
        positions: &plant_points.positions,
        graph: &graph,
        min_facing,
        foreground: &foreground,
        heights,
        options: &options.ncut,
    };
    let phase = Instant::now();
    let (groups, stacked) = split_stacked_leaves(groups, &adjacency, &leaf_test);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        stacked,
        "leaves lying on leaves split by their planes"
    );
    let phase = Instant::now();
    let (groups, _) = absorb_fragments(groups, &graph, options.ncut.min_segment_points);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        "fragments absorbed"
    );
    let phase = Instant::now();
    let (groups, sheet_merges) = merge_sheets(
        groups,
        &graph,
        &plant_points.positions,
        &options.ncut,
        options.ncut.min_merge_contact,
    );
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        merges = sheet_merges,
        "sheets merged"
    );
    let mut owner: Vec<Option<u32>> = vec![None; plant_points.len()];
    for (s, group) in groups.iter().enumerate() {
        for &node in group {
            owner[node as usize] = Some(s as u32);
        }
    }

    let mut segments = Vec::with_capacity(groups.len());
    let mut noise_of_segment = Vec::with_capacity(groups.len());
    let mut next_leaf = 0u32;
    for (id, group) in groups.iter().enumerate() {
        let (shape, noise, label) = leaf_test.label(group);
        noise_of_segment.push(noise);
        segments.push(Segment {
            id: id as u32,
            label,
            leaf_id: None,
            points: group.iter().map(|&i| plant[i as usize] as u32).collect(),
            num_points: group.len(),
            shape,
        });
    }
    let mut point_segment = vec![None; points.len()];
    for (local, s) in owner.iter().enumerate() {
        point_segment[plant[local]] = *s;
    }
    // Leaf points the stem test took: rims go back to their leaves, then small leaves it took
    // whole are looked for among what is left, and they take back their own rims.
    let mut leaf_parts = LeafParts {
        positions: &points.positions,
        foreground: &mut foreground,
        point_segment: &mut point_segment,
        segments: &mut segments,
        noise_of_segment: &mut noise_of_segment,
        spacing,
    };
    let phase = Instant::now();
    let all: Vec<usize> = (0..leaf_parts.segments.len()).collect();
    leaf_parts.give_back_borders(&all, &options.borders);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        "leaf rims given back"
    );
    let phase = Instant::now();
    let min_found_points =
        (MIN_FOUND_SHARE_OF_TYPICAL_LEAF * typical_leaf_points(leaf_parts.segments)) as usize;
    let before = leaf_parts.segments.len();
    let found =
        leaf_parts.find_missed_leaves(&points, plane_rms, min_found_points, heights, options);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        found,
        "small leaves found among the stem points"
    );
    if found > 0 {
        let found: Vec<usize> = (before..leaf_parts.segments.len()).collect();
        leaf_parts.give_back_borders(&found, &options.borders);
    }
    let phase = Instant::now();
    let relabelled =
        leaf_parts.rejudge_other_segments(&points, plane_rms, min_found_points, heights, options);
    leaf_parts.give_back_borders(&relabelled, &options.borders);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        relabelled = relabelled.len(),
        "small leaves among the segments called other"
    );
    let phase = Instant::now();
    let touching_cut = leaf_parts.split_touching_leaves(&points, plane_rms, heights, options);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        touching_cut,
        "leaf segments holding touching leaves cut"
    );
    let phase = Instant::now();
    let wall = label_pot_wall(&mut segments, &points.positions, &foreground);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        wall,
        "segments on the pot's wall"
    );
    let phase = Instant::now();
    let photo_inconsistent = label_photo_inconsistent(
        scene,
        &points,
        &plant_points.positions,
        &foreground,
        &mut segments,
        &options.photometric,
    );
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        photo_inconsistent,
        "leaf segments whose points the photos do not show alike"
    );
    let phase = Instant::now();
    let edge_on = label_edge_on_by_the_axis(&mut segments, &plant_points.positions, &foreground);
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        edge_on,
        "leaf segments standing edge-on by the plant's axis"
    );
    let phase = Instant::now();
    let pieces_joined = super::pieces::join_leaf_pieces(
        &mut segments,
        &mut point_segment,
        &points.positions,
        spacing,
    );
    tracing::debug!(
        seconds = phase.elapsed().as_secs_f64(),
        pieces_joined,
        "pieces of one leaf joined across a gap"
    );
    // A sheet far smaller than this plant's typical leaf is a crumb (of stem, pot, soil or a
    // stereo halo), not a leaf.
    let typical = typical_leaf_points(&segments);
    for segment in &mut segments {
        if segment.label == SegmentLabel::Leaf {
            if (segment.num_points as f64) < MIN_SHARE_OF_TYPICAL_LEAF * typical {
                segment.label = SegmentLabel::Other;
            } else {
                segment.leaf_id = Some(next_leaf);
                next_leaf += 1;
            }
        }
    }
    timings.partition = clock.elapsed().as_secs_f64();
    check_cancelled()?;
    timings.total = start.elapsed().as_secs_f64();
    Ok(Segmentation {
        points,
        foreground,
        point_segment,
        segments,
        sigma_3d: graph.sigma_3d,
        sigma_2d: graph.sigma_2d,
        edges_total: graph.edges.len(),
        edges_kept: graph.edges.iter().filter(|e| e.weight > 0.0).count(),
        edges_dropped_not_covisible: graph.dropped_not_covisible,
        threshold_components: components.count,
        sheet_merges,
        photo_inconsistent,
        pieces_joined,
        views_with_images,
        ncut: ncut_stats,
        timings,
        options: *options,
        graph,
        graph_points: plant,
        gap_fills,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::points::PointIds;
    use crate::graph::test_support::tube;
    use crate::segment::foreground::Plane;
    use nalgebra::Vector3;

    #[test]
    fn a_strip_of_the_stem_standing_edge_on_by_the_axis_is_not_a_leaf() {
        // A plant about the z axis: eight leaves spread out to 15 cm around a 6 mm stem.
        let mut rng = crate::util::rng::Rng::seed_from(81);
        let mut groups: Vec<Vec<Point3<f64>>> = (0..8)
            .map(|k| {
                let azimuth = k as f64 * std::f64::consts::FRAC_PI_4;
                let (c, s) = (azimuth.cos(), azimuth.sin());
                (0..300)
                    .map(|_| {
                        let (r, w) = (rng.range(0.02, 0.15), rng.range(-0.02, 0.02));
                        Point3::new(r * c - w * s, r * s + w * c, 0.15 + 0.1 * r)
                    })
                    .collect()
            })
            .collect();
        // A strip of the stem's surface on the side the cameras see: an arc of it, 3 cm tall.
        groups.push(
            (0..200)
                .map(|_| {
                    let angle = rng.range(0.0, 0.8);
                    let z = rng.range(0.05, 0.08);
                    Point3::new(0.006 * angle.cos(), 0.006 * angle.sin(), z)
                })
                .collect(),
        );
        // A leaf hanging straight down far out (edge-on, not by the axis), a small leaf lying
        // flat at the top of the stem (by the axis, not edge-on) and a leaf rising 50° from
        // the stem (by the axis, steep but not edge-on).
        groups.push(
            (0..200)
                .map(|_| Point3::new(0.12, rng.range(-0.02, 0.02), rng.range(0.1, 0.16)))
                .collect(),
        );
        groups.push(
            (0..200)
                .map(|_| Point3::new(rng.range(0.0, 0.06), rng.range(-0.01, 0.01), 0.31))
                .collect(),
        );
        let rise = 50f64.to_radians();
        groups.push(
            (0..200)
                .map(|_| {
                    let t = rng.range(0.0, 0.05);
                    Point3::new(
                        -t * rise.cos(),
                        rng.range(-0.01, 0.01),
                        0.25 + t * rise.sin(),
                    )
                })
                .collect(),
        );
        let positions: Vec<Point3<f64>> = groups.iter().flatten().copied().collect();
        let mut start = 0;
        let mut segments: Vec<Segment> = groups
            .iter()
            .enumerate()
            .map(|(id, group)| {
                let range = start..start + group.len();
                start = range.end;
                Segment {
                    id: id as u32,
                    label: SegmentLabel::Leaf,
                    leaf_id: None,
                    points: range.clone().map(|i| i as u32).collect(),
                    num_points: range.len(),
                    shape: Shape::of(group.iter().copied()),
                }
            })
            .collect();
        let foreground = upright(
            PointClass::Plant,
            positions.len(),
            None,
            Point3::new(0.002, -0.001, 0.2),
        );
        assert_eq!(
            label_edge_on_by_the_axis(&mut segments, &positions, &foreground),
            1
        );
        let others: Vec<u32> = segments
            .iter()
            .filter(|s| s.label != SegmentLabel::Leaf)
            .map(|s| s.id)
            .collect();
        assert_eq!(others, [8], "only the stem's strip stops being a leaf");
        assert_eq!(segments[8].label, SegmentLabel::Other);
        // Without plant points there is no reach to be near the axis within: nothing changes.
        let mut unchanged = segments.clone();
        unchanged[8].label = SegmentLabel::Leaf;
        assert_eq!(
            label_edge_on_by_the_axis(&mut unchanged, &[], &foreground),
            0
        );
    }

    #[test]
    fn a_piece_of_the_pot_wall_taken_for_a_leaf_is_labelled_pot() {
        // A pot on the floor (z = 0) around the z axis, rim at z = 0.12, its wall tapering from
        // 0.075 at the floor to 0.09 at the rim. The cameras' axis passes 4 cm from it.
        let mut rng = crate::util::rng::Rng::seed_from(3);
        let wall = |z: f64, angle: f64| {
            let radius = 0.075 + 0.015 * z / 0.12;
            Point3::new(radius * angle.cos(), radius * angle.sin(), z)
        };
        let mut positions: Vec<Point3<f64>> = Vec::new();
        let mut groups: Vec<(SegmentLabel, std::ops::Range<usize>)> = Vec::new();
        let mut add = |label, points: Vec<Point3<f64>>, positions: &mut Vec<Point3<f64>>| {
            let start = positions.len();
            positions.extend(points);
            groups.push((label, start..positions.len()));
        };
        // What the pot test found: an arc of the wall on one side.
        let arc = (0..300)
            .map(|_| wall(rng.range(0.0, 0.12), rng.range(3.0, 4.4)))
            .collect();
        add(SegmentLabel::Pot, arc, &mut positions);
        // Another arc of the wall, low down, which the leaf test took as a sheet.
        let piece = (0..400)
            .map(|_| wall(rng.range(0.01, 0.08), rng.range(0.5, 1.5)))
            .collect();
        add(SegmentLabel::Leaf, piece, &mut positions);
        // A crown of leaves above the pot (most of the plant's leaf points), and a leaf hanging
        // over the rim and down outside the wall.
        let above = (0..8000)
            .map(|_| {
                let (r, a) = (rng.range(0.1, 0.25), rng.range(2.0, 2.6));
                Point3::new(r * a.cos(), r * a.sin(), 0.2 + 0.2 * (r - 0.1))
            })
            .collect();
        add(SegmentLabel::Leaf, above, &mut positions);
        let hanging = (0..400)
            .map(|_| {
                let (t, w) = (rng.range(0.0, 1.0), rng.range(-0.02, 0.02));
                Point3::new(0.092 + 0.11 * t, w, 0.13 - 0.08 * t)
            })
            .collect();
        add(SegmentLabel::Leaf, hanging, &mut positions);
        let n = positions.len();
        let mut segments: Vec<Segment> = groups
            .iter()
            .enumerate()
            .map(|(id, (label, range))| Segment {
                id: id as u32,
                label: *label,
                leaf_id: None,
                points: range.clone().map(|i| i as u32).collect(),
                num_points: range.len(),
                shape: Shape::of(positions[range.clone()].iter().copied()),
            })
            .collect();
        let foreground = upright(PointClass::Plant, n, None, Point3::new(0.03, -0.025, 0.2));
        assert_eq!(label_pot_wall(&mut segments, &positions, &foreground), 1);
        let labels: Vec<SegmentLabel> = segments.iter().map(|s| s.label).collect();
        assert_eq!(
            labels,
            [
                SegmentLabel::Pot,
                SegmentLabel::Pot,
                SegmentLabel::Leaf,
                SegmentLabel::Leaf
            ]
        );
        // The same pot with a rosette of leaves lying 6 cm below its rim outside it (a tenth
        // of the leaf points): pieces of a plant taken for a pot, so nothing changes.
        let mut rosette_points = positions.clone();
        let start = rosette_points.len();
        rosette_points.extend((0..900).map(|k| {
            let (r, a) = (0.15 + 0.0001 * k as f64, 0.007 * k as f64);
            Point3::new(r * a.cos(), r * a.sin(), 0.06)
        }));
        let mut with_rosette = segments.clone();
        with_rosette[1].label = SegmentLabel::Leaf;
        with_rosette.push(Segment {
            id: 4,
            label: SegmentLabel::Leaf,
            leaf_id: None,
            points: (start as u32..rosette_points.len() as u32).collect(),
            num_points: 900,
            shape: Shape::of(rosette_points[start..].iter().copied()),
        });
        let rosette_foreground = upright(
            PointClass::Plant,
            rosette_points.len(),
            None,
            Point3::new(0.03, -0.025, 0.2),
        );
        assert_eq!(
            label_pot_wall(&mut with_rosette, &rosette_points, &rosette_foreground),
            0
        );
        assert_eq!(with_rosette[1].label, SegmentLabel::Leaf);
        // Without a pot found (too few pot points) nothing changes.
        let mut few = segments.clone();
        few[0]
            .points
            .truncate(super::super::pot::MIN_POT_POINTS - 1);
        few[1].label = SegmentLabel::Leaf;
        assert_eq!(label_pot_wall(&mut few, &positions, &foreground), 0);
        assert_eq!(few[1].label, SegmentLabel::Leaf);
    }

    /// Green points each seen by view 0, ids in order.
    #[test]
    fn strips_of_one_sheet_merge_round_after_round_and_a_fold_does_not() {
        // A flat sheet cut into three strips across its length, and a wall folded up at 90°
        // from the last strip's far edge (its first row lies in the sheet's plane).
        // Jittered within each surface, so that no point has neighbours exactly as near.
        let step = 0.001;
        let mut rng = crate::util::rng::Rng::seed_from(3);
        let mut jitter = || 0.3 * step * (rng.uniform() - 0.5);
        let mut positions = Vec::new();
        let mut groups: Vec<Vec<u32>> = vec![Vec::new(); 4];
        for i in 0..30 {
            for j in 0..12 {
                groups[i / 10].push(positions.len() as u32);
                let (x, y) = (i as f64 * step + jitter(), j as f64 * step + jitter());
                positions.push(Point3::new(x, y, 0.0));
            }
        }
        for k in 0..11 {
            for j in 0..12 {
                groups[3].push(positions.len() as u32);
                let (y, z) = (j as f64 * step + jitter(), k as f64 * step + jitter().abs());
                positions.push(Point3::new(30.0 * step, y, z));
            }
        }
        let points = green_points(positions);
        let graph = graph_without_images(&points);
        let options = NcutOptions::default();
        let (merged, merges) = merge_sheets(
            groups.clone(),
            &graph,
            &points.positions,
            &options,
            options.min_merge_contact,
        );
        // Two merges need two rounds: a strip merged in one round waits for the next.
        assert_eq!(merges, 2);
        let mut sheet: Vec<u32> = groups[..3].concat();
        sheet.sort_unstable();
        let mut found: Vec<Vec<u32>> = merged
            .into_iter()
            .map(|mut g| {
                g.sort_unstable();
                g
            })
            .collect();
        found.sort();
        assert_eq!(found, vec![sheet, groups[3].clone()]);
    }

    /// The kNN graph of `points` from 3D distances alone (no image gradients).
    fn graph_without_images(points: &PointSet) -> PointGraph {
        PointGraph::build(
            points,
            &[],
            GraphOptions {
                alpha: 0.0,
                ..GraphOptions::default()
            },
        )
    }

    fn green_points(positions: Vec<Point3<f64>>) -> PointSet {
        let n = positions.len();
        PointSet {
            positions,
            colors: vec![[40, 160, 40]; n],
            views: vec![vec![0]; n],
            point_ids: (0..n as u64).collect(),
            id_kind: PointIds::default(),
            thin_organ: Vec::new(),
            gap_fill: Vec::new(),
        }
    }

    #[test]
    fn plant_points_the_thin_organ_sweep_found_are_stem_candidates() {
        let mut points = green_points(vec![Point3::origin(); 4]);
        points.thin_organ = vec![false, true, true, true];
        let mut class = vec![
            PointClass::Plant,
            PointClass::Plant,
            PointClass::Floor,
            PointClass::Stem,
        ];
        thin_organs_are_stem_points(&points, &mut class);
        // Only plant points change: a sweep point on the floor stays floor.
        assert_eq!(
            class,
            vec![
                PointClass::Plant,
                PointClass::Stem,
                PointClass::Floor,
                PointClass::Stem
            ]
        );
    }

    /// A plant from the ground at 0 to 0.5 m.
    const HALF_METRE_PLANT: PlantHeights = PlantHeights {
        ground: 0.0,
        top: 0.5,
    };

    /// The plane z = 0.
    fn floor_at_zero() -> Plane {
        Plane {
            normal: Vector3::z(),
            offset: 0.0,
        }
    }

    /// A foreground with `z` up, every one of `n` points of one class.
    fn upright(
        class: PointClass,
        n: usize,
        floor: Option<Plane>,
        plant_center: Point3<f64>,
    ) -> Foreground {
        Foreground {
            class: vec![class; n],
            up: Vector3::z(),
            floor,
            walls: Vec::new(),
            plant_center,
            radius_limit: 1.0,
        }
    }

    /// Deterministic jitter in [−1, 1].
    fn jitter(k: usize) -> f64 {
        ((k as f64 * 12.9898).sin() * 43_758.545).fract()
    }

    #[test]
    fn without_a_floor_only_a_low_arc_around_the_axis_is_pot() {
        // A plant 1 m tall with no floor in its points (as the real Arabidopsis): its stem 5 cm
        // from the cameras' axis, the cameras looking at its middle.
        let stem: Vec<Point3<f64>> = (0..=200)
            .map(|k| Point3::new(0.05, 0.0, k as f64 * 0.005))
            .collect();
        let foreground = upright(
            PointClass::Plant,
            stem.len(),
            None,
            Point3::new(0.0, 0.0, 0.5),
        );
        let heights = PlantHeights::of(&stem, &foreground);
        assert!((heights.ground + 0.48).abs() < 0.01, "{heights:?}");
        assert!((heights.top - 0.96).abs() < 0.01, "{heights:?}");
        // Sixty points at height `z` (normals every way), placed by `at` from three jitters.
        let label = |z: f64, at: &dyn Fn(f64, f64, f64) -> Point3<f64>| {
            let points: Vec<Point3<f64>> = (0..60)
                .map(|k| at(jitter(k), jitter(k + 100), z + jitter(k + 200) * 0.008))
                .collect();
            let normals: Vec<Vector3<f64>> = (0..60)
                .map(|k| {
                    Vector3::new(jitter(k + 300), jitter(k + 400), jitter(k + 500))
                        .try_normalize(1e-9)
                        .unwrap_or_else(Vector3::z)
                })
                .collect();
            classify(
                &Shape::of(points.iter().copied()),
                &points,
                &normals,
                SheetScale {
                    noise: 0.001,
                    min_facing: MIN_LEAF_FACING,
                    min_points: NcutOptions::default().min_segment_points,
                },
                &foreground,
                heights,
                &NcutOptions::default(),
            )
        };
        // An arc of a wall 5 cm from the axis, 40° round it, 16 mm tall, 4 mm thick.
        let arc = |a: f64, r: f64, z: f64| {
            let (radius, angle) = (0.05 + 0.002 * r, 0.35 * a);
            Point3::new(radius * angle.cos(), radius * angle.sin(), z)
        };
        // A compact blob of the stem's halo, 8 mm across: also at one distance from the axis,
        // as small things far from it are, but reaching no further round it than across it.
        let blob = |a: f64, r: f64, z: f64| Point3::new(0.05 + 0.004 * r, 0.004 * a, z);
        // Just below the point the cameras look at: mid-plant, not low (heights measured from
        // that point called it low).
        assert_eq!(label(0.45, &arc), SegmentLabel::Other);
        assert_eq!(label(0.45, &blob), SegmentLabel::Other);
        // In the plant's lowest third: the arc is pot, the blob is not (the old test, spread
        // against distance alone, took the real Arabidopsis's lower stem and rosette for pot).
        assert_eq!(label(0.1, &arc), SegmentLabel::Pot);
        assert_eq!(label(0.1, &blob), SegmentLabel::Other);
    }

    /// Runs `run` on the segmentation's parts for `positions`, all of them stem-class points in
    /// no segment (points `spacing` apart); returns its result, the segments and each point's
    /// segment.
    fn with_stem_points<R>(
        positions: Vec<Point3<f64>>,
        spacing: f64,
        run: impl FnOnce(&mut LeafParts<'_>, &PointSet) -> R,
    ) -> (R, Vec<Segment>, Vec<Option<u32>>) {
        with_coloured_stem_points(green_points(positions), spacing, run)
    }

    /// [`with_stem_points`] for points with their own colours.
    fn with_coloured_stem_points<R>(
        points: PointSet,
        spacing: f64,
        run: impl FnOnce(&mut LeafParts<'_>, &PointSet) -> R,
    ) -> (R, Vec<Segment>, Vec<Option<u32>>) {
        let n = points.len();
        let mut foreground = upright(
            PointClass::Stem,
            n,
            Some(floor_at_zero()),
            Point3::new(0.05, 0.05, 0.2),
        );
        let mut point_segment = vec![None; n];
        let mut segments = Vec::new();
        let mut noise_of_segment = Vec::new();
        let mut parts = LeafParts {
            positions: &points.positions,
            foreground: &mut foreground,
            point_segment: &mut point_segment,
            segments: &mut segments,
            noise_of_segment: &mut noise_of_segment,
            spacing,
        };
        let result = run(&mut parts, &points);
        (result, segments, point_segment)
    }

    /// Adds a segment of `label` holding `group`, with its points' `noise`.
    fn add_segment(
        parts: &mut LeafParts<'_>,
        points: &PointSet,
        label: SegmentLabel,
        group: &[usize],
        noise: f64,
    ) {
        let s = parts.segments.len();
        parts.segments.push(Segment {
            id: s as u32,
            label,
            leaf_id: None,
            points: Vec::new(),
            num_points: 0,
            shape: Shape::of(group.iter().map(|&i| points.positions[i])),
        });
        parts.noise_of_segment.push(noise);
        for &i in group {
            parts.assign(i, s);
        }
        parts.refresh(s);
    }

    /// A strip cut from a thick stem's surface is bounded all round by the rest of the stem; a
    /// small leaf only where its twig joins it.
    #[test]
    fn a_stem_patch_is_bounded_all_round_and_a_leaf_has_a_free_edge() {
        let spacing = 0.002;
        let mut positions = tube(Point3::new(0.0, 0.0, 0.2), 0.012, 0.06, spacing);
        let around = ((std::f64::consts::TAU * 0.012 / spacing).ceil()) as usize;
        // Three columns of the stem, eight rows up.
        let patch: Vec<usize> = (10..18)
            .flat_map(|k| (0..3).map(move |j| k * around + j))
            .collect();
        let leaf_start = positions.len();
        for i in -4i32..=4 {
            for j in -2i32..=2 {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                if (u / 0.0095).powi(2) + (v / 0.0045).powi(2) <= 1.0 {
                    positions.push(Point3::new(0.1 + u, v, 0.25));
                }
            }
        }
        let leaf: Vec<usize> = (leaf_start..positions.len()).collect();
        // Its twig from its base, down and away.
        positions.extend((1..=10).map(|k| Point3::new(0.09 - k as f64 * spacing, 0.0, 0.25)));
        let (on_stem, on_leaf) = with_stem_points(positions, spacing, |parts, points| {
            let all = Neighbours::new(points.positions.iter().copied()).unwrap();
            (
                parts.bounded_share(&patch, &all),
                parts.bounded_share(&leaf, &all),
            )
        })
        .0;
        assert!(
            on_stem > MAX_FOUND_LEAF_BOUNDED_SHARE,
            "stem patch {on_stem:.2}"
        );
        assert!(on_leaf < 0.5, "leaf {on_leaf:.2}");
    }

    /// A flat elliptic leaf at 0.3 m sampled every 2 mm with 0.2 mm of noise, `half_length` long
    /// on either side and 4.5 mm wide on either side (`columns` grid columns either side of its
    /// middle, rows −2..=2), and a twig along its long side 2 mm below the rim (`twig` points
    /// either side). Returns the points (the leaf's first), the leaf points where `sheet(column,
    /// row)` holds, each leaf point's column and the leaf's point count.
    fn leaf_over_a_twig(
        half_length: f64,
        columns: i32,
        twig: i32,
        sheet: impl Fn(i32, i32) -> bool,
    ) -> (Vec<Point3<f64>>, Vec<usize>, Vec<i32>, usize) {
        let spacing = 0.002;
        let noise = 0.0002;
        let mut positions = Vec::new();
        let mut sheet_points = Vec::new();
        let mut column = Vec::new();
        for i in -columns..=columns {
            for j in -2i32..=2 {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                if (u / half_length).powi(2) + (v / 0.0045).powi(2) > 1.0 {
                    continue;
                }
                let k = positions.len();
                if sheet(i, j) {
                    sheet_points.push(k);
                }
                column.push(i);
                positions.push(Point3::new(
                    u + 0.3 * noise * jitter(k + 7),
                    v + 0.3 * noise * jitter(k + 11),
                    0.3 + noise * jitter(k),
                ));
            }
        }
        let leaf = positions.len();
        positions.extend((-twig..=twig).map(|k| Point3::new(k as f64 * spacing, 0.0045, 0.298)));
        (positions, sheet_points, column, leaf)
    }

    /// [`LeafParts::sheet_groups_with_rims`] of `sheet_points` among `positions` (2 mm apart,
    /// 0.2 mm of noise), every point a candidate.
    fn rim_groups(
        positions: Vec<Point3<f64>>,
        sheet_points: &[usize],
    ) -> Vec<(Vec<usize>, Vec<usize>)> {
        let n = positions.len();
        with_stem_points(positions, 0.002, |parts, _| {
            let noise_of = (0..n).map(|i| (i, 0.0002)).collect();
            parts.sheet_groups_with_rims(
                sheet_points,
                &vec![true; n],
                &noise_of,
                &BorderOptions::default(),
            )
        })
        .0
    }

    /// A leaf of a few dozen points whose rim did not pass the sheet test (on a small leaf the
    /// rim's neighbourhoods reach onto the twig): the group of its inner sheet points takes the
    /// rim back, and not the twig 2 mm below the rim.
    #[test]
    fn a_group_of_sheet_points_takes_back_its_rim_and_not_the_twig() {
        // An elliptic leaf 14 × 8 mm; its middle row and the next ones passed.
        let (positions, inner, _, leaf) =
            leaf_over_a_twig(0.0075, 3, 6, |i, j| j.abs() <= 1 && i.abs() <= 2);
        let groups = rim_groups(positions, &inner);
        assert_eq!(groups.len(), 1, "{groups:?}");
        assert!(inner.len() < leaf, "{} of {leaf} inner", inner.len());
        for pass in [&groups[0].0, &groups[0].1] {
            assert_eq!(pass, &(0..leaf).collect::<Vec<_>>(), "{leaf} leaf points");
        }
    }

    /// Three segments the main leaf test called other: a small leaf, a fold (two half-sheets
    /// at right angles, with free edges) and a strip cut from a thick stem's surface. With
    /// normals from within each segment only the leaf passes the found-leaf test; the strip's
    /// normals face one way too, but it is bounded all round by the rest of the stem.
    #[test]
    fn a_small_leaf_labelled_other_is_rejudged_and_a_fold_or_a_stem_strip_is_not() {
        let spacing = 0.002;
        let noise = 0.0002;
        let mut positions = Vec::new();
        let push = |positions: &mut Vec<Point3<f64>>, p: Point3<f64>| {
            let k = positions.len();
            positions.push(p + Vector3::new(0.0, 0.0, noise * jitter(k)));
            k
        };
        let mut leaf = Vec::new();
        for i in -6i32..=6 {
            for j in -3i32..=3 {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                if (u / 0.013).powi(2) + (v / 0.006).powi(2) <= 1.0 {
                    leaf.push(push(&mut positions, Point3::new(u, v, 0.3)));
                }
            }
        }
        let mut fold = Vec::new();
        for i in 0..6 {
            for j in -3i32..=3 {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                fold.push(push(&mut positions, Point3::new(0.2 + u, v, 0.3)));
                fold.push(push(&mut positions, Point3::new(0.2, v, 0.302 + u)));
            }
        }
        let start = positions.len();
        let stem = tube(Point3::new(0.1, 0.1, 0.15), 0.012, 0.06, spacing);
        let around = ((std::f64::consts::TAU * 0.012 / spacing).ceil()) as usize;
        for p in stem {
            push(&mut positions, p);
        }
        let strip: Vec<usize> = (10..18)
            .flat_map(|k| (0..3).map(move |j| start + k * around + j))
            .collect();
        let options = SegmentOptions::default();
        let (relabelled, segments, _) = with_stem_points(positions, spacing, |parts, points| {
            for group in [&leaf, &fold, &strip] {
                add_segment(parts, points, SegmentLabel::Other, group, noise);
            }
            parts.rejudge_other_segments(points, 0.5 * noise, 20, HALF_METRE_PLANT, &options)
        });
        assert_eq!(relabelled, vec![0]);
        let labels: Vec<SegmentLabel> = segments.iter().map(|s| s.label).collect();
        assert_eq!(
            labels,
            [SegmentLabel::Leaf, SegmentLabel::Other, SegmentLabel::Other]
        );
    }

    /// A small leaf rolled into a half pipe fails the leaf test (its normals face no one way),
    /// and so does a piece of bark of the same shape. On a plant whose leaves and stems differ
    /// in colour, the leaf-green one is relabelled leaf by its colour and the bark-coloured one
    /// is not; a green segment of twice a typical leaf's points is left to the touching-leaves
    /// cut.
    #[test]
    fn a_curled_small_leaf_is_called_leaf_by_its_colour_and_bark_of_its_shape_is_not() {
        let spacing = 0.002;
        let noise = 0.0002;
        let mut rng = crate::util::rng::Rng::seed_from(11);
        let mut positions: Vec<Point3<f64>> = Vec::new();
        let mut colors: Vec<[u8; 3]> = Vec::new();
        let mut add = |points: Vec<Point3<f64>>, rgb: [f64; 3]| {
            let start = positions.len();
            for p in points {
                let k = positions.len();
                positions.push(p + Vector3::new(0.0, 0.0, noise * jitter(k)));
                let shade = rng.range(0.5, 1.0);
                colors.push(
                    rgb.map(|c| (shade * (c + rng.range(-20.0, 20.0))).clamp(0.0, 255.0) as u8),
                );
            }
            (start..positions.len()).collect::<Vec<usize>>()
        };
        let green = [60.0, 125.0, 50.0];
        let bark = [115.0, 100.0, 60.0];
        let flat_leaf = |x: f64| {
            let mut out = Vec::new();
            for i in -6i32..=6 {
                for j in -3i32..=3 {
                    let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                    if (u / 0.013).powi(2) + (v / 0.006).powi(2) <= 1.0 {
                        out.push(Point3::new(x + u, 0.1 + v, 0.3));
                    }
                }
            }
            out
        };
        // Half pipes of radius 5 mm (eight points around), `rows` rows along x.
        let half_pipe = |centre: Point3<f64>, rows: usize| {
            let mut out = Vec::new();
            for row in 0..rows {
                for k in 0..8 {
                    let a = std::f64::consts::PI * k as f64 / 7.0;
                    out.push(
                        centre
                            + Vector3::new(row as f64 * spacing, 0.005 * a.cos(), 0.005 * a.sin()),
                    );
                }
            }
            out
        };
        let leaves: Vec<Vec<usize>> = [-0.05, 0.0, 0.05]
            .into_iter()
            .map(|x| add(flat_leaf(x), green))
            .collect();
        let curled_leaf = add(half_pipe(Point3::new(0.1, -0.1, 0.3), 6), green);
        let curled_bark = add(half_pipe(Point3::new(-0.1, -0.1, 0.3), 6), bark);
        let large = add(half_pipe(Point3::new(0.0, -0.15, 0.3), 16), green);
        add(
            tube(Point3::new(0.1, 0.1, 0.15), 0.012, 0.06, spacing),
            bark,
        );
        let n = positions.len();
        let points = PointSet {
            positions,
            colors,
            views: vec![vec![0]; n],
            point_ids: (0..n as u64).collect(),
            id_kind: PointIds::default(),
            thin_organ: Vec::new(),
            gap_fill: Vec::new(),
        };
        let options = SegmentOptions::default();
        let (relabelled, segments, _) =
            with_coloured_stem_points(points, spacing, |parts, points| {
                let groups = leaves.iter().map(|g| (SegmentLabel::Leaf, g)).chain([
                    (SegmentLabel::Other, &curled_leaf),
                    (SegmentLabel::Other, &curled_bark),
                    (SegmentLabel::Other, &large),
                ]);
                for (label, group) in groups {
                    add_segment(parts, points, label, group, noise);
                }
                assert!(
                    parts.organ_colours(points).is_some(),
                    "leaf green and bark differ"
                );
                parts.rejudge_other_segments(points, 0.5 * noise, 20, HALF_METRE_PLANT, &options)
            });
        assert_eq!(relabelled, vec![3]);
        let labels: Vec<SegmentLabel> = segments[3..].iter().map(|s| s.label).collect();
        assert_eq!(
            labels,
            [SegmentLabel::Leaf, SegmentLabel::Other, SegmentLabel::Other]
        );
    }

    /// A narrow leaf whose sheet points lie only at its base: the first pass takes back the rim
    /// within reach of them (three spacings), the second, from the sheet refitted to both, the
    /// next stretch of the leaf; neither takes the twig 2 mm below the leaf.
    #[test]
    fn a_second_pass_takes_back_more_of_a_leaf_whose_sheet_points_lie_at_one_end() {
        // An elliptic leaf 30 × 9 mm; its sheet points are the middle rows of its last four
        // columns.
        let (positions, seed, column, leaf) =
            leaf_over_a_twig(0.015, 7, 8, |i, j| i <= -4 && j.abs() <= 1);
        let groups = rim_groups(positions, &seed);
        assert_eq!(groups.len(), 1, "{groups:?}");
        let (first, second) = &groups[0];
        let columns = |group: &[usize]| -> Vec<i32> {
            let mut c: Vec<i32> = group.iter().map(|&p| column[p]).collect();
            c.dedup();
            c
        };
        assert!(first.iter().chain(second).all(|&p| p < leaf), "no twig");
        assert!(first.len() < second.len(), "{first:?} then {second:?}");
        assert!(
            (0..leaf).all(|p| column[p] > -3 || first.contains(&p)),
            "first pass: columns {:?}",
            columns(first)
        );
        assert!(
            (0..leaf).all(|p| column[p] > 0 || second.contains(&p)),
            "second pass: columns {:?}",
            columns(second)
        );
        assert!(
            first.iter().all(|&p| column[p] <= -1),
            "first pass: columns {:?}",
            columns(first)
        );
    }

    #[test]
    fn a_small_leaf_the_stem_test_took_whole_is_found_and_its_twig_and_stem_are_not() {
        let spacing = 0.002;
        let noise = 0.0002;
        let mut positions = Vec::new();
        // An elliptic leaf 26 × 12 mm, tilted 30° about x, at 0.3 m.
        let (tilt_cos, tilt_sin) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        for i in -6..=6 {
            for j in -3..=3 {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                if (u / 0.013).powi(2) + (v / 0.006).powi(2) > 1.0 {
                    continue;
                }
                let k = positions.len();
                let w = noise * jitter(k);
                positions.push(Point3::new(
                    u + 0.5 * noise * jitter(k + 7),
                    v * tilt_cos - w * tilt_sin,
                    0.3 + v * tilt_sin + w * tilt_cos,
                ));
            }
        }
        let leaf = positions.len();
        let twig_end = add_twig_and_stem(&mut positions, Point3::new(-0.013, 0.0, 0.3), 30);
        let options = SegmentOptions::default();
        let ((found, sizes), segments, point_segment) =
            with_stem_points(positions, spacing, |parts, points| {
                let found =
                    parts.find_missed_leaves(points, 0.5 * noise, 20, HALF_METRE_PLANT, &options);
                let sizes: Vec<usize> = parts.segments.iter().map(|s| s.num_points).collect();
                let all: Vec<usize> = (0..parts.segments.len()).collect();
                parts.give_back_borders(&all, &options.borders);
                (found, sizes)
            });
        assert_eq!(found, 1, "{sizes:?}");
        let members = &segments[0].points;
        let on_leaf = members.iter().filter(|&&p| (p as usize) < leaf).count();
        let elsewhere = members.len() - on_leaf;
        assert_eq!(segments[0].label, SegmentLabel::Leaf);
        assert!(on_leaf * 10 >= leaf * 9, "{on_leaf} of {leaf} leaf points");
        assert!(elsewhere <= 2, "{elsewhere} twig or stem points");
        assert!(
            (leaf..twig_end).all(|p| point_segment[p].is_none()),
            "the twig stays out"
        );
    }

    /// Adds a leaf's twig (`twig_points` points 2 mm apart from `leaf_base`, down and away at
    /// 45°) and a stem 12 mm in radius lower down, sampled all round with 0.06 mm of noise;
    /// returns where the twig ends (the stem's first point).
    fn add_twig_and_stem(
        positions: &mut Vec<Point3<f64>>,
        leaf_base: Point3<f64>,
        twig_points: usize,
    ) -> usize {
        let spacing = 0.002;
        let noise = 0.0002;
        positions.extend((1..=twig_points).map(|k| {
            let along = k as f64 * spacing * std::f64::consts::FRAC_1_SQRT_2;
            leaf_base + Vector3::new(-along, 0.0, -along)
        }));
        let twig_end = positions.len();
        positions.extend(
            tube(Point3::new(0.1, 0.1, 0.15), 0.012, 0.06, spacing)
                .into_iter()
                .enumerate()
                .map(|(k, p)| p + Vector3::new(0.0, 0.0, 0.3 * noise * jitter(k + 3))),
        );
        twig_end
    }

    /// A leaf of fewer points than the normalized cut's smallest segment (20), taken whole by
    /// the stem test, is found down to one sheet neighbourhood; the stem beside it, whose
    /// patches of that size are as flat, is not (bounded all round).
    #[test]
    fn a_leaf_smaller_than_the_smallest_segment_is_found_and_the_stem_is_not() {
        let spacing = 0.002;
        let noise = 0.0002;
        let mut positions = small_leaf(Point3::new(0.0, 0.0, 0.3), 0.3, 0.5, 0.012, 0.006, 11);
        let leaf = positions.len();
        assert!(
            (MIN_FOUND_LEAF_POINTS..NcutOptions::default().min_segment_points).contains(&leaf),
            "{leaf} leaf points"
        );
        let twig_end = add_twig_and_stem(&mut positions, Point3::new(0.0, 0.0, 0.3), 20);
        let options = SegmentOptions::default();
        let ((found, sizes), segments, point_segment) =
            with_stem_points(positions, spacing, |parts, points| {
                // A plant whose typical leaf has 60 points: a sixth of it is 10.
                let min_points = (MIN_FOUND_SHARE_OF_TYPICAL_LEAF * 60.0) as usize;
                let found = parts.find_missed_leaves(
                    points,
                    0.5 * noise,
                    min_points,
                    HALF_METRE_PLANT,
                    &options,
                );
                let sizes: Vec<usize> = parts.segments.iter().map(|s| s.num_points).collect();
                (found, sizes)
            });
        assert_eq!(found, 1, "{sizes:?}");
        assert_eq!(segments[0].label, SegmentLabel::Leaf);
        let on_leaf = segments[0]
            .points
            .iter()
            .filter(|&&p| (p as usize) < leaf)
            .count();
        assert!(on_leaf * 4 >= leaf * 3, "{on_leaf} of {leaf} leaf points");
        assert!(
            (twig_end..point_segment.len()).all(|p| point_segment[p].is_none()),
            "the stem stays out"
        );
    }

    /// A small leaf joined to a thick stem's surface in one group of sheet points (the group
    /// fails the leaf test as a whole) is peeled off it at the crease where it meets the stem:
    /// the leaf comes away as one part judged a leaf, and no part of the stem is judged one.
    #[test]
    fn a_small_leaf_joined_to_a_thick_stem_is_peeled_off_it() {
        let spacing = 0.002;
        let noise = 0.0002;
        let (centre, radius) = (Point3::new(0.1, 0.1, 0.15), 0.02);
        let mut positions: Vec<Point3<f64>> = tube(centre, radius, 0.08, spacing)
            .into_iter()
            .enumerate()
            .map(|(k, p)| p + Vector3::new(0.0, 0.0, 0.3 * noise * jitter(k + 3)))
            .collect();
        let stem = positions.len();
        // The leaf's base on the stem's surface halfway up, the leaf running out along +x and
        // tilted up by 30°.
        let base = centre + Vector3::new(radius + 0.5 * spacing, 0.0, 0.04);
        positions.extend(small_leaf(base, 0.0, 30f64.to_radians(), 0.024, 0.012, 5));
        let leaf = positions.len() - stem;
        let options = SegmentOptions::default();
        let plane_rms = 0.5 * noise;
        let ((parts, judged), _, _) = with_stem_points(positions, spacing, |parts, points| {
            let group: Vec<usize> = (0..points.len()).collect();
            let judge = parts
                .found_leaf_judge(plane_rms, 10, HALF_METRE_PLANT, &options.ncut)
                .expect("a flat sheet at 2 mm");
            let max_turn = PEEL_TURN_SCALE
                * (1.0
                    - FlatSheet::like(spacing, plane_rms)
                        .expect("a flat sheet at 2 mm")
                        .facing(SHEET_SHAPE_NEIGHBOURS));
            assert!(!parts.is_found_leaf(
                &judge,
                points,
                &group,
                plane_rms,
                MAX_FOUND_LEAF_BOUNDED_SHARE
            ));
            let peeled = parts.peel(points, &group, max_turn);
            let judged: Vec<bool> = peeled
                .iter()
                .map(|part| {
                    parts.is_found_leaf(&judge, points, part, plane_rms, MAX_PEELED_BOUNDED_SHARE)
                })
                .collect();
            (peeled, judged)
        });
        let leaves: Vec<&Vec<usize>> = parts
            .iter()
            .zip(&judged)
            .filter(|(_, leaf)| **leaf)
            .map(|(part, _)| part)
            .collect();
        assert_eq!(leaves.len(), 1, "{} parts", parts.len());
        let on_leaf = leaves[0].iter().filter(|&&p| p >= stem).count();
        let on_stem = leaves[0].len() - on_leaf;
        assert!(on_leaf * 4 >= leaf * 3, "{on_leaf} of {leaf} leaf points");
        assert!(on_stem <= 3, "{on_stem} stem points");
    }

    /// An elliptic leaf `length` × `width` on a 2 mm grid with 0.2 mm of noise, its base at
    /// `base`, running along `direction` (horizontal) and tilted up by `tilt` radians.
    fn small_leaf(
        base: Point3<f64>,
        direction: f64,
        tilt: f64,
        length: f64,
        width: f64,
        seed: usize,
    ) -> Vec<Point3<f64>> {
        let spacing = 0.002;
        let noise = 0.0002;
        let along = Vector3::new(
            direction.cos() * tilt.cos(),
            direction.sin() * tilt.cos(),
            tilt.sin(),
        );
        let across = Vector3::new(-direction.sin(), direction.cos(), 0.0);
        let normal = along.cross(&across);
        let mut points = Vec::new();
        let (half_length, half_width) = (0.5 * length, 0.5 * width);
        for i in 0..=((length / spacing) as i32) {
            for j in -((half_width / spacing) as i32)..=((half_width / spacing) as i32) {
                let (u, v) = (i as f64 * spacing, j as f64 * spacing);
                if ((u - half_length) / half_length).powi(2) + (v / half_width).powi(2) > 1.0 {
                    continue;
                }
                let k = seed + points.len();
                points.push(base + along * u + across * v + normal * (noise * jitter(k)));
            }
        }
        points
    }

    /// Runs [`LeafParts::split_touching_leaves`] on one leaf segment per `(start, end)` range
    /// of `positions` (2 mm spacing, 0.2 mm of noise); returns the cuts and the segments after.
    fn cut_touching_leaves(
        positions: Vec<Point3<f64>>,
        members: &[(usize, usize)],
    ) -> (usize, Vec<Segment>) {
        let leaves: Vec<_> = members
            .iter()
            .map(|&(start, end)| (start, end, SegmentLabel::Leaf))
            .collect();
        cut_touching_segments(positions, &leaves)
    }

    /// [`LeafParts::split_touching_leaves`] on segments of the points `start..end`, each with
    /// its label, among a plant of stem points.
    fn cut_touching_segments(
        positions: Vec<Point3<f64>>,
        members: &[(usize, usize, SegmentLabel)],
    ) -> (usize, Vec<Segment>) {
        let noise = 0.0002;
        let options = SegmentOptions::default();
        let (cuts, segments, _) = with_stem_points(positions, 0.002, |parts, points| {
            for &(start, end, label) in members {
                let group: Vec<usize> = (start..end).collect();
                add_segment(parts, points, label, &group, 0.5 * noise);
            }
            parts.split_touching_leaves(points, 0.5 * noise, HALF_METRE_PLANT, &options)
        });
        (cuts, segments)
    }

    /// Two small leaves 22 × 12 mm that leave one twig together, 70° apart and touching at
    /// their bases, and where the second one's points start.
    fn two_touching_small_leaves() -> (Vec<Point3<f64>>, usize) {
        let base = Point3::new(0.0, 0.0, 0.3);
        let mut positions = small_leaf(base, 0.0, 0.0, 0.022, 0.012, 0);
        let first = positions.len();
        positions.extend(small_leaf(
            base + Vector3::new(-0.002, 0.0, 0.0),
            std::f64::consts::PI,
            70f64.to_radians(),
            0.022,
            0.012,
            500,
        ));
        (positions, first)
    }

    /// Each segment is a leaf and holds (95 %) the points of one of the two leaves of
    /// [`two_touching_small_leaves`], whose second leaf starts at point `first`.
    fn assert_one_leaf_each<'a>(segments: impl IntoIterator<Item = &'a Segment>, first: usize) {
        for segment in segments {
            assert_eq!(segment.label, SegmentLabel::Leaf, "{segment:?}");
            let on_first = segment
                .points
                .iter()
                .filter(|&&p| (p as usize) < first)
                .count();
            let majority = on_first.max(segment.num_points - on_first);
            assert!(
                majority * 100 >= 95 * segment.num_points,
                "{on_first} of {} on the first leaf",
                segment.num_points
            );
        }
    }

    /// Two small leaves that leave one twig together, 70° apart and touching at their bases,
    /// in one leaf segment: cut into one segment per leaf. A smaller single leaf beside them is
    /// not tried; a single leaf with about as many points as the two, alone, is not cut.
    #[test]
    fn two_small_leaves_that_touch_at_their_bases_are_cut_apart_and_one_leaf_is_not() {
        let (mut positions, first) = two_touching_small_leaves();
        let both = positions.len();
        let single = small_leaf(Point3::new(0.2, 0.0, 0.3), 0.0, 0.2, 0.036, 0.012, 900);
        let singles = single.len();
        positions.extend(single);
        assert!(
            first >= 30 && both - first >= 30,
            "{first} and {}",
            both - first
        );
        let (cuts, segments) = cut_touching_leaves(positions, &[(0, both), (both, both + singles)]);
        assert_eq!(cuts, 1, "{segments:?}");
        assert_eq!(segments.len(), 3);
        assert_eq!(segments[1].num_points, singles, "the single leaf is whole");
        // Alone, the single leaf is the plant's typical leaf and is tried: not cut.
        let single = small_leaf(Point3::new(0.2, 0.0, 0.3), 0.0, 0.2, 0.044, 0.012, 900);
        let alone = single.len();
        let (single_cuts, single_segments) = cut_touching_leaves(single, &[(0, alone)]);
        assert_eq!(single_cuts, 0, "{single_segments:?}");
        assert_one_leaf_each([&segments[0], &segments[2]], first);
    }

    /// A segment the leaf test called other that holds two touching small leaves is cut into
    /// two leaves; one that is a stem's tube is not cut and stays other.
    #[test]
    fn touching_small_leaves_called_other_are_cut_into_leaves_and_a_stem_stays_other() {
        // Two small leaves touching at their bases, 70° apart, in one segment the leaf test
        // called other; a leaf segment of one leaf sets the typical leaf; and a segment called
        // other that is a stem's tube, 5 mm in radius and 8 cm long, sampled all round.
        let (mut positions, first) = two_touching_small_leaves();
        let both = positions.len();
        positions.extend(small_leaf(
            Point3::new(0.2, 0.0, 0.3),
            0.0,
            0.2,
            0.036,
            0.012,
            900,
        ));
        let leaves = positions.len();
        for i in 0..40 {
            for j in 0..16 {
                let k = positions.len();
                let angle = std::f64::consts::TAU * j as f64 / 16.0;
                let radius = 0.005 + 0.0002 * jitter(k);
                positions.push(Point3::new(
                    -0.2 + radius * angle.cos(),
                    0.1 + radius * angle.sin(),
                    0.25 + i as f64 * 0.002,
                ));
            }
        }
        let n = positions.len();
        let (cuts, segments) = cut_touching_segments(
            positions,
            &[
                (0, both, SegmentLabel::Other),
                (both, leaves, SegmentLabel::Leaf),
                (leaves, n, SegmentLabel::Other),
            ],
        );
        assert_eq!(cuts, 1, "{segments:?}");
        assert_eq!(segments.len(), 4, "{segments:?}");
        assert_eq!(
            segments[1].num_points,
            leaves - both,
            "the single leaf is whole"
        );
        assert_eq!(segments[2].label, SegmentLabel::Other, "the stem");
        assert_eq!(segments[2].num_points, n - leaves, "the stem is whole");
        assert_one_leaf_each([&segments[0], &segments[3]], first);
    }

    #[test]
    fn two_leaves_in_one_group_are_split_by_their_planes_and_a_piece_of_tube_is_not() {
        // A flat leaf 10 × 5 cm and a second one 8 × 4 cm going on from its end at 30° (one
        // group: the normalized cuts found no sweep that separates them), and apart from them
        // half of a tube 6 mm in radius (a stem seen from one side), each sampled on a 2 mm
        // grid with 0.2 mm of noise.
        let step = 0.002;
        let noise = 0.0002;
        let mut positions = Vec::new();
        for i in 0..50 {
            for j in 0..25 {
                let k = positions.len();
                positions.push(Point3::new(
                    i as f64 * step,
                    j as f64 * step - 0.025,
                    0.3 + noise * jitter(k),
                ));
            }
        }
        let first = positions.len();
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        for i in 0..40 {
            for j in 0..20 {
                let k = positions.len();
                let u = i as f64 * step + 0.5 * step;
                positions.push(Point3::new(
                    0.1 + u * c,
                    j as f64 * step - 0.019,
                    0.3 + u * s + noise * jitter(k),
                ));
            }
        }
        let leaves = positions.len();
        for i in 0..40 {
            for j in 0..10 {
                let k = positions.len();
                let angle = std::f64::consts::PI * j as f64 / 9.0;
                let radius = 0.006 + noise * jitter(k);
                positions.push(Point3::new(
                    0.3 + radius * angle.cos(),
                    0.1 + i as f64 * step,
                    0.2 + radius * angle.sin(),
                ));
            }
        }
        let n = positions.len();
        let points = green_points(positions);
        let graph = graph_without_images(&points);
        let adjacency = graph.adjacency();
        let foreground = upright(
            PointClass::Plant,
            n,
            Some(floor_at_zero()),
            Point3::new(0.0, 0.0, 0.2),
        );
        // The leaf test's cubic height field bends over such a pair where a quadratic one does
        // not; the band between the two is narrow, so the sheet tolerance is set inside it
        // here (the pair's residuals: 0.0088 cubic, 0.0107 quadratic, of its length).
        let mut options = SegmentOptions::default();
        options.ncut.max_sheet_residual = 0.0095;
        let pair: Vec<Point3<f64>> = points.positions[..leaves].to_vec();
        let shape = Shape::of(pair.iter().copied());
        let tolerance = sheet_tolerance(&options.ncut, &shape, noise);
        assert!(shape.cubic_sheet_residual(pair.iter().copied()) <= tolerance);
        assert!(shape.sheet_residual(pair.iter().copied()) > tolerance);
        let test = LeafTest {
            positions: &points.positions,
            graph: &graph,
            min_facing: MIN_LEAF_FACING,
            foreground: &foreground,
            heights: PlantHeights {
                ground: 0.0,
                top: 0.4,
            },
            options: &options.ncut,
        };
        let stacked: Vec<u32> = (0..leaves as u32).collect();
        assert_eq!(
            test.label(&stacked).2,
            SegmentLabel::Leaf,
            "one group passes as a leaf"
        );
        let tube: Vec<u32> = (leaves as u32..n as u32).collect();
        let (groups, split) = split_stacked_leaves(vec![stacked, tube.clone()], &adjacency, &test);
        assert_eq!(split, 1);
        // The tube is left as it was; the leaves come out as two main pieces (and perhaps a
        // few crumbs where they meet, for the fragment step).
        assert!(groups.contains(&tube));
        let mut pieces: Vec<&Vec<u32>> = groups.iter().filter(|g| **g != tube).collect();
        pieces.sort_by_key(|g| std::cmp::Reverse(g.len()));
        let lower = pieces[0].iter().filter(|&&p| (p as usize) < first).count();
        let upper = pieces[1].iter().filter(|&&p| (p as usize) >= first).count();
        assert!(
            lower * 100 >= 97 * pieces[0].len(),
            "{lower} of {}",
            pieces[0].len()
        );
        assert!(
            upper * 100 >= 97 * pieces[1].len(),
            "{upper} of {}",
            pieces[1].len()
        );
        assert!(
            pieces[0].len() * 100 >= 95 * first,
            "{} of {first}",
            pieces[0].len()
        );
        assert!(
            pieces[1].len() * 100 >= 95 * (leaves - first),
            "{} of {}",
            pieces[1].len(),
            leaves - first
        );
    }
}
