//! COLMAP's binary sparse-model format (`cameras.bin`, `images.bin`, `points3D.bin`, and the
//! optional `rigs.bin`, `frames.bin` of COLMAP ≥ 3.12). All values little-endian.
//!
//! Parsers work on byte slices so that they can be fuzzed; every record count is checked
//! against the bytes that remain before anything is allocated from it.

use std::path::Path;

use nalgebra::Point2;

use super::camera::{Camera, CameraModelKind};
use super::error::{Location, SceneError, SceneResult};
use super::model::{
    Frame, INVALID_POINT3D_ID, Image, Keypoint, Point3D, Reconstruction, Rig, SensorId,
    TrackElement, isometry_from_qt, qt_from_isometry,
};

/// Sizes (bytes) of the smallest possible record of each kind, used to bound counts.
const MIN_CAMERA_RECORD: usize = 4 + 4 + 8 + 8;
const MIN_IMAGE_RECORD: usize = 4 + 7 * 8 + 4 + 1 + 8;
const KEYPOINT_RECORD: usize = 8 + 8 + 8;
const MIN_POINT_RECORD: usize = 8 + 3 * 8 + 3 + 8 + 8;
const TRACK_ELEMENT_RECORD: usize = 4 + 4;
const MIN_RIG_RECORD: usize = 4 + 4;
const MIN_FRAME_RECORD: usize = 4 + 4 + 7 * 8 + 4;
const SENSOR_DATA_RECORD: usize = 4 + 4 + 8;
/// Longest image name accepted (bytes), far beyond any real path.
const MAX_NAME_LEN: usize = 4096;

/// A cursor over a file's bytes that reports truncation with the file name and offset.
struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    path: &'a Path,
    record: String,
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8], path: &'a Path) -> Self {
        Self {
            data,
            pos: 0,
            path,
            record: "header".to_owned(),
        }
    }

    fn set_record(&mut self, record: impl FnOnce() -> String) {
        self.record = record();
    }

    fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Parse {
            path: self.path.to_path_buf(),
            location: Location::Byte(self.pos as u64),
            record: self.record.clone(),
            message: message.into(),
        }
    }

    fn take<const N: usize>(&mut self) -> SceneResult<[u8; N]> {
        match self.data.get(self.pos..self.pos + N) {
            Some(bytes) => {
                self.pos += N;
                let mut out = [0u8; N];
                out.copy_from_slice(bytes);
                Ok(out)
            }
            None => Err(self.error(format!(
                "file truncated: needs {N} more bytes, {} left",
                self.remaining()
            ))),
        }
    }

    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn u8(&mut self) -> SceneResult<u8> {
        Ok(self.take::<1>()?[0])
    }
    fn u32(&mut self) -> SceneResult<u32> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn i32(&mut self) -> SceneResult<i32> {
        Ok(i32::from_le_bytes(self.take()?))
    }
    fn u64(&mut self) -> SceneResult<u64> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    fn f64(&mut self) -> SceneResult<f64> {
        Ok(f64::from_le_bytes(self.take()?))
    }

    fn pose(&mut self, what: &str) -> SceneResult<nalgebra::Isometry3<f64>> {
        let mut values = [0.0; 7];
        for v in &mut values {
            *v = self.f64()?;
        }
        isometry_from_qt(&values)
            .ok_or_else(|| self.error(format!("{what} is degenerate or not finite: {values:?}")))
    }

    /// Reads a count and checks that `count × min_record_size` bytes remain.
    fn count(&mut self, what: &str, min_record_size: usize) -> SceneResult<usize> {
        let count = self.u64()?;
        let fits = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(min_record_size))
            .is_some_and(|bytes| bytes <= self.remaining());
        if !fits {
            return Err(self.error(format!(
                "{what} count {count} cannot fit in the {} bytes left (each needs at least {min_record_size}): file truncated or count corrupt",
                self.remaining()
            )));
        }
        Ok(count as usize)
    }

    fn u32_count(&mut self, what: &str, min_record_size: usize) -> SceneResult<usize> {
        let count = self.u32()? as usize;
        if count.saturating_mul(min_record_size) > self.remaining() {
            return Err(self.error(format!(
                "{what} count {count} cannot fit in the {} bytes left: file truncated or count corrupt",
                self.remaining()
            )));
        }
        Ok(count)
    }

    fn nul_terminated_string(&mut self) -> SceneResult<String> {
        let rest = &self.data[self.pos.min(self.data.len())..];
        let Some(len) = rest.iter().take(MAX_NAME_LEN + 1).position(|&b| b == 0) else {
            return Err(self.error(format!(
                "name is not NUL-terminated within {MAX_NAME_LEN} bytes"
            )));
        };
        let name = std::str::from_utf8(&rest[..len])
            .map_err(|e| self.error(format!("name is not UTF-8: {e}")))?
            .to_owned();
        self.pos += len + 1;
        Ok(name)
    }

    fn finish(&self) -> SceneResult<()> {
        if self.remaining() != 0 {
            return Err(SceneError::Parse {
                path: self.path.to_path_buf(),
                location: Location::Byte(self.pos as u64),
                record: "end of file".to_owned(),
                message: format!("{} unexpected trailing bytes", self.remaining()),
            });
        }
        Ok(())
    }
}

