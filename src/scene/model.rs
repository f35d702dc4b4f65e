//! The in-memory COLMAP sparse model: cameras, registered images with their keypoints, 3D points
//! with their tracks, and (for models written by COLMAP ≥ 3.12) rigs and frames.
//!
//! Ids are COLMAP's and need not be contiguous; records keep their file order and are found by
//! id through hash indices. [`Reconstruction::from_parts`] checks every cross-reference once, so
//! later stages can index without re-checking.

use std::collections::HashMap;

use rayon::prelude::*;

use nalgebra::{Isometry3, Point2, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::camera::{Camera, CameraId};
use crate::util::id_hash::{IdMap, id_map_with_capacity};

/// Identifier of a registered image (`image_t`, 32 bit).
pub type ImageId = u32;
/// Identifier of a 3D point (`point3D_t`, 64 bit).
pub type Point3dId = u64;
/// Identifier of a rig (`rig_t`).
pub type RigId = u32;
/// Identifier of a frame (`frame_t`).
pub type FrameId = u32;

/// COLMAP's marker for "this keypoint has no 3D point" in binary files (`kInvalidPoint3DId`).
pub const INVALID_POINT3D_ID: u64 = u64::MAX;

/// A 2D feature of an image, in pixels (COLMAP convention), optionally triangulated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Keypoint {
    pub uv_image: Point2<f64>,
    pub point3d_id: Option<Point3dId>,
}

/// A registered image: its pose, camera, file name (relative to the images folder) and keypoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub id: ImageId,
    pub camera_id: CameraId,
    pub name: String,
    /// Rigid transform taking world points into this camera's frame.
    pub camera_from_world: Isometry3<f64>,
    pub keypoints: Vec<Keypoint>,
}

impl Image {
    /// The camera centre in world coordinates, `−Rᵀt`.
    pub fn center_world(&self) -> Point3<f64> {
        self.camera_from_world.inverse() * Point3::origin()
    }

    /// The viewing direction (camera +z) in world coordinates.
    pub fn view_direction_world(&self) -> Vector3<f64> {
        self.camera_from_world.rotation.inverse() * Vector3::z()
    }

    /// Number of keypoints that observe a 3D point.
    pub fn num_observations(&self) -> usize {
        self.keypoints
            .iter()
            .filter(|k| k.point3d_id.is_some())
            .count()
    }
}

/// One observation of a 3D point: an image and the index of the keypoint in that image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct TrackElement {
    pub image_id: ImageId,
    pub keypoint_index: u32,
}

/// A triangulated 3D point with colour, mean reprojection error (pixels) and its track.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Point3D {
    pub id: Point3dId,
    pub position_world: Point3<f64>,
    pub color: [u8; 3],
    /// Mean reprojection error in pixels as stored by COLMAP (−1 when never computed).
    pub error: f64,
    pub track: Vec<TrackElement>,
}

/// A sensor of a rig (COLMAP `sensor_t`): type 0 is a camera (id = camera id), 1 an IMU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SensorId {
    pub sensor_type: i32,
    pub id: u32,
}

impl SensorId {
    /// COLMAP's `SensorType::CAMERA`.
    pub const CAMERA: i32 = 0;
    /// COLMAP's `SensorType::IMU`.
    pub const IMU: i32 = 1;

    pub fn camera(camera_id: CameraId) -> Self {
        Self {
            sensor_type: Self::CAMERA,
            id: camera_id,
        }
    }

    /// The text-format name of the sensor type.
    pub fn type_name(&self) -> &'static str {
        match self.sensor_type {
            Self::CAMERA => "CAMERA",
            Self::IMU => "IMU",
            _ => "INVALID",
        }
    }

    /// Parses a text-format sensor type name.
    pub fn type_from_name(name: &str) -> Option<i32> {
        match name {
            "CAMERA" => Some(Self::CAMERA),
            "IMU" => Some(Self::IMU),
            _ => None,
        }
    }
}

/// A rig (COLMAP ≥ 3.12): a reference sensor and the other sensors' poses relative to it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rig {
    pub id: RigId,
    /// `None` only for a rig without sensors.
    pub reference_sensor: Option<SensorId>,
    /// Non-reference sensors with their `sensor_from_rig` pose when known.
    pub sensors: Vec<(SensorId, Option<Isometry3<f64>>)>,
}

