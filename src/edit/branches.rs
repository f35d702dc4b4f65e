//! Branch edits (seed 004 §7) as functions from the current branch tree to the edited one:
//! drawing a branch from a stroke in a photo, in the 3D panel's view or in 3D, moving a
//! control point, radii, a leaf at a tip, deletion. The session wraps them as undoable
//! commands.

use nalgebra::{Isometry3, Point2, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::command::{BranchEnd, ViewCameraRecord};
use crate::branch::skeleton::SkeletonError;
use crate::branch::{Branch, BranchPoint, BranchTree, GeneralizedCylinder, Spline, SplineError};
use crate::scene::{Camera, CameraModelKind};
use crate::util::polyline::resample;

/// Stroke samples take the point projecting nearest within this distance (pixels).
pub const BRANCH_TOLERANCE_PX: f64 = 8.0;
/// Strokes are resampled every this many pixels.
const STROKE_STEP_PX: f64 = 4.0;
/// At most this many samples per stroke.
const MAX_STROKE_SAMPLES: usize = 200;
/// Among candidates within this many pixels of the nearest, the front-most is taken.
const FRONT_TIE_PX: f64 = 2.0;

/// Why a branch edit could not be applied.
#[derive(Debug, thiserror::Error)]
pub enum BranchEditError {
    #[error("no branch with id {0}")]
    UnknownBranch(u32),
    #[error("branch {branch} has {count} control points; there is no control point {index}")]
    UnknownControlPoint {
        branch: u32,
        index: usize,
        count: usize,
    },
    #[error("radius {0} is not a positive finite number")]
    InvalidRadius(f64),
    #[error("the stroke needs at least two distinct finite points")]
    InvalidStroke,
    #[error("the stroke does not start on a branch ({0})")]
    NotOnBranch(String),
    #[error("no point lies under the stroke to give it depth, and it has no parent branch")]
    NoDepth,
    #[error("invalid view camera: {0}")]
    InvalidViewCamera(String),
    #[error("the control point is behind the view's camera")]
    BehindCamera,
    #[error(transparent)]
    Spline(#[from] SplineError),
    #[error(transparent)]
    Skeleton(#[from] SkeletonError),
}

/// A camera strokes are drawn in: a photo's or the 3D panel's.
#[derive(Clone, Debug)]
pub struct StrokeView {
    pub camera: Camera,
    pub camera_from_world: Isometry3<f64>,
}

impl StrokeView {
    /// The 3D panel's pinhole camera.
    pub fn from_view_camera(view: &ViewCameraRecord) -> Result<Self, BranchEditError> {
        let invalid = |m: &str| BranchEditError::InvalidViewCamera(m.to_owned());
        let [w, x, y, z] = view.rotation;
        let quaternion = Quaternion::new(w, x, y, z);
        if !quaternion.coords.iter().all(|c| c.is_finite()) || quaternion.norm() < 1e-9 {
            return Err(invalid("rotation is not a non-zero finite quaternion"));
        }
        if !view.translation.iter().all(|c| c.is_finite()) {
            return Err(invalid("translation is not finite"));
        }
        if !(view.focal_px.is_finite() && view.focal_px > 0.0) {
            return Err(invalid("focal length must be positive"));
        }
        let (width, height) = (view.width as f64, view.height as f64);
        let camera = Camera::new(
            0,
            CameraModelKind::Pinhole,
            view.width as u64,
            view.height as u64,
            vec![view.focal_px, view.focal_px, 0.5 * width, 0.5 * height],
        )
        .map_err(|e| BranchEditError::InvalidViewCamera(e.to_string()))?;
        Ok(Self {
            camera,
            camera_from_world: Isometry3::from_parts(
                Translation3::new(
                    view.translation[0],
                    view.translation[1],
                    view.translation[2],
                ),
                UnitQuaternion::from_quaternion(quaternion),
            ),
        })
    }

    fn project(&self, point_world: &Point3<f64>) -> Option<(Point2<f64>, f64)> {
        let point_camera = self.camera_from_world * point_world;
        let uv = self.camera.project(&point_camera.coords)?;
        Some((uv, point_camera.z))
    }

    /// The world point seen at `uv_image` at camera depth `depth` (z in the camera frame).
    fn at_depth(&self, uv_image: &Point2<f64>, depth: f64) -> Option<Point3<f64>> {
        let ray_camera = self.camera.unproject(uv_image)?;
        if ray_camera.z.abs() < 1e-12 || depth <= 0.0 {
            return None;
        }
        let point_camera = Point3::from(ray_camera * (depth / ray_camera.z));
        Some(self.camera_from_world.inverse() * point_camera)
    }

    /// Unit viewing ray (world frame) through a world point.
    fn ray_through(&self, point_world: &Point3<f64>) -> Vector3<f64> {
        let centre = self.camera_from_world.inverse() * Point3::origin();
        (point_world - centre)
            .try_normalize(1e-15)
            .unwrap_or_else(Vector3::zeros)
    }

    /// Where a point at the same camera depth as `point_world` appears at `uv_image`.
    pub fn drag(
        &self,
        point_world: &Point3<f64>,
        uv_image: &Point2<f64>,
    ) -> Result<Point3<f64>, BranchEditError> {
        let depth = (self.camera_from_world * point_world).z;
        self.at_depth(uv_image, depth)
            .ok_or(BranchEditError::BehindCamera)
    }
}

/// What strokes snap to.
pub struct SnapPoints<'a> {
    pub positions: &'a [Point3<f64>],
    /// Points a branch may snap to (stems, petioles: not leaves), by index.
    pub candidates: Vec<u32>,
    /// Typical distance between neighbouring points.
    pub spacing: f64,
}

fn check_radius(radius: f64) -> Result<f64, BranchEditError> {
    if radius.is_finite() && radius > 0.0 {
        Ok(radius)
    } else {
        Err(BranchEditError::InvalidRadius(radius))
    }
}

fn branch_mut(tree: &mut BranchTree, id: u32) -> Result<&mut Branch, BranchEditError> {
    tree.branches
        .iter_mut()
        .find(|b| b.id == id)
        .ok_or(BranchEditError::UnknownBranch(id))
}

/// The branch nearest to a pixel (its centreline projected within `tolerance_px`, widened by
/// its projected radius). Among branches the pixel lies on, the one whose centreline is
/// nearest wins, so a thin branch crossing a thick one is picked on its own axis.
pub fn pick_branch(
    tree: &BranchTree,
    view: &StrokeView,
    pixel: &Point2<f64>,
    tolerance_px: f64,
) -> Option<BranchPoint> {
    // (distance outside the projected radius, distance to the centreline, branch, fraction)
    let mut best: Option<(f64, f64, u32, f64)> = None;
    for branch in &tree.branches {
        let samples = 96;
        let projected: Vec<Option<(Point2<f64>, f64)>> = (0..=samples)
            .map(|k| {
                let fraction = k as f64 / samples as f64;
                view.project(&branch.cylinder.skeleton.point_at_fraction(fraction))
            })
            .collect();
        for k in 0..samples {
            let (Some((a, depth_a)), Some((b, _))) = (projected[k], projected[k + 1]) else {
                continue;
            };
            let ab = b - a;
            let along = if ab.norm_squared() < 1e-18 {
                0.0
            } else {
                ((pixel - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
            };
            let fraction = (k as f64 + along) / samples as f64;
            let radius_px = branch.cylinder.radius_at(fraction)
                * view.camera.focal_and_principal_point().0
                / depth_a.max(1e-12);
            let to_axis = (pixel - (a + ab * along)).norm();
            let distance = (to_axis - radius_px).max(0.0);
            if distance <= tolerance_px
                && best.is_none_or(|(d, axis, _, _)| (distance, to_axis) < (d, axis))
            {
                best = Some((distance, to_axis, branch.id, fraction));
            }
        }
    }
    let (distance, _, id, fraction) = best?;
    tree.point_on(id, fraction)
        .map(|point| BranchPoint { distance, ..point })
}

/// Points along a pixel polyline every [`STROKE_STEP_PX`] (ends kept, at most
/// [`MAX_STROKE_SAMPLES`]).
fn resample_stroke(stroke: &[[f64; 2]]) -> Result<Vec<Point2<f64>>, BranchEditError> {
    let points: Vec<Point2<f64>> = stroke
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .map(|p| Point2::new(p[0], p[1]))
        .collect();
    if points.len() != stroke.len() {
        return Err(BranchEditError::InvalidStroke);
    }
    let length = crate::util::polyline::length(&points);
    if points.len() < 2 || length < 1e-6 {
        return Err(BranchEditError::InvalidStroke);
    }
    let count = ((length / STROKE_STEP_PX).ceil() as usize + 1).clamp(2, MAX_STROKE_SAMPLES);
    Ok(resample(&points, count))
}

/// Median over a sliding window of 5 (ends shrink the window).
fn median_filter(values: &[f64]) -> Vec<f64> {
    (0..values.len())
        .map(|i| {
            let lo = i.saturating_sub(2);
            let hi = (i + 3).min(values.len());
            let mut window = values[lo..hi].to_vec();
            window.sort_by(f64::total_cmp);
            window[window.len() / 2]
        })
        .collect()
}

/// DrawBranch in a camera (seed 004 §7): the stroke starts on an existing branch (the first
/// branch of an empty tree is the main stem); each sample takes the 3D position of the snap
/// point projecting nearest within [`BRANCH_TOLERANCE_PX`] whose depth continues the branch
/// (a gate around the last traced depth, starting from the attachment point, or for a main
/// stem from the median front-most depth), moved back along the ray by the expected radius to
/// the centreline; samples with none inherit their depth from the parent branch: the
/// attachment point's depth, interpolated toward the next traced sample when there is one.
/// Depths are median-filtered so that one stray sample does not kink the branch.
pub fn draw_in_view(
    tree: &BranchTree,
    view: &StrokeView,
    stroke: &[[f64; 2]],
    snap: &SnapPoints<'_>,
    radius: Option<[f64; 2]>,
) -> Result<BranchTree, BranchEditError> {
    let samples = resample_stroke(stroke)?;
    let parent = if tree.branches.is_empty() {
        None
    } else {
        Some(
            pick_branch(tree, view, &samples[0], BRANCH_TOLERANCE_PX).ok_or_else(|| {
                BranchEditError::NotOnBranch(format!(
                    "no branch projects within {BRANCH_TOLERANCE_PX} px of ({:.1}, {:.1})",
                    samples[0].x, samples[0].y
                ))
            })?,
        )
    };
    let radii = branch_radii(tree, parent.as_ref(), radius, snap.spacing, None)?;
    let projected: Vec<(Point2<f64>, f64, u32)> = snap
        .candidates
        .iter()
        .filter_map(|&i| {
            view.project(&snap.positions[i as usize])
                .map(|(uv, depth)| (uv, depth, i))
        })
        .collect();
    let traced = if parent.is_some() {
        &samples[1..]
    } else {
        &samples[..]
    };
    let inherited = match &parent {
        Some(anchor) => Some(view.project(&anchor.position).map(|(_, d)| d).ok_or(
            BranchEditError::NotOnBranch("the attachment point is behind the camera".into()),
        )?),
        None => None,
    };
    let focal = view.camera.focal_and_principal_point().0.max(1e-9);
    // Trace along the stroke: each sample takes, among the points projecting within the
    // tolerance, the nearest whose depth continues the branch (within a gate around the last
    // traced depth that widens with the gap); among near ties, the one nearest that depth.
    let near_sample = |pixel: &Point2<f64>| -> Vec<(f64, f64, u32)> {
        projected
            .iter()
            .map(|(uv, depth, i)| ((uv - pixel).norm(), *depth + radii.0, *i))
            .filter(|(d, _, _)| *d <= BRANCH_TOLERANCE_PX)
            .collect()
    };
    // Among the candidates within FRONT_TIE_PX of the nearest projection, the one whose
    // depth is closest to `depth` (0: the front-most).
    let pick = |near: &[(f64, f64, u32)], depth: f64| {
        let nearest = near.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
        near.iter()
            .filter(|c| c.0 <= nearest + FRONT_TIE_PX)
            .min_by(|a, b| {
                (a.1 - depth)
                    .abs()
                    .total_cmp(&(b.1 - depth).abs())
                    .then(a.2.cmp(&b.2))
            })
            .map(|c| (c.1, c.2))
    };
    // A main stem starts from the median depth of the front-most points along the stroke.
    let start_depth = inherited.or_else(|| {
        let mut depths: Vec<f64> = traced
            .iter()
            .filter_map(|pixel| pick(&near_sample(pixel), 0.0).map(|(d, _)| d))
            .collect();
        depths.sort_by(f64::total_cmp);
        depths.get(depths.len() / 2).copied()
    });
    let Some(start_depth) = start_depth else {
        return Err(BranchEditError::NoDepth);
    };
    let mut hits: Vec<Option<(f64, u32)>> = Vec::with_capacity(traced.len());
    let mut last = (0, start_depth);
    for (k, pixel) in traced.iter().enumerate() {
        let (at, depth) = last;
        let gap = (k + 1 - at) as f64;
        let step_world = STROKE_STEP_PX * depth / focal;
        let gate = 3.0 * snap.spacing + radii.0 + 2.0 * gap * step_world;
        let mut near = near_sample(pixel);
        near.retain(|c| (c.1 - depth).abs() <= gate);
        let hit = pick(&near, depth);
        if let Some((depth, _)) = hit {
            last = (k + 1, depth);
        }
        hits.push(hit);
    }
    // Untraced samples: depth interpolated between the nearest traced ones (the attachment
    // point counts as traced before the first sample), held constant past the last.
    let known: Vec<(f64, f64)> = inherited
        .map(|d| (-1.0, d))
        .into_iter()
        .chain(
            hits.iter()
                .enumerate()
                .filter_map(|(k, h)| h.map(|(d, _)| (k as f64, d))),
        )
        .collect();
    if known.is_empty() {
        return Err(BranchEditError::NoDepth);
    }
    let depths: Vec<f64> = (0..hits.len())
        .map(|k| {
            let x = k as f64;
            let after = known.partition_point(|&(at, _)| at < x);
            match (after.checked_sub(1).map(|i| known[i]), known.get(after)) {
                (Some((x0, d0)), Some(&(x1, d1))) if x1 > x0 => {
                    d0 + (d1 - d0) * (x - x0) / (x1 - x0)
                }
                (_, Some(&(_, d))) | (Some((_, d)), None) => d,
                (None, None) => known[0].1,
            }
        })
        .collect();
    let filtered = median_filter(&depths);
    let positions: Vec<Point3<f64>> = traced
        .iter()
        .zip(&hits)
        .zip(&filtered)
        .filter_map(|((pixel, hit), &depth)| match hit {
            Some((hit_depth, point))
                if (hit_depth - depth).abs() <= 3.0 * snap.spacing + radii.0 =>
            {
                let surface = snap.positions[*point as usize];
                Some(surface + view.ray_through(&surface) * radii.0)
            }
            _ => view.at_depth(pixel, depth),
        })
        .collect();
    add_branch(tree, parent, positions, radii)
}

/// DrawBranch in 3D: the stroke starts on an existing branch (within three of its radii or
/// four point spacings); each sample moves to the centroid of the snap points within three
/// spacings of its nearest snap point (the nearest 3D points trace it), or stays where it
/// was drawn when none is within four spacings.
pub fn draw_in_world(
    tree: &BranchTree,
    stroke: &[[f64; 3]],
    snap: &SnapPoints<'_>,
    radius: Option<[f64; 2]>,
) -> Result<BranchTree, BranchEditError> {
    let points: Vec<Point3<f64>> = stroke
        .iter()
        .map(|p| Point3::new(p[0], p[1], p[2]))
        .collect();
    if points.len() < 2
        || points.iter().any(|p| !p.iter().all(|c| c.is_finite()))
        || points.windows(2).all(|w| (w[1] - w[0]).norm() < 1e-12)
    {
        return Err(BranchEditError::InvalidStroke);
    }
    let length = crate::util::polyline::length(&points);
    let step = (2.0 * snap.spacing).max(length / MAX_STROKE_SAMPLES as f64);
    let samples = resample(
        &points,
        ((length / step).ceil() as usize + 1).clamp(2, MAX_STROKE_SAMPLES),
    );
    let parent = if tree.branches.is_empty() {
        None
    } else {
        let anchor = tree
            .closest(&samples[0])
            .ok_or(BranchEditError::NotOnBranch("empty tree".into()))?;
        let reach = (3.0 * anchor.radius).max(4.0 * snap.spacing);
        if anchor.distance > reach {
            return Err(BranchEditError::NotOnBranch(format!(
                "the nearest branch is {:.4} away, farther than {reach:.4}",
                anchor.distance
            )));
        }
        Some(anchor)
    };
    let radii = branch_radii(tree, parent.as_ref(), radius, snap.spacing, Some(length))?;
    let traced = if parent.is_some() {
        &samples[1..]
    } else {
        &samples[..]
    };
    let positions = traced
        .iter()
        .map(|sample| {
            let nearest = snap
                .candidates
                .iter()
                .map(|&i| (snap.positions[i as usize] - sample).norm_squared())
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match nearest {
                Some((k, d2)) if d2.sqrt() <= 4.0 * snap.spacing => {
                    let centre = snap.positions[snap.candidates[k] as usize];
                    let near: Vec<&Point3<f64>> = snap
                        .candidates
                        .iter()
                        .map(|&i| &snap.positions[i as usize])
                        .filter(|p| (*p - centre).norm() <= 3.0 * snap.spacing)
                        .collect();
                    let sum: Vector3<f64> = near.iter().map(|p| p.coords).sum();
                    Point3::from(sum / near.len() as f64)
                }
                _ => *sample,
            }
        })
        .collect();
    add_branch(tree, parent, positions, radii)
}

/// Radii of a new branch: the given ones (checked), else from the parent's radius at the
/// attachment by the pipe model (Leonardo's rule: a parent's cross-section is shared by what
/// it carries): with n children already on the parent, the new one starts at the parent's
/// radius / √(n + 2), 0.71 of it for a first side branch and 0.29 for a petiole drawn from a
/// stem that carries ten; a main stem gets 2 % of its length (at least a point spacing). It
/// tapers to half its start.
fn branch_radii(
    tree: &BranchTree,
    parent: Option<&BranchPoint>,
    radius: Option<[f64; 2]>,
    spacing: f64,
    length: Option<f64>,
) -> Result<(f64, f64), BranchEditError> {
    if let Some([start, end]) = radius {
        return Ok((check_radius(start)?, check_radius(end)?));
    }
    let start = match parent {
        Some(anchor) => {
            let children = tree
                .branches
                .iter()
                .filter(|b| b.parent == Some(anchor.branch))
                .count();
            anchor.radius / ((children + 2) as f64).sqrt()
        }
        None => (0.02 * length.unwrap_or(0.0)).max(spacing),
    }
    .max(1e-9);
    Ok((start, 0.5 * start))
}

/// Appends a branch through the traced positions (after the attachment point, when there is
/// a parent): control points every eighth of its length or so (2 to 8), each the mean of the
/// traced positions around it, which smooths the pick noise.
fn add_branch(
    tree: &BranchTree,
    parent: Option<BranchPoint>,
    positions: Vec<Point3<f64>>,
    radii: (f64, f64),
) -> Result<BranchTree, BranchEditError> {
    let mut polyline: Vec<Point3<f64>> = parent.iter().map(|a| a.position).collect();
    for p in positions {
        if polyline.last().is_none_or(|last| (p - last).norm() > 1e-12) {
            polyline.push(p);
        }
    }
    if polyline.len() < 2 {
        return Err(BranchEditError::InvalidStroke);
    }
    let cumulative: Vec<f64> = std::iter::once(0.0)
        .chain(polyline.windows(2).scan(0.0, |total, w| {
            *total += (w[1] - w[0]).norm();
            Some(*total)
        }))
        .collect();
    let length = cumulative[cumulative.len() - 1];
    let count = (polyline.len() / 4 + 2).clamp(2, 8);
    let half_window = 0.5 * length / (count - 1) as f64;
    let even = resample(&polyline, count);
    let mut control_points: Vec<Point3<f64>> = Vec::with_capacity(count);
    for (k, fallback) in even.iter().enumerate() {
        let point = if k == 0 {
            polyline[0]
        } else if k + 1 == count {
            polyline[polyline.len() - 1]
        } else {
            let target = length * k as f64 / (count - 1) as f64;
            let window: Vec<&Point3<f64>> = polyline
                .iter()
                .zip(&cumulative)
                .filter(|(_, c)| (*c - target).abs() <= half_window)
                .map(|(p, _)| p)
                .collect();
            if window.is_empty() {
                *fallback
            } else {
                Point3::from(
                    window.iter().map(|p| p.coords).sum::<Vector3<f64>>() / window.len() as f64,
                )
            }
        };
        if control_points
            .last()
            .is_none_or(|last| (point - last).norm() > 1e-9 * length.max(1e-9))
        {
            control_points.push(point);
        }
    }
    let skeleton = Spline::new(control_points)?;
    let mut edited = tree.clone();
    edited.branches.push(Branch {
        id: tree.next_id(),
        parent: parent.map(|a| a.branch),
        parent_fraction: parent.map_or(0.0, |a| a.fraction),
        cylinder: GeneralizedCylinder::new(skeleton, radii.0, radii.1),
        leaf_at_tip: false,
    });
    Ok(edited)
}

/// MoveBranch: control point `index` of `branch` goes to `position`. A child's first control
/// point slides along its parent to the parent's point nearest `position`; the branch's
/// children follow it.
pub fn move_control_point(
    tree: &BranchTree,
    branch: u32,
    index: usize,
    position: Point3<f64>,
) -> Result<BranchTree, BranchEditError> {
    if !position.iter().all(|c| c.is_finite()) {
        return Err(BranchEditError::InvalidStroke);
    }
    let mut edited = tree.clone();
    let current = tree
        .get(branch)
        .ok_or(BranchEditError::UnknownBranch(branch))?;
    let count = current.cylinder.skeleton.control_points().len();
    if index >= count {
        return Err(BranchEditError::UnknownControlPoint {
            branch,
            index,
            count,
        });
    }
    let mut target = position;
    let mut fraction = current.parent_fraction;
    if index == 0
        && let Some(parent) = current.parent.and_then(|p| tree.get(p))
    {
        fraction = parent.cylinder.skeleton.closest_fraction(&position).0;
        target = parent.cylinder.skeleton.point_at_fraction(fraction);
    }
    let edited_branch = branch_mut(&mut edited, branch)?;
    let mut points = edited_branch.cylinder.skeleton.control_points().to_vec();
    points[index] = target;
    edited_branch.cylinder.skeleton = Spline::new(points)?;
    edited_branch.parent_fraction = fraction;
    edited.reattach_children(branch)?;
    Ok(edited)
}

/// SetRadius at one end of a branch.
pub fn set_radius(
    tree: &BranchTree,
    branch: u32,
    end: BranchEnd,
    radius: f64,
) -> Result<BranchTree, BranchEditError> {
    let radius = check_radius(radius)?;
    let mut edited = tree.clone();
    let cylinder = &mut branch_mut(&mut edited, branch)?.cylinder;
    match end {
        BranchEnd::Start => cylinder.radius_start = radius,
        BranchEnd::End => cylinder.radius_end = radius,
    }
    Ok(edited)
}

/// SetLeafAtTip.
pub fn set_leaf_at_tip(
    tree: &BranchTree,
    branch: u32,
    enabled: bool,
) -> Result<BranchTree, BranchEditError> {
    let mut edited = tree.clone();
    branch_mut(&mut edited, branch)?.leaf_at_tip = enabled;
    Ok(edited)
}

/// DeleteBranch: the branch and its descendants.
pub fn delete_branch(tree: &BranchTree, branch: u32) -> Result<BranchTree, BranchEditError> {
    tree.get(branch)
        .ok_or(BranchEditError::UnknownBranch(branch))?;
    let gone = tree.subtree(branch);
    Ok(BranchTree {
        branches: tree
            .branches
            .iter()
            .filter(|b| !gone.contains(&b.id))
            .cloned()
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight(id: u32, parent: Option<u32>, a: [f64; 3], b: [f64; 3], radius: f64) -> Branch {
        let (a, b) = (Point3::from(a), Point3::from(b));
        let spline = Spline::new(vec![a, Point3::from((a.coords + b.coords) * 0.5), b]).unwrap();
        Branch {
            id,
            parent,
            parent_fraction: 0.5,
            cylinder: GeneralizedCylinder::new(spline, radius, radius),
            leaf_at_tip: false,
        }
    }

    #[test]
    fn a_drawn_branch_shares_its_parent_with_its_siblings() {
        let anchor = |branch: u32| BranchPoint {
            branch,
            fraction: 0.5,
            position: Point3::origin(),
            tangent: Vector3::z(),
            radius: 0.012,
            distance: 0.0,
        };
        let mut tree = BranchTree {
            branches: vec![straight(0, None, [0.0; 3], [0.0, 0.0, 0.1], 0.012)],
        };
        // A first side branch: 1/√2 of its parent, tapering to half.
        let (start, end) = branch_radii(&tree, Some(&anchor(0)), None, 1e-3, None).unwrap();
        assert!((start - 0.012 / 2f64.sqrt()).abs() < 1e-12 && (end - 0.5 * start).abs() < 1e-15);
        // Ten petioles already on the stem: the eleventh gets 1/√12 of it (3.5 mm, not 8.4).
        for id in 1..=10 {
            tree.branches
                .push(straight(id, Some(0), [0.0; 3], [0.1, 0.0, 0.1], 0.003));
        }
        let (start, _) = branch_radii(&tree, Some(&anchor(0)), None, 1e-3, None).unwrap();
        assert!((start - 0.012 / 12f64.sqrt()).abs() < 1e-12, "{start}");
        // Children of other branches do not count; given radii are kept; a stem gets 2 % of
        // its length.
        let (start, _) = branch_radii(&tree, Some(&anchor(3)), None, 1e-3, None).unwrap();
        assert!((start - 0.012 / 2f64.sqrt()).abs() < 1e-12);
        let given = branch_radii(&tree, Some(&anchor(0)), Some([0.004, 0.002]), 1e-3, None);
        assert_eq!(given.unwrap(), (0.004, 0.002));
        let (stem, _) = branch_radii(&tree, None, None, 1e-3, Some(0.3)).unwrap();
        assert!((stem - 0.006).abs() < 1e-12);
    }

    /// A pinhole 400 px wide looking down +z from z = −1 at the plane z = 0 (200 px per
    /// unit there).
    fn view() -> StrokeView {
        StrokeView::from_view_camera(&ViewCameraRecord {
            rotation: [1.0, 0.0, 0.0, 0.0],
            translation: [0.0, 0.0, 1.0],
            focal_px: 200.0,
            width: 400,
            height: 400,
        })
        .unwrap()
    }

    #[test]
    fn a_thin_branch_over_a_thick_one_is_picked_on_its_own_axis() {
        // A thick vertical stem (radius 0.1 = 20 px) and a thin branch crossing it
        // horizontally at y = 0.25.
        let tree = BranchTree {
            branches: vec![
                straight(0, None, [0.0, -0.5, 0.0], [0.0, 0.5, 0.0], 0.1),
                straight(1, Some(0), [-0.4, 0.25, 0.0], [0.4, 0.25, 0.0], 0.005),
            ],
        };
        let view = view();
        let pixel_of = |x: f64, y: f64| Point2::new(200.0 + 200.0 * x, 200.0 + 200.0 * y);
        // On the thin branch's axis, inside the stem's silhouette: the thin branch.
        let picked = pick_branch(&tree, &view, &pixel_of(0.05, 0.25), 8.0).unwrap();
        assert_eq!(picked.branch, 1);
        assert!(
            (picked.fraction - (0.45 / 0.8)).abs() < 0.01,
            "{}",
            picked.fraction
        );
        // Inside the stem away from the thin branch: the stem.
        let picked = pick_branch(&tree, &view, &pixel_of(0.05, -0.2), 8.0).unwrap();
        assert_eq!(picked.branch, 0);
        assert!((picked.fraction - 0.3).abs() < 0.01, "{}", picked.fraction);
        // Beyond the tolerance from both: nothing.
        assert!(pick_branch(&tree, &view, &pixel_of(-0.3, -0.3), 8.0).is_none());
    }
}
