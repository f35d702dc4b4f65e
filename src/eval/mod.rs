//! `frond eval`: scores a reconstruction against synthetic ground truth.
//!
//! The prediction is the reconstruction output contract: `OUT/segmentation.ply` (the input
//! points with `leaf_id`, −1 = not a leaf; optionally `point_id`), `OUT/plant.glb` (nodes
//! `leaf_NNN` for segment NNN and `branch_NNN`, world frame) and optionally
//! `OUT/skeleton.json` (branches with a `centerline`, the schema of `gt/branches.json`).
//!
//! Points are paired with the truth by `point_id`, else by identical order and position; when
//! the prediction was made by real COLMAP (another gauge), it is first aligned by a similarity
//! from matched camera centres (Umeyama) and each point takes the label of the nearest ground-
//! truth surface sample.
//!
//! Takes a synthetic dataset's `gt/` and a reconstruction folder; returns an [`EvalReport`].

pub mod align;
pub mod compound;
pub mod dense;
pub mod geometry;
pub mod metrics;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

pub use align::{Similarity, umeyama};
pub use metrics::{
    FalseLeafCause, FalseLeaves, LeafScores, MatchingOptions, adjusted_rand_index, false_leaves,
    score_leaves,
};

use crate::graph::neighbours::Neighbours;
use crate::mesh::TriMesh;
use crate::scene::ply::{self, Ply};
use crate::scene::{SceneError, read_model};
use crate::synth::Part;

/// Evaluation failures; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
}

fn input_error(path: &Path, message: impl Into<String>) -> EvalError {
    EvalError::Input {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// A labelled point set.
#[derive(Clone, Debug, Default)]
pub struct LabelledPoints {
    pub positions: Vec<Point3<f64>>,
    pub point_ids: Option<Vec<u64>>,
    pub leaf_ids: Vec<i64>,
    /// Part per point (ground truth only).
    pub parts: Option<Vec<Part>>,
}

fn column<'a>(ply: &'a Ply, name: &str, path: &Path) -> Result<&'a [f64], EvalError> {
    ply.element("vertex")
        .and_then(|v| v.column(name))
        .map(|c| c.values.as_slice())
        .ok_or_else(|| input_error(path, format!("vertex element has no '{name}' property")))
}

/// Reads a labelled point PLY (`x y z leaf_id` [+ `point_id`, `part`]).
pub fn read_labelled_points(path: &Path) -> Result<LabelledPoints, EvalError> {
    let ply = ply::read_ply(path)?;
    let (x, y, z) = (
        column(&ply, "x", path)?,
        column(&ply, "y", path)?,
        column(&ply, "z", path)?,
    );
    let leaf = column(&ply, "leaf_id", path)?;
    let positions = (0..x.len())
        .map(|i| Point3::new(x[i], y[i], z[i]))
        .collect();
    let point_ids = column(&ply, "point_id", path)
        .ok()
        .map(|ids| ids.iter().map(|&v| v as u64).collect());
    let parts = match column(&ply, "part", path) {
        Ok(codes) => Some(
            codes
                .iter()
                .enumerate()
                .map(|(i, &c)| {
                    Part::from_code(c as u8)
                        .ok_or_else(|| input_error(path, format!("vertex {i}: unknown part {c}")))
                })
                .collect::<Result<Vec<_>, _>>()?,
        ),
        Err(_) => None,
    };
    Ok(LabelledPoints {
        positions,
        point_ids,
        leaf_ids: leaf.iter().map(|&v| v as i64).collect(),
        parts,
    })
}

/// One GT leaf.
#[derive(Clone, Debug, Deserialize)]
pub struct GtLeafRecord {
    pub id: u32,
    pub length: f64,
    pub area: f64,
    pub mesh: String,
    /// The branch (petiole or twig) the leaf grows from, when the dataset says.
    #[serde(default)]
    pub branch: Option<u32>,
    /// For a leaflet: its compound leaf (the rachis's branch id).
    #[serde(default)]
    pub compound_leaf: Option<u32>,
}

pub use crate::branch::plant::{SkeletonFile, SkeletonRecord};