/// A frame (COLMAP ≥ 3.12): one capture of a rig, with the images (data) it holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    pub id: FrameId,
    pub rig_id: RigId,
    pub rig_from_world: Isometry3<f64>,
    /// `(sensor, data id)`; for a camera the data id is the image id.
    pub data: Vec<(SensorId, u64)>,
}

/// A broken cross-reference or duplicate found while assembling a model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("duplicate {kind} id {id}")]
    DuplicateId { kind: &'static str, id: u64 },
    #[error("image {image_id} ({name}) uses camera {camera_id}, which is not in the model")]
    MissingCamera {
        image_id: ImageId,
        name: String,
        camera_id: CameraId,
    },
    #[error(
        "image {image_id} keypoint {keypoint_index} names 3D point {point3d_id}, which is not in the model"
    )]
    KeypointMissingPoint {
        image_id: ImageId,
        keypoint_index: usize,
        point3d_id: Point3dId,
    },
    #[error("3D point {point3d_id} track element {element}: image {image_id} is not in the model")]
    TrackMissingImage {
        point3d_id: Point3dId,
        element: usize,
        image_id: ImageId,
    },
    #[error(
        "3D point {point3d_id} track element {element}: image {image_id} has {num_keypoints} keypoints, index {keypoint_index} is out of range"
    )]
    TrackMissingKeypoint {
        point3d_id: Point3dId,
        element: usize,
        image_id: ImageId,
        keypoint_index: u32,
        num_keypoints: usize,
    },
    #[error(
        "3D point {point3d_id} track element {element}: keypoint {keypoint_index} of image {image_id} belongs to {actual}"
    )]
    TrackKeypointMismatch {
        point3d_id: Point3dId,
        element: usize,
        image_id: ImageId,
        keypoint_index: u32,
        actual: String,
    },
    #[error("3D point {point3d_id} has a non-finite coordinate")]
    NonFinitePoint { point3d_id: Point3dId },
    #[error("image {image_id} ({name}) is in no frame of the model's frames file")]
    ImageWithoutFrame { image_id: ImageId, name: String },
    #[error("frame {frame_id} uses rig {rig_id}, which is not in the rigs file")]
    FrameMissingRig { frame_id: FrameId, rig_id: RigId },
    #[error(
        "frame {frame_id}: camera {camera_id} is not a sensor of rig {rig_id} or has no pose in it"
    )]
    SensorWithoutPose {
        frame_id: FrameId,
        rig_id: RigId,
        camera_id: CameraId,
    },
}

/// A COLMAP sparse model with id indices. Records keep their file order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Reconstruction {
    cameras: Vec<Camera>,
    images: Vec<Image>,
    points: Vec<Point3D>,
    rigs: Vec<Rig>,
    frames: Vec<Frame>,
    #[serde(skip)]
    camera_index: IdMap<CameraId, usize>,
    #[serde(skip)]
    image_index: IdMap<ImageId, usize>,
    #[serde(skip)]
    point_index: IdMap<Point3dId, usize>,
}

fn build_index<T, Id: std::hash::Hash + Eq + Copy + Into<u64>>(
    items: &[T],
    kind: &'static str,
    id_of: impl Fn(&T) -> Id,
) -> Result<IdMap<Id, usize>, ModelError> {
    let mut index = id_map_with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let id = id_of(item);
        if index.insert(id, i).is_some() {
            return Err(ModelError::DuplicateId {
                kind,
                id: id.into(),
            });
        }
    }
    Ok(index)
}

impl Reconstruction {
    /// Assembles a model and checks it: unique ids, every image's camera exists, every
    /// keypoint's 3D point exists, every track element names an existing image and keypoint
    /// that points back to the same 3D point, all coordinates finite.
    pub fn from_parts(
        cameras: Vec<Camera>,
        images: Vec<Image>,
        points: Vec<Point3D>,
    ) -> Result<Self, ModelError> {
        Self::from_parts_with_rigs(cameras, images, points, Vec::new(), Vec::new())
    }

    /// As [`Reconstruction::from_parts`], with rigs and frames (COLMAP ≥ 3.12) kept as read.
    /// Image poses must already be composed from them (see [`compose_rig_poses`]).
    pub fn from_parts_with_rigs(
        cameras: Vec<Camera>,
        images: Vec<Image>,
        points: Vec<Point3D>,
        rigs: Vec<Rig>,
        frames: Vec<Frame>,
    ) -> Result<Self, ModelError> {
        let camera_index = build_index(&cameras, "camera", |c| c.id)?;
        let (image_index, point_index) = rayon::join(
            || build_index(&images, "image", |i| i.id),
            || build_index(&points, "3D point", |p| p.id),
        );
        let (image_index, point_index) = (image_index?, point_index?);
        let model = Self {
            cameras,
            images,
            points,
            rigs,
            frames,
            camera_index,
            image_index,
            point_index,
        };
        model.validate()?;
        Ok(model)
    }

