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

/// The points a skeleton is built from: points the foreground found on thin tubes, and the
/// points of segments labelled stem or other (never leaves or the pot).
pub fn skeleton_points(session: &Session) -> Vec<Point3<f64>> {
    let segmentation = session.segmentation();
    let points = &segmentation.points;
    let segments = session.segments();
    (0..points.len())
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
        .map(|i| points.positions[i])
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

/// One branch in `skeleton.json` (the schema of a synthetic dataset's `gt/branches.json`).
#[derive(Clone, Debug, Serialize)]
pub struct SkeletonRecord {
    pub id: u32,
    pub parent: Option<u32>,
    pub parent_fraction: f64,
    pub control_points: Vec<[f64; 3]>,
    pub radius_start: f64,
    pub radius_end: f64,
    pub length: f64,
    /// Points along the skeleton about every 2 mm (at least 8).
    pub centerline: Vec<[f64; 3]>,
}

/// The tree as `skeleton.json` records.
pub fn skeleton_records(tree: &BranchTree) -> Vec<SkeletonRecord> {
    tree.branches
        .iter()
        .map(|b| {
            let length = b.cylinder.length();
            let samples = ((length / 0.002).ceil() as usize).clamp(8, 2000);
            SkeletonRecord {
                id: b.id,
                parent: b.parent,
                parent_fraction: b.parent_fraction,
                control_points: b
                    .cylinder
                    .skeleton
                    .control_points()
                    .iter()
                    .map(|p| [p.x, p.y, p.z])
                    .collect(),
                radius_start: b.cylinder.radius_start,
                radius_end: b.cylinder.radius_end,
                length,
                centerline: b
                    .cylinder
                    .skeleton
                    .sample_by_arc_length(samples)
                    .iter()
                    .map(|(p, _)| [p.x, p.y, p.z])
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
