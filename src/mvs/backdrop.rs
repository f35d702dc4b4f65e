//! Carving against a plain backdrop. Phenotyping cabins photograph the plant before plain cloth
//! (ROMI's scanner, most lab set-ups); semi-global matching has nothing to match in that cloth
//! and smears a thin organ's depth into it beside the organ, a halo that nearby views share and
//! the free-space check ([`super::fusion::seen_through`]) cannot see through, because behind
//! it lies no surface stereo could confirm. The photos themselves can: the backdrop is behind
//! everything, so a point on a true surface projects, in every photo that frames it, onto that
//! surface or onto whatever hides it, never onto the backdrop. A point that projects onto the
//! backdrop in at least [`BackdropOptions::min_views`] photos lies in empty space and is
//! dropped (space carving, Kutulakos and Seitz 2000, with silhouettes from the backdrop's
//! colour, as ROMI's own pipeline carves with plant masks).
//!
//! The backdrop's colours are learnt from the photos' borders (top, left and right bands; the
//! pot often stands on the bottom one), pooled over all photos so that an organ crossing the
//! border in a few of them stays a minority. A border pixel whose ray passes through the box
//! the fused points span ([`PlantBox`]) may show the plant and is not learnt from: a close-up
//! whose leaves fill the frame leaves too few border pixels ([`MIN_LEARNT_SHARE`]) and carves
//! nothing, instead of taking the leaves' green for the backdrop. Colours are binned in cells of [`CELL`] levels per
//! channel; the most frequent cells that together hold [`BackdropOptions::border_share`] of the
//! border pixels are the backdrop, plus their neighbouring cells (tolerance for shading and
//! noise). The backdrop counts as plain only when that takes at most
//! [`BackdropOptions::max_cells`] cells; a patterned wall or a textured floor needs hundreds,
//! and then nothing is carved. A pixel is backdrop only when its 3 × 3 neighbourhood is, so a
//! point a pixel off a thin organ (calibration, resampling) still lands on it.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::stereo::LoadedView;
use crate::scene::Reconstruction;

/// Least share of the border pixels that must lie off the plant's box for a model to be learnt.
pub const MIN_LEARNT_SHARE: f64 = 0.1;

/// An axis-aligned box (world frame) holding the plant: the 2nd–98th percentiles of the fused
/// points per axis, widened by 5 % of its size on each side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantBox {
    pub min_world: Point3<f64>,
    pub max_world: Point3<f64>,
}

impl PlantBox {
    /// The box of `points_world` (none for fewer than 10 points).
    pub fn of(points_world: &[Point3<f64>]) -> Option<Self> {
        if points_world.len() < 10 {
            return None;
        }
        let mut min_world = Point3::origin();
        let mut max_world = Point3::origin();
        for axis in 0..3 {
            let mut values: Vec<f64> = points_world.iter().map(|p| p[axis]).collect();
            values.sort_by(f64::total_cmp);
            let lo = values[values.len() * 2 / 100];
            let hi = values[(values.len() * 98 / 100).min(values.len() - 1)];
            let margin = 0.05 * (hi - lo);
            min_world[axis] = lo - margin;
            max_world[axis] = hi + margin;
        }
        Some(Self {
            min_world,
            max_world,
        })
    }

    /// Whether the ray from `origin_world` along `direction_world` (forward only) crosses the
    /// box (slab test).
    pub fn crossed_by(&self, origin_world: &Point3<f64>, direction_world: &Vector3<f64>) -> bool {
        let (mut enter, mut leave) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let (o, d) = (origin_world[axis], direction_world[axis]);
            let (lo, hi) = (self.min_world[axis], self.max_world[axis]);
            if d.abs() < 1e-15 {
                if o < lo || o > hi {
                    return false;
                }
                continue;
            }
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            enter = enter.max(a.min(b));
            leave = leave.min(a.max(b));
        }
        enter <= leave
    }
}

/// Colour levels per cell side (8-bit channels: 32 cells per channel).
pub const CELL: u8 = 8;
const CELLS_PER_CHANNEL: usize = 256 / CELL as usize;

/// Settings of the backdrop carving.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BackdropOptions {
    /// A point is dropped when this many photos see the backdrop where it projects (0: off).
    pub min_views: usize,
    /// Width of the border bands, as a fraction of the image width.
    pub border_fraction: f64,
    /// Share of the border pixels the backdrop's colour cells hold.
    pub border_share: f64,
    /// Most colour cells a plain backdrop takes to hold that share.
    pub max_cells: usize,
}

