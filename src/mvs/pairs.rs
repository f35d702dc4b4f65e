//! Stereo partners: for each registered view, the views it shares most sparse points with at a
//! useful triangulation angle (COLMAP's patch-match view selection in spirit: enough overlap,
//! neither too narrow a baseline, where depth is noisy, nor too wide, where patches distort).

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};
use serde::Serialize;

use crate::scene::Reconstruction;

/// A view (left) and its partner (right), as positions in `Reconstruction::images()`. The
/// rectified frame puts the partner to the left view's right.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StereoPair {
    pub left: usize,
    pub right: usize,
    /// Sparse points both views observe.
    pub shared_points: usize,
    /// Angle between the two camera centres seen from the shared points' centroid, degrees.
    pub angle_deg: f64,
}

/// How partners are chosen.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PairOptions {
    pub partners_per_view: usize,
    /// Further partners per view (ranked after the first `partners_per_view`) whose depth maps
    /// only fill the gaps the others' fused points leave (see [`super::densify`]): 0 for none,
    /// 1 by default (leaf length and area from photos, README: *Gap fills*).
    pub fill_partners_per_view: usize,
    /// Triangulation angles outside `[min, max]` are never used; `ideal` scores best.
    pub min_angle_deg: f64,
    pub ideal_angle_deg: f64,
    pub max_angle_deg: f64,
    /// A partner must share at least this many sparse points with the view.
    pub min_shared_points: usize,
}

impl Default for PairOptions {
    fn default() -> Self {
        Self {
            partners_per_view: 1,
            fill_partners_per_view: 1,
            min_angle_deg: 3.0,
            ideal_angle_deg: 12.0,
            max_angle_deg: 35.0,
            min_shared_points: 10,
        }
    }
}

/// Score multiplier of a triangulation angle: rises linearly from 0 at `min` to 1 at `ideal`,
/// falls linearly to 0 at `max`.
fn angle_weight(angle_deg: f64, options: &PairOptions) -> f64 {
    if angle_deg <= options.min_angle_deg || angle_deg >= options.max_angle_deg {
        0.0
    } else if angle_deg <= options.ideal_angle_deg {
        (angle_deg - options.min_angle_deg) / (options.ideal_angle_deg - options.min_angle_deg)
    } else {
        (options.max_angle_deg - angle_deg) / (options.max_angle_deg - options.ideal_angle_deg)
    }
}