/// Parses `cameras.bin`.
pub fn parse_cameras(data: &[u8], path: &Path) -> SceneResult<Vec<Camera>> {
    let mut r = Reader::new(data, path);
    let count = r.count("camera", MIN_CAMERA_RECORD)?;
    let mut cameras = Vec::with_capacity(count);
    for index in 0..count {
        let start = r.pos;
        r.set_record(|| format!("camera record {index}"));
        let id = r.u32()?;
        r.set_record(|| format!("camera {id} (record {index})"));
        let model_id = r.i32()?;
        let Some(model) = CameraModelKind::from_id(model_id) else {
            return Err(r.error(format!("unknown or unsupported camera model id {model_id}")));
        };
        let width = r.u64()?;
        let height = r.u64()?;
        let mut params = Vec::with_capacity(model.num_params());
        for _ in 0..model.num_params() {
            params.push(r.f64()?);
        }
        let camera =
            Camera::new(id, model, width, height, params).map_err(|source| SceneError::Camera {
                path: path.to_path_buf(),
                location: Location::Byte(start as u64),
                camera_id: id,
                source,
            })?;
        cameras.push(camera);
    }
    r.finish()?;
    Ok(cameras)
}

/// Parses `images.bin`.
pub fn parse_images(data: &[u8], path: &Path) -> SceneResult<Vec<Image>> {
    let mut r = Reader::new(data, path);
    let count = r.count("image", MIN_IMAGE_RECORD)?;
    let mut images = Vec::with_capacity(count);
    for index in 0..count {
        r.set_record(|| format!("image record {index}"));
        let id = r.u32()?;
        r.set_record(|| format!("image {id} (record {index})"));
        let camera_from_world = r.pose("camera_from_world pose")?;
        let camera_id = r.u32()?;
        let name = r.nul_terminated_string()?;
        r.set_record(|| format!("image {id} '{name}' (record {index})"));
        let num_keypoints = r.count("keypoint", KEYPOINT_RECORD)?;
        let mut keypoints = Vec::with_capacity(num_keypoints);
        for k in 0..num_keypoints {
            let x = r.f64()?;
            let y = r.f64()?;
            let point3d_id = r.u64()?;
            if !x.is_finite() || !y.is_finite() {
                return Err(r.error(format!("keypoint {k} is not finite ({x}, {y})")));
            }
            keypoints.push(Keypoint {
                uv_image: Point2::new(x, y),
                point3d_id: (point3d_id != INVALID_POINT3D_ID).then_some(point3d_id),
            });
        }
        images.push(Image {
            id,
            camera_id,
            name,
            camera_from_world,
            keypoints,
        });
    }
    r.finish()?;
    Ok(images)
}

/// Parses `points3D.bin`.
pub fn parse_points(data: &[u8], path: &Path) -> SceneResult<Vec<Point3D>> {
    let mut r = Reader::new(data, path);
    let count = r.count("3D point", MIN_POINT_RECORD)?;
    let mut points = Vec::with_capacity(count);
    for index in 0..count {
        let id = r.u64()?;
        let x = r.f64()?;
        let y = r.f64()?;
        let z = r.f64()?;
        let color = r.take::<3>()?;
        let error = r.f64()?;
        if !(x.is_finite() && y.is_finite() && z.is_finite() && error.is_finite()) {
            r.set_record(|| format!("3D point {id} (record {index})"));
            return Err(r.error(format!(
                "non-finite value: xyz ({x}, {y}, {z}), error {error}"
            )));
        }
        let track_len = match r.count("track element", TRACK_ELEMENT_RECORD) {
            Ok(n) => n,
            Err(_) => {
                r.set_record(|| format!("3D point {id} (record {index})"));
                return Err(r.error("track length does not fit in the file"));
            }
        };
        let mut track = Vec::with_capacity(track_len);
        for _ in 0..track_len {
            let image_id = u32::from_le_bytes(r.take()?);
            let keypoint_index = u32::from_le_bytes(r.take()?);
            track.push(TrackElement {
                image_id,
                keypoint_index,
            });
        }
        points.push(Point3D {
            id,
            position_world: nalgebra::Point3::new(x, y, z),
            color,
            error,
            track,
        });
    }
    r.record = "end of file".to_owned();
    r.finish()?;
    Ok(points)
}

