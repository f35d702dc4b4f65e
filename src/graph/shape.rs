//! Shape descriptors of point groups from their principal components (seed 004 §6.2 uses the
//! same PCA for the flat leaf fit): centroid, axes, and how planar or linear the group is.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use serde::Serialize;

use crate::util::geometry::cubic_monomials;

/// Principal-component shape of a point group.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Shape {
    pub count: usize,
    pub centroid: Point3<f64>,
    /// Eigenvalues of the covariance, largest first.
    pub eigenvalues: [f64; 3],
    /// Matching unit axes; `axes[2]` is the normal of the best-fit plane.
    pub axes: [Vector3<f64>; 3],
}

impl Shape {
    /// PCA of the points (a degenerate shape for fewer than 3 points).
    pub fn of(points: impl Iterator<Item = Point3<f64>> + Clone) -> Self {
        let mut count = 0usize;
        let mut sum = Vector3::zeros();
        for p in points.clone() {
            sum += p.coords;
            count += 1;
        }
        if count == 0 {
            return Self {
                count,
                centroid: Point3::origin(),
                eigenvalues: [0.0; 3],
                axes: [Vector3::x(), Vector3::y(), Vector3::z()],
            };
        }
        let centroid = Point3::from(sum / count as f64);
        let mut covariance = Matrix3::zeros();
        for p in points {
            let d = p - centroid;
            covariance += d * d.transpose();
        }
        covariance /= count as f64;
        let eigen = SymmetricEigen::new(covariance);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let eigenvalues = order.map(|i| eigen.eigenvalues[i].max(0.0));
        let axes = order.map(|i| eigen.eigenvectors.column(i).into_owned());
        Self {
            count,
            centroid,
            eigenvalues,
            axes,
        }
    }

    /// Thickness relative to width, `√(λ₃/λ₂)`: 0 for a flat patch.
    pub fn flatness(&self) -> f64 {
        (self.eigenvalues[2] / self.eigenvalues[1].max(1e-300)).sqrt()
    }

    /// Width relative to length, `√(λ₂/λ₁)`: 0 for a line.
    pub fn width_ratio(&self) -> f64 {
        (self.eigenvalues[1] / self.eigenvalues[0].max(1e-300)).sqrt()
    }

    /// Length along the main axis of a uniformly covered patch, `√(12 λ₁)`.
    pub fn length(&self) -> f64 {
        (12.0 * self.eigenvalues[0]).sqrt()
    }

    /// Unit normal of the best-fit plane.
    pub fn normal(&self) -> Vector3<f64> {
        self.axes[2]
    }

    /// How far the points are from a smooth sheet: the RMS residual of the least-squares
    /// quadratic height field `w = a + bu + cv + du² + euv + fv²` over the PCA plane, relative
    /// to the group's length. Near 0 for a leaf, however bent or cupped; large for a tangle of
    /// leaves or a stem junction. Infinite for fewer than 6 points.
    pub fn sheet_residual(&self, points: impl Iterator<Item = Point3<f64>>) -> f64 {
        self.height_field_residual::<6>(points)
    }

    /// As [`Shape::sheet_residual`] with a cubic height field (10 terms): also fits leaves whose
    /// bend changes along the midrib. Infinite for fewer than 10 points.
    pub fn cubic_sheet_residual(&self, points: impl Iterator<Item = Point3<f64>>) -> f64 {
        self.height_field_residual::<10>(points)
    }

    /// RMS residual of a polynomial height field with the first `N` of the
    /// [`cubic_monomials`], relative to the length.
    fn height_field_residual<const N: usize>(
        &self,
        points: impl Iterator<Item = Point3<f64>>,
    ) -> f64 {
        self.fit_height_field::<N>(points)
            .map_or(f64::INFINITY, |(_, rms)| rms)
    }

    /// Least-squares coefficients of a height field with the first `N` of the
    /// [`cubic_monomials`] over the PCA plane, in coordinates relative to the length, and its
    /// relative RMS residual. `None` for fewer than `N` points or a singular fit.
    fn fit_height_field<const N: usize>(
        &self,
        points: impl Iterator<Item = Point3<f64>>,
    ) -> Option<([f64; 10], f64)> {
        let mut normal_matrix = nalgebra::SMatrix::<f64, N, N>::zeros();
        let mut rhs = nalgebra::SVector::<f64, N>::zeros();
        let mut samples = Vec::new();
        for p in points {
            let (u, v, w) = self.relative_coordinates(&p);
            let all = cubic_monomials(u, v);
            let basis = nalgebra::SVector::<f64, N>::from_fn(|i, _| all[i]);
            normal_matrix += basis * basis.transpose();
            rhs += basis * w;
            samples.push((basis, w));
        }
        if samples.len() < N {
            return None;
        }
        let regularised = normal_matrix + nalgebra::SMatrix::<f64, N, N>::identity() * 1e-9;
        let coefficients = regularised.cholesky()?.solve(&rhs);
        let squares: f64 = samples
            .iter()
            .map(|(basis, w)| (basis.dot(&coefficients) - w).powi(2))
            .sum();
        let mut all = [0.0; 10];
        for (a, c) in all.iter_mut().zip(coefficients.iter()) {
            *a = *c;
        }
        Some((all, (squares / samples.len() as f64).sqrt()))
    }

