//! Rectification of a view pair for row-wise stereo matching, for any COLMAP camera model:
//! both views are re-projected onto one plane parallel to the baseline (a shared rotation,
//! pinhole intrinsics), so that a scene point appears on the same row of both and its
//! disparity gives its depth, `Z = f·B / (d − (cx_left − cx_right))`.
//!
//! The resampling table maps each rectified pixel through the original camera model
//! (distortion included), so distorted photos need no separate undistortion step.

use nalgebra::{Point2, Point3, Rotation3, Vector3};
use rayon::prelude::*;

use crate::scene::{Camera, Image};

/// Per rectified pixel (row-major), the x and y pixel-index coordinates to sample in the
/// (resized) photo, −1 where there is nothing to sample.
pub type ResamplingTable = (Vec<f32>, Vec<f32>);

/// A rectified pinhole view. Pixel `(i, j)` has COLMAP coordinates `(i + ½, j + ½)`.
#[derive(Clone, Debug, PartialEq)]
pub struct RectifiedCamera {
    /// Shared by both views of a pair.
    pub rect_from_world: Rotation3<f64>,
    pub center_world: Point3<f64>,
    pub focal_px: f64,
    pub principal_px: Point2<f64>,
    pub width: usize,
    pub height: usize,
}

impl RectifiedCamera {
    /// `(u, v)` in COLMAP pixel coordinates and the depth along the rectified axis.
    pub fn project(&self, point_world: &Point3<f64>) -> Option<(Point2<f64>, f64)> {
        let point_rect = self.rect_from_world * (point_world - self.center_world);
        if point_rect.z <= 1e-9 {
            return None;
        }
        let uv = Point2::new(
            self.focal_px * point_rect.x / point_rect.z + self.principal_px.x,
            self.focal_px * point_rect.y / point_rect.z + self.principal_px.y,
        );
        Some((uv, point_rect.z))
    }

    /// The world point at rectified depth `depth` on the ray through pixel `(i, j)`'s centre.
    pub fn unproject_pixel(&self, i: usize, j: usize, depth: f64) -> Point3<f64> {
        let ray_rect = Vector3::new(
            (i as f64 + 0.5 - self.principal_px.x) / self.focal_px,
            (j as f64 + 0.5 - self.principal_px.y) / self.focal_px,
            1.0,
        );
        self.center_world + self.rect_from_world.inverse() * (ray_rect * depth)
    }

    /// Pixel indices of a COLMAP coordinate, if inside the image.
    pub fn pixel_of(&self, uv: &Point2<f64>) -> Option<(usize, usize)> {
        let (i, j) = (uv.x.floor(), uv.y.floor());
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.width && (j as usize) < self.height)
            .then_some((i as usize, j as usize))
    }

    /// For each rectified pixel (row-major) the pixel-index coordinates in a copy of the
    /// original image resized by `image_scale` (x, y), or −1 where the ray leaves the image.
    /// Ready for `cv::remap`.
    pub fn resampling_table(
        &self,
        image: &Image,
        camera: &Camera,
        image_scale: (f64, f64),
    ) -> ResamplingTable {
        let camera_from_rect =
            image.camera_from_world.rotation.to_rotation_matrix() * self.rect_from_world.inverse();
        let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..self.height)
            .into_par_iter()
            .map(|j| {
                let mut xs = vec![-1.0f32; self.width];
                let mut ys = vec![-1.0f32; self.width];
                let y = (j as f64 + 0.5 - self.principal_px.y) / self.focal_px;
                for i in 0..self.width {
                    let x = (i as f64 + 0.5 - self.principal_px.x) / self.focal_px;
                    let ray_camera = camera_from_rect * Vector3::new(x, y, 1.0);
                    if let Some(uv) = camera.project(&ray_camera)
                        && camera.contains(&uv)
                    {
                        xs[i] = (uv.x * image_scale.0 - 0.5) as f32;
                        ys[i] = (uv.y * image_scale.1 - 0.5) as f32;
                    }
                }
                (xs, ys)
            })
            .collect();
        let mut map_x = Vec::with_capacity(self.width * self.height);
        let mut map_y = Vec::with_capacity(self.width * self.height);
        for (xs, ys) in rows {
            map_x.extend(xs);
            map_y.extend(ys);
        }
        (map_x, map_y)
    }
}

/// Two views rectified onto a common image plane; `right` lies along +x of `left`.
#[derive(Clone, Debug, PartialEq)]
pub struct RectifiedPair {
    pub left: RectifiedCamera,
    pub right: RectifiedCamera,
    /// Distance between the camera centres (world units).
    pub baseline: f64,
}

