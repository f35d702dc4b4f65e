//! Fitting the generic leaf to one segment (seed 004 §6.2): flat fit by PCA and scaling,
//! orientation (facing up and away from the plant's axis, base toward the stem), boundary
//! warp by affine ICP against the back-projected image boundary, deformation out of the plane
//! toward the points, and texture from the best view.

use crate::util::geometry::distance_from_axis;
use nalgebra::{Matrix2, Matrix3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::template::LeafTemplate;
use crate::graph::shape::Shape;
use crate::mesh::TriMesh;
use crate::util::geometry::cubic_monomials;
use crate::util::polygon::{inside_polygon, polygon_area};
use crate::util::stats::quantile;

/// The boundary warp may shrink the points' flat fit to a third of its area (a segment whose
/// points spill over the leaf's margin) ...
const MIN_WARP_AREA_RATIO: f64 = 0.33;

/// ... and grow it threefold, or further where the image boundary itself encloses more: from
/// photos, stereo often samples only part of a weakly textured leaf (on medium seed 3, leaves
/// whose points cover 5 % of them), while the boundary follows the leaf's colour one superpixel
/// beyond the points (its own guard against bleeding, [`crate::segment::boundary`]). A warp
/// that grows the leaf half as much again as the boundary encloses has run off it.
fn max_warp_area_ratio(boundary_area: f64, flat_area: f64) -> f64 {
    let enclosed = if flat_area > 0.0 {
        boundary_area / flat_area
    } else {
        0.0
    };
    (1.5 * enclosed).max(3.0)
}

/// Fitting settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeafFitOptions {
    /// Register the outline to the image boundary (affine ICP).
    pub use_boundary: bool,
    /// Bend the leaf out of its plane toward the points.
    pub deform: bool,
    /// ICP stops when the mean distance falls below this fraction of the leaf length…
    pub icp_tolerance: f64,
    /// …or after this many iterations.
    pub icp_iterations: usize,
    /// Share of correspondences kept in each direction, the closest ones (trimmed ICP):
    /// notches an occluder cuts into the image boundary do not pull the outline in.
    pub icp_inlier_share: f64,
    /// Largest texture tile (texels); a leaf gets the power of two that matches its size in
    /// the photo it is textured from (at least 16), no more.
    pub texture_size: u32,
}

impl Default for LeafFitOptions {
    fn default() -> Self {
        Self {
            use_boundary: true,
            deform: true,
            icp_tolerance: 0.004,
            icp_iterations: 40,
            icp_inlier_share: 1.0,
            texture_size: 128,
        }
    }
}

/// Why a segment got no leaf.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("{0} points: too few to pose a leaf (left for the branch stage)")]
    TooFewPoints(usize),
    #[error("the points are collinear or coincident: no leaf plane")]
    Degenerate,
    #[error("no generic leaf to fit")]
    NoGenericLeaf,
}

/// The leaf's frame: origin at the points' centroid, x from base to tip, z the normal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LeafFrame {
    pub origin: Point3<f64>,
    pub x_axis: Vector3<f64>,
    pub y_axis: Vector3<f64>,
    pub normal: Vector3<f64>,
}

impl LeafFrame {
    pub fn to_plane(&self, p: &Point3<f64>) -> (Point2<f64>, f64) {
        let d = p - self.origin;
        (
            Point2::new(d.dot(&self.x_axis), d.dot(&self.y_axis)),
            d.dot(&self.normal),
        )
    }

    pub fn to_world(&self, q: &Point2<f64>, height: f64) -> Point3<f64> {
        self.origin + self.x_axis * q.x + self.y_axis * q.y + self.normal * height
    }

    /// Where the viewing ray through `uv_image` meets the leaf plane, in plane coordinates;
    /// `None` behind the camera, or where the ray grazes the plane (|cos| under 0.15).
    pub fn back_project(
        &self,
        uv_image: &Point2<f64>,
        camera: &crate::scene::Camera,
        camera_from_world: &nalgebra::Isometry3<f64>,
    ) -> Option<Point2<f64>> {
        let ray_camera = camera.unproject(uv_image)?;
        let world_from_camera = camera_from_world.inverse();
        let origin = world_from_camera * Point3::origin();
        let direction = (world_from_camera.rotation * ray_camera).normalize();
        let denominator = direction.dot(&self.normal);
        if denominator.abs() < 0.15 {
            return None;
        }
        let t = (self.origin - origin).dot(&self.normal) / denominator;
        (t > 0.0).then(|| self.to_plane(&(origin + direction * t)).0)
    }
}

/// Where the plant is, for the orientation of leaves: they face up and away from what they
/// grow from, base toward it.
#[derive(Clone, Debug)]
pub struct PlantContext {
    pub up: Vector3<f64>,
    /// A point on the plant's vertical axis.
    pub axis_point: Point3<f64>,
    /// Branch tips (empty before there are any: the vertical axis then stands in for them).
    pub support: Vec<Point3<f64>>,
}

impl PlantContext {
    /// The nearest branch tip to `p`, if there are branches.
    pub fn nearest_branch_point(&self, p: &Point3<f64>) -> Option<Point3<f64>> {
        self.support
            .iter()
            .min_by(|a, b| (*a - p).norm_squared().total_cmp(&(*b - p).norm_squared()))
            .copied()
    }

    /// The point on the plant's axis at p's height.
    pub fn axis_point_near(&self, p: &Point3<f64>) -> Point3<f64> {
        self.axis_point + self.up * self.up.dot(&(p - self.axis_point))
    }
}

