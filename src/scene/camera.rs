//! COLMAP camera models: intrinsics, projection (camera frame → pixel, with distortion) and
//! unprojection (pixel → normalised ray, by iterative undistortion).
//!
//! Pixel convention is COLMAP's: the top-left image corner is (0, 0), so the centre of the
//! top-left pixel is (0.5, 0.5) and the principal point of an ideal camera is (w/2, h/2).
//! Parameter orders follow COLMAP's `models.h` exactly, so that a camera read from a COLMAP
//! model projects to the same pixels COLMAP computes.

use nalgebra::{Matrix2, Point2, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Identifier of a camera in a COLMAP model (`camera_t`, 32 bit).
pub type CameraId = u32;

/// Smallest depth (camera-frame z) a point may have and still be projected.
const MIN_PROJECTABLE_DEPTH: f64 = f64::EPSILON;

/// Every COLMAP camera model Frond understands, with COLMAP's numeric model id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum CameraModelKind {
    /// `f, cx, cy`
    SimplePinhole,
    /// `fx, fy, cx, cy`
    Pinhole,
    /// `f, cx, cy, k`
    SimpleRadial,
    /// `f, cx, cy, k1, k2`
    Radial,
    /// `fx, fy, cx, cy, k1, k2, p1, p2`
    #[serde(rename = "OPENCV")]
    OpenCv,
    /// `fx, fy, cx, cy, k1, k2, k3, k4`
    #[serde(rename = "OPENCV_FISHEYE")]
    OpenCvFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6`
    #[serde(rename = "FULL_OPENCV")]
    FullOpenCv,
    /// `fx, fy, cx, cy, omega`
    #[serde(rename = "FOV")]
    Fov,
    /// `f, cx, cy, k`
    SimpleRadialFisheye,
    /// `f, cx, cy, k1, k2`
    RadialFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1`
    ThinPrismFisheye,
    /// `fx, fy, cx, cy, k0, k1, k2, k3, k4, k5, p0, p1, s0, s1, s2, s3`
    RadTanThinPrismFisheye,
}

impl CameraModelKind {
    /// All supported models, in COLMAP id order.
    pub const ALL: [CameraModelKind; 12] = [
        Self::SimplePinhole,
        Self::Pinhole,
        Self::SimpleRadial,
        Self::Radial,
        Self::OpenCv,
        Self::OpenCvFisheye,
        Self::FullOpenCv,
        Self::Fov,
        Self::SimpleRadialFisheye,
        Self::RadialFisheye,
        Self::ThinPrismFisheye,
        Self::RadTanThinPrismFisheye,
    ];

    /// COLMAP's numeric model id (`CameraModelId`).
    pub fn id(self) -> i32 {
        Self::ALL.iter().position(|&k| k == self).unwrap_or(0) as i32
    }

    /// The model with COLMAP's numeric id, if Frond supports it.
    pub fn from_id(id: i32) -> Option<Self> {
        usize::try_from(id)
            .ok()
            .and_then(|i| Self::ALL.get(i).copied())
    }