/// Everything under a synthetic dataset's `gt/`.
pub struct GroundTruth {
    pub root: PathBuf,
    pub points: LabelledPoints,
    pub leaves: Vec<(GtLeafRecord, TriMesh)>,
    pub branches: Vec<SkeletonRecord>,
    pub surface_samples: LabelledPoints,
    pub plant_height: f64,
}

pub(crate) fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|e| input_error(path, e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| input_error(path, e.to_string()))
}

impl GroundTruth {
    pub fn load(root: &Path) -> Result<Self, EvalError> {
        let gt = root.join("gt");
        let points = read_labelled_points(&gt.join("points.ply"))?;
        let records: Vec<GtLeafRecord> = read_json(&gt.join("leaves.json"))?;
        let mut leaves = Vec::with_capacity(records.len());
        for record in records {
            let mesh = TriMesh::read_ply(&gt.join(&record.mesh))?;
            leaves.push((record, mesh));
        }
        let branches = SkeletonFile::read(&gt.join("branches.json"))
            .map_err(|e| input_error(&gt.join("branches.json"), e.to_string()))?
            .branches;
        let surface_samples = read_labelled_points(&gt.join("surface_samples.ply"))?;
        let meta: serde_json::Value = read_json(&root.join("meta.json"))?;
        let plant_height = meta["plant"]["height"]
            .as_f64()
            .ok_or_else(|| input_error(&root.join("meta.json"), "no plant.height"))?;
        Ok(Self {
            root: root.to_path_buf(),
            points,
            leaves,
            branches,
            surface_samples,
            plant_height,
        })
    }
}

/// A reconstruction's output folder.
pub struct Prediction {
    pub points: LabelledPoints,
    /// Leaf meshes by segment id (`leaf_NNN` nodes).
    pub leaf_meshes: BTreeMap<i64, TriMesh>,
    pub branch_meshes: usize,
    pub skeleton: Option<Vec<SkeletonRecord>>,
    /// The petioles the model draws from leaves to the skeleton's branches (straight lines
    /// from the branch point `report.json` names to the leaf's base; empty without a report).
    pub drawn_petioles: Vec<SkeletonRecord>,
    /// The compound leaves `report.json` lists (empty without one).
    pub compound_leaves: Vec<crate::branch::compound::CompoundLeaf>,
}

/// The part of `report.json` the evaluation reads.
#[derive(Deserialize)]
struct ReportParts {
    #[serde(default)]
    compound_leaves: Vec<crate::branch::compound::CompoundLeaf>,
    #[serde(default)]
    attachment: Option<ReportAttachment>,
}

/// The petioles of `report.json`'s attachment and the leaves' bases they end at.
#[derive(Default, Deserialize)]
struct ReportAttachment {
    #[serde(default)]
    petioles: Vec<ReportPetiole>,
    #[serde(default)]
    leaves: Vec<ReportLeafOnBranch>,
}

#[derive(Deserialize)]
struct ReportPetiole {
    leaf: u32,
    branch: u32,
    parent_fraction: f64,
}

#[derive(Deserialize)]
struct ReportLeafOnBranch {
    leaf: u32,
    base_world: [f64; 3],
}

/// The petioles the model draws, as skeleton records: a straight line from the point at
/// `parent_fraction` of the arc length along its branch's spline to its leaf's base,
/// numbered as the model numbers them (after the skeleton's last id, in the report's order).
/// A petiole whose branch or leaf is not listed is left out.
fn drawn_petiole_records(
    skeleton: &[SkeletonRecord],
    attachment: &ReportAttachment,
) -> Vec<SkeletonRecord> {
    let bases: BTreeMap<u32, [f64; 3]> = attachment
        .leaves
        .iter()
        .map(|l| (l.leaf, l.base_world))
        .collect();
    let next_id = skeleton.iter().map(|b| b.id + 1).max().unwrap_or(0);
    attachment
        .petioles
        .iter()
        .zip(next_id..)
        .filter_map(|(petiole, id)| {
            let branch = skeleton.iter().find(|b| b.id == petiole.branch)?;
            let base = bases.get(&petiole.leaf)?;
            // Where the model starts it: on the branch's spline, by arc length.
            let control = branch
                .control_points
                .iter()
                .map(|c| Point3::from(*c))
                .collect();
            let start = crate::branch::Spline::new(control)
                .ok()?
                .point_at_fraction(petiole.parent_fraction.clamp(0.0, 1.0));
            let length = (Point3::from(*base) - start).norm();
            Some(SkeletonRecord {
                id,
                parent: Some(petiole.branch),
                parent_fraction: petiole.parent_fraction,
                control_points: vec![start.into(), *base],
                radius_start: 0.0,
                radius_end: 0.0,
                length,
                centerline: vec![start.into(), *base],
                observed_length: None,
                bridged_length: None,
            })
        })
        .collect()
}

