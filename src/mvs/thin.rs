//! Thin organs (stems, petioles, twigs) by a multi-view sweep of their image centrelines.
//!
//! Window-based stereo loses organs a few pixels wide: the matching window is mostly the
//! background behind them, so their disparity is smoothed away or smeared into a halo, and
//! the few depths that survive rarely agree across enough maps to pass fusion. Curvilinear
//! structures are found directly instead:
//!
//! 1. **Bars in each view.** At every pixel the Hessian of the smoothed grey image gives the
//!    direction across a line. A *bar* is a pixel whose colour differs from the colours on
//!    both sides across that direction, while the two sides agree with each other (a step edge
//!    differs on one side only, a blob has no across-direction). The response is
//!    `min(|c − l|, |c − r|) − |l − r|` in RGB over a few side distances (two Hessian scales),
//!    its best side distance gives the organ's half-width. Centreline pixels are the response's
//!    maxima across the bar.
//! 2. **A sweep along each centreline pixel's ray.** Depths are sampled evenly in inverse
//!    depth over the part of the view's depth range inside the region of interest, finely
//!    enough that the projection moves at most half a pixel in every neighbour view. A depth
//!    is supported by a neighbour view where its projection falls on a bar of that view with
//!    the same colour. The best-supported depth is kept when enough views support it and no
//!    other depth does as well (an ambiguous match along a row of parallel stems is dropped).
//!    This is most of densify's time, so each seed's ray is turned into every neighbour's
//!    frame once, and a sample stops counting views once it can no longer reach the required
//!    support (such samples never decide a seed): from photos of broadleaf seed 2 the sweep
//!    took 15.2 s instead of 24.5 s with the same points (the region clip alone: 0.5 %
//!    more points, 1.3 % fewer ambiguous seeds).
//! 3. **Points on the visible surface.** The sweep finds the axis (a bar's centre is the
//!    projection of the organ's axis); the point is moved towards the camera by the organ's
//!    radius (half-width × depth / focal), so it lies on the surface the photos show, like the
//!    window-stereo points. Points are merged on the fusion's voxel grid.
//!
//! Centreline curves shorter than an organ's ([`ThinOptions::min_curve_pixels`]) are texture
//! as often as organs: a stem seen between leaves, a small leaf or leaflet, a blotch of the
//! floor. On request ([`ThinOptions::min_short_curve_pixels`], `frond densify
//! --thin-short-bars N`) they are swept too, and their points are kept without the thin-organ
//! mark. Off by default: it doubles the sweep's seeds and time for small gains on broadleaf
//! plants (see the README's *Short bars*).
//!
//! Deterministic; every view in parallel.

use std::collections::BTreeMap;

use nalgebra::{Point2, Point3, Vector3};
use opencv::prelude::*;
use rayon::prelude::*;
use serde::Serialize;

use super::fusion::{FusedPoints, RegionOfInterest};
use super::stereo::LoadedView;
use crate::scene::Reconstruction;

/// Settings of the thin-organ sweep.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ThinOptions {
    pub enabled: bool,
    /// Least bar response (RGB distance, 0–441) of a centreline pixel and of the bar a
    /// neighbour view's projection must fall on.
    pub min_contrast: f64,
    /// Neighbour views checked per view (at most 64): the closest in viewing direction within
    /// the angle range.
    pub neighbour_views: usize,
    pub min_angle_deg: f64,
    pub max_angle_deg: f64,
    /// Neighbour views that must support a depth (besides the view itself).
    pub min_supporting: usize,
    /// A supporting view's bar colour may differ by at most this (RGB distance) from the
    /// centreline pixel's.
    pub max_color_difference: f64,
    /// Centreline curves shorter than this (pixels) are texture, not organs.
    pub min_curve_pixels: usize,
    /// Shorter curves of at least this many pixels are swept too, as *short bars*: a small
    /// leaf or leaflet seen edge-on or narrow is a bar a few pixels long. Their points are
    /// not marked as thin organs (0: short bars are not swept).
    pub min_short_curve_pixels: usize,
}

impl Default for ThinOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            min_contrast: 14.0,
            neighbour_views: 6,
            min_angle_deg: 15.0,
            max_angle_deg: 50.0,
            min_supporting: 3,
            max_color_difference: 40.0,
            min_curve_pixels: 15,
            min_short_curve_pixels: 0,
        }
    }
}

/// What the sweep did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ThinStats {
    /// Centreline pixels swept.
    pub seeds: usize,
    /// Seeds whose best depth enough views supported, uniquely.
    pub triangulated: usize,
    /// Seeds with two equally supported depths.
    pub ambiguous: usize,
    /// Points after merging on the voxel grid.
    pub points: usize,
    /// Of those, points of short bars (not marked as thin organs).
    pub short_bar_points: usize,
}

/// One view's bars, on its loaded (possibly downsized) pixel grid.
struct BarMap {
    width: usize,
    height: usize,
    /// Smoothed colour, RGB.
    color: Vec<[f32; 3]>,
    /// Best bar response per pixel (0 where none).
    response: Vec<f32>,
    /// Half-width (pixels) of the best response.
    half_width: Vec<f32>,
    /// Unit direction across the bar.
    across: Vec<[f32; 2]>,
    /// Response ≥ the minimum contrast, dilated by one pixel.
    mask: Vec<bool>,
    /// Direction across the strongest bar pixel next to each mask pixel.
    mask_across: Vec<[f32; 2]>,
}

