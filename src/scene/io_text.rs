//! COLMAP's text sparse-model format (`cameras.txt`, `images.txt`, `points3D.txt`, and the
//! optional `rigs.txt`, `frames.txt` of COLMAP ≥ 3.12). Lines starting with `#` are comments.
//!
//! Numbers are written in Rust's shortest round-trip form, so text output loses nothing.

use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use nalgebra::Point2;

use super::camera::{Camera, CameraModelKind};
use super::error::{Location, SceneError, SceneResult};
use super::model::{
    Frame, Image, Keypoint, Point3D, Reconstruction, Rig, SensorId, TrackElement, isometry_from_qt,
    qt_from_isometry,
};

/// Tokens of one line, with enough context to report errors.
struct Line<'a> {
    path: &'a Path,
    number: usize,
    record: String,
    tokens: std::str::SplitAsciiWhitespace<'a>,
}

impl<'a> Line<'a> {
    fn new(path: &'a Path, number: usize, text: &'a str, record: String) -> Self {
        Self {
            path,
            number,
            record,
            tokens: text.split_ascii_whitespace(),
        }
    }

    fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Parse {
            path: self.path.to_path_buf(),
            location: Location::Line(self.number),
            record: self.record.clone(),
            message: message.into(),
        }
    }

    fn token(&mut self, what: &str) -> SceneResult<&'a str> {
        self.tokens
            .next()
            .ok_or_else(|| self.error(format!("missing {what}")))
    }

    fn parse<T: FromStr>(&mut self, what: &str) -> SceneResult<T> {
        let token = self.token(what)?;
        token
            .parse()
            .map_err(|_| self.error(format!("{what} '{token}' is not a valid number")))
    }

    fn finite(&mut self, what: &str) -> SceneResult<f64> {
        let value: f64 = self.parse(what)?;
        if value.is_finite() {
            Ok(value)
        } else {
            Err(self.error(format!("{what} is not finite ({value})")))
        }
    }

    fn pose(&mut self, what: &str) -> SceneResult<nalgebra::Isometry3<f64>> {
        let mut values = [0.0; 7];
        for (v, name) in values
            .iter_mut()
            .zip(["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"])
        {
            *v = self.parse(name)?;
        }
        isometry_from_qt(&values)
            .ok_or_else(|| self.error(format!("{what} is degenerate or not finite: {values:?}")))
    }

    fn sensor_type(&mut self) -> SceneResult<i32> {
        let token = self.token("sensor type")?;
        SensorId::type_from_name(token)
            .or_else(|| token.parse().ok())
            .ok_or_else(|| self.error(format!("unknown sensor type '{token}'")))
    }

    fn rest(&mut self) -> Vec<&'a str> {
        self.tokens.by_ref().collect()
    }

    fn finish(&mut self) -> SceneResult<()> {
        match self.tokens.next() {
            None => Ok(()),
            Some(extra) => Err(self.error(format!("unexpected extra value '{extra}'"))),
        }
    }
}

/// Non-comment, non-empty lines with their 1-based line numbers.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Parses `cameras.txt`.
pub fn parse_cameras(text: &str, path: &Path) -> SceneResult<Vec<Camera>> {
    let mut cameras = Vec::new();
    for (number, text) in data_lines(text) {
        let mut line = Line::new(path, number, text, "camera".to_owned());
        let id: u32 = line.parse("CAMERA_ID")?;
        line.record = format!("camera {id}");
        let model_name = line.token("MODEL")?;
        let model = CameraModelKind::from_name(model_name)
            .or_else(|| model_name.parse().ok().and_then(CameraModelKind::from_id))
            .ok_or_else(|| {
                line.error(format!(
                    "unknown or unsupported camera model '{model_name}'"
                ))
            })?;
        let width: u64 = line.parse("WIDTH")?;
        let height: u64 = line.parse("HEIGHT")?;
        let params = line
            .rest()
            .iter()
            .map(|t| {
                t.parse::<f64>()
                    .map_err(|_| line.error(format!("parameter '{t}' is not a valid number")))
            })
            .collect::<SceneResult<Vec<f64>>>()?;
        let camera =
            Camera::new(id, model, width, height, params).map_err(|source| SceneError::Camera {
                path: path.to_path_buf(),
                location: Location::Line(number),
                camera_id: id,
                source,
            })?;
        cameras.push(camera);
    }
    Ok(cameras)
}

