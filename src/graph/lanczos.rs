//! Lanczos iteration with full reorthogonalisation for the largest eigenpair of a sparse
//! symmetric operator, restricted to the orthogonal complement of known eigenvectors.
//!
//! Used for the normalized cut (Shi & Malik 2000): the Fiedler vector of
//! `L = I − D^{-1/2} W D^{-1/2}` is the second-largest eigenvector of `½(I + D^{-1/2} W D^{-1/2})`,
//! whose largest is `D^{1/2}·1` (deflated). No dense eigen-solve of a large group is ever made:
//! only the small tridiagonal matrix is diagonalised.

use nalgebra::{DMatrix, SymmetricEigen};

use super::components::Adjacency;
use crate::util::rng::Rng;

/// Settings of the iteration.
#[derive(Clone, Copy, Debug)]
pub struct LanczosOptions {
    pub max_iterations: usize,
    /// Stop when the Ritz residual `β·|s_last|` falls below this.
    pub tolerance: f64,
    pub seed: u64,
}

impl Default for LanczosOptions {
    fn default() -> Self {
        Self {
            max_iterations: 60,
            tolerance: 1e-4,
            seed: 7,
        }
    }
}

/// Lanes of [`dot`]: independent partial sums, so that the additions of a long dot product
/// need not wait for each other (one running sum is bound by the adder's latency: measured, the
/// reorthogonalisation's dot products were half of the Lanczos time).
const DOT_LANES: usize = 8;

