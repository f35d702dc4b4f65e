//! Open polylines of points in any dimension.

use nalgebra::Point;

/// Arc length of a polyline (0 for fewer than two points).
pub fn length<const D: usize>(polyline: &[Point<f64, D>]) -> f64 {
    polyline.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}

/// `n` points equally spaced in arc length along a polyline.
pub fn resample<const D: usize>(polyline: &[Point<f64, D>], n: usize) -> Vec<Point<f64, D>> {
    if polyline.len() < 2 || n < 2 {
        return polyline.to_vec();
    }
    let lengths: Vec<f64> = polyline.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let total: f64 = lengths.iter().sum();
    if total <= 0.0 {
        return vec![polyline[0]; n];
    }
    let mut out = Vec::with_capacity(n);
    let mut segment = 0;
    let mut walked = 0.0;
    for k in 0..n {
        let target = total * k as f64 / (n - 1) as f64;
        while segment + 1 < lengths.len() && walked + lengths[segment] < target {
            walked += lengths[segment];
            segment += 1;
        }
        let t = if lengths[segment] > 0.0 {
            ((target - walked) / lengths[segment]).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push(polyline[segment] + (polyline[segment + 1] - polyline[segment]) * t);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point2, Point3};

    #[test]
    fn resampling_spaces_points_evenly_in_2d_and_3d() {
        let l = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 3.0),
        ];
        let out = resample(&l, 5);
        assert_eq!(out.len(), 5);
        assert!((out[1] - Point2::new(1.0, 0.0)).norm() < 1e-12);
        assert!((out[4] - Point2::new(1.0, 3.0)).norm() < 1e-12);
        let l = [Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, 2.0)];
        let out = resample(&l, 3);
        assert!((out[1] - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
    }
}