/// Where a view's image lands on the rectified plane: `(u_min, u_max, v_min, v_max)` in
/// normalised-times-focal units, from rays through its border.
fn rectified_extent(
    image: &Image,
    camera: &Camera,
    rect_from_world: &Rotation3<f64>,
    focal_px: f64,
) -> Option<(f64, f64, f64, f64)> {
    let rect_from_camera = rect_from_world
        * image
            .camera_from_world
            .rotation
            .to_rotation_matrix()
            .inverse();
    let (w, h) = (camera.width as f64, camera.height as f64);
    const SAMPLES: usize = 32;
    let mut extent = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for k in 0..=SAMPLES {
        let t = k as f64 / SAMPLES as f64;
        for uv in [
            Point2::new(t * w, 0.0),
            Point2::new(t * w, h),
            Point2::new(0.0, t * h),
            Point2::new(w, t * h),
        ] {
            let Some(ray_camera) = camera.unproject(&uv) else {
                continue;
            };
            let ray_rect = rect_from_camera * ray_camera.normalize();
            // Rays nearly parallel to the plane would stretch the image without bound.
            if ray_rect.z < 0.2 {
                continue;
            }
            let (u, v) = (
                focal_px * ray_rect.x / ray_rect.z,
                focal_px * ray_rect.y / ray_rect.z,
            );
            extent = (
                extent.0.min(u),
                extent.1.max(u),
                extent.2.min(v),
                extent.3.max(v),
            );
        }
    }
    (extent.0 < extent.1 && extent.2 < extent.3).then_some(extent)
}