/// A segment's image boundary in a view, for the boundary warp and the texture.
pub struct BoundaryView<'a> {
    /// Boundary polygon in pixels (COLMAP convention).
    pub polygon: &'a [[f64; 2]],
    pub camera: &'a crate::scene::Camera,
    pub camera_from_world: nalgebra::Isometry3<f64>,
    /// The photo, RGB.
    pub image: Option<&'a image::RgbImage>,
}

/// A smooth height field `h(x, y)` over the leaf plane: least-squares polynomial (planar,
/// quadratic or cubic by the number of points) with Huber reweighting, so outliers make no
/// spikes; evaluated values are clamped to the observed range plus a margin.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeightField {
    coefficients: Vec<f64>,
    scale: f64,
    min: f64,
    max: f64,
}

impl HeightField {
    pub fn flat() -> Self {
        Self {
            coefficients: vec![0.0],
            scale: 1.0,
            min: 0.0,
            max: 0.0,
        }
    }

    /// Fits `h` to samples `(x, y, h)`; `scale` normalises coordinates (the leaf length).
    pub fn fit(samples: &[(Point2<f64>, f64)], scale: f64) -> Self {
        let terms = match samples.len() {
            0..=9 => 1,
            10..=39 => 6,
            _ => 10,
        };
        if terms == 1 {
            return Self::flat();
        }
        let scale = scale.max(1e-9);
        let mut weights = vec![1.0; samples.len()];
        let mut coefficients = vec![0.0; terms];
        for _ in 0..3 {
            let mut a = nalgebra::DMatrix::<f64>::zeros(terms, terms);
            let mut b = nalgebra::DVector::<f64>::zeros(terms);
            for ((q, h), w) in samples.iter().zip(&weights) {
                let m = cubic_monomials(q.x / scale, q.y / scale);
                for i in 0..terms {
                    b[i] += w * m[i] * h;
                    for j in 0..terms {
                        a[(i, j)] += w * m[i] * m[j];
                    }
                }
            }
            for i in 0..terms {
                a[(i, i)] += 1e-9;
            }
            let Some(solution) = a.cholesky().map(|c| c.solve(&b)) else {
                return Self::flat();
            };
            coefficients = solution.iter().copied().collect();
            // Huber weights from the residuals' robust scale.
            let residuals: Vec<f64> = samples
                .iter()
                .map(|(q, h)| {
                    let m = cubic_monomials(q.x / scale, q.y / scale);
                    h - (0..terms).map(|i| coefficients[i] * m[i]).sum::<f64>()
                })
                .collect();
            let mut absolute: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
            absolute.sort_by(f64::total_cmp);
            let sigma = 1.4826 * absolute[absolute.len() / 2] + 1e-12;
            for (w, r) in weights.iter_mut().zip(&residuals) {
                let k = 1.5 * sigma;
                *w = if r.abs() <= k { 1.0 } else { k / r.abs() };
            }
        }
        let heights: Vec<f64> = samples.iter().map(|s| s.1).collect();
        let (min, max) = heights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
                (a.min(h), b.max(h))
            });
        let margin = 0.05 * scale;
        Self {
            coefficients,
            scale,
            min: min - margin,
            max: max + margin,
        }
    }

    pub fn at(&self, q: &Point2<f64>) -> f64 {
        let terms = self.coefficients.len();
        let m = cubic_monomials(q.x / self.scale, q.y / self.scale);
        let h: f64 = (0..terms).map(|i| self.coefficients[i] * m[i]).sum();
        h.clamp(self.min.min(0.0), self.max.max(0.0))
    }
}

/// A 2D affine map `q = M p + t` (template → leaf plane).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Affine2 {
    pub matrix: Matrix2<f64>,
    pub translation: Vector2<f64>,
}

impl Affine2 {
    pub fn apply(&self, p: &Point2<f64>) -> Point2<f64> {
        Point2::from(self.matrix * p.coords + self.translation)
    }

    /// Least-squares affine map taking `from[i]` to `to[i]`.
    pub fn fit(from: &[Point2<f64>], to: &[Point2<f64>]) -> Option<Self> {
        if from.len() < 3 {
            return None;
        }
        // Solve for rows of [M | t] with normal equations on (x, y, 1).
        let mut ata = Matrix3::zeros();
        let mut atx = Vector3::zeros();
        let mut aty = Vector3::zeros();
        for (p, q) in from.iter().zip(to) {
            let row = Vector3::new(p.x, p.y, 1.0);
            ata += row * row.transpose();
            atx += row * q.x;
            aty += row * q.y;
        }
        let inverse = ata.try_inverse()?;
        let (rx, ry) = (inverse * atx, inverse * aty);
        let matrix = Matrix2::new(rx.x, rx.y, ry.x, ry.y);
        let affine = Self {
            matrix,
            translation: Vector2::new(rx.z, ry.z),
        };
        (affine.matrix.determinant() > 1e-12 && affine.matrix.iter().all(|v| v.is_finite()))
            .then_some(affine)
    }
}

/// Closest point on a closed polyline.
fn closest_on_loop(p: &Point2<f64>, polygon: &[Point2<f64>]) -> Point2<f64> {
    let mut best = (f64::INFINITY, polygon[0]);
    for i in 0..polygon.len() {
        let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        let ab = b - a;
        let t = if ab.norm_squared() < 1e-24 {
            0.0
        } else {
            ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        };
        let c = a + ab * t;
        let d = (p - c).norm_squared();
        if d < best.0 {
            best = (d, c);
        }
    }
    best.1
}

/// Outcome of the boundary registration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IcpReport {
    pub iterations: usize,
    /// Mean symmetric distance between the warped outline and the boundary, relative to the
    /// leaf length, before and after.
    pub initial_distance: f64,
    pub final_distance: f64,
}

