//! Centripetal Catmull–Rom splines through 3D control points (C¹, no cusps or self-intersections
//! within a segment; Yuksel et al. 2011), with arc-length parametrisation.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Samples per segment of the arc-length table.
const TABLE_SAMPLES_PER_SEGMENT: usize = 32;

/// A C¹ curve through its control points (at least two, consecutive points distinct).
/// Deserializing validates the control points and rebuilds the arc-length table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "SplineData")]
pub struct Spline {
    control_points: Vec<Point3<f64>>,
    /// Cumulative arc length at uniformly spaced curve parameters, for arc-length lookups.
    #[serde(skip)]
    arc_table: Vec<(f64, f64)>,
    /// The curve's points at the arc table's parameters (the polyline that closest-point and
    /// distance queries walk), so that queries do not evaluate the curve again.
    #[serde(skip)]
    arc_points: Vec<Point3<f64>>,
}

/// What a spline is stored as.
#[derive(Deserialize)]
struct SplineData {
    control_points: Vec<Point3<f64>>,
}

impl TryFrom<SplineData> for Spline {
    type Error = SplineError;
    fn try_from(data: SplineData) -> Result<Self, SplineError> {
        Spline::new(data.control_points)
    }
}

/// Why a spline could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplineError {
    #[error("a spline needs at least 2 control points, got {0}")]
    TooFewPoints(usize),
    #[error("control point {0} is not finite")]
    NonFinite(usize),
    #[error("control points {0} and {1} coincide")]
    Coincident(usize, usize),
}

