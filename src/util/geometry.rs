//! Small geometric solvers shared by the stages.

use nalgebra::{Matrix3, Point3, Vector3};

/// Distance of `point` from the vertical axis through `axis_point` along the unit `up`.
pub fn distance_from_axis(point: &Point3<f64>, axis_point: &Point3<f64>, up: &Vector3<f64>) -> f64 {
    let offset = point - axis_point;
    (offset - up * up.dot(&offset)).norm()
}

/// Any unit vector perpendicular to `v`.
pub fn any_perpendicular(v: &Vector3<f64>) -> Vector3<f64> {
    let helper = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    v.cross(&helper).normalize()
}

/// The axis-aligned box `(min, max)` around `points` (infinite and inverted for none).
pub fn bounding_box<'a>(
    points: impl IntoIterator<Item = &'a Point3<f64>>,
) -> (Point3<f64>, Point3<f64>) {
    points.into_iter().fold(
        (
            Point3::from([f64::INFINITY; 3]),
            Point3::from([f64::NEG_INFINITY; 3]),
        ),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    )
}

/// The monomials of a bivariate cubic, `1, u, v, u², uv, v², u³, u²v, uv², v³`: a height field
/// over a plane built from the first 1, 3, 6 or 10 is constant, planar, quadratic or cubic.
pub fn cubic_monomials(u: f64, v: f64) -> [f64; 10] {
    [
        1.0,
        u,
        v,
        u * u,
        u * v,
        v * v,
        u * u * u,
        u * u * v,
        u * v * v,
        v * v * v,
    ]
}

/// The least-squares point closest to all lines `(origin, direction)` (e.g. the point a
/// ring of cameras looks at). `None` when the lines are (nearly) parallel, so that the
/// system is ill-conditioned: smallest eigenvalue below 1e-3 of the largest.
pub fn closest_point_to_lines(lines: &[(Point3<f64>, Vector3<f64>)]) -> Option<Point3<f64>> {
    let mut normal = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for (origin, direction) in lines {
        let direction = direction.try_normalize(1e-12)?;
        let projector = Matrix3::identity() - direction * direction.transpose();
        normal += projector;
        rhs += projector * origin.coords;
    }
    let eigenvalues = normal.symmetric_eigen().eigenvalues;
    let (lo, hi) = eigenvalues
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
            (lo.min(e), hi.max(e))
        });
    if lo.is_nan() || lo <= 1e-3 * hi {
        return None;
    }
    let solved = normal.try_inverse()? * rhs;
    solved
        .iter()
        .all(|c| c.is_finite())
        .then(|| Point3::from(solved))
}

/// The common centre of concentric circles through planar points `(x, y, circle)` (e.g. a
/// tapered pot's wall in height bands, one radius per band; or one circle for all): least
/// squares of `x² + y² + D x + E y + F_c = 0`, Kåsa's algebraic circle fit with one `F` per
/// circle, so an arc is enough. Circle indices at or above `circles` count as the last.
/// `None` without enough points to fix the centre (collinear points, fewer than three).
pub fn concentric_circle_centre(
    points: &[(f64, f64, usize)],
    circles: usize,
) -> Option<(f64, f64)> {
    let circles = circles.max(1);
    let unknowns = 2 + circles;
    let mut normal = nalgebra::DMatrix::<f64>::zeros(unknowns, unknowns);
    let mut rhs = nalgebra::DVector::<f64>::zeros(unknowns);
    let mut on_circle = vec![0usize; circles];
    for &(x, y, circle) in points {
        let circle = circle.min(circles - 1);
        on_circle[circle] += 1;
        let mut row = nalgebra::DVector::<f64>::zeros(unknowns);
        row[0] = x;
        row[1] = y;
        row[2 + circle] = 1.0;
        normal += &row * row.transpose();
        rhs -= &row * (x * x + y * y);
    }
    if points.len() < 3 {
        return None;
    }
    // A circle without points leaves its unknown free: pin it to zero.
    for (circle, &count) in on_circle.iter().enumerate() {
        if count == 0 {
            normal[(2 + circle, 2 + circle)] = 1.0;
        }
    }
    let solution = normal.lu().solve(&rhs)?;
    let (cx, cy) = (-0.5 * solution[0], -0.5 * solution[1]);
    (cx.is_finite() && cy.is_finite()).then_some((cx, cy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_lines_meet_and_parallel_lines_do_not() {
        let target = Point3::new(1.0, 2.0, 3.0);
        let lines: Vec<_> = [
            Point3::new(5.0, 0.0, 0.0),
            Point3::new(0.0, 6.0, 1.0),
            Point3::new(-3.0, -1.0, 7.0),
        ]
        .into_iter()
        .map(|o| (o, (target - o) * 2.0))
        .collect();
        let found = closest_point_to_lines(&lines).unwrap();
        assert!((found - target).norm() < 1e-9);
        let parallel: Vec<_> = (0..4)
            .map(|k| (Point3::new(k as f64, 0.0, 0.0), Vector3::z()))
            .collect();
        assert!(closest_point_to_lines(&parallel).is_none());
        assert!(closest_point_to_lines(&[]).is_none());
    }
}