/// Separable Gaussian blur of a plane (clamped borders).
fn blur(plane: &[f32], width: usize, height: usize, sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil().max(1.0) as isize;
    let kernel: Vec<f32> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let total: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
    let clamp = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let mut rows = vec![0.0f32; plane.len()];
    for j in 0..height {
        for i in 0..width {
            let mut sum = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                sum += w * plane[j * width + clamp(i as isize + k as isize - radius, width)];
            }
            rows[j * width + i] = sum;
        }
    }
    let mut out = vec![0.0f32; plane.len()];
    for j in 0..height {
        for i in 0..width {
            let mut sum = 0.0;
            for (k, w) in kernel.iter().enumerate() {
                sum += w * rows[clamp(j as isize + k as isize - radius, height) * width + i];
            }
            out[j * width + i] = sum;
        }
    }
    out
}

impl BarMap {
    /// Side distances (pixels) tried at each Hessian scale.
    const SCALES: [(f64, [f32; 2]); 2] = [(1.2, [2.0, 3.0]), (2.5, [4.5, 6.5])];

    fn from_rgb(rgb: &[[u8; 3]], width: usize, height: usize, min_contrast: f64) -> Self {
        let n = width * height;
        let planes: Vec<Vec<f32>> = (0..3)
            .map(|c| {
                let plane: Vec<f32> = rgb.iter().map(|p| f32::from(p[c])).collect();
                blur(&plane, width, height, 0.7)
            })
            .collect();
        let color: Vec<[f32; 3]> = (0..n)
            .map(|k| [planes[0][k], planes[1][k], planes[2][k]])
            .collect();
        let grey: Vec<f32> = color.iter().map(|c| (c[0] + c[1] + c[2]) / 3.0).collect();
        let mut response = vec![0.0f32; n];
        let mut half_width = vec![0.0f32; n];
        let mut across = vec![[0.0f32; 2]; n];
        let sample = |x: f32, y: f32| -> Option<[f32; 3]> {
            if x < 0.0 || y < 0.0 || x > (width - 1) as f32 || y > (height - 1) as f32 {
                return None;
            }
            let (i, j) = (x.floor() as usize, y.floor() as usize);
            let (i1, j1) = ((i + 1).min(width - 1), (j + 1).min(height - 1));
            let (fx, fy) = (x - i as f32, y - j as f32);
            let mut out = [0.0; 3];
            for (c, o) in out.iter_mut().enumerate() {
                let top = color[j * width + i][c] * (1.0 - fx) + color[j * width + i1][c] * fx;
                let bottom = color[j1 * width + i][c] * (1.0 - fx) + color[j1 * width + i1][c] * fx;
                *o = top * (1.0 - fy) + bottom * fy;
            }
            Some(out)
        };
        let distance = |a: &[f32; 3], b: &[f32; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        // Per pixel, the response at each side distance (two per scale) and each scale's
        // direction across.
        let mut per_side = vec![[f32::NEG_INFINITY; 4]; n];
        let mut per_scale_across = vec![[[0.0f32; 2]; 2]; n];
        for (scale, (sigma, sides)) in Self::SCALES.into_iter().enumerate() {
            let smooth = blur(&grey, width, height, sigma);
            for j in 1..height.saturating_sub(1) {
                for i in 1..width.saturating_sub(1) {
                    let k = j * width + i;
                    let at = |di: isize, dj: isize| {
                        smooth[(j as isize + dj) as usize * width + (i as isize + di) as usize]
                    };
                    let dxx = at(1, 0) - 2.0 * at(0, 0) + at(-1, 0);
                    let dyy = at(0, 1) - 2.0 * at(0, 0) + at(0, -1);
                    let dxy = 0.25 * (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1));
                    // Eigenvalues of [[dxx, dxy], [dxy, dyy]]; the larger in magnitude is
                    // across the bar.
                    let mean = 0.5 * (dxx + dyy);
                    let root = (0.25 * (dxx - dyy).powi(2) + dxy * dxy).sqrt();
                    let (l1, l2) = (mean + root, mean - root);
                    let (strong, weak) = if l1.abs() >= l2.abs() {
                        (l1, l2)
                    } else {
                        (l2, l1)
                    };
                    if strong.abs() < 1e-3 || strong.abs() < 2.0 * weak.abs() {
                        continue;
                    }
                    // Eigenvector of `strong`.
                    let (vx, vy) = if dxy.abs() > 1e-6 {
                        (strong - dyy, dxy)
                    } else if dxx.abs() >= dyy.abs() {
                        (1.0, 0.0)
                    } else {
                        (0.0, 1.0)
                    };
                    let norm = (vx * vx + vy * vy).sqrt();
                    if norm <= 0.0 {
                        continue;
                    }
                    let (nx, ny) = (vx / norm, vy / norm);
                    let c = color[k];
                    per_scale_across[k][scale] = [nx, ny];
                    for (side, w) in sides.into_iter().enumerate() {
                        let (Some(l), Some(r)) = (
                            sample(i as f32 - w * nx, j as f32 - w * ny),
                            sample(i as f32 + w * nx, j as f32 + w * ny),
                        ) else {
                            continue;
                        };
                        per_side[k][2 * scale + side] =
                            distance(&c, &l).min(distance(&c, &r)) - distance(&l, &r);
                    }
                }
            }
        }
        // The best response; the half-width from the nearest sides that give most of it (the
        // sides of a thin bar are as different from it a little farther out, not less).
        let widths: Vec<f32> = Self::SCALES.iter().flat_map(|(_, sides)| *sides).collect();
        for k in 0..n {
            let values = per_side[k];
            let (best, at) = values
                .iter()
                .enumerate()
                .fold(
                    (0.0f32, None),
                    |(b, a), (s, &v)| if v > b { (v, Some(s)) } else { (b, a) },
                );
            let Some(at) = at else {
                continue;
            };
            response[k] = best;
            across[k] = per_scale_across[k][at / 2];
            let nearest = values.iter().position(|&v| v >= 0.8 * best).unwrap_or(at);
            half_width[k] = (widths[nearest] - 1.0).max(0.5);
        }
        // The mask, one pixel wider than the bars, takes the direction of the strongest bar
        // pixel next to it.
        let low = min_contrast as f32;
        let mut mask = vec![false; n];
        let mut mask_across = vec![[0.0f32; 2]; n];
        for j in 0..height {
            for i in 0..width {
                let mut best = (low, None);
                for dj in j.saturating_sub(1)..=(j + 1).min(height - 1) {
                    for di in i.saturating_sub(1)..=(i + 1).min(width - 1) {
                        let value = response[dj * width + di];
                        if value >= best.0 {
                            best = (value, Some(dj * width + di));
                        }
                    }
                }
                if let Some(source) = best.1 {
                    mask[j * width + i] = true;
                    mask_across[j * width + i] = across[source];
                }
            }
        }
        Self {
            width,
            height,
            color,
            response,
            half_width,
            across,
            mask,
            mask_across,
        }
    }