impl RectifiedPair {
    /// Rectifies `left` and `right` at `scale` times the smaller focal length. Each rectified
    /// image covers its view's extent (the rows both views cover; both as wide as the wider),
    /// at most `max_side` pixels a side (cropped about the centre beyond). `None` for coincident centres, a baseline along
    /// the viewing direction, or views with no common rows.
    pub fn new(
        (left_image, left_camera): (&Image, &Camera),
        (right_image, right_camera): (&Image, &Camera),
        scale: f64,
        max_side: usize,
    ) -> Option<Self> {
        let (center_left, center_right) = (left_image.center_world(), right_image.center_world());
        let baseline_world = center_right - center_left;
        let baseline = baseline_world.norm();
        if baseline.is_nan() || baseline <= 0.0 || scale.is_nan() || scale <= 0.0 {
            return None;
        }
        let x_axis = baseline_world / baseline;
        let mean_axis = left_image.view_direction_world() + right_image.view_direction_world();
        let y_axis = mean_axis.cross(&x_axis);
        // The baseline must not run along the viewing direction (that is not stereo).
        if y_axis.norm() < 0.1 * mean_axis.norm() {
            return None;
        }
        let y_axis = y_axis.normalize();
        let z_axis = x_axis.cross(&y_axis);
        let rect_from_world = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_rows(&[
            x_axis.transpose(),
            y_axis.transpose(),
            z_axis.transpose(),
        ]));
        let focal_px = scale * left_camera.mean_focal().min(right_camera.mean_focal());
        let extent_left = rectified_extent(left_image, left_camera, &rect_from_world, focal_px)?;
        let extent_right = rectified_extent(right_image, right_camera, &rect_from_world, focal_px)?;
        let v_range = (
            extent_left.2.max(extent_right.2),
            extent_left.3.min(extent_right.3),
        );
        if v_range.0 >= v_range.1 {
            return None;
        }
        // Semi-global matching wants images of one size: both take the wider extent.
        let width = ((extent_left.1 - extent_left.0).max(extent_right.1 - extent_right.0))
            .ceil()
            .max(1.0);
        let crop = |lo: f64, hi: f64| {
            let size = (hi - lo).ceil().max(1.0) as usize;
            if size <= max_side {
                (lo, size)
            } else {
                let mid = 0.5 * (lo + hi);
                (mid - 0.5 * max_side as f64, max_side)
            }
        };
        let make = |center_world: Point3<f64>, u_range: (f64, f64)| {
            let (u_start, width) = crop(u_range.0, u_range.0 + width);
            let (v_start, height) = crop(v_range.0, v_range.1);
            RectifiedCamera {
                rect_from_world,
                center_world,
                focal_px,
                principal_px: Point2::new(-u_start, -v_start),
                width,
                height,
            }
        };
        Some(Self {
            left: make(center_left, (extent_left.0, extent_left.1)),
            right: make(center_right, (extent_right.0, extent_right.1)),
            baseline,
        })
    }

    /// Moves the partner's image window by `shift_px` pixels along the rows (its principal
    /// point moves by `shift_px`), so every disparity `u_left − u_right` drops by `shift_px`.
    pub fn shift_partner_window(&mut self, shift_px: f64) {
        self.right.principal_px.x += shift_px;
    }

    /// The disparity offset from the two principal points, `cx_left − cx_right`.
    fn principal_offset(&self) -> f64 {
        self.left.principal_px.x - self.right.principal_px.x
    }

    /// Rectified depth (along the shared z axis) of a disparity `u_left − u_right`.
    pub fn depth_from_disparity(&self, disparity_px: f64) -> Option<f64> {
        let effective = disparity_px - self.principal_offset();
        (effective > 1e-6).then(|| self.left.focal_px * self.baseline / effective)
    }

    /// The disparity of a world point, if in front of both views.
    pub fn disparity_of(&self, point_world: &Point3<f64>) -> Option<f64> {
        let (uv_left, _) = self.left.project(point_world)?;
        let (uv_right, _) = self.right.project(point_world)?;
        Some(uv_left.x - uv_right.x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mvs::pairs::tests::ring_model;
    use crate::scene::CameraModelKind;
    use crate::scene::synthetic::example_camera;

    #[test]
    fn rectified_views_share_rows_and_disparity_gives_depth() {
        let model = ring_model(24, 50);
        let images = model.images();
        let camera = model.camera_of(&images[0]);
        for (a, b) in [(0, 1), (1, 0), (5, 7)] {
            let pair = RectifiedPair::new((&images[a], camera), (&images[b], camera), 1.0, 4000)
                .expect("a stereo pair");
            for point in model.points() {
                let x = point.position_world;
                let (uv_left, depth) = pair.left.project(&x).unwrap();
                let (uv_right, depth_right) = pair.right.project(&x).unwrap();
                assert!((uv_left.y - uv_right.y).abs() < 1e-9, "rows differ");
                assert!((depth - depth_right).abs() < 1e-9);
                let d = uv_left.x - uv_right.x;
                let z = pair.depth_from_disparity(d).unwrap();
                assert!((z - depth).abs() < 1e-9 * depth);
                // Back-projection through the pixel centre nearest to the point.
                let (i, j) = pair.left.pixel_of(&uv_left).unwrap();
                let back = pair.left.unproject_pixel(i, j, depth);
                let footprint = depth / pair.left.focal_px;
                assert!((back - x).norm() < footprint, "{}", (back - x).norm());
            }
        }
        // Sliding the partner's window lowers every disparity by the shift; depths stay.
        let mut pair =
            RectifiedPair::new((&images[0], camera), (&images[1], camera), 1.0, 4000).unwrap();
        let x = model.points()[0].position_world;
        let (d, z) = (
            pair.disparity_of(&x).unwrap(),
            pair.left.project(&x).unwrap().1,
        );
        pair.shift_partner_window(37.0);
        assert!((pair.disparity_of(&x).unwrap() - (d - 37.0)).abs() < 1e-9);
        assert!((pair.depth_from_disparity(d - 37.0).unwrap() - z).abs() < 1e-9 * z);
        // Coincident centres are no pair.
        assert!(
            RectifiedPair::new((&images[0], camera), (&images[0], camera), 1.0, 4000).is_none()
        );
    }

    #[test]
    fn resampling_table_follows_the_distorted_camera() {
        let model = ring_model(24, 50);
        let images = model.images();
        let camera = example_camera(CameraModelKind::OpenCv, 1, 640, 480);
        let pair =
            RectifiedPair::new((&images[0], &camera), (&images[1], &camera), 0.5, 4000).unwrap();
        let (map_x, map_y) = pair.left.resampling_table(&images[0], &camera, (0.5, 0.5));
        assert_eq!(map_x.len(), pair.left.width * pair.left.height);
        let mut checked = 0;
        for point in model.points() {
            let x = point.position_world;
            let (uv_rect, _) = pair.left.project(&x).unwrap();
            let Some((i, j)) = pair.left.pixel_of(&uv_rect) else {
                continue;
            };
            // The table at that rectified pixel points where the real camera sees its ray.
            let ray_point = pair.left.unproject_pixel(i, j, 4.0);
            let uv = camera
                .project(&(images[0].camera_from_world * ray_point).coords)
                .unwrap();
            let k = j * pair.left.width + i;
            assert!((map_x[k] as f64 - (uv.x * 0.5 - 0.5)).abs() < 1e-3);
            assert!((map_y[k] as f64 - (uv.y * 0.5 - 0.5)).abs() < 1e-3);
            checked += 1;
        }
        assert!(checked > 40);
    }
}
