//! Scene summary for `frond info`: counts, track statistics, reprojection error recomputed by
//! Frond beside the one COLMAP stored, image file checks and the bounding box.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::Serialize;

use super::{ImageFileStatus, ModelFormat, Scene, SceneSource};
use crate::util::stats::quantile_sorted;

#[derive(Clone, Debug, Serialize)]
pub struct CameraSummary {
    pub id: u32,
    pub model: String,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ImageProblem {
    pub image_id: u32,
    pub name: String,
    #[serde(flatten)]
    pub status: ImageFileStatus,
}

#[derive(Clone, Debug, Serialize)]
pub struct ImageSummary {
    pub registered: usize,
    pub files_present: usize,
    pub files_missing: usize,
    pub files_unreadable: usize,
    pub files_size_mismatch: usize,
    pub images_folder: Option<String>,
    /// The first problems found (at most 20).
    pub problems: Vec<ImageProblem>,
}

#[derive(Clone, Debug, Serialize)]
pub struct PointSummary {
    pub count: usize,
    pub observations: usize,
    pub mean_track_length: f64,
    pub mean_observations_per_image: f64,
}

/// Reprojection error in pixels. "Mean" follows COLMAP: the mean over points of each point's
/// mean error over its track.
#[derive(Clone, Debug, Serialize)]
pub struct ReprojectionSummary {
    /// Mean of the errors COLMAP stored (points with a stored error ≥ 0).
    pub stored_mean_px: Option<f64>,
    /// The same statistic recomputed by projecting every point into every image of its track.
    pub recomputed_mean_px: Option<f64>,
    /// Root mean square over all observations.
    pub recomputed_rms_px: Option<f64>,
    /// Largest per-point |stored − recomputed|.
    pub max_point_difference_px: Option<f64>,
    /// Observations whose point projected behind the camera.
    pub failed_projections: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct BoundingBox {
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// 1st and 99th percentile per axis: the box without outliers.
    pub robust_min: [f64; 3],
    pub robust_max: [f64; 3],
}

#[derive(Clone, Debug, Serialize)]
pub struct DenseSummary {
    pub points: usize,
    pub with_normals: bool,
    pub with_visibility: bool,
}

/// Everything `frond info` reports.
#[derive(Clone, Debug, Serialize)]
pub struct SceneSummary {
    pub source: SceneSource,
    pub format: ModelFormat,
    pub cameras: Vec<CameraSummary>,
    pub camera_models: BTreeMap<String, usize>,
    pub images: ImageSummary,
    pub points: PointSummary,
    pub reprojection: ReprojectionSummary,
    pub bounding_box: Option<BoundingBox>,
    pub dense: Option<DenseSummary>,
}

/// Computes the summary of a loaded scene.
pub fn summarize(scene: &Scene) -> SceneSummary {
    let model = &scene.reconstruction;
    let cameras: Vec<CameraSummary> = model
        .cameras()
        .iter()
        .map(|c| CameraSummary {
            id: c.id,
            model: c.model.name().to_owned(),
            width: c.width,
            height: c.height,
            params: c.params().to_vec(),
        })
        .collect();
    let mut camera_models = BTreeMap::new();
    for c in model.cameras() {
        *camera_models.entry(c.model.name().to_owned()).or_insert(0) += 1;
    }

    let statuses: Vec<(usize, ImageFileStatus)> = model
        .images()
        .par_iter()
        .enumerate()
        .map(|(i, image)| (i, scene.image_file_status(image)))
        .collect();
    let mut images = ImageSummary {
        registered: model.images().len(),
        files_present: 0,
        files_missing: 0,
        files_unreadable: 0,
        files_size_mismatch: 0,
        images_folder: scene
            .source
            .images_dir
            .as_ref()
            .map(|p| p.display().to_string()),
        problems: Vec::new(),
    };
    for (i, status) in statuses {
        match &status {
            ImageFileStatus::Present => images.files_present += 1,
            ImageFileStatus::Missing | ImageFileStatus::NoImagesFolder => images.files_missing += 1,
            ImageFileStatus::Unreadable { .. } => images.files_unreadable += 1,
            ImageFileStatus::SizeMismatch { .. } => images.files_size_mismatch += 1,
        }
        if status != ImageFileStatus::Present
            && status != ImageFileStatus::NoImagesFolder
            && images.problems.len() < 20
        {
            let image = &model.images()[i];
            images.problems.push(ImageProblem {
                image_id: image.id,
                name: image.name.clone(),
                status,
            });
        }
    }

    let observations = model.num_observations();
    let points = PointSummary {
        count: model.points().len(),
        observations,
        mean_track_length: ratio(observations, model.points().len()),
        mean_observations_per_image: ratio(observations, model.images().len()),
    };

    SceneSummary {
        source: scene.source.clone(),
        format: scene.format,
        cameras,
        camera_models,
        images,
        points,
        reprojection: reprojection_summary(model),
        bounding_box: bounding_box(model),
        dense: scene.dense.as_ref().map(|d| DenseSummary {
            points: d.positions_world.len(),
            with_normals: d.normals_world.is_some(),
            with_visibility: !d.visible_in.is_empty(),
        }),
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
}

/// Per point: (stored error, recomputed mean, sum of squares, observations, failures).
fn reprojection_summary(model: &super::Reconstruction) -> ReprojectionSummary {
    let per_point: Vec<(f64, Option<f64>, f64, usize, usize)> = model
        .points()
        .par_iter()
        .map(|p| {
            let errors = model.reprojection_errors(p);
            let ok: Vec<f64> = errors.iter().flatten().copied().collect();
            let failures = errors.len() - ok.len();
            let mean = (!ok.is_empty()).then(|| ok.iter().sum::<f64>() / ok.len() as f64);
            let squares = ok.iter().map(|e| e * e).sum();
            (p.error, mean, squares, ok.len(), failures)
        })
        .collect();
    let stored: Vec<f64> = per_point
        .iter()
        .map(|t| t.0)
        .filter(|e| *e >= 0.0)
        .collect();
    let recomputed: Vec<f64> = per_point.iter().filter_map(|t| t.1).collect();
    let squares: f64 = per_point.iter().map(|t| t.2).sum();
    let count: usize = per_point.iter().map(|t| t.3).sum();
    let max_difference = per_point
        .iter()
        .filter(|t| t.0 >= 0.0)
        .filter_map(|t| t.1.map(|m| (m - t.0).abs()))
        .fold(None, |acc: Option<f64>, d| {
            Some(acc.map_or(d, |a| a.max(d)))
        });
    ReprojectionSummary {
        stored_mean_px: (!stored.is_empty())
            .then(|| stored.iter().sum::<f64>() / stored.len() as f64),
        recomputed_mean_px: (!recomputed.is_empty())
            .then(|| recomputed.iter().sum::<f64>() / recomputed.len() as f64),
        recomputed_rms_px: (count > 0).then(|| (squares / count as f64).sqrt()),
        max_point_difference_px: max_difference,
        failed_projections: per_point.iter().map(|t| t.4).sum(),
    }
}

fn bounding_box(model: &super::Reconstruction) -> Option<BoundingBox> {
    if model.points().is_empty() {
        return None;
    }
    let mut min = [f64::INFINITY; 3];
    let mut max = [f64::NEG_INFINITY; 3];
    let mut robust_min = [0.0; 3];
    let mut robust_max = [0.0; 3];
    for axis in 0..3 {
        let mut values: Vec<f64> = model
            .points()
            .iter()
            .map(|p| p.position_world[axis])
            .collect();
        values.sort_by(f64::total_cmp);
        min[axis] = values[0];
        max[axis] = values[values.len() - 1];
        robust_min[axis] = quantile_sorted(&values, 0.01);
        robust_max[axis] = quantile_sorted(&values, 0.99);
    }
    Some(BoundingBox {
        min,
        max,
        robust_min,
        robust_max,
    })
}

fn fmt_px(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".to_owned(), |v| format!("{v:.4} px"))
}

impl SceneSummary {
    /// Human-readable report.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "model:        {} ({}, {:?} layout)",
            self.source.model_dir.display(),
            self.format,
            self.source.layout
        );
        for other in &self.source.other_models {
            let _ = writeln!(s, "also found:   {}", other.display());
        }
        let models: Vec<String> = self
            .camera_models
            .iter()
            .map(|(m, n)| format!("{n} {m}"))
            .collect();
        let _ = writeln!(
            s,
            "cameras:      {} ({})",
            self.cameras.len(),
            models.join(", ")
        );
        for c in self.cameras.iter().take(8) {
            let params: Vec<String> = c.params.iter().map(|p| format!("{p:.6}")).collect();
            let _ = writeln!(
                s,
                "  camera {:>4}: {} {}x{} [{}]",
                c.id,
                c.model,
                c.width,
                c.height,
                params.join(", ")
            );
        }
        if self.cameras.len() > 8 {
            let _ = writeln!(s, "  … {} more", self.cameras.len() - 8);
        }
        let i = &self.images;
        let _ = writeln!(
            s,
            "images:       {} registered; files: {} present, {} missing, {} unreadable, {} wrong size ({})",
            i.registered,
            i.files_present,
            i.files_missing,
            i.files_unreadable,
            i.files_size_mismatch,
            i.images_folder.as_deref().unwrap_or("no images folder")
        );
        for p in &i.problems {
            let _ = writeln!(s, "  image {} '{}': {:?}", p.image_id, p.name, p.status);
        }
        let p = &self.points;
        let _ = writeln!(
            s,
            "points:       {} ({} observations, mean track length {:.3}, {:.1} observations per image)",
            p.count, p.observations, p.mean_track_length, p.mean_observations_per_image
        );
        let r = &self.reprojection;
        let _ = writeln!(
            s,
            "reprojection: stored mean {}, recomputed mean {} (rms {}, max per-point difference {}, {} failed)",
            fmt_px(r.stored_mean_px),
            fmt_px(r.recomputed_mean_px),
            fmt_px(r.recomputed_rms_px),
            fmt_px(r.max_point_difference_px),
            r.failed_projections
        );
        if let Some(b) = &self.bounding_box {
            let f = |v: [f64; 3]| format!("({:.4}, {:.4}, {:.4})", v[0], v[1], v[2]);
            let _ = writeln!(
                s,
                "bounds:       {} – {} (1–99%: {} – {})",
                f(b.min),
                f(b.max),
                f(b.robust_min),
                f(b.robust_max)
            );
        }
        if let Some(d) = &self.dense {
            let _ = writeln!(
                s,
                "dense:        {} points (normals: {}, visibility: {})",
                d.points, d.with_normals, d.with_visibility
            );
        }
        s
    }
}
