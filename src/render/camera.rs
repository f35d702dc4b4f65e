//! The view a render is made from: [`ViewCamera`] (pinhole intrinsics in COLMAP's pixel
//! convention, pose and clip planes), built from a COLMAP camera, with its clip-space matrix and
//! the projection of world points to pixels and its scale (pixels per metre, as
//! [`ViewProjection`]). Plain nalgebra; nothing here touches the GPU.

use nalgebra::{Isometry3, Matrix4, Point2, Point3};

use super::RenderError;
use crate::scene::{Camera, CameraModelKind, ViewProjection};

/// A pinhole view: intrinsics in pixels (COLMAP convention), pose and clip planes.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewCamera {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub camera_from_world: Isometry3<f64>,
    pub near: f64,
    pub far: f64,
}

impl ViewCamera {
    /// A view from a COLMAP camera (SIMPLE_PINHOLE or PINHOLE) and an image pose.
    pub fn from_colmap(
        camera: &Camera,
        camera_from_world: &Isometry3<f64>,
        near: f64,
        far: f64,
    ) -> Result<Self, RenderError> {
        if !matches!(
            camera.model,
            CameraModelKind::SimplePinhole | CameraModelKind::Pinhole
        ) {
            return Err(RenderError::UnsupportedCamera {
                camera_id: camera.id,
                model: camera.model,
            });
        }
        let (fx, fy, cx, cy) = camera.focal_and_principal_point();
        Ok(Self {
            width: camera.width,
            height: camera.height,
            fx,
            fy,
            cx,
            cy,
            camera_from_world: *camera_from_world,
            near,
            far,
        })
    }

    /// Maps camera coordinates (x right, y down, z forward) to wgpu clip space so that
    /// `ndc = (2u/W − 1, 1 − 2v/H)` for the COLMAP pixel `(u, v)`, and depth 0..1 between the
    /// clip planes.
    pub fn clip_from_camera(&self) -> Matrix4<f64> {
        let (w, h) = (self.width as f64, self.height as f64);
        let (n, f) = (self.near, self.far);
        Matrix4::new(
            2.0 * self.fx / w,
            0.0,
            2.0 * self.cx / w - 1.0,
            0.0,
            0.0,
            -2.0 * self.fy / h,
            1.0 - 2.0 * self.cy / h,
            0.0,
            0.0,
            0.0,
            f / (f - n),
            -f * n / (f - n),
            0.0,
            0.0,
            1.0,
            0.0,
        )
    }

    /// Pixel position (COLMAP convention) and depth of a world point; `None` behind the camera.
    pub fn project(&self, point_world: &Point3<f64>) -> Option<(Point2<f64>, f64)> {
        let p = self.camera_from_world * point_world;
        (p.z > 1e-9).then(|| {
            (
                Point2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy),
                p.z,
            )
        })
    }
}

impl ViewProjection for ViewCamera {
    fn project_px(&self, point_world: &Point3<f64>) -> Option<Point2<f64>> {
        self.project(point_world).map(|(uv, _)| uv)
    }

    /// `fx` over the point's depth: exact for lengths parallel to the image's x axis.
    fn px_per_metre(&self, point_world: &Point3<f64>) -> Option<f64> {
        self.project(point_world)
            .map(|(_, depth_camera)| self.fx / depth_camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distorted_cameras_are_refused() {
        let camera = crate::scene::synthetic::example_camera(CameraModelKind::OpenCv, 3, 64, 48);
        let err = ViewCamera::from_colmap(&camera, &Isometry3::identity(), 0.1, 10.0).unwrap_err();
        assert!(err.to_string().contains("OPENCV"), "{err}");
    }

    #[test]
    fn a_length_along_the_image_x_axis_spans_px_per_metre_pixels() {
        let camera = ViewCamera {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 480.0,
            cx: 320.0,
            cy: 240.0,
            camera_from_world: crate::scene::synthetic::look_at(
                Point3::new(1.0, -3.0, 2.0),
                Point3::new(0.0, 0.0, 1.0),
            ),
            near: 0.01,
            far: 100.0,
        };
        let world_from_camera = camera.camera_from_world.inverse();
        for point_camera in [
            Point3::new(0.0, 0.0, 2.0),
            Point3::new(0.4, -0.3, 3.5),
            Point3::new(-1.0, 0.2, 0.7),
        ] {
            let p = world_from_camera * point_camera;
            let scale = camera.px_per_metre(&p).unwrap();
            // A step of d metres along the camera's x axis at the same depth moves the pixel
            // by d·scale along u and not at all along v.
            let d = 0.05;
            let q = world_from_camera * (point_camera + nalgebra::Vector3::x() * d);
            let (a, b) = (
                camera.project_px(&p).unwrap(),
                camera.project_px(&q).unwrap(),
            );
            assert!(
                ((b.x - a.x) - d * scale).abs() < 1e-9 * scale,
                "{a:?} {b:?}"
            );
            assert!((b.y - a.y).abs() < 1e-9);
        }
        let behind = world_from_camera * Point3::new(0.0, 0.0, -1.0);
        assert!(camera.project_px(&behind).is_none() && camera.px_per_metre(&behind).is_none());
    }
}