    /// Centreline pixels: responses of at least `min_contrast` that are maxima across the bar,
    /// on connected curves of at least `min_length` pixels (texture gives short pieces).
    fn centreline(&self, min_contrast: f64, min_length: usize) -> Vec<usize> {
        self.centreline_curves(min_contrast, min_length)
            .into_iter()
            .map(|(k, _)| k)
            .collect()
    }

    /// Centreline pixels with the size (pixels) of the curve each lies on, for curves of at
    /// least `min_length` pixels.
    fn centreline_curves(&self, min_contrast: f64, min_length: usize) -> Vec<(usize, usize)> {
        let maxima = self.maxima(min_contrast);
        let mut on = vec![false; self.response.len()];
        for &k in &maxima {
            on[k] = true;
        }
        let mut sets = crate::util::union_find::UnionFind::new(self.response.len());
        for &k in &maxima {
            let (i, j) = (k % self.width, k / self.width);
            // Forward neighbours only (each pair once): right, and the three below.
            let mut link = |a: usize, b: usize| {
                if on[b] {
                    sets.union(a, b);
                }
            };
            if i + 1 < self.width {
                link(k, k + 1);
            }
            if j + 1 < self.height {
                let below = k + self.width;
                link(k, below);
                if i > 0 {
                    link(k, below - 1);
                }
                if i + 1 < self.width {
                    link(k, below + 1);
                }
            }
        }
        let mut sizes = std::collections::HashMap::<usize, usize>::new();
        for &k in &maxima {
            *sizes.entry(sets.find(k)).or_default() += 1;
        }
        maxima
            .into_iter()
            .map(|k| (k, sizes[&sets.find(k)]))
            .filter(|&(_, size)| size >= min_length)
            .collect()
    }

    /// Responses of at least `min_contrast` that are maxima across the bar.
    fn maxima(&self, min_contrast: f64) -> Vec<usize> {
        let (w, h) = (self.width as isize, self.height as isize);
        (0..self.response.len())
            .filter(|&k| {
                let value = self.response[k];
                if f64::from(value) < min_contrast {
                    return false;
                }
                let (i, j) = ((k % self.width) as isize, (k / self.width) as isize);
                let [nx, ny] = self.across[k];
                [-1.0f32, 1.0].iter().all(|s| {
                    let (a, b) = (i + (s * nx).round() as isize, j + (s * ny).round() as isize);
                    a < 0
                        || b < 0
                        || a >= w
                        || b >= h
                        || self.response[(b * w + a) as usize] <= value
                })
            })
            .collect()
    }

    /// Bilinear bar response at a pixel position (0 outside).
    fn response_at(&self, pixel: &Point2<f64>) -> f32 {
        let (x, y) = (pixel.x, pixel.y);
        if x < 0.0 || y < 0.0 || x > (self.width - 1) as f64 || y > (self.height - 1) as f64 {
            return 0.0;
        }
        let (i, j) = (x.floor() as usize, y.floor() as usize);
        let (i1, j1) = ((i + 1).min(self.width - 1), (j + 1).min(self.height - 1));
        let (fx, fy) = ((x - i as f64) as f32, (y - j as f64) as f32);
        let r = |a: usize, b: usize| self.response[b * self.width + a].max(0.0);
        (r(i, j) * (1.0 - fx) + r(i1, j) * fx) * (1.0 - fy)
            + (r(i, j1) * (1.0 - fx) + r(i1, j1) * fx) * fy
    }