/// `a · b` over their common length, summed in [`DOT_LANES`] lanes (element `i` in lane
/// `i mod DOT_LANES`, the tail in a lane of its own) and the lanes added pairwise: a fixed
/// order, so the same on every machine.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut lanes = [0.0; DOT_LANES];
    let (chunks_a, chunks_b) = (a.chunks_exact(DOT_LANES), b.chunks_exact(DOT_LANES));
    let tail: f64 = chunks_a
        .remainder()
        .iter()
        .zip(chunks_b.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in chunks_a.zip(chunks_b) {
        for k in 0..DOT_LANES {
            lanes[k] += x[k] * y[k];
        }
    }
    let mut width = DOT_LANES;
    while width > 1 {
        width /= 2;
        for k in 0..width {
            lanes[k] += lanes[k + width];
        }
    }
    lanes[0] + tail
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

fn normalize(v: &mut [f64]) -> f64 {
    let norm = dot(v, v).sqrt();
    if norm > 0.0 {
        for x in v.iter_mut() {
            *x /= norm;
        }
    }
    norm
}

/// The largest eigenpair of the symmetric operator `apply` on the complement of the orthonormal
/// vectors `deflate`. Returns `(eigenvalue, unit eigenvector)`, or `None` when the complement
/// is empty.
pub fn largest_eigenpair(
    n: usize,
    apply: impl Fn(&[f64], &mut [f64]),
    deflate: &[Vec<f64>],
    options: &LanczosOptions,
) -> Option<(f64, Vec<f64>)> {
    if n <= deflate.len() {
        return None;
    }
    let mut rng = Rng::seed_from(options.seed);
    // One modified Gram–Schmidt pass over the deflated vectors and the basis so far.
    let orthogonalize = |w: &mut [f64], basis: &[Vec<f64>]| {
        for q in deflate.iter().chain(basis) {
            let c = dot(q, w);
            axpy(-c, q, w);
        }
    };
    let mut q: Vec<f64> = (0..n).map(|_| rng.uniform() - 0.5).collect();
    // A random start may lie anywhere: twice is enough (Kahan–Parlett).
    orthogonalize(&mut q, &[]);
    orthogonalize(&mut q, &[]);
    if normalize(&mut q) == 0.0 {
        return None;
    }
    let max_iterations = options.max_iterations.min(n - deflate.len()).max(1);
    let mut basis: Vec<Vec<f64>> = vec![q];
    let mut alphas: Vec<f64> = Vec::new();
    let mut betas: Vec<f64> = Vec::new();
    let mut w = vec![0.0; n];
    for j in 0..max_iterations {
        apply(&basis[j], &mut w);
        let alpha = dot(&basis[j], &w);
        alphas.push(alpha);
        // The three-term recurrence leaves `w` nearly orthogonal to the basis: what rounding
        // adds along older vectors is tiny, and one pass removes it (full reorthogonalisation,
        // Golub & Van Loan §10.3), where two passes were needed without the recurrence.
        axpy(-alpha, &basis[j], &mut w);
        if j > 0 {
            axpy(-betas[j - 1], &basis[j - 1], &mut w);
        }
        orthogonalize(&mut w, &basis);
        let beta = normalize(&mut w);
        if beta < 1e-12 || j + 1 == max_iterations {
            break;
        }
        if alphas.len().is_multiple_of(5) {
            // The Ritz residual `β·|s_last|` needs only the last component of the top Ritz
            // vector `s`; where the cheap solve fails, the full one below decides.
            let converged = match largest_ritz_value(&alphas, &betas) {
                Some((_, s_last)) => beta * s_last.abs() < options.tolerance,
                None => {
                    let (_, s) = top_eigenpair(&alphas, &betas)?;
                    beta * s[alphas.len() - 1].abs() < options.tolerance
                }
            };
            if converged {
                break;
            }
        }
        betas.push(beta);
        basis.push(w.clone());
    }
    let (theta, s) = top_eigenpair(&alphas, &betas)?;
    let mut vector = vec![0.0; n];
    for (si, q) in s.iter().zip(&basis) {
        axpy(*si, q, &mut vector);
    }
    normalize(&mut vector);
    Some((theta, vector))
}

/// The largest eigenvalue of the symmetric tridiagonal matrix of diagonal `diagonal` and
/// off-diagonal `off` (`off[i]` couples rows `i` and `i + 1`) and its unit eigenvector (dense).
fn top_eigenpair(diagonal: &[f64], off: &[f64]) -> Option<(f64, Vec<f64>)> {
    let eigen = SymmetricEigen::new(tridiagonal(diagonal, off));
    let (k, &theta) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    Some((
        theta,
        eigen.eigenvectors.column(k).iter().copied().collect(),
    ))
}

/// The dense symmetric tridiagonal matrix of diagonal `diagonal` and off-diagonal `off`.
fn tridiagonal(diagonal: &[f64], off: &[f64]) -> DMatrix<f64> {
    let m = diagonal.len();
    let mut t = DMatrix::zeros(m, m);
    for i in 0..m {
        t[(i, i)] = diagonal[i];
        if i + 1 < m {
            t[(i, i + 1)] = off[i];
            t[(i + 1, i)] = off[i];
        }
    }
    t
}

/// The largest eigenvalue of the symmetric tridiagonal matrix of [`top_eigenpair`] and the
/// last component of its unit eigenvector (up to sign), in O(m²) where the eigenvectors cost
/// O(m³): implicit QL iterations with Wilkinson shifts that rotate only the last row of the
/// eigenvector matrix. `None` where an eigenvalue takes more than 60 iterations.
fn largest_ritz_value(diagonal: &[f64], off: &[f64]) -> Option<(f64, f64)> {
    let m = diagonal.len();
    if m == 0 || off.len() + 1 < m {
        return None;
    }
    let mut d = diagonal.to_vec();
    let mut e = vec![0.0; m];
    e[..m - 1].copy_from_slice(&off[..m - 1]);
    let mut last = vec![0.0; m];
    last[m - 1] = 1.0;
    for l in 0..m {
        let mut iterations = 0;
        loop {
            // The first negligible off-diagonal element at or after `l` splits the matrix.
            let mut split = l;
            while split + 1 < m
                && e[split].abs() > f64::EPSILON * (d[split].abs() + d[split + 1].abs())
            {
                split += 1;
            }
            if split == l {
                break;
            }
            iterations += 1;
            if iterations > 60 {
                return None;
            }
            // Wilkinson shift from the leading 2×2 block, then a chase from `split` up to `l`.
            let mut g = (d[l + 1] - d[l]) / (2.0 * e[l]);
            let mut r = g.hypot(1.0);
            g = d[split] - d[l] + e[l] / (g + r.copysign(g));
            let (mut s, mut c, mut p) = (1.0, 1.0, 0.0);
            let mut deflated = false;
            for i in (l..split).rev() {
                let f = s * e[i];
                let b = c * e[i];
                // Both are bounded by the matrix's norm: no overflow to guard against.
                r = (f * f + g * g).sqrt();
                e[i + 1] = r;
                if r == 0.0 {
                    // Underflow: the matrix split at `i + 1`; start again.
                    d[i + 1] -= p;
                    e[split] = 0.0;
                    deflated = true;
                    break;
                }
                s = f / r;
                c = g / r;
                g = d[i + 1] - p;
                r = (d[i] - g) * s + 2.0 * c * b;
                p = s * r;
                d[i + 1] = g + p;
                g = c * r - b;
                let below = last[i + 1];
                last[i + 1] = s * last[i] + c * below;
                last[i] = c * last[i] - s * below;
            }
            if deflated {
                continue;
            }
            d[l] -= p;
            e[l] = g;
            e[split] = 0.0;
        }
    }
    let (top, &theta) = d.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    Some((theta, last[top]))
}

/// The Fiedler vector of a connected weighted graph for the normalized cut: the generalized
/// eigenvector `y` of `(D − W) y = λ D y` with the second smallest `λ`. Returns `(λ, y)`.
pub fn fiedler_vector(adjacency: &Adjacency, options: &LanczosOptions) -> Option<(f64, Vec<f64>)> {
    let n = adjacency.num_nodes();
    if n < 2 {
        return None;
    }
    let degrees = adjacency.degrees();
    if degrees.iter().any(|&d| d <= 0.0) {
        return None;
    }
    let inv_sqrt: Vec<f64> = degrees.iter().map(|d| 1.0 / d.sqrt()).collect();
    let mut top: Vec<f64> = degrees.iter().map(|d| d.sqrt()).collect();
    normalize(&mut top);
    // The operator's off-diagonal entries `½·w_ij/√(d_i·d_j)`, once per solve: each
    // application then reads one number per edge besides `x`.
    let mut scaled = vec![0.0; adjacency.neighbours.len()];
    for i in 0..n {
        let range = adjacency.offsets[i]..adjacency.offsets[i + 1];
        for (e, (j, w)) in range.zip(adjacency.row(i)) {
            scaled[e] = 0.5 * inv_sqrt[i] * w * inv_sqrt[j];
        }
    }
    let apply = |x: &[f64], y: &mut [f64]| {
        for (i, yi) in y.iter_mut().enumerate().take(n) {
            let range = adjacency.offsets[i]..adjacency.offsets[i + 1];
            let sum: f64 = adjacency.neighbours[range.clone()]
                .iter()
                .zip(&scaled[range])
                .map(|(&j, s)| s * x[j as usize])
                .sum();
            *yi = 0.5 * x[i] + sum;
        }
    };
    let (theta, z) = largest_eigenpair(n, apply, &[top], options)?;
    let lambda = 2.0 * (1.0 - theta);
    let y = z.iter().zip(&inv_sqrt).map(|(zi, s)| zi * s).collect();
    Some((lambda, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dot_product_in_lanes_is_the_dot_product() {
        let mut rng = Rng::seed_from(3);
        for n in 0..70 {
            let a: Vec<f64> = (0..n).map(|_| rng.uniform() - 0.5).collect();
            let b: Vec<f64> = (0..n + 3).map(|_| rng.uniform() - 0.5).collect();
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            let scale: f64 = a.iter().zip(&b).map(|(x, y)| (x * y).abs()).sum();
            assert!(
                (dot(&a, &b) - plain).abs() <= 1e-14 * scale.max(1e-300),
                "n = {n}: {} vs {plain}",
                dot(&a, &b)
            );
            assert_eq!(dot(&a, &b), dot(&b, &a), "n = {n}");
        }
        // Exact where every product and partial sum is: small integers.
        let a: Vec<f64> = (0..37).map(f64::from).collect();
        assert_eq!(dot(&a, &a), (0..37).map(|k| f64::from(k * k)).sum::<f64>());
    }

    #[test]
    fn the_cheap_ritz_value_matches_the_dense_eigensolver() {
        let mut rng = Rng::seed_from(11);
        // Random tridiagonals of many sizes, some with clustered diagonals, repeated
        // eigenvalues (zero couplings) and Lanczos-like tiny couplings.
        for trial in 0..300usize {
            let m = 1 + trial % 60;
            let diagonal: Vec<f64> = (0..m)
                .map(|i| match trial % 3 {
                    0 => rng.uniform(),
                    1 => 0.9 + 1e-6 * rng.uniform(),
                    _ => (i % 4) as f64,
                })
                .collect();
            let off: Vec<f64> = (0..m.saturating_sub(1))
                .map(|i| match trial % 5 {
                    0 if i % 7 == 3 => 0.0,
                    1 => 1e-9 * rng.uniform(),
                    _ => rng.uniform() - 0.5,
                })
                .collect();
            let (theta, s_last) = largest_ritz_value(&diagonal, &off).unwrap();
            let (dense_theta, dense_s) = top_eigenpair(&diagonal, &off).unwrap();
            assert!(
                (theta - dense_theta).abs() < 1e-12,
                "trial {trial}: {theta} vs {dense_theta}"
            );
            // The top eigenvalue can be repeated, where the eigenvector is not unique: compare
            // only where it is well separated from the next one.
            let eigen = SymmetricEigen::new(tridiagonal(&diagonal, &off));
            let mut sorted: Vec<f64> = eigen.eigenvalues.iter().copied().collect();
            sorted.sort_by(|a, b| b.total_cmp(a));
            let gap = if m > 1 { sorted[0] - sorted[1] } else { 1.0 };
            if gap > 1e-6 {
                assert!(
                    (s_last.abs() - dense_s[m - 1].abs()).abs() < 1e-8,
                    "trial {trial}: {s_last} vs {}",
                    dense_s[m - 1]
                );
            }
        }
    }

    #[test]
    fn largest_eigenpair_of_a_diagonal_operator_with_deflation() {
        let diag = [5.0, 3.0, 9.0, 1.0, 7.0];
        let apply = |x: &[f64], y: &mut [f64]| {
            for i in 0..5 {
                y[i] = diag[i] * x[i];
            }
        };
        let (value, vector) = largest_eigenpair(5, apply, &[], &LanczosOptions::default()).unwrap();
        assert!((value - 9.0).abs() < 1e-9);
        assert!(vector[2].abs() > 0.999);
        let mut e2 = vec![0.0; 5];
        e2[2] = 1.0;
        let (value, vector) =
            largest_eigenpair(5, apply, &[e2], &LanczosOptions::default()).unwrap();
        assert!((value - 7.0).abs() < 1e-9);
        assert!(vector[4].abs() > 0.999);
    }

    #[test]
    fn fiedler_vector_of_a_path_matches_the_closed_form_and_splits_a_barbell() {
        // Path of n nodes, unit weights: λ₂ of the random-walk Laplacian is 1 − cos(π/(n−1)).
        let n = 30;
        let path = Adjacency::from_edges(n, (0..n as u32 - 1).map(|i| (i, i + 1, 1.0)));
        let (lambda, y) = fiedler_vector(&path, &LanczosOptions::default()).unwrap();
        let expected = 1.0 - (std::f64::consts::PI / (n - 1) as f64).cos();
        assert!((lambda - expected).abs() < 1e-6, "{lambda} vs {expected}");
        // Monotone along the path.
        let increasing = y.windows(2).all(|w| w[1] > w[0]);
        let decreasing = y.windows(2).all(|w| w[1] < w[0]);
        assert!(increasing || decreasing);

        // Two 10-cliques joined by one weak edge: the sign of y separates them.
        let mut edges = Vec::new();
        for block in 0..2u32 {
            for i in 0..10u32 {
                for j in i + 1..10 {
                    edges.push((block * 10 + i, block * 10 + j, 1.0));
                }
            }
        }
        edges.push((0, 10, 0.05));
        let barbell = Adjacency::from_edges(20, edges.into_iter());
        let (_, y) = fiedler_vector(&barbell, &LanczosOptions::default()).unwrap();
        let sign = y[0].signum();
        assert!(y[..10].iter().all(|v| v.signum() == sign));
        assert!(y[10..].iter().all(|v| v.signum() == -sign));
    }
}