impl Prediction {
    pub fn load(out: &Path) -> Result<Self, EvalError> {
        let points = read_labelled_points(&out.join("segmentation.ply"))?;
        let glb_path = out.join("plant.glb");
        let mut leaf_meshes = BTreeMap::new();
        let mut branch_meshes = 0;
        if glb_path.is_file() {
            let bytes =
                std::fs::read(&glb_path).map_err(|e| input_error(&glb_path, e.to_string()))?;
            let nodes = crate::model::gltf::read_glb_meshes(&bytes, &glb_path)
                .map_err(|e| input_error(&glb_path, e.to_string()))?;
            for node in nodes {
                if let Some(id) = node.name.strip_prefix("leaf_").and_then(|s| s.parse().ok()) {
                    leaf_meshes.insert(id, node.mesh);
                } else if node.name.starts_with("branch_") {
                    branch_meshes += 1;
                }
            }
        }
        let skeleton_path = out.join("skeleton.json");
        let skeleton = if skeleton_path.is_file() {
            Some(
                SkeletonFile::read(&skeleton_path)
                    .map_err(|e| input_error(&skeleton_path, e.to_string()))?
                    .branches,
            )
        } else {
            None
        };
        let report_path = out.join("report.json");
        let report = if report_path.is_file() {
            read_json::<ReportParts>(&report_path)?
        } else {
            ReportParts {
                compound_leaves: Vec::new(),
                attachment: None,
            }
        };
        let drawn_petioles = match (&skeleton, &report.attachment) {
            (Some(skeleton), Some(attachment)) => drawn_petiole_records(skeleton, attachment),
            _ => Vec::new(),
        };
        Ok(Self {
            points,
            leaf_meshes,
            branch_meshes,
            skeleton,
            drawn_petioles,
            compound_leaves: report.compound_leaves,
        })
    }

    /// Applies a similarity to every predicted position and mesh.
    pub fn transform(&mut self, similarity: &Similarity) {
        for p in &mut self.points.positions {
            *p = similarity.apply(p);
        }
        for mesh in self.leaf_meshes.values_mut() {
            for p in &mut mesh.positions {
                *p = similarity.apply(&p.cast::<f64>()).cast::<f32>();
            }
            mesh.compute_normals();
        }
        let drawn = self.drawn_petioles.iter_mut();
        for branch in self.skeleton.iter_mut().flatten().chain(drawn) {
            for c in &mut branch.centerline {
                let p = similarity.apply(&Point3::from(*c));
                *c = [p.x, p.y, p.z];
            }
            branch.radius_start *= similarity.scale;
            branch.radius_end *= similarity.scale;
            branch.length *= similarity.scale;
            for length in [&mut branch.observed_length, &mut branch.bridged_length]
                .into_iter()
                .flatten()
            {
                *length *= similarity.scale;
            }
        }
    }
}

/// Evaluation settings.
#[derive(Clone, Debug, Serialize)]
pub struct EvalOptions {
    pub matching: MatchingOptions,
    /// Surface samples per leaf for Chamfer distances.
    pub surface_samples: usize,
    /// When predicted points are not ours: a point takes the label of the nearest GT surface
    /// sample within this fraction of the plant height, else counts as not plant.
    pub transfer_radius: f64,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            matching: MatchingOptions::default(),
            surface_samples: 2000,
            transfer_radius: 0.01,
        }
    }
}

/// Per matched leaf geometry errors.
#[derive(Clone, Debug, Serialize)]
pub struct LeafGeometryError {
    pub gt_leaf: i64,
    pub segment: i64,
    /// Symmetric Chamfer distance between the surfaces divided by the GT leaf length.
    pub chamfer_relative: f64,
    pub area_relative_error: f64,
    /// Predicted area over GT area (above 1: the prediction is too large).
    pub area_ratio: f64,
    /// Angle between mean normals, ignoring orientation, degrees.
    pub normal_angle_deg: f64,
}

