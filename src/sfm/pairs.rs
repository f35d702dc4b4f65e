//! Which photo pairs to match: the pairs a capture of one plant needs, not all N(N−1)/2.
//!
//! Preemptive matching (Wu, "Towards linear-time incremental structure from motion", 3DV
//! 2013): the few largest-scale features of every photo (the most repeatable across views) are
//! matched between every pair, which costs little, and the number of their matches predicts
//! whether a pair overlaps. Each photo is then matched in full with the photos it shares the
//! most preemptive matches with, and with its neighbours in file-name order (captures are
//! usually walks around the plant). A vocabulary of visual words trained on the capture itself
//! was tried first and missed the loop closures of 30°-spaced rings (every photo shows the
//! same kind of background). Takes every photo's [`Descriptors`] and feature scales (in name
//! order) and [`PairOptions`]; returns the pairs `(i, j)`, `i < j`.

use std::collections::BTreeSet;

use rayon::prelude::*;

use super::matching::{Descriptors, MatchOptions, match_descriptors};

/// How many pairs to choose.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PairOptions {
    /// Photos matched in full with each photo: those with the most preemptive matches.
    pub retrieved: usize,
    /// Neighbours on each side in file-name order matched with each photo.
    pub sequential: usize,
    /// Largest-scale features per photo matched preemptively.
    pub preemptive_features: usize,
    /// Fewer preemptive matches than this: the pair is not retrieved.
    pub min_preemptive_matches: usize,
}

impl Default for PairOptions {
    fn default() -> Self {
        Self {
            retrieved: 12,
            sequential: 2,
            preemptive_features: 512,
            min_preemptive_matches: 4,
        }
    }
}

/// The `count` largest-scale features of a photo (ties and scale-less features: in feature
/// order); all of them when there are fewer, a spread sample when the scales are unknown.
pub fn preemptive_sample(descriptors: &Descriptors, scales: &[f32], count: usize) -> Descriptors {
    if descriptors.len() <= count {
        return descriptors.clone();
    }
    if scales.len() != descriptors.len() {
        return descriptors.spread_sample(count);
    }
    let mut order: Vec<usize> = (0..scales.len()).collect();
    order.sort_by(|&a, &b| scales[b].total_cmp(&scales[a]).then(a.cmp(&b)));
    order.truncate(count);
    order.sort_unstable();
    descriptors.select(&order)
}

/// Preemptive match counts of every pair `(i, j)`, `i < j`, in row-major order of the upper
/// triangle.
pub fn preemptive_scores(samples: &[Descriptors], matching: &MatchOptions) -> Vec<usize> {
    let n = samples.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    pairs
        .par_iter()
        .map(|&(i, j)| match_descriptors(&samples[i], &samples[j], matching).len())
        .collect()
}

/// The pairs to match (see the module docs), sorted. `samples` are the photos' preemptive
/// features ([`preemptive_sample`]).
pub fn select_pairs(
    samples: &[Descriptors],
    options: &PairOptions,
    matching: &MatchOptions,
) -> Vec<(usize, usize)> {
    choose_pairs(samples, options, matching, false)
}

/// [`select_pairs`] plus, for every photo, up to [`PairOptions::retrieved`] photos that are
/// its relative neighbours: candidates are taken most similar first, and one is passed over
/// when a photo already taken is more similar to it than this photo is (it is reached
/// through that one). In a dense capture the most similar photos are all one's neighbours
/// along the same walk, so plain retrieval never reaches a second ring of photos taken from
/// another height (measured on a 200-photo orbit: 3 of 1,229 verified pairs joined the two
/// rings, all by file-name order); the relative neighbours step past the walk.
pub fn select_pairs_diverse(
    samples: &[Descriptors],
    options: &PairOptions,
    matching: &MatchOptions,
) -> Vec<(usize, usize)> {
    choose_pairs(samples, options, matching, true)
}

