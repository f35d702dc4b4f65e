//! Branches as the user edits them by hand in a view (seed 004 §7): each branch of a tree
//! projected into the view as its skeleton curve, its control points and a disc at each end
//! (the end's radius, seen across the view ray), and the handle nearest to a press.
//!
//! Takes a [`BranchTree`] and a view ([`ViewProjection`]: a photo, or the GUI's 3D panel
//! camera); returns [`BranchHandles`] in the view's pixels (COLMAP convention) and
//! [`HandlePick`]s. The GUI draws the handles, and turns a pick and the pixel where the drag
//! ends into an edit command ([`EndDisc::radius_through`] gives a Radius drag's new radius).

use nalgebra::Point2;

use super::{Branch, BranchTree};
use crate::scene::ViewProjection;

/// A branch end seen in a view: a disc of the end's radius about the projected end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndDisc {
    pub centre_px: Point2<f64>,
    pub radius_px: f64,
    /// The view's scale at the end (pixels per metre across the view ray).
    pub px_per_metre: f64,
}

impl EndDisc {
    /// How far a press at `pixel_px` is from the disc as a handle: its distance to the rim or
    /// to the centre, whichever is less (a press on the rim or anywhere near the centre
    /// grabs it).
    pub fn grab_distance_px(&self, pixel_px: &Point2<f64>) -> f64 {
        let from_centre = (self.centre_px.x - pixel_px.x).hypot(self.centre_px.y - pixel_px.y);
        (from_centre - self.radius_px).abs().min(from_centre)
    }

    /// The radius (metres) of the disc about the same centre whose rim passes through
    /// `pixel_px`: what a radius drag released there sets.
    pub fn radius_through(&self, pixel_px: &Point2<f64>) -> f64 {
        (pixel_px.x - self.centre_px.x).hypot(pixel_px.y - self.centre_px.y) / self.px_per_metre
    }
}

/// One branch projected into a view (pixels, COLMAP convention).
#[derive(Clone, Debug, PartialEq)]
pub struct BranchHandles {
    pub branch: u32,
    /// Skeleton samples at equal arc length that project (for drawing the branch).
    pub curve_px: Vec<Point2<f64>>,
    /// Every control point, in skeleton order; `None` where it does not project.
    pub control_points_px: Vec<Option<Point2<f64>>>,
    /// The discs at the start and at the end; `None` where the end does not project.
    pub ends: [Option<EndDisc>; 2],
    pub leaf_at_tip: bool,
}

impl BranchHandles {
    /// Projects `branch` into `view`, its curve from `curve_samples` skeleton samples (at
    /// least 2; 0 for no curve).
    pub fn project(branch: &Branch, view: &impl ViewProjection, curve_samples: usize) -> Self {
        let skeleton = &branch.cylinder.skeleton;
        let curve_px = if curve_samples == 0 {
            Vec::new()
        } else {
            skeleton
                .sample_by_arc_length(curve_samples)
                .iter()
                .filter_map(|(p, _)| view.project_px(p))
                .collect()
        };
        let controls = skeleton.control_points();
        let end = |p: Option<&nalgebra::Point3<f64>>, radius: f64| {
            let p = p?;
            let centre_px = view.project_px(p)?;
            let px_per_metre = view.px_per_metre(p)?;
            Some(EndDisc {
                centre_px,
                radius_px: radius * px_per_metre,
                px_per_metre,
            })
        };
        Self {
            branch: branch.id,
            curve_px,
            control_points_px: controls.iter().map(|p| view.project_px(p)).collect(),
            ends: [
                end(controls.first(), branch.cylinder.radius_start),
                end(controls.last(), branch.cylinder.radius_end),
            ],
            leaf_at_tip: branch.leaf_at_tip,
        }
    }
}

/// Every branch of `tree` projected into `view` (see [`BranchHandles::project`]).
pub fn project_branches(
    tree: &BranchTree,
    view: &impl ViewProjection,
    curve_samples: usize,
) -> Vec<BranchHandles> {
    tree.branches
        .iter()
        .map(|branch| BranchHandles::project(branch, view, curve_samples))
        .collect()
}

