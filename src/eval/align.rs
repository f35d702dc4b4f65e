//! Similarity alignment of two point sets (Umeyama 1991): the scale, rotation and translation
//! minimising Σ‖y_i − (s R x_i + t)‖². Used to bring a reconstruction made by real COLMAP (its
//! own gauge) into the ground-truth frame through matched camera centres.

use nalgebra::{Matrix3, Point3, Rotation3, Vector3};

/// `target = scale · rotation · source + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

impl Similarity {
    pub fn identity() -> Self {
        Self {
            scale: 1.0,
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
        }
    }

    pub fn apply(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * p.coords * self.scale + self.translation)
    }
}

/// Why an alignment could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlignError {
    #[error("need at least 3 correspondences, got {0}")]
    TooFew(usize),
    #[error("source points are degenerate (all coincident or collinear)")]
    Degenerate,
}

/// Umeyama's closed-form similarity from `source[i]` to `target[i]`.
pub fn umeyama(source: &[Point3<f64>], target: &[Point3<f64>]) -> Result<Similarity, AlignError> {
    let n = source.len().min(target.len());
    if n < 3 {
        return Err(AlignError::TooFew(n));
    }
    let mean = |points: &[Point3<f64>]| {
        points[..n]
            .iter()
            .fold(Vector3::zeros(), |acc, p| acc + p.coords)
            / n as f64
    };
    let (mu_x, mu_y) = (mean(source), mean(target));
    let mut covariance = Matrix3::zeros();
    let mut variance_x = 0.0;
    for i in 0..n {
        let x = source[i].coords - mu_x;
        let y = target[i].coords - mu_y;
        covariance += y * x.transpose();
        variance_x += x.norm_squared();
    }
    covariance /= n as f64;
    variance_x /= n as f64;
    if variance_x < 1e-18 {
        return Err(AlignError::Degenerate);
    }
    let svd = covariance.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(AlignError::Degenerate);
    };
    let mut s = Matrix3::identity();
    if (u.determinant() * v_t.determinant()) < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let singular = svd.singular_values;
    if singular[1] < 1e-12 * singular[0].max(1e-300) {
        return Err(AlignError::Degenerate);
    }
    let rotation = u * s * v_t;
    let trace = (Matrix3::from_diagonal(&singular) * s).trace();
    let scale = trace / variance_x;
    let rotation = Rotation3::from_matrix_unchecked(rotation);
    let translation = mu_y - rotation * mu_x * scale;
    Ok(Similarity {
        scale,
        rotation,
        translation,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    #[test]
    fn recovers_a_known_similarity() {
        let mut rng = Rng::seed_from(11);
        let truth = Similarity {
            scale: 2.7,
            rotation: Rotation3::from_euler_angles(0.4, -1.1, 2.3),
            translation: Vector3::new(1.0, -5.0, 0.3),
        };
        let source: Vec<Point3<f64>> = (0..40)
            .map(|_| Point3::new(rng.normal(), rng.normal(), rng.normal()))
            .collect();
        let target: Vec<Point3<f64>> = source.iter().map(|p| truth.apply(p)).collect();
        let found = umeyama(&source, &target).unwrap();
        assert!((found.scale - truth.scale).abs() < 1e-9);
        assert!((found.rotation.matrix() - truth.rotation.matrix()).norm() < 1e-9);
        assert!((found.translation - truth.translation).norm() < 1e-9);
    }

    #[test]
    fn a_reflection_is_never_returned() {
        let source = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ];
        let mirrored: Vec<Point3<f64>> =
            source.iter().map(|p| Point3::new(-p.x, p.y, p.z)).collect();
        let found = umeyama(&source, &mirrored).unwrap();
        assert!((found.rotation.matrix().determinant() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn degenerate_input() {
        let p = Point3::new(1.0, 2.0, 3.0);
        assert_eq!(umeyama(&[p, p], &[p, p]), Err(AlignError::TooFew(2)));
        assert_eq!(umeyama(&[p, p, p], &[p, p, p]), Err(AlignError::Degenerate));
        let line: Vec<Point3<f64>> = (0..5).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        assert_eq!(umeyama(&line, &line), Err(AlignError::Degenerate));
    }
}
