//! Compound-leaf scores: are the leaflets found on the right rachis? A predicted compound
//! leaf's rachis lies on a true rachis when at least half of its centreline (from where the
//! rachis starts) passes within that rachis's tolerance (2 mean radii, at least 3 mm, as the
//! skeleton scores use). A true leaflet is on the right rachis when the segment matched to it
//! is a leaflet of a predicted compound leaf whose rachis lies on the leaflet's true rachis.
//!
//! Takes the truth's leaflets and branches, the leaf matches, and the prediction's compound
//! leaves and skeleton; returns [`CompoundScores`].

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::Point3;
use serde::Serialize;

use super::geometry::distance_to_polylines;
use super::metrics::LeafMatch;
use crate::branch::compound::CompoundLeaf;
use crate::branch::plant::SkeletonRecord;

/// Share of a predicted rachis that must lie on a true one.
const MIN_ON_RACHIS: f64 = 0.5;

/// How compound leaves were recovered.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CompoundScores {
    pub true_compound_leaves: usize,
    pub predicted_compound_leaves: usize,
    /// Predicted rachises lying on a true rachis.
    pub predicted_on_a_true_rachis: usize,
    /// True rachises some predicted rachis lies on.
    pub true_rachises_found: usize,
    /// True leaflets matched to a predicted segment.
    pub leaflets_matched: usize,
    /// Of those, leaflets of a predicted compound leaf whose rachis lies on their true rachis.
    pub leaflets_on_right_rachis: usize,
    /// `leaflets_on_right_rachis / leaflets_matched`.
    pub right_rachis_share: f64,
}

/// The centreline of a predicted rachis from where it starts.
fn rachis_line(compound: &CompoundLeaf, skeleton: &[SkeletonRecord]) -> Vec<Point3<f64>> {
    let Some(branch) = skeleton.iter().find(|b| b.id == compound.rachis) else {
        return Vec::new();
    };
    let n = branch.centerline.len();
    branch
        .centerline
        .iter()
        .enumerate()
        .filter(|(i, _)| n < 2 || *i as f64 / (n - 1) as f64 >= compound.rachis_from)
        .map(|(_, c)| Point3::from(*c))
        .collect()
}

