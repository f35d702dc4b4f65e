//! The editing session: current labels over the automatic segmentation, edits as commands
//! with exact undo and redo.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use nalgebra::Point2;

use super::branches::{self, BranchEditError, SnapPoints, StrokeView};
use super::command::{BranchStroke, BranchTarget, Command, PixelRef, ViewCameraRecord};
use super::stroke::{Side, Stroke};
use crate::branch::skeleton::SkeletonStats;
use crate::branch::{BranchPoint, BranchTree};
use crate::graph::maxflow::{CutSide, MaxFlow, MaxFlowError};
use crate::graph::neighbours::Neighbours;
use crate::pipeline::{EditCount, PlantState, SkeletonRun};
use crate::scene::{ImageId, Scene};
use crate::segment::boundary::{Boundary, BoundaryError, BoundaryOptions};
use crate::segment::labels::Labels;
pub use crate::segment::labels::SegmentState;
use crate::segment::views::{Projected, ViewCache};
use crate::segment::{SegmentLabel, Segmentation};

/// ε of the graph-cut smoothness term `1 / (d² + ε)` (seed 004 §5.3).
pub const GRAPH_CUT_EPSILON: f64 = 1e-4;
/// Clicks pick the nearest projected point within this distance (pixels).
pub const PICK_TOLERANCE_PX: f64 = 12.0;
/// Points projecting closer than this to a split stroke are left to the graph cut (pixels);
/// farther ones are seeded on their side.
pub const STROKE_MARGIN_PX: f64 = 8.0;

