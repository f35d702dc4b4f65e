//! The reconstruction pipeline (seed 004 §4–7) as one library call, and the files it writes.
//!
//! Scene → foreground and automatic segmentation ([`crate::segment`]) → labels → automatic
//! skeleton ([`crate::branch`]) → image boundaries and leaf fits ([`crate::leaf`]) → petioles
//! and posed leaves → plant model ([`crate::model`]) → files. [`reconstruct`] runs all of it
//! from a scene; [`fit_leaves`] and [`write_plant`] run the leaf and output stages on a
//! [`PlantState`], the plain data an editing session (or the automatic run) holds, so the
//! CLI's `reconstruct` and `replay` and the GUI's export write the same files the same way.
//!
//! Files, each with one schema and one writer here ([`files`]): `segmentation.ply`,
//! `segments.json`, `skeleton.json`, `plant.glb`, `plant.obj` (+ `.mtl`, atlas pages) and
//! `report.json` ([`ReconstructionReport`]).

pub mod density;
pub mod files;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::branch::BranchTree;
use crate::branch::attach::{
    Attachment, BladeEnds, PosedKind, attach_leaves, end_branches_at_blades,
};
use crate::branch::compound::{
    CompoundLeaf, LeafOnBranch, compound_leaves as find_compound_leaves,
};
use crate::branch::plant::{
    BranchSupport, PlantSkeletonOptions, automatic_plant_skeleton, model_branches,
    plant_branch_support,
};
use crate::branch::skeleton::SkeletonStats;
use crate::leaf::{
    Boundaries, LeafError, LeafInput, LeafOptions, LeafReconstruction, LeafTimings, PlantContext,
    SkippedLeaf, UnusableView, gap_fill, reconstruct_leaves,
};
use crate::model::{CompoundGroup, ModelLeaf, PlantModel};
use crate::scene::{Scene, SceneError};
use crate::segment::boundary::BoundaryOptions;
use crate::segment::{
    Labels, SegmentError, SegmentOptions, Segmentation, ViewCache, segment_scene,
};
use crate::util::progress::Progress;

pub use density::{PointDensity, point_density};
pub use files::{SegmentsFile, write_segmentation};

