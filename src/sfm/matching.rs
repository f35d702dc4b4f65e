//! SIFT descriptor matching between two photos, as COLMAP's CPU matcher defines a match (the
//! nearest neighbour by angle between unit descriptors, Lowe's ratio test on angles, a maximum
//! angle, and the mutual check), computed as blocked matrix products (`matrixmultiply`'s SIMD
//! SGEMM through nalgebra) instead of COLMAP's scalar integer loops. Takes two
//! [`Descriptors`] and [`MatchOptions`]; returns the index pairs of the matches.

use nalgebra::{DMatrix, DMatrixView};

/// Length of a SIFT descriptor.
pub const DESCRIPTOR_DIM: usize = 128;

/// A photo's descriptors, one unit-length row of [`DESCRIPTOR_DIM`] floats per feature, in the
/// database's feature order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Descriptors {
    data: Vec<f32>,
}

impl Descriptors {
    /// From COLMAP's row-major `u8` blob of `count` rows (each row normalised to unit length;
    /// an all-zero row stays zero and matches nothing).
    pub fn from_u8(bytes: &[u8], count: usize) -> Result<Self, String> {
        if bytes.len() != count * DESCRIPTOR_DIM {
            return Err(format!(
                "descriptor blob holds {} bytes, expected {count} × {DESCRIPTOR_DIM}",
                bytes.len()
            ));
        }
        let mut data: Vec<f32> = bytes.iter().map(|&b| f32::from(b)).collect();
        for row in data.chunks_exact_mut(DESCRIPTOR_DIM) {
            normalise(row);
        }
        Ok(Self { data })
    }

    /// From float rows (normalised here).
    pub fn from_rows(rows: &[[f32; DESCRIPTOR_DIM]]) -> Self {
        let mut data: Vec<f32> = rows.iter().flatten().copied().collect();
        for row in data.chunks_exact_mut(DESCRIPTOR_DIM) {
            normalise(row);
        }
        Self { data }
    }

    pub fn len(&self) -> usize {
        self.data.len() / DESCRIPTOR_DIM
    }

    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    pub fn row(&self, i: usize) -> &[f32] {
        &self.data[i * DESCRIPTOR_DIM..(i + 1) * DESCRIPTOR_DIM]
    }

    /// The rows, concatenated.
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }

    /// The rows at `indices`, in that order.
    pub fn select(&self, indices: &[usize]) -> Descriptors {
        let mut data = Vec::with_capacity(indices.len() * DESCRIPTOR_DIM);
        for &k in indices {
            data.extend_from_slice(self.row(k));
        }
        Descriptors { data }
    }

    /// At most `max` rows spread evenly over the features (all of them when there are fewer).
    pub fn spread_sample(&self, max: usize) -> Descriptors {
        let n = self.len();
        if n <= max {
            return self.clone();
        }
        let mut data = Vec::with_capacity(max * DESCRIPTOR_DIM);
        for k in 0..max {
            data.extend_from_slice(self.row(k * n / max));
        }
        Descriptors { data }
    }
}

fn normalise(row: &mut [f32]) {
    let norm = row.iter().map(|v| v * v).sum::<f32>().sqrt();
    if norm > 0.0 {
        row.iter_mut().for_each(|v| *v /= norm);
    }
}

/// What counts as a match (COLMAP's `SiftMatching` defaults).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MatchOptions {
    /// Lowe's ratio of the nearest to the second-nearest angle.
    pub max_ratio: f32,
    /// Largest angle (radians) between matched unit descriptors.
    pub max_distance: f32,
    /// Keep only mutual nearest neighbours.
    pub cross_check: bool,
}

impl Default for MatchOptions {
    fn default() -> Self {
        Self {
            max_ratio: 0.8,
            max_distance: 0.7,
            cross_check: true,
        }
    }
}

/// The two largest similarities seen for one feature, and the index of the largest.
#[derive(Clone, Copy, Debug)]
struct BestTwo {
    first: f32,
    second: f32,
    index: u32,
}

impl BestTwo {
    const EMPTY: BestTwo = BestTwo {
        first: -1.0,
        second: -1.0,
        index: u32::MAX,
    };

    #[inline]
    fn offer(&mut self, similarity: f32, index: u32) {
        if similarity > self.first {
            self.second = self.first;
            self.first = similarity;
            self.index = index;
        } else if similarity > self.second {
            self.second = similarity;
        }
    }

    /// The nearest neighbour, if it passes the distance and ratio tests.
    fn accepted(&self, options: &MatchOptions) -> Option<u32> {
        if self.index == u32::MAX {
            return None;
        }
        let nearest = self.first.clamp(-1.0, 1.0).acos();
        if nearest > options.max_distance {
            return None;
        }
        let second = self.second.clamp(-1.0, 1.0).acos();
        (nearest < options.max_ratio * second).then_some(self.index)
    }
}

/// Rows of `a` per matrix product: bounds the similarity block to `BLOCK_ROWS × len(b)` floats.
const BLOCK_ROWS: usize = 1024;

