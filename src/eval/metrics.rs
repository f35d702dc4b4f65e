//! Segmentation metrics on labelled points: adjusted Rand index, one-to-one leaf matching by
//! point IoU, over- and under-segmentation.

use std::collections::{BTreeMap, HashMap};

use serde::Serialize;

/// Adjusted Rand index (Hubert & Arabie 1985) of two labellings of the same items.
/// 1 for identical partitions, ≈ 0 for independent ones. Defined as 1 when both labellings put
/// everything in one cluster (or there are fewer than two items).
pub fn adjusted_rand_index(a: &[i64], b: &[i64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return 1.0;
    }
    let pairs = |k: u64| (k * k.saturating_sub(1) / 2) as f64;
    let mut cells: HashMap<(i64, i64), u64> = HashMap::new();
    let mut rows: HashMap<i64, u64> = HashMap::new();
    let mut cols: HashMap<i64, u64> = HashMap::new();
    for i in 0..n {
        *cells.entry((a[i], b[i])).or_insert(0) += 1;
        *rows.entry(a[i]).or_insert(0) += 1;
        *cols.entry(b[i]).or_insert(0) += 1;
    }
    let index: f64 = cells.values().map(|&c| pairs(c)).sum();
    let sum_rows: f64 = rows.values().map(|&c| pairs(c)).sum();
    let sum_cols: f64 = cols.values().map(|&c| pairs(c)).sum();
    let expected = sum_rows * sum_cols / pairs(n as u64);
    let maximum = 0.5 * (sum_rows + sum_cols);
    if (maximum - expected).abs() < 1e-12 {
        return 1.0;
    }
    (index - expected) / (maximum - expected)
}

/// Parameters of leaf matching.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MatchingOptions {
    /// A GT leaf is recovered by a segment overlapping it with point IoU ≥ this.
    pub iou_threshold: f64,
    /// GT leaves (and predicted segments) with fewer points are not scored.
    pub min_leaf_points: usize,
    /// A segment "holds part of" a leaf when it has at least this fraction of the leaf's
    /// (or the segment's) points and at least `min_fragment_points`.
    pub fragment_fraction: f64,
    pub min_fragment_points: usize,
}

impl Default for MatchingOptions {
    fn default() -> Self {
        Self {
            iou_threshold: 0.5,
            min_leaf_points: 20,
            fragment_fraction: 0.1,
            min_fragment_points: 5,
        }
    }
}

/// A recovered leaf: GT leaf, predicted segment and their IoU.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LeafMatch {
    pub gt_leaf: i64,
    pub segment: i64,
    pub iou: f64,
}

/// Leaf-level segmentation scores.
#[derive(Clone, Debug, Serialize)]
pub struct LeafScores {
    /// GT leaves with at least `min_leaf_points` points.
    pub gt_leaves: usize,
    /// Predicted leaf segments with at least `min_leaf_points` points.
    pub predicted_segments: usize,
    pub matched: usize,
    pub recall: f64,
    pub precision: f64,
    /// GT leaves split over two or more segments that each hold a fragment of them.
    pub over_segmented: usize,
    /// Segments holding fragments of two or more GT leaves.
    pub under_segmented: usize,
    pub matches: Vec<LeafMatch>,
}

