//! The reconstruction's files, one writer each (`plant.glb`/`plant.obj` are written by
//! [`crate::model::PlantModel::export`]):
//!
//! - `segmentation.ply`: every input point with `x y z red green blue`, `leaf_id` (the
//!   segment id of leaf segments, −1 otherwise) and the point's id in the input: `point_id`,
//!   the COLMAP point3D id of the input model (sparse models and Frond's dense workspaces),
//!   or `fused_index`, the row of `fused.ply`, when the dense points are not the model's.
//! - `segments.json` ([`SegmentsFile`]): every live segment with its label, confirmation,
//!   size and known image boundaries, the foreground, and the edit count.
//! - `skeleton.json` ([`crate::branch::plant::SkeletonFile`]).
//! - `report.json` ([`super::ReconstructionReport`]).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{EditCount, PipelineError, PlantState, output_error};
use crate::branch::BranchTree;
use crate::branch::plant::{BranchSupport, SkeletonFile, skeleton_records};
use crate::graph::points::PointIds;
use crate::leaf::Boundaries;
use crate::model::{segmentation_ply, write_segmentation_ply};
use crate::segment::SegmentLabel;
use crate::util::atomic::write_atomic;

pub const SEGMENTATION_FILE: &str = "segmentation.ply";
pub const SEGMENTS_FILE: &str = "segments.json";
pub const SKELETON_FILE: &str = "skeleton.json";
pub const REPORT_FILE: &str = "report.json";

/// Centreline sampling of `skeleton.json` (metres between samples, at least this many).
const SKELETON_SPACING: f64 = 0.002;
const SKELETON_MIN_SAMPLES: usize = 8;

/// Pretty JSON, written atomically.
pub(super) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), PipelineError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| output_error(path, e))?;
    write_atomic(path, text.as_bytes()).map_err(|e| output_error(path, e))
}

/// Reads a JSON file of format `format` written at `version` (the only version read).
pub(super) fn read_versioned<T: serde::de::DeserializeOwned>(
    path: &Path,
    format: &str,
    version: u32,
) -> Result<T, PipelineError> {
    let text = std::fs::read_to_string(path).map_err(|e| output_error(path, e))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| output_error(path, format!("not JSON: {e}")))?;
    if value.get("format").and_then(|f| f.as_str()) != Some(format) {
        return Err(output_error(path, format!("not a {format} file")));
    }
    let found = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
    if found != version as u64 {
        return Err(output_error(
            path,
            format!("{format} version {found} is not supported (this Frond reads {version})"),
        ));
    }
    serde_json::from_value(value).map_err(|e| output_error(path, format!("malformed: {e}")))
}

/// `skeleton.json`: the branch tree as records with sampled centrelines.
pub fn write_skeleton(
    branches: &BranchTree,
    support: &[BranchSupport],
    out: &Path,
) -> Result<(), PipelineError> {
    let path = out.join(SKELETON_FILE);
    let mut records = skeleton_records(branches, SKELETON_SPACING, SKELETON_MIN_SAMPLES);
    for record in &mut records {
        if let Some(s) = support.iter().find(|s| s.id == record.id) {
            record.observed_length = Some(s.observed_length);
            record.bridged_length = Some(s.bridged_length);
        }
    }
    write_atomic(&path, SkeletonFile::new(records).to_json().as_bytes())
        .map_err(|e| output_error(&path, e))
}

/// The name and version of `segments.json`'s schema.
pub const SEGMENTS_FORMAT: &str = "frond segments";
pub const SEGMENTS_VERSION: u32 = 2;

/// A segment's image boundary in one photo.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoundaryRecord {
    /// The COLMAP image id.
    pub image_id: u32,
    pub area_px: f64,
    /// Pixels, COLMAP convention (centre of the top-left pixel at (0.5, 0.5)).
    pub polygon: Vec<[f64; 2]>,
}

/// One live segment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SegmentRecord {
    /// Its id (the `leaf_id` of its points when it is a leaf).
    pub id: u32,
    pub label: SegmentLabel,
    pub confirmed: bool,
    pub points: usize,
    /// Known boundaries, by image id.
    pub boundaries: Vec<BoundaryRecord>,
}

/// `segments.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SegmentsFile {
    pub format: String,
    pub version: u32,
    /// Input points (rows of `segmentation.ply`).
    pub points: usize,
    /// Live leaf segments.
    pub leaves: usize,
    /// Points per foreground class.
    pub foreground: BTreeMap<String, usize>,
    /// The plant's up direction and a point on its axis (world frame).
    pub up: [f64; 3],
    pub plant_center: [f64; 3],
    pub segments: Vec<SegmentRecord>,
    pub edits: EditCount,
}

impl SegmentsFile {
    /// The file of a plant state with these boundaries.
    pub fn of_state(state: &PlantState, boundaries: &Boundaries) -> Self {
        let sizes = state.labels.sizes();
        let images = state.scene.reconstruction.images();
        let segments: Vec<SegmentRecord> = state
            .labels
            .segments
            .iter()
            .enumerate()
            .filter_map(|(id, segment)| {
                let segment = segment.as_ref()?;
                (sizes[id] > 0).then(|| SegmentRecord {
                    id: id as u32,
                    label: segment.label,
                    confirmed: segment.confirmed,
                    points: sizes[id],
                    boundaries: boundaries
                        .range((id as u32, 0)..=(id as u32, usize::MAX))
                        .filter_map(|((_, view), b)| {
                            Some(BoundaryRecord {
                                image_id: images.get(*view)?.id,
                                area_px: b.area_px,
                                polygon: b.polygon.clone(),
                            })
                        })
                        .collect(),
                })
            })
            .collect();
        let foreground = &state.segmentation.foreground;
        Self {
            format: SEGMENTS_FORMAT.to_owned(),
            version: SEGMENTS_VERSION,
            points: state.segmentation.points.len(),
            leaves: segments
                .iter()
                .filter(|s| s.label == SegmentLabel::Leaf)
                .count(),
            foreground: state.segmentation.class_counts(),
            up: foreground.up.into(),
            plant_center: foreground.plant_center.coords.into(),
            segments,
            edits: state.edits,
        }
    }

    /// Reads and checks a `segments.json`.
    pub fn read(path: &Path) -> Result<Self, PipelineError> {
        read_versioned(path, SEGMENTS_FORMAT, SEGMENTS_VERSION)
    }
}

/// Writes `segmentation.ply` and `segments.json` of a plant state into `out`.
pub fn write_segmentation(
    state: &PlantState,
    boundaries: &Boundaries,
    out: &Path,
) -> Result<(), PipelineError> {
    std::fs::create_dir_all(out).map_err(|e| output_error(out, e))?;
    let points = &state.segmentation.points;
    let id_column = match points.id_kind {
        PointIds::ModelPoint3D => "point_id",
        PointIds::FusedRow => "fused_index",
    };
    let ply = segmentation_ply(
        &points.positions,
        &points.colors,
        (id_column, &points.point_ids),
        &state.labels.leaf_ids(),
        &state
            .labels
            .segment_of
            .iter()
            .map(|&s| s as i64)
            .collect::<Vec<_>>(),
    );
    let ply_path = out.join(SEGMENTATION_FILE);
    write_segmentation_ply(&ply_path, &ply).map_err(|e| output_error(&ply_path, e))?;
    write_json(
        &out.join(SEGMENTS_FILE),
        &SegmentsFile::of_state(state, boundaries),
    )
}
