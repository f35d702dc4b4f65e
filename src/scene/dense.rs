//! COLMAP's fused dense point cloud: `fused.ply` (positions, normals, colours) and its
//! visibility file `fused.ply.vis` (for each point, the images that see it, as positions in
//! the dense workspace's image list, which is the file order of its sparse model). `frond
//! densify` adds the vertex properties `thin_organ` (1: a point its thin-organ sweep found on
//! a stem's or petiole's centreline) and `gap_fill` (1: a point of its fill partners' depth
//! maps where the main partners' left a gap); COLMAP's files have neither.

use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::error::{Location, SceneError, SceneResult};
use super::model::{ImageId, Reconstruction};
use super::ply::{self, Element};

/// Dense points with optional normals and the images that see each point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensePoints {
    pub positions_world: Vec<Point3<f32>>,
    pub normals_world: Option<Vec<Vector3<f32>>>,
    pub colors: Vec<[u8; 3]>,
    /// For each point, the ids of the images that see it (empty when no `.vis` file exists).
    pub visible_in: Vec<Vec<ImageId>>,
    /// For each point, whether `frond densify`'s thin-organ sweep found it (empty when the
    /// file has no `thin_organ` property).
    pub thin_organ: Vec<bool>,
    /// For each point, whether it fills a gap of the main stereo partners' points, from
    /// `frond densify`'s fill partners (empty when the file has no `gap_fill` property).
    pub gap_fill: Vec<bool>,
}

fn column<'a>(vertex: &'a Element, name: &str, path: &Path) -> SceneResult<&'a [f64]> {
    vertex
        .column(name)
        .map(|c| c.values.as_slice())
        .ok_or_else(|| SceneError::Parse {
            path: path.to_path_buf(),
            location: Location::Byte(0),
            record: "header".to_owned(),
            message: format!("vertex element has no '{name}' property"),
        })
}

/// Reads `fused.ply` and, when present, `fused.ply.vis`, mapping visibility indices to the
/// image ids of `model` (the dense workspace's sparse model).
pub fn read_fused(ply_path: &Path, model: &Reconstruction) -> SceneResult<DensePoints> {
    let ply = ply::read_ply(ply_path)?;
    let vertex = ply.element("vertex").ok_or_else(|| SceneError::Parse {
        path: ply_path.to_path_buf(),
        location: Location::Byte(0),
        record: "header".to_owned(),
        message: "no vertex element".to_owned(),
    })?;
    let (x, y, z) = (
        column(vertex, "x", ply_path)?,
        column(vertex, "y", ply_path)?,
        column(vertex, "z", ply_path)?,
    );
    let mut positions_world = Vec::with_capacity(vertex.count);
    for i in 0..vertex.count {
        let p = Point3::new(x[i] as f32, y[i] as f32, z[i] as f32);
        if !p.iter().all(|c| c.is_finite()) {
            return Err(SceneError::Parse {
                path: ply_path.to_path_buf(),
                location: Location::Byte(0),
                record: format!("vertex {i}"),
                message: "non-finite position".to_owned(),
            });
        }
        positions_world.push(p);
    }
    let normals_world = match (
        vertex.column("nx"),
        vertex.column("ny"),
        vertex.column("nz"),
    ) {
        (Some(nx), Some(ny), Some(nz)) => Some(
            (0..vertex.count)
                .map(|i| {
                    Vector3::new(
                        nx.values[i] as f32,
                        ny.values[i] as f32,
                        nz.values[i] as f32,
                    )
                })
                .collect(),
        ),
        _ => None,
    };
    let colors = match (
        vertex.column("red"),
        vertex.column("green"),
        vertex.column("blue"),
    ) {
        (Some(r), Some(g), Some(b)) => (0..vertex.count)
            .map(|i| {
                [
                    r.values[i].clamp(0.0, 255.0) as u8,
                    g.values[i].clamp(0.0, 255.0) as u8,
                    b.values[i].clamp(0.0, 255.0) as u8,
                ]
            })
            .collect(),
        _ => vec![[200, 200, 200]; vertex.count],
    };
    let flag = |name: &str| -> Vec<bool> {
        vertex
            .column(name)
            .map(|c| c.values.iter().map(|&v| v > 0.0).collect())
            .unwrap_or_default()
    };
    let (thin_organ, gap_fill) = (flag("thin_organ"), flag("gap_fill"));
    let vis_path = ply_path.with_file_name(format!(
        "{}.vis",
        ply_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    ));
    let visible_in = if vis_path.is_file() {
        let bytes = std::fs::read(&vis_path).map_err(|e| SceneError::io(&vis_path, e))?;
        parse_visibility(&bytes, &vis_path, vertex.count, model)?
    } else {
        Vec::new()
    };
    Ok(DensePoints {
        positions_world,
        normals_world,
        colors,
        visible_in,
        thin_organ,
        gap_fill,
    })
}