/// Correspondences from each point of `from` to its nearest point on the closed curve `to`
/// (or, with `to_points`, its nearest point of `to`), the closest `share` of them.
fn trimmed_pairs(
    from: &[Point2<f64>],
    to: &[Point2<f64>],
    to_points: bool,
    share: f64,
) -> Vec<(usize, Point2<f64>, f64)> {
    let mut pairs: Vec<(usize, Point2<f64>, f64)> = from
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let target = if to_points {
                to.iter()
                    .copied()
                    .min_by(|a, b| (a - p).norm_squared().total_cmp(&(b - p).norm_squared()))
                    .unwrap_or(*p)
            } else {
                closest_on_loop(p, to)
            };
            (i, target, (target - p).norm())
        })
        .collect();
    let keep = ((pairs.len() as f64 * share.clamp(0.1, 1.0)).ceil() as usize).max(3);
    if keep < pairs.len() {
        pairs.select_nth_unstable_by(keep, |a, b| a.2.total_cmp(&b.2));
        pairs.truncate(keep);
    }
    pairs
}

/// Affine ICP of two closed curves (seed 004 §6.2, after Besl & McKay 1992, for curves):
/// correspondences both ways (outline → nearest boundary point, and boundary → nearest
/// outline point, so the outline can neither shrink into part of the boundary nor swell
/// past it), the closest share of each kept (trimmed ICP, Chetverikov et al. 2002),
/// least-squares affine update, until the mean distance of the kept pairs falls below the
/// tolerance or stops improving.
pub fn register_outline(
    template_outline: &[Point2<f64>],
    boundary: &[Point2<f64>],
    initial: Affine2,
    length: f64,
    options: &LeafFitOptions,
) -> (Affine2, IcpReport) {
    let share = options.icp_inlier_share;
    let pairs = |affine: &Affine2| {
        let warped: Vec<Point2<f64>> = template_outline.iter().map(|p| affine.apply(p)).collect();
        let forward = trimmed_pairs(&warped, boundary, false, share);
        let backward = trimmed_pairs(boundary, &warped, true, share);
        (forward, backward)
    };
    let mean_distance = |forward: &[(usize, Point2<f64>, f64)],
                         backward: &[(usize, Point2<f64>, f64)]| {
        let mean = |v: &[(usize, Point2<f64>, f64)]| {
            v.iter().map(|x| x.2).sum::<f64>() / v.len().max(1) as f64
        };
        0.5 * (mean(forward) + mean(backward)) / length.max(1e-12)
    };
    let mut current = initial;
    let (mut forward, mut backward) = pairs(&current);
    let initial_distance = mean_distance(&forward, &backward);
    let mut distance = initial_distance;
    let mut iterations = 0;
    while iterations < options.icp_iterations && distance > options.icp_tolerance {
        iterations += 1;
        let warped: Vec<Point2<f64>> = template_outline.iter().map(|p| current.apply(p)).collect();
        let mut from = Vec::with_capacity(forward.len() + backward.len());
        let mut to = Vec::with_capacity(from.capacity());
        for (i, target, _) in &forward {
            from.push(template_outline[*i]);
            to.push(*target);
        }
        // Boundary → outline: the template point whose warped image is nearest.
        for (b, target, _) in &backward {
            if let Some(i) = warped.iter().position(|w| w == target) {
                from.push(template_outline[i]);
                to.push(boundary[*b]);
            }
        }
        let Some(next) = Affine2::fit(&from, &to) else {
            break;
        };
        let (next_forward, next_backward) = pairs(&next);
        let next_distance = mean_distance(&next_forward, &next_backward);
        if next_distance >= distance - 1e-6 {
            if next_distance < distance {
                current = next;
                distance = next_distance;
            }
            break;
        }
        current = next;
        distance = next_distance;
        forward = next_forward;
        backward = next_backward;
    }
    (
        current,
        IcpReport {
            iterations,
            initial_distance,
            final_distance: distance,
        },
    )
}

/// A fitted leaf.
#[derive(Clone, Debug, Serialize)]
pub struct FittedLeaf {
    pub frame: LeafFrame,
    pub affine: Affine2,
    pub heights: HeightField,
    /// The leaf surface in world coordinates; uvs span this leaf's texture tile [0, 1]².
    #[serde(skip)]
    pub mesh: TriMesh,
    #[serde(skip)]
    pub texture: image::RgbaImage,
    pub points: usize,
    /// RMS distance of the points to the fitted surface (metres).
    pub point_residual: f64,
    pub icp: Option<IcpReport>,
    /// Area enclosed by the back-projected image boundary on the leaf plane (m²), when used.
    pub boundary_area: Option<f64>,
    /// Area enclosed by the fitted outline on the leaf plane (m²).
    pub outline_area: f64,
    /// Length of the leaf along its midrib in the plane (metres).
    pub length: f64,
    /// Where the midrib starts (meets the petiole) and ends, world frame.
    pub base: [f64; 3],
    pub tip: [f64; 3],
    pub area: f64,
    /// Share of texels taken from the photo (the rest inherit the generic texture).
    pub textured_fraction: f64,
    pub notes: Vec<String>,
}

/// Intersects the viewing ray of a pixel with the leaf plane; `None` for rays nearly parallel
/// to the plane or hitting it behind the camera.
fn back_project(
    pixel: &Point2<f64>,
    view: &BoundaryView<'_>,
    frame: &LeafFrame,
) -> Option<Point2<f64>> {
    frame
        .back_project(pixel, view.camera, &view.camera_from_world)
        .filter(|q| q.x.is_finite() && q.y.is_finite())
}