    /// The pixel nearest a position (rounded by a cast: `f64::round` is a library call, and
    /// this runs for every sample of the sweep).
    fn index_of(&self, pixel: &Point2<f64>) -> Option<usize> {
        let (x, y) = (pixel.x + 0.5, pixel.y + 0.5);
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (i, j) = (x as usize, y as usize);
        (i < self.width && j < self.height).then(|| j * self.width + i)
    }
}

/// The centreline pixels of an RGB image's bars, row-major (a tuning aid: what the sweep
/// starts from in one photo).
pub fn centreline_pixels(
    rgb: &[[u8; 3]],
    width: usize,
    height: usize,
    options: &ThinOptions,
) -> Vec<usize> {
    BarMap::from_rgb(rgb, width, height, options.min_contrast)
        .centreline(options.min_contrast, options.min_curve_pixels)
}

/// Pixels along a bar to the second point that gives its direction in other views.
const TANGENT_STEP: f64 = 3.0;
/// A supporting bar may turn at most asin(0.5) = 30° from the direction this bar would have
/// there.
const MAX_ACROSS_SINE: f64 = 0.5;

/// A view for the sweep: its pose, camera and bars.
struct SweepView<'a> {
    position: usize,
    center_world: Point3<f64>,
    axis_world: Vector3<f64>,
    image: &'a crate::scene::model::Image,
    camera: &'a crate::scene::Camera,
    scale: (f64, f64),
    bars: BarMap,
    /// Camera-z depth range of the view's sparse points.
    depth_range: Option<(f64, f64)>,
}

impl SweepView<'_> {
    /// Loaded-image pixel (array coordinates) of a world point.
    fn pixel_of(&self, point_world: &Point3<f64>) -> Option<Point2<f64>> {
        self.pixel_of_camera(&(self.image.camera_from_world * point_world).coords)
    }

    /// Loaded-image pixel of a point in this view's camera frame.
    fn pixel_of_camera(&self, point_camera: &Vector3<f64>) -> Option<Point2<f64>> {
        let uv = self.camera.project(point_camera)?;
        Some(Point2::new(
            uv.x * self.scale.0 - 0.5,
            uv.y * self.scale.1 - 0.5,
        ))
    }

    /// The world ray (centre, direction with camera-z component 1) through a loaded pixel.
    fn ray(&self, x: f64, y: f64) -> Option<Vector3<f64>> {
        let uv = Point2::new((x + 0.5) / self.scale.0, (y + 0.5) / self.scale.1);
        let direction_camera = self.camera.unproject(&uv)?;
        Some(self.image.camera_from_world.rotation.inverse() * direction_camera)
    }
}

