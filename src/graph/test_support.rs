//! Test scenes for the segmentation: points seen by a ring of cameras, with tracks.

use nalgebra::{Point2, Point3};

use crate::scene::model::{Image, Keypoint, Point3D, TrackElement};
use crate::scene::synthetic::look_at;
use crate::scene::{Camera, Reconstruction};

/// A model whose points are `positions`, each observed by every camera of a 12-view ring
/// (radius 1.2 m, 0.6 m high, looking at (0, 0, 0.2)) that projects it inside the image.
pub fn ring_model(positions: &[Point3<f64>]) -> Reconstruction {
    let camera = Camera::simple_pinhole(1, 640, 480, 500.0);
    let poses: Vec<_> = (0..12)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 12.0;
            look_at(
                Point3::new(1.2 * a.cos(), 1.2 * a.sin(), 0.6),
                Point3::new(0.0, 0.0, 0.2),
            )
        })
        .collect();
    let mut keypoints: Vec<Vec<Keypoint>> = vec![Vec::new(); poses.len()];
    let mut points = Vec::new();
    for (i, p) in positions.iter().enumerate() {
        let mut track = Vec::new();
        for (v, pose) in poses.iter().enumerate() {
            let Some(uv) = camera.project(&(pose * p).coords) else {
                continue;
            };
            if !camera.contains(&uv) {
                continue;
            }
            track.push(TrackElement {
                image_id: v as u32 + 1,
                keypoint_index: keypoints[v].len() as u32,
            });
            keypoints[v].push(Keypoint {
                uv_image: Point2::new(uv.x, uv.y),
                point3d_id: Some(i as u64 + 1),
            });
        }
        points.push(Point3D {
            id: i as u64 + 1,
            position_world: *p,
            color: [90, 140, 60],
            error: 0.0,
            track,
        });
    }
    let images = poses
        .iter()
        .zip(keypoints)
        .enumerate()
        .map(|(v, (pose, keypoints))| Image {
            id: v as u32 + 1,
            camera_id: 1,
            name: format!("view_{v:02}.png"),
            camera_from_world: *pose,
            keypoints,
        })
        .collect();
    Reconstruction::from_parts(vec![camera], images, points).expect("consistent test model")
}

/// Points on a square grid patch: `n × n` points of spacing `step`, centred at `center`,
/// spanned by `u` and `v`.
pub fn patch(
    center: Point3<f64>,
    u: nalgebra::Vector3<f64>,
    v: nalgebra::Vector3<f64>,
    n: usize,
    step: f64,
) -> Vec<Point3<f64>> {
    let half = (n as f64 - 1.0) / 2.0;
    let mut out = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            out.push(center + u * ((i as f64 - half) * step) + v * ((j as f64 - half) * step));
        }
    }
    out
}

/// Points on a vertical cylinder of `radius` from `base` up `height`.
pub fn tube(base: Point3<f64>, radius: f64, height: f64, step: f64) -> Vec<Point3<f64>> {
    let around = ((std::f64::consts::TAU * radius / step).ceil() as usize).max(6);
    let along = (height / step).ceil() as usize;
    let mut out = Vec::new();
    for k in 0..along {
        for j in 0..around {
            let a = std::f64::consts::TAU * (j as f64 + 0.5 * (k % 2) as f64) / around as f64;
            out.push(
                base + nalgebra::Vector3::new(radius * a.cos(), radius * a.sin(), k as f64 * step),
            );
        }
    }
    out
}
