//! Whether a scene's points are dense enough for the leaf graph (seed 004 §5.1 needs leaves
//! sampled by many points), measured in the photos' own scale: the sample spacing around each
//! point, in pixel footprints (the world size of one pixel at the point's depth in a view that
//! sees it), median over the points. The spacing is estimated from the radius `r` holding a
//! point's 8 nearest neighbours as `r·√(π/8)` (a surface sampled every `s` holds 8 points
//! within `s·√(8/π)`): it measures coverage, where the nearest neighbour alone would be fooled
//! by SfM's points, which cluster on texture. Takes a scene; returns a [`PointDensity`] with
//! the decision.

use serde::{Deserialize, Serialize};

use crate::graph::neighbours::Neighbours;
use crate::graph::points::PointSet;
use crate::scene::Scene;

/// Points farther apart than this many pixel footprints (median) are too sparse for the leaf
/// graph: such a scene is densified first when its photos are there. Measured: Frond's
/// semi-dense stereo 1.3 footprints; synthetic semi-dense datasets 1.8–3.4 (8–16 views,
/// 8,000–30,000 points); COLMAP's sparse points 17 (24 synthetic photos of a broadleaf) and
/// 43 (the real figurine in `../shared/data`). The threshold sits between, nearer the dense
/// side, since densifying a usable scene only costs time while segmenting a sparse one finds
/// no plant.
pub const MAX_SPACING_FOOTPRINTS: f64 = 6.0;

/// Neighbours whose radius estimates the spacing.
const NEIGHBOURS: usize = 8;

/// At most this many points are measured (an even stride through the set).
const SAMPLES: usize = 20_000;

/// How densely a scene's points sample its surfaces, and what follows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointDensity {
    pub points: usize,
    /// Median sample spacing in pixel footprints (NaN without enough points seen by a
    /// camera).
    pub spacing_footprints: f64,
    pub threshold_footprints: f64,
    /// Whether the scene has dense points (`fused.ply`) already.
    pub has_dense_points: bool,
    /// The points are too sparse for the leaf graph.
    pub too_sparse: bool,
}

/// Measures the scene's point spacing (see the module docs).
pub fn point_density(scene: &Scene) -> PointDensity {
    // The points the segmentation works on (gap fills are the leaf stage's).
    let (points, _) = PointSet::from_scene(scene).split_gap_fills();
    let spacing_footprints = median_spacing_footprints(scene, &points);
    PointDensity {
        points: points.len(),
        spacing_footprints,
        threshold_footprints: MAX_SPACING_FOOTPRINTS,
        has_dense_points: scene
            .dense
            .as_ref()
            .is_some_and(|d| !d.visible_in.is_empty()),
        // Fewer than two points measure as NaN: nothing to segment, so too sparse.
        too_sparse: spacing_footprints.is_nan() || spacing_footprints > MAX_SPACING_FOOTPRINTS,
    }
}

/// The median over (a stride of) the points of the estimated spacing divided by the pixel
/// footprint in the first view that sees the point in front of it.
fn median_spacing_footprints(scene: &Scene, points: &PointSet) -> f64 {
    let model = &scene.reconstruction;
    let images = model.images();
    spacing_in_footprints(&points.positions, |i| {
        points.views[i].iter().find_map(|&view| {
            let image = images.get(view as usize)?;
            let depth = (image.camera_from_world * points.positions[i]).z;
            let focal = model.camera_of(image).mean_focal();
            (depth > 0.0 && focal > 0.0).then(|| depth / focal)
        })
    })
}

/// The median of `r₈·√(π/8) / footprint(i)` over (a stride of) the points with a footprint;
/// NaN when there are too few.
fn spacing_in_footprints(
    positions: &[nalgebra::Point3<f64>],
    footprint: impl Fn(usize) -> Option<f64>,
) -> f64 {
    let n = positions.len();
    if n <= NEIGHBOURS {
        return f64::NAN;
    }
    let Ok(neighbours) = Neighbours::new(positions.iter().copied()) else {
        return f64::NAN;
    };
    let stride = n.div_ceil(SAMPLES).max(1);
    let mut ratios: Vec<f64> = (0..n)
        .step_by(stride)
        .filter_map(|i| {
            let footprint = footprint(i)?;
            let radius = neighbours
                .around(i, NEIGHBOURS)
                .into_iter()
                .filter(|r| r.index != i)
                .nth(NEIGHBOURS - 1)?
                .distance();
            Some(radius * (std::f64::consts::PI / NEIGHBOURS as f64).sqrt() / footprint)
        })
        .collect();
    crate::util::stats::quantile(&mut ratios, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn a_regular_grid_measures_its_spacing_in_footprints() {
        // A 60×60 grid 1 cm apart, 2 mm per pixel: 5 footprints (the square grid's eighth
        // neighbour sits at √2 spacings, so the estimate reads 0.89 of it).
        let grid: Vec<Point3<f64>> = (0..3600)
            .map(|k| Point3::new((k % 60) as f64 * 0.01, (k / 60) as f64 * 0.01, 0.0))
            .collect();
        let measured = spacing_in_footprints(&grid, |_| Some(0.002));
        assert!((4.0..5.5).contains(&measured), "{measured}");
        // Twice the footprint (twice as far away): half as many footprints.
        let far = spacing_in_footprints(&grid, |_| Some(0.004));
        assert!((far - measured / 2.0).abs() < 1e-9, "{far} vs {measured}");
    }

    #[test]
    fn clustered_points_read_as_sparse_although_their_nearest_neighbours_are_close() {
        // Triples 0.5 mm apart (features on texture), triples 5 cm apart: the nearest
        // neighbour is a quarter footprint away, but the surface is covered every 5 cm.
        let mut clustered = Vec::new();
        for k in 0..400 {
            let centre = Point3::new((k % 20) as f64 * 0.05, (k / 20) as f64 * 0.05, 0.0);
            for j in 0..3 {
                clustered.push(centre + nalgebra::Vector3::new(j as f64 * 0.0005, 0.0, 0.0));
            }
        }
        let measured = spacing_in_footprints(&clustered, |_| Some(0.002));
        assert!(measured > MAX_SPACING_FOOTPRINTS, "{measured}");
        assert!(spacing_in_footprints(&clustered[..5], |_| Some(0.002)).is_nan());
    }
}
