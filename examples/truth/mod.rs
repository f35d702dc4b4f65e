//! What the tuning aids that hold a reconstruction against a synthetic dataset's truth share:
//! loading both in the truth's frame, the points' spacing, and the true leaf masks per view.

use std::num::NonZero;
use std::path::Path;

use anyhow::{Context, Result};
use frond::eval::{GroundTruth, Prediction, align_to_ground_truth};
use frond::graph::neighbours::Neighbours;
use frond::scene::model::Reconstruction;
use frond::scene::read_model;
use image::{ImageBuffer, Luma};
use nalgebra::Point3;

/// The dataset's truth and the reconstruction in `out`, moved into the truth's frame by the
/// camera centres of `model` (the COLMAP model it was made from) when given, as it must be
/// when the reconstruction was not made from the dataset's own model.
pub fn load_aligned(
    gt_root: &Path,
    out: &Path,
    model: Option<&Path>,
) -> Result<(GroundTruth, Prediction)> {
    let truth = GroundTruth::load(gt_root)?;
    let mut prediction = Prediction::load(out)?;
    if let Some(model) = model {
        let (similarity, _) = align_to_ground_truth(gt_root, model)?;
        prediction.transform(&similarity);
    }
    Ok((truth, prediction))
}

/// Median distance from a point to its nearest other point, over every 17th point.
pub fn point_spacing(points: &Neighbours) -> f64 {
    let Some(two) = NonZero::new(2) else {
        return 0.0;
    };
    let mut gaps: Vec<f64> = (0..points.len())
        .step_by(17)
        .filter_map(|i| {
            points
                .nearest_k(&points.point(i), two)
                .get(1)
                .map(|n| n.distance())
        })
        .collect();
    gaps.sort_by(f64::total_cmp);
    gaps.get(gaps.len() / 2).copied().unwrap_or(0.0)
}

/// The dataset's views with their true leaf masks (`gt/masks`: leaf id + 1 per pixel, 0 where
/// no leaf is).
pub struct LeafMasks {
    model: Reconstruction,
    masks: Vec<ImageBuffer<Luma<u16>, Vec<u16>>>,
}

impl LeafMasks {
    pub fn load(gt_root: &Path) -> Result<Self> {
        let (model, _) = read_model(&gt_root.join("sparse/0"))?;
        let mut masks = Vec::new();
        for image in model.images() {
            let stem = Path::new(&image.name)
                .file_stem()
                .context("image name")?
                .to_string_lossy()
                .to_string();
            let path = gt_root.join("gt/masks").join(format!("{stem}.png"));
            masks.push(
                image::open(&path)
                    .with_context(|| format!("{}", path.display()))?
                    .into_luma16(),
            );
        }
        Ok(Self { model, masks })
    }

    /// Number of views.
    pub fn len(&self) -> usize {
        self.masks.len()
    }

    /// Views in which `p` projects into the image onto a mask value that `accept` takes.
    pub fn views_where(&self, p: &Point3<f64>, accept: impl Fn(u16) -> bool) -> usize {
        self.model
            .images()
            .iter()
            .zip(&self.masks)
            .filter(|(image, mask)| {
                self.model.project(image, p).is_some_and(|uv| {
                    let (x, y) = (uv.x.floor(), uv.y.floor());
                    x >= 0.0
                        && y >= 0.0
                        && (x as u32) < mask.width()
                        && (y as u32) < mask.height()
                        && accept(mask.get_pixel(x as u32, y as u32).0[0])
                })
            })
            .count()
    }
}
