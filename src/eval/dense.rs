//! Accuracy of a reconstructed point cloud against the synthetic plant's surface: for each
//! point, the distance to the true surface, taken as the distance to the plane of its nearest
//! ground-truth surface samples (point-to-plane, so the samples' spacing does not count as
//! error), bounded by the distance to the nearest sample.

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
    let samples = &gt.surface_samples;
    let parts = samples
        .parts
        .as_ref()
        .ok_or_else(|| input_error(&gt.root, "surface_samples.ply has no part column"))?;
    let sample_neighbours = Neighbours::new(samples.positions.iter().copied())
        .map_err(|e| input_error(&gt.root, format!("cannot index surface samples: {e:?}")))?;
    let Some(neighbours) = std::num::NonZero::new(8.min(sample_neighbours.len())) else {
        return Err(input_error(&gt.root, "no surface samples"));
    };
    let gate = gate_fraction_of_height * gt.plant_height;
    // Per point: (distance to the surface, nearest sample) when near a plant surface.
    let hits: Vec<Option<(f64, usize)>> = points
        .par_iter()
        .map(|p| {
            let nearest = sample_neighbours.nearest_k(p, neighbours);
            let first = nearest.first()?;
            let sample = first.index;
            let distance = first.distance();
            if !parts[sample].is_plant() || distance > gate {
                return None;
            }
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
            Some((to_plane.min(distance), sample))
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