/// Parses `images.txt`: an image line followed by its (possibly empty) keypoint line.
pub fn parse_images(text: &str, path: &Path) -> SceneResult<Vec<Image>> {
    let mut images = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((number, text)) = lines.next() {
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut line = Line::new(path, number, text, "image".to_owned());
        let id: u32 = line.parse("IMAGE_ID")?;
        line.record = format!("image {id}");
        let camera_from_world = line.pose("camera_from_world pose")?;
        let camera_id: u32 = line.parse("CAMERA_ID")?;
        let name = line.rest().join(" ");
        if name.is_empty() {
            return Err(line.error("missing NAME"));
        }
        let record = format!("image {id} '{name}'");
        let (points_number, points_text) = lines.next().unwrap_or((number + 1, ""));
        let mut points_line = Line::new(path, points_number, points_text, record);
        let values = points_line.rest();
        if !values.len().is_multiple_of(3) {
            return Err(points_line.error(format!(
                "keypoint line has {} values, not a multiple of 3 (X Y POINT3D_ID)",
                values.len()
            )));
        }
        let mut keypoints = Vec::with_capacity(values.len() / 3);
        for (k, triple) in values.chunks_exact(3).enumerate() {
            let coordinate = |s: &str| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| points_line.error(format!("keypoint {k}: bad coordinate '{s}'")))
            };
            let x = coordinate(triple[0])?;
            let y = coordinate(triple[1])?;
            let point3d_id = match triple[2] {
                "-1" => None,
                s => Some(s.parse::<u64>().map_err(|_| {
                    points_line.error(format!("keypoint {k}: bad POINT3D_ID '{s}'"))
                })?),
            };
            keypoints.push(Keypoint {
                uv_image: Point2::new(x, y),
                point3d_id,
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
    Ok(images)
}

/// Parses `points3D.txt`.
pub fn parse_points(text: &str, path: &Path) -> SceneResult<Vec<Point3D>> {
    let mut points = Vec::new();
    for (number, text) in data_lines(text) {
        let mut line = Line::new(path, number, text, "3D point".to_owned());
        let id: u64 = line.parse("POINT3D_ID")?;
        line.record = format!("3D point {id}");
        let x = line.finite("X")?;
        let y = line.finite("Y")?;
        let z = line.finite("Z")?;
        let r: u8 = line.parse("R")?;
        let g: u8 = line.parse("G")?;
        let b: u8 = line.parse("B")?;
        let error = line.finite("ERROR")?;
        let rest = line.rest();
        if !rest.len().is_multiple_of(2) {
            return Err(line.error(format!(
                "track has {} values, not pairs of IMAGE_ID POINT2D_IDX",
                rest.len()
            )));
        }
        let track = rest
            .chunks_exact(2)
            .enumerate()
            .map(
                |(e, pair)| match (pair[0].parse::<u32>(), pair[1].parse::<u32>()) {
                    (Ok(image_id), Ok(keypoint_index)) => Ok(TrackElement {
                        image_id,
                        keypoint_index,
                    }),
                    _ => Err(line.error(format!(
                        "track element {e} '{} {}' is not two ids",
                        pair[0], pair[1]
                    ))),
                },
            )
            .collect::<SceneResult<Vec<_>>>()?;
        points.push(Point3D {
            id,
            position_world: nalgebra::Point3::new(x, y, z),
            color: [r, g, b],
            error,
            track,
        });
    }
    Ok(points)
}

/// Parses `rigs.txt` (COLMAP ≥ 3.12).
pub fn parse_rigs(text: &str, path: &Path) -> SceneResult<Vec<Rig>> {
    let mut rigs = Vec::new();
    for (number, text) in data_lines(text) {
        let mut line = Line::new(path, number, text, "rig".to_owned());
        let id: u32 = line.parse("RIG_ID")?;
        line.record = format!("rig {id}");
        let num_sensors: usize = line.parse("NUM_SENSORS")?;
        let mut reference_sensor = None;
        let mut sensors = Vec::new();
        if num_sensors > 0 {
            reference_sensor = Some(SensorId {
                sensor_type: line.sensor_type()?,
                id: line.parse("REF_SENSOR_ID")?,
            });
            for _ in 1..num_sensors {
                let sensor = SensorId {
                    sensor_type: line.sensor_type()?,
                    id: line.parse("SENSOR_ID")?,
                };
                let pose = match line.token("HAS_POSE")? {
                    "0" | "false" => None,
                    "1" | "true" => Some(line.pose("sensor_from_rig pose")?),
                    other => return Err(line.error(format!("HAS_POSE '{other}' is not 0 or 1"))),
                };
                sensors.push((sensor, pose));
            }
        }
        line.finish()?;
        rigs.push(Rig {
            id,
            reference_sensor,
            sensors,
        });
    }
    Ok(rigs)
}

/// Parses `frames.txt` (COLMAP ≥ 3.12).
pub fn parse_frames(text: &str, path: &Path) -> SceneResult<Vec<Frame>> {
    let mut frames = Vec::new();
    for (number, text) in data_lines(text) {
        let mut line = Line::new(path, number, text, "frame".to_owned());
        let id: u32 = line.parse("FRAME_ID")?;
        line.record = format!("frame {id}");
        let rig_id: u32 = line.parse("RIG_ID")?;
        let rig_from_world = line.pose("rig_from_world pose")?;
        let num_data: usize = line.parse("NUM_DATA_IDS")?;
        let mut data = Vec::new();
        for _ in 0..num_data {
            let sensor = SensorId {
                sensor_type: line.sensor_type()?,
                id: line.parse("SENSOR_ID")?,
            };
            data.push((sensor, line.parse("DATA_ID")?));
        }
        line.finish()?;
        frames.push(Frame {
            id,
            rig_id,
            rig_from_world,
            data,
        });
    }
    Ok(frames)
}

fn push_pose(out: &mut String, pose: &nalgebra::Isometry3<f64>) {
    for v in qt_from_isometry(pose) {
        let _ = write!(out, " {v}");
    }
}

/// Serialises cameras as `cameras.txt`.
pub fn encode_cameras(cameras: &[Camera]) -> String {
    let mut out = String::from(
        "# Camera list with one line of data per camera:\n\
         #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(out, "# Number of cameras: {}", cameras.len());
    for c in cameras {
        let _ = write!(out, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for p in c.params() {
            let _ = write!(out, " {p}");
        }
        out.push('\n');
    }
    out
}

/// Serialises images as `images.txt`.
pub fn encode_images(images: &[Image]) -> String {
    let observations: usize = images.iter().map(Image::num_observations).sum();
    let mean = if images.is_empty() {
        0.0
    } else {
        observations as f64 / images.len() as f64
    };
    let mut out = String::from(
        "# Image list with two lines of data per image:\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(
        out,
        "# Number of images: {}, mean observations per image: {mean}",
        images.len()
    );
    for image in images {
        let _ = write!(out, "{}", image.id);
        push_pose(&mut out, &image.camera_from_world);
        let _ = writeln!(out, " {} {}", image.camera_id, image.name);
        let mut first = true;
        for k in &image.keypoints {
            if !first {
                out.push(' ');
            }
            first = false;
            match k.point3d_id {
                Some(id) => {
                    let _ = write!(out, "{} {} {id}", k.uv_image.x, k.uv_image.y);
                }
                None => {
                    let _ = write!(out, "{} {} -1", k.uv_image.x, k.uv_image.y);
                }
            }
        }
        out.push('\n');
    }
    out
}

/// Serialises 3D points as `points3D.txt`.
pub fn encode_points(points: &[Point3D]) -> String {
    let observations: usize = points.iter().map(|p| p.track.len()).sum();
    let mean = if points.is_empty() {
        0.0
    } else {
        observations as f64 / points.len() as f64
    };
    let mut out = String::with_capacity(64 + points.len() * 96 + observations * 12);
    out.push_str(
        "# 3D point list with one line of data per point:\n\
         #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    let _ = writeln!(
        out,
        "# Number of points: {}, mean track length: {mean}",
        points.len()
    );
    for p in points {
        let [x, y, z] = [p.position_world.x, p.position_world.y, p.position_world.z];
        let [r, g, b] = p.color;
        let _ = write!(out, "{} {x} {y} {z} {r} {g} {b} {}", p.id, p.error);
        for t in &p.track {
            let _ = write!(out, " {} {}", t.image_id, t.keypoint_index);
        }
        out.push('\n');
    }
    out
}

/// Serialises rigs as `rigs.txt`.
pub fn encode_rigs(rigs: &[Rig]) -> String {
    let mut out = String::from(
        "# Rig calib list with one line of data per calib:\n\
         #   RIG_ID, NUM_SENSORS, REF_SENSOR_TYPE, REF_SENSOR_ID, SENSORS[] as (SENSOR_TYPE, SENSOR_ID, HAS_POSE, [QW, QX, QY, QZ, TX, TY, TZ])\n",
    );
    let _ = writeln!(out, "# Number of rigs: {}", rigs.len());
    for rig in rigs {
        match rig.reference_sensor {
            None => {
                let _ = writeln!(out, "{} 0", rig.id);
            }
            Some(reference) => {
                let _ = write!(
                    out,
                    "{} {} {} {}",
                    rig.id,
                    rig.sensors.len() + 1,
                    reference.type_name(),
                    reference.id
                );
                for (sensor, pose) in &rig.sensors {
                    let _ = write!(out, " {} {}", sensor.type_name(), sensor.id);
                    match pose {
                        Some(pose) => {
                            out.push_str(" 1");
                            push_pose(&mut out, pose);
                        }
                        None => out.push_str(" 0"),
                    }
                }
                out.push('\n');
            }
        }
    }
    out
}

/// Serialises frames as `frames.txt`.
pub fn encode_frames(frames: &[Frame]) -> String {
    let mut out = String::from(
        "# Frame list with one line of data per frame:\n\
         #   FRAME_ID, RIG_ID, RIG_FROM_WORLD[QW, QX, QY, QZ, TX, TY, TZ], NUM_DATA_IDS, DATA_IDS[] as (SENSOR_TYPE, SENSOR_ID, DATA_ID)\n",
    );
    let _ = writeln!(out, "# Number of frames: {}", frames.len());
    for frame in frames {
        let _ = write!(out, "{} {}", frame.id, frame.rig_id);
        push_pose(&mut out, &frame.rig_from_world);
        let _ = write!(out, " {}", frame.data.len());
        for (sensor, data_id) in &frame.data {
            let _ = write!(out, " {} {} {data_id}", sensor.type_name(), sensor.id);
        }
        out.push('\n');
    }
    out
}

/// The files of a text model and their contents.
pub fn encode_model(model: &Reconstruction) -> Vec<(&'static str, Vec<u8>)> {
    let mut files = vec![
        ("cameras.txt", encode_cameras(model.cameras()).into_bytes()),
        ("images.txt", encode_images(model.images()).into_bytes()),
        ("points3D.txt", encode_points(model.points()).into_bytes()),
    ];
    if !model.rigs().is_empty() || !model.frames().is_empty() {
        files.push(("rigs.txt", encode_rigs(model.rigs()).into_bytes()));
        files.push(("frames.txt", encode_frames(model.frames()).into_bytes()));
    }
    files
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("model/points3D.txt")
    }

    #[test]
    fn parses_colmap_documentation_example() {
        let text = "# 3D point list with one line of data per point:\n\
            #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
            # Number of points: 3, mean track length: 3.3334\n\
            63390 1.67241 0.292931 0.609726 115 121 122 1.33927 16 6542 15 7345 6 6714 14 7227\n\
            63376 2.01848 0.108877 -0.0260841 102 209 250 1.73449 16 6519 15 7322 14 7212 8 3991\n";
        let points = parse_points(text, &path()).unwrap();
        assert_eq!(points.len(), 2);
        assert_eq!(points[0].id, 63390);
        assert_eq!(points[1].color, [102, 209, 250]);
        assert_eq!(points[1].track[3].image_id, 8);
        assert_eq!(points[1].track[3].keypoint_index, 3991);
    }

    #[test]
    fn errors_name_line_and_record() {
        let text = "# header\n5 1 2 3 255 0 0 0.5 1 2\n6 1 2 x 0 0 0 0.5\n";
        let err = parse_points(text, &path()).unwrap_err().to_string();
        assert_eq!(
            err,
            "model/points3D.txt: line 3: 3D point 6: Z 'x' is not a valid number"
        );
        let err = parse_points("7 1 2 3 256 0 0 0.5\n", &path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("R '256'"), "{err}");
        let err = parse_points("7 1 2 3 1 0 0 0.5 4\n", &path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("pairs"), "{err}");
        let err = parse_points("7 1 nan 3 1 0 0 0.5\n", &path())
            .unwrap_err()
            .to_string();
        assert!(err.contains("not finite"), "{err}");
    }

    #[test]
    fn image_with_empty_keypoint_line_and_spaces_in_name() {
        let text = "# c\n1 1 0 0 0 0 0 0 3 dir/my photo.jpg\n\n2 1 0 0 0 1 2 3 3 b.jpg\n1.5 2.5 -1 3 4 9\n";
        let images = parse_images(text, Path::new("images.txt")).unwrap();
        assert_eq!(images.len(), 2);
        assert_eq!(images[0].name, "dir/my photo.jpg");
        assert!(images[0].keypoints.is_empty());
        assert_eq!(images[1].keypoints.len(), 2);
        assert_eq!(images[1].keypoints[0].point3d_id, None);
        assert_eq!(images[1].keypoints[1].point3d_id, Some(9));
    }

    #[test]
    fn camera_with_wrong_parameter_count_names_the_camera() {
        let err = parse_cameras("3 PINHOLE 640 480 500 500 320\n", Path::new("cameras.txt"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("cameras.txt: line 1: camera 3:"), "{err}");
        assert!(err.contains("takes 4 parameters"), "{err}");
        let err = parse_cameras("3 PANORAMA 640 480 500\n", Path::new("cameras.txt"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("unknown or unsupported camera model 'PANORAMA'"),
            "{err}"
        );
    }
}