/// Why an edit could not be applied (the session is unchanged).
#[derive(Debug, thiserror::Error)]
pub enum EditError {
    #[error("no image with id {0} in the model")]
    UnknownImage(ImageId),
    #[error(
        "no point of a segment projects within {tolerance} px of ({x:.1}, {y:.1}) in image {image_id}"
    )]
    NothingUnderClick {
        image_id: ImageId,
        x: f64,
        y: f64,
        tolerance: f64,
    },
    #[error("no branch lies within {tolerance} px of ({x:.1}, {y:.1}) in the 3D view")]
    NothingUnderViewClick { x: f64, y: f64, tolerance: f64 },
    #[error("the stroke needs at least two distinct finite points (three if closed)")]
    InvalidStroke,
    #[error("the stroke crosses no segment in image {0}")]
    StrokeCrossesNothing(ImageId),
    #[error("the stroke leaves all {0} points of the segment on one side")]
    StrokeDoesNotSplit(usize),
    #[error("both clicks are on the same segment")]
    SameSegment,
    #[error(transparent)]
    MaxFlow(#[from] MaxFlowError),
    #[error(transparent)]
    Boundary(#[from] BoundaryError),
    #[error(transparent)]
    Branch(#[from] BranchEditError),
}

/// Everything an applied command changed, to undo and redo it exactly.
#[derive(Clone, Debug, Default)]
struct Change {
    /// `(point, before, after)` segment ids (−1 = none).
    points: Vec<(u32, i32, i32)>,
    segments_before: Vec<Option<SegmentState>>,
    segments_after: Vec<Option<SegmentState>>,
    /// Merge edges appended (`added_edges` grows by this many).
    added_edges: Vec<(u32, u32)>,
    /// Graph edges newly cut by the stroke.
    cut_edges: Vec<usize>,
    /// The branch tree before and after, for branch commands.
    branches: Option<Box<(BranchTree, BranchTree)>>,
}

struct Applied {
    command: Command,
    change: Change,
}

/// The editing session (see the module docs).
pub struct Session {
    scene: Scene,
    segmentation: Segmentation,
    /// Point → graph node.
    node_of: Vec<Option<u32>>,
    /// Per graph node: `(neighbour node, edge index)`.
    adjacency: Vec<Vec<(u32, u32)>>,
    labels: Labels,
    added_edges: Vec<(u32, u32)>,
    cut_edges: HashSet<usize>,
    history: Vec<Applied>,
    cursor: usize,
    views: ViewCache,
    boundaries: BTreeMap<(u32, usize), Boundary>,
    branches: BranchTree,
    initial_skeleton: SkeletonRun,
}

impl Session {
    /// Starts a session on an automatic segmentation of `scene`, with the automatic skeleton
    /// of its non-leaf points as the first branch tree (empty when there is none).
    pub fn new(scene: Scene, segmentation: Segmentation) -> Self {
        let n = segmentation.points.len();
        let mut node_of = vec![None; n];
        for (node, &point) in segmentation.graph_points.iter().enumerate() {
            node_of[point] = Some(node as u32);
        }
        let mut adjacency = vec![Vec::new(); segmentation.graph.num_nodes];
        for (index, edge) in segmentation.graph.edges.iter().enumerate() {
            adjacency[edge.a as usize].push((edge.b, index as u32));
            adjacency[edge.b as usize].push((edge.a, index as u32));
        }
        let labels = Labels::automatic(&segmentation);
        let mut session = Self {
            scene,
            segmentation,
            node_of,
            adjacency,
            labels,
            added_edges: Vec::new(),
            cut_edges: HashSet::new(),
            history: Vec::new(),
            cursor: 0,
            views: ViewCache::new(BoundaryOptions::default()),
            boundaries: BTreeMap::new(),
            branches: BranchTree::default(),
            initial_skeleton: SkeletonRun::default(),
        };
        let (tree, run) = crate::pipeline::automatic_skeleton(
            &session.segmentation,
            &session.labels,
            &Default::default(),
        );
        session.branches = tree;
        session.initial_skeleton = run;
        session
    }

    /// The branch tree.
    pub fn branches(&self) -> &BranchTree {
        &self.branches
    }

    /// How the first branch tree came out.
    pub fn initial_skeleton(&self) -> &SkeletonRun {
        &self.initial_skeleton
    }

    /// How much of each branch the points show (observed vs bridged length), measured on the
    /// points the automatic skeleton uses under the current labels.
    pub fn branch_support(&self) -> Vec<crate::branch::plant::BranchSupport> {
        crate::branch::plant::plant_branch_support(
            &self.segmentation,
            &self.labels,
            &self.branches,
            &self.initial_skeleton.options.tube,
        )
    }

    /// The camera of a photo, for strokes drawn in it.
    pub fn stroke_view(&self, image_id: ImageId) -> Result<StrokeView, EditError> {
        let view = self.view_index(image_id)?;
        let image = &self.scene.reconstruction.images()[view];
        Ok(StrokeView {
            camera: self.scene.reconstruction.camera_of(image).clone(),
            camera_from_world: image.camera_from_world,
        })
    }

    /// The branch under a click in a photo.
    pub fn pick_branch(&self, at: &PixelRef) -> Result<BranchPoint, EditError> {
        let view = self.stroke_view(at.image_id)?;
        let pixel = Point2::new(at.pixel[0], at.pixel[1]);
        branches::pick_branch(&self.branches, &view, &pixel, PICK_TOLERANCE_PX).ok_or(
            EditError::NothingUnderClick {
                image_id: at.image_id,
                x: pixel.x,
                y: pixel.y,
                tolerance: PICK_TOLERANCE_PX,
            },
        )
    }

    /// The branch under a pixel of the 3D panel's view (its camera as the command carries it).
    pub fn pick_branch_in_view(
        &self,
        camera: &ViewCameraRecord,
        pixel: [f64; 2],
    ) -> Result<BranchPoint, EditError> {
        let view = StrokeView::from_view_camera(camera)?;
        let pixel = Point2::new(pixel[0], pixel[1]);
        branches::pick_branch(&self.branches, &view, &pixel, PICK_TOLERANCE_PX).ok_or(
            EditError::NothingUnderViewClick {
                x: pixel.x,
                y: pixel.y,
                tolerance: PICK_TOLERANCE_PX,
            },
        )
    }

    /// What branch strokes snap to: non-leaf plant points; in a photo, those it sees.
    fn snap_points(&self, view: Option<usize>) -> SnapPoints<'_> {
        let points = &self.segmentation.points;
        let mut candidates = crate::branch::plant::skeleton_point_indices(
            &self.segmentation.points,
            &self.segmentation.foreground,
            &self.labels,
        );
        if let Some(view) = view {
            candidates.retain(|&p| {
                points.views[p as usize]
                    .binary_search(&(view as u32))
                    .is_ok()
            });
        }
        SnapPoints {
            positions: &points.positions,
            candidates,
            spacing: self.segmentation.sigma_3d.max(1e-9),
        }
    }

    /// The edited branch tree for a branch command (`None` for other commands).
    fn plan_branches(&self, command: &Command) -> Result<Option<BranchTree>, EditError> {
        let tree = &self.branches;
        let edited = match command {
            Command::AutomaticSkeleton => {
                self.automatic_skeleton().map_err(BranchEditError::from)?.0
            }
            Command::DrawBranch { stroke, radius } => match stroke {
                BranchStroke::Image { image_id, stroke } => {
                    let view = self.stroke_view(*image_id)?;
                    let snap = self.snap_points(Some(self.view_index(*image_id)?));
                    branches::draw_in_view(tree, &view, stroke, &snap, *radius)?
                }
                BranchStroke::View { camera, stroke } => {
                    let view = StrokeView::from_view_camera(camera)?;
                    branches::draw_in_view(tree, &view, stroke, &self.snap_points(None), *radius)?
                }
                BranchStroke::World { points } => {
                    branches::draw_in_world(tree, points, &self.snap_points(None), *radius)?
                }
            },
            Command::MoveBranch {
                branch,
                control_point,
                to,
            } => {
                let current = tree
                    .get(*branch)
                    .and_then(|b| b.cylinder.skeleton.control_points().get(*control_point))
                    .copied();
                let position = match (to, current) {
                    (BranchTarget::World { position }, _) => nalgebra::Point3::from(*position),
                    (_, None) => nalgebra::Point3::origin(), // refused by move_control_point
                    (BranchTarget::Image { at }, Some(current)) => {
                        self.stroke_view(at.image_id)?
                            .drag(&current, &Point2::new(at.pixel[0], at.pixel[1]))?
                    }
                    (BranchTarget::View { camera, pixel }, Some(current)) => {
                        StrokeView::from_view_camera(camera)?
                            .drag(&current, &Point2::new(pixel[0], pixel[1]))?
                    }
                };
                branches::move_control_point(tree, *branch, *control_point, position)?
            }
            Command::SetRadius {
                branch,
                end,
                radius,
            } => branches::set_radius(tree, *branch, *end, *radius)?,
            Command::SetLeafAtTip { branch, enabled } => {
                branches::set_leaf_at_tip(tree, *branch, *enabled)?
            }
            Command::DeleteBranch { branch } => branches::delete_branch(tree, *branch)?,
            _ => return Ok(None),
        };
        Ok(Some(edited))
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn segmentation(&self) -> &Segmentation {
        &self.segmentation
    }

    /// The session's plant as plain data, for the pipeline's leaf and output stages.
    pub fn plant_state(&self) -> PlantState<'_> {
        PlantState {
            scene: &self.scene,
            segmentation: &self.segmentation,
            labels: &self.labels,
            branches: &self.branches,
            skeleton: &self.initial_skeleton,
            views: &self.views,
            boundaries: &self.boundaries,
            edits: EditCount {
                history: self.history.len(),
                applied: self.cursor,
            },
        }
    }

    /// The current labels.
    pub fn labels(&self) -> &Labels {
        &self.labels
    }

    /// Current segment id per point (−1 = none).
    pub fn segment_of(&self) -> &[i32] {
        &self.labels.segment_of
    }

    /// State of every segment id (`None` for ids whose points were merged away).
    pub fn segments(&self) -> &[Option<SegmentState>] {
        &self.labels.segments
    }

    /// The projections and superpixels of the views, shared by edits and leaf boundaries.
    pub fn views(&self) -> &ViewCache {
        &self.views
    }

    /// Every cached image boundary, by (segment, view).
    pub fn boundaries(&self) -> &BTreeMap<(u32, usize), Boundary> {
        &self.boundaries
    }

    /// The automatic skeleton of the current labels' non-leaf points.
    fn automatic_skeleton(
        &self,
    ) -> Result<(BranchTree, SkeletonStats), crate::branch::skeleton::SkeletonError> {
        crate::branch::plant::automatic_plant_skeleton(
            &self.segmentation,
            &self.labels,
            &Default::default(),
        )
    }

    /// `leaf_id` per point: the segment id of leaf segments, −1 otherwise.
    pub fn leaf_ids(&self) -> Vec<i64> {
        self.labels.leaf_ids()
    }

    /// Points of a segment.
    pub fn members(&self, segment: u32) -> Vec<u32> {
        self.labels.members(segment)
    }

    /// The commands applied so far (up to the undo position) and the redo-able ones after.
    pub fn history(&self) -> (Vec<&Command>, usize) {
        (
            self.history.iter().map(|a| &a.command).collect(),
            self.cursor,
        )
    }

    pub fn can_undo(&self) -> bool {
        self.cursor > 0
    }

    pub fn can_redo(&self) -> bool {
        self.cursor < self.history.len()
    }

    /// The boundary computed for a segment in a view, if any.
    pub fn boundary(&self, segment: u32, view: usize) -> Option<&Boundary> {
        self.boundaries.get(&(segment, view))
    }

    fn view_index(&self, image_id: ImageId) -> Result<usize, EditError> {
        self.scene
            .reconstruction
            .image_position(image_id)
            .ok_or(EditError::UnknownImage(image_id))
    }

    /// Projections of the points seen in a view (cached).
    fn projected(&self, view: usize) -> Arc<Vec<Projected>> {
        self.views
            .projected(&self.scene, &self.segmentation.points, view)
    }

    /// The point of a segment under a click: nearest projection within the tolerance, the
    /// front-most among near-ties.
    pub fn pick(&self, at: &PixelRef) -> Result<u32, EditError> {
        let view = self.view_index(at.image_id)?;
        let click = Point2::new(at.pixel[0], at.pixel[1]);
        let projected = self.projected(view);
        let candidates: Vec<(f64, f64, u32)> = projected
            .iter()
            .filter(|p| self.labels.segment_of[p.point as usize] >= 0)
            .map(|p| ((p.uv_image - click).norm(), p.depth_camera, p.point))
            .filter(|(d, _, _)| *d <= PICK_TOLERANCE_PX)
            .collect();
        let nearest = candidates.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
        candidates
            .iter()
            .filter(|c| c.0 <= nearest + 3.0)
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.2.cmp(&b.2)))
            .map(|c| c.2)
            .ok_or(EditError::NothingUnderClick {
                image_id: at.image_id,
                x: click.x,
                y: click.y,
                tolerance: PICK_TOLERANCE_PX,
            })
    }

    /// The segment under a click.
    pub fn pick_segment(&self, at: &PixelRef) -> Result<u32, EditError> {
        let point = self.pick(at)?;
        Ok(self.labels.segment_of[point as usize] as u32)
    }

    /// Applies a command; on error nothing changes. Redo-able commands after the undo
    /// position are dropped.
    pub fn apply(&mut self, command: Command) -> Result<(), EditError> {
        let change = self.plan(&command)?;
        self.forward(&change);
        self.history.truncate(self.cursor);
        self.history.push(Applied { command, change });
        self.cursor += 1;
        Ok(())
    }

    /// Undoes the last applied command; false when there is none.
    pub fn undo(&mut self) -> bool {
        if self.cursor == 0 {
            return false;
        }
        self.cursor -= 1;
        let change = self.history[self.cursor].change.clone();
        self.backward(&change);
        true
    }

    /// Redoes the next undone command; false when there is none.
    pub fn redo(&mut self) -> bool {
        if self.cursor >= self.history.len() {
            return false;
        }
        let change = self.history[self.cursor].change.clone();
        self.forward(&change);
        self.cursor += 1;
        true
    }

    /// Drops the cached image boundaries of every segment whose members a change moves:
    /// they describe regions that no longer exist.
    fn forget_boundaries(&mut self, change: &Change) {
        let touched: HashSet<i32> = change
            .points
            .iter()
            .flat_map(|&(_, before, after)| [before, after])
            .collect();
        if !touched.is_empty() {
            self.boundaries
                .retain(|(segment, _), _| !touched.contains(&(*segment as i32)));
        }
    }

    fn forward(&mut self, change: &Change) {
        self.forget_boundaries(change);
        for &(point, _, after) in &change.points {
            self.labels.segment_of[point as usize] = after;
        }
        self.labels.segments = change.segments_after.clone();
        self.added_edges.extend_from_slice(&change.added_edges);
        self.cut_edges.extend(change.cut_edges.iter().copied());
        if let Some(trees) = &change.branches {
            self.branches = trees.1.clone();
        }
    }

    fn backward(&mut self, change: &Change) {
        self.forget_boundaries(change);
        for &(point, before, _) in change.points.iter().rev() {
            self.labels.segment_of[point as usize] = before;
        }
        self.labels.segments = change.segments_before.clone();
        let keep = self.added_edges.len() - change.added_edges.len();
        self.added_edges.truncate(keep);
        for edge in &change.cut_edges {
            self.cut_edges.remove(edge);
        }
        if let Some(trees) = &change.branches {
            self.branches = trees.0.clone();
        }
    }

    /// Computes what a command would change, without changing anything.
    fn plan(&mut self, command: &Command) -> Result<Change, EditError> {
        let mut change = Change {
            segments_before: self.labels.segments.clone(),
            segments_after: self.labels.segments.clone(),
            ..Change::default()
        };
        if let Some(edited) = self.plan_branches(command)? {
            change.branches = Some(Box::new((self.branches.clone(), edited)));
            return Ok(change);
        }
        match command {
            Command::ConfirmSegment { at } => {
                let segment = self.pick_segment(at)?;
                let view = self.view_index(at.image_id)?;
                self.compute_boundary(segment, view)?;
                if let Some(state) = change.segments_after[segment as usize].as_mut() {
                    state.confirmed = true;
                }
            }
            Command::MarkLeaf { at } => {
                let segment = self.pick_segment(at)?;
                if let Some(state) = change.segments_after[segment as usize].as_mut() {
                    state.label = SegmentLabel::Leaf;
                }
            }
            Command::MarkNonLeaf { at, label } => {
                let segment = self.pick_segment(at)?;
                if let Some(state) = change.segments_after[segment as usize].as_mut() {
                    state.label = if *label == SegmentLabel::Leaf {
                        SegmentLabel::Other
                    } else {
                        *label
                    };
                }
            }
            Command::MergeByClick { first, second } => {
                let (a, b) = (self.pick(first)?, self.pick(second)?);
                let (sa, sb) = (
                    self.labels.segment_of[a as usize],
                    self.labels.segment_of[b as usize],
                );
                if sa == sb {
                    return Err(EditError::SameSegment);
                }
                for p in self.members(sb as u32) {
                    change.points.push((p, sb, sa));
                }
                change.segments_after[sb as usize] = None;
                if let (Some(na), Some(nb)) = (self.node_of[a as usize], self.node_of[b as usize]) {
                    change.added_edges.push((na, nb));
                }
            }
            Command::ResetSegment { at } => {
                let segment = self.pick_segment(at)?;
                let members = self.members(segment);
                let mut restored: BTreeMap<u32, SegmentState> = BTreeMap::new();
                for &p in &members {
                    let auto = self.segmentation.point_segment[p as usize];
                    let after = auto.map_or(-1, |s| s as i32);
                    if after != segment as i32 {
                        change.points.push((p, segment as i32, after));
                    }
                    if let Some(s) = auto {
                        restored.insert(
                            s,
                            SegmentState {
                                label: self.segmentation.segments[s as usize].label,
                                confirmed: false,
                            },
                        );
                    }
                }
                let still_used = restored.contains_key(&segment);
                for (s, state) in restored {
                    change.segments_after[s as usize] = Some(state);
                }
                if !still_used {
                    change.segments_after[segment as usize] = None;
                }
            }
            Command::SplitByStroke {
                image_id,
                stroke,
                closed,
            } => {
                self.plan_split(*image_id, stroke, *closed, &mut change)?;
            }
            Command::AutomaticSkeleton
            | Command::DrawBranch { .. }
            | Command::MoveBranch { .. }
            | Command::SetRadius { .. }
            | Command::SetLeafAtTip { .. }
            | Command::DeleteBranch { .. } => {} // planned above by plan_branches
        }
        Ok(change)
    }

    /// SplitByStroke (seed 004 §5.3): the segment crossed by the stroke is re-solved as a
    /// two-label graph cut minimising Σ (1 − δ(l_p, l_q)) / (d²(p, q) + ε) + Σ D(l_p), with
    /// hard data terms for the points projecting farther than the margin on either side,
    /// and the graph edges crossing the stroke cut.
    fn plan_split(
        &self,
        image_id: ImageId,
        stroke: &[[f64; 2]],
        closed: bool,
        change: &mut Change,
    ) -> Result<(), EditError> {
        let view = self.view_index(image_id)?;
        let stroke = Stroke::new(
            stroke.iter().map(|p| Point2::new(p[0], p[1])).collect(),
            closed,
        )
        .ok_or(EditError::InvalidStroke)?;
        let projected = self.projected(view);
        // The segment the stroke runs over: most points within 20 px of it.
        let mut votes: BTreeMap<i32, usize> = BTreeMap::new();
        for p in projected.iter() {
            let s = self.labels.segment_of[p.point as usize];
            if s >= 0 && stroke.distance(&p.uv_image) <= 20.0 {
                *votes.entry(s).or_insert(0) += 1;
            }
        }
        let segment = votes
            .into_iter()
            .max_by_key(|&(s, count)| (count, std::cmp::Reverse(s)))
            .map(|(s, _)| s)
            .ok_or(EditError::StrokeCrossesNothing(image_id))?;
        let members = self.members(segment as u32);
        let local: HashMap<u32, u32> = members
            .iter()
            .enumerate()
            .map(|(i, &p)| (p, i as u32))
            .collect();
        let uv: HashMap<u32, Point2<f64>> = projected
            .iter()
            .filter(|p| local.contains_key(&p.point))
            .map(|p| (p.point, p.uv_image))
            .collect();
        // Seeds: points seen in the view between the margin and the stroke's reach; points
        // farther away follow the graph (the stroke's extension is only a guess there).
        let length: f64 = stroke
            .points()
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .sum();
        let reach = (0.5 * length).max(40.0);
        let mut flow = MaxFlow::new(members.len());
        for (i, p) in members.iter().enumerate() {
            if let Some(position) = uv.get(p)
                && (STROKE_MARGIN_PX..=reach).contains(&stroke.distance(position))
            {
                match stroke.side(position) {
                    Side::Inside => flow.add_terminal_weights(i, f64::INFINITY, 0.0)?,
                    Side::Outside => flow.add_terminal_weights(i, 0.0, f64::INFINITY)?,
                }
            }
        }
        let graph = &self.segmentation.graph;
        for (i, &p) in members.iter().enumerate() {
            let Some(node) = self.node_of[p as usize] else {
                continue;
            };
            for &(neighbour_node, edge) in &self.adjacency[node as usize] {
                let q = self.segmentation.graph_points[neighbour_node as usize] as u32;
                let Some(&j) = local.get(&q) else { continue };
                if (j as usize) <= i || self.cut_edges.contains(&(edge as usize)) {
                    continue;
                }
                if let (Some(a), Some(b)) = (uv.get(&p), uv.get(&q))
                    && stroke.crosses(a, b)
                {
                    change.cut_edges.push(edge as usize);
                    continue;
                }
                let d = graph.distance(&graph.edges[edge as usize]);
                if d.is_finite() {
                    let capacity = 1.0 / (d * d + GRAPH_CUT_EPSILON);
                    flow.add_edge(i, j as usize, capacity, capacity)?;
                }
            }
        }
        // Members that are no graph node (leaf rims the segmentation took back from the stem
        // test) follow the nearest member that is one.
        let with_node: Vec<usize> = (0..members.len())
            .filter(|&i| self.node_of[members[i] as usize].is_some())
            .collect();
        if with_node.len() < members.len() {
            let positions = &self.segmentation.points.positions;
            if let Ok(index) =
                Neighbours::new(with_node.iter().map(|&i| positions[members[i] as usize]))
            {
                let sigma = std::f64::consts::SQRT_2 * graph.sigma_3d.max(1e-12);
                for (i, &p) in members.iter().enumerate() {
                    if self.node_of[p as usize].is_some() {
                        continue;
                    }
                    if let Some(nearest) = index.nearest(&positions[p as usize]) {
                        let d = nearest.distance() / sigma;
                        let capacity = 1.0 / (d * d + GRAPH_CUT_EPSILON);
                        flow.add_edge(i, with_node[nearest.index], capacity, capacity)?;
                    }
                }
            }
        }
        for &(a, b) in &self.added_edges {
            let (pa, pb) = (
                self.segmentation.graph_points[a as usize] as u32,
                self.segmentation.graph_points[b as usize] as u32,
            );
            if let (Some(&i), Some(&j)) = (local.get(&pa), local.get(&pb)) {
                let capacity = 1.0 / GRAPH_CUT_EPSILON;
                flow.add_edge(i as usize, j as usize, capacity, capacity)?;
            }
        }
        flow.solve();
        let inside: Vec<u32> = members
            .iter()
            .enumerate()
            .filter(|(i, _)| flow.side(*i) == CutSide::Source)
            .map(|(_, &p)| p)
            .collect();
        if inside.is_empty() || inside.len() == members.len() {
            return Err(EditError::StrokeDoesNotSplit(members.len()));
        }
        let new_segment = change.segments_after.len() as i32;
        let label = change.segments_after[segment as usize].map_or(SegmentLabel::Leaf, |s| s.label);
        change.segments_after.push(Some(SegmentState {
            label,
            confirmed: false,
        }));
        if let Some(state) = change.segments_after[segment as usize].as_mut() {
            state.confirmed = false;
        }
        for p in inside {
            change.points.push((p, segment, new_segment));
        }
        Ok(())
    }

    /// The image boundary of a segment in a view (seed 004 §5.4), computed without touching
    /// the cache (callable from many threads at once; see [`Session::store_boundary`]).
    pub fn boundary_in_view(&self, segment: u32, view: usize) -> Result<Boundary, EditError> {
        Ok(self.views.boundary(
            &self.scene,
            &self.segmentation.points,
            &self.labels.segment_of,
            segment,
            view,
        )?)
    }

    /// Caches a boundary computed by [`Session::boundary_in_view`] for the current segments.
    pub fn store_boundary(&mut self, segment: u32, view: usize, boundary: Boundary) {
        self.boundaries.insert((segment, view), boundary);
    }

    /// Reconstructs every leaf segment under the current labels (seed 004 §6) and keeps the
    /// image boundaries it computed.
    pub fn fit_leaves(
        &mut self,
        options: &crate::leaf::LeafOptions,
        progress: &dyn crate::util::progress::Progress,
    ) -> Result<crate::leaf::LeafReconstruction, crate::leaf::LeafError> {
        let leaves = crate::pipeline::fit_leaves(&self.plant_state(), options, progress)?;
        self.store_boundaries(
            leaves
                .boundaries
                .iter()
                .map(|(key, boundary)| (*key, boundary.clone())),
        );
        Ok(leaves)
    }

    /// Caches the boundaries a leaf reconstruction computed for the current segments.
    pub fn store_boundaries(
        &mut self,
        boundaries: impl IntoIterator<Item = ((u32, usize), Boundary)>,
    ) {
        self.boundaries.extend(boundaries);
    }

    /// Computes (and caches) the image boundary of a segment in a view (seed 004 §5.4).
    pub fn compute_boundary(&mut self, segment: u32, view: usize) -> Result<&Boundary, EditError> {
        if !self.boundaries.contains_key(&(segment, view)) {
            let boundary = self.boundary_in_view(segment, view)?;
            self.boundaries.insert((segment, view), boundary);
        }
        Ok(&self.boundaries[&(segment, view)])
    }

    /// Computes the superpixels of these views in parallel ahead of boundary work.
    pub fn prepare_views(&self, views: &[usize]) -> Result<(), EditError> {
        use rayon::prelude::*;
        views
            .par_iter()
            .try_for_each(|&view| self.views.oversegmentation(&self.scene, view).map(|_| ()))
            .map_err(EditError::from)
    }

    /// The view where a segment's boundary is best: among the views seeing most of its
    /// points, the one with the largest region.
    pub fn best_view(
        &mut self,
        segment: u32,
        candidates: usize,
    ) -> Result<Option<usize>, EditError> {
        let members = self.members(segment);
        let mut seen: BTreeMap<u32, usize> = BTreeMap::new();
        for &p in &members {
            for &v in &self.segmentation.points.views[p as usize] {
                *seen.entry(v).or_insert(0) += 1;
            }
        }
        let mut ranked: Vec<(usize, u32)> = seen.into_iter().map(|(v, c)| (c, v)).collect();
        ranked.sort_by(|a, b| b.cmp(a));
        let mut best: Option<(f64, usize)> = None;
        for &(_, view) in ranked.iter().take(candidates.max(1)) {
            let area = self.compute_boundary(segment, view as usize)?.area_px;
            if best.is_none_or(|(a, _)| area > a) {
                best = Some((area, view as usize));
            }
        }
        Ok(best.map(|(_, v)| v))
    }
}
