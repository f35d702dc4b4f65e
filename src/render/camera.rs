//! The view a render is made from: [`ViewCamera`] (pinhole intrinsics in COLMAP's pixel
//! convention, pose and clip planes), built from a COLMAP camera, with its clip-space matrix and
//! the projection of world points to pixels. Plain nalgebra; nothing here touches the GPU.

use nalgebra::{Isometry3, Matrix4, Point2, Point3};

use super::RenderError;
use crate::scene::{Camera, CameraModelKind};

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distorted_cameras_are_refused() {
        let camera = crate::scene::synthetic::example_camera(CameraModelKind::OpenCv, 3, 64, 48);
        let err = ViewCamera::from_colmap(&camera, &Isometry3::identity(), 0.1, 10.0).unwrap_err();
        assert!(err.to_string().contains("OPENCV"), "{err}");
    }
}