/// Texels per side for a leaf's texture: about one texel per photo pixel along the leaf's
/// longer side (rounded up to a power of two, 16 to `max_size`); `max_size` without a photo.
fn texture_size_for(
    frame: &LeafFrame,
    affine: &Affine2,
    template: &LeafTemplate,
    boundary: Option<&BoundaryView<'_>>,
    max_size: u32,
) -> u32 {
    let max_size = max_size.max(16);
    let Some(view) = boundary.filter(|b| b.image.is_some()) else {
        return max_size;
    };
    let (lo, hi) = (template.texture_min, template.texture_max);
    let corners = [
        Point2::new(lo.x, lo.y),
        Point2::new(hi.x, lo.y),
        Point2::new(hi.x, hi.y),
        Point2::new(lo.x, hi.y),
    ];
    let pixels: Option<Vec<Point2<f64>>> = corners
        .iter()
        .map(|c| {
            let world = frame.to_world(&affine.apply(c), 0.0);
            view.camera
                .project(&(view.camera_from_world * world).coords)
        })
        .collect();
    let Some(pixels) = pixels else {
        return max_size;
    };
    // Longer side of the texture rectangle as seen in the photo.
    let side = |a: usize, b: usize| (pixels[a] - pixels[b]).norm();
    let longest = side(0, 1).max(side(1, 2)).max(side(2, 3)).max(side(3, 0));
    if !longest.is_finite() {
        return max_size;
    }
    (longest.ceil().max(1.0) as u32)
        .checked_next_power_of_two()
        .unwrap_or(max_size)
        .clamp(16, max_size)
}

fn sample_rgb(image: &image::RgbImage, pixel: &Point2<f64>) -> Option<[u8; 3]> {
    // COLMAP pixel centres are at +0.5: bilinear interpolation between centres.
    let (x, y) = (pixel.x - 0.5, pixel.y - 0.5);
    if x < 0.0 || y < 0.0 || x >= (image.width() - 1) as f64 || y >= (image.height() - 1) as f64 {
        return None;
    }
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let mut out = [0.0f64; 3];
    for (dx, dy, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let p = image.get_pixel(x0 + dx, y0 + dy);
        for c in 0..3 {
            out[c] += w * p[c] as f64;
        }
    }
    Some(out.map(|v| v.round().clamp(0.0, 255.0) as u8))
}