/// Median and mean of a list (None when empty).
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub count: usize,
    pub median: Option<f64>,
    pub mean: Option<f64>,
}

impl Summary {
    pub fn of(values: &[f64]) -> Self {
        let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        Self {
            count: n,
            median: (n > 0).then(|| {
                if n % 2 == 1 {
                    sorted[n / 2]
                } else {
                    0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
                }
            }),
            mean: (n > 0).then(|| sorted.iter().sum::<f64>() / n as f64),
        }
    }
}

/// Branch skeleton scores.
#[derive(Clone, Debug, Serialize)]
pub struct SkeletonScores {
    /// Mean distance from the GT main stem's centreline to the predicted skeleton, in units of
    /// the stem's mean radius.
    pub stem_distance_in_radii: Option<f64>,
    /// GT branches longer than 10 mean radii.
    pub eligible_branches: usize,
    /// Of those, branches with ≥ 80 % of their centreline within 2 radii (≥ 3 mm) of the
    /// predicted skeleton.
    pub matched_branches: usize,
    pub branch_recall: f64,
    /// Length-weighted scores, branches and petioles apart.
    pub length: SkeletonLengthScores,
    /// The same scores of the model's whole structure: the skeleton and the petioles drawn
    /// from its leaves to it (`report.json`'s attachment), which `skeleton.json` leaves out.
    pub with_drawn_petioles: Option<SkeletonLengthScores>,
}

/// Length-weighted skeleton scores. A true centreline point is found when the prediction
/// passes within its branch's tolerance (2 mean radii, at least 3 mm); a predicted point is on
/// the plant when it lies within the tolerance of some true branch. A *petiole* is a true
/// branch that carries a leaf and has no child branch (without leaf records: any branch
/// without children other than the stem); every other true branch, the stem included, is a
/// *branch*.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SkeletonLengthScores {
    /// True branch (stem included) centreline length, model units of the truth (metres).
    pub true_branch_length: f64,
    pub true_petiole_length: f64,
    pub predicted_length: f64,
    /// Share of the true branch length the prediction passes within tolerance of.
    pub branch_recall: f64,
    /// Share of the true petiole length the prediction passes within tolerance of.
    pub petiole_recall: f64,
    /// Share of the predicted length within tolerance of some true branch or petiole.
    pub precision: f64,
    /// Each predicted branch's part of `predicted_length`: which of them lie off the plant.
    pub predicted_branches: Vec<PredictedBranchScore>,
    /// Where the predicted length off the plant lies (the rest of `precision`).
    pub off_plant: OffPlantLength,
}

/// The predicted skeleton length off the plant (beyond every true branch's tolerance), by the
/// nearest true surface within [`OffPlantLength::NEAR`] (model units of the truth): what a
/// user would see drawn there. The four add up to `predicted_length` × (1 − `precision`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct OffPlantLength {
    /// Along a leaf blade: a petiole drawn on into its leaf, a branch on a leaf's edge.
    pub on_leaves: f64,
    /// Beside a true stem or petiole, but farther than the tolerance from its centreline.
    pub beside_stems: f64,
    /// On the pot or its soil.
    pub on_pot: f64,
    /// Near no sampled surface: floor, backdrop or air (straight bridges, halo).
    pub elsewhere: f64,
}

impl OffPlantLength {
    /// How near a true surface sample a piece of skeleton must lie to be counted on it
    /// (metres; the surface samples lie about 2 mm apart).
    pub const NEAR: f64 = 0.005;
}

/// One predicted branch's share of [`SkeletonLengthScores::precision`].
#[derive(Clone, Debug, Default, Serialize)]
pub struct PredictedBranchScore {
    pub id: u32,
    pub parent: Option<u32>,
    /// Centreline length, model units of the truth.
    pub length: f64,
    /// The part of `length` within tolerance of some true branch or petiole.
    pub on_plant_length: f64,
    /// The part of the branch drawn where no point is, as the skeleton recorded it (after
    /// alignment to the truth's units; absent where the skeleton did not record it).
    pub bridged_length: Option<f64>,
}