    /// COLMAP's model name, as written in `cameras.txt`.
    pub fn name(self) -> &'static str {
        match self {
            Self::SimplePinhole => "SIMPLE_PINHOLE",
            Self::Pinhole => "PINHOLE",
            Self::SimpleRadial => "SIMPLE_RADIAL",
            Self::Radial => "RADIAL",
            Self::OpenCv => "OPENCV",
            Self::OpenCvFisheye => "OPENCV_FISHEYE",
            Self::FullOpenCv => "FULL_OPENCV",
            Self::Fov => "FOV",
            Self::SimpleRadialFisheye => "SIMPLE_RADIAL_FISHEYE",
            Self::RadialFisheye => "RADIAL_FISHEYE",
            Self::ThinPrismFisheye => "THIN_PRISM_FISHEYE",
            Self::RadTanThinPrismFisheye => "RAD_TAN_THIN_PRISM_FISHEYE",
        }
    }

    /// The model with COLMAP's name, if Frond supports it.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.name() == name)
    }

    /// Number of parameters COLMAP stores for the model.
    pub fn num_params(self) -> usize {
        match self {
            Self::SimplePinhole => 3,
            Self::Pinhole => 4,
            Self::SimpleRadial | Self::SimpleRadialFisheye => 4,
            Self::Radial | Self::RadialFisheye => 5,
            Self::OpenCv | Self::OpenCvFisheye => 8,
            Self::FullOpenCv | Self::ThinPrismFisheye => 12,
            Self::Fov => 5,
            Self::RadTanThinPrismFisheye => 16,
        }
    }

    /// Names of the parameters, in storage order (COLMAP's `params_info`).
    pub fn param_names(self) -> &'static str {
        match self {
            Self::SimplePinhole => "f, cx, cy",
            Self::Pinhole => "fx, fy, cx, cy",
            Self::SimpleRadial | Self::SimpleRadialFisheye => "f, cx, cy, k",
            Self::Radial | Self::RadialFisheye => "f, cx, cy, k1, k2",
            Self::OpenCv => "fx, fy, cx, cy, k1, k2, p1, p2",
            Self::OpenCvFisheye => "fx, fy, cx, cy, k1, k2, k3, k4",
            Self::FullOpenCv => "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6",
            Self::Fov => "fx, fy, cx, cy, omega",
            Self::ThinPrismFisheye => "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1",
            Self::RadTanThinPrismFisheye => {
                "fx, fy, cx, cy, k0, k1, k2, k3, k4, k5, p0, p1, s0, s1, s2, s3"
            }
        }
    }

    /// Whether the model has a single focal length `f` (shared by x and y).
    fn has_single_focal(self) -> bool {
        matches!(
            self,
            Self::SimplePinhole
                | Self::SimpleRadial
                | Self::Radial
                | Self::SimpleRadialFisheye
                | Self::RadialFisheye
        )
    }

    /// Whether the distortion acts on the equidistant fisheye coordinates
    /// `(u, v)·atan(r)/r` rather than on the perspective ones.
    pub fn is_fisheye(self) -> bool {
        matches!(
            self,
            Self::OpenCvFisheye
                | Self::SimpleRadialFisheye
                | Self::RadialFisheye
                | Self::ThinPrismFisheye
                | Self::RadTanThinPrismFisheye
        )
    }
}

impl std::fmt::Display for CameraModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a camera's intrinsics were rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    #[error("model {model} takes {expected} parameters ({names}), got {got}")]
    ParamCount {
        model: CameraModelKind,
        expected: usize,
        names: &'static str,
        got: usize,
    },
    #[error("parameter {index} of {model} is not finite ({value})")]
    NonFinite {
        model: CameraModelKind,
        index: usize,
        value: f64,
    },
    #[error("focal length must be positive, got {0}")]
    Focal(f64),
    #[error("image size {width}x{height} is not plausible")]
    Size { width: u64, height: u64 },
}

/// Largest image side Frond accepts; anything larger is a corrupt record, not a photo.
pub const MAX_IMAGE_SIDE: u64 = 1 << 20;

/// A camera: model, image size in pixels and the model's parameters (COLMAP order).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub id: CameraId,
    pub model: CameraModelKind,
    pub width: u32,
    pub height: u32,
    params: Vec<f64>,
}