    fn validate(&self) -> Result<(), ModelError> {
        self.images
            .par_iter()
            .try_for_each(|image| self.validate_image(image))?;
        self.points
            .par_iter()
            .try_for_each(|point| self.validate_point(point))
    }

    fn validate_image(&self, image: &Image) -> Result<(), ModelError> {
        if !self.camera_index.contains_key(&image.camera_id) {
            return Err(ModelError::MissingCamera {
                image_id: image.id,
                name: image.name.clone(),
                camera_id: image.camera_id,
            });
        }
        for (keypoint_index, keypoint) in image.keypoints.iter().enumerate() {
            if let Some(point3d_id) = keypoint.point3d_id
                && !self.point_index.contains_key(&point3d_id)
            {
                return Err(ModelError::KeypointMissingPoint {
                    image_id: image.id,
                    keypoint_index,
                    point3d_id,
                });
            }
        }
        Ok(())
    }

    fn validate_point(&self, point: &Point3D) -> Result<(), ModelError> {
        if !point.position_world.iter().all(|c| c.is_finite()) {
            return Err(ModelError::NonFinitePoint {
                point3d_id: point.id,
            });
        }
        for (element, t) in point.track.iter().enumerate() {
            let Some(image) = self.image(t.image_id) else {
                return Err(ModelError::TrackMissingImage {
                    point3d_id: point.id,
                    element,
                    image_id: t.image_id,
                });
            };
            let Some(keypoint) = image.keypoints.get(t.keypoint_index as usize) else {
                return Err(ModelError::TrackMissingKeypoint {
                    point3d_id: point.id,
                    element,
                    image_id: t.image_id,
                    keypoint_index: t.keypoint_index,
                    num_keypoints: image.keypoints.len(),
                });
            };
            if keypoint.point3d_id != Some(point.id) {
                return Err(ModelError::TrackKeypointMismatch {
                    point3d_id: point.id,
                    element,
                    image_id: t.image_id,
                    keypoint_index: t.keypoint_index,
                    actual: match keypoint.point3d_id {
                        Some(other) => format!("3D point {other}"),
                        None => "no 3D point".to_owned(),
                    },
                });
            }
        }
        Ok(())
    }

    /// Rebuilds the id indices (after deserialising, which skips them).
    pub fn rebuild_indices(&mut self) -> Result<(), ModelError> {
        self.camera_index = build_index(&self.cameras, "camera", |c| c.id)?;
        self.image_index = build_index(&self.images, "image", |i| i.id)?;
        self.point_index = build_index(&self.points, "3D point", |p| p.id)?;
        self.validate()
    }

    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }
    pub fn images(&self) -> &[Image] {
        &self.images
    }
    pub fn points(&self) -> &[Point3D] {
        &self.points
    }
    pub fn rigs(&self) -> &[Rig] {
        &self.rigs
    }
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    pub fn camera(&self, id: CameraId) -> Option<&Camera> {
        self.camera_index.get(&id).map(|&i| &self.cameras[i])
    }
    pub fn image(&self, id: ImageId) -> Option<&Image> {
        self.image_index.get(&id).map(|&i| &self.images[i])
    }
    pub fn point(&self, id: Point3dId) -> Option<&Point3D> {
        self.point_index.get(&id).map(|&i| &self.points[i])
    }
    /// Position of an image in file order (COLMAP's dense workspace numbers images this way).
    pub fn image_position(&self, id: ImageId) -> Option<usize> {
        self.image_index.get(&id).copied()
    }
    /// Position of a 3D point in file order.
    pub fn point_position(&self, id: Point3dId) -> Option<usize> {
        self.point_index.get(&id).copied()
    }

    /// The camera of an image. Always present once the model is validated.
    pub fn camera_of(&self, image: &Image) -> &Camera {
        &self.cameras[self.camera_index[&image.camera_id]]
    }

    /// Total number of observations (sum of track lengths).
    pub fn num_observations(&self) -> usize {
        self.points.iter().map(|p| p.track.len()).sum()
    }

    /// Projects a world point into an image, in pixels; `None` if behind the camera.
    pub fn project(&self, image: &Image, point_world: &Point3<f64>) -> Option<Point2<f64>> {
        let point_camera = image.camera_from_world * point_world;
        self.camera_of(image).project(&point_camera.coords)
    }

    /// Reprojection error (pixels) of every observation of a point, in track order; `None`
    /// entries for observations whose projection failed (behind the camera).
    pub fn reprojection_errors(&self, point: &Point3D) -> Vec<Option<f64>> {
        point
            .track
            .iter()
            .map(|t| {
                let image = self.image(t.image_id)?;
                let keypoint = image.keypoints.get(t.keypoint_index as usize)?;
                let projected = self.project(image, &point.position_world)?;
                Some((projected - keypoint.uv_image).norm())
            })
            .collect()
    }
}