/// A handle under a press.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HandlePick {
    /// Control point `control_point` (index into the skeleton's control points).
    ControlPoint { branch: u32, control_point: usize },
    /// End `end` of a branch (0 the start, 1 the end, as in [`BranchHandles::ends`]) with its
    /// disc.
    End {
        branch: u32,
        end: usize,
        disc: EndDisc,
    },
}

/// The candidate at the least distance within `tolerance_px`; the first among equals.
fn nearest(
    candidates: impl Iterator<Item = (f64, HandlePick)>,
    tolerance_px: f64,
) -> Option<HandlePick> {
    let mut best: Option<(f64, HandlePick)> = None;
    for (distance, pick) in candidates {
        if distance <= tolerance_px && best.is_none_or(|(d, _)| distance < d) {
            best = Some((distance, pick));
        }
    }
    best.map(|(_, pick)| pick)
}

/// The control point nearest to `pixel_px` within `tolerance_px` (a move drag's handle).
pub fn nearest_control_point(
    handles: &[BranchHandles],
    pixel_px: &Point2<f64>,
    tolerance_px: f64,
) -> Option<HandlePick> {
    let candidates = handles.iter().flat_map(|handle| {
        handle
            .control_points_px
            .iter()
            .enumerate()
            .filter_map(move |(control_point, uv)| {
                let uv = (*uv)?;
                Some((
                    (uv.x - pixel_px.x).hypot(uv.y - pixel_px.y),
                    HandlePick::ControlPoint {
                        branch: handle.branch,
                        control_point,
                    },
                ))
            })
    });
    nearest(candidates, tolerance_px)
}

