//! Geometric error measures between surfaces and skeletons.

use nalgebra::Point3;

use std::collections::BTreeSet;

use super::{
    GtLeafRecord, LabelledPoints, OffPlantLength, PredictedBranchScore, SkeletonLengthScores,
    SkeletonRecord, SkeletonScores,
};
use crate::branch::spline::point_segment_distance;
use crate::graph::neighbours::Neighbours;
use crate::mesh::{TriMesh, point_triangle_distance};
use crate::synth::scene::Part;
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

/// Per triangle of `mesh`: its centroid and the radius of the sphere about it holding the
/// triangle (the cull of [`distance_to_mesh`]).
pub fn bounding_spheres(mesh: &TriMesh) -> Vec<(Point3<f32>, f32)> {
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
pub(crate) fn distance_to_polylines(p: &Point3<f64>, lines: &[Vec<Point3<f64>>]) -> f64 {
    lines
        .iter()
        .flat_map(|line| {
            line.windows(2)
                .map(|w| point_segment_distance(p, &w[0], &w[1]))
        })
        .fold(f64::INFINITY, f64::min)
}

/// The true branches that are petioles: each carries a leaf and has no child branch. When no
/// leaf record names its branch, every branch without children other than the root.
pub fn petiole_ids(gt: &[SkeletonRecord], leaves: &[(GtLeafRecord, TriMesh)]) -> BTreeSet<u32> {
    let parents: BTreeSet<u32> = gt.iter().filter_map(|b| b.parent).collect();
    let bearing: BTreeSet<u32> = leaves.iter().filter_map(|(r, _)| r.branch).collect();
    gt.iter()
        .filter(|b| b.parent.is_some() && !parents.contains(&b.id))
        .filter(|b| bearing.is_empty() || bearing.contains(&b.id))
        .map(|b| b.id)
        .collect()
}

/// A polyline cut into pieces no longer than `step`: (midpoint, length) of each.
fn pieces(line: &[[f64; 3]], step: f64) -> Vec<(Point3<f64>, f64)> {
    let mut out = Vec::new();
    for w in line.windows(2) {
        let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
        let length = (b - a).norm();
        if !length.is_finite() || length <= 0.0 {
            continue;
        }
        let n = (length / step).ceil().max(1.0) as usize;
        for k in 0..n {
            let t = (k as f64 + 0.5) / n as f64;
            out.push((a + (b - a) * t, length / n as f64));
        }
    }
    out
}

/// The true surfaces an off-plant piece of skeleton may lie on: the ground truth's surface
/// samples with their parts (points without a part are left out).
pub struct TrueSurfaces {
    samples: Option<Neighbours>,
    parts: Vec<Part>,
}

impl TrueSurfaces {
    pub fn new(samples: &LabelledPoints) -> Self {
        let (positions, parts): (Vec<Point3<f64>>, Vec<Part>) = match &samples.parts {
            Some(parts) => samples
                .positions
                .iter()
                .copied()
                .zip(parts.iter().copied())
                .unzip(),
            None => (Vec::new(), Vec::new()),
        };
        let samples = (!positions.is_empty())
            .then(|| Neighbours::new(positions).ok())
            .flatten();
        Self { samples, parts }
    }

    /// No surfaces: every off-plant piece counts as `elsewhere`.
    pub fn none() -> Self {
        Self {
            samples: None,
            parts: Vec::new(),
        }
    }

    /// The part of the nearest sample within [`OffPlantLength::NEAR`] of `p`.
    fn part_near(&self, p: &Point3<f64>) -> Option<Part> {
        let nearest = self.samples.as_ref()?.nearest(p)?;
        (nearest.distance() <= OffPlantLength::NEAR)
            .then(|| self.parts.get(nearest.index).copied())
            .flatten()
    }
}

/// Length-weighted recall (branches and petioles apart) and precision of a predicted skeleton
/// (see [`SkeletonLengthScores`]); the length off the plant is told apart by the true surface
/// it lies near.
pub fn skeleton_length_scores(
    gt: &[SkeletonRecord],
    petioles: &BTreeSet<u32>,
    predicted: &[SkeletonRecord],
    surfaces: &TrueSurfaces,
) -> SkeletonLengthScores {
    const STEP: f64 = 0.001;
    let tolerance = |b: &SkeletonRecord| (2.0 * b.mean_radius()).max(0.003);
    let predicted_lines: Vec<Vec<Point3<f64>>> = predicted
        .iter()
        .map(|b| b.centerline.iter().map(|c| Point3::from(*c)).collect())
        .collect();
    let (mut found, mut total) = ([0.0; 2], [0.0; 2]);
    for branch in gt {
        let class = usize::from(petioles.contains(&branch.id));
        let limit = tolerance(branch);
        for (p, length) in pieces(&branch.centerline, STEP) {
            total[class] += length;
            if distance_to_polylines(&p, &predicted_lines) <= limit {
                found[class] += length;
            }
        }
    }
    let true_lines: Vec<(Vec<Point3<f64>>, f64)> = gt
        .iter()
        .map(|b| {
            let line = b.centerline.iter().map(|c| Point3::from(*c)).collect();
            (line, tolerance(b))
        })
        .collect();
    let (mut on, mut predicted_length) = (0.0, 0.0);
    let mut off_plant = OffPlantLength::default();
    let mut per_branch = Vec::with_capacity(predicted.len());
    for branch in predicted {
        let (mut branch_on, mut branch_length) = (0.0, 0.0);
        for (p, length) in pieces(&branch.centerline, STEP) {
            branch_length += length;
            let near = true_lines.iter().any(|(line, limit)| {
                line.windows(2)
                    .any(|w| point_segment_distance(&p, &w[0], &w[1]) <= *limit)
            });
            if near {
                branch_on += length;
            } else {
                match surfaces.part_near(&p) {
                    Some(Part::Leaf) => off_plant.on_leaves += length,
                    Some(Part::Stem) => off_plant.beside_stems += length,
                    Some(Part::Pot) => off_plant.on_pot += length,
                    _ => off_plant.elsewhere += length,
                }
            }
        }
        predicted_length += branch_length;
        on += branch_on;
        per_branch.push(PredictedBranchScore {
            id: branch.id,
            parent: branch.parent,
            length: branch_length,
            on_plant_length: branch_on,
            bridged_length: branch.bridged_length,
        });
    }
    let share = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    SkeletonLengthScores {
        true_branch_length: total[0],
        true_petiole_length: total[1],
        predicted_length,
        branch_recall: share(found[0], total[0]),
        petiole_recall: share(found[1], total[1]),
        precision: share(on, predicted_length),
        predicted_branches: per_branch,
        off_plant,
    }
}

/// Scores a predicted skeleton against the GT branches (see [`SkeletonScores`]); `petioles`
/// are the true branches scored as petioles (see [`petiole_ids`]).
pub fn score_skeleton(
    gt: &[SkeletonRecord],
    petioles: &BTreeSet<u32>,
    predicted: &[SkeletonRecord],
    surfaces: &TrueSurfaces,
) -> SkeletonScores {
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
        with_drawn_petioles: None,
        stem_distance_in_radii,
        eligible_branches: eligible.len(),
        matched_branches: matched,
        branch_recall: if eligible.is_empty() {
            0.0
        } else {
            matched as f64 / eligible.len() as f64
        },
        length: skeleton_length_scores(gt, petioles, predicted, surfaces),
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
            observed_length: None,
            bridged_length: None,
        };
        let gt = vec![stem.clone()];
        let none = BTreeSet::new();
        let perfect = score_skeleton(&gt, &none, &gt, &TrueSurfaces::none());
        assert!(perfect.stem_distance_in_radii.unwrap() < 1e-9);
        assert_eq!(perfect.branch_recall, 1.0);
        assert!((perfect.length.branch_recall - 1.0).abs() < 1e-9);
        assert!((perfect.length.precision - 1.0).abs() < 1e-9);
        assert!((perfect.length.true_branch_length - 0.49).abs() < 1e-9);
        let mut shifted = stem;
        for c in &mut shifted.centerline {
            c[0] += 0.05;
        }
        let scores = score_skeleton(&gt, &none, &[shifted], &TrueSurfaces::none());
        assert!((scores.stem_distance_in_radii.unwrap() - 5.0).abs() < 1e-6);
        assert_eq!(scores.matched_branches, 0);
        assert_eq!(scores.length.branch_recall, 0.0);
        assert_eq!(scores.length.precision, 0.0);
    }

    fn record(id: u32, parent: Option<u32>, radius: f64, line: Vec<[f64; 3]>) -> SkeletonRecord {
        SkeletonRecord {
            id,
            parent,
            parent_fraction: 1.0,
            control_points: Vec::new(),
            radius_start: radius,
            radius_end: radius,
            length: 0.0,
            centerline: line,
            observed_length: None,
            bridged_length: None,
        }
    }

    #[test]
    fn length_scores_keep_petioles_apart_and_charge_a_pot_rim_to_precision() {
        // A 0.3 m stem, a 0.2 m petiole leaving its top sideways, a 0.1 m twig with a child.
        let stem = record(
            0,
            None,
            0.004,
            (0..=30).map(|k| [0.0, 0.0, k as f64 * 0.01]).collect(),
        );
        let petiole = record(
            1,
            Some(0),
            0.002,
            (0..=20).map(|k| [k as f64 * 0.01, 0.0, 0.3]).collect(),
        );
        let twig = record(
            2,
            Some(0),
            0.002,
            (0..=10).map(|k| [0.0, k as f64 * 0.01, 0.2]).collect(),
        );
        let twig_child = record(
            3,
            Some(2),
            0.001,
            (0..=5).map(|k| [0.0, 0.1, 0.2 + k as f64 * 0.01]).collect(),
        );
        let gt = vec![stem.clone(), petiole, twig, twig_child];
        let leaves = vec![
            (
                GtLeafRecord {
                    id: 0,
                    length: 0.1,
                    area: 0.01,
                    mesh: String::new(),
                    branch: Some(1),
                    compound_leaf: None,
                },
                TriMesh::default(),
            ),
            (
                GtLeafRecord {
                    id: 1,
                    length: 0.1,
                    area: 0.01,
                    mesh: String::new(),
                    branch: Some(3),
                    compound_leaf: None,
                },
                TriMesh::default(),
            ),
        ];
        let petioles = petiole_ids(&gt, &leaves);
        assert_eq!(petioles.into_iter().collect::<Vec<_>>(), vec![1, 3]);
        // Without leaf records every childless non-root branch is a petiole.
        assert_eq!(
            petiole_ids(&gt, &[]).into_iter().collect::<Vec<_>>(),
            vec![1, 3]
        );
        let petioles = petiole_ids(&gt, &leaves);
        // The prediction: the stem 2 mm off axis and a pot rim (a circle of radius 0.1 m at
        // the floor), nothing else.
        let rim = record(
            9,
            None,
            0.003,
            (0..=64)
                .map(|k| {
                    let a = k as f64 / 64.0 * std::f64::consts::TAU;
                    [0.1 * a.cos(), 0.1 * a.sin(), -0.05]
                })
                .collect(),
        );
        let mut off = stem;
        for c in &mut off.centerline {
            c[0] += 0.002;
        }
        // The true surfaces: the pot's rim sampled every millimetre, 1 mm below the drawn rim.
        let rim_samples: Vec<Point3<f64>> = (0..628)
            .map(|k| {
                let a = k as f64 / 628.0 * std::f64::consts::TAU;
                Point3::new(0.1 * a.cos(), 0.1 * a.sin(), -0.051)
            })
            .collect();
        let surfaces = TrueSurfaces::new(&LabelledPoints {
            parts: Some(vec![Part::Pot; rim_samples.len()]),
            leaf_ids: vec![-1; rim_samples.len()],
            point_ids: None,
            positions: rim_samples,
        });
        let scores = skeleton_length_scores(&gt, &petioles, &[off, rim.clone()], &surfaces);
        // Branch length is stem + twig = 0.4 m; the stem (0.3 m) is found. Petioles 0.25 m,
        // none found except where the petiole leaves the stem (within 3 mm of it).
        assert!((scores.true_branch_length - 0.4).abs() < 1e-9);
        assert!((scores.true_petiole_length - 0.25).abs() < 1e-9);
        assert!((scores.branch_recall - 0.75).abs() < 0.01, "{scores:?}");
        assert!(scores.petiole_recall < 0.03, "{scores:?}");
        let rim_length = rim.centerline_length();
        let expected = 0.3 / (0.3 + rim_length);
        assert!(
            (scores.precision - expected).abs() < 0.01,
            "{scores:?} vs {expected}"
        );
        // Each predicted branch's share: the stem lies on the plant, the rim nowhere near it.
        let by_id = |id: u32| {
            scores
                .predicted_branches
                .iter()
                .find(|b| b.id == id)
                .unwrap_or_else(|| panic!("branch {id} missing: {scores:?}"))
        };
        let (stem_score, rim_score) = (by_id(0), by_id(9));
        assert!((stem_score.length - 0.3).abs() < 1e-6, "{stem_score:?}");
        assert!(
            (stem_score.on_plant_length - 0.3).abs() < 1e-6,
            "{stem_score:?}"
        );
        assert!(
            (rim_score.length - rim_length).abs() < 1e-6,
            "{rim_score:?}"
        );
        assert_eq!(rim_score.on_plant_length, 0.0, "{rim_score:?}");
        // The length off the plant is the rim's, and it lies on the pot.
        let off_plant = &scores.off_plant;
        assert!(
            (off_plant.on_pot - rim_length).abs() < 1e-6,
            "{off_plant:?}"
        );
        assert_eq!(off_plant.on_leaves + off_plant.beside_stems, 0.0);
        assert_eq!(off_plant.elsewhere, 0.0);
        // Without the surfaces the same length is counted elsewhere.
        let blind = skeleton_length_scores(
            &gt,
            &petioles,
            std::slice::from_ref(&rim),
            &TrueSurfaces::none(),
        );
        assert!((blind.off_plant.elsewhere - rim_length).abs() < 1e-6);
        let total: f64 = scores.predicted_branches.iter().map(|b| b.length).sum();
        assert!((total - scores.predicted_length).abs() < 1e-9);
    }
}