impl Camera {
    /// Checks the parameter count, finiteness, focal lengths and image size.
    pub fn new(
        id: CameraId,
        model: CameraModelKind,
        width: u64,
        height: u64,
        params: Vec<f64>,
    ) -> Result<Self, CameraError> {
        if params.len() != model.num_params() {
            return Err(CameraError::ParamCount {
                model,
                expected: model.num_params(),
                names: model.param_names(),
                got: params.len(),
            });
        }
        if let Some((index, &value)) = params.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(CameraError::NonFinite {
                model,
                index,
                value,
            });
        }
        if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            return Err(CameraError::Size { width, height });
        }
        let camera = Self {
            id,
            model,
            width: width as u32,
            height: height as u32,
            params,
        };
        let (fx, fy, _, _) = camera.focal_and_principal_point();
        for f in [fx, fy] {
            if f <= 0.0 {
                return Err(CameraError::Focal(f));
            }
        }
        Ok(camera)
    }

    /// A pinhole camera with square pixels and the principal point at the image centre.
    pub fn simple_pinhole(id: CameraId, width: u32, height: u32, focal_px: f64) -> Self {
        Self {
            id,
            model: CameraModelKind::SimplePinhole,
            width,
            height,
            params: vec![focal_px, width as f64 / 2.0, height as f64 / 2.0],
        }
    }

    /// The parameters in COLMAP order (see [`CameraModelKind::param_names`]).
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// `(fx, fy, cx, cy)` in pixels.
    pub fn focal_and_principal_point(&self) -> (f64, f64, f64, f64) {
        let p = &self.params;
        if self.model.has_single_focal() {
            (p[0], p[0], p[1], p[2])
        } else {
            (p[0], p[1], p[2], p[3])
        }
    }

    /// Mean focal length in pixels.
    pub fn mean_focal(&self) -> f64 {
        let (fx, fy, _, _) = self.focal_and_principal_point();
        0.5 * (fx + fy)
    }

    /// Distortion parameters (everything after focal length and principal point).
    fn extra(&self) -> &[f64] {
        if self.model.has_single_focal() {
            &self.params[3..]
        } else {
            &self.params[4..]
        }
    }

    /// Whether a pixel position lies inside the image rectangle `[0, w] × [0, h]`.
    pub fn contains(&self, uv_image: &Point2<f64>) -> bool {
        uv_image.x >= 0.0
            && uv_image.y >= 0.0
            && uv_image.x <= self.width as f64
            && uv_image.y <= self.height as f64
    }

    /// Projects a point in the camera frame to pixels (COLMAP `ImgFromCam`).
    /// `None` if the point is not in front of the camera.
    pub fn project(&self, point_camera: &Vector3<f64>) -> Option<Point2<f64>> {
        if point_camera.z <= MIN_PROJECTABLE_DEPTH || !point_camera.iter().all(|c| c.is_finite()) {
            return None;
        }
        let normal = Vector2::new(
            point_camera.x / point_camera.z,
            point_camera.y / point_camera.z,
        );
        let distorted = self.distort_normalized(normal);
        let (fx, fy, cx, cy) = self.focal_and_principal_point();
        Some(Point2::new(fx * distorted.x + cx, fy * distorted.y + cy))
    }

    /// Lifts a pixel to a ray direction `(u, v, 1)` in the camera frame (COLMAP `CamFromImg`).
    /// `None` if undistortion does not converge or the pixel maps behind the camera.
    pub fn unproject(&self, uv_image: &Point2<f64>) -> Option<Vector3<f64>> {
        let (fx, fy, cx, cy) = self.focal_and_principal_point();
        let distorted = Vector2::new((uv_image.x - cx) / fx, (uv_image.y - cy) / fy);
        let normal = match self.model {
            CameraModelKind::SimplePinhole | CameraModelKind::Pinhole => distorted,
            CameraModelKind::Fov => fov_undistort(self.extra()[0], distorted),
            kind => {
                let undistorted = self.iterative_undistortion(distorted)?;
                if kind.is_fisheye() {
                    normal_from_fisheye(undistorted)?
                } else {
                    undistorted
                }
            }
        };
        normal
            .iter()
            .all(|c| c.is_finite())
            .then(|| Vector3::new(normal.x, normal.y, 1.0))
    }

    /// Maps normalised perspective coordinates `(x/z, y/z)` to distorted normalised coordinates.
    fn distort_normalized(&self, normal: Vector2<f64>) -> Vector2<f64> {
        match self.model {
            CameraModelKind::SimplePinhole | CameraModelKind::Pinhole => normal,
            CameraModelKind::Fov => fov_distort(self.extra()[0], normal),
            kind => {
                let base = if kind.is_fisheye() {
                    fisheye_from_normal(normal)
                } else {
                    normal
                };
                base + self.distortion_delta(base)
            }
        }
    }

    /// The additive distortion `D(p)` of the model at `p` (COLMAP's `Distortion`), for every
    /// model whose image coordinates are `p + D(p)`.
    fn distortion_delta(&self, p: Vector2<f64>) -> Vector2<f64> {
        let e = self.extra();
        let (u, v) = (p.x, p.y);
        let (u2, v2, uv) = (u * u, v * v, u * v);
        let r2 = u2 + v2;
        match self.model {
            CameraModelKind::SimplePinhole | CameraModelKind::Pinhole | CameraModelKind::Fov => {
                Vector2::zeros()
            }
            CameraModelKind::SimpleRadial | CameraModelKind::SimpleRadialFisheye => p * (e[0] * r2),
            CameraModelKind::Radial | CameraModelKind::RadialFisheye => {
                p * (e[0] * r2 + e[1] * r2 * r2)
            }
            CameraModelKind::OpenCv => {
                let (k1, k2, p1, p2) = (e[0], e[1], e[2], e[3]);
                let radial = k1 * r2 + k2 * r2 * r2;
                Vector2::new(
                    u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2),
                    v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2),
                )
            }
            CameraModelKind::OpenCvFisheye => {
                let (k1, k2, k3, k4) = (e[0], e[1], e[2], e[3]);
                let (t2, t4) = (r2, r2 * r2);
                p * (k1 * t2 + k2 * t4 + k3 * t4 * t2 + k4 * t4 * t4)
            }
            CameraModelKind::FullOpenCv => {
                let (k1, k2, p1, p2, k3, k4, k5, k6) =
                    (e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7]);
                let (r4, r6) = (r2 * r2, r2 * r2 * r2);
                let radial =
                    (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
                Vector2::new(
                    u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) - u,
                    v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) - v,
                )
            }
            CameraModelKind::ThinPrismFisheye => {
                let (k1, k2, p1, p2, k3, k4, sx1, sy1) =
                    (e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7]);
                let (r4, r6, r8) = (r2 * r2, r2 * r2 * r2, r2 * r2 * r2 * r2);
                let radial = k1 * r2 + k2 * r4 + k3 * r6 + k4 * r8;
                Vector2::new(
                    u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) + sx1 * r2,
                    v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) + sy1 * r2,
                )
            }
            CameraModelKind::RadTanThinPrismFisheye => {
                // Radial polynomial in θ² (θ = |p| in fisheye coordinates), then tangential and
                // thin-prism terms on the radially distorted point (Aria "Fisheye624").
                let mut radial = 1.0;
                let mut theta_power = 1.0;
                for k in &e[0..6] {
                    theta_power *= r2;
                    radial += k * theta_power;
                }
                let (p0, p1, s0, s1, s2, s3) = (e[6], e[7], e[8], e[9], e[10], e[11]);
                let x = radial * u;
                let y = radial * v;
                let (x2, y2, xy) = (x * x, y * y, x * y);
                let rr2 = x2 + y2;
                let rr4 = rr2 * rr2;
                Vector2::new(
                    x + 2.0 * p1 * xy + p0 * (rr2 + 2.0 * x2) + s0 * rr2 + s1 * rr4 - u,
                    y + 2.0 * p0 * xy + p1 * (rr2 + 2.0 * y2) + s2 * rr2 + s3 * rr4 - v,
                )
            }
        }
    }

    /// Solves `p + D(p) = distorted` for `p` by Newton's method with a central-difference
    /// Jacobian (COLMAP's `IterativeUndistortion`, with a convergence check).
    fn iterative_undistortion(&self, distorted: Vector2<f64>) -> Option<Vector2<f64>> {
        const MAX_ITERATIONS: usize = 100;
        const TOLERANCE_SQUARED: f64 = 1e-26;
        let mut p = distorted;
        for _ in 0..MAX_ITERATIONS {
            let residual = p + self.distortion_delta(p) - distorted;
            if residual.norm_squared() < TOLERANCE_SQUARED {
                return Some(p);
            }
            let step = 1e-7 * p.amax().max(1.0);
            let mut jacobian = Matrix2::identity();
            for axis in 0..2 {
                let mut offset = Vector2::zeros();
                offset[axis] = step;
                let derivative = (self.distortion_delta(p + offset)
                    - self.distortion_delta(p - offset))
                    / (2.0 * step);
                jacobian[(0, axis)] += derivative.x;
                jacobian[(1, axis)] += derivative.y;
            }
            let update = jacobian.try_inverse()? * residual;
            p -= update;
            if !p.iter().all(|c| c.is_finite()) {
                return None;
            }
        }
        let residual = p + self.distortion_delta(p) - distorted;
        (residual.norm() < 1e-9).then_some(p)
    }
}

