//! Branches of a reconstructed plant: the automatic skeleton from a session's non-leaf points,
//! the skeleton file the evaluation reads, and meshes for export.

use nalgebra::Point3;
use serde::Serialize;

use super::skeleton::{SkeletonError, SkeletonOptions, SkeletonStats, automatic_skeleton};
use super::{BranchTree, CylinderMeshing};
use crate::edit::Session;
use crate::graph::foreground::PointClass;
use crate::graph::pipeline::SegmentLabel;
use crate::model::ModelBranch;

/// Indices of the points a skeleton is built from (and branch strokes snap to): points the
/// foreground found on thin tubes, and the points of segments labelled stem or other (never
/// leaves or the pot).
pub fn skeleton_point_indices(session: &Session) -> Vec<u32> {
    let segmentation = session.segmentation();
    let segments = session.segments();
    (0..segmentation.points.len())
        .filter(|&i| {
            let segment = session.segment_of()[i];
            let label = (segment >= 0)
                .then(|| segments.get(segment as usize).copied().flatten())
                .flatten()
                .map(|s| s.label);
            match label {
                Some(SegmentLabel::Stem | SegmentLabel::Other) => true,
                Some(SegmentLabel::Leaf | SegmentLabel::Pot) => false,
                None => segmentation.foreground.class[i] == PointClass::Stem,
            }
        })
        .map(|i| i as u32)
        .collect()
}

/// The points a skeleton is built from (see [`skeleton_point_indices`]).
pub fn skeleton_points(session: &Session) -> Vec<Point3<f64>> {
    let positions = &session.segmentation().points.positions;
    skeleton_point_indices(session)
        .into_iter()
        .map(|i| positions[i as usize])
        .collect()
}

/// The automatic skeleton of a session's plant.
pub fn session_skeleton(
    session: &Session,
    options: &SkeletonOptions,
) -> Result<(BranchTree, SkeletonStats), SkeletonError> {
    let foreground = &session.segmentation().foreground;
    automatic_skeleton(
        &skeleton_points(session),
        &foreground.up,
        &foreground.plant_center,
        options,
    )
}

/// One branch as written to `skeleton.json` and to a synthetic dataset's `gt/branches.json`
/// (the schema `frond eval` reads).
#[derive(Clone, Debug, Serialize)]
pub struct SkeletonRecord {
    pub id: u32,
    pub parent: Option<u32>,
    pub parent_fraction: f64,
    pub control_points: Vec<[f64; 3]>,
    pub radius_start: f64,
    pub radius_end: f64,
    pub length: f64,
    /// Points along the skeleton about every `spacing` metres, for distance metrics.
    pub centerline: Vec<[f64; 3]>,
}

/// The tree as records, centrelines sampled about every `spacing` metres (at least
/// `min_samples` points, at most 2,000).
pub fn skeleton_records(
    tree: &BranchTree,
    spacing: f64,
    min_samples: usize,
) -> Vec<SkeletonRecord> {
    let as_array = |p: &Point3<f64>| [p.x, p.y, p.z];
    tree.branches
        .iter()
        .map(|b| {
            let skeleton = &b.cylinder.skeleton;
            let length = b.cylinder.length();
            let samples = ((length / spacing).ceil() as usize).clamp(min_samples.max(2), 2000);
            SkeletonRecord {
                id: b.id,
                parent: b.parent,
                parent_fraction: b.parent_fraction,
                control_points: skeleton.control_points().iter().map(as_array).collect(),
                radius_start: b.cylinder.radius_start,
                radius_end: b.cylinder.radius_end,
                length,
                centerline: skeleton
                    .sample_by_arc_length(samples)
                    .iter()
                    .map(|(p, _)| as_array(p))
                    .collect(),
            }
        })
        .collect()
}

/// Bark colour of exported branches (linear RGBA).
pub const BARK_COLOR: [f32; 4] = [0.32, 0.24, 0.15, 1.0];

/// Branch meshes for export: resolution from each branch's size, the start open where it
/// joins its parent, the tip capped.
pub fn model_branches(tree: &BranchTree) -> Vec<ModelBranch> {
    tree.branches
        .iter()
        .map(|b| {
            let radius = b.cylinder.radius_start.max(b.cylinder.radius_end).max(1e-6);
            let meshing = CylinderMeshing {
                radial_segments: if radius > 0.005 { 12 } else { 8 },
                axial_segments: ((b.cylinder.length() / (2.0 * radius)).ceil() as usize)
                    .clamp(2, 64),
                cap_start: b.parent.is_none(),
                cap_end: true,
            };
            ModelBranch {
                id: b.id,
                mesh: b.cylinder.mesh(&meshing),
                color: BARK_COLOR,
            }
        })
        .collect()
}

/// A session's plant as a model: the fitted leaves, the branches, a petiole from each leaf to
/// its nearest branch, and posed leaves for small segments and leaf-at-tip branches (seed 004
/// §7).
pub struct SessionPlant {
    pub model: crate::model::PlantModel,
    pub attachment: super::attach::Attachment,
    /// Seconds spent attaching the leaves.
    pub attach_seconds: f64,
}

/// Builds the plant model of a session whose leaves have been reconstructed.
pub fn session_plant(session: &Session, leaves: &crate::leaf::LeafReconstruction) -> SessionPlant {
    use crate::branch::attach::{PosedKind, attach_leaves};
    use crate::model::{ModelLeaf, PlantModel};
    let clock = std::time::Instant::now();
    let branches = session.branches();
    let positions = &session.segmentation().points.positions;
    let small_segments: Vec<(u32, Vec<Point3<f64>>)> = leaves
        .skipped
        .iter()
        .filter(|s| s.for_branch_stage)
        .map(|s| {
            let members = session.members(s.segment);
            (
                s.segment,
                members.iter().map(|&p| positions[p as usize]).collect(),
            )
        })
        .collect();
    let up = session.segmentation().foreground.up;
    let attachment = attach_leaves(branches, leaves, &small_segments, &up);
    let attach_seconds = clock.elapsed().as_secs_f64();
    // Tip leaves are numbered after every segment id.
    let tip_leaf_base = session.segments().len() as u32;
    let mut branches_out = model_branches(branches);
    let petiole_tree = BranchTree {
        branches: attachment
            .petioles
            .iter()
            .enumerate()
            .map(|(k, p)| super::Branch {
                id: branches.next_id() + k as u32,
                parent: Some(p.branch),
                parent_fraction: p.parent_fraction,
                cylinder: p.cylinder.clone(),
                leaf_at_tip: false,
            })
            .collect(),
    };
    branches_out.extend(model_branches(&petiole_tree));
    let model = PlantModel {
        leaves: leaves
            .leaves
            .iter()
            .map(|l| ModelLeaf {
                id: l.segment,
                mesh: l.fit.mesh.clone(),
                texture: l.fit.texture.clone(),
            })
            .chain(attachment.posed.iter().map(|p| ModelLeaf {
                id: match p.kind {
                    PosedKind::SmallSegment => p.source,
                    PosedKind::BranchTip => tip_leaf_base + p.source,
                },
                mesh: p.mesh.clone(),
                texture: p.texture.clone(),
            }))
            .collect(),
        branches: branches_out,
        up: Some(up.into()),
    };
    SessionPlant {
        model,
        attachment,
        attach_seconds,
    }
}