/// Builds a unit quaternion from file values `(w, x, y, z)`. Values that are already unit
/// length are kept bit-exact so that read → write → read round-trips; others are normalised.
/// `None` for a zero or non-finite quaternion.
pub fn unit_quaternion_from_wxyz(w: f64, x: f64, y: f64, z: f64) -> Option<UnitQuaternion<f64>> {
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    if !norm.is_finite() || norm < 1e-12 {
        return None;
    }
    if (norm - 1.0).abs() < 1e-12 {
        Some(UnitQuaternion::new_unchecked(q))
    } else {
        Some(UnitQuaternion::from_quaternion(q))
    }
}

/// Builds a pose from file values `(qw, qx, qy, qz, tx, ty, tz)`.
pub fn isometry_from_qt(values: &[f64; 7]) -> Option<Isometry3<f64>> {
    let rotation = unit_quaternion_from_wxyz(values[0], values[1], values[2], values[3])?;
    let t = Vector3::new(values[4], values[5], values[6]);
    t.iter()
        .all(|c| c.is_finite())
        .then(|| Isometry3::from_parts(Translation3::from(t), rotation))
}

/// The file values `(qw, qx, qy, qz, tx, ty, tz)` of a pose.
pub fn qt_from_isometry(pose: &Isometry3<f64>) -> [f64; 7] {
    let q = pose.rotation.quaternion();
    let t = pose.translation.vector;
    [q.w, q.i, q.j, q.k, t.x, t.y, t.z]
}

