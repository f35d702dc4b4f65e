//! One depth map per stereo pair: both views resampled onto the rectified plane, matched row by
//! row with OpenCV's semi-global block matching (Hirschmüller 2008), disparities turned into
//! depths along the rectified axis of the left view.

use opencv::core::{Mat, Size};
use opencv::prelude::*;
use serde::Serialize;

use super::pairs::StereoPair;
use super::rectify::{RectifiedCamera, RectifiedPair, ResamplingTable};

/// Semi-global matching settings.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct StereoOptions {
    /// Matching block side, pixels (odd).
    pub block_size: i32,
    /// Most disparities searched per pair (the far end of the range is dropped beyond).
    pub max_disparities: i32,
    /// Best cost must beat the second best by this percentage.
    pub uniqueness_ratio: i32,
    /// Connected disparity blobs smaller than this are removed as speckles (pixels).
    pub speckle_window: i32,
    /// Disparity margin added on each side of the sparse points' range, as a fraction of it.
    pub range_margin: f64,
}

impl Default for StereoOptions {
    fn default() -> Self {
        Self {
            block_size: 5,
            max_disparities: 256,
            uniqueness_ratio: 10,
            speckle_window: 100,
            range_margin: 0.15,
        }
    }
}

/// An image ready for resampling: 8-bit BGR, possibly downsized from the photo, with the
/// factors (x, y) from photo pixels to its pixels.
pub struct LoadedView {
    pub bgr: Mat,
    pub scale: (f64, f64),
}

/// The left view's depths on its rectified grid (0 = no depth) and its colours: the result of
/// stereo matching one pair (not the occlusion z-buffer of
/// [`crate::graph::visibility::SplatDepthMap`]).
#[derive(Clone, Debug)]
pub struct RectifiedDepthMap {
    pub pair: StereoPair,
    pub camera: RectifiedCamera,
    /// Rectified depth per pixel, row-major; 0 where matching gave nothing.
    pub depth: Vec<f32>,
    /// RGB per pixel.
    pub colors: Vec<[u8; 3]>,
    /// The disparity range searched, `[min, min + count)`.
    pub disparity_range: (i32, i32),
}

impl RectifiedDepthMap {
    pub fn depth_at(&self, i: usize, j: usize) -> f32 {
        self.depth[j * self.camera.width + i]
    }

    pub fn valid_pixels(&self) -> usize {
        self.depth.iter().filter(|&&z| z > 0.0).count()
    }
}

/// The disparity range `[min, min + count)` (count a positive multiple of 16) covering
/// `disparities` with `margin` of their spread on each side, at most `max_count` wide (the
/// smallest disparities, the farthest points, are dropped first). `None` without disparities.
pub fn disparity_range(disparities: &[f64], margin: f64, max_count: i32) -> Option<(i32, i32)> {
    let finite = disparities.iter().copied().filter(|d| d.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
        (lo.min(d), hi.max(d))
    });
    if lo > hi {
        return None;
    }
    let spread = (hi - lo).max(8.0);
    let (lo, hi) = (lo - margin * spread, hi + margin * spread);
    let max_count = i64::from((max_count.max(16) / 16) * 16);
    let full = (hi.ceil() - lo.floor()).max(1.0) as i64;
    let count = ((full + 15) / 16 * 16).min(max_count);
    let min = if full <= count {
        lo.floor() as i64
    } else {
        hi.ceil() as i64 - count
    };
    let count = i32::try_from(count).ok()?;
    Some((i32::try_from(min).ok()?, count))
}

impl LoadedView {
    /// Its pixels as RGB, row-major.
    pub fn rgb(&self) -> opencv::Result<Vec<[u8; 3]>> {
        let copy;
        let mat = if self.bgr.is_continuous() {
            &self.bgr
        } else {
            copy = self.bgr.try_clone()?;
            &copy
        };
        let bgr: &[opencv::core::Vec3b] = mat.data_typed()?;
        Ok(bgr.iter().map(|p| [p[2], p[1], p[0]]).collect())
    }
}

fn remap(
    view: &LoadedView,
    map: &ResamplingTable,
    camera: &RectifiedCamera,
) -> opencv::Result<Mat> {
    let (rows, cols) = (camera.height as i32, camera.width as i32);
    let map_x = Mat::new_rows_cols_with_data(rows, cols, &map.0)?;
    let map_y = Mat::new_rows_cols_with_data(rows, cols, &map.1)?;
    let mut out = Mat::default();
    opencv::imgproc::remap(
        &view.bgr,
        &mut out,
        &map_x,
        &map_y,
        opencv::imgproc::INTER_LINEAR,
        opencv::core::BORDER_CONSTANT,
        opencv::core::Scalar::all(0.0),
    )?;
    Ok(out)
}