/// Parses `rigs.bin` (COLMAP ≥ 3.12).
pub fn parse_rigs(data: &[u8], path: &Path) -> SceneResult<Vec<Rig>> {
    let mut r = Reader::new(data, path);
    let count = r.count("rig", MIN_RIG_RECORD)?;
    let mut rigs = Vec::with_capacity(count);
    for index in 0..count {
        r.set_record(|| format!("rig record {index}"));
        let id = r.u32()?;
        r.set_record(|| format!("rig {id} (record {index})"));
        let num_sensors = r.u32_count("sensor", 8)?;
        let mut reference_sensor = None;
        let mut sensors = Vec::with_capacity(num_sensors.saturating_sub(1));
        if num_sensors > 0 {
            reference_sensor = Some(SensorId {
                sensor_type: r.i32()?,
                id: r.u32()?,
            });
            for _ in 1..num_sensors {
                let sensor = SensorId {
                    sensor_type: r.i32()?,
                    id: r.u32()?,
                };
                let pose = match r.u8()? {
                    0 => None,
                    1 => Some(r.pose("sensor_from_rig pose")?),
                    other => return Err(r.error(format!("has_pose flag is {other}, not 0 or 1"))),
                };
                sensors.push((sensor, pose));
            }
        }
        rigs.push(Rig {
            id,
            reference_sensor,
            sensors,
        });
    }
    r.finish()?;
    Ok(rigs)
}

/// Parses `frames.bin` (COLMAP ≥ 3.12).
pub fn parse_frames(data: &[u8], path: &Path) -> SceneResult<Vec<Frame>> {
    let mut r = Reader::new(data, path);
    let count = r.count("frame", MIN_FRAME_RECORD)?;
    let mut frames = Vec::with_capacity(count);
    for index in 0..count {
        r.set_record(|| format!("frame record {index}"));
        let id = r.u32()?;
        r.set_record(|| format!("frame {id} (record {index})"));
        let rig_id = r.u32()?;
        let rig_from_world = r.pose("rig_from_world pose")?;
        let num_data = r.u32_count("data id", SENSOR_DATA_RECORD)?;
        let mut data_ids = Vec::with_capacity(num_data);
        for _ in 0..num_data {
            let sensor = SensorId {
                sensor_type: r.i32()?,
                id: r.u32()?,
            };
            data_ids.push((sensor, r.u64()?));
        }
        frames.push(Frame {
            id,
            rig_id,
            rig_from_world,
            data: data_ids,
        });
    }
    r.finish()?;
    Ok(frames)
}

/// Little-endian byte sink.
#[derive(Default)]
struct Writer {
    bytes: Vec<u8>,
}

