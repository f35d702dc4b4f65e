//! Image boundary of a segment in a view (seed 004 §5.4): the image is oversegmented once by
//! the watershed into superpixels; a two-label graph cut over the superpixels, seeded with the
//! superpixels under the segment's projected points (foreground) and under other points
//! (background), with colour histograms of the seeds as data terms and colour similarity
//! across superpixel borders as smoothness, gives the region; its outer contour is the
//! boundary polygon.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point2;
use opencv::core::{Mat, Point, Scalar, Vector};
use opencv::prelude::*;
use serde::Serialize;

use crate::graph::gradient::GradientImage;
use crate::graph::maxflow::{CutSide, MaxFlow, MaxFlowError};
use crate::util::polygon::{offset_polygon, polygon_area};

/// Settings of oversegmentation and graph cut.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BoundaryOptions {
    /// Grid step of the watershed markers (pixels): superpixels are about this wide.
    pub superpixel_step: u32,
    /// Weight of the smoothness term relative to the colour data term.
    pub smoothness: f64,
    /// Histogram bins per colour channel.
    pub bins: usize,
    /// Spatial prior: nats per pixel for each point spacing a foreground superpixel lies
    /// beyond the reach of the segment's points (see [`ForegroundReach`]).
    pub reach_slope: f64,
    /// The graph cut's search window: the segment's projected points' bounding box grown on
    /// every side by this fraction of its longer side (beyond it, everything is background).
    pub window_margin: f64,
}

impl Default for BoundaryOptions {
    fn default() -> Self {
        Self {
            superpixel_step: 10,
            smoothness: 3.0,
            bins: 8,
            reach_slope: 1.0,
            window_margin: 0.5,
        }
    }
}

/// Boundary failures.
#[derive(Debug, thiserror::Error)]
pub enum BoundaryError {
    #[error("image: {0}")]
    Image(String),
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
    #[error("no projected point of the segment falls in the image")]
    NoForeground,
    #[error(transparent)]
    MaxFlow(#[from] MaxFlowError),
}

/// The closed outer boundary of a segment's region in a view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Boundary {
    /// Polygon vertices in pixels (COLMAP convention), counter-clockwise on screen.
    pub polygon: Vec<[f64; 2]>,
    /// Area of the region inside the polygon, pixels².
    pub area_px: f64,
    /// Superpixels in the region.
    pub superpixels: usize,
}

/// How far a region may extend from the segment's projected points: two point spacings (the
/// median nearest-neighbour distance of the projections) or one superpixel, whichever is
/// larger; beyond it, labelling a pixel foreground costs `slope` nats per spacing.
struct ForegroundReach {
    tree: Option<ImmutableKdTree<f64, 2>>,
    spacing: f64,
    reach: f64,
    slope: f64,
}

impl ForegroundReach {
    fn new(foreground: &[Point2<f64>], superpixel_step: f64, slope: f64) -> Self {
        let points: Vec<[f64; 2]> = foreground.iter().map(|p| [p.x, p.y]).collect();
        let tree = (points.len() >= 2)
            .then(|| ImmutableKdTree::<f64, 2>::new_from_slice(&points).ok())
            .flatten();
        let spacing = match &tree {
            Some(tree) => {
                let two = std::num::NonZero::<usize>::MIN.saturating_add(1);
                let mut gaps: Vec<f64> = points
                    .iter()
                    .filter_map(|p| {
                        tree.query(p)
                            .nearest_n::<SquaredEuclidean<f64>>(two)
                            .execute()
                            .get(1)
                            .map(|n| n.distance.sqrt())
                    })
                    .collect();
                gaps.sort_by(f64::total_cmp);
                gaps.get(gaps.len() / 2).copied().unwrap_or(superpixel_step)
            }
            None => superpixel_step,
        }
        .max(0.5);
        Self {
            tree,
            spacing,
            reach: (2.0 * spacing).max(superpixel_step),
            slope: slope.max(0.0),
        }
    }

    /// Cost per pixel of calling a pixel at `at` foreground, nats.
    fn penalty(&self, at: &Point2<f64>) -> f64 {
        let Some(tree) = &self.tree else { return 0.0 };
        let one = std::num::NonZero::<usize>::MIN;
        let Some(nearest) = tree
            .query(&[at.x, at.y])
            .nearest_n::<SquaredEuclidean<f64>>(one)
            .execute()
            .first()
            .map(|n| n.distance.sqrt())
        else {
            return 0.0;
        };
        self.slope * ((nearest - self.reach) / self.spacing).max(0.0)
    }
}