    /// A point's coordinates in the PCA frame (main axis, second axis, normal) about the
    /// centroid, divided by the length.
    fn relative_coordinates(&self, p: &Point3<f64>) -> (f64, f64, f64) {
        let scale = self.length().max(1e-12);
        let d = p - self.centroid;
        (
            d.dot(&self.axes[0]) / scale,
            d.dot(&self.axes[1]) / scale,
            d.dot(&self.axes[2]) / scale,
        )
    }

    /// The quadratic height field (the surface [`Shape::sheet_residual`] measures against)
    /// fitted to `points`, to tell how far other points lie from the same sheet. `None` for
    /// fewer than 6 points or a degenerate group.
    pub fn quadratic_sheet(&self, points: impl Iterator<Item = Point3<f64>>) -> Option<Sheet> {
        let (coefficients, rms) = self.fit_height_field::<6>(points)?;
        Some(Sheet {
            shape: *self,
            coefficients,
            rms: rms * self.length(),
        })
    }
}

/// A smooth sheet fitted to a point group: a polynomial height field over its PCA plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sheet {
    shape: Shape,
    coefficients: [f64; 10],
    /// RMS distance of the fitted points from the sheet (world units).
    pub rms: f64,
}

impl Sheet {
    /// Distance of a point from the sheet along its plane's normal (world units); the height
    /// field is extrapolated beyond the fitted points, so this is meant for points near them.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        let (u, v, w) = self.shape.relative_coordinates(p);
        let height: f64 = cubic_monomials(u, v)
            .iter()
            .zip(&self.coefficients)
            .map(|(m, c)| m * c)
            .sum();
        (w - height).abs() * self.shape.length()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_line_and_blob() {
        let plane: Vec<Point3<f64>> = (0..400)
            .map(|k| Point3::new((k % 20) as f64 * 0.01, (k / 20) as f64 * 0.005, 0.0))
            .collect();
        let s = Shape::of(plane.iter().copied());
        assert!(s.flatness() < 1e-6);
        assert!(s.normal().z.abs() > 0.999);
        assert!((s.length() - 0.2).abs() < 0.02, "{}", s.length());
        let line: Vec<Point3<f64>> = (0..50).map(|k| Point3::new(0.0, 0.0, k as f64)).collect();
        assert!(Shape::of(line.iter().copied()).width_ratio() < 1e-6);
        assert_eq!(Shape::of(std::iter::empty()).count, 0);
    }

    #[test]
    fn a_bent_sheet_is_a_sheet_and_two_crossed_sheets_are_not() {
        let bent: Vec<Point3<f64>> = (0..900)
            .map(|k| {
                let (u, v) = ((k % 30) as f64 / 30.0 * 0.2, (k / 30) as f64 / 30.0 * 0.1);
                Point3::new(u, v, 2.0 * u * u - 0.5 * v * v)
            })
            .collect();
        let shape = Shape::of(bent.iter().copied());
        assert!(shape.sheet_residual(bent.iter().copied()) < 0.005);
        let mut crossed = bent.clone();
        crossed.extend(bent.iter().map(|p| Point3::new(p.x, p.z, p.y)));
        let shape = Shape::of(crossed.iter().copied());
        assert!(shape.sheet_residual(crossed.iter().copied()) > 0.03);
    }

    #[test]
    fn a_fitted_sheet_measures_how_far_points_lie_from_it() {
        let surface = |u: f64, v: f64| 0.5 * u * u - 0.2 * v * v + 0.1 * u;
        let points: Vec<Point3<f64>> = (0..600)
            .map(|k| {
                let (u, v) = ((k % 30) as f64 / 30.0 * 0.2, (k / 30) as f64 / 20.0 * 0.1);
                Point3::new(u, v, surface(u, v))
            })
            .collect();
        let shape = Shape::of(points.iter().copied());
        let sheet = shape.quadratic_sheet(points.iter().copied()).unwrap();
        // The parabola, tilted by the PCA frame, is nearly a quadratic height field over it.
        assert!(sheet.rms < 5e-5, "{}", sheet.rms);
        // On the surface, also a little beyond the fitted points: on the sheet.
        for (u, v) in [(0.1, 0.05), (0.21, 0.05), (0.1, -0.01)] {
            let on = Point3::new(u, v, surface(u, v));
            assert!(
                sheet.distance(&on) < 1e-4,
                "({u}, {v}): {}",
                sheet.distance(&on)
            );
        }
        // Lifted off it along the surface's normal by 1 mm.
        let (u, v) = (0.1, 0.05);
        let normal = nalgebra::Vector3::new(-(u + 0.1), 0.4 * v, 1.0).normalize();
        let off = Point3::new(u, v, surface(u, v)) + normal * 0.001;
        let d = sheet.distance(&off);
        assert!((d - 0.001).abs() < 1.5e-4, "{d}");
        // Too few points for a quadratic.
        assert!(
            shape
                .quadratic_sheet(points.iter().copied().take(5))
                .is_none()
        );
    }
}