/// Sets each image's `camera_from_world` from its frame and rig, as COLMAP ≥ 3.12 does on read:
/// `camera_from_world = sensor_from_rig ∘ rig_from_world` (identity for the reference sensor).
pub fn compose_rig_poses(
    images: &mut [Image],
    rigs: &[Rig],
    frames: &[Frame],
) -> Result<(), ModelError> {
    if rigs.is_empty() && frames.is_empty() {
        return Ok(());
    }
    let rig_by_id: HashMap<RigId, &Rig> = rigs.iter().map(|r| (r.id, r)).collect();
    let mut frame_of_image: HashMap<(CameraId, u64), &Frame> = HashMap::new();
    for frame in frames {
        for (sensor, data_id) in &frame.data {
            if sensor.sensor_type == SensorId::CAMERA {
                frame_of_image.insert((sensor.id, *data_id), frame);
            }
        }
    }
    for image in images.iter_mut() {
        let Some(frame) = frame_of_image.get(&(image.camera_id, image.id as u64)) else {
            return Err(ModelError::ImageWithoutFrame {
                image_id: image.id,
                name: image.name.clone(),
            });
        };
        let Some(rig) = rig_by_id.get(&frame.rig_id) else {
            return Err(ModelError::FrameMissingRig {
                frame_id: frame.id,
                rig_id: frame.rig_id,
            });
        };
        let sensor = SensorId::camera(image.camera_id);
        let sensor_from_rig = if rig.reference_sensor == Some(sensor) {
            Some(Isometry3::identity())
        } else {
            rig.sensors
                .iter()
                .find(|(s, _)| *s == sensor)
                .and_then(|(_, pose)| *pose)
        };
        let Some(sensor_from_rig) = sensor_from_rig else {
            return Err(ModelError::SensorWithoutPose {
                frame_id: frame.id,
                rig_id: rig.id,
                camera_id: image.camera_id,
            });
        };
        image.camera_from_world = sensor_from_rig * frame.rig_from_world;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::camera::Camera;

    fn tiny() -> (Vec<Camera>, Vec<Image>, Vec<Point3D>) {
        let cameras = vec![Camera::simple_pinhole(7, 100, 80, 90.0)];
        let images = vec![Image {
            id: 3,
            camera_id: 7,
            name: "a.png".into(),
            camera_from_world: Isometry3::translation(0.0, 0.0, 5.0),
            keypoints: vec![
                Keypoint {
                    uv_image: Point2::new(50.0, 40.0),
                    point3d_id: Some(11),
                },
                Keypoint {
                    uv_image: Point2::new(10.0, 10.0),
                    point3d_id: None,
                },
            ],
        }];
        let points = vec![Point3D {
            id: 11,
            position_world: Point3::origin(),
            color: [1, 2, 3],
            error: 0.0,
            track: vec![TrackElement {
                image_id: 3,
                keypoint_index: 0,
            }],
        }];
        (cameras, images, points)
    }

    #[test]
    fn valid_model_indexes_by_id() {
        let (c, i, p) = tiny();
        let model = Reconstruction::from_parts(c, i, p).unwrap();
        assert_eq!(model.image(3).unwrap().name, "a.png");
        assert_eq!(model.point(11).unwrap().color, [1, 2, 3]);
        assert!(model.camera(8).is_none());
        let errors = model.reprojection_errors(model.point(11).unwrap());
        assert_eq!(errors, vec![Some(0.0)]);
        assert_eq!(
            model.image(3).unwrap().center_world(),
            Point3::new(0., 0., -5.)
        );
    }

    #[test]
    fn broken_references_are_named() {
        let (c, mut i, p) = tiny();
        i[0].camera_id = 9;
        let err = Reconstruction::from_parts(c, i, p).unwrap_err();
        assert!(err.to_string().contains("camera 9"), "{err}");

        let (c, i, mut p) = tiny();
        p[0].track[0].keypoint_index = 5;
        let err = Reconstruction::from_parts(c, i, p).unwrap_err();
        assert!(
            matches!(err, ModelError::TrackMissingKeypoint { .. }),
            "{err}"
        );

        let (c, i, mut p) = tiny();
        p[0].track[0].keypoint_index = 1;
        let err = Reconstruction::from_parts(c, i, p).unwrap_err();
        assert!(
            matches!(err, ModelError::TrackKeypointMismatch { .. }),
            "{err}"
        );

        let (c, i, mut p) = tiny();
        p.push(p[0].clone());
        let err = Reconstruction::from_parts(c, i, p).unwrap_err();
        assert_eq!(
            err,
            ModelError::DuplicateId {
                kind: "3D point",
                id: 11
            }
        );

        let (c, i, mut p) = tiny();
        p[0].position_world.x = f64::INFINITY;
        assert!(matches!(
            Reconstruction::from_parts(c, i, p),
            Err(ModelError::NonFinitePoint { .. })
        ));
    }

    #[test]
    fn rig_poses_compose_sensor_from_rig_after_rig_from_world() {
        let (_, mut images, _) = tiny();
        let sensor_from_rig = Isometry3::translation(1.0, 0.0, 0.0);
        let rig_from_world = Isometry3::translation(0.0, 2.0, 0.0);
        let rigs = vec![Rig {
            id: 1,
            reference_sensor: Some(SensorId::camera(99)),
            sensors: vec![(SensorId::camera(7), Some(sensor_from_rig))],
        }];
        let frames = vec![Frame {
            id: 4,
            rig_id: 1,
            rig_from_world,
            data: vec![(SensorId::camera(7), 3)],
        }];
        compose_rig_poses(&mut images, &rigs, &frames).unwrap();
        let t = images[0].camera_from_world.translation.vector;
        assert_eq!(t, Vector3::new(1.0, 2.0, 0.0));

        let frames_without_image: Vec<Frame> = Vec::new();
        let err = compose_rig_poses(&mut images, &rigs, &frames_without_image).unwrap_err();
        assert!(matches!(
            err,
            ModelError::ImageWithoutFrame { image_id: 3, .. }
        ));
    }

    #[test]
    fn quaternion_round_trip_is_bit_exact_for_unit_input() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0);
        let c = q.quaternion();
        let back = unit_quaternion_from_wxyz(c.w, c.i, c.j, c.k).unwrap();
        assert_eq!(back, q);
        assert!(unit_quaternion_from_wxyz(0.0, 0.0, 0.0, 0.0).is_none());
        assert!(unit_quaternion_from_wxyz(f64::NAN, 0.0, 0.0, 1.0).is_none());
        let normalized = unit_quaternion_from_wxyz(2.0, 0.0, 0.0, 0.0).unwrap();
        assert_eq!(normalized.quaternion().w, 1.0);
    }
}