/// The branch end whose disc is nearest to `pixel_px` within `tolerance_px`, by
/// [`EndDisc::grab_distance_px`] (a radius drag's handle).
pub fn nearest_end(
    handles: &[BranchHandles],
    pixel_px: &Point2<f64>,
    tolerance_px: f64,
) -> Option<HandlePick> {
    let candidates = handles.iter().flat_map(|handle| {
        handle
            .ends
            .iter()
            .enumerate()
            .filter_map(move |(end, disc)| {
                let disc = (*disc)?;
                Some((
                    disc.grab_distance_px(pixel_px),
                    HandlePick::End {
                        branch: handle.branch,
                        end,
                        disc,
                    },
                ))
            })
    });
    nearest(candidates, tolerance_px)
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::*;
    use crate::branch::{GeneralizedCylinder, Spline};
    use crate::scene::synthetic::look_at;
    use crate::scene::{Camera, Image, PhotoView, Reconstruction};

    fn branch(id: u32, points: &[[f64; 3]], radii: (f64, f64)) -> Branch {
        let spline = Spline::new(points.iter().map(|&p| Point3::from(p)).collect()).unwrap();
        Branch {
            id,
            parent: None,
            parent_fraction: 0.0,
            cylinder: GeneralizedCylinder::new(spline, radii.0, radii.1),
            leaf_at_tip: id == 2,
        }
    }

    /// A photo 800 px wide with a 400 px focal, from y = −2 looking at the origin (200 px
    /// per metre there).
    fn photo() -> Reconstruction {
        let image = Image {
            id: 1,
            camera_id: 1,
            name: "a.png".into(),
            camera_from_world: look_at(Point3::new(0.0, -2.0, 0.0), Point3::origin()),
            keypoints: Vec::new(),
        };
        let camera = Camera::simple_pinhole(1, 800, 600, 400.0);
        Reconstruction::from_parts(vec![camera], vec![image], Vec::new()).unwrap()
    }

    fn tree() -> BranchTree {
        BranchTree {
            branches: vec![
                branch(
                    1,
                    &[[0.0, 0.0, -0.5], [0.0, 0.0, 0.0], [0.0, 0.0, 0.5]],
                    (0.05, 0.02),
                ),
                // Its last control point lies behind the camera.
                branch(
                    2,
                    &[[0.5, 0.0, 0.0], [0.6, -1.0, 0.0], [0.6, -3.0, 0.0]],
                    (0.03, 0.01),
                ),
            ],
        }
    }

    #[test]
    fn a_radius_round_trips_through_its_projected_disc() {
        let model = photo();
        let view = PhotoView::new(&model, &model.images()[0]);
        let handles = project_branches(&tree(), &view, 16);
        let stem = &handles[0];
        assert_eq!(stem.curve_px.len(), 16);
        for (k, radius) in [0.05, 0.02].into_iter().enumerate() {
            let disc = stem.ends[k].unwrap();
            // The stem's ends are at depth 2 m, 0.5 m off the axis (θ = atan ¼): across
            // the ray a pinhole spans f / (depth · cos θ) = 100·√4.25 px per metre (to the
            // finite difference's step).
            let expected = 100.0 * 4.25f64.sqrt();
            assert!(
                (disc.px_per_metre - expected).abs() < 1e-3 * expected,
                "{disc:?}"
            );
            assert!((disc.radius_px - radius * disc.px_per_metre).abs() < 1e-12);
            // A point on the rim, in any direction, gives the radius back; one at twice the
            // distance twice the radius.
            for angle in [0.0f64, 1.0, 2.5] {
                let (dx, dy) = (angle.cos(), angle.sin());
                let rim = disc.centre_px + nalgebra::Vector2::new(dx, dy) * disc.radius_px;
                assert!((disc.radius_through(&rim) - radius).abs() < 1e-12);
                let out = disc.centre_px + nalgebra::Vector2::new(dx, dy) * 2.0 * disc.radius_px;
                assert!((disc.radius_through(&out) - 2.0 * radius).abs() < 1e-12);
                assert!(disc.grab_distance_px(&rim) < 1e-9);
            }
        }
        // The ends project where the photo puts them.
        let end = view.project_px(&Point3::new(0.0, 0.0, 0.5)).unwrap();
        assert!((stem.ends[1].unwrap().centre_px - end).norm() < 1e-9);
    }

    #[test]
    fn control_points_behind_the_camera_keep_the_others_indices() {
        let model = photo();
        let view = PhotoView::new(&model, &model.images()[0]);
        let handles = project_branches(&tree(), &view, 0);
        let side = &handles[1];
        assert!(side.curve_px.is_empty());
        assert_eq!(side.control_points_px.len(), 3);
        assert!(side.control_points_px[2].is_none() && side.ends[1].is_none());
        assert!(side.leaf_at_tip);
        // Pressing on the second control point picks index 1.
        let second = side.control_points_px[1].unwrap();
        let pick =
            nearest_control_point(&handles, &(second + nalgebra::Vector2::new(3.0, 0.0)), 5.0);
        assert_eq!(
            pick,
            Some(HandlePick::ControlPoint {
                branch: 2,
                control_point: 1
            })
        );
    }

    #[test]
    fn the_nearest_handle_within_the_tolerance_is_picked() {
        let model = photo();
        let view = PhotoView::new(&model, &model.images()[0]);
        let handles = project_branches(&tree(), &view, 0);
        let tip = handles[0].ends[1].unwrap();
        let centre = tip.centre_px;
        // Exactly on a control point: that one; past the tolerance: none.
        assert_eq!(
            nearest_control_point(&handles, &centre, 1.0),
            Some(HandlePick::ControlPoint {
                branch: 1,
                control_point: 2
            })
        );
        let away = centre + nalgebra::Vector2::new(0.0, -30.0);
        assert_eq!(nearest_control_point(&handles, &away, 29.0), None);
        assert!(nearest_control_point(&handles, &away, 31.0).is_some());
        // Inside the tip's disc (4 px radius): grabbed by its centre distance; just outside
        // its rim: by the rim distance.
        let inside = centre + nalgebra::Vector2::new(1.0, 0.0);
        let rim_out = centre + nalgebra::Vector2::new(tip.radius_px + 2.0, 0.0);
        for (press, distance) in [(inside, 1.0), (rim_out, 2.0)] {
            let Some(HandlePick::End { branch, end, disc }) = nearest_end(&handles, &press, 3.0)
            else {
                panic!("no end under {press:?}");
            };
            assert_eq!((branch, end, disc), (1, 1, tip));
            assert!((disc.grab_distance_px(&press) - distance).abs() < 1e-9);
            assert!(nearest_end(&handles, &press, distance - 1e-6).is_none());
        }
    }
}