impl Default for BackdropOptions {
    fn default() -> Self {
        Self {
            min_views: 2,
            border_fraction: 0.025,
            border_share: 0.9,
            max_cells: 64,
        }
    }
}

/// What the photos' borders said about the backdrop.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BackdropModel {
    /// Border pixels learnt from.
    pub border_pixels: usize,
    /// Border pixels left out because their rays cross the plant's box.
    pub border_pixels_on_plant: usize,
    /// Colour cells holding [`BackdropOptions::border_share`] of them.
    pub cells: usize,
    /// Whether that is few enough for a plain backdrop (otherwise nothing is carved).
    pub plain: bool,
    /// Mean colour (RGB) of the border pixels in those cells.
    pub mean_rgb: [f64; 3],
    #[serde(skip)]
    is_backdrop: Vec<bool>,
}

fn cell_of(rgb: [u8; 3]) -> usize {
    let c = |v: u8| (v / CELL) as usize;
    (c(rgb[0]) * CELLS_PER_CHANNEL + c(rgb[1])) * CELLS_PER_CHANNEL + c(rgb[2])
}

impl BackdropModel {
    /// Learns the backdrop's colours from the border bands of `images` (RGB rows of
    /// `width × height` pixels), leaving out the pixels `on_plant(image, x, y)` says may show
    /// the plant (`image` counts the images from 0).
    pub fn learn<'a>(
        images: impl IntoIterator<Item = (&'a [[u8; 3]], usize, usize)>,
        on_plant: impl Fn(usize, usize, usize) -> bool,
        options: &BackdropOptions,
    ) -> Self {
        let mut counts = vec![0usize; CELLS_PER_CHANNEL.pow(3)];
        let mut sums = vec![[0.0f64; 3]; counts.len()];
        let (mut total, mut left_out) = (0usize, 0usize);
        for (index, (rgb, width, height)) in images.into_iter().enumerate() {
            if width == 0 || height == 0 || rgb.len() != width * height {
                continue;
            }
            let band = ((options.border_fraction * width as f64).round() as usize)
                .clamp(1, width.min(height) / 2);
            for y in 0..height {
                for x in 0..width {
                    if y >= band && x >= band && x + band < width {
                        continue;
                    }
                    if on_plant(index, x, y) {
                        left_out += 1;
                        continue;
                    }
                    let pixel = rgb[y * width + x];
                    let cell = cell_of(pixel);
                    counts[cell] += 1;
                    for c in 0..3 {
                        sums[cell][c] += pixel[c] as f64;
                    }
                    total += 1;
                }
            }
        }
        let mut order: Vec<usize> = (0..counts.len()).filter(|&c| counts[c] > 0).collect();
        order.sort_by_key(|&c| (std::cmp::Reverse(counts[c]), c));
        let wanted = (options.border_share * total as f64).ceil() as usize;
        let (mut held, mut chosen) = (0usize, Vec::new());
        for &c in &order {
            if held >= wanted {
                break;
            }
            held += counts[c];
            chosen.push(c);
        }
        let learnt_enough =
            total > 0 && total as f64 >= MIN_LEARNT_SHARE * (total + left_out) as f64;
        let plain = learnt_enough && chosen.len() <= options.max_cells;
        let mut mean_rgb = [0.0; 3];
        for &c in &chosen {
            for k in 0..3 {
                mean_rgb[k] += sums[c][k] / held.max(1) as f64;
            }
        }
        let mut is_backdrop = vec![false; counts.len()];
        if plain {
            let n = CELLS_PER_CHANNEL as i64;
            for &c in &chosen {
                let (r, g, b) = (c as i64 / (n * n), (c as i64 / n) % n, c as i64 % n);
                for dr in -1..=1 {
                    for dg in -1..=1 {
                        for db in -1..=1 {
                            let (rr, gg, bb) = (r + dr, g + dg, b + db);
                            if [rr, gg, bb].iter().all(|v| (0..n).contains(v)) {
                                is_backdrop[((rr * n + gg) * n + bb) as usize] = true;
                            }
                        }
                    }
                }
            }
        }
        Self {
            border_pixels: total,
            border_pixels_on_plant: left_out,
            cells: chosen.len(),
            plain,
            mean_rgb,
            is_backdrop,
        }
    }