/// Scores compound leaves. `leaflet_rachis` maps each true leaflet (GT leaf id) to its true
/// rachis (GT branch id); `truth` is the true skeleton.
pub fn score_compound(
    leaflet_rachis: &BTreeMap<i64, u32>,
    truth: &[SkeletonRecord],
    matches: &[LeafMatch],
    predicted: &[CompoundLeaf],
    skeleton: &[SkeletonRecord],
) -> CompoundScores {
    let true_rachises: BTreeSet<u32> = leaflet_rachis.values().copied().collect();
    // The true rachis each predicted compound leaf lies on.
    let on_rachis: Vec<Option<u32>> = predicted
        .iter()
        .map(|compound| {
            let line = rachis_line(compound, skeleton);
            if line.is_empty() {
                return None;
            }
            true_rachises
                .iter()
                .filter_map(|&id| {
                    let branch = truth.iter().find(|b| b.id == id)?;
                    let tolerance = (2.0 * branch.mean_radius()).max(0.003);
                    let centreline =
                        vec![branch.centerline.iter().map(|c| Point3::from(*c)).collect()];
                    let close = line
                        .iter()
                        .filter(|p| distance_to_polylines(p, &centreline) <= tolerance)
                        .count();
                    Some((close as f64 / line.len() as f64, id))
                })
                .filter(|(share, _)| *share >= MIN_ON_RACHIS)
                .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
                .map(|(_, id)| id)
        })
        .collect();
    let compound_of_segment: BTreeMap<i64, usize> = predicted
        .iter()
        .enumerate()
        .flat_map(|(k, c)| c.leaflets.iter().map(move |&l| (l as i64, k)))
        .collect();
    let mut matched = 0;
    let mut right = 0;
    for m in matches {
        let Some(&rachis) = leaflet_rachis.get(&m.gt_leaf) else {
            continue;
        };
        matched += 1;
        let placed = compound_of_segment
            .get(&m.segment)
            .and_then(|&k| on_rachis[k]);
        right += usize::from(placed == Some(rachis));
    }
    CompoundScores {
        true_compound_leaves: true_rachises.len(),
        predicted_compound_leaves: predicted.len(),
        predicted_on_a_true_rachis: on_rachis.iter().filter(|r| r.is_some()).count(),
        true_rachises_found: on_rachis.iter().flatten().collect::<BTreeSet<_>>().len(),
        leaflets_matched: matched,
        leaflets_on_right_rachis: right,
        right_rachis_share: if matched == 0 {
            0.0
        } else {
            right as f64 / matched as f64
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::branch::compound::Arrangement;

    fn line(id: u32, from: [f64; 3], to: [f64; 3]) -> SkeletonRecord {
        let centerline = (0..=20)
            .map(|k| {
                let t = k as f64 / 20.0;
                [0, 1, 2].map(|i| from[i] + (to[i] - from[i]) * t)
            })
            .collect();
        SkeletonRecord {
            id,
            parent: None,
            parent_fraction: 0.0,
            control_points: vec![from, to],
            radius_start: 0.002,
            radius_end: 0.001,
            length: 0.2,
            centerline,
            observed_length: None,
            bridged_length: None,
        }
    }

    fn compound(rachis: u32, rachis_from: f64, leaflets: Vec<u32>) -> CompoundLeaf {
        CompoundLeaf {
            id: 0,
            rachis,
            rachis_from,
            petiolules: Vec::new(),
            leaflets,
            arrangement: Arrangement {
                leaves: 0,
                paired: 1.0,
                left: 0,
                right: 0,
                out_of_plane: 0.0,
            },
        }
    }

    #[test]
    fn leaflets_count_on_the_rachis_their_compound_leaf_lies_on() {
        // Two true rachises; the prediction draws the first as the end of a stem that runs
        // along the second's direction first.
        let truth = vec![
            line(1, [0.0, 0.0, 0.1], [0.2, 0.0, 0.1]),
            line(2, [0.0, 0.0, 0.1], [0.0, 0.2, 0.1]),
        ];
        let leaflet_rachis: BTreeMap<i64, u32> =
            [(10, 1), (11, 1), (12, 2), (13, 2)].into_iter().collect();
        let matches: Vec<LeafMatch> = [(10, 0), (11, 1), (12, 2), (13, 3)]
            .into_iter()
            .map(|(gt_leaf, segment)| LeafMatch {
                gt_leaf,
                segment,
                iou: 0.9,
            })
            .collect();
        let skeleton = vec![
            // A stem from below that continues along rachis 1 from half its length.
            line(0, [-0.2, 0.0, 0.1], [0.2, 0.0, 0.1]),
            line(5, [0.0, 0.0, 0.1], [0.0, 0.2, 0.1]),
        ];
        let predicted = vec![compound(0, 0.5, vec![0, 1]), compound(5, 0.0, vec![2])];
        let scores = score_compound(&leaflet_rachis, &truth, &matches, &predicted, &skeleton);
        assert_eq!(scores.true_compound_leaves, 2);
        assert_eq!(scores.predicted_on_a_true_rachis, 2);
        assert_eq!(scores.true_rachises_found, 2);
        assert_eq!(scores.leaflets_matched, 4);
        // Segment 3 is in no compound leaf.
        assert_eq!(scores.leaflets_on_right_rachis, 3);
        assert!((scores.right_rachis_share - 0.75).abs() < 1e-12);
        // The whole stem as the rachis lies half off rachis 1: still on it (≥ 50 %), but a
        // rachis swapped onto the other true rachis is wrong for its leaflets.
        let swapped = vec![compound(5, 0.0, vec![0, 1]), compound(0, 0.5, vec![2, 3])];
        let scores = score_compound(&leaflet_rachis, &truth, &matches, &swapped, &skeleton);
        assert_eq!(scores.leaflets_on_right_rachis, 0);
    }
}
