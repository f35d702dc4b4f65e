//! Accuracy of a reconstructed point cloud against the synthetic plant's surface: for each
//! point, the distance to the true surface, taken as the distance to the plane of its nearest
//! ground-truth surface samples (point-to-plane, so the samples' spacing does not count as
//! error), bounded by the distance to the nearest sample. For thin organs
//! ([`thin_organ_accuracy`]): how much of the true stem and petiole centrelines the points
//! cover, how densely, how close, and how many points float in the plant's space away from
//! every true surface (the halo stereo smears around thin organs).

use nalgebra::Point3;
use rayon::prelude::*;
use serde::Serialize;

use super::{EvalError, GroundTruth, input_error};
use crate::graph::neighbours::Neighbours;
use crate::graph::shape::Shape;
use crate::util::stats::quantile_sorted;

/// How many points lie on the plant and how far from its surface.
#[derive(Clone, Debug, Serialize)]
pub struct PointAccuracy {
    pub points: usize,
    /// Points whose nearest true surface is a leaf or the stem, within `gate` of it.
    pub plant_points: usize,
    /// Of those, on leaves.
    pub leaf_points: usize,
    /// Distance beyond which a point is not counted as on the plant (fraction of the height).
    pub gate_fraction_of_height: f64,
    pub plant_height: f64,
    pub median_error: f64,
    pub p90_error: f64,
    pub median_error_fraction_of_height: f64,
    /// Different leaves with at least 20 points on them.
    pub leaves_covered: usize,
    pub leaves_total: usize,
}

/// Scores `points` (in the ground truth's frame) against the true surfaces.
pub fn point_accuracy(
    gt: &GroundTruth,
    points: &[Point3<f64>],
    gate_fraction_of_height: f64,
) -> Result<PointAccuracy, EvalError> {
    let surface = TrueSurface::of(gt)?;
    let parts = surface.parts;
    let samples = &gt.surface_samples;
    let gate = gate_fraction_of_height * gt.plant_height;
    // Per point: (distance to the surface, nearest sample) when near a plant surface.
    let hits: Vec<Option<(f64, usize)>> = points
        .par_iter()
        .map(|p| {
            let hit = surface.hit(p)?;
            (parts[hit.sample].is_plant() && hit.nearest <= gate)
                .then_some((hit.surface, hit.sample))
        })
        .collect();
    let mut errors: Vec<f64> = hits.iter().flatten().map(|(e, _)| *e).collect();
    errors.sort_by(f64::total_cmp);
    let mut per_leaf = std::collections::BTreeMap::new();
    let mut leaf_points = 0;
    for (_, sample) in hits.iter().flatten() {
        if samples.leaf_ids[*sample] >= 0 {
            leaf_points += 1;
            *per_leaf.entry(samples.leaf_ids[*sample]).or_insert(0usize) += 1;
        }
    }
    let median = quantile_sorted(&errors, 0.5);
    Ok(PointAccuracy {
        points: points.len(),
        plant_points: errors.len(),
        leaf_points,
        gate_fraction_of_height,
        plant_height: gt.plant_height,
        median_error: median,
        p90_error: quantile_sorted(&errors, 0.9),
        median_error_fraction_of_height: median / gt.plant_height,
        leaves_covered: per_leaf.values().filter(|&&n| n >= 20).count(),
        leaves_total: gt.leaves.len(),
    })
}

/// How well a point cloud keeps the thin organs (stems, petioles, twigs) of a synthetic plant.
#[derive(Clone, Debug, Serialize)]
pub struct ThinOrganAccuracy {
    /// True stem and petiole centreline length (metres).
    pub centerline_length: f64,
    /// Share of that length with a point within the organ's radius + `near` of its centreline.
    pub centerline_coverage: f64,
    /// Points within radius + `near` of a true centreline, per metre of centreline.
    pub points_per_metre: f64,
    /// Median distance of those points to the organ's true surface (|distance to the axis −
    /// radius|), metres.
    pub median_surface_distance: f64,
    /// Pixel footprint at the plant (median camera distance / mean focal length), metres.
    pub pixel_footprint: f64,
    /// Points in the plant's space (inside its bounding cylinder, above the soil).
    pub points_in_plant_space: usize,
    /// Share of those farther than two pixel footprints from every true surface (leaf, stem or
    /// pot): the halo.
    pub halo_fraction: f64,
    pub near: f64,
}