impl Spline {
    /// Builds a spline; consecutive control points must differ.
    pub fn new(control_points: Vec<Point3<f64>>) -> Result<Self, SplineError> {
        if control_points.len() < 2 {
            return Err(SplineError::TooFewPoints(control_points.len()));
        }
        if let Some(i) = control_points
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(SplineError::NonFinite(i));
        }
        if let Some(i) = control_points
            .windows(2)
            .position(|w| (w[1] - w[0]).norm() < 1e-12)
        {
            return Err(SplineError::Coincident(i, i + 1));
        }
        let mut spline = Self {
            control_points,
            arc_table: Vec::new(),
            arc_points: Vec::new(),
        };
        spline.build_arc_table();
        Ok(spline)
    }

    pub fn control_points(&self) -> &[Point3<f64>] {
        &self.control_points
    }

    fn segments(&self) -> usize {
        self.control_points.len() - 1
    }

    /// The four points of segment `i`, with phantom end points mirrored.
    fn segment_points(&self, i: usize) -> [Point3<f64>; 4] {
        let p = &self.control_points;
        let n = p.len();
        let p1 = p[i];
        let p2 = p[i + 1];
        let p0 = if i == 0 { p1 + (p1 - p2) } else { p[i - 1] };
        let p3 = if i + 2 >= n { p2 + (p2 - p1) } else { p[i + 2] };
        [p0, p1, p2, p3]
    }

    /// Point at curve parameter `t` ∈ [0, 1] (uniform over segments, not arc length).
    pub fn point(&self, t: f64) -> Point3<f64> {
        let scaled = t.clamp(0.0, 1.0) * self.segments() as f64;
        let i = (scaled.floor() as usize).min(self.segments() - 1);
        let u = scaled - i as f64;
        centripetal_catmull_rom(self.segment_points(i), u)
    }

    /// Unit tangent at curve parameter `t`.
    pub fn tangent(&self, t: f64) -> Vector3<f64> {
        let h = 1e-5;
        let (a, b) = ((t - h).max(0.0), (t + h).min(1.0));
        let d = self.point(b) - self.point(a);
        d.try_normalize(1e-15).unwrap_or_else(|| {
            (self.control_points[self.control_points.len() - 1] - self.control_points[0])
                .normalize()
        })
    }

    fn build_arc_table(&mut self) {
        let samples = self.segments() * TABLE_SAMPLES_PER_SEGMENT;
        let mut table = Vec::with_capacity(samples + 1);
        let mut points = Vec::with_capacity(samples + 1);
        let mut length = 0.0;
        let mut previous = self.point(0.0);
        table.push((0.0, 0.0));
        points.push(previous);
        for k in 1..=samples {
            let t = k as f64 / samples as f64;
            let p = self.point(t);
            length += (p - previous).norm();
            previous = p;
            table.push((t, length));
            points.push(p);
        }
        self.arc_table = table;
        self.arc_points = points;
    }

    /// Total arc length.
    pub fn length(&self) -> f64 {
        self.arc_table.last().map_or(0.0, |e| e.1)
    }

    /// Curve parameter at arc-length fraction `s` ∈ [0, 1].
    pub fn parameter_at_fraction(&self, s: f64) -> f64 {
        let target = s.clamp(0.0, 1.0) * self.length();
        let k = self.arc_table.partition_point(|e| e.1 < target);
        if k == 0 {
            return 0.0;
        }
        if k >= self.arc_table.len() {
            return 1.0;
        }
        let (t0, l0) = self.arc_table[k - 1];
        let (t1, l1) = self.arc_table[k];
        if l1 - l0 < 1e-15 {
            t0
        } else {
            t0 + (t1 - t0) * (target - l0) / (l1 - l0)
        }
    }

    /// Point at arc-length fraction `s` ∈ [0, 1].
    pub fn point_at_fraction(&self, s: f64) -> Point3<f64> {
        self.point(self.parameter_at_fraction(s))
    }

    /// `n ≥ 2` points equally spaced in arc length, with unit tangents.
    pub fn sample_by_arc_length(&self, n: usize) -> Vec<(Point3<f64>, Vector3<f64>)> {
        let n = n.max(2);
        (0..n)
            .map(|k| {
                let t = self.parameter_at_fraction(k as f64 / (n - 1) as f64);
                (self.point(t), self.tangent(t))
            })
            .collect()
    }

    /// The curve's closest point to `p`: `(arc-length fraction, distance)`, over the polyline
    /// of the arc-length table.
    pub fn closest_fraction(&self, p: &Point3<f64>) -> (f64, f64) {
        let total = self.length().max(1e-300);
        let mut best = (0.0, f64::INFINITY);
        for (w, table) in self.arc_points.windows(2).zip(self.arc_table.windows(2)) {
            let (start, end) = (w[0], w[1]);
            let (start_length, end_length) = (table[0].1, table[1].1);
            let ab = end - start;
            let along = if ab.norm_squared() < 1e-30 {
                0.0
            } else {
                ((p - start).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
            };
            let distance = (p - (start + ab * along)).norm();
            if distance < best.1 {
                best = (
                    (start_length + along * (end_length - start_length)) / total,
                    distance,
                );
            }
        }
        (best.0.clamp(0.0, 1.0), best.1)
    }

    /// Distance from `p` to the curve (sampled densely: the arc table's polyline).
    pub fn distance_to(&self, p: &Point3<f64>) -> f64 {
        self.arc_points
            .windows(2)
            .map(|w| point_segment_distance(p, &w[0], &w[1]))
            .fold(f64::INFINITY, f64::min)
    }
}

/// Distance from `p` to segment `ab`.
pub fn point_segment_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let ab = b - a;
    let length2 = ab.norm_squared();
    if length2 < 1e-30 {
        return (p - a).norm();
    }
    let t = ((p - a).dot(&ab) / length2).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}