/// Pipeline failures.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Segment(#[from] SegmentError),
    #[error(transparent)]
    Leaf(#[from] LeafError),
    #[error(transparent)]
    Sfm(#[from] crate::sfm::SfmError),
    #[error(transparent)]
    Mvs(#[from] crate::mvs::MvsError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

/// Whether `path` is a folder of photos with no COLMAP model in it (what `frond reconstruct`
/// and the GUI run structure from motion on).
pub fn is_photo_folder(path: &Path) -> bool {
    path.is_dir()
        && crate::scene::SceneSource::locate(path).is_err()
        && crate::sfm::list_photos(path).is_ok_and(|photos| !photos.is_empty())
}

/// What [`photos_to_scene`] did.
pub struct PhotosRun {
    pub sfm: crate::sfm::SfmReport,
    pub densify: crate::mvs::DensifyReport,
    /// Points in the dense workspace.
    pub dense_points: usize,
    /// The dense workspace: a COLMAP folder to reconstruct from.
    pub workspace: PathBuf,
}

/// Photos to a scene: structure from motion by COLMAP into `out/sfm`, then semi-dense stereo
/// into `out/dense` (the returned workspace). COLMAP's undistortion is skipped: densify reads
/// the photos through the model's camera, distortion included.
pub fn photos_to_scene(
    photos: &Path,
    sfm_options: &crate::sfm::SfmOptions,
    densify_options: &crate::mvs::DensifyOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<PhotosRun, PipelineError> {
    let sfm_out = out.join("sfm");
    let sfm_options = crate::sfm::SfmOptions {
        undistort: false,
        ..sfm_options.clone()
    };
    let sfm = crate::sfm::run_sfm(photos, &sfm_out, &sfm_options, progress)?;
    let scene = Scene::from_source(crate::scene::SceneSource {
        layout: crate::scene::LayoutKind::Explicit,
        model_dir: sfm_out.join("sparse").join("0"),
        images_dir: Some(photos.to_path_buf()),
        fused_ply: None,
        other_models: Vec::new(),
    })?;
    let workspace = out.join("dense");
    let (densify, dense_points) = densify_workspace(&scene, densify_options, &workspace, progress)?;
    Ok(PhotosRun {
        sfm,
        densify,
        dense_points,
        workspace,
    })
}

/// How the input becomes a scene: photos or a COLMAP folder, and what was run on it.
#[derive(Clone, Debug)]
pub struct InputOptions {
    pub sfm: crate::sfm::SfmOptions,
    pub densify: crate::mvs::DensifyOptions,
    /// Densify a COLMAP folder whose points are too sparse for the leaf graph (when its photos
    /// are there); `false` segments the points as they are.
    pub auto_densify: bool,
}

impl Default for InputOptions {
    fn default() -> Self {
        Self {
            sfm: Default::default(),
            densify: Default::default(),
            auto_densify: true,
        }
    }
}

/// What [`open_input`] did to make a scene of the input.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ScenePreparation {
    /// The folder given.
    pub given: PathBuf,
    /// The folder the scene was read from (the given one, or a workspace written from it).
    pub scene: PathBuf,
    /// Structure from motion ran on a folder of photos.
    pub sfm: bool,
    /// How densely the given COLMAP scene's points sampled the plant (not measured for
    /// photos).
    pub density: Option<PointDensity>,
    /// The points were densified into `scene` first.
    pub densified: bool,
    /// In words, for the user.
    pub note: String,
}

/// Opens the input of a reconstruction (see the module docs): a folder of photos goes through
/// [`photos_to_scene`] into `out/sfm` and `out/dense`; a COLMAP folder is read as it is,
/// unless its points are too sparse for the leaf graph ([`point_density`]), it has no dense
/// points and its photos are there: then it is densified into `out/dense` first (with
/// `auto_densify`).
pub fn open_input(
    path: &Path,
    options: &InputOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(Scene, ScenePreparation), PipelineError> {
    if is_photo_folder(path) {
        let run = photos_to_scene(path, &options.sfm, &options.densify, out, progress)?;
        let scene = Scene::open(&run.workspace)?;
        let mut note = format!(
            "{} of {} photos registered by COLMAP; {} semi-dense points",
            run.sfm.registered, run.sfm.photos, run.dense_points
        );
        if !run.sfm.unregistered.is_empty() {
            note.push_str(&format!(
                "; not registered: {}",
                run.sfm.unregistered.join(", ")
            ));
        }
        if !run.sfm.rejected.is_empty() {
            let rejected: Vec<String> = run
                .sfm
                .rejected
                .iter()
                .map(|r| format!("{} ({})", r.photo, r.reason))
                .collect();
            note.push_str(&format!("; left out: {}", rejected.join(", ")));
        }
        return Ok((
            scene,
            ScenePreparation {
                given: path.to_path_buf(),
                scene: run.workspace,
                sfm: true,
                density: None,
                densified: true,
                note,
            },
        ));
    }
    let scene = Scene::open(path)?;
    open_scene(scene, path, options, out, progress)
}

/// [`open_input`] for a scene already read from `given`.
pub fn open_scene(
    scene: Scene,
    given: &Path,
    options: &InputOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(Scene, ScenePreparation), PipelineError> {
    progress.stage("measuring point density", 0);
    let density = point_density(&scene);
    let photos = scene
        .reconstruction
        .images()
        .iter()
        .filter(|image| scene.image_file_status(image) == crate::scene::ImageFileStatus::Present)
        .count();
    let mut preparation = ScenePreparation {
        given: given.to_path_buf(),
        scene: scene.source.model_dir.clone(),
        sfm: false,
        density: Some(density.clone()),
        densified: false,
        note: String::new(),
    };
    let spacing = format!(
        "{} points {:.1} pixel footprints apart (median)",
        density.points, density.spacing_footprints
    );
    if density.has_dense_points || !density.too_sparse {
        preparation.note = format!("{spacing}: segmented as they are");
        return Ok((scene, preparation));
    }
    if !options.auto_densify {
        preparation.note = format!(
            "{spacing}, too sparse for the leaf graph (over {}), segmented as they are (densifying was turned off)",
            density.threshold_footprints
        );
        return Ok((scene, preparation));
    }
    if photos < 2 {
        preparation.note = format!(
            "{spacing}, too sparse for the leaf graph, but only {photos} photos are readable: segmented as they are"
        );
        return Ok((scene, preparation));
    }
    let workspace = out.join("dense");
    let points = match densify_workspace(&scene, &options.densify, &workspace, progress) {
        Ok((_, points)) => points,
        // Stereo that cannot run on these views leaves the points as they are, as before.
        Err(PipelineError::Mvs(e)) => {
            preparation.note = format!(
                "{spacing}, too sparse for the leaf graph, but densifying failed ({e}): segmented as they are"
            );
            tracing::warn!("{}", preparation.note);
            return Ok((scene, preparation));
        }
        Err(e) => return Err(e),
    };
    preparation.note = format!(
        "{spacing}, too sparse for the leaf graph (over {}): densified into {} ({points} points)",
        density.threshold_footprints,
        workspace.display()
    );
    tracing::info!("{}", preparation.note);
    preparation.scene = workspace.clone();
    preparation.densified = true;
    Ok((Scene::open(&workspace)?, preparation))
}

/// Semi-dense stereo of a scene into a dense workspace at `out` (what `frond densify`
/// writes); returns the report and the number of points written.
pub fn densify_workspace(
    scene: &Scene,
    options: &crate::mvs::DensifyOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(crate::mvs::DensifyReport, usize), PipelineError> {
    let (fused, report) = crate::mvs::densify(scene, options, progress)?;
    let dense = crate::mvs::write_workspace(scene, &fused, &report, options, out)?;
    Ok((report, dense.points().len()))
}

/// The branch support of a plant at a glance (see [`BranchSupport`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SupportSummary {
    /// Branch length with points along it, world units.
    pub observed_length: f64,
    /// Branch length drawn where no point is (bridged across gaps and occlusions).
    pub bridged_length: f64,
    /// Branches of which less than half is observed: what to check first.
    pub mostly_bridged: Vec<u32>,
}

impl SupportSummary {
    pub fn new(support: &[BranchSupport]) -> Self {
        Self {
            observed_length: support.iter().map(|s| s.observed_length).sum(),
            bridged_length: support.iter().map(|s| s.bridged_length).sum(),
            mostly_bridged: support
                .iter()
                .filter(|s| s.observed_fraction() < 0.5)
                .map(|s| s.id)
                .collect(),
        }
    }
}

/// How the automatic skeleton of a plant came out.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SkeletonRun {
    /// The options it ran with (the branch support of later edits is measured on the same
    /// points).
    pub options: PlantSkeletonOptions,
    pub stats: Option<SkeletonStats>,
    /// Why there is none, when there is none.
    pub error: Option<String>,
    pub seconds: f64,
}

/// The automatic skeleton of the labels' non-leaf points (an empty tree, with the reason,
/// when there is none).
pub fn automatic_skeleton(
    segmentation: &Segmentation,
    labels: &Labels,
    options: &PlantSkeletonOptions,
) -> (BranchTree, SkeletonRun) {
    let clock = Instant::now();
    let (tree, stats, error) = match automatic_plant_skeleton(segmentation, labels, options) {
        Ok((tree, stats)) => (tree, Some(stats), None),
        Err(e) => {
            tracing::info!("no automatic skeleton: {e}");
            (BranchTree::default(), None, Some(e.to_string()))
        }
    };
    (
        tree,
        SkeletonRun {
            options: *options,
            stats,
            error,
            seconds: clock.elapsed().as_secs_f64(),
        },
    )
}

/// How many edits made the state (0 for the automatic result).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct EditCount {
    /// Commands in the history.
    pub history: usize,
    /// Commands applied (the undo position).
    pub applied: usize,
}

/// The plant as it stands: every output is written from this (see the module docs).
#[derive(Clone, Copy)]
pub struct PlantState<'a> {
    pub scene: &'a Scene,
    pub segmentation: &'a Segmentation,
    pub labels: &'a Labels,
    pub branches: &'a BranchTree,
    /// How the first (automatic) skeleton came out.
    pub skeleton: &'a SkeletonRun,
    /// Projections and superpixels per view.
    pub views: &'a ViewCache,
    /// Image boundaries known so far, by (segment, view index).
    pub boundaries: &'a Boundaries,
    pub edits: EditCount,
}

impl PlantState<'_> {
    /// The plant's up direction and axis (from the segmentation) and its branch tips.
    pub fn plant_context(&self) -> PlantContext {
        let foreground = &self.segmentation.foreground;
        PlantContext {
            up: foreground.up,
            axis_point: foreground.plant_center,
            support: self
                .branches
                .branches
                .iter()
                .map(|b| b.cylinder.skeleton.point_at_fraction(1.0))
                .collect(),
        }
    }
}

/// Reconstructs every leaf segment of the state (seed 004 §6).
pub fn fit_leaves(
    state: &PlantState,
    options: &LeafOptions,
    progress: &dyn Progress,
) -> Result<LeafReconstruction, LeafError> {
    let plant = state.plant_context();
    let fills = &state.segmentation.gap_fills;
    let extended;
    let (points, labels) = if fills.is_empty() {
        (&state.segmentation.points, state.labels)
    } else {
        extended = gap_fill::with_gap_fills(
            &state.segmentation.points,
            state.labels,
            &state.segmentation.foreground.class,
            fills,
        );
        (&extended.0, &extended.1)
    };
    let n = state.segmentation.points.len();
    let on_leaves = labels.segment_of[n.min(labels.segment_of.len())..]
        .iter()
        .filter(|&&s| s >= 0)
        .count();
    if !fills.is_empty() {
        tracing::info!("gap fills: {on_leaves} of {} on leaf segments", fills.len());
    }
    let input = LeafInput {
        scene: state.scene,
        points,
        labels,
        plant: &plant,
        views: state.views,
    };
    let mut leaves = reconstruct_leaves(&input, options, progress)?;
    leaves.gap_fills = fills.len();
    leaves.gap_fills_on_leaves = on_leaves;
    Ok(leaves)
}

/// A plant model with how its leaves were attached.
pub struct AssembledPlant {
    pub model: PlantModel,
    /// The state's branches, ended where fitted leaves' blades begin
    /// ([`end_branches_at_blades`]): the ones the model holds.
    pub branches: BranchTree,
    pub attachment: Attachment,
    /// Leaflets on their rachis (see [`crate::branch::compound`]).
    pub compound_leaves: Vec<CompoundLeaf>,
    /// Seconds spent attaching the leaves.
    pub attach_seconds: f64,
}

/// The plant model (seed 004 §7): the fitted leaves, the branches ended where a leaf's blade
/// begins, a petiole from each leaf to its nearest branch, and posed leaves for small segments
/// and leaf-at-tip branches.
pub fn assemble_plant(state: &PlantState, leaves: &LeafReconstruction) -> AssembledPlant {
    let clock = Instant::now();
    let (ended, blade_ends) = end_branches_at_blades(state.branches, leaves);
    let branches = &ended;
    let positions = &state.segmentation.points.positions;
    let small_segments: Vec<(u32, Vec<nalgebra::Point3<f64>>)> = leaves
        .skipped
        .iter()
        .filter(|s| s.for_branch_stage)
        .map(|s| {
            let members = state.labels.members(s.segment);
            (
                s.segment,
                members.iter().map(|&p| positions[p as usize]).collect(),
            )
        })
        .collect();
    let up = state.segmentation.foreground.up;
    let mut attachment = attach_leaves(branches, leaves, &small_segments, &up);
    attachment.blade_ends = blade_ends;
    let compound_leaves = find_compound_leaves(branches, &attachment.on_branches);
    let attach_seconds = clock.elapsed().as_secs_f64();
    // Tip leaves are numbered after every segment id.
    let tip_leaf_base = state.labels.segments.len() as u32;
    let mut branches_out = model_branches(branches);
    let petiole_tree = BranchTree {
        branches: attachment
            .petioles
            .iter()
            .enumerate()
            .map(|(k, p)| p.as_branch(branches.next_id() + k as u32))
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
        compound_leaves: compound_leaves
            .iter()
            .map(|c| CompoundGroup {
                id: c.id,
                rachis: c.rachis,
                leaflets: c.leaflets.clone(),
                branches: (c.rachis_from == 0.0)
                    .then_some(c.rachis)
                    .into_iter()
                    .chain(c.petiolules.iter().copied())
                    .collect(),
            })
            .collect(),
        up: Some(up.into()),
    };
    AssembledPlant {
        model,
        branches: ended,
        attachment,
        compound_leaves,
        attach_seconds,
    }
}

/// The stages a reconstruction runs, in order (as `report.json` lists them).
pub const STAGES: [&str; 7] = [
    "foreground",
    "segmentation",
    "skeleton",
    "boundaries",
    "leaves",
    "attachment",
    "export",
];

/// Output counts of a reconstruction.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReportCounts {
    pub points: usize,
    /// Points per foreground class.
    pub foreground: BTreeMap<String, usize>,
    pub segments: usize,
    pub leaves_fitted: usize,
    pub leaves_skipped: usize,
    /// Gap fills of the input (`frond densify --fill-partners`), and those the leaf stage
    /// fitted leaves with (see the README's *Gap fills*).
    #[serde(default)]
    pub gap_fills: usize,
    #[serde(default)]
    pub gap_fills_on_leaves: usize,
    pub branches: usize,
    pub petioles: usize,
    pub leaves_touching_branches: usize,
    pub leaves_posed: usize,
    pub triangles: usize,
    pub atlas_pages: usize,
}