    /// Whether a colour is the backdrop's (always false when the backdrop is not plain).
    pub fn is_backdrop(&self, rgb: [u8; 3]) -> bool {
        self.plain && self.is_backdrop.get(cell_of(rgb)).copied().unwrap_or(false)
    }
}

/// One photo as the carving sees it: its pose and camera, its pixels as loaded for matching.
pub struct CarvingView<'a> {
    pub image: &'a crate::scene::model::Image,
    pub camera: &'a crate::scene::Camera,
    /// Factors from photo pixels to loaded pixels.
    pub scale: (f64, f64),
    pub rgb: Vec<[u8; 3]>,
    pub width: usize,
    pub height: usize,
}

impl<'a> CarvingView<'a> {
    /// The view of model image `position` loaded as `view`.
    pub fn new(
        model: &'a Reconstruction,
        position: usize,
        view: &LoadedView,
    ) -> opencv::Result<Self> {
        use opencv::prelude::*;
        let image = &model.images()[position];
        Ok(Self {
            image,
            camera: model.camera_of(image),
            scale: view.scale,
            rgb: view.rgb()?,
            width: view.bgr.cols() as usize,
            height: view.bgr.rows() as usize,
        })
    }

    /// The world ray (camera centre, direction) through loaded pixel `(x, y)`.
    pub fn ray(&self, x: usize, y: usize) -> Option<(Point3<f64>, Vector3<f64>)> {
        let uv = nalgebra::Point2::new(
            (x as f64 + 0.5) / self.scale.0,
            (y as f64 + 0.5) / self.scale.1,
        );
        let direction_camera = self.camera.unproject(&uv)?;
        Some((
            self.image.center_world(),
            self.image.camera_from_world.rotation.inverse() * direction_camera,
        ))
    }

    /// Whether the photo sees the backdrop all around where `point_world` projects (false
    /// when it projects behind the camera or within a pixel of the image's edge).
    fn sees_backdrop_at(&self, point_world: &Point3<f64>, model: &BackdropModel) -> bool {
        let point_camera = self.image.camera_from_world * point_world;
        if point_camera.z <= 0.0 {
            return false;
        }
        let Some(uv) = self.camera.project(&point_camera.coords) else {
            return false;
        };
        let (x, y) = (uv.x * self.scale.0 - 0.5, uv.y * self.scale.1 - 0.5);
        let (x, y) = (x.round(), y.round());
        // Written so that a NaN (a degenerate projection) also returns.
        let inside =
            x >= 1.0 && y >= 1.0 && x + 1.0 < self.width as f64 && y + 1.0 < self.height as f64;
        if !inside {
            return false;
        }
        let (x, y) = (x as usize, y as usize);
        (y - 1..=y + 1)
            .all(|yy| (x - 1..=x + 1).all(|xx| model.is_backdrop(self.rgb[yy * self.width + xx])))
    }
}