/// Resizes a BGR photo so its longest side is at most `max_side` (area averaging).
pub fn load_view(bgr: Mat, max_side: u32) -> opencv::Result<LoadedView> {
    let (width, height) = (bgr.cols(), bgr.rows());
    let longest = width.max(height).max(1) as f64;
    let factor = max_side as f64 / longest;
    if factor >= 1.0 {
        return Ok(LoadedView {
            bgr,
            scale: (1.0, 1.0),
        });
    }
    let size = Size::new(
        ((width as f64 * factor).round() as i32).max(1),
        ((height as f64 * factor).round() as i32).max(1),
    );
    let mut small = Mat::default();
    opencv::imgproc::resize(
        &bgr,
        &mut small,
        size,
        0.0,
        0.0,
        opencv::imgproc::INTER_AREA,
    )?;
    Ok(LoadedView {
        scale: (
            size.width as f64 / width as f64,
            size.height as f64 / height as f64,
        ),
        bgr: small,
    })
}

/// Matches a rectified pair over `range` and returns the left view's depth map.
/// `tables` are the resampling tables of the left and right views (see
/// [`RectifiedCamera::resampling_table`]).
pub fn match_pair(
    pair: StereoPair,
    rectified: &RectifiedPair,
    views: (&LoadedView, &LoadedView),
    tables: (&ResamplingTable, &ResamplingTable),
    range: (i32, i32),
    options: &StereoOptions,
) -> opencv::Result<RectifiedDepthMap> {
    let left = remap(views.0, tables.0, &rectified.left)?;
    let right = remap(views.1, tables.1, &rectified.right)?;
    let block = options.block_size.max(1) | 1;
    let channels = 3;
    let mut matcher = opencv::calib3d::StereoSGBM::create(
        range.0,
        range.1,
        block,
        8 * channels * block * block,
        32 * channels * block * block,
        1,
        63,
        options.uniqueness_ratio,
        options.speckle_window,
        2,
        opencv::calib3d::StereoSGBM_MODE_SGBM_3WAY,
    )?;
    let mut disparity = Mat::default();
    matcher.compute(&left, &right, &mut disparity)?;
    let fixed: &[i16] = disparity.data_typed::<i16>()?;
    let (width, height) = (rectified.left.width, rectified.left.height);
    let right_width = rectified.right.width;
    let mut depth = vec![0.0f32; width * height];
    for j in 0..height {
        for i in 0..width {
            let k = j * width + i;
            if tables.0.0[k] < 0.0 || i32::from(fixed[k]) < range.0 * 16 {
                continue;
            }
            let d = fixed[k] as f64 / 16.0;
            // The match must land on the right view's image, not on its black border.
            let i_right = (i as f64 - d).round();
            if i_right < 0.0 || i_right as usize >= right_width {
                continue;
            }
            if j >= rectified.right.height || tables.1.0[j * right_width + i_right as usize] < 0.0 {
                continue;
            }
            if let Some(z) = rectified.depth_from_disparity(d) {
                depth[k] = z as f32;
            }
        }
    }
    let bgr: &[opencv::core::Vec3b] = left.data_typed()?;
    let colors = bgr.iter().map(|p| [p[2], p[1], p[0]]).collect();
    Ok(RectifiedDepthMap {
        pair,
        camera: rectified.left.clone(),
        depth,
        colors,
        disparity_range: range,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disparity_range_covers_the_points_in_multiples_of_16() {
        let (min, count) = disparity_range(&[40.0, 100.0, 70.0], 0.1, 256).unwrap();
        assert_eq!(count % 16, 0);
        assert!(
            min as f64 <= 34.0 && (min + count) as f64 >= 106.0,
            "{min} {count}"
        );
        // Too wide: the near end (large disparities) is kept.
        let (min, count) = disparity_range(&[0.0, 1000.0], 0.0, 256).unwrap();
        assert_eq!(count, 256);
        assert_eq!(min + count, 1000);
        assert!(disparity_range(&[], 0.1, 256).is_none());
        assert!(disparity_range(&[f64::NAN], 0.1, 256).is_none());
        // Negative disparities (principal points far apart) are fine.
        let (min, count) = disparity_range(&[-50.0, -20.0], 0.1, 256).unwrap();
        assert!(min <= -53 && min + count >= -17);
    }
}