/// The evaluation report.
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    pub points_scored: usize,
    /// How predicted points were paired with the truth.
    pub pairing: String,
    pub alignment: Option<AlignmentReport>,
    /// ARI over points whose GT part is leaf or stem (non-leaf labels form one cluster).
    pub ari_plant: f64,
    /// ARI over all points.
    pub ari_all: f64,
    pub leaves: LeafScores,
    /// The predicted leaf segments that match no true leaf, by what they hold.
    pub false_leaves: FalseLeaves,
    pub leaf_geometry: Vec<LeafGeometryError>,
    pub chamfer_relative: Summary,
    pub area_relative_error: Summary,
    pub normal_angle_deg: Summary,
    pub skeleton: Option<SkeletonScores>,
    /// Leaflets on their rachis (when the truth has compound leaves).
    pub compound: Option<compound::CompoundScores>,
    pub options: EvalOptions,
}

#[derive(Clone, Debug, Serialize)]
pub struct AlignmentReport {
    pub cameras_matched: usize,
    pub scale: f64,
    /// RMS camera-centre residual after alignment, in GT units (metres).
    pub rms_camera_residual: f64,
}

/// Aligns a prediction made from another COLMAP model (`pred_model`) to the GT cameras.
pub fn align_to_ground_truth(
    gt_root: &Path,
    pred_model: &Path,
) -> Result<(Similarity, AlignmentReport), EvalError> {
    let (gt_model, _) = read_model(&gt_root.join("sparse/0"))?;
    let (pred, _) = read_model(pred_model)?;
    let gt_centers: HashMap<&str, Point3<f64>> = gt_model
        .images()
        .iter()
        .map(|i| (i.name.as_str(), i.center_world()))
        .collect();
    let mut source = Vec::new();
    let mut target = Vec::new();
    for image in pred.images() {
        if let Some(c) = gt_centers.get(image.name.as_str()) {
            source.push(image.center_world());
            target.push(*c);
        }
    }
    let similarity = umeyama(&source, &target).map_err(|e| {
        input_error(
            pred_model,
            format!("cannot align cameras to the truth: {e}"),
        )
    })?;
    let rms = (source
        .iter()
        .zip(&target)
        .map(|(s, t)| (similarity.apply(s) - t).norm_squared())
        .sum::<f64>()
        / source.len() as f64)
        .sqrt();
    Ok((
        similarity,
        AlignmentReport {
            cameras_matched: source.len(),
            scale: similarity.scale,
            rms_camera_residual: rms,
        },
    ))
}

/// GT leaf id and part for each predicted point, and how they were paired.
fn pair_points(
    gt: &GroundTruth,
    pred: &Prediction,
    options: &EvalOptions,
) -> Result<(Vec<i64>, Vec<Part>, String), EvalError> {
    let gt_parts = gt
        .points
        .parts
        .as_ref()
        .ok_or_else(|| input_error(&gt.root, "gt/points.ply has no part column"))?;
    if let (Some(pred_ids), Some(gt_ids)) = (&pred.points.point_ids, &gt.points.point_ids) {
        let index: HashMap<u64, usize> =
            gt_ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        if pred_ids.iter().all(|id| index.contains_key(id)) {
            let (leaves, parts) = pred_ids
                .iter()
                .map(|id| {
                    let i = index[id];
                    (gt.points.leaf_ids[i], gt_parts[i])
                })
                .unzip();
            return Ok((leaves, parts, "point_id".into()));
        }
    }
    let same_order = pred.points.positions.len() == gt.points.positions.len()
        && pred
            .points
            .positions
            .iter()
            .zip(&gt.points.positions)
            .all(|(a, b)| (a - b).norm() < 1e-5);
    if same_order {
        return Ok((gt.points.leaf_ids.clone(), gt_parts.clone(), "order".into()));
    }
    // Different point sets: nearest GT surface sample within the transfer radius.
    let samples = &gt.surface_samples;
    let sample_parts = samples
        .parts
        .as_ref()
        .ok_or_else(|| input_error(&gt.root, "surface_samples.ply has no part column"))?;
    if samples.positions.is_empty() {
        return Err(input_error(
            &gt.root,
            "no surface samples to transfer labels from",
        ));
    }
    let sample_neighbours = Neighbours::new(samples.positions.iter().copied())
        .map_err(|e| input_error(&gt.root, format!("cannot index surface samples: {e:?}")))?;
    let radius = options.transfer_radius * gt.plant_height;
    let (leaves, parts) = pred
        .points
        .positions
        .iter()
        .map(|p| {
            let nearest = sample_neighbours.nearest_one(p);
            if nearest.distance() <= radius {
                let i = nearest.index;
                (samples.leaf_ids[i], sample_parts[i])
            } else {
                (-1, Part::Background)
            }
        })
        .unzip();
    Ok((leaves, parts, "nearest surface sample".into()))
}

