//! The current labels of a plant's points: which segment each point is in and what each
//! segment is. The automatic segmentation gives the first labels ([`Labels::automatic`]); the
//! editing session changes them by commands; every later stage (boundaries, leaves, skeleton,
//! exports) reads them as plain data.

use serde::{Deserialize, Serialize};

use super::automatic::{SegmentLabel, Segmentation};

/// The state of a segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SegmentState {
    pub label: SegmentLabel,
    /// The user confirmed it (seed 004 §5.2).
    pub confirmed: bool,
}

/// Segment id per point and state per segment id.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Labels {
    /// Segment id per point (−1 = in no segment).
    pub segment_of: Vec<i32>,
    /// State per segment id (`None` for ids whose points were merged away).
    pub segments: Vec<Option<SegmentState>>,
}

impl Labels {
    /// The automatic segmentation's labels, nothing confirmed.
    pub fn automatic(segmentation: &Segmentation) -> Self {
        Self {
            segment_of: segmentation
                .point_segment
                .iter()
                .map(|s| s.map_or(-1, |s| s as i32))
                .collect(),
            segments: segmentation
                .segments
                .iter()
                .map(|s| {
                    Some(SegmentState {
                        label: s.label,
                        confirmed: false,
                    })
                })
                .collect(),
        }
    }

    /// The state of a segment id (`None` when it does not exist or was merged away).
    pub fn state(&self, segment: u32) -> Option<SegmentState> {
        self.segments.get(segment as usize).copied().flatten()
    }

    /// The label of a point's segment (`None` when the point is in no live segment).
    pub fn label_of_point(&self, point: usize) -> Option<SegmentLabel> {
        let segment = *self.segment_of.get(point)?;
        if segment < 0 {
            return None;
        }
        self.state(segment as u32).map(|s| s.label)
    }

    /// Points of a segment, in increasing order.
    pub fn members(&self, segment: u32) -> Vec<u32> {
        (0..self.segment_of.len() as u32)
            .filter(|&p| self.segment_of[p as usize] == segment as i32)
            .collect()
    }

    /// Points per segment id (0 for merged-away ids).
    pub fn sizes(&self) -> Vec<usize> {
        let mut sizes = vec![0usize; self.segments.len()];
        for &s in &self.segment_of {
            if s >= 0
                && let Some(size) = sizes.get_mut(s as usize)
            {
                *size += 1;
            }
        }
        sizes
    }

    /// Live leaf segments with at least one point, in id order.
    pub fn leaf_segments(&self) -> Vec<u32> {
        let sizes = self.sizes();
        self.segments
            .iter()
            .enumerate()
            .filter(|(id, s)| s.is_some_and(|s| s.label == SegmentLabel::Leaf) && sizes[*id] > 0)
            .map(|(id, _)| id as u32)
            .collect()
    }

    /// `leaf_id` per point: the segment id of leaf segments, −1 otherwise (the column of
    /// `segmentation.ply`, and the `NNN` of the glb's `leaf_NNN` nodes).
    pub fn leaf_ids(&self) -> Vec<i64> {
        (0..self.segment_of.len())
            .map(|p| match self.label_of_point(p) {
                Some(SegmentLabel::Leaf) => self.segment_of[p] as i64,
                _ => -1,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels() -> Labels {
        let leaf = Some(SegmentState {
            label: SegmentLabel::Leaf,
            confirmed: false,
        });
        let stem = Some(SegmentState {
            label: SegmentLabel::Stem,
            confirmed: true,
        });
        Labels {
            segment_of: vec![0, 1, -1, 0, 3, 2],
            segments: vec![leaf, stem, None, leaf],
        }
    }

    #[test]
    fn leaf_ids_name_live_leaf_segments_only() {
        // Point 5 names merged-away segment 2: no label, so not a leaf.
        assert_eq!(labels().leaf_ids(), vec![0, -1, -1, 0, 3, -1]);
    }

    #[test]
    fn members_sizes_and_leaf_segments_agree() {
        let labels = labels();
        assert_eq!(labels.members(0), vec![0, 3]);
        assert_eq!(labels.sizes(), vec![2, 1, 1, 1]);
        assert_eq!(labels.leaf_segments(), vec![0, 3]);
        assert_eq!(labels.label_of_point(1), Some(SegmentLabel::Stem));
        assert_eq!(labels.label_of_point(2), None);
    }
}