/// The outer contour of the largest connected region of a binary (8-bit) mask, as OpenCV
/// traces it through the region's edge pixels; `None` for an empty mask.
pub(crate) fn largest_outer_contour(mask: &Mat) -> opencv::Result<Option<Vector<Point>>> {
    let mut contours = Vector::<Vector<Point>>::new();
    opencv::imgproc::find_contours(
        mask,
        &mut contours,
        opencv::imgproc::RETR_EXTERNAL,
        opencv::imgproc::CHAIN_APPROX_SIMPLE,
        Point::new(0, 0),
    )?;
    let mut best: Option<(f64, Vector<Point>)> = None;
    for contour in contours.iter() {
        let area = opencv::imgproc::contour_area_def(&contour)?;
        if best.as_ref().is_none_or(|(a, _)| area > *a) {
            best = Some((area, contour));
        }
    }
    Ok(best.map(|(_, contour)| contour))
}

/// A superpixel seeds the foreground only where the segment's points fall on it about as
/// densely as on the segment's typical superpixel: at least this share of the median votes
/// per pixel. Points densified from photos leave a halo 1–3 px off a leaf's edge (2–5 % of a
/// leaf's points); a superpixel of backdrop just off the edge then gets a few votes, no
/// background point outvotes them, and it joined the leaf and lent its colour to the leaf's
/// colour model. Such superpixels are left to the colour and smoothness terms instead.
const SEED_VOTE_DENSITY: f64 = 0.5;

/// Which superpixels seed the foreground: the segment's points fall on them, at least as
/// many as other points, and at least [`SEED_VOTE_DENSITY`] of the segment's median votes
/// per pixel. Where no superpixel passes the density test, every superpixel the segment
/// outvotes seeds it.
fn foreground_seeds(fg_votes: &[u32], bg_votes: &[u32], sizes: &[u32]) -> Vec<bool> {
    let outvotes = |l: usize| fg_votes[l] > 0 && fg_votes[l] >= bg_votes[l];
    let density = |l: usize| fg_votes[l] as f64 / sizes[l].max(1) as f64;
    let mut densities: Vec<f64> = (0..fg_votes.len())
        .filter(|&l| fg_votes[l] > 0)
        .map(density)
        .collect();
    densities.sort_by(f64::total_cmp);
    let typical = densities.get(densities.len() / 2).copied().unwrap_or(0.0);
    let dense: Vec<bool> = (0..fg_votes.len())
        .map(|l| outvotes(l) && density(l) >= SEED_VOTE_DENSITY * typical)
        .collect();
    if dense.iter().any(|&d| d) {
        dense
    } else {
        (0..fg_votes.len()).map(outvotes).collect()
    }
}

/// Watershed superpixels of one view with their colours and adjacency.
pub struct Oversegmentation {
    width: usize,
    height: usize,
    /// Superpixel per pixel.
    labels: Vec<u32>,
    count: usize,
    /// Sparse colour histogram per superpixel: `(bin, pixel count)`.
    histograms: Vec<Vec<(u16, u32)>>,
    mean_colors: Vec<[f32; 3]>,
    sizes: Vec<u32>,
    /// Mean pixel position per superpixel.
    centroids: Vec<Point2<f64>>,
    /// `(a, b, border length)` with `a < b`.
    borders: Vec<(u32, u32, u32)>,
    bins: usize,
}