/// Where a point lies against the true surface.
struct SurfaceHit {
    /// Distance to the plane of its nearest samples of the same part and leaf, bounded by
    /// `nearest`.
    surface: f64,
    /// Distance to the nearest sample.
    nearest: f64,
    sample: usize,
}

/// The true surfaces of a synthetic plant: its surface samples, indexed.
struct TrueSurface<'a> {
    samples: &'a super::LabelledPoints,
    parts: &'a [crate::synth::Part],
    index: Neighbours,
    neighbours: std::num::NonZero<usize>,
}

impl<'a> TrueSurface<'a> {
    fn of(gt: &'a GroundTruth) -> Result<Self, EvalError> {
        let samples = &gt.surface_samples;
        let parts = samples
            .parts
            .as_ref()
            .ok_or_else(|| input_error(&gt.root, "surface_samples.ply has no part column"))?;
        let index = Neighbours::new(samples.positions.iter().copied())
            .map_err(|e| input_error(&gt.root, format!("cannot index surface samples: {e:?}")))?;
        let Some(neighbours) = std::num::NonZero::new(8.min(index.len())) else {
            return Err(input_error(&gt.root, "no surface samples"));
        };
        Ok(Self {
            samples,
            parts,
            index,
            neighbours,
        })
    }

    /// Where `p` lies against the surface (see [`SurfaceHit`]).
    fn hit(&self, p: &Point3<f64>) -> Option<SurfaceHit> {
        let (samples, parts) = (self.samples, self.parts);
        let nearest = self.index.nearest_k(p, self.neighbours);
        let first = nearest.first()?;
        let sample = first.index;
        let distance = first.distance();
        let same: Vec<Point3<f64>> = nearest
            .iter()
            .map(|n| n.index)
            .filter(|&i| {
                samples.leaf_ids[i] == samples.leaf_ids[sample] && parts[i] == parts[sample]
            })
            .map(|i| samples.positions[i])
            .collect();
        let to_plane = if same.len() >= 4 {
            let shape = Shape::of(same.iter().copied());
            (p - shape.centroid).dot(&shape.normal()).abs()
        } else {
            distance
        };
        Some(SurfaceHit {
            surface: to_plane.min(distance),
            nearest: distance,
            sample,
        })
    }
}

/// Scores `points` (in the ground truth's frame) on the thin organs (see
/// [`ThinOrganAccuracy`]); `near` is the slack beyond an organ's radius (2 mm in the issue's
/// measure).
pub fn thin_organ_accuracy(
    gt: &GroundTruth,
    points: &[Point3<f64>],
    near: f64,
) -> Result<ThinOrganAccuracy, EvalError> {
    let index = Neighbours::new(points.iter().copied())
        .map_err(|e| input_error(&gt.root, format!("cannot index the points: {e:?}")))?;
    // Coverage along 1 mm pieces of every true centreline.
    let (mut covered, mut length) = (0.0, 0.0);
    let mut near_points = std::collections::BTreeMap::<usize, f64>::new();
    for branch in &gt.branches {
        let radius = branch.mean_radius();
        let limit = radius + near;
        for w in branch.centerline.windows(2) {
            let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
            let span = (b - a).norm();
            if !span.is_finite() || span <= 0.0 {
                continue;
            }
            let n = (span / 0.001).ceil() as usize;
            for k in 0..n {
                let p = a + (b - a) * ((k as f64 + 0.5) / n as f64);
                length += span / n as f64;
                let around = index.within_radius(&p, limit);
                if !around.is_empty() {
                    covered += span / n as f64;
                }
                for q in around {
                    let axis =
                        crate::branch::spline::point_segment_distance(&points[q.index], &a, &b);
                    let d = (axis - radius).abs();
                    let entry = near_points.entry(q.index).or_insert(f64::INFINITY);
                    *entry = entry.min(d);
                }
            }
        }
    }
    let mut distances: Vec<f64> = near_points.values().copied().collect();
    distances.sort_by(f64::total_cmp);
    // The halo: points in the plant's space away from every true surface.
    let surface = TrueSurface::of(gt)?;
    let space = PlantSpace::of(gt)?;
    let footprint = pixel_footprint(gt)?;
    let inside: Vec<&Point3<f64>> = points.iter().filter(|p| space.contains(p)).collect();
    let halo = inside
        .par_iter()
        .filter(|p| {
            surface
                .hit(p)
                .is_none_or(|hit| hit.surface > 2.0 * footprint)
        })
        .count();
    Ok(ThinOrganAccuracy {
        centerline_length: length,
        centerline_coverage: if length > 0.0 { covered / length } else { 0.0 },
        points_per_metre: if length > 0.0 {
            near_points.len() as f64 / length
        } else {
            0.0
        },
        median_surface_distance: quantile_sorted(&distances, 0.5),
        pixel_footprint: footprint,
        points_in_plant_space: inside.len(),
        halo_fraction: if inside.is_empty() {
            0.0
        } else {
            halo as f64 / inside.len() as f64
        },
        near,
    })
}