/// The frame of a point group: PCA axes, normal facing up and away from what the leaf grows
/// from (a branch ending near one of its ends, else the plant's axis), x from the end nearer it (the
/// base, where a leaf meets its petiole or stem) to the other.
pub fn leaf_frame(
    points: &[Point3<f64>],
    plant: &PlantContext,
) -> Result<(LeafFrame, Shape), FitError> {
    if points.len() < 3 {
        return Err(FitError::TooFewPoints(points.len()));
    }
    let shape = Shape::of(points.iter().copied());
    if shape.eigenvalues[1] <= 1e-14 * shape.eigenvalues[0].max(1e-300)
        || shape.eigenvalues[0] <= 0.0
    {
        return Err(FitError::Degenerate);
    }
    let mut x_axis = shape.axes[0];
    let mut along: Vec<f64> = points
        .iter()
        .map(|p| (p - shape.centroid).dot(&x_axis))
        .collect();
    let lo = quantile(&mut along, 0.02);
    let hi = quantile(&mut along, 0.98);
    let ends = [shape.centroid + x_axis * lo, shape.centroid + x_axis * hi];
    // What the leaf grows from: a branch ending within a quarter of the leaf's length of one
    // of its ends (its petiole); else the plant's axis (the skeleton may miss the leaf's
    // branch, and a branch merely passing by is often another leaf's).
    let branch_at_end = ends
        .iter()
        .filter_map(|end| {
            plant
                .nearest_branch_point(end)
                .map(|b| ((b - end).norm(), b))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .filter(|(distance, _)| *distance <= 0.25 * (hi - lo));
    let distance_to_support = |p: &Point3<f64>| match branch_at_end {
        Some((_, branch_point)) => (p - branch_point).norm(),
        None => distance_from_axis(p, &plant.axis_point_near(p), &plant.up),
    };
    let support = branch_at_end.map_or_else(|| plant.axis_point_near(&shape.centroid), |b| b.1);
    let away = shape.centroid - support;
    let outward = (away - plant.up * plant.up.dot(&away))
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::zeros);
    let mut normal = shape.normal();
    if normal.dot(&(plant.up + outward)) < 0.0 {
        normal = -normal;
    }
    // The base is the end nearer the support.
    if distance_to_support(&ends[1]) < distance_to_support(&ends[0]) {
        x_axis = -x_axis;
    }
    let y_axis = normal.cross(&x_axis).normalize();
    let x_axis = y_axis.cross(&normal).normalize();
    Ok((
        LeafFrame {
            origin: shape.centroid,
            x_axis,
            y_axis,
            normal,
        },
        shape,
    ))
}

/// Fits the template to a segment's points (and its boundary view when given).
pub fn fit_leaf(
    points: &[Point3<f64>],
    template: &LeafTemplate,
    plant: &PlantContext,
    boundary: Option<&BoundaryView<'_>>,
    options: &LeafFitOptions,
) -> Result<FittedLeaf, FitError> {
    let mut notes = Vec::new();
    let finite: Vec<Point3<f64>> = points
        .iter()
        .copied()
        .filter(|p| p.coords.iter().all(|c| c.is_finite()))
        .collect();
    if finite.len() < points.len() {
        notes.push(format!(
            "{} non-finite points ignored",
            points.len() - finite.len()
        ));
    }
    let points = &finite[..];
    let (frame, _) = leaf_frame(points, plant)?;
    let samples: Vec<(Point2<f64>, f64)> = points.iter().map(|p| frame.to_plane(p)).collect();
    // Flat fit: scale the template to the points' extent along the two axes.
    let mut xs: Vec<f64> = samples.iter().map(|s| s.0.x).collect();
    let mut ys: Vec<f64> = samples.iter().map(|s| s.0.y).collect();
    let (x_lo, x_hi) = (quantile(&mut xs, 0.01), quantile(&mut xs, 0.99));
    let (y_lo, y_hi) = (quantile(&mut ys, 0.01), quantile(&mut ys, 0.99));
    // Extend by half the mean point spacing: points stop short of the margin.
    let area_estimate = (x_hi - x_lo).max(1e-9) * (y_hi - y_lo).max(1e-9) * 0.7;
    let half_spacing = 0.5 * (area_estimate / points.len() as f64).sqrt();
    let (x_lo, x_hi, y_lo, y_hi) = (
        x_lo - half_spacing,
        x_hi + half_spacing,
        y_lo - half_spacing,
        y_hi + half_spacing,
    );
    let template_width = template.texture_max.y - template.texture_min.y;
    let scale_x = x_hi - x_lo;
    let scale_y = (y_hi - y_lo) / template_width.max(1e-9);
    let template_mid_y = 0.5 * (template.texture_min.y + template.texture_max.y);
    let mut affine = Affine2 {
        matrix: Matrix2::new(scale_x, 0.0, 0.0, scale_y),
        translation: Vector2::new(x_lo, 0.5 * (y_lo + y_hi) - scale_y * template_mid_y),
    };
    let length = scale_x;

    // Boundary warp: register the outline to the back-projected image boundary.
    let mut icp = None;
    let mut boundary_area = None;
    if options.use_boundary
        && let Some(view) = boundary
    {
        let projected: Vec<Point2<f64>> = view
            .polygon
            .iter()
            .filter_map(|p| back_project(&Point2::new(p[0], p[1]), view, &frame))
            .collect();
        let flat_area = affine.matrix.determinant().abs() * template.area();
        if view.polygon.len() < 3 {
            notes.push(format!(
                "boundary has {} vertices: no warp",
                view.polygon.len()
            ));
        } else if projected.len() >= 8
            && projected.len() * 10 >= view.polygon.len() * 8
            && polygon_area(&projected) < 0.05 * flat_area
        {
            notes.push("boundary encloses almost no area on the leaf plane: no warp".into());
        } else if projected.len() >= 8 && projected.len() * 10 >= view.polygon.len() * 8 {
            let dense = crate::util::polyline::resample(
                &{
                    let mut closed = projected.clone();
                    closed.push(projected[0]);
                    closed
                },
                150,
            );
            let enclosed = polygon_area(&projected);
            boundary_area = Some(enclosed);
            let outline = template.dense_outline(120);
            let (registered, report) = register_outline(&outline, &dense, affine, length, options);
            let area_ratio = registered.matrix.determinant() / affine.matrix.determinant();
            if (MIN_WARP_AREA_RATIO..=max_warp_area_ratio(enclosed, flat_area))
                .contains(&area_ratio)
                && report.final_distance <= report.initial_distance
            {
                affine = registered;
                icp = Some(report);
            } else {
                notes.push(format!("boundary warp rejected (area ×{area_ratio:.2})"));
            }
        } else {
            notes.push("boundary view too oblique for the warp".into());
        }
    }

    // Deformation perpendicular to the plane toward the points.
    let heights = if options.deform {
        HeightField::fit(&samples, length)
    } else {
        HeightField::flat()
    };
    let point_residual = (samples
        .iter()
        .map(|(q, h)| (h - heights.at(q)).powi(2))
        .sum::<f64>()
        / samples.len() as f64)
        .sqrt();

    // Mesh: resolution from the point density.
    let along = ((points.len() as f64).sqrt() * 1.2).clamp(6.0, 30.0) as usize;
    let across = if along > 14 { 9 } else { 7 };
    let (mut mesh, flat) = template.mesh(along, across);
    for (vertex, p) in mesh.positions.iter_mut().zip(&flat) {
        let q = affine.apply(p);
        *vertex = frame.to_world(&q, heights.at(&q)).cast::<f32>();
    }
    mesh.compute_normals();

    // Texture: the photo where the boundary region sees the leaf, else the generic texture.
    let size = texture_size_for(&frame, &affine, template, boundary, options.texture_size);
    let mut texture = image::RgbaImage::new(size, size);
    let mut from_photo = 0usize;
    let extent = template.texture_max - template.texture_min;
    for j in 0..size {
        for i in 0..size {
            let u = (i as f64 + 0.5) / size as f64;
            let v = (j as f64 + 0.5) / size as f64;
            let p = Point2::new(
                template.texture_min.x + u * extent.x,
                template.texture_max.y - v * extent.y,
            );
            let generic = {
                let (w, h) = template.texture.dimensions();
                if w == 0 || h == 0 {
                    image::Rgba([70, 130, 55, 255])
                } else {
                    *template.texture.get_pixel(
                        ((u * w as f64) as u32).min(w - 1),
                        ((v * h as f64) as u32).min(h - 1),
                    )
                }
            };
            let mut texel = image::Rgba([generic[0], generic[1], generic[2], 255]);
            if let Some(view) = boundary
                && let Some(photo) = view.image
            {
                let q = affine.apply(&p);
                let world = frame.to_world(&q, heights.at(&q));
                let camera_point = view.camera_from_world * world;
                if let Some(pixel) = view.camera.project(&camera_point.coords)
                    && inside_polygon(&pixel, view.polygon)
                    && let Some(rgb) = sample_rgb(photo, &pixel)
                {
                    texel = image::Rgba([rgb[0], rgb[1], rgb[2], 255]);
                    from_photo += 1;
                }
            }
            texture.put_pixel(i, j, texel);
        }
    }
    let area = mesh.area();
    let outline_area = polygon_area(
        &template
            .dense_outline(120)
            .iter()
            .map(|p| affine.apply(p))
            .collect::<Vec<_>>(),
    );
    let on_surface = |template_point: Point2<f64>| {
        let q = affine.apply(&template_point);
        let p = frame.to_world(&q, heights.at(&q));
        [p.x, p.y, p.z]
    };
    let base = on_surface(Point2::new(0.0, template.midrib[0].y));
    let tip = on_surface(Point2::new(
        1.0,
        template.midrib[template.midrib.len() - 1].y,
    ));
    Ok(FittedLeaf {
        frame,
        affine,
        heights,
        mesh,
        texture,
        points: points.len(),
        point_residual,
        icp,
        boundary_area,
        outline_area,
        length,
        base,
        tip,
        area,
        textured_fraction: from_photo as f64 / (size * size) as f64,
        notes,
    })
}

/// [`fit_leaf`] with the first of `templates` (the generic leaf) and, where that fit's outline
/// is registered to the image boundary, with each other one (alternative generic leaves): the
/// fit whose registered outline lies nearest the boundary (final ICP distance, relative to the
/// leaf length) is kept, and its notes name the alternative it took. One generic outline for
/// every leaf stretched elliptic leaves fitted with an ovate one: the outline's wide part sat
/// on the leaf's, its tip ran past the leaf's by up to 24 mm and its base stopped short.
pub fn fit_leaf_best_outline(
    points: &[Point3<f64>],
    templates: &[&LeafTemplate],
    plant: &PlantContext,
    boundary: Option<&BoundaryView<'_>>,
    options: &LeafFitOptions,
) -> Result<FittedLeaf, FitError> {
    let Some((first, others)) = templates.split_first() else {
        return Err(FitError::NoGenericLeaf);
    };
    let mut fitted = fit_leaf(points, first, plant, boundary, options)?;
    for (k, template) in others.iter().enumerate() {
        let Some(best) = fitted.icp.map(|icp| icp.final_distance) else {
            break;
        };
        if let Ok(mut other) = fit_leaf(points, template, plant, boundary, options)
            && other.icp.is_some_and(|icp| icp.final_distance < best)
        {
            other
                .notes
                .push(format!("outline of alternative generic leaf {}", k + 1));
            fitted = other;
        }
    }
    Ok(fitted)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn affine_fit_recovers_a_map() {
        let truth = Affine2 {
            matrix: Matrix2::new(2.0, 0.3, -0.2, 0.7),
            translation: Vector2::new(1.0, -3.0),
        };
        let from: Vec<Point2<f64>> = (0..20)
            .map(|k| Point2::new((k as f64).sin(), (k as f64 * 0.7).cos()))
            .collect();
        let to: Vec<Point2<f64>> = from.iter().map(|p| truth.apply(p)).collect();
        let found = Affine2::fit(&from, &to).unwrap();
        assert!((found.matrix - truth.matrix).norm() < 1e-9);
        assert!((found.translation - truth.translation).norm() < 1e-9);
    }

    #[test]
    fn icp_registers_a_scaled_ellipse() {
        let outline: Vec<Point2<f64>> = (0..120)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 120.0;
                Point2::new(0.5 + 0.5 * t.cos(), 0.2 * t.sin())
            })
            .collect();
        let truth = Affine2 {
            matrix: Matrix2::new(0.12, 0.01, -0.005, 0.09),
            translation: Vector2::new(-0.05, 0.01),
        };
        let boundary: Vec<Point2<f64>> = (0..150)
            .map(|k| {
                let t = std::f64::consts::TAU * (k as f64 + 0.3) / 150.0;
                truth.apply(&Point2::new(0.5 + 0.5 * t.cos(), 0.2 * t.sin()))
            })
            .collect();
        let initial = Affine2 {
            matrix: Matrix2::new(0.1, 0.0, 0.0, 0.1),
            translation: Vector2::new(-0.04, 0.0),
        };
        let (found, report) = register_outline(
            &outline,
            &boundary,
            initial,
            0.12,
            &LeafFitOptions::default(),
        );
        assert!(report.final_distance < 0.01, "{report:?}");
        assert!(report.final_distance < report.initial_distance);
        let corner = Point2::new(1.0, 0.0);
        assert!((found.apply(&corner) - truth.apply(&corner)).norm() < 0.004);
    }

    #[test]
    fn height_field_ignores_an_outlier_and_follows_a_bend() {
        let mut rng = Rng::seed_from(2);
        let mut samples: Vec<(Point2<f64>, f64)> = (0..400)
            .map(|_| {
                let q = Point2::new(rng.range(-0.1, 0.1), rng.range(-0.05, 0.05));
                (q, -2.0 * q.x * q.x)
            })
            .collect();
        samples.push((Point2::new(0.0, 0.0), 0.05));
        let field = HeightField::fit(&samples, 0.2);
        assert!(field.at(&Point2::new(0.0, 0.0)).abs() < 1e-3);
        assert!((field.at(&Point2::new(0.08, 0.0)) + 2.0 * 0.0064).abs() < 1e-3);
    }

    #[test]
    fn frame_faces_up_and_away_with_the_base_toward_the_axis() {
        // A horizontal leaf east of the axis, extending outward.
        let points: Vec<Point3<f64>> = (0..200)
            .map(|k| Point3::new(0.1 + 0.002 * (k % 50) as f64, 0.001 * (k / 50) as f64, 0.3))
            .collect();
        let plant = PlantContext {
            up: Vector3::z(),
            axis_point: Point3::origin(),
            support: Vec::new(),
        };
        let (frame, _) = leaf_frame(&points, &plant).unwrap();
        assert!(frame.normal.z > 0.99);
        assert!(frame.x_axis.x > 0.99, "x runs outward from the base");
        assert!(leaf_frame(&points[..2], &plant).is_err());
        let line: Vec<Point3<f64>> = (0..10).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        assert_eq!(leaf_frame(&line, &plant).unwrap_err(), FitError::Degenerate);
    }

    /// A tilted elliptic leaf 0.1 m x 0.04 m, 15 cm east of the axis, as points; a camera
    /// above it looking down, and the ellipse's outline as the image boundary.
    fn leaf_scene() -> (
        Vec<Point3<f64>>,
        crate::scene::Camera,
        nalgebra::Isometry3<f64>,
    ) {
        let mut rng = Rng::seed_from(5);
        let points = (0..400)
            .filter_map(|_| {
                let (u, v) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                (u * u + v * v <= 1.0)
                    .then(|| Point3::new(0.15 + 0.05 * u, 0.02 * v, 0.3 + 0.01 * u))
            })
            .collect();
        let camera = crate::scene::Camera::simple_pinhole(1, 800, 600, 900.0);
        // Camera 0.5 m above the leaf looking straight down (camera z = world −z).
        let camera_from_world = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(-0.15, 0.0, 0.8),
            nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        (points, camera, camera_from_world)
    }

    /// The outline of [`leaf_scene`]'s leaf as the camera sees it (the image boundary).
    fn leaf_outline_in_view(
        camera: &crate::scene::Camera,
        camera_from_world: &nalgebra::Isometry3<f64>,
    ) -> Vec<[f64; 2]> {
        (0..100)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 100.0;
                let p = Point3::new(0.15 + 0.05 * t.cos(), 0.02 * t.sin(), 0.3 + 0.01 * t.cos());
                let pixel = camera.project(&(camera_from_world * p).coords).unwrap();
                [pixel.x, pixel.y]
            })
            .collect()
    }

    fn ellipse_template() -> LeafTemplate {
        let outline: Vec<Point2<f64>> = (0..64)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 64.0;
                Point2::new(0.5 + 0.5 * t.cos(), 0.2 * t.sin())
            })
            .collect();
        LeafTemplate::from_outline(&outline, LeafTemplate::plain_texture(32)).unwrap()
    }

    fn plant() -> PlantContext {
        PlantContext {
            up: Vector3::z(),
            axis_point: Point3::origin(),
            support: Vec::new(),
        }
    }

    #[test]
    fn a_leaf_takes_the_generic_outline_that_fits_its_boundary() {
        // An elliptic leaf, and an ovate generic leaf (widest near its base) beside the
        // elliptic one: fitted with the ovate outline alone, the leaf's ends move.
        let (points, camera, camera_from_world) = leaf_scene();
        let polygon = leaf_outline_in_view(&camera, &camera_from_world);
        let view = BoundaryView {
            polygon: &polygon,
            camera: &camera,
            camera_from_world,
            image: None,
        };
        let ovate: Vec<Point2<f64>> = (0..64)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 64.0;
                Point2::new(0.5 + 0.5 * t.cos(), 0.2 * t.sin() * (1.0 - 0.6 * t.cos()))
            })
            .collect();
        let ovate = LeafTemplate::from_outline(&ovate, LeafTemplate::plain_texture(32)).unwrap();
        let ellipse = ellipse_template();
        let options = LeafFitOptions::default();
        let fit = |templates: &[&LeafTemplate]| {
            fit_leaf_best_outline(&points, templates, &plant(), Some(&view), &options).unwrap()
        };
        // The leaf runs 0.1 m along x and rises 0.02 m over it.
        let truth = (0.1f64 * 0.1 + 0.02 * 0.02).sqrt();
        let length_error = |f: &FittedLeaf| {
            let (base, tip) = (Point3::from(f.base), Point3::from(f.tip));
            ((tip - base).norm() / truth - 1.0).abs()
        };
        let alone = fit(&[&ovate]);
        let best = fit(&[&ovate, &ellipse]);
        eprintln!(
            "length error: ovate alone {:.4}, best of two {:.4}; ICP {:?} vs {:?}",
            length_error(&alone),
            length_error(&best),
            alone.icp,
            best.icp
        );
        assert!(
            best.notes
                .iter()
                .any(|n| n.contains("alternative generic leaf 1")),
            "{:?}",
            best.notes
        );
        assert!(best.icp.unwrap().final_distance < alone.icp.unwrap().final_distance);
        assert!(length_error(&best) < 0.5 * length_error(&alone));
        // The generic leaf keeps a leaf it fits best, and without a boundary there is no
        // choice to make.
        let kept = fit(&[&ellipse, &ovate]);
        assert!(
            !kept.notes.iter().any(|n| n.contains("alternative")),
            "{:?}",
            kept.notes
        );
        let blind =
            fit_leaf_best_outline(&points, &[&ovate, &ellipse], &plant(), None, &options).unwrap();
        assert!(!blind.notes.iter().any(|n| n.contains("alternative")));
        assert!(matches!(
            fit_leaf_best_outline(&points, &[], &plant(), None, &options),
            Err(FitError::NoGenericLeaf)
        ));
    }

    #[test]
    fn boundary_warp_recovers_the_outline_area() {
        let (points, camera, camera_from_world) = leaf_scene();
        let polygon = leaf_outline_in_view(&camera, &camera_from_world);
        let photo = image::RgbImage::from_pixel(800, 600, image::Rgb([10, 200, 30]));
        let view = BoundaryView {
            polygon: &polygon,
            camera: &camera,
            camera_from_world,
            image: Some(&photo),
        };
        let options = LeafFitOptions::default();
        let fit = fit_leaf(
            &points,
            &ellipse_template(),
            &plant(),
            Some(&view),
            &options,
        )
        .unwrap();
        let truth = std::f64::consts::PI * 0.05 * 0.02 * (1.0f64 + 0.04).sqrt();
        assert!(fit.icp.is_some(), "{:?}", fit.notes);
        assert!(
            (fit.outline_area / truth - 1.0).abs() < 0.06,
            "outline {} vs {truth}",
            fit.outline_area
        );
        assert!(fit.textured_fraction > 0.5);
        let texel = fit
            .texture
            .get_pixel(fit.texture.width() / 2, fit.texture.height() / 2);
        assert_eq!((texel[0], texel[1], texel[2]), (10, 200, 30));
        // About one texel per photo pixel: the leaf spans ~90 px here.
        assert_eq!(fit.texture.width(), 128);
        assert!(
            fit.mesh
                .positions
                .iter()
                .all(|p| p.iter().all(|c| c.is_finite()))
        );
    }

    #[test]
    fn a_leaf_sampled_on_a_small_patch_grows_to_its_image_boundary() {
        // Stereo sampled only the leaf's middle fifth along its length, a third of its width.
        let (points, camera, camera_from_world) = leaf_scene();
        let patch: Vec<Point3<f64>> = points
            .into_iter()
            .filter(|p| (p.x - 0.15).abs() < 0.01 && p.y.abs() < 0.007)
            .collect();
        assert!(patch.len() >= 20, "{} points", patch.len());
        let polygon = leaf_outline_in_view(&camera, &camera_from_world);
        let view = BoundaryView {
            polygon: &polygon,
            camera: &camera,
            camera_from_world,
            image: None,
        };
        let fit = fit_leaf(
            &patch,
            &ellipse_template(),
            &plant(),
            Some(&view),
            &LeafFitOptions::default(),
        )
        .unwrap();
        let truth = std::f64::consts::PI * 0.05 * 0.02 * (1.0f64 + 0.04).sqrt();
        // The points' own extent is about a tenth of the leaf; the warp takes the boundary.
        assert!(fit.icp.is_some(), "{:?}", fit.notes);
        assert!(
            (fit.outline_area / truth - 1.0).abs() < 0.15,
            "outline {} vs {truth}",
            fit.outline_area
        );
        // The bound grows with what the boundary encloses, never below threefold.
        assert!((max_warp_area_ratio(0.0, 1.0) - 3.0).abs() < 1e-12);
        assert!((max_warp_area_ratio(10.0, 1.0) - 15.0).abs() < 1e-12);
        assert!((max_warp_area_ratio(1.0, 0.0) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_refused_or_noted_never_a_panic() {
        let (points, camera, camera_from_world) = leaf_scene();
        let template = ellipse_template();
        let options = LeafFitOptions::default();
        let fit = |points: &[Point3<f64>], view: Option<&BoundaryView<'_>>| {
            fit_leaf(points, &template, &plant(), view, &options)
        };
        // Too few points: left for the branch stage.
        for n in 0..3 {
            assert_eq!(
                fit(&points[..n], None).unwrap_err(),
                FitError::TooFewPoints(n)
            );
        }
        // Collinear and coincident points: no plane.
        let line: Vec<Point3<f64>> = (0..30)
            .map(|k| Point3::new(0.1 + 0.01 * k as f64, 0.0, 0.3))
            .collect();
        assert_eq!(fit(&line, None).unwrap_err(), FitError::Degenerate);
        let same = vec![Point3::new(0.1, 0.2, 0.3); 20];
        assert_eq!(fit(&same, None).unwrap_err(), FitError::Degenerate);
        // Non-finite points are dropped and noted; too few finite ones is too few points.
        let mut noisy = points.clone();
        noisy[3] = Point3::new(f64::NAN, 0.0, 0.0);
        noisy[7] = Point3::new(0.0, f64::INFINITY, 0.0);
        let fitted = fit(&noisy, None).unwrap();
        assert!(fitted.notes.iter().any(|n| n.contains("2 non-finite")));
        let nan = [Point3::new(f64::NAN, 0.0, 0.0); 5];
        assert_eq!(fit(&nan, None).unwrap_err(), FitError::TooFewPoints(0));
        // Open or empty boundaries, a boundary of NaNs, one behind the camera, and no photo:
        // the leaf is still posed from its points, and the note says why the warp was skipped.
        let open = [[400.0, 300.0], [420.0, 310.0]];
        let flat: Vec<[f64; 2]> = (0..20).map(|k| [300.0 + 10.0 * k as f64, 300.0]).collect();
        let nans = vec![[f64::NAN, 1.0]; 20];
        let behind_pose = nalgebra::Isometry3::translation(0.0, 0.0, -2.0) * camera_from_world;
        for (polygon, pose, expected) in [
            (&open[..], camera_from_world, "2 vertices"),
            (&flat[..], camera_from_world, "no area"),
            (&nans[..], camera_from_world, "oblique"),
            (&flat[..], behind_pose, "oblique"),
        ] {
            let view = BoundaryView {
                polygon,
                camera: &camera,
                camera_from_world: pose,
                image: None,
            };
            let fitted = fit(&points, Some(&view)).unwrap();
            assert!(fitted.icp.is_none());
            assert!(
                fitted.notes.iter().any(|n| n.contains(expected)),
                "{expected}: {:?}",
                fitted.notes
            );
            assert_eq!(fitted.textured_fraction, 0.0);
            assert!(
                fitted
                    .mesh
                    .positions
                    .iter()
                    .all(|p| p.iter().all(|c| c.is_finite()))
            );
        }
    }
}
