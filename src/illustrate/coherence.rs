//! Frame-to-frame coherence of a fly-through drawing: how much of one frame's ink is where the
//! previous frame's ink lands once the camera's motion is taken out. Each ink pixel of frame A
//! is lifted to 3D with A's depth (the front-most surface within two pixels, since outlines lie
//! on the edges of surfaces), projected into frame B, and counted as stable when B has ink within
//! one pixel of it; the score is the mean of both directions. Strokes that stick to the plant
//! score near 1; strokes placed anew every frame (the seed's screen-space error diffusion) score
//! what chance overlap gives.

use image::GrayImage;
use nalgebra::Point3;
use serde::Serialize;

use super::Drawing;

/// Ink is darker than this.
const INK: u8 = 128;

/// Coherence of a sequence of frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoherenceReport {
    pub frames: usize,
    /// Share of ink that stays put between consecutive frames (mean of both directions), per
    /// pair.
    pub stable_ink: Vec<f64>,
    pub mean_stable_ink: f64,
    pub min_stable_ink: f64,
    /// Mean image motion of the ink between consecutive frames (pixels): how far the camera
    /// moved, for scale.
    pub mean_motion_px: f64,
}

/// Front-most depth within two pixels of `(x, y)`.
fn nearby_depth(drawing: &Drawing, x: i64, y: i64) -> Option<f64> {
    let (w, h) = (drawing.width as i64, drawing.height as i64);
    let mut best: Option<f32> = None;
    for dy in -2..=2 {
        for dx in -2..=2 {
            let (qx, qy) = (x + dx, y + dy);
            if qx < 0 || qy < 0 || qx >= w || qy >= h {
                continue;
            }
            let d = drawing.depth[(qy * w + qx) as usize];
            if d > 0.0 && best.is_none_or(|b| d < b) {
                best = Some(d);
            }
        }
    }
    best.map(|d| d as f64)
}

/// Ink of `a` carried into `b`'s image: `(stable share, mean motion in pixels)`; `None`
/// without ink on a surface.
fn carried(a: &Drawing, ink_a: &GrayImage, b: &Drawing, ink_b: &GrayImage) -> Option<(f64, f64)> {
    let world_from_a = a.camera.camera_from_world.inverse();
    let (bw, bh) = (b.width as i64, b.height as i64);
    let (mut considered, mut stable, mut motion) = (0usize, 0usize, 0.0f64);
    for (x, y, pixel) in ink_a.enumerate_pixels() {
        if pixel[0] >= INK {
            continue;
        }
        let Some(z) = nearby_depth(a, x as i64, y as i64) else {
            continue;
        };
        let (u, v) = (x as f64 + 0.5, y as f64 + 0.5);
        let p_camera = Point3::new(
            (u - a.camera.cx) / a.camera.fx * z,
            (v - a.camera.cy) / a.camera.fy * z,
            z,
        );
        let Some((q, _)) = b.camera.project(&(world_from_a * p_camera)) else {
            continue;
        };
        let (qx, qy) = (q.x.floor() as i64, q.y.floor() as i64);
        if qx < 0 || qy < 0 || qx >= bw || qy >= bh {
            continue;
        }
        considered += 1;
        motion += ((q.x - u).powi(2) + (q.y - v).powi(2)).sqrt();
        let hit = (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (sx, sy) = (qx + dx, qy + dy);
                sx >= 0
                    && sy >= 0
                    && sx < bw
                    && sy < bh
                    && ink_b.get_pixel(sx as u32, sy as u32)[0] < INK
            })
        });
        stable += hit as usize;
    }
    (considered > 0).then(|| {
        (
            stable as f64 / considered as f64,
            motion / considered as f64,
        )
    })
}

/// Coherence of consecutive frames (each with its raster).
pub fn coherence(frames: &[(Drawing, GrayImage)]) -> CoherenceReport {
    let mut stable_ink = Vec::new();
    let mut motions = Vec::new();
    for pair in frames.windows(2) {
        let ((a, ink_a), (b, ink_b)) = (&pair[0], &pair[1]);
        let forward = carried(a, ink_a, b, ink_b);
        let backward = carried(b, ink_b, a, ink_a);
        if let (Some(f), Some(r)) = (forward, backward) {
            stable_ink.push(0.5 * (f.0 + r.0));
            motions.push(0.5 * (f.1 + r.1));
        }
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    CoherenceReport {
        frames: frames.len(),
        mean_stable_ink: mean(&stable_ink),
        min_stable_ink: if stable_ink.is_empty() {
            0.0
        } else {
            stable_ink.iter().copied().fold(f64::INFINITY, f64::min)
        },
        mean_motion_px: mean(&motions),
        stable_ink,
    }
}