/// The plant's space in a synthetic dataset: the upright cylinder around its axis that holds its
/// surfaces, above the soil (where no true surface but the plant's lies).
struct PlantSpace {
    center: Point3<f64>,
    radius: f64,
    bottom: f64,
    top: f64,
}

impl PlantSpace {
    fn of(gt: &GroundTruth) -> Result<Self, EvalError> {
        let meta_path = gt.root.join("meta.json");
        let meta: serde_json::Value = super::read_json(&meta_path)?;
        let plant = &meta["plant"];
        let number = |v: &serde_json::Value, what: &str| {
            v.as_f64()
                .ok_or_else(|| input_error(&meta_path, format!("no {what}")))
        };
        let center = Point3::new(
            number(&plant["center"][0], "plant.center")?,
            number(&plant["center"][1], "plant.center")?,
            0.0,
        );
        let soil = number(&plant["pot"]["soil_height"], "plant.pot.soil_height")?;
        let pot_top = number(&plant["pot"]["height"], "plant.pot.height")?;
        let plant_samples = gt
            .surface_samples
            .positions
            .iter()
            .zip(gt.surface_samples.parts.iter().flatten())
            .filter(|(_, part)| part.is_plant())
            .map(|(p, _)| p);
        let (mut radius, mut top) = (0.0f64, f64::NEG_INFINITY);
        for p in plant_samples {
            radius = radius.max((p.x - center.x).hypot(p.y - center.y));
            top = top.max(p.z);
        }
        Ok(Self {
            center,
            radius,
            bottom: soil.max(pot_top) + 0.005,
            top,
        })
    }

    fn contains(&self, p: &Point3<f64>) -> bool {
        p.z > self.bottom
            && p.z <= self.top
            && (p.x - self.center.x).hypot(p.y - self.center.y) <= self.radius
    }
}

/// Median camera distance to the plant's centre over the mean focal length of the dataset's
/// true cameras.
fn pixel_footprint(gt: &GroundTruth) -> Result<f64, EvalError> {
    let (model, _) = crate::scene::read_model(&gt.root.join("sparse/0"))?;
    let focal: Vec<f64> = model
        .cameras()
        .iter()
        .map(|c| {
            let (fx, fy, _, _) = c.focal_and_principal_point();
            0.5 * (fx + fy)
        })
        .collect();
    let mean_focal = focal.iter().sum::<f64>() / focal.len().max(1) as f64;
    let center = Point3::new(0.0, 0.0, 0.5 * gt.plant_height);
    let distance = crate::util::stats::median(
        model
            .images()
            .iter()
            .map(|i| (i.center_world() - center).norm()),
    )
    .ok_or_else(|| input_error(&gt.root, "the true model has no images"))?;
    if mean_focal <= 0.0 || !mean_focal.is_finite() {
        return Err(input_error(
            &gt.root,
            "the true cameras have no focal length",
        ));
    }
    Ok(distance / mean_focal)
}
