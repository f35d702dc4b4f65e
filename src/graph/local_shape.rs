//! Local shape of the surface around each point, from the principal components of its k
//! nearest neighbours: how thick (`√(λ₃/λ₂)`) and how elongated (`√(λ₂/λ₁)`) the neighbourhood
//! is. Points on a leaf have flat neighbourhoods; points on a thin stem or petiole have
//! neighbourhoods that wrap around it: thick and elongated.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::points::PointSet;
use super::shape::Shape;

/// Local shape features of one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalShape {
    /// `√(λ₃/λ₂)`: 0 on a flat sheet, near 1 on a round blob or thin tube.
    pub thickness: f64,
    /// `√(λ₂/λ₁)`: near 0 along a line, near 1 on an isotropic patch.
    pub elongation: f64,
    pub normal: nalgebra::Vector3<f64>,
}

/// Local shapes of every point from its `k` nearest neighbours (itself included).
pub fn local_shapes(points: &PointSet, k: usize) -> Vec<LocalShape> {
    let coordinates: Vec<[f64; 3]> = points.positions.iter().map(|p| [p.x, p.y, p.z]).collect();
    let fallback = LocalShape {
        thickness: 0.0,
        elongation: 1.0,
        normal: nalgebra::Vector3::z(),
    };
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&coordinates) else {
        return vec![fallback; points.len()];
    };
    let Some(wanted) = std::num::NonZero::new((k + 1).min(points.len())) else {
        return Vec::new();
    };
    coordinates
        .par_iter()
        .map(|c| {
            let neighbours = tree
                .query(c)
                .nearest_n::<SquaredEuclidean<f64>>(wanted)
                .execute();
            let shape = Shape::of(neighbours.iter().map(|r| points.positions[r.item as usize]));
            if shape.count < 4 {
                return fallback;
            }
            LocalShape {
                thickness: shape.flatness(),
                elongation: shape.width_ratio(),
                normal: shape.normal(),
            }
        })
        .collect()
}
