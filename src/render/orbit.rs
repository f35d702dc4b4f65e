//! An orbit camera for interactive 3D views: a target, the plant's up direction, azimuth,
//! elevation and distance; framing a point set, orbiting, panning and zooming by screen
//! deltas. Takes points and screen deltas; returns a [`ViewCamera`] for a panel size.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::camera::ViewCamera;
use crate::util::geometry::any_perpendicular;

/// Vertical field of view of an orbit view (degrees; it spans the panel's shorter side).
pub const FIELD_OF_VIEW_DEG: f64 = 45.0;

/// An orbit camera about a target, with the plant's up direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orbit {
    pub target: Point3<f64>,
    pub up: Vector3<f64>,
    /// Azimuth and elevation (radians) of the eye seen from the target.
    pub yaw: f64,
    pub pitch: f64,
    pub distance: f64,
}

impl Orbit {
    /// Frames `points` (their centroid as the target, their 95th-percentile distance from
    /// it filling the view with a margin), looking from the side and a little above along
    /// `up`; `None` without points.
    pub fn framing(points: &[Point3<f64>], up: &Vector3<f64>) -> Option<Self> {
        let chosen: Vec<&Point3<f64>> = points.iter().collect();
        if chosen.is_empty() {
            return None;
        }
        let n = chosen.len() as f64;
        let target = Point3::from(chosen.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n);
        let mut distances: Vec<f64> = chosen.iter().map(|p| (*p - target).norm()).collect();
        distances.sort_by(f64::total_cmp);
        let radius = distances[(distances.len() - 1) * 95 / 100].max(1e-6);
        let up = up.try_normalize(1e-12).unwrap_or(Vector3::z());
        Some(Self {
            target,
            up,
            yaw: 0.6,
            pitch: 0.35,
            distance: radius / (FIELD_OF_VIEW_DEG.to_radians() * 0.5).tan() * 1.3,
        })
    }

    /// The eye position.
    pub fn eye(&self) -> Point3<f64> {
        let e1 = any_perpendicular(&self.up).normalize();
        let e2 = self.up.cross(&e1);
        let direction = (e1 * self.yaw.cos() + e2 * self.yaw.sin()) * self.pitch.cos()
            + self.up * self.pitch.sin();
        self.target + direction * self.distance
    }

    /// `camera_from_world` with COLMAP's axes (x right, y down, z forward).
    pub fn camera_from_world(&self) -> Isometry3<f64> {
        let eye = self.eye();
        let z = (self.target - eye).normalize();
        let up_across = self.up - z * self.up.dot(&z);
        let y = -up_across
            .try_normalize(1e-12)
            .unwrap_or_else(|| any_perpendicular(&z));
        let x = y.cross(&z);
        let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
            x.transpose(),
            y.transpose(),
            z.transpose(),
        ]));
        let translation = -(rotation * eye.coords);
        Isometry3::from_parts(
            Translation3::from(translation),
            UnitQuaternion::from_rotation_matrix(&rotation),
        )
    }

    /// The render core's camera for a panel of `width` × `height` pixels.
    pub fn view_camera(&self, width: u32, height: u32) -> ViewCamera {
        // The field of view spans the panel's shorter side.
        let focal = width.min(height) as f64 * 0.5 / (FIELD_OF_VIEW_DEG.to_radians() * 0.5).tan();
        ViewCamera {
            width,
            height,
            fx: focal,
            fy: focal,
            cx: width as f64 * 0.5,
            cy: height as f64 * 0.5,
            camera_from_world: self.camera_from_world(),
            near: self.distance * 0.01,
            far: self.distance * 20.0,
        }
    }

    /// Orbits by screen deltas (points).
    pub fn rotate(&mut self, dx: f64, dy: f64) {
        self.yaw -= dx * 0.008;
        self.pitch = (self.pitch + dy * 0.008).clamp(-1.5, 1.5);
    }

    /// Pans the target by screen deltas (points) in a panel whose shorter side is `side`
    /// points.
    pub fn pan(&mut self, dx: f64, dy: f64, side: f64) {
        let camera = self.camera_from_world();
        let rotation = camera.rotation.inverse();
        let world_per_point =
            2.0 * self.distance * (FIELD_OF_VIEW_DEG.to_radians() * 0.5).tan() / side;
        let right = rotation * Vector3::x();
        let down = rotation * Vector3::y();
        self.target -= (right * dx + down * dy) * world_per_point;
    }

    /// Half the view's extent at the target's distance (world units).
    pub fn half_height_at_target(&self) -> f64 {
        self.distance * (FIELD_OF_VIEW_DEG.to_radians() * 0.5).tan()
    }

    /// Moves the eye `factor` times closer.
    pub fn zoom(&mut self, factor: f64) {
        self.distance = (self.distance / factor).max(1e-6);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn orbit() -> Orbit {
        Orbit {
            target: Point3::new(1.0, 2.0, 3.0),
            up: Vector3::z(),
            yaw: 0.3,
            pitch: 0.4,
            distance: 2.0,
        }
    }

    #[test]
    fn the_orbit_camera_looks_at_its_target_with_up_on_screen_up() {
        let orbit = orbit();
        let camera = orbit.view_camera(640, 480);
        let (uv, depth) = camera.project(&orbit.target).unwrap();
        assert!(
            (uv.x - 320.0).abs() < 1e-6 && (uv.y - 240.0).abs() < 1e-6,
            "{uv:?}"
        );
        assert!((depth - 2.0).abs() < 1e-9);
        // A point above the target projects above the centre (smaller v).
        let (above, _) = camera
            .project(&(orbit.target + Vector3::z() * 0.1))
            .unwrap();
        assert!(
            above.y < 240.0 && (above.x - 320.0).abs() < 1e-6,
            "{above:?}"
        );
        assert!((orbit.eye() - orbit.target).norm() - 2.0 < 1e-12);
    }

    #[test]
    fn panning_moves_the_target_across_the_view_and_zoom_keeps_it() {
        let mut orbit = orbit();
        let before = orbit.view_camera(640, 480);
        orbit.pan(10.0, 0.0, 480.0);
        // The old target now appears 10 points to the right of the centre.
        let (uv, _) = orbit
            .view_camera(640, 480)
            .project(&Point3::new(1.0, 2.0, 3.0))
            .unwrap();
        assert!(
            (uv.x - 330.0).abs() < 1e-6 && (uv.y - 240.0).abs() < 1e-6,
            "{uv:?}"
        );
        orbit.zoom(2.0);
        assert!((orbit.distance - 1.0).abs() < 1e-12);
        assert_ne!(before, orbit.view_camera(640, 480));
    }
}
