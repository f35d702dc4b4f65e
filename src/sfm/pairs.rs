//! Which photo pairs to match: the pairs a capture of one plant needs, not all N(N−1)/2.
//!
//! Image retrieval by a bag of visual words built from the capture itself (Sivic & Zisserman's
//! tf-idf scoring, as COLMAP's vocabulary-tree matcher uses with a pre-trained tree): a
//! vocabulary from a spread sample of every photo's descriptors (spherical k-means, seeded),
//! one tf-idf histogram per photo, and for each photo its most similar photos. Captures are
//! usually walks around the plant, so the neighbours in file-name order are added too; the
//! retrieval finds the loop closures and the other rings. Takes every photo's
//! [`Descriptors`] (in name order) and [`PairOptions`]; returns the pairs `(i, j)`, `i < j`.

use std::collections::BTreeSet;

use nalgebra::{DMatrix, DMatrixView};

use super::matching::{DESCRIPTOR_DIM, Descriptors};
use crate::util::rng::Rng;

/// How many pairs to choose.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PairOptions {
    /// Most similar photos matched with each photo.
    pub retrieved: usize,
    /// Neighbours on each side in file-name order matched with each photo.
    pub sequential: usize,
    /// Visual words of the vocabulary.
    pub words: usize,
    /// Descriptors per photo used to train the vocabulary.
    pub training_per_photo: usize,
    /// Seed of the vocabulary's initial centres.
    pub seed: u64,
}

impl Default for PairOptions {
    fn default() -> Self {
        Self {
            retrieved: 8,
            sequential: 2,
            words: 256,
            training_per_photo: 200,
            seed: 1,
        }
    }
}

/// Per photo, the dot products of its unit descriptors with the unit centres: rows × words,
/// column-major.
fn similarities(descriptors: &[f32], rows: usize, centres: &DMatrix<f32>) -> DMatrix<f32> {
    let transposed: DMatrix<f32> =
        DMatrixView::from_slice(descriptors, DESCRIPTOR_DIM, rows).transpose();
    transposed * centres
}

/// The nearest centre of each row of `descriptors`.
fn assign(descriptors: &[f32], rows: usize, centres: &DMatrix<f32>) -> Vec<usize> {
    if rows == 0 {
        return Vec::new();
    }
    let s = similarities(descriptors, rows, centres);
    let mut best = vec![(f32::NEG_INFINITY, 0usize); rows];
    for (w, column) in s.as_slice().chunks_exact(rows).enumerate() {
        for (b, &v) in best.iter_mut().zip(column) {
            if v > b.0 {
                *b = (v, w);
            }
        }
    }
    best.into_iter().map(|(_, w)| w).collect()
}

/// A vocabulary of unit centres (128 × words, column-major) by spherical k-means.
fn vocabulary(training: &Descriptors, words: usize, seed: u64) -> DMatrix<f32> {
    let n = training.len();
    let words = words.clamp(1, n.max(1));
    let mut rng = Rng::seed_from(seed);
    let mut order: Vec<usize> = (0..n).collect();
    rng.shuffle(&mut order);
    let mut centres = DMatrix::<f32>::zeros(DESCRIPTOR_DIM, words);
    for (w, &k) in order.iter().take(words).enumerate() {
        centres.column_mut(w).copy_from_slice(training.row(k));
    }
    for _ in 0..8 {
        let labels = assign(training.as_slice(), n, &centres);
        let mut sums = DMatrix::<f32>::zeros(DESCRIPTOR_DIM, words);
        let mut counts = vec![0usize; words];
        for (k, &w) in labels.iter().enumerate() {
            counts[w] += 1;
            for (s, v) in sums.column_mut(w).iter_mut().zip(training.row(k)) {
                *s += v;
            }
        }
        for w in 0..words {
            let norm = sums.column(w).norm();
            // An empty word keeps its centre.
            if counts[w] > 0 && norm > 0.0 {
                let unit = sums.column(w) / norm;
                centres.set_column(w, &unit);
            }
        }
    }
    centres
}

/// tf-idf similarity of every photo pair (symmetric, 1 on the diagonal for photos with words).
pub fn retrieval_scores(photos: &[Descriptors], options: &PairOptions) -> DMatrix<f32> {
    let n = photos.len();
    let mut training = Vec::new();
    for photo in photos {
        training.extend_from_slice(photo.spread_sample(options.training_per_photo).as_slice());
    }
    let training = Descriptors::from_normalised(training);
    let centres = vocabulary(&training, options.words, options.seed);
    let words = centres.ncols();
    let counts: Vec<Vec<f32>> = photos
        .iter()
        .map(|photo| {
            let mut histogram = vec![0.0f32; words];
            for w in assign(photo.as_slice(), photo.len(), &centres) {
                histogram[w] += 1.0;
            }
            histogram
        })
        .collect();
    let idf: Vec<f32> = (0..words)
        .map(|w| {
            let containing = counts.iter().filter(|h| h[w] > 0.0).count();
            if containing == 0 {
                0.0
            } else {
                (n as f32 / containing as f32).ln()
            }
        })
        .collect();
    let mut histograms = DMatrix::<f32>::zeros(words, n);
    for (i, h) in counts.iter().enumerate() {
        let total: f32 = h.iter().sum::<f32>().max(1.0);
        for w in 0..words {
            histograms[(w, i)] = h[w] / total * idf[w];
        }
        let norm = histograms.column(i).norm();
        if norm > 0.0 {
            histograms.column_mut(i).unscale_mut(norm);
        }
    }
    histograms.transpose() * &histograms
}