/// Parses `fused.ply.vis`: u64 point count, then per point a u32 count and that many u32
/// image positions.
pub fn parse_visibility(
    bytes: &[u8],
    path: &Path,
    num_points: usize,
    model: &Reconstruction,
) -> SceneResult<Vec<Vec<ImageId>>> {
    let err = |pos: usize, record: String, message: String| SceneError::Parse {
        path: path.to_path_buf(),
        location: Location::Byte(pos as u64),
        record,
        message,
    };
    let read_u32 = |pos: usize, record: &dyn Fn() -> String| -> SceneResult<u32> {
        bytes
            .get(pos..pos + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or_else(|| err(pos, record(), "file truncated".to_owned()))
    };
    let header = bytes
        .get(0..8)
        .ok_or_else(|| err(0, "header".into(), "file truncated".into()))?;
    let count = u64::from_le_bytes(header.try_into().unwrap_or([0; 8]));
    if count != num_points as u64 {
        return Err(err(
            0,
            "header".into(),
            format!("lists {count} points but the PLY has {num_points}"),
        ));
    }
    let image_ids: Vec<ImageId> = model.images().iter().map(|i| i.id).collect();
    let mut pos = 8;
    let mut visible_in = Vec::with_capacity(num_points.min(bytes.len() / 4));
    for point in 0..num_points {
        let record = || format!("point {point}");
        let n = read_u32(pos, &record)? as usize;
        pos += 4;
        if n.saturating_mul(4) > bytes.len() - pos {
            return Err(err(
                pos,
                record(),
                format!("{n} images cannot fit in the file"),
            ));
        }
        let mut ids = Vec::with_capacity(n);
        for _ in 0..n {
            let index = read_u32(pos, &record)? as usize;
            let id = image_ids.get(index).copied().ok_or_else(|| {
                err(
                    pos,
                    record(),
                    format!(
                        "image index {index} out of range (model has {} images)",
                        image_ids.len()
                    ),
                )
            })?;
            ids.push(id);
            pos += 4;
        }
        visible_in.push(ids);
    }
    if pos != bytes.len() {
        return Err(err(pos, "end of file".into(), "trailing bytes".into()));
    }
    Ok(visible_in)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::camera::Camera;
    use crate::scene::model::Image;
    use nalgebra::Isometry3;

    fn model_with_images(ids: &[u32]) -> Reconstruction {
        let images = ids
            .iter()
            .map(|&id| Image {
                id,
                camera_id: 1,
                name: format!("{id}.png"),
                camera_from_world: Isometry3::identity(),
                keypoints: vec![],
            })
            .collect();
        Reconstruction::from_parts(vec![Camera::simple_pinhole(1, 4, 4, 2.0)], images, vec![])
            .unwrap()
    }

    fn vis_bytes(lists: &[Vec<u32>]) -> Vec<u8> {
        let mut out = (lists.len() as u64).to_le_bytes().to_vec();
        for l in lists {
            out.extend_from_slice(&(l.len() as u32).to_le_bytes());
            for i in l {
                out.extend_from_slice(&i.to_le_bytes());
            }
        }
        out
    }

    #[test]
    fn visibility_maps_positions_to_image_ids() {
        let model = model_with_images(&[10, 20, 5]);
        let bytes = vis_bytes(&[vec![0, 2], vec![1]]);
        let vis = parse_visibility(&bytes, Path::new("f.vis"), 2, &model).unwrap();
        assert_eq!(vis, vec![vec![10, 5], vec![20]]);
    }

    #[test]
    fn visibility_errors() {
        let model = model_with_images(&[10]);
        let bytes = vis_bytes(&[vec![3]]);
        let err = parse_visibility(&bytes, Path::new("f.vis"), 1, &model).unwrap_err();
        assert!(err.to_string().contains("out of range"), "{err}");
        let err = parse_visibility(&bytes, Path::new("f.vis"), 2, &model).unwrap_err();
        assert!(err.to_string().contains("lists 1 points"), "{err}");
        let mut lying = vis_bytes(&[vec![]]);
        lying[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        let err = parse_visibility(&lying, Path::new("f.vis"), 1, &model).unwrap_err();
        assert!(err.to_string().contains("cannot fit"), "{err}");
    }
}
