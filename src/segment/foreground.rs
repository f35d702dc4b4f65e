//! Foreground separation: which points belong to the plant.
//!
//! Seed 004 keeps the largest connected component in front of the cameras, which still holds
//! pot and floor. Here the floor (the dominant plane facing the cameras' up direction, found by
//! RANSAC), walls (further dominant planes far from the plant) and the background (far from the
//! plant's vertical axis) are labelled per point; small isolated clusters are outliers. The pot
//! stays in the foreground and is labelled later from its segments' shape.

use crate::util::geometry::distance_from_axis;
use nalgebra::{Point3, Vector3};
use serde::Serialize;

use crate::graph::components::Adjacency;
use crate::graph::knn_pairs;
use crate::graph::local_shape;
use crate::graph::neighbours::Neighbours;
use crate::graph::points::PointSet;
use crate::scene::Reconstruction;
use crate::util::geometry::closest_point_to_lines;
use crate::util::rng::Rng;
use crate::util::stats::median;

/// What a point was found to be before segmentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PointClass {
    Plant,
    /// On a thin tube (stem, petiole, twig): its neighbourhood wraps around an axis.
    Stem,
    Floor,
    Wall,
    Background,
    Outlier,
}

/// A plane `n·x = d` with unit normal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Plane {
    pub normal: Vector3<f64>,
    pub offset: f64,
}

impl Plane {
    pub fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) - self.offset
    }

    /// Least-squares plane through points.
    fn fit(points: &[Point3<f64>]) -> Option<Self> {
        let shape = crate::graph::shape::Shape::of(points.iter().copied());
        (shape.count >= 3).then(|| Self {
            normal: shape.normal(),
            offset: shape.normal().dot(&shape.centroid.coords),
        })
    }
}

/// Parameters of the separation.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, serde::Deserialize)]
pub struct ForegroundOptions {
    pub ransac_iterations: usize,
    /// A plane must hold this fraction of the points to count as floor or wall.
    pub min_plane_fraction: f64,
    /// Points beyond this fraction of the cameras' horizontal distance from the plant's axis
    /// are background.
    pub max_radius_fraction: f64,
    /// Connected clusters smaller than this are outliers.
    pub min_cluster_points: usize,
    /// Neighbours over which the normal coherence that tells stems from leaves is measured.
    pub stem_neighbours: usize,
    /// A point is on a stem when the median `|n_i · n_p|` of its neighbours' normals is below
    /// this (see [`crate::graph::local_shape::normal_coherence`]) and below what a flat sheet
    /// with the points' spacing and noise reaches (see `max_flat_stem_share`).
    pub max_stem_coherence: f64,
    /// The share of a flat sheet's points, sampled with the measured spacing and noise, that
    /// the stem test may call stem ([`crate::graph::local_shape::FlatSheet::coherence`]):
    /// where the noise is large against the spacing the threshold drops below
    /// `max_stem_coherence`, so small noisy leaves are not taken for stems.
    #[serde(default = "default_max_flat_stem_share")]
    pub max_flat_stem_share: f64,
    pub seed: u64,
}

impl Default for ForegroundOptions {
    fn default() -> Self {
        Self {
            ransac_iterations: 600,
            min_plane_fraction: 0.03,
            max_radius_fraction: 0.6,
            min_cluster_points: 30,
            stem_neighbours: 20,
            max_stem_coherence: 0.9,
            max_flat_stem_share: default_max_flat_stem_share(),
            seed: 1,
        }
    }
}

fn default_max_flat_stem_share() -> f64 {
    0.05
}

/// Normals of the stem test come from this many neighbours.
const STEM_NORMAL_NEIGHBOURS: usize = 8;

/// The result: a class per point and the geometry found.
#[derive(Clone, Debug, Serialize)]
pub struct Foreground {
    pub class: Vec<PointClass>,
    /// Up direction (floor normal when a floor was found, else the cameras' mean up).
    pub up: Vector3<f64>,
    pub floor: Option<Plane>,
    pub walls: Vec<Plane>,
    /// Point the cameras look at (least-squares intersection of their optical axes).
    pub plant_center: Point3<f64>,
    /// Horizontal radius beyond which points are background.
    pub radius_limit: f64,
}

/// Why no plant could be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ForegroundError {
    #[error("the model has no registered images")]
    NoCameras,
    #[error("the model has no 3D points")]
    NoPoints,
    #[error("no plant in front of the cameras: {0}")]
    NoPlant(String),
}

