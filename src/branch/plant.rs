//! Branches of a reconstructed plant: the automatic skeleton of the current labels' non-leaf
//! points, the `skeleton.json` schema (one type, written by [`crate::pipeline`], read by
//! [`crate::eval`]) and branch meshes for export. Takes the segmentation and its labels;
//! returns a [`BranchTree`], skeleton records and model branches.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::skeleton::{SkeletonError, SkeletonOptions, SkeletonStats, automatic_skeleton};
use super::{BranchTree, CylinderMeshing};
use crate::model::ModelBranch;
use crate::segment::foreground::{Foreground, PointClass};
use crate::segment::{Labels, SegmentLabel, Segmentation};

/// Indices of the points a skeleton is built from (and branch strokes snap to): points the
/// foreground found on thin tubes, and the points of segments labelled stem or other (never
/// leaves or the pot).
pub fn skeleton_point_indices(foreground: &Foreground, labels: &Labels) -> Vec<u32> {
    (0..labels.segment_of.len())
        .filter(|&i| match labels.label_of_point(i) {
            Some(SegmentLabel::Stem | SegmentLabel::Other) => true,
            Some(SegmentLabel::Leaf | SegmentLabel::Pot) => false,
            None => foreground.class[i] == PointClass::Stem,
        })
        .map(|i| i as u32)
        .collect()
}

/// The points a skeleton is built from (see [`skeleton_point_indices`]).
pub fn skeleton_points(segmentation: &Segmentation, labels: &Labels) -> Vec<Point3<f64>> {
    let positions = &segmentation.points.positions;
    skeleton_point_indices(&segmentation.foreground, labels)
        .into_iter()
        .map(|i| positions[i as usize])
        .collect()
}

/// The automatic skeleton of a plant under the given labels.
pub fn automatic_plant_skeleton(
    segmentation: &Segmentation,
    labels: &Labels,
    options: &SkeletonOptions,
) -> Result<(BranchTree, SkeletonStats), SkeletonError> {
    let foreground = &segmentation.foreground;
    automatic_skeleton(
        &skeleton_points(segmentation, labels),
        &foreground.up,
        &foreground.plant_center,
        options,
    )
}

/// One branch as written to `skeleton.json` and to a synthetic dataset's `gt/branches.json`
/// (the schema `frond eval` reads). Fields after `radius_end` other than `centerline` may be
/// missing in files written by other tools.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkeletonRecord {
    pub id: u32,
    #[serde(default)]
    pub parent: Option<u32>,
    /// Where along the parent it starts (0 = the parent's base, 1 = its tip).
    #[serde(default)]
    pub parent_fraction: f64,
    /// The spline's control points (world frame).
    #[serde(default)]
    pub control_points: Vec<[f64; 3]>,
    pub radius_start: f64,
    pub radius_end: f64,
    /// Arc length of the spline (world units).
    #[serde(default)]
    pub length: f64,
    /// Points along the skeleton about every `spacing` metres, for distance metrics.
    pub centerline: Vec<[f64; 3]>,
}

impl SkeletonRecord {
    /// Length of the sampled centreline.
    pub fn centerline_length(&self) -> f64 {
        self.centerline
            .windows(2)
            .map(|w| (Point3::from(w[1]) - Point3::from(w[0])).norm())
            .sum()
    }

    pub fn mean_radius(&self) -> f64 {
        0.5 * (self.radius_start + self.radius_end)
    }
}

/// The name and version of the skeleton file format.
pub const SKELETON_FORMAT: &str = "frond skeleton";
pub const SKELETON_VERSION: u32 = 1;

/// `skeleton.json` / `gt/branches.json`: the format's name and version, and the branches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkeletonFile {
    pub format: String,
    pub version: u32,
    pub branches: Vec<SkeletonRecord>,
}

/// Why a skeleton file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SkeletonFileError {
    #[error("{path}: {message}")]
    Read { path: String, message: String },
}

impl SkeletonFile {
    pub fn new(branches: Vec<SkeletonRecord>) -> Self {
        Self {
            format: SKELETON_FORMAT.to_owned(),
            version: SKELETON_VERSION,
            branches,
        }
    }

    /// Pretty JSON, as written.
    pub fn to_json(&self) -> String {
        // Plain data of numbers and strings: serialising it cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Parses a skeleton file; a bare array of branches (files written before the format had
    /// a version) reads as version 0.
    pub fn parse(text: &str, path: &std::path::Path) -> Result<Self, SkeletonFileError> {
        let error = |message: String| SkeletonFileError::Read {
            path: path.display().to_string(),
            message,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| error(format!("not JSON: {e}")))?;
        if value.is_array() {
            let branches = serde_json::from_value(value)
                .map_err(|e| error(format!("malformed branches: {e}")))?;
            return Ok(Self {
                format: SKELETON_FORMAT.to_owned(),
                version: 0,
                branches,
            });
        }
        if value.get("format").and_then(|f| f.as_str()) != Some(SKELETON_FORMAT) {
            return Err(error(format!("not a {SKELETON_FORMAT} file")));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if version == 0 || version > SKELETON_VERSION as u64 {
            return Err(error(format!(
                "version {version} is not supported (this Frond reads up to {SKELETON_VERSION})"
            )));
        }
        serde_json::from_value(value).map_err(|e| error(format!("malformed skeleton: {e}")))
    }

    /// Reads a skeleton file.
    pub fn read(path: &std::path::Path) -> Result<Self, SkeletonFileError> {
        let text = std::fs::read_to_string(path).map_err(|e| SkeletonFileError::Read {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::parse(&text, path)
    }
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
