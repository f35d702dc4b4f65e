//! Closed 2D polygons: area, point containment, convex hull and solidity.

use nalgebra::Point2;

/// Area enclosed by a closed polygon (shoelace formula).
pub fn polygon_area(polygon: &[Point2<f64>]) -> f64 {
    let n = polygon.len();
    0.5 * (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        .abs()
}

/// Area of the convex hull of a point set (Andrew's monotone chain, then the shoelace formula).
pub fn convex_hull_area(points: &[Point2<f64>]) -> f64 {
    let mut sorted: Vec<Point2<f64>> = points
        .iter()
        .copied()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .collect();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return 0.0;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * sorted.len());
    let n = sorted.len();
    for reversed in [false, true] {
        let start = hull.len();
        for k in 0..n {
            let p = sorted[if reversed { n - 1 - k } else { k }];
            while hull.len() >= start + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], &p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        // The last point of each chain starts the other.
        hull.pop();
    }
    polygon_area(&hull)
}

/// Solidity of a closed polygon: its area over its convex hull's (1 for a convex outline;
/// lower for notched or two-lobed shapes such as two merged leaves).
pub fn solidity(polygon: &[Point2<f64>]) -> f64 {
    let hull = convex_hull_area(polygon);
    if hull > 0.0 {
        (polygon_area(polygon) / hull).min(1.0)
    } else {
        0.0
    }
}

/// Even-odd point-in-polygon test (a closed polygon, vertices as `[x, y]` or points).
pub fn inside_polygon<V: Copy + Into<[f64; 2]>>(p: &Point2<f64>, polygon: &[V]) -> bool {
    let mut inside = false;
    let n = polygon.len();
    for i in 0..n {
        let (a, b): ([f64; 2], [f64; 2]) = (polygon[i].into(), polygon[(i + 1) % n].into());
        if (a[1] > p.y) != (b[1] > p.y) {
            let x = a[0] + (p.y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convex_hull_and_solidity() {
        let square = [
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(2.0, 2.0),
            Point2::new(0.0, 2.0),
        ];
        assert!((convex_hull_area(&square) - 4.0).abs() < 1e-12);
        assert!((solidity(&square) - 1.0).abs() < 1e-12);
        // An L (three unit squares of a 2x2 square): hull = square minus one triangle.
        let l_shape = [
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(2.0, 1.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 2.0),
            Point2::new(0.0, 2.0),
        ];
        assert!((convex_hull_area(&l_shape) - 3.5).abs() < 1e-12);
        assert!((solidity(&l_shape) - 3.0 / 3.5).abs() < 1e-12);
        // Collinear or too few points enclose nothing.
        let line = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(2.0, 2.0),
        ];
        assert_eq!(convex_hull_area(&line), 0.0);
        assert_eq!(solidity(&line[..2]), 0.0);
    }

    #[test]
    fn inside_follows_the_even_odd_rule() {
        let square = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        assert!(inside_polygon(&Point2::new(1.0, 1.0), &square));
        assert!(!inside_polygon(&Point2::new(3.0, 1.0), &square));
        assert!(!inside_polygon(&Point2::new(1.0, 1.0), &square[..2]));
        assert!((polygon_area(&square.map(|p| Point2::new(p[0], p[1]))) - 4.0).abs() < 1e-12);
    }
}
