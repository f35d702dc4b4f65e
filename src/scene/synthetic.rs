//! Deterministic synthetic COLMAP models: points in a ball seen by a ring of cameras, with
//! consistent keypoints and tracks, non-contiguous ids and any camera model.
//!
//! Used for round-trip and interop tests, fuzzing seeds, benchmarks (a 1M-point, 200-image
//! model) and the bundled fixture. This is not the plant generator (`synth`): it knows nothing
//! of plants, only of COLMAP's data model.

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

use super::camera::{Camera, CameraId, CameraModelKind};
use super::model::{Frame, Image, Keypoint, Point3D, Reconstruction, Rig, SensorId, TrackElement};
use crate::util::rng::Rng;

/// What to generate.
#[derive(Clone, Debug)]
pub struct SyntheticModelSpec {
    pub num_points: usize,
    pub num_images: usize,
    pub width: u32,
    pub height: u32,
    pub camera_model: CameraModelKind,
    /// One camera for all images (a single lens), or one per image.
    pub shared_camera: bool,
    /// Images come in stereo pairs on a two-camera rig, with rigs and frames (COLMAP ≥ 3.12).
    pub rig_pairs: bool,
    /// Longest track; tracks have 2..=max observations.
    pub max_track_length: usize,
    /// Keypoints per image that observe no 3D point.
    pub unmatched_keypoints_per_image: usize,
    /// Standard deviation of the keypoint noise, pixels.
    pub keypoint_noise_px: f64,
    pub seed: u64,
}

impl Default for SyntheticModelSpec {
    fn default() -> Self {
        Self {
            num_points: 2_000,
            num_images: 12,
            width: 320,
            height: 240,
            camera_model: CameraModelKind::SimpleRadial,
            shared_camera: true,
            rig_pairs: false,
            max_track_length: 6,
            unmatched_keypoints_per_image: 20,
            keypoint_noise_px: 0.3,
            seed: 1,
        }
    }
}

/// A camera of the given model with plausible, moderate distortion for its kind.
pub fn example_camera(model: CameraModelKind, id: CameraId, width: u32, height: u32) -> Camera {
    let focal = 1.2 * width as f64;
    let (cx, cy) = (width as f64 / 2.0 + 0.7, height as f64 / 2.0 - 0.4);
    let mut params = match model {
        CameraModelKind::SimplePinhole
        | CameraModelKind::SimpleRadial
        | CameraModelKind::Radial
        | CameraModelKind::SimpleRadialFisheye
        | CameraModelKind::RadialFisheye => vec![focal, cx, cy],
        _ => vec![focal, focal * 1.002, cx, cy],
    };
    let distortion: &[f64] = match model {
        CameraModelKind::SimplePinhole | CameraModelKind::Pinhole => &[],
        CameraModelKind::SimpleRadial | CameraModelKind::SimpleRadialFisheye => &[-0.04],
        CameraModelKind::Radial | CameraModelKind::RadialFisheye => &[-0.04, 0.01],
        CameraModelKind::OpenCv => &[-0.05, 0.01, 0.001, -0.0005],
        CameraModelKind::OpenCvFisheye => &[0.02, -0.01, 0.003, -0.001],
        CameraModelKind::FullOpenCv => &[-0.05, 0.01, 0.001, -0.0005, 0.002, 0.01, 0.001, 0.0005],
        CameraModelKind::Fov => &[0.4],
        CameraModelKind::ThinPrismFisheye => {
            &[0.02, -0.01, 0.001, -0.0005, 0.002, -0.001, 0.0008, -0.0004]
        }
        CameraModelKind::RadTanThinPrismFisheye => &[
            0.02, -0.01, 0.002, -0.001, 0.0005, -0.0002, 0.001, -0.0005, 0.0008, 0.0001, -0.0004,
            0.0001,
        ],
    };
    params.extend_from_slice(distortion);
    Camera::new(id, model, width as u64, height as u64, params)
        .unwrap_or_else(|e| unreachable!("example camera parameters are valid: {e}"))
}