/// For each point, how many of `views` see the backdrop where it projects.
pub fn backdrop_sightings(
    points_world: &[Point3<f64>],
    views: &[CarvingView],
    model: &BackdropModel,
) -> Vec<u32> {
    if !model.plain {
        return vec![0; points_world.len()];
    }
    points_world
        .par_iter()
        .map(|p| {
            views
                .iter()
                .filter(|v| v.sees_backdrop_at(p, model))
                .count() as u32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: usize, height: usize, f: impl Fn(usize, usize) -> [u8; 3]) -> Vec<[u8; 3]> {
        (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect()
    }

    /// Dark cloth with a little grain, a green stem up the middle crossing the top border.
    fn cabin(seed: usize) -> Vec<[u8; 3]> {
        image(200, 150, |x, y| {
            if (95..105).contains(&x) && y < 120 {
                [60, 140, 50]
            } else {
                let grain = ((x * 7 + y * 13 + seed * 31) % 5) as u8;
                [20 + grain, 22 + grain, 27 + grain]
            }
        })
    }

    #[test]
    fn plain_cloth_is_learnt_and_the_plant_is_not_backdrop() {
        let photos: Vec<Vec<[u8; 3]>> = (0..6).map(cabin).collect();
        let model = BackdropModel::learn(
            photos.iter().map(|p| (p.as_slice(), 200, 150)),
            |_, _, _| false,
            &BackdropOptions::default(),
        );
        assert!(model.plain, "{model:?}");
        assert!(model.cells <= 4, "{} cells", model.cells);
        assert!(model.is_backdrop([22, 24, 29]));
        assert!(model.is_backdrop([25, 27, 32]));
        assert!(!model.is_backdrop([60, 140, 50]), "the stem");
        assert!(!model.is_backdrop([120, 70, 40]), "a terracotta pot");
        assert!(
            (model.mean_rgb[0] - 22.0).abs() < 2.0,
            "{:?}",
            model.mean_rgb
        );
    }

    #[test]
    fn a_patterned_backdrop_is_not_plain_and_carves_nothing() {
        // Colours all over the cube, as a patterned wall or a terrazzo floor gives.
        let photos: Vec<Vec<[u8; 3]>> = (0..4)
            .map(|s| {
                image(200, 150, move |x, y| {
                    let h = (x * 2654435761 + y * 40503 + s * 97) as u64;
                    [
                        (h % 251) as u8,
                        ((h >> 8) % 241) as u8,
                        ((h >> 16) % 239) as u8,
                    ]
                })
            })
            .collect();
        let model = BackdropModel::learn(
            photos.iter().map(|p| (p.as_slice(), 200, 150)),
            |_, _, _| false,
            &BackdropOptions::default(),
        );
        assert!(!model.plain, "{} cells", model.cells);
        assert!(!model.is_backdrop([22, 24, 29]));
        let views: Vec<CarvingView> = Vec::new();
        assert_eq!(
            backdrop_sightings(&[Point3::origin(); 3], &views, &model),
            vec![0; 3]
        );
    }

    #[test]
    fn no_photos_learn_nothing() {
        let model = BackdropModel::learn(
            std::iter::empty(),
            |_, _, _| false,
            &BackdropOptions::default(),
        );
        assert!(!model.plain);
        assert_eq!(model.border_pixels, 0);
        // A malformed image (wrong pixel count) is skipped, not indexed out of bounds.
        let short = vec![[0u8; 3]; 10];
        let model = BackdropModel::learn(
            [(short.as_slice(), 200, 150)],
            |_, _, _| false,
            &BackdropOptions::default(),
        );
        assert_eq!(model.border_pixels, 0);
    }

    /// A close-up whose leaves fill the frame: uniform green all around the border would pass
    /// for a plain backdrop, but its rays cross the plant's box and are not learnt from.
    #[test]
    fn a_border_the_plant_fills_is_not_taken_for_the_backdrop() {
        let photos: Vec<Vec<[u8; 3]>> = (0..4)
            .map(|s| {
                image(200, 150, move |x, y| {
                    [50, 120 + ((x + y + s) % 4) as u8, 40]
                })
            })
            .collect();
        let images = || photos.iter().map(|p| (p.as_slice(), 200usize, 150usize));
        let options = BackdropOptions::default();
        let naive = BackdropModel::learn(images(), |_, _, _| false, &options);
        assert!(naive.plain && naive.is_backdrop([50, 121, 40]), "{naive:?}");
        // Only the top-left corner's rays miss the plant: under a tenth of the border.
        let model = BackdropModel::learn(images(), |_, x, y| x > 20 || y > 20, &options);
        assert!(!model.plain, "{model:?}");
        assert!(model.border_pixels_on_plant > 4 * model.border_pixels);
        assert!(!model.is_backdrop([50, 121, 40]));
    }

    #[test]
    fn rays_cross_the_plant_box_or_pass_it() {
        let plant = PlantBox {
            min_world: Point3::new(-1.0, -1.0, -1.0),
            max_world: Point3::new(1.0, 1.0, 1.0),
        };
        let eye = Point3::new(0.0, 0.0, -5.0);
        assert!(plant.crossed_by(&eye, &Vector3::new(0.0, 0.0, 1.0)));
        assert!(plant.crossed_by(&eye, &Vector3::new(0.15, 0.15, 1.0)));
        assert!(!plant.crossed_by(&eye, &Vector3::new(0.3, 0.0, 1.0)));
        assert!(
            !plant.crossed_by(&eye, &Vector3::new(0.0, 0.0, -1.0)),
            "behind the eye"
        );
        let inside = Point3::new(0.5, 0.0, 0.0);
        assert!(plant.crossed_by(&inside, &Vector3::new(1.0, 0.0, 0.0)));
        let points: Vec<Point3<f64>> = (0..100).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        let of = PlantBox::of(&points).unwrap();
        assert!((of.min_world.x - (2.0 - 4.8)).abs() < 1e-9, "{of:?}");
        assert!(PlantBox::of(&points[..5]).is_none());
    }
}
