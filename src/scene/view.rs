//! A view world points are seen in, as the editing tools need it: where a point appears (pixels,
//! COLMAP convention) and how many pixels a metre spans there, across the view ray. The trait
//! [`ViewProjection`] covers both kinds of view: a registered photo ([`PhotoView`], with its
//! camera model's distortion) and the GUI's 3D panel camera (`render::ViewCamera`, which
//! implements it beside its definition).
//!
//! Takes a reconstruction and one of its images; returns pixels, pixels per metre and the
//! corners of the photo's frustum in the world frame.

use nalgebra::{Point2, Point3};

use super::model::{Image, Reconstruction};
use crate::util::geometry::any_perpendicular;

/// A camera that projects world points to pixels (COLMAP convention).
pub trait ViewProjection {
    /// Pixel position of a world point; `None` when it is not in front of the camera.
    fn project_px(&self, point_world: &Point3<f64>) -> Option<Point2<f64>>;

    /// Pixels per metre at a world point, for lengths across the view ray (a radius seen
    /// face-on); `None` where the point does not project.
    fn px_per_metre(&self, point_world: &Point3<f64>) -> Option<f64>;
}

/// A registered photo of a reconstruction, seen as a camera.
#[derive(Clone, Copy, Debug)]
pub struct PhotoView<'a> {
    pub model: &'a Reconstruction,
    pub image: &'a Image,
}

impl<'a> PhotoView<'a> {
    /// The photo `image` of `model` (which must hold it: its camera is looked up there).
    pub fn new(model: &'a Reconstruction, image: &'a Image) -> Self {
        Self { model, image }
    }

    /// The corners of the image rectangle (pixels (0, 0), (w, 0), (w, h), (0, h), in that
    /// order) at camera depth `depth_camera`, in the world frame: with the camera centre, the
    /// frustum drawn for a photo. Pinhole intrinsics only (distortion ignored).
    pub fn frustum_corners_world(&self, depth_camera: f64) -> [Point3<f64>; 4] {
        let camera = self.model.camera_of(self.image);
        let (fx, fy, cx, cy) = camera.focal_and_principal_point();
        let world_from_camera = self.image.camera_from_world.inverse();
        let corner = |u: f64, v: f64| {
            world_from_camera
                * Point3::new(
                    (u - cx) / fx * depth_camera,
                    (v - cy) / fy * depth_camera,
                    depth_camera,
                )
        };
        let (w, h) = (camera.width as f64, camera.height as f64);
        [
            corner(0.0, 0.0),
            corner(w, 0.0),
            corner(w, h),
            corner(0.0, h),
        ]
    }
}

impl ViewProjection for PhotoView<'_> {
    fn project_px(&self, point_world: &Point3<f64>) -> Option<Point2<f64>> {
        self.model.project(self.image, point_world)
    }

    /// By finite difference through the camera model: the pixel step of a move of 1/1000 of
    /// the distance to the camera, across the view ray. `None` also where that scale is zero
    /// or not finite.
    fn px_per_metre(&self, point_world: &Point3<f64>) -> Option<f64> {
        let ray = point_world - self.image.center_world();
        let distance = ray.norm();
        let across = any_perpendicular(&ray.try_normalize(1e-12)?);
        let step = distance * 1e-3;
        let a = self.model.project(self.image, point_world)?;
        let b = self
            .model
            .project(self.image, &(point_world + across * step))?;
        let scale = (b - a).norm() / step;
        (scale.is_finite() && scale > 0.0).then_some(scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::synthetic::{example_camera, look_at};
    use crate::scene::{Camera, CameraModelKind};
    use nalgebra::Vector3;

    fn photo(camera: Camera) -> Reconstruction {
        let image = Image {
            id: 1,
            camera_id: camera.id,
            name: "a.png".into(),
            camera_from_world: look_at(Point3::new(0.0, -4.0, 1.0), Point3::new(0.2, 0.0, 0.9)),
            keypoints: Vec::new(),
        };
        Reconstruction::from_parts(vec![camera], vec![image], Vec::new()).unwrap()
    }

    #[test]
    fn a_length_across_the_ray_spans_px_per_metre_pixels() {
        for camera in [
            Camera::simple_pinhole(1, 800, 600, 700.0),
            example_camera(CameraModelKind::OpenCv, 1, 800, 600),
        ] {
            let model = photo(camera);
            let view = PhotoView::new(&model, &model.images()[0]);
            let centre = model.images()[0].center_world();
            for p in [Point3::new(0.2, 0.0, 0.9), Point3::new(-0.3, 0.5, 1.2)] {
                let scale = view.px_per_metre(&p).unwrap();
                // A short segment across the ray, in a direction of its own (not the one
                // the finite difference takes), projects to its length times the scale.
                let ray = (p - centre).normalize();
                let across = ray.cross(&Vector3::z()).normalize();
                let half = 0.002;
                let a = view.project_px(&(p - across * half)).unwrap();
                let b = view.project_px(&(p + across * half)).unwrap();
                let measured = (b - a).norm() / (2.0 * half);
                assert!(
                    (measured - scale).abs() < 0.02 * scale,
                    "{measured} against {scale}"
                );
            }
            // Twice as far along the same ray: half the scale (pinhole), about half (OpenCV).
            let p = Point3::new(0.2, 0.0, 0.9);
            let far = centre + (p - centre) * 2.0;
            let ratio = view.px_per_metre(&far).unwrap() / view.px_per_metre(&p).unwrap();
            assert!((ratio - 0.5).abs() < 0.01, "{ratio}");
        }
    }

    #[test]
    fn points_behind_the_photo_have_no_pixel_and_no_scale() {
        let model = photo(Camera::simple_pinhole(1, 800, 600, 700.0));
        let view = PhotoView::new(&model, &model.images()[0]);
        let behind = Point3::new(0.0, -8.0, 1.0);
        assert!(view.project_px(&behind).is_none());
        assert!(view.px_per_metre(&behind).is_none());
        let at_centre = model.images()[0].center_world();
        assert!(view.px_per_metre(&at_centre).is_none());
    }

    #[test]
    fn frustum_corners_project_back_to_the_image_corners() {
        let model = photo(Camera::simple_pinhole(1, 800, 600, 700.0));
        let image = &model.images()[0];
        let view = PhotoView::new(&model, image);
        let corners = view.frustum_corners_world(0.5);
        let expected = [[0.0, 0.0], [800.0, 0.0], [800.0, 600.0], [0.0, 600.0]];
        for (corner, [u, v]) in corners.iter().zip(expected) {
            let uv = view.project_px(corner).unwrap();
            assert!((uv.x - u).abs() < 1e-6 && (uv.y - v).abs() < 1e-6, "{uv:?}");
            let depth = (image.camera_from_world * corner).z;
            assert!((depth - 0.5).abs() < 1e-9);
        }
    }
}
