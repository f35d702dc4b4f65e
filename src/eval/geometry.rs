//! Geometric error measures between surfaces and skeletons.

use nalgebra::Point3;

use super::{SkeletonRecord, SkeletonScores};
use crate::branch::spline::point_segment_distance;
use crate::mesh::{TriMesh, point_triangle_distance};
use crate::util::rng::Rng;

/// Exact distance from `p` to the surface of `mesh` (brute force over triangles with a
/// bounding-sphere cull; leaf meshes have a few hundred triangles).
pub fn distance_to_mesh(p: &Point3<f32>, mesh: &TriMesh, spheres: &[(Point3<f32>, f32)]) -> f32 {
    let mut best = f32::INFINITY;
    for (t, &(center, radius)) in spheres.iter().enumerate() {
        if (p - center).norm() - radius >= best {
            continue;
        }
        let [a, b, c] = mesh.corners(t);
        best = best.min(point_triangle_distance(p, &a, &b, &c));
    }
    best
}

pub(crate) fn bounding_spheres(mesh: &TriMesh) -> Vec<(Point3<f32>, f32)> {
    (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            let center = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let radius = [a, b, c]
                .iter()
                .map(|p| (p - center).norm())
                .fold(0.0, f32::max);
            (center, radius)
        })
        .collect()
}

/// Symmetric Chamfer distance ½(mean d(a→B) + mean d(b→A)) between two surfaces, from
/// `samples` area-weighted samples of each; `None` if either surface is empty.
pub fn symmetric_chamfer(a: &TriMesh, b: &TriMesh, samples: usize, seed: u64) -> Option<f64> {
    if a.area() <= 0.0 || b.area() <= 0.0 {
        return None;
    }
    let mut rng = Rng::seed_from(seed);
    let spheres_a = bounding_spheres(a);
    let spheres_b = bounding_spheres(b);
    let one_way = |from: &TriMesh, to: &TriMesh, spheres: &[(Point3<f32>, f32)], rng: &mut Rng| {
        let points = from.sample_surface(samples, rng);
        points
            .iter()
            .map(|s| distance_to_mesh(&s.position, to, spheres) as f64)
            .sum::<f64>()
            / points.len().max(1) as f64
    };
    let ab = one_way(a, b, &spheres_b, &mut rng);
    let ba = one_way(b, a, &spheres_a, &mut rng);
    Some(0.5 * (ab + ba))
}

/// Angle between the area-weighted mean normals of two surfaces, ignoring orientation
/// (a leaf seen from below is the same leaf), degrees.
pub fn normal_angle_deg(a: &TriMesh, b: &TriMesh) -> f64 {
    let (na, nb) = (a.mean_normal(), b.mean_normal());
    let cosine = na.dot(&nb).abs().clamp(0.0, 1.0) as f64;
    cosine.acos().to_degrees()
}

/// Distance from `p` to a set of polylines.
fn distance_to_polylines(p: &Point3<f64>, lines: &[Vec<Point3<f64>>]) -> f64 {
    lines
        .iter()
        .flat_map(|line| {
            line.windows(2)
                .map(|w| point_segment_distance(p, &w[0], &w[1]))
        })
        .fold(f64::INFINITY, f64::min)
}

/// Scores a predicted skeleton against the GT branches (see [`SkeletonScores`]).
pub fn score_skeleton(gt: &[SkeletonRecord], predicted: &[SkeletonRecord]) -> SkeletonScores {
    let lines: Vec<Vec<Point3<f64>>> = predicted
        .iter()
        .map(|b| b.centerline.iter().map(|c| Point3::from(*c)).collect())
        .collect();
    let stem_distance_in_radii = gt.iter().find(|b| b.parent.is_none()).and_then(|stem| {
        if lines.is_empty() || stem.centerline.is_empty() {
            return None;
        }
        let mean = stem
            .centerline
            .iter()
            .map(|c| distance_to_polylines(&Point3::from(*c), &lines))
            .sum::<f64>()
            / stem.centerline.len() as f64;
        Some(mean / stem.mean_radius().max(1e-9))
    });
    let eligible: Vec<&SkeletonRecord> = gt
        .iter()
        .filter(|b| b.centerline_length() > 10.0 * b.mean_radius())
        .collect();
    let matched = eligible
        .iter()
        .filter(|b| {
            let tolerance = (2.0 * b.mean_radius()).max(0.003);
            let close = b
                .centerline
                .iter()
                .filter(|c| distance_to_polylines(&Point3::from(**c), &lines) <= tolerance)
                .count();
            !b.centerline.is_empty() && close as f64 >= 0.8 * b.centerline.len() as f64
        })
        .count();
    SkeletonScores {
        stem_distance_in_radii,
        eligible_branches: eligible.len(),
        matched_branches: matched,
        branch_recall: if eligible.is_empty() {
            0.0
        } else {
            matched as f64 / eligible.len() as f64
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn plate(offset_z: f32, size: f32) -> TriMesh {
        let mut mesh = TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, offset_z),
                Point3::new(size, 0.0, offset_z),
                Point3::new(size, size, offset_z),
                Point3::new(0.0, size, offset_z),
            ],
            normals: Vec::new(),
            uvs: vec![[0.0; 2]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        mesh.compute_normals();
        mesh
    }

    #[test]
    fn chamfer_of_a_surface_with_itself_is_zero_and_of_a_shifted_copy_is_the_shift() {
        let a = plate(0.0, 1.0);
        assert!(symmetric_chamfer(&a, &a, 500, 1).unwrap() < 1e-6);
        let b = plate(0.05, 1.0);
        let d = symmetric_chamfer(&a, &b, 500, 1).unwrap();
        assert!((d - 0.05).abs() < 1e-5, "{d}");
    }

    #[test]
    fn normal_angle_ignores_orientation() {
        let a = plate(0.0, 1.0);
        let mut flipped = a.clone();
        for t in &mut flipped.triangles {
            t.swap(1, 2);
        }
        assert!(normal_angle_deg(&a, &flipped) < 1e-3);
        let mut tilted = a.clone();
        let rotation = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.5);
        for p in &mut tilted.positions {
            *p = rotation * *p;
        }
        assert!((normal_angle_deg(&a, &tilted) - 0.5f64.to_degrees()).abs() < 1e-3);
    }

    #[test]
    fn skeleton_scores_a_perfect_and_a_shifted_prediction() {
        let stem = SkeletonRecord {
            id: 0,
            parent: None,
            parent_fraction: 0.0,
            control_points: Vec::new(),
            radius_start: 0.01,
            radius_end: 0.01,
            length: 0.49,
            centerline: (0..50).map(|k| [0.0, 0.0, k as f64 * 0.01]).collect(),
        };
        let gt = vec![stem.clone()];
        let perfect = score_skeleton(&gt, &gt);
        assert!(perfect.stem_distance_in_radii.unwrap() < 1e-9);
        assert_eq!(perfect.branch_recall, 1.0);
        let mut shifted = stem;
        for c in &mut shifted.centerline {
            c[0] += 0.05;
        }
        let scores = score_skeleton(&gt, &[shifted]);
        assert!((scores.stem_distance_in_radii.unwrap() - 5.0).abs() < 1e-6);
        assert_eq!(scores.matched_branches, 0);
    }
}