/// Equidistant fisheye coordinates of a normalised perspective point: scales by `atan(r)/r`.
fn fisheye_from_normal(normal: Vector2<f64>) -> Vector2<f64> {
    let r = normal.norm();
    if r > f64::EPSILON {
        normal * (r.atan() / r)
    } else {
        normal
    }
}

/// Inverse of [`fisheye_from_normal`]; `None` at or beyond 90° from the optical axis.
fn normal_from_fisheye(fisheye: Vector2<f64>) -> Option<Vector2<f64>> {
    let theta = fisheye.norm();
    if theta >= std::f64::consts::FRAC_PI_2 {
        return None;
    }
    if theta > f64::EPSILON {
        Some(fisheye * (theta.tan() / theta))
    } else {
        Some(fisheye)
    }
}

/// FOV model (Devernay & Faugeras 2001): `r_d = atan(2 r tan(ω/2)) / ω`.
fn fov_distort(omega: f64, normal: Vector2<f64>) -> Vector2<f64> {
    let r = normal.norm();
    let factor = if omega.abs() < 1e-6 {
        // ω → 0 is the pinhole camera; the next term is O(ω²).
        1.0 - omega * omega * (1.0 / 12.0 - r * r / 3.0)
    } else if r < 1e-9 {
        2.0 * (omega / 2.0).tan() / omega
    } else {
        (2.0 * r * (omega / 2.0).tan()).atan() / (r * omega)
    };
    normal * factor
}