/// RANSAC for a dominant plane among `candidates`: hypotheses are least-squares planes through
/// a random point and its 16 nearest neighbours (a hypothesis lands on a plane holding a
/// fraction p of the points with probability p, not p³ as with random triples), scored on a
/// subsample by the number of points within `tolerance`; `accept` filters hypotheses (normal
/// direction, which side the scene lies on).
fn ransac_plane(
    points: &[Point3<f64>],
    candidates: &[usize],
    tolerance: f64,
    iterations: usize,
    accept: impl Fn(&Plane) -> bool,
    rng: &mut Rng,
) -> Option<(Plane, Vec<usize>)> {
    if candidates.len() < 20 {
        return None;
    }
    let neighbours = Neighbours::new(candidates.iter().map(|&i| points[i])).ok()?;
    let hypothesis_points = std::num::NonZero::new(17usize.min(candidates.len()))?;
    let sample: Vec<usize> = (0..candidates.len().min(6000))
        .map(|_| candidates[rng.below(candidates.len())])
        .collect();
    let mut best: Option<(Plane, usize)> = None;
    for _ in 0..iterations {
        let seed = rng.below(candidates.len());
        let local: Vec<Point3<f64>> = neighbours
            .nearest_k(&points[candidates[seed]], hypothesis_points)
            .iter()
            .map(|r| points[candidates[r.index]])
            .collect();
        let Some(plane) = Plane::fit(&local) else {
            continue;
        };
        if !accept(&plane) {
            continue;
        }
        let inliers = sample
            .iter()
            .filter(|&&i| plane.signed_distance(&points[i]).abs() < tolerance)
            .count();
        if best.is_none_or(|(_, n)| inliers > n) {
            best = Some((plane, inliers));
        }
    }
    let (plane, _) = best?;
    Some(refine_plane(points, candidates, plane, tolerance, accept))
}

/// Local optimisation of a RANSAC plane: refit on all its inliers among `candidates` and
/// recollect them, again while that gains inliers. A hypothesis fitted to a few noisy
/// neighbours may be tilted by a degree or two; its inlier band then crosses the true plane,
/// and the refits turn it into that plane. (With a single refit, photos of a medium plant gave
/// a floor of 78k points on one run and of 286k on another, from nearly the same points.)
fn refine_plane(
    points: &[Point3<f64>],
    candidates: &[usize],
    mut plane: Plane,
    tolerance: f64,
    accept: impl Fn(&Plane) -> bool,
) -> (Plane, Vec<usize>) {
    let members_of = |plane: &Plane| -> Vec<usize> {
        candidates
            .iter()
            .copied()
            .filter(|&i| plane.signed_distance(&points[i]).abs() < tolerance)
            .collect()
    };
    let mut members = members_of(&plane);
    for round in 0..MAX_REFITS {
        let inliers: Vec<Point3<f64>> = members.iter().map(|&i| points[i]).collect();
        let Some(mut refined) = Plane::fit(&inliers) else {
            break;
        };
        if refined.normal.dot(&plane.normal) < 0.0 {
            refined.normal = -refined.normal;
            refined.offset = -refined.offset;
        }
        if !accept(&refined) {
            break;
        }
        let refined_members = members_of(&refined);
        // The first refit is taken as it is (a least-squares plane of the inliers); later ones
        // only while they gain.
        if round > 0 && refined_members.len() <= members.len() {
            break;
        }
        plane = refined;
        members = refined_members;
    }
    (plane, members)
}

/// Refits of a RANSAC plane on its inliers ([`ransac_plane`]).
const MAX_REFITS: usize = 10;

