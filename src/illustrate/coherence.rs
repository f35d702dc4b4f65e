//! Frame-to-frame coherence of a fly-through drawing: how much of one frame's ink is where the
//! previous frame's ink lands once the camera's motion is taken out. Every pixel of frame B on
//! the plant is lifted to 3D with B's depth (the front-most surface within two pixels, since
//! outlines lie on the edges of surfaces) and projected into frame A, whose ink is read there
//! (bilinear); the score is 1 − Σ|ink_B − ink_A| / Σ(ink_B + ink_A), the mean of both
//! directions, for the whole drawing and for each layer alone. Strokes that stick to the plant
//! score near 1 (less the resampling of anti-aliased lines); strokes placed anew every frame
//! score about the ink density.

use image::GrayImage;
use nalgebra::Point3;
use serde::Serialize;

use super::{Drawing, Layer};

/// Coherence of one set of strokes over a sequence of frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SequenceCoherence {
    /// Per consecutive pair (mean of both directions).
    pub stable_ink: Vec<f64>,
    pub mean_stable_ink: f64,
    pub min_stable_ink: f64,
    /// Mean image motion of the plant between consecutive frames (pixels), for scale.
    pub mean_motion_px: f64,
}

/// Coherence of a fly-through: the whole drawing and each layer with ink.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoherenceReport {
    pub frames: usize,
    pub all: SequenceCoherence,
    pub by_layer: std::collections::BTreeMap<String, SequenceCoherence>,
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

/// Ink (0 paper … 1 black) of a raster at a sub-pixel position (COLMAP convention), bilinear;
/// paper outside.
fn ink_at(raster: &GrayImage, u: f64, v: f64) -> f64 {
    let (x, y) = (u - 0.5, v - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let mut total = 0.0;
    for (dx, dy, weight) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (px, py) = (x0 as i64 + dx, y0 as i64 + dy);
        if px >= 0 && py >= 0 && (px as u32) < raster.width() && (py as u32) < raster.height() {
            total += weight * (1.0 - raster.get_pixel(px as u32, py as u32)[0] as f64 / 255.0);
        }
    }
    total
}

/// Frame `b`'s ink compared with frame `a`'s ink carried along the camera motion: every pixel
/// of `b` on the plant (a depth within two pixels) is lifted to 3D and looked up in `a`.
/// Returns `(1 − Σ|ink_b − ink_a| / Σ(ink_b + ink_a), mean motion in pixels)`: 1 when the ink
/// moves exactly with the plant, the ink density when it is redrawn at random; `None` without
/// ink on the plant.
fn carried(a: &Drawing, ink_a: &GrayImage, b: &Drawing, ink_b: &GrayImage) -> Option<(f64, f64)> {
    let world_from_b = b.camera.camera_from_world.inverse();
    let (mut difference, mut total, mut motion, mut pixels) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for (x, y, pixel) in ink_b.enumerate_pixels() {
        let Some(z) = nearby_depth(b, x as i64, y as i64) else {
            continue;
        };
        let (u, v) = (x as f64 + 0.5, y as f64 + 0.5);
        let p_camera = Point3::new(
            (u - b.camera.cx) / b.camera.fx * z,
            (v - b.camera.cy) / b.camera.fy * z,
            z,
        );
        let Some((q, _)) = a.camera.project(&(world_from_b * p_camera)) else {
            continue;
        };
        let ink_here = 1.0 - pixel[0] as f64 / 255.0;
        let ink_there = ink_at(ink_a, q.x, q.y);
        difference += (ink_here - ink_there).abs();
        total += ink_here + ink_there;
        motion += ((q.x - u).powi(2) + (q.y - v).powi(2)).sqrt();
        pixels += 1;
    }
    (total > 0.0).then(|| (1.0 - difference / total, motion / pixels.max(1) as f64))
}

fn sequence(frames: &[Drawing], rasters: &[GrayImage]) -> SequenceCoherence {
    let mut stable_ink = Vec::new();
    let mut motions = Vec::new();
    for k in 1..frames.len() {
        let (a, b) = (&frames[k - 1], &frames[k]);
        let forward = carried(a, &rasters[k - 1], b, &rasters[k]);
        let backward = carried(b, &rasters[k], a, &rasters[k - 1]);
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
    SequenceCoherence {
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

/// Coherence of consecutive frames, whole and per layer.
/// `rasters` are the frames' whole drawings ([`Drawing::raster`]), which the caller has already
/// made to write them; the per-layer rasters are made here.
pub fn coherence(
    frames: &[Drawing],
    rasters: &[GrayImage],
) -> Result<CoherenceReport, super::IllustrateError> {
    let all = sequence(frames, rasters);
    let mut by_layer = std::collections::BTreeMap::new();
    for layer in Layer::ALL {
        if !frames
            .iter()
            .any(|d| d.strokes.iter().any(|s| s.layer == layer))
        {
            continue;
        }
        let rasters = frames
            .iter()
            .map(|d| d.raster_layers(Some(layer)))
            .collect::<Result<Vec<_>, _>>()?;
        by_layer.insert(layer.name().to_owned(), sequence(frames, &rasters));
    }
    Ok(CoherenceReport {
        frames: frames.len(),
        all,
        by_layer,
    })
}