/// Barry–Goldman evaluation of a centripetal (α = ½) Catmull–Rom segment from `p1` to `p2`.
fn centripetal_catmull_rom(p: [Point3<f64>; 4], u: f64) -> Point3<f64> {
    let knot = |a: &Point3<f64>, b: &Point3<f64>| (b - a).norm().sqrt().max(1e-12);
    let t0 = 0.0;
    let t1 = t0 + knot(&p[0], &p[1]);
    let t2 = t1 + knot(&p[1], &p[2]);
    let t3 = t2 + knot(&p[2], &p[3]);
    let t = t1 + u * (t2 - t1);
    let lerp = |a: &Point3<f64>, b: &Point3<f64>, ta: f64, tb: f64| -> Point3<f64> {
        Point3::from(a.coords * ((tb - t) / (tb - ta)) + b.coords * ((t - ta) / (tb - ta)))
    };
    let a1 = lerp(&p[0], &p[1], t0, t1);
    let a2 = lerp(&p[1], &p[2], t1, t2);
    let a3 = lerp(&p[2], &p[3], t2, t3);
    let b1 = lerp(&a1, &a2, t0, t2);
    let b2 = lerp(&a2, &a3, t1, t3);
    lerp(&b1, &b2, t1, t2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serde_round_trip_rebuilds_the_arc_table_and_validates() {
        let spline = Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.0, 0.3, 1.0),
            Point3::new(1.0, 0.0, 2.0),
        ])
        .unwrap();
        let json = serde_json::to_string(&spline).unwrap();
        let back: Spline = serde_json::from_str(&json).unwrap();
        assert_eq!(back, spline);
        assert!((back.length() - spline.length()).abs() < 1e-12);
        assert_eq!(back.point_at_fraction(0.5), spline.point_at_fraction(0.5));
        let coincident = r#"{"control_points":[[0,0,0],[0,0,0]]}"#;
        let error = serde_json::from_str::<Spline>(coincident).unwrap_err();
        assert!(error.to_string().contains("coincide"), "{error}");
    }

    #[test]
    fn passes_through_control_points() {
        let points = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.2, 0.0),
            Point3::new(2.0, 1.0, 0.5),
            Point3::new(2.5, 2.0, 1.5),
        ];
        let spline = Spline::new(points.clone()).unwrap();
        for (k, p) in points.iter().enumerate() {
            let q = spline.point(k as f64 / 3.0);
            assert!((q - p).norm() < 1e-9, "{k}: {q:?}");
        }
    }

    #[test]
    fn straight_line_has_exact_length_and_uniform_arc_samples() {
        let spline = Spline::new(vec![Point3::origin(), Point3::new(0.0, 0.0, 2.0)]).unwrap();
        assert!((spline.length() - 2.0).abs() < 1e-9);
        let samples = spline.sample_by_arc_length(5);
        for (k, (p, t)) in samples.iter().enumerate() {
            assert!((p.z - 0.5 * k as f64).abs() < 1e-6);
            assert!((t - Vector3::z()).norm() < 1e-6);
        }
        assert!((spline.distance_to(&Point3::new(1.0, 0.0, 1.0)) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn closest_fraction_finds_the_foot_of_the_perpendicular() {
        let spline = Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(0.0, 0.0, 3.0),
        ])
        .unwrap();
        let (fraction, distance) = spline.closest_fraction(&Point3::new(0.5, 0.0, 1.5));
        assert!((fraction - 0.5).abs() < 1e-3, "{fraction}");
        assert!((distance - 0.5).abs() < 1e-3, "{distance}");
        let (fraction, distance) = spline.closest_fraction(&Point3::new(0.0, 0.0, -2.0));
        assert_eq!(fraction, 0.0);
        assert!((distance - 2.0).abs() < 1e-9);
    }

    #[test]
    fn tangent_is_continuous_across_control_points() {
        let spline = Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.5, 1.0, 0.0),
            Point3::new(1.0, 2.0, 0.3),
        ])
        .unwrap();
        for k in 1..3 {
            let t = k as f64 / 3.0;
            let before = spline.tangent(t - 1e-4);
            let after = spline.tangent(t + 1e-4);
            assert!(before.dot(&after) > 0.999, "kink at control point {k}");
        }
    }

    #[test]
    fn invalid_control_points() {
        assert_eq!(
            Spline::new(vec![Point3::origin()]),
            Err(SplineError::TooFewPoints(1))
        );
        assert_eq!(
            Spline::new(vec![Point3::origin(), Point3::origin()]),
            Err(SplineError::Coincident(0, 1))
        );
        assert_eq!(
            Spline::new(vec![Point3::origin(), Point3::new(f64::NAN, 0.0, 0.0)]),
            Err(SplineError::NonFinite(1))
        );
    }
}