/// Labels every point (see the module docs).
pub fn separate_foreground(
    points: &PointSet,
    model: &Reconstruction,
    options: &ForegroundOptions,
) -> Result<Foreground, ForegroundError> {
    if points.is_empty() {
        return Err(ForegroundError::NoPoints);
    }
    let images = model.images();
    if images.is_empty() {
        return Err(ForegroundError::NoCameras);
    }
    let centers: Vec<Point3<f64>> = images.iter().map(|i| i.center_world()).collect();
    let axes: Vec<(Point3<f64>, Vector3<f64>)> = images
        .iter()
        .map(|i| (i.center_world(), i.view_direction_world()))
        .collect();
    let mut camera_up = images
        .iter()
        .map(|i| i.camera_from_world.rotation.inverse() * -Vector3::y())
        .sum::<Vector3<f64>>();
    camera_up = camera_up.try_normalize(1e-9).unwrap_or_else(Vector3::z);
    let look_at = closest_point_to_lines(&axes).unwrap_or_else(|| {
        Point3::from(
            points
                .positions
                .iter()
                .map(|p| p.coords)
                .sum::<Vector3<f64>>()
                / points.len() as f64,
        )
    });
    let camera_distance = median(centers.iter().map(|c| (c - look_at).norm())).unwrap_or(0.0);

    // Scale of the point spacing: median nearest-neighbour distance.
    let pairs = knn_pairs(points, 1);
    let spacing = median(
        pairs
            .iter()
            .map(|&(a, b)| (points.positions[a as usize] - points.positions[b as usize]).norm()),
    )
    .unwrap_or(0.0);
    let tolerance = (3.0 * spacing).max(0.004 * camera_distance);
    let mut rng = Rng::seed_from(options.seed);
    let n = points.len();
    let mut class = vec![PointClass::Plant; n];
    let min_plane = ((options.min_plane_fraction * n as f64) as usize).max(3);
    let all: Vec<usize> = (0..n).collect();

    // Floor: the largest plane within 30° of the cameras' up that has the cameras and nearly
    // all points on one side (a plane through the plant splits its points).
    let subsample: Vec<usize> = (0..n.min(4000)).map(|_| rng.below(n)).collect();
    let oriented = |plane: &Plane| {
        let mut plane = *plane;
        let camera_side = centers
            .iter()
            .map(|c| plane.signed_distance(c))
            .sum::<f64>();
        if camera_side < 0.0 {
            plane.normal = -plane.normal;
            plane.offset = -plane.offset;
        }
        plane
    };
    let supports_scene = |plane: &Plane| {
        let plane = oriented(plane);
        let below = subsample
            .iter()
            .filter(|&&i| plane.signed_distance(&points.positions[i]) < -tolerance)
            .count();
        plane.normal.dot(&camera_up) > 30f64.to_radians().cos()
            && (below as f64) < 0.05 * subsample.len() as f64
    };
    let floor = ransac_plane(
        &points.positions,
        &all,
        tolerance,
        options.ransac_iterations,
        supports_scene,
        &mut rng,
    )
    .filter(|(_, inliers)| inliers.len() >= min_plane)
    .map(|(plane, _)| oriented(&plane));
    tracing::info!(
        ?floor,
        ?camera_up,
        tolerance,
        spacing,
        camera_distance,
        "floor plane"
    );
    let up = floor.map_or(camera_up, |f| f.normal);
    if let Some(floor) = &floor {
        for (i, p) in points.positions.iter().enumerate() {
            if floor.signed_distance(p) < tolerance {
                class[i] = PointClass::Floor;
            }
        }
    }

    // Horizontal distance from the vertical axis through the look-at point.
    let horizontal = |p: &Point3<f64>| distance_from_axis(p, &look_at, &up);
    let camera_radius = median(centers.iter().map(horizontal)).unwrap_or(0.0);
    let radius_limit = options.max_radius_fraction * camera_radius.max(1e-9);
    for (i, p) in points.positions.iter().enumerate() {
        if class[i] == PointClass::Plant && horizontal(p) > radius_limit {
            class[i] = PointClass::Background;
        }
    }

    // Walls: further large planes roughly parallel to up, outside the plant's radius.
    let mut walls = Vec::new();
    for _ in 0..3 {
        let remaining: Vec<usize> = (0..n)
            .filter(|&i| class[i] == PointClass::Background)
            .collect();
        let Some((plane, inliers)) = ransac_plane(
            &points.positions,
            &remaining,
            tolerance,
            options.ransac_iterations / 2,
            |plane| plane.normal.dot(&up).abs() < 30f64.to_radians().sin(),
            &mut rng,
        ) else {
            break;
        };
        if inliers.len() < min_plane || plane.signed_distance(&look_at).abs() < radius_limit {
            break;
        }
        for i in inliers {
            class[i] = PointClass::Wall;
        }
        walls.push(plane);
    }

    // Outliers: small clusters of the remaining plant candidates (3D kNN, 3σ links).
    let candidates: Vec<usize> = (0..n).filter(|&i| class[i] == PointClass::Plant).collect();
    if candidates.is_empty() {
        return Err(ForegroundError::NoPlant(format!(
            "all {n} points are floor, walls or background (radius limit {radius_limit:.3})"
        )));
    }
    let subset = points.subset(&candidates);
    let links = knn_pairs(&subset, 4);
    let lengths: Vec<f64> = links
        .iter()
        .map(|&(a, b)| (subset.positions[a as usize] - subset.positions[b as usize]).norm())
        .collect();
    let sigma = (lengths.iter().map(|l| l * l).sum::<f64>() / lengths.len().max(1) as f64).sqrt();
    let adjacency = Adjacency::from_edges(
        subset.len(),
        links
            .iter()
            .zip(&lengths)
            .filter(|(_, l)| **l < 3.0 * sigma)
            .map(|(&(a, b), _)| (a, b, 1.0)),
    );
    let components = adjacency.components();
    let groups = components.groups();
    for group in &groups {
        if group.len() < options.min_cluster_points {
            for &local in group {
                class[candidates[local as usize]] = PointClass::Outlier;
            }
        }
    }
    if !class.contains(&PointClass::Plant) {
        return Err(ForegroundError::NoPlant(
            "only small isolated clusters remain near the cameras' focus".into(),
        ));
    }

    // Stems: points whose surroundings turn around a thin tube (incoherent normals).
    let plant: Vec<usize> = (0..n).filter(|&i| class[i] == PointClass::Plant).collect();
    let plant_points = points.subset(&plant);
    // One neighbour search serves the normals, their coherence, the planes and the spacing.
    let most_neighbours = STEM_NORMAL_NEIGHBOURS
        .max(options.stem_neighbours)
        .max(local_shape::PLANE_NEIGHBOURS);
    let neighbourhoods = local_shape::Neighbourhoods::of(&plant_points, most_neighbours);
    let measured = neighbourhoods.as_ref().map(|around| {
        let normals: Vec<Vector3<f64>> = around
            .shapes(&plant_points, STEM_NORMAL_NEIGHBOURS)
            .iter()
            .map(|s| s.normal)
            .collect();
        let coherence = around.normal_coherence(&normals, options.stem_neighbours);
        let planes = around.planes(&plant_points, local_shape::PLANE_NEIGHBOURS);
        let plane_rms = median(planes.iter().map(|p| p.rms)).unwrap_or(0.0);
        (coherence, around.median_spacing(&plant_points), plane_rms)
    });
    // Points no tree can index are all coherent, like a flat sheet's.
    let (coherence, spacing, plane_rms) =
        measured.unwrap_or_else(|| (vec![1.0; plant_points.len()], 0.0, 0.0));
    let flat = local_shape::FlatSheet::like(spacing, plane_rms).map_or(1.0, |sheet| {
        sheet.coherence(
            STEM_NORMAL_NEIGHBOURS,
            options.stem_neighbours,
            options.max_flat_stem_share,
        )
    });
    let stem_coherence = options.max_stem_coherence.min(flat);
    tracing::debug!(flat, stem_coherence, "stem test threshold");
    for (local, &c) in coherence.iter().enumerate() {
        if c < stem_coherence {
            class[plant[local]] = PointClass::Stem;
        }
    }
    Ok(Foreground {
        class,
        up,
        floor,
        walls,
        plant_center: look_at,
        radius_limit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::test_support::{patch, ring_model, tube};

    #[test]
    fn closest_point_of_lines_through_a_common_point() {
        let target = Point3::new(1.0, 2.0, 3.0);
        let lines: Vec<(Point3<f64>, Vector3<f64>)> = [
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.2),
            Vector3::new(-0.5, 0.5, 1.0),
        ]
        .iter()
        .map(|d| {
            let d = d.normalize();
            (target - d * 4.0, d)
        })
        .collect();
        let found = closest_point_to_lines(&lines).unwrap();
        assert!((found - target).norm() < 1e-9);
        let parallel = vec![
            (Point3::origin(), Vector3::x()),
            (Point3::new(0.0, 1.0, 0.0), Vector3::x()),
        ];
        assert!(closest_point_to_lines(&parallel).is_none());
    }

    #[test]
    fn a_tilted_plane_hypothesis_is_refined_onto_the_floor_under_a_pot() {
        // A floor (z = 0, ±3 mm of noise) and, on it, a pot's soil disc 15 mm up: a plane
        // hypothesis tilted by 4° through the disc's edge takes a band of floor and soil.
        let mut rng = Rng::seed_from(3);
        let mut points = Vec::new();
        for i in 0..120 {
            for j in 0..120 {
                let (x, y) = (-0.6 + 0.01 * f64::from(i), -0.6 + 0.01 * f64::from(j));
                let noise = 0.006 * (rng.uniform() - 0.5);
                if x.hypot(y) < 0.12 {
                    points.push(Point3::new(x, y, 0.015 + noise));
                } else {
                    points.push(Point3::new(x, y, noise));
                }
            }
        }
        let floor_points = points.iter().filter(|p| p.z < 0.01).count();
        let candidates: Vec<usize> = (0..points.len()).collect();
        let tilt = 4f64.to_radians();
        let normal = Vector3::new(0.0, -tilt.sin(), tilt.cos());
        let hypothesis = Plane {
            normal,
            offset: normal.dot(&Vector3::new(0.0, 0.12, 0.012)),
        };
        let (plane, members) = refine_plane(&points, &candidates, hypothesis, 0.01, |_| true);
        let angle = plane.normal.angle(&Vector3::z()).to_degrees();
        assert!(angle < 0.3, "normal {angle}° off the floor's");
        assert!(plane.offset.abs() < 0.003, "offset {}", plane.offset);
        assert!(
            members.len() as f64 >= 0.98 * floor_points as f64,
            "{} of {floor_points} floor points",
            members.len()
        );
    }

    #[test]
    fn floor_background_stem_and_leaves_are_told_apart() {
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        let mut positions = patch(Point3::new(0.0, 0.0, 0.0), x, y, 120, 0.01); // floor 1.2 m
        let floor = positions.len();
        let stem = tube(Point3::new(0.0, 0.0, 0.0), 0.0025, 0.3, 0.0015);
        positions.extend(&stem);
        let stem_end = positions.len();
        let leaf_a = patch(Point3::new(0.06, 0.0, 0.3), x, y, 40, 0.0015);
        let leaf_b = patch(
            Point3::new(-0.05, 0.03, 0.22),
            (x + z * 0.3).normalize(),
            y,
            40,
            0.0015,
        );
        positions.extend(&leaf_a);
        positions.extend(&leaf_b);
        let leaves_end = positions.len();
        // A far wall ring, beyond the plant's radius.
        for k in 0..2000 {
            let a = std::f64::consts::TAU * k as f64 / 2000.0;
            positions.push(Point3::new(
                2.5 * a.cos(),
                2.5 * a.sin(),
                0.3 + 0.2 * (k % 5) as f64,
            ));
        }
        let model = ring_model(&positions);
        let points = PointSet::from_reconstruction(&model);
        let found = separate_foreground(&points, &model, &ForegroundOptions::default()).unwrap();
        let floor_plane = found.floor.expect("floor found");
        assert!(
            floor_plane.normal.z > 0.999 && floor_plane.offset.abs() < 1e-3,
            "{floor_plane:?}"
        );
        let count = |range: std::ops::Range<usize>, class: PointClass| {
            range.filter(|&i| found.class[i] == class).count()
        };
        assert!(count(0..floor, PointClass::Floor) as f64 > 0.99 * floor as f64);
        let stem_points = stem_end - floor;
        assert!(count(floor..stem_end, PointClass::Stem) as f64 > 0.7 * stem_points as f64);
        let leaf_points = leaves_end - stem_end;
        assert!(count(stem_end..leaves_end, PointClass::Plant) as f64 > 0.97 * leaf_points as f64);
        let far = positions.len() - leaves_end;
        let background = count(leaves_end..positions.len(), PointClass::Background)
            + count(leaves_end..positions.len(), PointClass::Wall);
        assert!(background as f64 > 0.99 * far as f64);
    }

    #[test]
    fn no_points_and_no_plant_are_clear_errors() {
        let model = ring_model(&[]);
        let points = PointSet::from_reconstruction(&model);
        assert_eq!(
            separate_foreground(&points, &model, &ForegroundOptions::default()).unwrap_err(),
            ForegroundError::NoPoints
        );
        // Only a floor: nothing is left for the plant.
        let floor = patch(
            Point3::new(0.0, 0.0, 0.0),
            Vector3::x(),
            Vector3::y(),
            60,
            0.02,
        );
        let model = ring_model(&floor);
        let points = PointSet::from_reconstruction(&model);
        let err = separate_foreground(&points, &model, &ForegroundOptions::default()).unwrap_err();
        assert!(matches!(err, ForegroundError::NoPlant(_)), "{err}");
    }
}