/// A petiole in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PetioleRecord {
    /// The leaf (segment id).
    pub leaf: u32,
    pub branch: u32,
    pub parent_fraction: f64,
    pub length: f64,
    /// Length along which points show the petiole, as for branches ([`BranchSupport`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub observed_length: Option<f64>,
    /// Length drawn where no point is: a straight line guessed across a gap.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bridged_length: Option<f64>,
}

/// A posed (synthesized) leaf in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PosedRecord {
    pub kind: PosedKind,
    /// The segment (small segments) or the branch (tips).
    pub source: u32,
    pub branch: u32,
    pub base: [f64; 3],
    pub tip: [f64; 3],
    pub length: f64,
}

/// How the leaves were attached, as the report holds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttachmentRecord {
    pub petioles: Vec<PetioleRecord>,
    pub posed: Vec<PosedRecord>,
    pub average: Option<crate::branch::attach::AverageLeaf>,
    /// Leaves whose base already touches a branch.
    pub touching: usize,
    /// Every fitted leaf: the branch it is attached to (directly or by its petiole), where
    /// along it, and the leaf's base and tip.
    #[serde(default)]
    pub leaves: Vec<LeafOnBranch>,
    /// Branch ends cut back where a fitted leaf's blade begins (the branches in
    /// `skeleton.json` and the model are the cut ones).
    #[serde(default)]
    pub blade_ends: BladeEnds,
}