/// The camera-z depths of the sparse points an image observes: 2nd–98th percentile, widened
/// by 10 %.
fn depth_range(model: &Reconstruction, position: usize) -> Option<(f64, f64)> {
    let image = &model.images()[position];
    let mut depths: Vec<f64> = image
        .keypoints
        .iter()
        .filter_map(|k| k.point3d_id)
        .filter_map(|id| model.point(id))
        .map(|p| (image.camera_from_world * p.position_world).z)
        .filter(|z| *z > 0.0)
        .collect();
    if depths.len() < 10 {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    let lo = depths[depths.len() * 2 / 100];
    let hi = depths[(depths.len() * 98 / 100).min(depths.len() - 1)];
    Some((0.9 * lo, 1.1 * hi))
}

/// Sweeps the centreline pixels of every view and returns the thin-organ points, merged on a
/// grid of `voxel` (world units). `loaded` holds the views (model image position, pixels).
pub fn sweep(
    model: &Reconstruction,
    loaded: &[(usize, LoadedView)],
    roi: Option<&RegionOfInterest>,
    voxel: f64,
    options: &ThinOptions,
) -> opencv::Result<(FusedPoints, ThinStats)> {
    let images = model.images();
    let views: Vec<SweepView> = loaded
        .par_iter()
        .map(|(position, view)| {
            let rgb = view.rgb()?;
            let (width, height) = (view.bgr.cols() as usize, view.bgr.rows() as usize);
            let image = &images[*position];
            Ok(SweepView {
                position: *position,
                center_world: image.center_world(),
                axis_world: image.view_direction_world(),
                image,
                camera: model.camera_of(image),
                scale: view.scale,
                bars: BarMap::from_rgb(&rgb, width, height, options.min_contrast),
                depth_range: depth_range(model, *position),
            })
        })
        .collect::<opencv::Result<_>>()?;
    let results: Vec<(ThinStats, Vec<ThinPoint>)> = (0..views.len())
        .into_par_iter()
        .map(|v| sweep_view(&views, v, roi, options))
        .collect();
    let mut stats = ThinStats::default();
    let mut points = Vec::new();
    for (s, p) in results {
        stats.seeds += s.seeds;
        stats.triangulated += s.triangulated;
        stats.ambiguous += s.ambiguous;
        points.extend(p);
    }
    let fused = without_isolated(merge(&points, voxel), voxel);
    stats.points = fused.len();
    stats.short_bar_points = fused.thin_organ.iter().filter(|&&organ| !organ).count();
    Ok((fused, stats))
}

struct ThinPoint {
    position_world: Point3<f64>,
    color: [u8; 3],
    /// Image positions of the view and its supporting views.
    views: Vec<u32>,
    /// On a curve long enough for an organ (else a short bar).
    thin_organ: bool,
}

fn neighbours_of(views: &[SweepView], v: usize, options: &ThinOptions) -> Vec<usize> {
    let (lo, hi) = (
        options.min_angle_deg.to_radians().cos(),
        options.max_angle_deg.to_radians().cos(),
    );
    let mut others: Vec<(f64, usize)> = (0..views.len())
        .filter(|&u| u != v)
        .filter_map(|u| {
            let cosine = views[v].axis_world.dot(&views[u].axis_world);
            (cosine <= lo && cosine >= hi).then_some((-cosine, u))
        })
        .collect();
    others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    others
        .into_iter()
        .take(options.neighbour_views.min(64))
        .map(|(_, u)| u)
        .collect()
}

fn sweep_view(
    views: &[SweepView],
    v: usize,
    roi: Option<&RegionOfInterest>,
    options: &ThinOptions,
) -> (ThinStats, Vec<ThinPoint>) {
    let mut stats = ThinStats::default();
    let mut out = Vec::new();
    let view = &views[v];
    let Some((near, far)) = view.depth_range else {
        return (stats, out);
    };
    let neighbours = neighbours_of(views, v, options);
    if neighbours.len() < options.min_supporting {
        return (stats, out);
    }
    // One seed per 2 × 2 pixel cell: the points are merged a voxel of 1.5 pixels wide anyway.
    let mut taken = std::collections::HashSet::new();
    let shortest = match options.min_short_curve_pixels {
        0 => options.min_curve_pixels,
        short => short.min(options.min_curve_pixels),
    };
    let seeds: Vec<(usize, bool)> = view
        .bars
        .centreline_curves(options.min_contrast, shortest)
        .into_iter()
        .filter(|&(k, _)| taken.insert(((k % view.bars.width) / 2, (k / view.bars.width) / 2)))
        .map(|(k, size)| (k, size >= options.min_curve_pixels))
        .collect();
    stats.seeds = seeds.len();
    // This view's centre in each neighbour's camera frame: a point at depth z on a ray is then
    // that centre plus z times the ray's direction in the neighbour's frame.
    let centres: Vec<Vector3<f64>> = neighbours
        .iter()
        .map(|&u| (views[u].image.camera_from_world * view.center_world).coords)
        .collect();
    let mut rays: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::with_capacity(neighbours.len());
    let focal = view.camera.mean_focal() * 0.5 * (view.scale.0 + view.scale.1);
    let max_color = options.max_color_difference as f32;
    let mut scores: Vec<u8> = Vec::new();
    for (k, organ) in seeds {
        let (i, j) = (k % view.bars.width, k / view.bars.width);
        let Some(direction) = view.ray(i as f64, j as f64) else {
            continue;
        };
        // A point a few pixels along the bar, for the bar's direction in the other views.
        let [nx, ny] = view.bars.across[k];
        let Some(along) = view.ray(
            i as f64 - f64::from(ny) * TANGENT_STEP,
            j as f64 + f64::from(nx) * TANGENT_STEP,
        ) else {
            continue;
        };
        let at = |z: f64| view.center_world + direction * z;
        // Only the depths inside the region of interest are swept.
        let Some((near, far)) = clip_to_region(view.center_world, direction, near, far, roi) else {
            continue;
        };
        rays.clear();
        rays.extend(neighbours.iter().map(|&u| {
            let rotation = &views[u].image.camera_from_world.rotation;
            (rotation * direction, rotation * along)
        }));
        // Samples evenly in inverse depth, at most half a pixel apart in every neighbour.
        let mut travel = 0.0f64;
        for &u in &neighbours {
            if let (Some(a), Some(b)) = (views[u].pixel_of(&at(near)), views[u].pixel_of(&at(far)))
            {
                travel = travel.max((a - b).norm());
            }
        }
        // The masks are a pixel wider than the bars, so a pixel's step misses none.
        let count = (travel.ceil() as usize).clamp(2, 2000);
        let color = view.bars.color[k];
        let inverse_at = |s: f64| 1.0 / near + (1.0 / far - 1.0 / near) * s / (count - 1) as f64;
        // The neighbour views that see a bar of this colour and direction at sample `s` (bit
        // i: `neighbours[i]`), and the sum of their bar responses there (largest on the bars'
        // centrelines). `quick`: only the count, and 0 as soon as it cannot reach
        // `min_supporting` (such samples never decide a seed).
        let support = |s: f64, quick: bool| -> (u8, f32, u64) {
            let z = 1.0 / inverse_at(s);
            // The fine search below may step a little past the clipped range.
            if roi.is_some_and(|r| !r.contains(&at(z))) {
                return (0, 0.0, 0);
            }
            let (mut count, mut strength, mut seen) = (0u8, 0.0f32, 0u64);
            for (bit, &u) in neighbours.iter().enumerate() {
                if quick && usize::from(count) + neighbours.len() - bit < options.min_supporting {
                    return (0, 0.0, 0);
                }
                let other = &views[u];
                let (ray, ray_along) = &rays[bit];
                let Some(pixel) = other.pixel_of_camera(&(centres[bit] + ray * z)) else {
                    continue;
                };
                let Some(index) = other.bars.index_of(&pixel) else {
                    continue;
                };
                if !other.bars.mask[index] {
                    continue;
                }
                // The bar must run the way this one would there.
                let Some(next) = other.pixel_of_camera(&(centres[bit] + ray_along * z)) else {
                    continue;
                };
                let tangent = next - pixel;
                let [ax, ay] = other.bars.mask_across[index];
                let length = tangent.norm();
                if length > 1e-6
                    && (tangent.x * f64::from(ax) + tangent.y * f64::from(ay)).abs()
                        > MAX_ACROSS_SINE * length
                {
                    continue;
                }
                let c = other.bars.color[index];
                let d = ((c[0] - color[0]).powi(2)
                    + (c[1] - color[1]).powi(2)
                    + (c[2] - color[2]).powi(2))
                .sqrt();
                if d <= max_color {
                    count += 1;
                    if !quick {
                        strength += other.bars.response_at(&pixel);
                    }
                    seen |= 1 << bit;
                }
            }
            (count, strength, seen)
        };
        scores.clear();
        scores.extend((0..count).map(|s| support(s as f64, true).0));
        let best = scores.iter().copied().max().unwrap_or(0);
        if usize::from(best) < options.min_supporting {
            continue;
        }
        // Runs of the best score; more than one (apart by more than a few samples) is
        // ambiguous.
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for (s, &score) in scores.iter().enumerate() {
            if score != best {
                continue;
            }
            match runs.last_mut() {
                Some(run) if s <= run.1 + 3 => run.1 = s,
                _ => runs.push((s, s)),
            }
        }
        if runs.len() != 1 {
            stats.ambiguous += 1;
            continue;
        }
        // Within the run, a tenth of a pixel at a time: where the supporting bars are
        // strongest, i.e. nearest their centrelines.
        let (first, last) = runs[0];
        let (_, mut best_strength, mut supporting) = support(first as f64, false);
        let mut best_sample = first as f64;
        let fine_first = first.saturating_sub(1) as f64;
        let fine_last = (last + 1).min(count - 1) as f64;
        let steps = ((fine_last - fine_first) * 10.0).ceil() as usize;
        for t in 0..=steps {
            let s = fine_first + t as f64 * 0.1;
            let (n, strength, seen) = support(s, false);
            if n >= best && strength > best_strength {
                (best_sample, best_strength, supporting) = (s, strength, seen);
            }
        }
        let inverse = inverse_at(best_sample);
        let z = 1.0 / inverse;
        let axis_point = at(z);
        let radius = f64::from(view.bars.half_width[k]) * z / focal.max(1e-9);
        let position_world = axis_point - direction.normalize() * radius;
        let mut seen: Vec<u32> = vec![view.position as u32];
        seen.extend(
            neighbours
                .iter()
                .enumerate()
                .filter(|(bit, _)| supporting & (1 << bit) != 0)
                .map(|(_, &u)| views[u].position as u32),
        );
        seen.sort_unstable();
        stats.triangulated += 1;
        out.push(ThinPoint {
            position_world,
            color: [
                color[0].round().clamp(0.0, 255.0) as u8,
                color[1].round().clamp(0.0, 255.0) as u8,
                color[2].round().clamp(0.0, 255.0) as u8,
            ],
            views: seen,
            thin_organ: organ,
        });
    }
    (stats, out)
}

/// The part of the depth range `near..far` (camera z, with `direction`'s camera-z component 1)
/// that lies inside the region of interest; `None` when the ray misses it.
fn clip_to_region(
    center_world: Point3<f64>,
    direction: Vector3<f64>,
    near: f64,
    far: f64,
    roi: Option<&RegionOfInterest>,
) -> Option<(f64, f64)> {
    let Some(region) = roi else {
        return Some((near, far));
    };
    let offset = center_world - region.center_world;
    let a = direction.norm_squared();
    let b = 2.0 * direction.dot(&offset);
    let c = offset.norm_squared() - region.radius * region.radius;
    let discriminant = b * b - 4.0 * a * c;
    if a <= 0.0 || discriminant < 0.0 {
        return None;
    }
    let root = discriminant.sqrt();
    let (enter, leave) = ((-b - root) / (2.0 * a), (-b + root) / (2.0 * a));
    let (near, far) = (near.max(enter), far.min(leave));
    (near < far).then_some((near, far))
}

/// Organs are curves: a point with fewer than [`MIN_CURVE_NEIGHBOURS`] others within
/// [`CURVE_RADIUS_VOXELS`] voxels is a chance match and is dropped.
const MIN_CURVE_NEIGHBOURS: usize = 3;
const CURVE_RADIUS_VOXELS: f64 = 3.0;

fn without_isolated(points: FusedPoints, voxel: f64) -> FusedPoints {
    let Ok(index) =
        crate::graph::neighbours::Neighbours::new(points.positions_world.iter().copied())
    else {
        return FusedPoints::default();
    };
    let keep: Vec<bool> = points
        .positions_world
        .par_iter()
        .map(|p| index.within_radius(p, CURVE_RADIUS_VOXELS * voxel).len() > MIN_CURVE_NEIGHBOURS)
        .collect();
    select(points, &keep)
}

/// A surface window stereo sampled (a leaf blade, the floor) has about π·2² ≈ 12 fused points
/// within two voxels of any point on it; a sweep point with fewer than this many there adds
/// what stereo missed, one with more repeats it (leaf midribs, floor texture) and is dropped.
const MAX_FUSED_AROUND: usize = 4;

/// Keeps the sweep's points where the fused stereo points are sparse (see
/// [`MAX_FUSED_AROUND`]); `stats.points` counts the kept ones.
pub fn where_stereo_is_sparse(
    thin: FusedPoints,
    mut stats: ThinStats,
    fused: &FusedPoints,
    voxel: f64,
) -> (FusedPoints, ThinStats) {
    let Ok(index) =
        crate::graph::neighbours::Neighbours::new(fused.positions_world.iter().copied())
    else {
        return (thin, stats);
    };
    let keep: Vec<bool> = thin
        .positions_world
        .par_iter()
        .map(|p| index.within_radius(p, 2.0 * voxel).len() < MAX_FUSED_AROUND)
        .collect();
    let kept = select(thin, &keep);
    stats.points = kept.len();
    stats.short_bar_points = kept.thin_organ.iter().filter(|&&organ| !organ).count();
    (kept, stats)
}

/// The points whose `keep` is true, in order (gap-fill marks kept where the points carry them).
pub(super) fn select(points: FusedPoints, keep: &[bool]) -> FusedPoints {
    let mut out = FusedPoints::default();
    let marks_fills = points.gap_fill.len() == points.len();
    for (k, &keep) in keep.iter().enumerate() {
        if keep {
            out.positions_world.push(points.positions_world[k]);
            out.colors.push(points.colors[k]);
            out.views.push(points.views[k].clone());
            out.support.push(points.support[k]);
            out.thin_organ.push(points.thin_organ[k]);
            if marks_fills {
                out.gap_fill.push(points.gap_fill[k]);
            }
        }
    }
    out
}

/// Averages the points in each voxel (views united); deterministic order (by voxel).
fn merge(points: &[ThinPoint], voxel: f64) -> FusedPoints {
    let mut fused = FusedPoints::default();
    if voxel.is_nan() || voxel <= 0.0 {
        return fused;
    }
    let mut cells: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
    for (k, p) in points.iter().enumerate() {
        let key = [
            (p.position_world.x / voxel).floor() as i64,
            (p.position_world.y / voxel).floor() as i64,
            (p.position_world.z / voxel).floor() as i64,
        ];
        cells.entry(key).or_default().push(k);
    }
    for members in cells.values() {
        let n = members.len() as f64;
        let mut sum = Vector3::zeros();
        let mut color = [0.0f64; 3];
        let mut views: Vec<u32> = Vec::new();
        for &k in members {
            sum += points[k].position_world.coords;
            for (sum, c) in color.iter_mut().zip(points[k].color) {
                *sum += f64::from(c);
            }
            views.extend(&points[k].views);
        }
        views.sort_unstable();
        views.dedup();
        fused.positions_world.push(Point3::from(sum / n));
        fused.colors.push(color.map(|c| (c / n).round() as u8));
        fused.views.push(views);
        fused.support.push(members.len() as u32);
        // A voxel is an organ's where most of its samples are.
        let organ = members.iter().filter(|&&k| points[k].thin_organ).count();
        fused.thin_organ.push(2 * organ >= members.len());
    }
    fused
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey image with a vertical bar of `width` pixels at column `at` and a step edge.
    fn image(w: usize, h: usize, bar: (usize, usize), edge: usize) -> Vec<[u8; 3]> {
        let mut rgb = vec![[120u8, 110, 100]; w * h];
        for j in 0..h {
            for i in 0..w {
                if i >= edge {
                    rgb[j * w + i] = [200, 190, 180];
                }
                if i >= bar.0 && i < bar.0 + bar.1 {
                    rgb[j * w + i] = [40, 150, 40];
                }
            }
        }
        rgb
    }

    #[test]
    fn a_bar_is_found_at_its_centre_and_a_step_edge_is_not() {
        let (w, h) = (80, 40);
        for width in [2usize, 3, 5, 8] {
            let rgb = image(w, h, (20, width), 55);
            let bars = BarMap::from_rgb(&rgb, w, h, 14.0);
            let line = bars.centreline(14.0, 10);
            let row = h / 2;
            let columns: Vec<usize> = line
                .iter()
                .filter(|&&k| k / w == row)
                .map(|&k| k % w)
                .collect();
            assert!(!columns.is_empty(), "width {width}: no centreline");
            let centre = 20.0 + (width as f64 - 1.0) / 2.0;
            for c in &columns {
                assert!(
                    (*c as f64 - centre).abs() <= 1.0,
                    "width {width}: centreline at {c}, bar centre {centre}"
                );
            }
            // Nothing along the step edge, in the flat areas or at the image border.
            assert!(
                line.iter().all(|&k| (k % w) < 50),
                "width {width}: {columns:?}"
            );
            // The half-width follows the bar's.
            let k = row * w + columns[0];
            let half = f64::from(bars.half_width[k]);
            assert!(
                half >= 0.4 * width as f64 - 0.6 && half <= 0.5 * width as f64 + 2.0,
                "width {width}: half-width {half}"
            );
        }
    }

    #[test]
    fn a_ray_is_swept_only_where_it_crosses_the_region_of_interest() {
        let region = RegionOfInterest {
            center_world: Point3::new(0.0, 0.0, 5.0),
            radius: 1.0,
        };
        let origin = Point3::origin();
        // Straight through the centre: depths 4 to 6 of 0.5 to 100.
        let (near, far) =
            clip_to_region(origin, Vector3::z(), 0.5, 100.0, Some(&region)).expect("crosses");
        assert!(
            (near - 4.0).abs() < 1e-9 && (far - 6.0).abs() < 1e-9,
            "{near} {far}"
        );
        // The view's own range still bounds it.
        let (near, far) =
            clip_to_region(origin, Vector3::z(), 4.5, 5.5, Some(&region)).expect("crosses");
        assert!((near - 4.5).abs() < 1e-9 && (far - 5.5).abs() < 1e-9);
        // A direction with camera-z component 1 but off-axis: depths are camera z, not range.
        let slanted = Vector3::new(0.1, 0.0, 1.0);
        let (near, far) =
            clip_to_region(origin, slanted, 0.5, 100.0, Some(&region)).expect("crosses");
        for z in [near, far] {
            let distance = (origin + slanted * z - region.center_world).norm();
            assert!((distance - 1.0).abs() < 1e-9, "{distance}");
        }
        // Missing the region, or the region beyond the range: nothing to sweep.
        assert!(
            clip_to_region(
                origin,
                Vector3::new(1.0, 0.0, 1.0),
                0.5,
                100.0,
                Some(&region)
            )
            .is_none()
        );
        assert!(clip_to_region(origin, Vector3::z(), 0.5, 3.0, Some(&region)).is_none());
        // No region: the view's range.
        assert_eq!(
            clip_to_region(origin, Vector3::z(), 0.5, 3.0, None),
            Some((0.5, 3.0))
        );
    }

    #[test]
    fn a_position_maps_to_its_nearest_pixel_and_outside_positions_to_none() {
        let bars = BarMap::from_rgb(&[[0u8; 3]; 12], 4, 3, 14.0);
        let at = |x: f64, y: f64| bars.index_of(&Point2::new(x, y));
        assert_eq!(at(0.0, 0.0), Some(0));
        assert_eq!(at(-0.4, 0.2), Some(0));
        assert_eq!(at(1.5, 0.0), Some(2));
        assert_eq!(at(1.49, 1.6), Some(4 * 2 + 1));
        assert_eq!(at(3.4, 2.4), Some(11));
        for (x, y) in [
            (-0.6, 0.0),
            (0.0, -0.6),
            (3.6, 0.0),
            (0.0, 2.6),
            (f64::NAN, 0.0),
        ] {
            assert_eq!(at(x, y), None, "({x}, {y})");
        }
    }

    #[test]
    fn a_round_blob_is_not_a_bar() {
        let (w, h) = (60, 60);
        let mut rgb = vec![[120u8, 110, 100]; w * h];
        for j in 0..h {
            for i in 0..w {
                if (i as f64 - 30.0).hypot(j as f64 - 30.0) <= 2.5 {
                    rgb[j * w + i] = [30, 30, 30];
                }
            }
        }
        let bars = BarMap::from_rgb(&rgb, w, h, 14.0);
        // Pieces of ring around it may peak, but they make no curve.
        assert!(bars.centreline(14.0, 10).is_empty());
    }

    #[test]
    fn a_short_bar_is_a_curve_of_its_own_length() {
        // A dark bar 3 pixels wide and 9 long (a small leaf), and a long one (a stem).
        let (w, h) = (60, 60);
        let mut rgb = vec![[120u8, 110, 100]; w * h];
        for j in 5..55 {
            for i in 9..12 {
                rgb[j * w + i] = [30, 60, 30];
            }
        }
        for j in 26..35 {
            for i in 39..42 {
                rgb[j * w + i] = [30, 60, 30];
            }
        }
        let bars = BarMap::from_rgb(&rgb, w, h, 14.0);
        let options = ThinOptions::default();
        let column = |k: usize| k % w;
        let organ = bars.centreline(options.min_contrast, options.min_curve_pixels);
        assert!(
            organ.iter().all(|&k| column(k) < 20),
            "only the long bar is an organ"
        );
        assert!(organ.len() >= 40, "{}", organ.len());
        let curves = bars.centreline_curves(options.min_contrast, 4);
        let short: Vec<&(usize, usize)> = curves.iter().filter(|(k, _)| column(*k) > 30).collect();
        assert!(!short.is_empty(), "the short bar is a curve");
        for &&(k, size) in &short {
            assert_eq!(column(k), 40);
            assert!((4..options.min_curve_pixels).contains(&size), "{size}");
        }
    }

    #[test]
    fn merge_averages_within_a_voxel() {
        let point = |x: f64, view: u32| ThinPoint {
            position_world: Point3::new(x, 0.05, 0.05),
            color: [10, 20, 30],
            views: vec![view],
            thin_organ: view != 3,
        };
        let fused = merge(&[point(0.01, 1), point(0.03, 2), point(0.25, 3)], 0.1);
        assert_eq!(fused.len(), 2);
        assert!((fused.positions_world[0].x - 0.02).abs() < 1e-12);
        assert_eq!(fused.views[0], vec![1, 2]);
        assert_eq!(fused.support, vec![2, 1]);
        // A short bar's voxel is not an organ's.
        assert_eq!(fused.thin_organ, vec![true, false]);
        assert!(merge(&[point(0.0, 1)], 0.0).is_empty());
    }
}
