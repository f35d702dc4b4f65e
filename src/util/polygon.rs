//! Closed 2D polygons: area, point containment, convex hull, solidity and offsetting.

use nalgebra::Point2;

/// Twice the signed area of a closed polygon (shoelace formula): positive counter-clockwise
/// in x-right, y-up axes.
fn twice_signed_area(polygon: &[Point2<f64>]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum()
}

/// Area enclosed by a closed polygon (shoelace formula).
pub fn polygon_area(polygon: &[Point2<f64>]) -> f64 {
    0.5 * twice_signed_area(polygon).abs()
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

/// The polygon moved outward by `distance` (inward where negative): every edge shifts along
/// its outward normal and each vertex goes to where its two shifted edges meet (a miter),
/// the miter capped at twice `distance` so a spike stays a spike. Either orientation; fewer
/// than three vertices, or no area, come back unchanged.
///
/// A region's contour traced through the centres of its edge pixels (OpenCV's
/// `find_contours`) encloses half a pixel less than its pixels all round; half a pixel
/// outward gives back the region's edge.
pub fn offset_polygon(polygon: &[Point2<f64>], distance: f64) -> Vec<Point2<f64>> {
    let n = polygon.len();
    let signed = twice_signed_area(polygon);
    if n < 3 || signed == 0.0 {
        return polygon.to_vec();
    }
    // For a positive (counter-clockwise in x-right, y-up axes) polygon the outward normal of
    // an edge d is (d.y, -d.x).
    let sign = signed.signum();
    let normal = |i: usize| {
        let d = polygon[(i + 1) % n] - polygon[i];
        let len = d.norm();
        (len > 0.0).then(|| nalgebra::Vector2::new(d.y, -d.x) * (sign / len))
    };
    (0..n)
        .map(|i| {
            let before = normal((i + n - 1) % n);
            let after = normal(i);
            let shift = match (before, after) {
                (Some(a), Some(b)) => {
                    let sum = a + b;
                    let cos_half_squared = (sum.norm_squared() / 4.0).max(1e-12);
                    // The miter a + b over 1 + cos θ: length distance / cos(θ/2).
                    let miter = sum / (2.0 * cos_half_squared);
                    let capped = if miter.norm() > 2.0 {
                        miter * (2.0 / miter.norm())
                    } else {
                        miter
                    };
                    capped * distance
                }
                (Some(a), None) | (None, Some(a)) => a * distance,
                (None, None) => nalgebra::Vector2::zeros(),
            };
            polygon[i] + shift
        })
        .collect()
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

    #[test]
    fn half_a_pixel_outward_gives_a_pixel_blocks_area_back() {
        // The contour through the centres of a 6 x 4 block of pixels.
        let centres = [
            Point2::new(0.5, 0.5),
            Point2::new(5.5, 0.5),
            Point2::new(5.5, 3.5),
            Point2::new(0.5, 3.5),
        ];
        assert!((polygon_area(&centres) - 15.0).abs() < 1e-12);
        for polygon in [centres.to_vec(), centres.iter().rev().copied().collect()] {
            let grown = offset_polygon(&polygon, 0.5);
            assert!((polygon_area(&grown) - 24.0).abs() < 1e-9, "{grown:?}");
            assert!(grown.contains(&Point2::new(0.0, 0.0)), "{grown:?}");
            let back = offset_polygon(&grown, -0.5);
            assert!((polygon_area(&back) - 15.0).abs() < 1e-9);
        }
        // A needle's tip moves at most twice the distance.
        let needle = [
            Point2::new(0.0, 0.0),
            Point2::new(100.0, 1.0),
            Point2::new(0.0, 2.0),
        ];
        let grown = offset_polygon(&needle, 0.5);
        assert!((grown[1] - needle[1]).norm() <= 1.0 + 1e-9);
        assert!(polygon_area(&grown) > polygon_area(&needle));
        // Degenerate input comes back as it was.
        let line = [Point2::new(0.0, 0.0), Point2::new(1.0, 1.0)];
        assert_eq!(offset_polygon(&line, 0.5), line.to_vec());
    }
}