impl AttachmentRecord {
    /// The record of an attachment, with each petiole's support (`petiole_support`, by leaf
    /// id; see [`petiole_support`]).
    fn of(attachment: &Attachment, petiole_support: &[BranchSupport]) -> Self {
        Self {
            petioles: attachment
                .petioles
                .iter()
                .map(|p| {
                    let support = petiole_support.iter().find(|s| s.id == p.leaf);
                    PetioleRecord {
                        leaf: p.leaf,
                        branch: p.branch,
                        parent_fraction: p.parent_fraction,
                        length: p.length,
                        observed_length: support.map(|s| s.observed_length),
                        bridged_length: support.map(|s| s.bridged_length),
                    }
                })
                .collect(),
            posed: attachment
                .posed
                .iter()
                .map(|p| PosedRecord {
                    kind: p.kind,
                    source: p.source,
                    branch: p.branch,
                    base: p.base,
                    tip: p.tip,
                    length: p.length,
                })
                .collect(),
            average: attachment.average,
            touching: attachment.touching,
            leaves: attachment.on_branches.clone(),
            blade_ends: attachment.blade_ends,
        }
    }
}

/// The generic leaf's source, by COLMAP image id.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct TemplateRecord {
    pub segment: u32,
    pub image_id: u32,
}