/// `camera_from_world` for a camera at `center_world` looking at `target_world`, y down.
pub fn look_at(center_world: Point3<f64>, target_world: Point3<f64>) -> Isometry3<f64> {
    let forward = (target_world - center_world).normalize();
    let world_up = if forward.z.abs() > 0.99 {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let right = forward.cross(&world_up).normalize();
    let down = forward.cross(&right);
    // Rows of the rotation are the camera axes (x right, y down, z forward) in world frame.
    let rotation_matrix =
        nalgebra::Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
    // The rows are orthonormal by construction; `from_matrix` (an iterative fit) can fail
    // near half-turn rotations, the exact conversion cannot.
    let rotation = UnitQuaternion::from_rotation_matrix(
        &nalgebra::Rotation3::from_matrix_unchecked(rotation_matrix),
    );
    let translation = -(rotation * center_world.coords);
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// Image id of the `i`-th generated image (deliberately non-contiguous).
fn image_id(i: usize) -> u32 {
    3 * i as u32 + 2
}

/// Point id of the `i`-th generated point (deliberately non-contiguous).
fn point_id(i: usize) -> u64 {
    7 * i as u64 + 100
}

/// Generates a consistent model. Deterministic for a given spec.
pub fn generate(spec: &SyntheticModelSpec) -> Reconstruction {
    let mut rng = Rng::seed_from(spec.seed);
    let num_images = if spec.rig_pairs {
        spec.num_images.div_ceil(2) * 2
    } else {
        spec.num_images
    };
    let cameras: Vec<Camera> = if spec.rig_pairs {
        (0..2)
            .map(|i| example_camera(spec.camera_model, i + 1, spec.width, spec.height))
            .collect()
    } else if spec.shared_camera {
        vec![example_camera(
            spec.camera_model,
            1,
            spec.width,
            spec.height,
        )]
    } else {
        (0..num_images)
            .map(|i| example_camera(spec.camera_model, 10 + i as u32, spec.width, spec.height))
            .collect()
    };

    // Cameras on a ring (two heights) around a unit ball, looking at its centre.
    let baseline = Isometry3::translation(-0.3, 0.0, 0.0);
    let mut poses = Vec::with_capacity(num_images);
    let ring_positions = if spec.rig_pairs {
        num_images / 2
    } else {
        num_images
    };
    for i in 0..ring_positions {
        let angle = std::f64::consts::TAU * i as f64 / ring_positions.max(1) as f64;
        let height = if i % 2 == 0 { 0.8 } else { 2.0 };
        let center = Point3::new(4.0 * angle.cos(), 4.0 * angle.sin(), height);
        let pose = look_at(center, Point3::new(0.0, 0.0, 0.3 * rng.range(-1.0, 1.0)));
        poses.push(pose);
        if spec.rig_pairs {
            poses.push(baseline * pose);
        }
    }
    let camera_of_image = |i: usize| -> &Camera {
        if spec.rig_pairs {
            &cameras[i % 2]
        } else if spec.shared_camera {
            &cameras[0]
        } else {
            &cameras[i]
        }
    };

    // Points and their observations.
    let mut per_image: Vec<Vec<(Point2<f64>, Option<usize>)>> = vec![Vec::new(); num_images];
    let mut positions = Vec::with_capacity(spec.num_points);
    let mut colors = Vec::with_capacity(spec.num_points);
    for p in 0..spec.num_points {
        let position = loop {
            let v = Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            if v.norm_squared() <= 1.0 {
                break Point3::from(v);
            }
        };
        colors.push([
            (127.5 * (position.x + 1.0)) as u8,
            (127.5 * (position.y + 1.0)) as u8,
            (127.5 * (position.z + 1.0)) as u8,
        ]);
        positions.push(position);
        let wanted = 2 + rng.below(spec.max_track_length.saturating_sub(1).max(1));
        let start = rng.below(num_images);
        let mut found = 0;
        for step in 0..num_images {
            if found == wanted {
                break;
            }
            let i = (start + step) % num_images;
            let camera = camera_of_image(i);
            let Some(uv) = camera.project(&(poses[i] * position).coords) else {
                continue;
            };
            let noisy = uv + pixel_noise(&mut rng, spec.keypoint_noise_px);
            if camera.contains(&noisy) {
                per_image[i].push((noisy, Some(p)));
                found += 1;
            }
        }
    }

    // Keypoints: observations plus unmatched features, shuffled.
    let mut tracks: Vec<Vec<TrackElement>> = vec![Vec::new(); spec.num_points];
    let mut images = Vec::with_capacity(num_images);
    for (i, mut entries) in per_image.into_iter().enumerate() {
        let camera = camera_of_image(i);
        for _ in 0..spec.unmatched_keypoints_per_image {
            let uv = Point2::new(
                rng.range(0.0, camera.width as f64),
                rng.range(0.0, camera.height as f64),
            );
            entries.push((uv, None));
        }
        rng.shuffle(&mut entries);
        let id = image_id(i);
        let keypoints = entries
            .iter()
            .enumerate()
            .map(|(k, (uv, point))| {
                if let Some(p) = point {
                    tracks[*p].push(TrackElement {
                        image_id: id,
                        keypoint_index: k as u32,
                    });
                }
                Keypoint {
                    uv_image: *uv,
                    point3d_id: point.map(point_id),
                }
            })
            .collect();
        images.push(Image {
            id,
            camera_id: camera.id,
            name: format!("view_{i:04}.png"),
            camera_from_world: poses[i],
            keypoints,
        });
    }

    let mut points = Vec::with_capacity(spec.num_points);
    for (p, track) in tracks.into_iter().enumerate() {
        // Mean reprojection error over the track, as COLMAP stores it.
        let mut sum = 0.0;
        for t in &track {
            let i = ((t.image_id - 2) / 3) as usize;
            let camera = camera_of_image(i);
            let image = &images[i];
            if let Some(uv) = camera.project(&(image.camera_from_world * positions[p]).coords) {
                sum += (uv - image.keypoints[t.keypoint_index as usize].uv_image).norm();
            }
        }
        let error = if track.is_empty() {
            0.0
        } else {
            sum / track.len() as f64
        };
        points.push(Point3D {
            id: point_id(p),
            position_world: positions[p],
            color: colors[p],
            error,
            track,
        });
    }

    let (rigs, frames) = if spec.rig_pairs {
        let rig = Rig {
            id: 1,
            reference_sensor: Some(SensorId::camera(cameras[0].id)),
            sensors: vec![(SensorId::camera(cameras[1].id), Some(baseline))],
        };
        let frames = (0..num_images / 2)
            .map(|f| Frame {
                id: f as u32 + 1,
                rig_id: 1,
                rig_from_world: poses[2 * f],
                data: vec![
                    (SensorId::camera(cameras[0].id), image_id(2 * f) as u64),
                    (SensorId::camera(cameras[1].id), image_id(2 * f + 1) as u64),
                ],
            })
            .collect();
        (vec![rig], frames)
    } else {
        (Vec::new(), Vec::new())
    };
    Reconstruction::from_parts_with_rigs(cameras, images, points, rigs, frames)
        .unwrap_or_else(|e| unreachable!("generated model is consistent: {e}"))
}

/// Settings of the bundled `fixtures/toy_scene` (kept here so a test can check the fixture
/// is what the generator makes today).
pub fn toy_scene_spec() -> SyntheticModelSpec {
    SyntheticModelSpec {
        num_points: 1_500,
        num_images: 8,
        width: 240,
        height: 180,
        camera_model: CameraModelKind::SimpleRadial,
        seed: 2026,
        ..Default::default()
    }
}

/// Renders each image of a model as the splats of its keypoints (observed points in their
/// colour, unmatched keypoints grey) on a dark background, and writes `dir/<image name>`.
/// Gives a generated model image files of the right size for its cameras.
pub fn render_point_splats(
    model: &Reconstruction,
    dir: &std::path::Path,
) -> Result<(), crate::scene::SceneError> {
    use crate::scene::SceneError;
    use opencv::core::{Mat, Point, Scalar, Vector};
    use opencv::imgproc;

    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    for image in model.images() {
        let path = dir.join(&image.name);
        let cv_error = |e: opencv::Error| SceneError::Image {
            path: path.clone(),
            image_id: image.id,
            message: format!("OpenCV: {e}"),
        };
        let camera = model.camera_of(image);
        let mut mat = Mat::new_rows_cols_with_default(
            camera.height as i32,
            camera.width as i32,
            opencv::core::CV_8UC3,
            Scalar::new(40.0, 32.0, 28.0, 0.0),
        )
        .map_err(cv_error)?;
        for keypoint in &image.keypoints {
            let color = match keypoint.point3d_id.and_then(|id| model.point(id)) {
                Some(point) => {
                    let [r, g, b] = point.color;
                    Scalar::new(b as f64, g as f64, r as f64, 0.0)
                }
                None => Scalar::new(120.0, 120.0, 120.0, 0.0),
            };
            // COLMAP pixel centres are at +0.5; OpenCV's at integers.
            let center = Point::new(
                (keypoint.uv_image.x - 0.5).round() as i32,
                (keypoint.uv_image.y - 0.5).round() as i32,
            );
            imgproc::circle(&mut mat, center, 1, color, -1, imgproc::LINE_8, 0)
                .map_err(cv_error)?;
        }
        let mut encoded = Vector::<u8>::new();
        opencv::imgcodecs::imencode(".png", &mat, &mut encoded, &Vector::new())
            .map_err(cv_error)?;
        crate::util::atomic::write_atomic(&path, encoded.as_slice())
            .map_err(|e| SceneError::io(&path, e))?;
    }
    Ok(())
}

/// Isotropic Gaussian pixel noise with standard deviation `sigma`.
fn pixel_noise(rng: &mut Rng, sigma: f64) -> nalgebra::Vector2<f64> {
    nalgebra::Vector2::new(sigma * rng.normal(), sigma * rng.normal())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_model_is_consistent_and_deterministic() {
        let spec = SyntheticModelSpec::default();
        let a = generate(&spec);
        let b = generate(&spec);
        assert_eq!(a, b);
        assert_eq!(a.points().len(), 2_000);
        assert_eq!(a.images().len(), 12);
        let mean_track = a.num_observations() as f64 / a.points().len() as f64;
        assert!(mean_track > 2.5, "mean track length {mean_track}");
        // Stored errors equal recomputed ones.
        for p in a.points().iter().take(50) {
            let errors = a.reprojection_errors(p);
            let mean = errors.iter().flatten().sum::<f64>() / errors.len() as f64;
            assert!((mean - p.error).abs() < 1e-9);
        }
    }

    #[test]
    fn look_at_centres_the_target() {
        let pose = look_at(Point3::new(3.0, -2.0, 1.0), Point3::new(0.5, 0.5, 0.0));
        let target_camera = pose * Point3::new(0.5, 0.5, 0.0);
        assert!(target_camera.x.abs() < 1e-12 && target_camera.y.abs() < 1e-12);
        assert!(target_camera.z > 0.0);
        // World up (+z) maps to image up (−y in camera frame).
        let up_camera = pose.rotation * Vector3::z();
        assert!(up_camera.y < 0.0);
        // Every direction on a ring, including half turns, looks at the target.
        for k in 0..360 {
            let a = (k as f64).to_radians();
            let center = Point3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.7);
            let target = Point3::new(0.1, -0.2, 0.3);
            let p = look_at(center, target) * target;
            assert!(
                p.x.abs() < 1e-9 && p.y.abs() < 1e-9 && p.z > 0.0,
                "{k}°: {p:?}"
            );
        }
    }

    #[test]
    fn rig_pairs_compose_to_the_image_poses() {
        let spec = SyntheticModelSpec {
            rig_pairs: true,
            num_images: 6,
            num_points: 200,
            ..Default::default()
        };
        let model = generate(&spec);
        assert_eq!(model.frames().len(), 3);
        let mut images = model.images().to_vec();
        for image in &mut images {
            image.camera_from_world = Isometry3::identity();
        }
        crate::scene::model::compose_rig_poses(&mut images, model.rigs(), model.frames()).unwrap();
        for (composed, original) in images.iter().zip(model.images()) {
            let difference = composed.camera_from_world.inverse() * original.camera_from_world;
            assert!(difference.translation.vector.norm() < 1e-12);
            assert!(difference.rotation.angle() < 1e-12);
        }
    }
}
