//! Colour-gradient images for the 2D term of the edge distance (seed 004 §5.1): `g(u)` is the
//! colour difference between adjacent pixels, computed once per view; `d2D` of an edge takes
//! the largest `g` along the segment joining the two projections.

use nalgebra::Point2;
use opencv::core::{Mat, Size};
use opencv::prelude::*;

use crate::scene::{Image, Scene, SceneError};

/// Per-pixel colour gradient magnitude (Euclidean RGB difference to the right and lower
/// neighbours, the larger of the two), in 8-bit colour units.
#[derive(Clone, Debug)]
pub struct GradientImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

/// What the samples along one projected segment saw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentSamples {
    pub max: f32,
    pub sum_squares: f64,
    pub count: usize,
}

/// Standard deviation (pixels) of the Gaussian applied before differencing: it removes sensor
/// noise and JPEG ringing without moving leaf edges.
pub const PRESMOOTH_SIGMA_PX: f64 = 0.8;

impl GradientImage {
    /// Grey levels for display, row-major: the gradient scaled so that its 99th percentile
    /// (rank rounded down, finite values only) is white.
    pub fn to_grey(&self) -> Vec<u8> {
        let mut sorted: Vec<f32> = self
            .data
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        let scale = if sorted.is_empty() {
            1.0
        } else {
            let k = (sorted.len() - 1) * 99 / 100;
            let (_, high, _) = sorted.select_nth_unstable_by(k, f32::total_cmp);
            high.max(1e-6)
        };
        self.data
            .iter()
            .map(|v| ((v / scale).clamp(0.0, 1.0) * 255.0) as u8)
            .collect()
    }

    /// Computes the gradient image of an 8-bit BGR image.
    pub fn from_bgr(mat: &Mat) -> opencv::Result<Self> {
        let mut smoothed = Mat::default();
        opencv::imgproc::gaussian_blur(
            mat,
            &mut smoothed,
            Size::new(0, 0),
            PRESMOOTH_SIGMA_PX,
            PRESMOOTH_SIGMA_PX,
            opencv::core::BORDER_REFLECT,
        )?;
        let (w, h) = (smoothed.cols() as usize, smoothed.rows() as usize);
        let bytes = smoothed.data_bytes()?;
        let channels = smoothed.channels() as usize;
        let pixel = |x: usize, y: usize| {
            let i = (y * w + x) * channels;
            [bytes[i] as f32, bytes[i + 1] as f32, bytes[i + 2] as f32]
        };
        let diff = |a: [f32; 3], b: [f32; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        let mut data = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let here = pixel(x, y);
                let right = if x + 1 < w {
                    diff(here, pixel(x + 1, y))
                } else {
                    0.0
                };
                let down = if y + 1 < h {
                    diff(here, pixel(x, y + 1))
                } else {
                    0.0
                };
                data[y * w + x] = right.max(down);
            }
        }
        Ok(Self {
            width: w as u32,
            height: h as u32,
            data,
        })
    }

    /// Loads an image of the scene and computes its gradient image.
    pub fn for_image(scene: &Scene, image: &Image) -> Result<Self, SceneError> {
        let mat = scene.load_image(image)?;
        Self::from_bgr(&mat).map_err(|e| SceneError::Image {
            path: scene.image_path(image).unwrap_or_default(),
            image_id: image.id,
            message: format!("gradient: {e}"),
        })
    }

    fn at(&self, x: f64, y: f64) -> Option<f32> {
        if x < 0.0 || y < 0.0 {
            return None;
        }
        let (xi, yi) = (x as u32, y as u32);
        (xi < self.width && yi < self.height).then(|| self.data[(yi * self.width + xi) as usize])
    }

    /// Largest gradient on the segment between two pixel positions (COLMAP convention),
    /// sampled at one-pixel steps including both ends; `None` if an end is outside the image.
    pub fn max_along(&self, a: &Point2<f64>, b: &Point2<f64>) -> Option<f32> {
        self.sample_along(a, b).map(|s| s.max)
    }

    /// The samples of the segment between two pixel positions: largest value, sum of squares
    /// and count (for the scale σ2D of the gradient). `None` if an end is outside the image.
    pub fn sample_along(&self, a: &Point2<f64>, b: &Point2<f64>) -> Option<SegmentSamples> {
        self.at(a.x, a.y)?;
        self.at(b.x, b.y)?;
        let steps = (b - a).abs().max().ceil().max(1.0) as usize;
        let mut samples = SegmentSamples::default();
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let p = a + (b - a) * t;
            if let Some(g) = self.at(p.x, p.y) {
                samples.max = samples.max.max(g);
                samples.sum_squares += (g as f64) * (g as f64);
                samples.count += 1;
            }
        }
        Some(samples)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_grey_puts_the_99th_percentile_at_white() {
        let image = GradientImage {
            width: 100,
            height: 2,
            data: (0..200).map(|i| i as f32).chain([]).collect(),
        };
        let grey = image.to_grey();
        // Rank (199 × 99) / 100 = 197: value 197 and above are white, half of it mid-grey.
        assert_eq!(grey[197], 255);
        assert_eq!(grey[199], 255);
        assert!(grey[196] < 255);
        assert_eq!(grey[98], (98.0f32 / 197.0 * 255.0) as u8);
        assert_eq!(grey[0], 0);
        let flat = GradientImage {
            width: 1,
            height: 1,
            data: vec![f32::NAN],
        };
        assert_eq!(flat.to_grey(), vec![0]);
    }
    use opencv::core::{CV_8UC3, Rect, Scalar};

    fn two_tone(width: i32, height: i32, split_x: i32) -> Mat {
        let mut mat = Mat::new_rows_cols_with_default(
            height,
            width,
            CV_8UC3,
            Scalar::new(40.0, 160.0, 40.0, 0.0),
        )
        .unwrap();
        let mut right =
            Mat::roi_mut(&mut mat, Rect::new(split_x, 0, width - split_x, height)).unwrap();
        right
            .set_to(
                &Scalar::new(30.0, 90.0, 200.0, 0.0),
                &opencv::core::no_array(),
            )
            .unwrap();
        mat
    }

    #[test]
    fn edge_between_colours_is_found_only_when_the_segment_crosses_it() {
        let gradient = GradientImage::from_bgr(&two_tone(60, 40, 30)).unwrap();
        let inside = gradient
            .max_along(&Point2::new(5.5, 20.5), &Point2::new(25.5, 10.5))
            .unwrap();
        let crossing = gradient
            .max_along(&Point2::new(20.5, 20.5), &Point2::new(40.5, 20.5))
            .unwrap();
        assert!(inside < 1.0, "{inside}");
        assert!(crossing > 40.0, "{crossing}");
        assert!(
            gradient
                .max_along(&Point2::new(-1.0, 3.0), &Point2::new(4.0, 3.0))
                .is_none()
        );
    }
}