/// The pairs to match (see the module docs), sorted.
pub fn select_pairs(photos: &[Descriptors], options: &PairOptions) -> Vec<(usize, usize)> {
    let n = photos.len();
    let mut pairs = BTreeSet::new();
    let mut add = |i: usize, j: usize| {
        if i != j {
            pairs.insert((i.min(j), i.max(j)));
        }
    };
    if n <= options.retrieved + 2 * options.sequential + 1 {
        // Every photo would be matched with nearly every other anyway.
        for i in 0..n {
            for j in i + 1..n {
                add(i, j);
            }
        }
        return pairs.into_iter().collect();
    }
    for i in 0..n {
        for d in 1..=options.sequential {
            if i + d < n {
                add(i, i + d);
            }
        }
    }
    let scores = retrieval_scores(photos, options);
    for i in 0..n {
        let mut ranked: Vec<(f32, usize)> = (0..n)
            .filter(|&j| j != i)
            .map(|j| (scores[(i, j)], j))
            .collect();
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(_, j) in ranked.iter().take(options.retrieved) {
            add(i, j);
        }
    }
    pairs.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Photos of a "scene" of distinct local patterns seen along a path: photo k sees the
    /// patterns in [4k, 4k + 40), so photos overlap when they are near in the walk. The files
    /// are named out of walk order (a shuffle), so only the retrieval can find the neighbours.
    fn walk(photos: usize, seed: u64) -> (Vec<Descriptors>, Vec<usize>) {
        let mut rng = Rng::seed_from(seed);
        let patterns: Vec<[f32; DESCRIPTOR_DIM]> = (0..4 * photos + 40)
            .map(|_| std::array::from_fn(|_| rng.uniform().powi(4) as f32))
            .collect();
        let mut position: Vec<usize> = (0..photos).collect();
        rng.shuffle(&mut position);
        let mut descriptors = Vec::new();
        for &k in &position {
            let mut rows: Vec<[f32; DESCRIPTOR_DIM]> = Vec::new();
            for pattern in &patterns[4 * k..4 * k + 40] {
                for _ in 0..3 {
                    let mut row = *pattern;
                    row.iter_mut()
                        .for_each(|v| *v = (*v + 0.01 * rng.normal() as f32).max(0.0));
                    rows.push(row);
                }
            }
            descriptors.push(Descriptors::from_rows(&rows));
        }
        (descriptors, position)
    }

    #[test]
    fn retrieval_finds_the_overlapping_photos_of_a_shuffled_walk() {
        let (photos, position) = walk(30, 4);
        let options = PairOptions {
            sequential: 0,
            retrieved: 4,
            words: 64,
            ..PairOptions::default()
        };
        let pairs = select_pairs(&photos, &options);
        assert!(pairs.len() < 30 * 29 / 2 / 3, "{} pairs", pairs.len());
        // Every photo is paired with both of its walk neighbours.
        for (i, &k) in position.iter().enumerate() {
            for (j, &l) in position.iter().enumerate() {
                if l == k + 1 {
                    assert!(pairs.contains(&(i.min(j), i.max(j))), "{k}–{l} missing");
                }
            }
        }
        // Most chosen pairs overlap (their windows share patterns).
        let overlapping = pairs
            .iter()
            .filter(|&&(i, j)| position[i].abs_diff(position[j]) < 10)
            .count();
        assert!(
            overlapping * 10 >= pairs.len() * 9,
            "{overlapping} of {}",
            pairs.len()
        );
        // Deterministic.
        assert_eq!(pairs, select_pairs(&photos, &options));
    }

    #[test]
    fn small_captures_are_matched_exhaustively_and_sequence_neighbours_are_kept() {
        let (photos, _) = walk(6, 2);
        let pairs = select_pairs(&photos, &PairOptions::default());
        assert_eq!(pairs.len(), 15);
        let (photos, _) = walk(20, 3);
        let options = PairOptions {
            retrieved: 2,
            sequential: 1,
            words: 32,
            ..PairOptions::default()
        };
        let pairs = select_pairs(&photos, &options);
        for i in 0..19 {
            assert!(pairs.contains(&(i, i + 1)));
        }
        assert!(pairs.iter().all(|&(i, j)| i < j && j < 20));
    }
}