/// Inverse of [`fov_distort`]: `r = tan(r_d ω) / (2 tan(ω/2))`.
fn fov_undistort(omega: f64, distorted: Vector2<f64>) -> Vector2<f64> {
    let r = distorted.norm();
    let factor = if omega.abs() < 1e-6 {
        1.0 + omega * omega * (1.0 / 12.0 - r * r / 3.0)
    } else if r < 1e-9 {
        omega / (2.0 * (omega / 2.0).tan())
    } else {
        (r * omega).tan() / (r * 2.0 * (omega / 2.0).tan())
    };
    distorted * factor
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Realistic parameters for every model on a 800×600 image: moderate distortion, so that
    /// the distortion is invertible over the whole image (as it is for a calibrated lens).
    pub(crate) fn realistic_camera(
        model: CameraModelKind,
        focal: f64,
        coefficients: &[f64],
    ) -> Camera {
        let (w, h) = (800u64, 600u64);
        let (cx, cy) = (w as f64 / 2.0 + 3.1, h as f64 / 2.0 - 2.3);
        let mut params = if model.has_single_focal() {
            vec![focal, cx, cy]
        } else {
            vec![focal, focal * 1.01, cx, cy]
        };
        let extra = model.num_params() - params.len();
        params.extend(coefficients.iter().take(extra).copied());
        Camera::new(1, model, w, h, params).expect("valid test camera")
    }

    /// Scales per-model distortion so that it stays monotone within the field of view.
    fn coefficient_scale(model: CameraModelKind) -> Vec<f64> {
        match model {
            CameraModelKind::Fov => vec![0.6],
            CameraModelKind::FullOpenCv => {
                vec![0.1, 0.02, 0.01, 0.01, 0.005, 0.05, 0.01, 0.005]
            }
            CameraModelKind::ThinPrismFisheye => {
                vec![0.05, 0.01, 0.005, 0.005, 0.002, 0.001, 0.005, 0.005]
            }
            CameraModelKind::RadTanThinPrismFisheye => vec![
                0.05, 0.01, 0.002, 0.001, 0.0005, 0.0002, 0.005, 0.005, 0.005, 0.001, 0.005, 0.001,
            ],
            _ => vec![0.1, 0.02, 0.01, 0.01],
        }
    }

    fn model_strategy() -> impl Strategy<Value = CameraModelKind> {
        (0usize..CameraModelKind::ALL.len()).prop_map(|i| CameraModelKind::ALL[i])
    }

    #[test]
    fn model_ids_and_names_round_trip() {
        for (i, kind) in CameraModelKind::ALL.iter().enumerate() {
            assert_eq!(kind.id(), i as i32);
            assert_eq!(CameraModelKind::from_id(i as i32), Some(*kind));
            assert_eq!(CameraModelKind::from_name(kind.name()), Some(*kind));
            assert_eq!(
                kind.param_names().split(", ").count(),
                kind.num_params(),
                "{kind}"
            );
        }
        assert_eq!(CameraModelKind::from_id(-1), None);
        assert_eq!(CameraModelKind::from_id(12), None);
        assert_eq!(CameraModelKind::from_name("PINHOLE_X"), None);
    }

    #[test]
    fn rejects_bad_intrinsics() {
        let err = Camera::new(1, CameraModelKind::Pinhole, 10, 10, vec![1.0, 1.0, 5.0]);
        assert!(matches!(err, Err(CameraError::ParamCount { got: 3, .. })));
        let err = Camera::new(
            1,
            CameraModelKind::SimplePinhole,
            10,
            10,
            vec![f64::NAN, 5., 5.],
        );
        assert!(matches!(err, Err(CameraError::NonFinite { index: 0, .. })));
        let err = Camera::new(1, CameraModelKind::SimplePinhole, 10, 10, vec![-3., 5., 5.]);
        assert!(matches!(err, Err(CameraError::Focal(_))));
        let err = Camera::new(1, CameraModelKind::SimplePinhole, 0, 10, vec![3., 5., 5.]);
        assert!(matches!(err, Err(CameraError::Size { .. })));
    }

    #[test]
    fn pinhole_projects_principal_ray_to_principal_point() {
        let camera = Camera::simple_pinhole(1, 640, 480, 500.0);
        let uv = camera.project(&Vector3::new(0.0, 0.0, 2.0)).unwrap();
        assert_eq!(uv, Point2::new(320.0, 240.0));
        let uv = camera.project(&Vector3::new(1.0, -0.5, 2.0)).unwrap();
        assert!((uv - Point2::new(570.0, 115.0)).norm() < 1e-12);
        assert!(camera.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
        assert!(camera.project(&Vector3::new(0.0, f64::NAN, 1.0)).is_none());
    }

    #[test]
    fn simple_radial_matches_closed_form() {
        let camera = Camera::new(
            1,
            CameraModelKind::SimpleRadial,
            100,
            100,
            vec![100.0, 50.0, 50.0, 0.1],
        )
        .unwrap();
        // u = 0.2, v = 0.1 → r² = 0.05, factor 1 + 0.1·0.05 = 1.005.
        let uv = camera.project(&Vector3::new(0.2, 0.1, 1.0)).unwrap();
        assert!((uv.x - (50.0 + 100.0 * 0.2 * 1.005)).abs() < 1e-12);
        assert!((uv.y - (50.0 + 100.0 * 0.1 * 1.005)).abs() < 1e-12);
    }

    #[test]
    fn fov_small_omega_is_continuous() {
        let p = Vector2::new(0.3, -0.2);
        for omega in [1e-7, 2e-6] {
            let d = fov_distort(omega, p);
            assert!((d - p).norm() < 1e-9, "{omega}: {d:?}");
            let back = fov_undistort(omega, d);
            assert!((back - p).norm() < 1e-9);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]

        /// Unproject then project returns the pixel, anywhere in the image, for every model.
        /// Focal lengths keep the image corners within ~45° of the axis, where these
        /// distortion polynomials are monotone (a polynomial fitted to a lens folds back outside
        /// its calibrated field, and there no ray maps to the pixel).
        #[test]
        fn unproject_then_project_returns_pixel(
            model in model_strategy(),
            focal in 500.0f64..900.0,
            signs in proptest::collection::vec(-1.0f64..1.0, 12),
            fx in 0.0f64..=1.0,
            fy in 0.0f64..=1.0,
        ) {
            let scale = coefficient_scale(model);
            let coefficients: Vec<f64> =
                scale.iter().cycle().zip(&signs).map(|(s, r)| s * r).collect();
            let camera = realistic_camera(model, focal, &coefficients);
            let pixel = Point2::new(fx * camera.width as f64, fy * camera.height as f64);
            let ray = camera.unproject(&pixel);
            prop_assert!(ray.is_some(), "{model} failed to unproject {pixel:?}");
            let ray = ray.unwrap();
            for depth in [0.5, 3.0] {
                let back = camera.project(&(ray * depth)).unwrap();
                prop_assert!((back - pixel).norm() < 1e-6,
                    "{model}: {pixel:?} -> {back:?} (params {:?})", camera.params());
            }
        }

        /// Project then unproject returns the ray direction, for points inside the view.
        #[test]
        fn project_then_unproject_returns_ray(
            model in model_strategy(),
            x in -0.5f64..0.5,
            y in -0.4f64..0.4,
            depth in 0.1f64..50.0,
        ) {
            let camera = realistic_camera(model, 600.0, &coefficient_scale(model));
            let point_camera = Vector3::new(x * depth, y * depth, depth);
            let pixel = camera.project(&point_camera).unwrap();
            let ray = camera.unproject(&pixel).unwrap();
            prop_assert!((ray * depth - point_camera).norm() < 1e-7 * depth.max(1.0));
        }
    }

    #[test]
    fn every_model_unprojects_the_image_corners() {
        for model in CameraModelKind::ALL {
            let camera = realistic_camera(model, 400.0, &coefficient_scale(model));
            for (x, y) in [(0.0, 0.0), (800.0, 0.0), (0.0, 600.0), (800.0, 600.0)] {
                let pixel = Point2::new(x, y);
                let ray = camera
                    .unproject(&pixel)
                    .unwrap_or_else(|| panic!("{model} corner {pixel:?}"));
                let back = camera.project(&ray).unwrap();
                assert!((back - pixel).norm() < 1e-6, "{model}: {back:?}");
            }
        }
    }
}