/// One fitted leaf in the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LeafRecord {
    pub segment: u32,
    /// The COLMAP image its boundary and texture come from.
    pub image_id: Option<u32>,
    pub points: usize,
    pub point_residual: f64,
    pub length: f64,
    pub base: [f64; 3],
    pub tip: [f64; 3],
    pub area: f64,
    pub icp: Option<crate::leaf::fit::IcpReport>,
    pub boundary_area: Option<f64>,
    pub outline_area: f64,
    pub textured_fraction: f64,
    pub notes: Vec<String>,
}

/// The parameters a reconstruction ran with.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReportParameters {
    pub segmentation: SegmentOptions,
    pub leaves: LeafOptions,
}

/// Seconds per stage (`total` is their sum, segmentation included).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReportTimings {
    pub leaves: LeafTimings,
    pub skeleton: f64,
    pub attachment: f64,
    pub export: f64,
    pub total: f64,
}

/// The name and version of `report.json`'s schema.
pub const REPORT_FORMAT: &str = "frond report";
pub const REPORT_VERSION: u32 = 2;

/// `report.json`: what a reconstruction did (see the README's format section).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReconstructionReport {
    pub format: String,
    pub version: u32,
    /// The Frond version that wrote it.
    pub frond: String,
    /// The COLMAP model folder read.
    pub input: PathBuf,
    /// How the input became that scene (structure from motion, densifying), when known.
    pub preparation: Option<ScenePreparation>,
    pub stages: Vec<String>,
    pub edits: EditCount,
    pub counts: ReportCounts,
    pub skeleton: Option<SkeletonStats>,
    /// Why there is no automatic skeleton, when there is none.
    pub skeleton_error: Option<String>,
    /// How much of the branches the points show (per branch in `skeleton.json`).
    #[serde(default)]
    pub skeleton_support: SupportSummary,
    /// The same of the petioles drawn from leaves to branches (`mostly_bridged` lists leaf
    /// ids; per petiole in `attachment.petioles`).
    #[serde(default)]
    pub petiole_support: SupportSummary,
    pub attachment: AttachmentRecord,
    /// Compound leaves: a rachis (branch id) and its leaflets (segment ids).
    #[serde(default)]
    pub compound_leaves: Vec<CompoundLeaf>,
    pub template: Option<TemplateRecord>,
    pub skipped: Vec<SkippedLeaf>,
    pub unusable_views: Vec<UnusableView>,
    pub leaves: Vec<LeafRecord>,
    pub parameters: ReportParameters,
    /// The automatic segmentation's statistics (segments, σ, edge counts, timings).
    pub segmentation: serde_json::Value,
    pub timings: ReportTimings,
    /// Files written, relative to the output folder.
    pub files: Vec<PathBuf>,
}