/// Scores a prediction (already in the GT frame) against the truth.
pub fn evaluate(
    gt: &GroundTruth,
    pred: &Prediction,
    alignment: Option<AlignmentReport>,
    options: &EvalOptions,
) -> Result<EvalReport, EvalError> {
    let (gt_leaf, gt_part, pairing) = pair_points(gt, pred, options)?;
    let predicted = &pred.points.leaf_ids;
    let n = predicted.len();
    let collapse = |l: i64| if l < 0 { -1 } else { l };
    let plant: Vec<usize> = (0..n).filter(|&i| gt_part[i].is_plant()).collect();
    let ari_plant = adjusted_rand_index(
        &plant
            .iter()
            .map(|&i| collapse(gt_leaf[i]))
            .collect::<Vec<_>>(),
        &plant
            .iter()
            .map(|&i| collapse(predicted[i]))
            .collect::<Vec<_>>(),
    );
    let ari_all = adjusted_rand_index(
        &gt_leaf.iter().map(|&l| collapse(l)).collect::<Vec<_>>(),
        &predicted.iter().map(|&l| collapse(l)).collect::<Vec<_>>(),
    );
    let leaves = score_leaves(&gt_leaf, predicted, &options.matching);
    let false_leaves = false_leaves(&gt_leaf, &gt_part, predicted, &leaves, &options.matching);

    let gt_leaf_by_id: HashMap<i64, &(GtLeafRecord, TriMesh)> =
        gt.leaves.iter().map(|l| (l.0.id as i64, l)).collect();
    let leaf_geometry: Vec<LeafGeometryError> = leaves
        .matches
        .iter()
        .filter_map(|m| {
            let (record, gt_mesh) = gt_leaf_by_id.get(&m.gt_leaf)?;
            let pred_mesh = pred.leaf_meshes.get(&m.segment)?;
            let seed = (m.gt_leaf as u64) << 32 | m.segment as u64;
            let chamfer =
                geometry::symmetric_chamfer(gt_mesh, pred_mesh, options.surface_samples, seed)?;
            let pred_area = pred_mesh.area();
            let angle = geometry::normal_angle_deg(gt_mesh, pred_mesh);
            Some(LeafGeometryError {
                gt_leaf: m.gt_leaf,
                segment: m.segment,
                chamfer_relative: chamfer / record.length,
                area_relative_error: (pred_area - record.area).abs() / record.area,
                area_ratio: pred_area / record.area,
                normal_angle_deg: angle,
            })
        })
        .collect();
    let pick = |f: fn(&LeafGeometryError) -> f64| {
        Summary::of(&leaf_geometry.iter().map(f).collect::<Vec<_>>())
    };
    let skeleton = pred.skeleton.as_ref().map(|skeleton| {
        let petioles = geometry::petiole_ids(&gt.branches, &gt.leaves);
        let surfaces = geometry::TrueSurfaces::new(&gt.surface_samples);
        let mut scores = geometry::score_skeleton(&gt.branches, &petioles, skeleton, &surfaces);
        let whole: Vec<SkeletonRecord> = skeleton
            .iter()
            .chain(&pred.drawn_petioles)
            .cloned()
            .collect();
        scores.with_drawn_petioles = Some(geometry::skeleton_length_scores(
            &gt.branches,
            &petioles,
            &whole,
            &surfaces,
        ));
        scores
    });
    let leaflet_rachis: BTreeMap<i64, u32> = gt
        .leaves
        .iter()
        .filter_map(|(record, _)| Some((record.id as i64, record.compound_leaf?)))
        .collect();
    let compound = (!leaflet_rachis.is_empty()).then(|| {
        compound::score_compound(
            &leaflet_rachis,
            &gt.branches,
            &leaves.matches,
            &pred.compound_leaves,
            pred.skeleton.as_deref().unwrap_or(&[]),
        )
    });
    Ok(EvalReport {
        points_scored: n,
        pairing,
        alignment,
        ari_plant,
        ari_all,
        chamfer_relative: pick(|e| e.chamfer_relative),
        area_relative_error: pick(|e| e.area_relative_error),
        normal_angle_deg: pick(|e| e.normal_angle_deg),
        leaves,
        false_leaves,
        leaf_geometry,
        skeleton,
        compound,
        options: options.clone(),
    })
}