impl Oversegmentation {
    /// Oversegments an 8-bit BGR image: markers at the lowest-gradient pixel of every grid
    /// cell, then OpenCV's watershed.
    pub fn compute(bgr: &Mat, options: &BoundaryOptions) -> Result<Self, BoundaryError> {
        let (width, height) = (bgr.cols() as usize, bgr.rows() as usize);
        let gradient = GradientImage::from_bgr(bgr)?;
        let step = options.superpixel_step.max(2) as usize;
        let mut markers = Mat::new_rows_cols_with_default(
            height as i32,
            width as i32,
            opencv::core::CV_32S,
            Scalar::all(0.0),
        )?;
        let mut next = 1i32;
        for cy in (0..height).step_by(step) {
            for cx in (0..width).step_by(step) {
                let mut best = (f32::INFINITY, cx, cy);
                for y in cy..(cy + step).min(height) {
                    for x in cx..(cx + step).min(width) {
                        let g = gradient.data[y * width + x];
                        if g < best.0 {
                            best = (g, x, y);
                        }
                    }
                }
                *markers.at_2d_mut::<i32>(best.2 as i32, best.1 as i32)? = next;
                next += 1;
            }
        }
        opencv::imgproc::watershed(bgr, &mut markers)?;
        let marker_data: Vec<i32> = markers.data_typed::<i32>()?.to_vec();
        // Watershed lines (−1) join the neighbouring region on their left or above.
        let mut labels = vec![0u32; width * height];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                let m = marker_data[i];
                labels[i] = if m > 0 {
                    (m - 1) as u32
                } else if x > 0 {
                    labels[i - 1]
                } else if y > 0 {
                    labels[i - width]
                } else {
                    marker_data
                        .iter()
                        .find(|&&v| v > 0)
                        .map_or(0, |&v| (v - 1) as u32)
                };
            }
        }
        let count = (next - 1).max(1) as usize;
        let bytes = bgr.data_bytes()?;
        let channels = bgr.channels() as usize;
        let bins = options.bins.clamp(2, 16);
        let mut dense: Vec<std::collections::HashMap<u16, u32>> =
            vec![std::collections::HashMap::new(); count];
        let mut sums = vec![[0f64; 3]; count];
        let mut sizes = vec![0u32; count];
        let mut position_sums = vec![[0f64; 2]; count];
        for (i, &label) in labels.iter().enumerate() {
            position_sums[label as usize][0] += (i % width) as f64 + 0.5;
            position_sums[label as usize][1] += (i / width) as f64 + 0.5;
            let (b, g, r) = (
                bytes[i * channels],
                bytes[i * channels + 1],
                bytes[i * channels + 2],
            );
            let bin = |v: u8| (v as usize * bins / 256) as u16;
            let key = (bin(r) * bins as u16 + bin(g)) * bins as u16 + bin(b);
            *dense[label as usize].entry(key).or_insert(0) += 1;
            sums[label as usize][0] += r as f64;
            sums[label as usize][1] += g as f64;
            sums[label as usize][2] += b as f64;
            sizes[label as usize] += 1;
        }
        let histograms = dense
            .into_iter()
            .map(|h| {
                let mut v: Vec<(u16, u32)> = h.into_iter().collect();
                v.sort_unstable();
                v
            })
            .collect();
        let mean_colors = sums
            .iter()
            .zip(&sizes)
            .map(|(s, &n)| {
                let n = n.max(1) as f64;
                [(s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32]
            })
            .collect();
        let centroids = position_sums
            .iter()
            .zip(&sizes)
            .map(|(s, &n)| {
                let n = n.max(1) as f64;
                Point2::new(s[0] / n, s[1] / n)
            })
            .collect();
        let mut border_map: std::collections::HashMap<(u32, u32), u32> =
            std::collections::HashMap::new();
        for y in 0..height {
            for x in 0..width {
                let a = labels[y * width + x];
                for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                    if nx < width && ny < height {
                        let b = labels[ny * width + nx];
                        if a != b {
                            *border_map.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                        }
                    }
                }
            }
        }
        let mut borders: Vec<(u32, u32, u32)> = border_map
            .into_iter()
            .map(|((a, b), n)| (a, b, n))
            .collect();
        borders.sort_unstable();
        Ok(Self {
            width,
            height,
            labels,
            count,
            histograms,
            mean_colors,
            sizes,
            centroids,
            borders,
            bins,
        })
    }

    /// Number of superpixels.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    fn label_at(&self, p: &Point2<f64>) -> Option<u32> {
        if p.x < 0.0 || p.y < 0.0 {
            return None;
        }
        let (x, y) = (p.x as usize, p.y as usize);
        (x < self.width && y < self.height).then(|| self.labels[y * self.width + x])
    }

    /// The region of the segment whose projected points are `foreground` (other points:
    /// `background`), as a two-label graph cut over the superpixels.
    pub fn boundary(
        &self,
        foreground: &[Point2<f64>],
        background: &[Point2<f64>],
        options: &BoundaryOptions,
    ) -> Result<Boundary, BoundaryError> {
        let n = self.count;
        let mut fg_votes = vec![0u32; n];
        let mut bg_votes = vec![0u32; n];
        for p in foreground {
            if let Some(l) = self.label_at(p) {
                fg_votes[l as usize] += 1;
            }
        }
        if fg_votes.iter().all(|&v| v == 0) {
            return Err(BoundaryError::NoForeground);
        }
        for p in background {
            if let Some(l) = self.label_at(p) {
                bg_votes[l as usize] += 1;
            }
        }
        // Search window: the foreground's bounding box grown by a share of its size.
        let (mut lo, mut hi) = (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in foreground {
            lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        let margin = options.window_margin.max(0.0) * (hi - lo).max();
        let (lo, hi) = (lo.map(|c| c - margin), hi.map(|c| c + margin));
        let in_window: Vec<bool> = self
            .centroids
            .iter()
            .map(|c| c.x >= lo.x && c.x <= hi.x && c.y >= lo.y && c.y <= hi.y)
            .collect();
        let reach = ForegroundReach::new(
            foreground,
            options.superpixel_step as f64,
            options.reach_slope,
        );

        let seed_fg = foreground_seeds(&fg_votes, &bg_votes, &self.sizes);
        let seed_bg: Vec<bool> = (0..n)
            .map(|l| !seed_fg[l] && (bg_votes[l] > 0 || !in_window[l]))
            .collect();
        let bins = self.bins * self.bins * self.bins;
        // Colour models: the foreground from its seeds; the background from its seeds and
        // from everything outside the search window, so that colours the segment's points
        // never touch (a backdrop without 3D points) are explained as background.
        let model = |samples: &dyn Fn(usize) -> bool| {
            let mut h = vec![1.0f64; bins];
            for l in 0..n {
                if samples(l) {
                    for &(bin, c) in &self.histograms[l] {
                        h[bin as usize] += c as f64;
                    }
                }
            }
            let total: f64 = h.iter().sum();
            h.iter().map(|v| -(v / total).ln()).collect::<Vec<f64>>()
        };
        let cost_fg = model(&|l| seed_fg[l] && in_window[l]);
        let cost_bg = model(&|l| seed_bg[l] && !seed_fg[l]);
        // Negative log-likelihood of each superpixel's pixels under each model.
        let colour_cost: Vec<(f64, f64)> = (0..n)
            .map(|l| {
                self.histograms[l]
                    .iter()
                    .fold((0.0, 0.0), |(as_fg, as_bg), &(bin, c)| {
                        (
                            as_fg + c as f64 * cost_fg[bin as usize],
                            as_bg + c as f64 * cost_bg[bin as usize],
                        )
                    })
            })
            .collect();
        // A vote of the segment fixes a superpixel's label only where its colour agrees: a
        // point at the margin (or a little off it: keypoint noise) lands in a superpixel that straddles
        // or lies outside the leaf, and must not drag that superpixel in.
        let agrees_fg = |l: usize| colour_cost[l].0 <= colour_cost[l].1;
        let mut hard_fg: Vec<bool> = (0..n).map(|l| seed_fg[l] && agrees_fg(l)).collect();
        if !hard_fg.iter().any(|&h| h) {
            hard_fg.clone_from(&seed_fg);
        }
        // Other segments' points are trusted as they are: where another leaf of the same
        // colour touches this one, they are all that separates the two.
        let hard_bg: Vec<bool> = (0..n)
            .map(|l| !hard_fg[l] && (!in_window[l] || bg_votes[l] > fg_votes[l]))
            .collect();
        let mut flow = MaxFlow::new(n);
        for l in 0..n {
            if hard_fg[l] {
                flow.add_terminal_weights(l, f64::INFINITY, 0.0)?;
            } else if hard_bg[l] {
                flow.add_terminal_weights(l, 0.0, f64::INFINITY)?;
            } else {
                // Cutting the source link labels the superpixel background: it costs the
                // background's negative log-likelihood, and vice versa.
                let (mut as_fg, as_bg) = colour_cost[l];
                // Spatial prior: the leaf lies where its points are; a superpixel far from
                // every projected point of the segment pays per pixel for each point
                // spacing beyond the reach.
                as_fg += self.sizes[l] as f64 * reach.penalty(&self.centroids[l]);
                flow.add_terminal_weights(l, as_bg, as_fg)?;
            }
        }
        let color_distance = |a: u32, b: u32| {
            let (p, q) = (self.mean_colors[a as usize], self.mean_colors[b as usize]);
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)) as f64
        };
        let beta = {
            let relevant: Vec<f64> = self
                .borders
                .iter()
                .filter(|(a, b, _)| in_window[*a as usize] || in_window[*b as usize])
                .map(|(a, b, _)| color_distance(*a, *b))
                .collect();
            let mean = relevant.iter().sum::<f64>() / relevant.len().max(1) as f64;
            1.0 / (2.0 * mean.max(1e-6))
        };
        for &(a, b, length) in &self.borders {
            if !in_window[a as usize] && !in_window[b as usize] {
                continue;
            }
            let weight = options.smoothness * length as f64 * (-beta * color_distance(a, b)).exp();
            flow.add_edge(a as usize, b as usize, weight, weight)?;
        }
        flow.solve();
        let inside: Vec<bool> = (0..n).map(|l| flow.side(l) == CutSide::Source).collect();

        // Outer contour of the largest connected region.
        let mut mask = Mat::new_rows_cols_with_default(
            self.height as i32,
            self.width as i32,
            opencv::core::CV_8UC1,
            Scalar::all(0.0),
        )?;
        {
            let data = mask.data_bytes_mut()?;
            for (i, &l) in self.labels.iter().enumerate() {
                if inside[l as usize] {
                    data[i] = 255;
                }
            }
        }
        let Some(contour) = largest_outer_contour(&mask)? else {
            return Err(BoundaryError::NoForeground);
        };
        let mut simplified = Vector::<Point>::new();
        opencv::imgproc::approx_poly_dp(&contour, &mut simplified, 1.0, true)?;
        // The contour runs through the centres of the region's edge pixels; the region's edge
        // is half a pixel outside them (on a 100 px wide leaf, 2 % of its area).
        let centres: Vec<Point2<f64>> = simplified
            .iter()
            .map(|p| Point2::new(p.x as f64 + 0.5, p.y as f64 + 0.5))
            .collect();
        let edge = offset_polygon(&centres, 0.5);
        let area = polygon_area(&edge);
        let polygon = edge.iter().map(|p| [p.x, p.y]).collect();
        Ok(Boundary {
            polygon,
            area_px: area,
            superpixels: inside.iter().filter(|&&v| v).count(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::core::CV_8UC3;

    /// A textured green ellipse (the "leaf") on a textured brown background.
    fn scene() -> Mat {
        scene_on(&[])
    }

    /// The leaf of [`scene`] on a background of blotches (`(x, y, radius, bgr)`) like the
    /// floor of a photo, which no single colour model describes.
    fn scene_on(blotches: &[(i32, i32, i32, [f64; 3])]) -> Mat {
        let mut mat =
            Mat::new_rows_cols_with_default(240, 320, CV_8UC3, Scalar::new(40.0, 70.0, 110.0, 0.0))
                .unwrap();
        for &(x, y, r, [b, g, red]) in blotches {
            opencv::imgproc::circle(
                &mut mat,
                Point::new(x, y),
                r,
                Scalar::new(b, g, red, 0.0),
                -1,
                opencv::imgproc::LINE_8,
                0,
            )
            .unwrap();
        }
        opencv::imgproc::ellipse(
            &mut mat,
            Point::new(150, 120),
            opencv::core::Size::new(80, 45),
            20.0,
            0.0,
            360.0,
            Scalar::new(50.0, 160.0, 60.0, 0.0),
            -1,
            opencv::imgproc::LINE_8,
            0,
        )
        .unwrap();
        let mut rng = crate::util::rng::Rng::seed_from(4);
        let data = mat.data_bytes_mut().unwrap();
        for v in data.iter_mut() {
            *v = (*v as f64 + rng.range(-12.0, 12.0)).clamp(0.0, 255.0) as u8;
        }
        mat
    }

    #[test]
    fn the_region_under_the_points_follows_the_colour_edge() {
        let image = scene();
        let superpixels = Oversegmentation::compute(&image, &BoundaryOptions::default()).unwrap();
        assert!(superpixels.len() > 500);
        // Sparse foreground points inside the ellipse's core, background points outside.
        let mut rng = crate::util::rng::Rng::seed_from(5);
        let (mut fg, mut bg) = (Vec::new(), Vec::new());
        for _ in 0..3000 {
            let p = Point2::new(rng.range(0.0, 320.0), rng.range(0.0, 240.0));
            let (dx, dy) = (p.x - 150.5, p.y - 120.5);
            let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
            let (u, v) = ((dx * c + dy * s) / 80.0, (-dx * s + dy * c) / 45.0);
            let r = u * u + v * v;
            if r < 0.5 && rng.chance(0.1) {
                fg.push(p);
            } else if r > 1.4 && rng.chance(0.2) {
                bg.push(p);
            }
        }
        let boundary = superpixels
            .boundary(&fg, &bg, &BoundaryOptions::default())
            .unwrap();
        let expected = std::f64::consts::PI * 80.0 * 45.0;
        let relative = (boundary.area_px - expected).abs() / expected;
        assert!(relative < 0.08, "area {} vs {expected}", boundary.area_px);
        assert!(boundary.polygon.len() >= 8);
    }

    /// Points densified from photos: the leaf's points cover it, and a few (4 %) lie 1–3 px
    /// off its edge, where the backdrop has no points of its own. The halo must not pull
    /// the backdrop's superpixels into the leaf.
    #[test]
    fn a_halo_of_points_off_the_edge_does_not_grow_the_region() {
        let mut rng = crate::util::rng::Rng::seed_from(6);
        let blotches: Vec<(i32, i32, i32, [f64; 3])> = (0..90)
            .map(|_| {
                let grey = rng.range(60.0, 200.0);
                (
                    rng.range(0.0, 320.0) as i32,
                    rng.range(0.0, 240.0) as i32,
                    rng.range(6.0, 20.0) as i32,
                    [
                        grey + rng.range(-40.0, 60.0),
                        grey + rng.range(-40.0, 20.0),
                        grey + rng.range(-40.0, 60.0),
                    ],
                )
            })
            .collect();
        let image = scene_on(&blotches);
        let superpixels = Oversegmentation::compute(&image, &BoundaryOptions::default()).unwrap();
        let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
        let rotate = |x: f64, y: f64| (x * c - y * s, x * s + y * c);
        let (mut fg, mut bg) = (Vec::new(), Vec::new());
        while fg.len() < 3000 {
            let (u, v) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            if u * u + v * v < 1.0 {
                let (x, y) = rotate(80.0 * u, 45.0 * v);
                fg.push(Point2::new(150.5 + x, 120.5 + y));
            }
        }
        for _ in 0..120 {
            let t = rng.range(0.0, std::f64::consts::TAU);
            let (ex, ey) = rotate(80.0 * t.cos(), 45.0 * t.sin());
            let (nx, ny) = rotate(t.cos() / 80.0, t.sin() / 45.0);
            let (norm, off) = ((nx * nx + ny * ny).sqrt(), rng.range(1.0, 3.0));
            fg.push(Point2::new(
                150.5 + ex + off * nx / norm,
                120.5 + ey + off * ny / norm,
            ));
        }
        for _ in 0..1500 {
            let p = Point2::new(rng.range(0.0, 320.0), rng.range(0.0, 240.0));
            let (dx, dy) = (p.x - 150.5, p.y - 120.5);
            let (u, v) = ((dx * c + dy * s) / 80.0, (-dx * s + dy * c) / 45.0);
            if u * u + v * v > 2.0 {
                bg.push(p);
            }
        }
        let boundary = superpixels
            .boundary(&fg, &bg, &BoundaryOptions::default())
            .unwrap();
        let expected = std::f64::consts::PI * 80.0 * 45.0;
        let relative = (boundary.area_px - expected) / expected;
        assert!(
            relative.abs() < 0.04,
            "area {} vs {expected}",
            boundary.area_px
        );
    }

    #[test]
    fn sparse_votes_do_not_seed_the_foreground() {
        // Superpixels of 100 px: two under the leaf (30 and 28 votes), two just off its edge
        // with a halo point or two, one that other points outvote.
        let seeds = foreground_seeds(&[30, 2, 6, 28, 1], &[0, 0, 9, 0, 0], &[100; 5]);
        assert_eq!(seeds, vec![true, false, false, true, false]);
        // Density is per pixel: a small superpixel with few votes is as dense as a big one.
        let seeds = foreground_seeds(&[30, 3, 28], &[0, 0, 0], &[100, 10, 100]);
        assert_eq!(seeds, vec![true, true, true]);
        // Where every dense superpixel is outvoted, the sparse ones the segment holds seed it.
        let seeds = foreground_seeds(&[30, 2, 40], &[50, 0, 60], &[100; 3]);
        assert_eq!(seeds, vec![false, true, false]);
    }

    #[test]
    fn no_foreground_is_an_error() {
        let superpixels = Oversegmentation::compute(&scene(), &BoundaryOptions::default()).unwrap();
        let err = superpixels.boundary(&[Point2::new(-5.0, 3.0)], &[], &BoundaryOptions::default());
        assert!(matches!(err, Err(BoundaryError::NoForeground)));
    }
}