fn output_error(path: &Path, message: impl std::fmt::Display) -> PipelineError {
    PipelineError::Output {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

impl ReconstructionReport {
    /// Reads and checks a `report.json` (this format and version only).
    pub fn read(path: &Path) -> Result<Self, PipelineError> {
        files::read_versioned(path, REPORT_FORMAT, REPORT_VERSION)
    }
}

/// How much of each petiole drawn from a leaf to a branch the points show, as
/// [`plant_branch_support`] measures branches; each support's `id` is the petiole's leaf.
fn petiole_support(state: &PlantState, attachment: &Attachment) -> Vec<BranchSupport> {
    let tree = BranchTree {
        branches: attachment
            .petioles
            .iter()
            .map(|p| p.as_branch(p.leaf))
            .collect(),
    };
    plant_branch_support(
        state.segmentation,
        state.labels,
        &tree,
        &state.skeleton.options.tube,
    )
}

/// Writes every output of a plant whose leaves were reconstructed into `out`:
/// `skeleton.json`, `plant.glb`, `plant.obj` (+ materials, atlas), `segmentation.ply`,
/// `segments.json` and `report.json`, each atomically.
pub fn write_plant(
    state: &PlantState,
    leaves: &LeafReconstruction,
    leaf_options: &LeafOptions,
    preparation: Option<&ScenePreparation>,
    out: &Path,
) -> Result<ReconstructionReport, PipelineError> {
    std::fs::create_dir_all(out).map_err(|e| output_error(out, e))?;
    let AssembledPlant {
        model,
        branches,
        attachment,
        compound_leaves,
        attach_seconds,
    } = assemble_plant(state, leaves);
    let support = plant_branch_support(
        state.segmentation,
        state.labels,
        &branches,
        &state.skeleton.options.tube,
    );
    files::write_skeleton(&branches, &support, out)?;
    let petiole_support = petiole_support(state, &attachment);
    let clock = Instant::now();
    let export = model.export(out).map_err(|e| output_error(out, e))?;
    let mut boundaries = state.boundaries.clone();
    for (key, boundary) in &leaves.boundaries {
        boundaries.entry(*key).or_insert_with(|| boundary.clone());
    }
    write_segmentation(state, &boundaries, out)?;
    let export_seconds = clock.elapsed().as_secs_f64();
    let images = state.scene.reconstruction.images();
    let image_id = |view: usize| images.get(view).map(|i| i.id);
    let segmentation = state.segmentation;
    let mut written: Vec<PathBuf> = export
        .files
        .iter()
        .map(|f| f.strip_prefix(out).unwrap_or(f).to_path_buf())
        .collect();
    written.extend(
        [
            files::SKELETON_FILE,
            files::SEGMENTATION_FILE,
            files::SEGMENTS_FILE,
            files::REPORT_FILE,
        ]
        .map(PathBuf::from),
    );
    let timings = ReportTimings {
        leaves: leaves.timings.clone(),
        skeleton: state.skeleton.seconds,
        attachment: attach_seconds,
        export: export_seconds,
        total: segmentation.timings.total
            + state.skeleton.seconds
            + leaves.timings.template
            + leaves.timings.boundaries
            + leaves.timings.fitting
            + attach_seconds
            + export_seconds,
    };
    let report = ReconstructionReport {
        format: REPORT_FORMAT.to_owned(),
        version: REPORT_VERSION,
        frond: env!("CARGO_PKG_VERSION").to_owned(),
        input: state.scene.source.model_dir.clone(),
        preparation: preparation.cloned(),
        stages: STAGES.iter().map(|s| s.to_string()).collect(),
        edits: state.edits,
        counts: ReportCounts {
            points: segmentation.points.len(),
            foreground: segmentation.class_counts(),
            segments: state.labels.segments.iter().flatten().count(),
            leaves_fitted: leaves.leaves.len(),
            leaves_skipped: leaves.skipped.len(),
            gap_fills: leaves.gap_fills,
            gap_fills_on_leaves: leaves.gap_fills_on_leaves,
            branches: branches.branches.len(),
            petioles: attachment.petioles.len(),
            leaves_touching_branches: attachment.touching,
            leaves_posed: attachment.posed.len(),
            triangles: export.triangles,
            atlas_pages: export.atlas_pages,
        },
        skeleton: state.skeleton.stats.clone(),
        skeleton_error: state.skeleton.error.clone(),
        skeleton_support: SupportSummary::new(&support),
        petiole_support: SupportSummary::new(&petiole_support),
        attachment: AttachmentRecord::of(&attachment, &petiole_support),
        compound_leaves,
        template: leaves.template_source.and_then(|t| {
            Some(TemplateRecord {
                segment: t.segment,
                image_id: image_id(t.view)?,
            })
        }),
        skipped: leaves.skipped.clone(),
        unusable_views: leaves.unusable_views.clone(),
        leaves: leaves
            .leaves
            .iter()
            .map(|l| LeafRecord {
                segment: l.segment,
                image_id: l.view.and_then(image_id),
                points: l.fit.points,
                point_residual: l.fit.point_residual,
                length: l.fit.length,
                base: l.fit.base,
                tip: l.fit.tip,
                area: l.fit.area,
                icp: l.fit.icp,
                boundary_area: l.fit.boundary_area,
                outline_area: l.fit.outline_area,
                textured_fraction: l.fit.textured_fraction,
                notes: l.fit.notes.clone(),
            })
            .collect(),
        parameters: ReportParameters {
            segmentation: segmentation.options,
            leaves: *leaf_options,
        },
        segmentation: serde_json::to_value(segmentation)
            .map_err(|e| output_error(&out.join(files::REPORT_FILE), e))?,
        timings,
        files: written,
    };
    files::write_json(&out.join(files::REPORT_FILE), &report)?;
    Ok(report)
}

/// `segmentation.ply` and `segments.json` of an automatic segmentation (what `frond segment`
/// writes): its labels, no branches, no boundaries, no edits.
pub fn write_automatic_segmentation(
    scene: &Scene,
    segmentation: &Segmentation,
    out: &Path,
) -> Result<(), PipelineError> {
    let labels = Labels::automatic(segmentation);
    let views = ViewCache::default();
    let boundaries = Boundaries::new();
    let state = PlantState {
        scene,
        segmentation,
        labels: &labels,
        branches: &BranchTree::default(),
        skeleton: &SkeletonRun::default(),
        views: &views,
        boundaries: &boundaries,
        edits: EditCount::default(),
    };
    write_segmentation(&state, &boundaries, out)
}

/// Options of a whole reconstruction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ReconstructOptions {
    pub segmentation: SegmentOptions,
    pub leaves: LeafOptions,
    pub skeleton: PlantSkeletonOptions,
}

/// What [`reconstruct`] returns: the report it wrote and the leaves it fitted.
pub struct Reconstruction {
    pub report: ReconstructionReport,
    pub leaves: LeafReconstruction,
}

/// The whole automatic reconstruction of a scene into `out` (see the module docs): the same
/// files an editing session with no edits exports.
pub fn reconstruct(
    scene: &Scene,
    options: &ReconstructOptions,
    preparation: Option<&ScenePreparation>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Reconstruction, PipelineError> {
    let segmentation = segment_scene(scene, &options.segmentation, progress)?;
    progress.stage("automatic skeleton", 0);
    let labels = Labels::automatic(&segmentation);
    let (branches, skeleton) = automatic_skeleton(&segmentation, &labels, &options.skeleton);
    if let Some(error) = &skeleton.error {
        tracing::warn!("no automatic skeleton: {error}");
    }
    let views = ViewCache::new(BoundaryOptions::default());
    let boundaries = Boundaries::new();
    let state = PlantState {
        scene,
        segmentation: &segmentation,
        labels: &labels,
        branches: &branches,
        skeleton: &skeleton,
        views: &views,
        boundaries: &boundaries,
        edits: EditCount::default(),
    };
    let leaves = fit_leaves(&state, &options.leaves, progress)?;
    progress.stage("export", 0);
    let report = write_plant(&state, &leaves, &options.leaves, preparation, out)?;
    Ok(Reconstruction { report, leaves })
}