fn fmt_opt(v: Option<f64>, scale: f64, unit: &str) -> String {
    v.map_or_else(|| "n/a".into(), |v| format!("{:.3}{unit}", v * scale))
}

impl EvalReport {
    /// Human-readable summary.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let l = &self.leaves;
        let _ = writeln!(
            s,
            "points scored:     {} (paired by {})",
            self.points_scored, self.pairing
        );
        if let Some(a) = &self.alignment {
            let _ = writeln!(
                s,
                "alignment:         {} cameras, scale {:.4}, rms camera residual {:.4} m",
                a.cameras_matched, a.scale, a.rms_camera_residual
            );
        }
        let _ = writeln!(
            s,
            "ARI (plant / all): {:.4} / {:.4}",
            self.ari_plant, self.ari_all
        );
        let _ = writeln!(
            s,
            "leaves:            recall {:.3} ({}/{}), precision {:.3} ({} segments)",
            l.recall, l.matched, l.gt_leaves, l.precision, l.predicted_segments
        );
        let _ = writeln!(
            s,
            "segmentation:      {} over-segmented leaves ({:.1}%), {} under-segmented segments",
            l.over_segmented,
            if l.gt_leaves == 0 {
                0.0
            } else {
                100.0 * l.over_segmented as f64 / l.gt_leaves as f64
            },
            l.under_segmented
        );
        if !self.false_leaves.segments.is_empty() {
            let causes: Vec<String> = self
                .false_leaves
                .counts
                .iter()
                .map(|(cause, count)| format!("{count} {}", cause.replace('_', " ")))
                .collect();
            let _ = writeln!(
                s,
                "unmatched leaves:  {} segments: {}",
                self.false_leaves.segments.len(),
                causes.join(", ")
            );
        }
        let _ = writeln!(
            s,
            "leaf geometry:     {} leaves; Chamfer/length median {} mean {}; area error median {} mean {}; normal angle median {}",
            self.chamfer_relative.count,
            fmt_opt(self.chamfer_relative.median, 100.0, "%"),
            fmt_opt(self.chamfer_relative.mean, 100.0, "%"),
            fmt_opt(self.area_relative_error.median, 100.0, "%"),
            fmt_opt(self.area_relative_error.mean, 100.0, "%"),
            fmt_opt(self.normal_angle_deg.median, 1.0, "°"),
        );
        if let Some(k) = &self.skeleton {
            let _ = writeln!(
                s,
                "skeleton:          stem distance {} radii; branch recall {:.3} ({}/{})",
                fmt_opt(k.stem_distance_in_radii, 1.0, ""),
                k.branch_recall,
                k.matched_branches,
                k.eligible_branches
            );
            let _ = writeln!(
                s,
                "skeleton length:   branch recall {:.3} of {:.3} m, petiole recall {:.3} of {:.3} m, precision {:.3} of {:.3} m",
                k.length.branch_recall,
                k.length.true_branch_length,
                k.length.petiole_recall,
                k.length.true_petiole_length,
                k.length.precision,
                k.length.predicted_length
            );
            if let Some(w) = &k.with_drawn_petioles {
                let drawn = w.predicted_length - k.length.predicted_length;
                let drawn_on = w.precision * w.predicted_length
                    - k.length.precision * k.length.predicted_length;
                let _ = writeln!(
                    s,
                    "with drawn petioles: petiole recall {:.3}, precision {:.3} of {:.3} m (the petioles drawn from leaves: {:.3} m, {:.0} % on the plant)",
                    w.petiole_recall,
                    w.precision,
                    w.predicted_length,
                    drawn,
                    if drawn > 0.0 {
                        100.0 * drawn_on / drawn
                    } else {
                        0.0
                    }
                );
            }
            // Where the precision goes: the branches with the most length off the plant.
            let mut off: Vec<&PredictedBranchScore> = k
                .length
                .predicted_branches
                .iter()
                .filter(|b| b.length - b.on_plant_length > 0.0)
                .collect();
            off.sort_by(|a, b| {
                (b.length - b.on_plant_length).total_cmp(&(a.length - a.on_plant_length))
            });
            if !off.is_empty() {
                let listed: Vec<String> = off
                    .iter()
                    .take(5)
                    .map(|b| {
                        let bridged = b
                            .bridged_length
                            .map(|l| format!(", {:.0} bridged", 1e3 * l))
                            .unwrap_or_default();
                        format!(
                            "branch {} {:.0} of {:.0} mm{bridged}",
                            b.id,
                            1e3 * (b.length - b.on_plant_length),
                            1e3 * b.length
                        )
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "off the plant:     {}{}",
                    listed.join("; "),
                    if off.len() > 5 {
                        format!(" (and {} more)", off.len() - 5)
                    } else {
                        String::new()
                    }
                );
                let o = &k.length.off_plant;
                let _ = writeln!(
                    s,
                    "off the plant on:  leaves {:.0} mm, beside stems {:.0} mm, pot {:.0} mm, elsewhere {:.0} mm",
                    1e3 * o.on_leaves,
                    1e3 * o.beside_stems,
                    1e3 * o.on_pot,
                    1e3 * o.elsewhere
                );
            }
        }
        if let Some(c) = &self.compound {
            let _ = writeln!(
                s,
                "compound leaves:   {} predicted ({} on a true rachis) for {} true ({} found); leaflets on the right rachis {:.3} ({}/{} matched)",
                c.predicted_compound_leaves,
                c.predicted_on_a_true_rachis,
                c.true_compound_leaves,
                c.true_rachises_found,
                c.right_rachis_share,
                c.leaflets_on_right_rachis,
                c.leaflets_matched
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(id: u32, centerline: Vec<[f64; 3]>) -> SkeletonRecord {
        SkeletonRecord {
            id,
            parent: None,
            parent_fraction: 0.0,
            control_points: centerline.clone(),
            radius_start: 0.01,
            radius_end: 0.01,
            length: 0.0,
            centerline,
            observed_length: None,
            bridged_length: None,
        }
    }

    #[test]
    fn a_drawn_petiole_runs_from_its_branch_point_to_its_leaf_base() {
        // A stem 0.3 tall through uneven control points (the fraction is of arc length, not of
        // control points).
        let stem = record(0, vec![[0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.0, 0.0, 0.3]]);
        let attachment = ReportAttachment {
            petioles: vec![
                ReportPetiole {
                    leaf: 7,
                    branch: 0,
                    parent_fraction: 0.5,
                },
                // A branch the skeleton does not have, and a leaf with no base: left out.
                ReportPetiole {
                    leaf: 8,
                    branch: 3,
                    parent_fraction: 0.5,
                },
                ReportPetiole {
                    leaf: 9,
                    branch: 0,
                    parent_fraction: 1.0,
                },
            ],
            leaves: vec![
                ReportLeafOnBranch {
                    leaf: 7,
                    base_world: [0.1, 0.0, 0.15],
                },
                ReportLeafOnBranch {
                    leaf: 8,
                    base_world: [0.0, 0.1, 0.15],
                },
            ],
        };
        let drawn = drawn_petiole_records(&[stem], &attachment);
        assert_eq!(drawn.len(), 1, "{drawn:?}");
        let petiole = &drawn[0];
        // Numbered after the skeleton's branches, as the model numbers its petioles.
        assert_eq!((petiole.id, petiole.parent), (1, Some(0)));
        // Halfway up the stem, to the spline's arc-length table (0.1 mm on 0.3).
        let start = Point3::from(petiole.centerline[0]);
        assert!(
            (start - Point3::new(0.0, 0.0, 0.15)).norm() < 1e-4,
            "{start:?}"
        );
        assert_eq!(petiole.centerline[1], [0.1, 0.0, 0.15]);
        assert!((petiole.length - 0.1).abs() < 1e-4);
    }
}