/// The matches `(index in a, index in b)` between two photos' descriptors, ordered by the index
/// in `a`.
pub fn match_descriptors(
    a: &Descriptors,
    b: &Descriptors,
    options: &MatchOptions,
) -> Vec<(u32, u32)> {
    let (rows, columns) = (a.len(), b.len());
    if rows == 0 || columns == 0 {
        return Vec::new();
    }
    // Column-major 128 × n views of the row-major descriptors are their transposes.
    let b_transposed = DMatrixView::from_slice(b.as_slice(), DESCRIPTOR_DIM, columns);
    let mut best_in_b = vec![BestTwo::EMPTY; rows];
    let mut best_in_a = vec![BestTwo::EMPTY; columns];
    for start in (0..rows).step_by(BLOCK_ROWS) {
        let end = (start + BLOCK_ROWS).min(rows);
        let block = &a.as_slice()[start * DESCRIPTOR_DIM..end * DESCRIPTOR_DIM];
        let block: DMatrix<f32> =
            DMatrixView::from_slice(block, DESCRIPTOR_DIM, end - start).transpose();
        // (end − start) × columns, column-major.
        let similarity = block * b_transposed;
        for (j, column) in similarity.as_slice().chunks_exact(end - start).enumerate() {
            let best_a = &mut best_in_a[j];
            for (offset, (&s, best_b)) in column.iter().zip(&mut best_in_b[start..end]).enumerate()
            {
                best_b.offer(s, j as u32);
                best_a.offer(s, (start + offset) as u32);
            }
        }
    }
    best_in_b
        .iter()
        .enumerate()
        .filter_map(|(i, best)| {
            let j = best.accepted(options)?;
            if options.cross_check && best_in_a[j as usize].accepted(options) != Some(i as u32) {
                return None;
            }
            Some((i as u32, j))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    fn random_rows(rng: &mut Rng, n: usize) -> Vec<[f32; DESCRIPTOR_DIM]> {
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.uniform() as f32))
            .collect()
    }

    /// The same tests, one pair at a time: the reference for the blocked products.
    fn brute_force(a: &Descriptors, b: &Descriptors, options: &MatchOptions) -> Vec<(u32, u32)> {
        let dot = |x: &[f32], y: &[f32]| x.iter().zip(y).map(|(p, q)| p * q).sum::<f32>();
        let nearest = |row: &[f32], other: &Descriptors| {
            let mut best = BestTwo::EMPTY;
            for k in 0..other.len() {
                best.offer(dot(row, other.row(k)), k as u32);
            }
            best.accepted(options)
        };
        (0..a.len())
            .filter_map(|i| {
                let j = nearest(a.row(i), b)?;
                (!options.cross_check || nearest(b.row(j as usize), a) == Some(i as u32))
                    .then_some((i as u32, j))
            })
            .collect()
    }

    #[test]
    fn perturbed_copies_are_matched_to_their_originals_and_agree_with_brute_force() {
        let mut rng = Rng::seed_from(5);
        // More rows than one block, so block boundaries are crossed.
        let originals = random_rows(&mut rng, BLOCK_ROWS + 300);
        let mut permutation: Vec<usize> = (0..originals.len()).collect();
        rng.shuffle(&mut permutation);
        // b: a shuffled, slightly perturbed copy of the first 900 rows, plus 400 unrelated rows.
        let mut b_rows: Vec<[f32; DESCRIPTOR_DIM]> = Vec::new();
        let mut truth = Vec::new();
        for (position, &k) in permutation.iter().filter(|&&k| k < 900).enumerate() {
            let mut row = originals[k];
            row.iter_mut()
                .for_each(|v| *v += 0.02 * rng.normal() as f32);
            b_rows.push(row);
            truth.push((k as u32, position as u32));
        }
        b_rows.extend(random_rows(&mut rng, 400));
        let a = Descriptors::from_rows(&originals);
        let b = Descriptors::from_rows(&b_rows);
        let options = MatchOptions::default();
        let matches = match_descriptors(&a, &b, &options);
        truth.sort();
        let correct = matches
            .iter()
            .filter(|m| truth.binary_search(m).is_ok())
            .count();
        assert!(correct >= 880, "{correct} of 900 found");
        assert_eq!(correct, matches.len(), "every match is a true one");
        assert_eq!(matches, brute_force(&a, &b, &options));
        // Without the mutual check there are at least as many.
        let one_way = MatchOptions {
            cross_check: false,
            ..options
        };
        assert_eq!(
            match_descriptors(&a, &b, &one_way),
            brute_force(&a, &b, &one_way)
        );
    }

    #[test]
    fn ambiguous_and_distant_neighbours_are_rejected() {
        let mut rng = Rng::seed_from(9);
        let rows = random_rows(&mut rng, 1);
        let a = Descriptors::from_rows(&rows);
        // Two identical candidates: the ratio test fails.
        let b = Descriptors::from_rows(&[rows[0], rows[0]]);
        assert!(match_descriptors(&a, &b, &MatchOptions::default()).is_empty());
        // One orthogonal candidate: too far.
        let mut orthogonal = [0.0f32; DESCRIPTOR_DIM];
        orthogonal[0] = 1.0;
        let mut only = [0.0f32; DESCRIPTOR_DIM];
        only[1] = 1.0;
        let a = Descriptors::from_rows(&[orthogonal]);
        let b = Descriptors::from_rows(&[only]);
        assert!(match_descriptors(&a, &b, &MatchOptions::default()).is_empty());
        assert!(
            match_descriptors(&a, &Descriptors::default(), &MatchOptions::default()).is_empty()
        );
    }

    #[test]
    fn blobs_of_the_wrong_size_are_refused_and_rows_are_unit() {
        assert!(Descriptors::from_u8(&[0; 100], 1).is_err());
        let d = Descriptors::from_u8(&[3; 256], 2).unwrap();
        assert_eq!(d.len(), 2);
        let norm: f32 = d.row(1).iter().map(|v| v * v).sum();
        assert!((norm - 1.0).abs() < 1e-5);
        assert_eq!(d.spread_sample(1).len(), 1);
        assert_eq!(d.spread_sample(5).len(), 2);
    }
}