/// Scores predicted leaf segments against GT leaves. Labels are per point; negative labels
/// mean "not a leaf" on either side.
pub fn score_leaves(gt: &[i64], predicted: &[i64], options: &MatchingOptions) -> LeafScores {
    let n = gt.len().min(predicted.len());
    let mut gt_size: BTreeMap<i64, usize> = BTreeMap::new();
    let mut pred_size: BTreeMap<i64, usize> = BTreeMap::new();
    let mut overlap: HashMap<(i64, i64), usize> = HashMap::new();
    for i in 0..n {
        if gt[i] >= 0 {
            *gt_size.entry(gt[i]).or_insert(0) += 1;
        }
        if predicted[i] >= 0 {
            *pred_size.entry(predicted[i]).or_insert(0) += 1;
        }
        if gt[i] >= 0 && predicted[i] >= 0 {
            *overlap.entry((gt[i], predicted[i])).or_insert(0) += 1;
        }
    }
    let eligible_gt: Vec<i64> = gt_size
        .iter()
        .filter(|(_, s)| **s >= options.min_leaf_points)
        .map(|(l, _)| *l)
        .collect();
    let eligible_pred = pred_size
        .values()
        .filter(|s| **s >= options.min_leaf_points)
        .count();

    // Candidate pairs by IoU, best first; greedy one-to-one assignment.
    let mut candidates: Vec<LeafMatch> = overlap
        .iter()
        .filter(|((g, _), _)| gt_size[g] >= options.min_leaf_points)
        .map(|(&(g, p), &count)| LeafMatch {
            gt_leaf: g,
            segment: p,
            iou: count as f64 / (gt_size[&g] + pred_size[&p] - count) as f64,
        })
        .filter(|m| m.iou >= options.iou_threshold)
        .collect();
    candidates.sort_by(|a, b| {
        b.iou
            .total_cmp(&a.iou)
            .then(a.gt_leaf.cmp(&b.gt_leaf))
            .then(a.segment.cmp(&b.segment))
    });
    let mut used_gt = std::collections::HashSet::new();
    let mut used_pred = std::collections::HashSet::new();
    let mut matches = Vec::new();
    for m in candidates {
        if used_gt.contains(&m.gt_leaf) || used_pred.contains(&m.segment) {
            continue;
        }
        used_gt.insert(m.gt_leaf);
        used_pred.insert(m.segment);
        matches.push(m);
    }
    matches.sort_by_key(|m| m.gt_leaf);

    let is_fragment = |count: usize, whole: usize| {
        count >= options.min_fragment_points
            && count as f64 >= options.fragment_fraction * whole as f64
    };
    let mut fragments_of_gt: HashMap<i64, usize> = HashMap::new();
    let mut fragments_in_pred: HashMap<i64, usize> = HashMap::new();
    for (&(g, p), &count) in &overlap {
        if gt_size[&g] >= options.min_leaf_points && is_fragment(count, gt_size[&g]) {
            *fragments_of_gt.entry(g).or_insert(0) += 1;
        }
        if gt_size[&g] >= options.min_leaf_points && is_fragment(count, pred_size[&p]) {
            *fragments_in_pred.entry(p).or_insert(0) += 1;
        }
    }
    let over_segmented = fragments_of_gt.values().filter(|&&k| k >= 2).count();
    let under_segmented = fragments_in_pred.values().filter(|&&k| k >= 2).count();
    let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    LeafScores {
        gt_leaves: eligible_gt.len(),
        predicted_segments: eligible_pred,
        matched: matches.len(),
        recall: ratio(matches.len(), eligible_gt.len()),
        precision: ratio(matches.len(), eligible_pred),
        over_segmented,
        under_segmented,
        matches,
    }
}

/// What a predicted leaf segment that matched no true leaf holds (its points' majority).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FalseLeafCause {
    /// Mostly one true leaf that another segment matched: that leaf is over-segmented.
    LeafFragment,
    /// Mostly one true leaf that nothing matched: the segment covers too little of it.
    PartialLeaf,
    /// Mostly leaves, but several of them: touching leaves in one segment.
    MergedLeaves,
    /// Mostly stem, twig or petiole surface.
    Stem,
    /// Mostly the pot.
    Pot,
    /// Mostly the floor or soil.
    Floor,
    /// Mostly on no true surface (the stereo halo, outliers, the backdrop).
    OffSurface,
}

/// The unmatched predicted leaf segments by what they hold.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FalseLeaves {
    /// Count per cause.
    pub counts: BTreeMap<String, usize>,
    /// `(segment, cause)` for each unmatched segment with enough points, by segment.
    pub segments: Vec<(i64, FalseLeafCause)>,
}