fn choose_pairs(
    samples: &[Descriptors],
    options: &PairOptions,
    matching: &MatchOptions,
    diverse: bool,
) -> Vec<(usize, usize)> {
    let n = samples.len();
    let mut pairs = BTreeSet::new();
    if n <= options.retrieved + 2 * options.sequential + 1 {
        // Every photo would be matched with nearly every other anyway.
        for i in 0..n {
            for j in i + 1..n {
                pairs.insert((i, j));
            }
        }
        return pairs.into_iter().collect();
    }
    for i in 0..n {
        for d in 1..=options.sequential {
            if i + d < n {
                pairs.insert((i, i + d));
            }
        }
    }
    let scores = preemptive_scores(samples, matching);
    let mut score = vec![vec![0usize; n]; n];
    let upper = (0..n).flat_map(|i| (i + 1..n).map(move |j| (i, j)));
    for ((i, j), &s) in upper.zip(&scores) {
        score[i][j] = s;
        score[j][i] = s;
    }
    for (i, row) in score.iter().enumerate() {
        let mut ranked: Vec<(usize, usize)> = row
            .iter()
            .enumerate()
            .filter(|&(j, &s)| j != i && s >= options.min_preemptive_matches)
            .map(|(j, &s)| (s, j))
            .collect();
        ranked.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(_, j) in ranked.iter().take(options.retrieved) {
            pairs.insert((i.min(j), i.max(j)));
        }
        if diverse {
            let mut taken: Vec<usize> = Vec::new();
            for &(s, j) in &ranked {
                if taken.len() >= options.retrieved {
                    break;
                }
                if taken.iter().all(|&t| score[t][j] <= s) {
                    taken.push(j);
                    pairs.insert((i.min(j), i.max(j)));
                }
            }
        }
    }
    pairs.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sfm::matching::DESCRIPTOR_DIM;
    use crate::util::rng::Rng;

    /// Photos of a "scene" of distinct local patterns seen along a path: photo k sees the
    /// patterns in [3k, 3k + 30), so photos overlap when they are near in the walk. The files
    /// are named out of walk order (a shuffle), so only the retrieval can find the neighbours.
    fn walk(photos: usize, seed: u64) -> (Vec<Descriptors>, Vec<usize>) {
        let mut rng = Rng::seed_from(seed);
        let patterns: Vec<[f32; DESCRIPTOR_DIM]> = (0..3 * photos + 30)
            .map(|_| std::array::from_fn(|_| rng.uniform().powi(4) as f32))
            .collect();
        let mut position: Vec<usize> = (0..photos).collect();
        rng.shuffle(&mut position);
        let mut descriptors = Vec::new();
        for &k in &position {
            let mut rows: Vec<[f32; DESCRIPTOR_DIM]> = Vec::new();
            for pattern in &patterns[3 * k..3 * k + 30] {
                let mut row = *pattern;
                row.iter_mut()
                    .for_each(|v| *v = (*v + 0.01 * rng.normal() as f32).max(0.0));
                rows.push(row);
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
            ..PairOptions::default()
        };
        let matching = MatchOptions::default();
        let pairs = select_pairs(&photos, &options, &matching);
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
        assert_eq!(pairs, select_pairs(&photos, &options, &matching));
    }

    /// Two rings of 20 photos: photo k of a ring sees that ring's patterns [2k, 2k + 30), so
    /// ring neighbours share most of them, and the two photos at position k of the two rings
    /// share 6 patterns of their own (another height, little in common).
    fn two_rings(seed: u64) -> Vec<Descriptors> {
        let mut rng = Rng::seed_from(seed);
        let mut pattern =
            || -> [f32; DESCRIPTOR_DIM] { std::array::from_fn(|_| rng.uniform().powi(4) as f32) };
        let rings: Vec<Vec<[f32; DESCRIPTOR_DIM]>> = (0..2)
            .map(|_| (0..70).map(|_| pattern()).collect())
            .collect();
        let shared: Vec<[f32; DESCRIPTOR_DIM]> = (0..120).map(|_| pattern()).collect();
        let mut photos = Vec::new();
        for ring in &rings {
            for k in 0..20 {
                let mut rows: Vec<[f32; DESCRIPTOR_DIM]> = ring[2 * k..2 * k + 30].to_vec();
                rows.extend_from_slice(&shared[6 * k..6 * k + 6]);
                photos.push(Descriptors::from_rows(&rows));
            }
        }
        photos
    }

    #[test]
    fn relative_neighbours_reach_the_other_ring_where_the_most_similar_do_not() {
        let photos = two_rings(7);
        let options = PairOptions {
            sequential: 0,
            retrieved: 4,
            ..PairOptions::default()
        };
        let matching = MatchOptions::default();
        let across =
            |pairs: &[(usize, usize)]| pairs.iter().filter(|&&(i, j)| (i < 20) != (j < 20)).count();
        let plain = select_pairs(&photos, &options, &matching);
        assert_eq!(across(&plain), 0, "{plain:?}");
        let diverse = select_pairs_diverse(&photos, &options, &matching);
        // Every photo reaches its counterpart in the other ring, and keeps its plain pairs.
        for k in 0..20 {
            assert!(diverse.contains(&(k, k + 20)), "{k}: {diverse:?}");
        }
        assert!(plain.iter().all(|p| diverse.contains(p)));
        assert!(diverse.len() < 40 * 39 / 2 / 4, "{} pairs", diverse.len());
        assert_eq!(diverse, select_pairs_diverse(&photos, &options, &matching));
    }

    #[test]
    fn small_captures_are_matched_exhaustively_and_sequence_neighbours_are_kept() {
        let (photos, _) = walk(6, 2);
        let matching = MatchOptions::default();
        let pairs = select_pairs(&photos, &PairOptions::default(), &matching);
        assert_eq!(pairs.len(), 15);
        let (photos, _) = walk(20, 3);
        let options = PairOptions {
            retrieved: 2,
            sequential: 1,
            ..PairOptions::default()
        };
        let pairs = select_pairs(&photos, &options, &matching);
        for i in 0..19 {
            assert!(pairs.contains(&(i, i + 1)));
        }
        assert!(pairs.iter().all(|&(i, j)| i < j && j < 20));
    }
}

#[cfg(test)]
mod sample_tests {
    use super::*;

    #[test]
    fn the_preemptive_sample_keeps_the_largest_scales_in_feature_order() {
        let rows: Vec<[f32; 128]> = (0..5)
            .map(|k| std::array::from_fn(|d| if d == k { 1.0 } else { 0.0 }))
            .collect();
        let descriptors = Descriptors::from_rows(&rows);
        let sample = preemptive_sample(&descriptors, &[1.0, 5.0, 2.0, 4.0, 3.0], 3);
        assert_eq!(sample.len(), 3);
        assert_eq!(sample.row(0), descriptors.row(1));
        assert_eq!(sample.row(1), descriptors.row(3));
        assert_eq!(sample.row(2), descriptors.row(4));
        assert_eq!(preemptive_sample(&descriptors, &[], 2).len(), 2);
        assert_eq!(preemptive_sample(&descriptors, &[], 9).len(), 5);
    }
}