impl Writer {
    fn u8(&mut self, v: u8) {
        self.bytes.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    fn pose(&mut self, pose: &nalgebra::Isometry3<f64>) {
        for v in qt_from_isometry(pose) {
            self.f64(v);
        }
    }
}

/// Serialises cameras in COLMAP's binary layout.
pub fn encode_cameras(cameras: &[Camera]) -> Vec<u8> {
    let mut w = Writer::default();
    w.u64(cameras.len() as u64);
    for camera in cameras {
        w.u32(camera.id);
        w.i32(camera.model.id());
        w.u64(camera.width as u64);
        w.u64(camera.height as u64);
        for &p in camera.params() {
            w.f64(p);
        }
    }
    w.bytes
}

/// Serialises images in COLMAP's binary layout.
pub fn encode_images(images: &[Image]) -> Vec<u8> {
    let mut w = Writer::default();
    w.u64(images.len() as u64);
    for image in images {
        w.u32(image.id);
        w.pose(&image.camera_from_world);
        w.u32(image.camera_id);
        w.bytes.extend_from_slice(image.name.as_bytes());
        w.u8(0);
        w.u64(image.keypoints.len() as u64);
        for k in &image.keypoints {
            w.f64(k.uv_image.x);
            w.f64(k.uv_image.y);
            w.u64(k.point3d_id.unwrap_or(INVALID_POINT3D_ID));
        }
    }
    w.bytes
}

/// Serialises 3D points in COLMAP's binary layout.
pub fn encode_points(points: &[Point3D]) -> Vec<u8> {
    let observations: usize = points.iter().map(|p| p.track.len()).sum();
    let mut w = Writer {
        bytes: Vec::with_capacity(8 + points.len() * MIN_POINT_RECORD + observations * 8),
    };
    w.u64(points.len() as u64);
    for p in points {
        w.u64(p.id);
        for c in p.position_world.iter() {
            w.f64(*c);
        }
        w.bytes.extend_from_slice(&p.color);
        w.f64(p.error);
        w.u64(p.track.len() as u64);
        for t in &p.track {
            w.u32(t.image_id);
            w.u32(t.keypoint_index);
        }
    }
    w.bytes
}

/// Serialises rigs in COLMAP's binary layout.
pub fn encode_rigs(rigs: &[Rig]) -> Vec<u8> {
    let mut w = Writer::default();
    w.u64(rigs.len() as u64);
    for rig in rigs {
        w.u32(rig.id);
        match rig.reference_sensor {
            None => w.u32(0),
            Some(reference) => {
                w.u32(rig.sensors.len() as u32 + 1);
                w.i32(reference.sensor_type);
                w.u32(reference.id);
                for (sensor, pose) in &rig.sensors {
                    w.i32(sensor.sensor_type);
                    w.u32(sensor.id);
                    match pose {
                        Some(pose) => {
                            w.u8(1);
                            w.pose(pose);
                        }
                        None => w.u8(0),
                    }
                }
            }
        }
    }
    w.bytes
}

/// Serialises frames in COLMAP's binary layout.
pub fn encode_frames(frames: &[Frame]) -> Vec<u8> {
    let mut w = Writer::default();
    w.u64(frames.len() as u64);
    for frame in frames {
        w.u32(frame.id);
        w.u32(frame.rig_id);
        w.pose(&frame.rig_from_world);
        w.u32(frame.data.len() as u32);
        for (sensor, data_id) in &frame.data {
            w.i32(sensor.sensor_type);
            w.u32(sensor.id);
            w.u64(*data_id);
        }
    }
    w.bytes
}

/// The files of a binary model and their encoded contents.
pub fn encode_model(model: &Reconstruction) -> Vec<(&'static str, Vec<u8>)> {
    let mut files = vec![
        ("cameras.bin", encode_cameras(model.cameras())),
        ("images.bin", encode_images(model.images())),
        ("points3D.bin", encode_points(model.points())),
    ];
    if !model.rigs().is_empty() || !model.frames().is_empty() {
        files.push(("rigs.bin", encode_rigs(model.rigs())));
        files.push(("frames.bin", encode_frames(model.frames())));
    }
    files
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("test.bin")
    }

    #[test]
    fn lying_count_is_rejected_before_allocation() {
        let mut data = Vec::new();
        data.extend_from_slice(&u64::MAX.to_le_bytes());
        let err = parse_points(&data, &path()).unwrap_err().to_string();
        assert!(err.contains("cannot fit"), "{err}");
        let err = parse_cameras(&data, &path()).unwrap_err().to_string();
        assert!(err.contains("test.bin"), "{err}");
    }

    #[test]
    fn truncated_camera_names_record_and_offset() {
        let cameras = vec![Camera::simple_pinhole(42, 10, 10, 5.0)];
        let bytes = encode_cameras(&cameras);
        for cut in 1..bytes.len() {
            let err = parse_cameras(&bytes[..cut], &path())
                .unwrap_err()
                .to_string();
            assert!(err.starts_with("test.bin: byte"), "{err}");
        }
        let err = parse_cameras(&bytes[..bytes.len() - 3], &path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("camera 42"), "{err}");
        assert_eq!(parse_cameras(&bytes, &path()).unwrap(), cameras);
    }

    #[test]
    fn unknown_model_and_trailing_bytes_are_errors() {
        let mut bytes = encode_cameras(&[Camera::simple_pinhole(1, 10, 10, 5.0)]);
        bytes[12..16].copy_from_slice(&99i32.to_le_bytes());
        let err = parse_cameras(&bytes, &path()).unwrap_err().to_string();
        assert!(err.contains("camera model id 99"), "{err}");

        let mut bytes = encode_cameras(&[Camera::simple_pinhole(1, 10, 10, 5.0)]);
        bytes.push(7);
        let err = parse_cameras(&bytes, &path()).unwrap_err().to_string();
        assert!(err.contains("trailing"), "{err}");
    }

    #[test]
    fn nan_point_is_rejected_with_its_id() {
        let points = vec![Point3D {
            id: 77,
            position_world: nalgebra::Point3::new(0.0, f64::NAN, 1.0),
            color: [0; 3],
            error: 0.0,
            track: vec![],
        }];
        let err = parse_points(&encode_points(&points), &path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("3D point 77"), "{err}");
    }

    #[test]
    fn unterminated_name_is_an_error() {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&1u64.to_le_bytes());
        bytes.extend_from_slice(&5u32.to_le_bytes());
        for v in [1.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&1u32.to_le_bytes());
        bytes.extend_from_slice(b"abcdefghijklmnop");
        let err = parse_images(&bytes, &path()).unwrap_err().to_string();
        assert!(err.contains("image 5"), "{err}");
    }
}