/// Why each predicted leaf segment (with at least `min_leaf_points`) that `scores` did not
/// match is not a leaf: `gt_leaf` and `gt_part` are the truth per predicted point (leaf id,
/// −1 off leaves; [`crate::synth::scene::Part`]), `predicted` the predicted leaf id per point.
pub fn false_leaves(
    gt_leaf: &[i64],
    gt_part: &[crate::synth::scene::Part],
    predicted: &[i64],
    scores: &LeafScores,
    options: &MatchingOptions,
) -> FalseLeaves {
    use crate::synth::scene::Part;
    let matched_segments: std::collections::HashSet<i64> =
        scores.matches.iter().map(|m| m.segment).collect();
    let matched_leaves: std::collections::HashSet<i64> =
        scores.matches.iter().map(|m| m.gt_leaf).collect();
    // Per unmatched segment: points per true leaf, and per non-leaf part.
    let mut on_leaves: BTreeMap<i64, BTreeMap<i64, usize>> = BTreeMap::new();
    let mut on_parts: BTreeMap<i64, [usize; 5]> = BTreeMap::new();
    let n = gt_leaf.len().min(gt_part.len()).min(predicted.len());
    for i in 0..n {
        let s = predicted[i];
        if s < 0 || matched_segments.contains(&s) {
            continue;
        }
        if gt_leaf[i] >= 0 && gt_part[i] == Part::Leaf {
            *on_leaves
                .entry(s)
                .or_default()
                .entry(gt_leaf[i])
                .or_insert(0) += 1;
        } else {
            on_parts.entry(s).or_insert([0; 5])[gt_part[i] as usize] += 1;
        }
    }
    let mut segments: Vec<i64> = on_leaves.keys().chain(on_parts.keys()).copied().collect();
    segments.sort_unstable();
    segments.dedup();
    let mut out = FalseLeaves::default();
    for s in segments {
        let leaves = on_leaves.get(&s);
        let parts = on_parts.get(&s).copied().unwrap_or([0; 5]);
        let leaf_points: usize = leaves.map_or(0, |l| l.values().sum());
        let other_points: usize = parts.iter().sum();
        let total = leaf_points + other_points;
        if total < options.min_leaf_points {
            continue;
        }
        let cause = if leaf_points >= other_points {
            let (leaf, largest) = leaves
                .and_then(|l| l.iter().max_by_key(|&(id, c)| (*c, -*id)))
                .map_or((-1, 0), |(id, c)| (*id, *c));
            if 2 * largest < leaf_points {
                FalseLeafCause::MergedLeaves
            } else if matched_leaves.contains(&leaf) {
                FalseLeafCause::LeafFragment
            } else {
                FalseLeafCause::PartialLeaf
            }
        } else {
            let part = (0..5)
                .max_by_key(|&k| (parts[k], std::cmp::Reverse(k)))
                .unwrap_or(4);
            match part {
                k if k == Part::Stem as usize => FalseLeafCause::Stem,
                k if k == Part::Pot as usize => FalseLeafCause::Pot,
                k if k == Part::Floor as usize => FalseLeafCause::Floor,
                // Points paired with a leaf sample but no leaf id, or background.
                _ => FalseLeafCause::OffSurface,
            }
        };
        let name = serde_json::to_value(cause)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        *out.counts.entry(name).or_insert(0) += 1;
        out.segments.push((s, cause));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(sizes: &[(i64, usize)]) -> Vec<i64> {
        sizes
            .iter()
            .flat_map(|&(label, n)| std::iter::repeat_n(label, n))
            .collect()
    }

    #[test]
    fn ari_of_identical_and_relabelled_partitions_is_one() {
        let a = labels(&[(0, 10), (1, 20), (2, 5)]);
        let b = labels(&[(7, 10), (3, 20), (-1, 5)]);
        assert!((adjusted_rand_index(&a, &a) - 1.0).abs() < 1e-12);
        assert!((adjusted_rand_index(&a, &b) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ari_matches_a_hand_computed_value() {
        // a = {0,0,1,1}, b = {0,1,1,1}: cells (0,0)=1,(0,1)=1,(1,1)=2 → index 1;
        // rows 1+1 = 2, cols 0+3 = 3, pairs(4) = 6 → expected 1, max 2.5 → ARI 0.
        let a = [0, 0, 1, 1];
        let b = [0, 1, 1, 1];
        assert!(adjusted_rand_index(&a, &b).abs() < 1e-12);
        // Random labels of many items score near 0.
        let mut rng = crate::util::rng::Rng::seed_from(2);
        let x: Vec<i64> = (0..5000).map(|_| rng.below(5) as i64).collect();
        let y: Vec<i64> = (0..5000).map(|_| rng.below(5) as i64).collect();
        assert!(adjusted_rand_index(&x, &y).abs() < 0.01);
    }

    #[test]
    fn perfect_prediction_recovers_every_leaf() {
        let gt = labels(&[(0, 50), (1, 40), (2, 30), (-1, 100), (3, 10)]);
        let scores = score_leaves(&gt, &gt, &MatchingOptions::default());
        assert_eq!(scores.gt_leaves, 3, "leaf 3 has too few points to score");
        assert_eq!(scores.matched, 3);
        assert_eq!(scores.recall, 1.0);
        assert_eq!(scores.precision, 1.0);
        assert_eq!(scores.over_segmented, 0);
        assert_eq!(scores.under_segmented, 0);
    }

    #[test]
    fn merging_two_leaves_loses_the_smaller_one() {
        let gt = labels(&[(0, 50), (1, 40), (2, 30)]);
        let merged = labels(&[(0, 50), (0, 40), (2, 30)]);
        let scores = score_leaves(&gt, &merged, &MatchingOptions::default());
        assert_eq!(scores.matched, 2);
        assert!((scores.recall - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(scores.precision, 1.0);
        assert_eq!(scores.under_segmented, 1);
        assert_eq!(scores.over_segmented, 0);
    }

    #[test]
    fn splitting_a_leaf_in_thirds_loses_it_and_counts_an_over_segmentation() {
        let gt = labels(&[(0, 60), (1, 40)]);
        let split = labels(&[(10, 20), (11, 20), (12, 20), (1, 40)]);
        let scores = score_leaves(&gt, &split, &MatchingOptions::default());
        assert_eq!(scores.matched, 1);
        assert_eq!(scores.recall, 0.5);
        assert_eq!(scores.predicted_segments, 4);
        assert_eq!(scores.precision, 0.25);
        assert_eq!(scores.over_segmented, 1);
        // A 2:1 split keeps the leaf (IoU 2/3) but still counts as over-segmented.
        let split = labels(&[(10, 40), (11, 20), (1, 40)]);
        let scores = score_leaves(&gt, &split, &MatchingOptions::default());
        assert_eq!(scores.recall, 1.0);
        assert!((scores.precision - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(scores.over_segmented, 1);
    }

    #[test]
    fn unmatched_segments_are_told_apart_by_what_they_hold() {
        use crate::synth::scene::Part;
        let (mut gt, mut part, mut predicted) = (Vec::new(), Vec::new(), Vec::new());
        let mut add = |leaf: i64, kind: Part, segment: i64, count: usize| {
            for _ in 0..count {
                gt.push(leaf);
                part.push(kind);
                predicted.push(segment);
            }
        };
        // Leaf 0 is found by segment 10; segment 11 holds the rest of it.
        add(0, Part::Leaf, 10, 40);
        add(0, Part::Leaf, 11, 20);
        // Segment 12 holds a third of leaf 1, which nothing found.
        add(1, Part::Leaf, 12, 30);
        add(1, Part::Leaf, -1, 70);
        // Segment 13 holds a third of each of leaves 2, 3 and 4.
        for leaf in 2..5 {
            add(leaf, Part::Leaf, 13, 10);
            add(leaf, Part::Leaf, -1, 20);
        }
        // A piece of stem, a piece of halo, and a stem crumb too small to score.
        add(-1, Part::Stem, 14, 25);
        add(-1, Part::Background, 15, 25);
        add(-1, Part::Stem, 16, 10);
        let options = MatchingOptions::default();
        let scores = score_leaves(&gt, &predicted, &options);
        assert_eq!(scores.matched, 1);
        let found = false_leaves(&gt, &part, &predicted, &scores, &options);
        assert_eq!(
            found.segments,
            vec![
                (11, FalseLeafCause::LeafFragment),
                (12, FalseLeafCause::PartialLeaf),
                (13, FalseLeafCause::MergedLeaves),
                (14, FalseLeafCause::Stem),
                (15, FalseLeafCause::OffSurface),
            ]
        );
        assert_eq!(found.counts["leaf_fragment"], 1);
        assert_eq!(found.counts.values().sum::<usize>(), 5);
    }
}