/// Each view's best partners by `shared points × angle weight`, at most `partners_per_view`
/// per view: each pair gives its left view a depth map. Deterministic: ties go to the lower
/// image position.
pub fn select_pairs(model: &Reconstruction, options: &PairOptions) -> Vec<StereoPair> {
    let images = model.images();
    // Per unordered pair: shared point count and the sum of their positions.
    let mut shared: HashMap<(usize, usize), (usize, Vector3<f64>)> = HashMap::new();
    let mut views = Vec::new();
    for point in model.points() {
        views.clear();
        views.extend(
            point
                .track
                .iter()
                .filter_map(|t| model.image_position(t.image_id)),
        );
        views.sort_unstable();
        views.dedup();
        for (k, &a) in views.iter().enumerate() {
            for &b in &views[k + 1..] {
                let entry = shared.entry((a, b)).or_insert((0, Vector3::zeros()));
                entry.0 += 1;
                entry.1 += point.position_world.coords;
            }
        }
    }
    let centers: Vec<Point3<f64>> = images.iter().map(|i| i.center_world()).collect();
    let mut candidates: Vec<Vec<(f64, StereoPair)>> = vec![Vec::new(); images.len()];
    let mut keys: Vec<_> = shared.into_iter().collect();
    keys.sort_unstable_by_key(|(k, _)| *k);
    for ((a, b), (count, sum)) in keys {
        if count < options.min_shared_points.max(1) {
            continue;
        }
        let centroid = Point3::from(sum / count as f64);
        let (ray_a, ray_b) = (centers[a] - centroid, centers[b] - centroid);
        let cosine = ray_a.normalize().dot(&ray_b.normalize()).clamp(-1.0, 1.0);
        let angle_deg = cosine.acos().to_degrees();
        let score = count as f64 * angle_weight(angle_deg, options);
        if score.is_nan() || score <= 0.0 {
            continue;
        }
        for (left, right) in [(a, b), (b, a)] {
            candidates[left].push((
                score,
                StereoPair {
                    left,
                    right,
                    shared_points: count,
                    angle_deg,
                },
            ));
        }
    }
    let mut pairs = Vec::new();
    for list in &mut candidates {
        list.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.right.cmp(&y.1.right)));
        pairs.extend(
            list.iter()
                .take(options.partners_per_view)
                .map(|(_, pair)| *pair),
        );
    }
    pairs
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::model::{Image, Keypoint, Point3D, TrackElement};
    use crate::scene::synthetic::look_at;
    use crate::scene::{Camera, Reconstruction};
    use crate::util::rng::Rng;

    /// `num_views` pinhole cameras on a horizontal ring of radius 4 around points in a unit
    /// ball, every point observed by every view.
    pub(crate) fn ring_model(num_views: usize, num_points: usize) -> Reconstruction {
        let camera = Camera::simple_pinhole(1, 640, 480, 500.0);
        let mut rng = Rng::seed_from(7);
        let positions: Vec<Point3<f64>> = (0..num_points)
            .map(|_| {
                Point3::new(
                    rng.range(-0.5, 0.5),
                    rng.range(-0.5, 0.5),
                    rng.range(-0.5, 0.5),
                )
            })
            .collect();
        let mut images = Vec::new();
        for v in 0..num_views {
            let angle = std::f64::consts::TAU * v as f64 / num_views as f64;
            let center = Point3::new(4.0 * angle.cos(), 4.0 * angle.sin(), 0.0);
            let camera_from_world = look_at(center, Point3::origin());
            let keypoints = positions
                .iter()
                .enumerate()
                .map(|(p, x)| Keypoint {
                    uv_image: camera
                        .project(&(camera_from_world * x).coords)
                        .expect("in front"),
                    point3d_id: Some(p as u64 + 1),
                })
                .collect();
            images.push(Image {
                id: v as u32 + 1,
                camera_id: 1,
                name: format!("view_{v:04}.png"),
                camera_from_world,
                keypoints,
            });
        }
        let points = positions
            .iter()
            .enumerate()
            .map(|(p, x)| Point3D {
                id: p as u64 + 1,
                position_world: *x,
                color: [100, 150, 50],
                error: 0.5,
                track: (0..num_views)
                    .map(|v| TrackElement {
                        image_id: v as u32 + 1,
                        keypoint_index: p as u32,
                    })
                    .collect(),
            })
            .collect();
        Reconstruction::from_parts(vec![camera], images, points).expect("consistent model")
    }

    #[test]
    fn ring_neighbours_are_partners_and_pairs_are_unique() {
        // 24 views on a ring, 15° apart: neighbours (15°) beat second neighbours (30°).
        let model = ring_model(24, 50);
        let options = PairOptions {
            partners_per_view: 2,
            ..PairOptions::default()
        };
        let pairs = select_pairs(&model, &options);
        let mut seen = std::collections::HashSet::new();
        for pair in &pairs {
            assert_ne!(pair.left, pair.right);
            assert!(seen.insert((pair.left, pair.right)));
            let gap = (pair.left as i64 - pair.right as i64).rem_euclid(24);
            assert!(gap == 1 || gap == 23, "{pair:?}");
            assert!((pair.angle_deg - 15.0).abs() < 0.5, "{pair:?}");
            assert_eq!(pair.shared_points, 50);
        }
        // Every view is the left view of both its neighbours.
        assert_eq!(pairs.len(), 48);
        for view in 0..24 {
            assert_eq!(pairs.iter().filter(|p| p.left == view).count(), 2);
        }
    }

    #[test]
    fn too_few_shared_points_or_bad_angles_give_no_pairs() {
        assert!(select_pairs(&ring_model(6, 5), &PairOptions::default()).is_empty());
        // 4 views: 90° apart, beyond the largest useful angle.
        assert!(select_pairs(&ring_model(4, 50), &PairOptions::default()).is_empty());
        let options = PairOptions::default();
        assert_eq!(angle_weight(12.0, &options), 1.0);
        assert_eq!(angle_weight(1.0, &options), 0.0);
        assert_eq!(angle_weight(40.0, &options), 0.0);
    }
}
