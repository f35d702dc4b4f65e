//! The user's actions, as data (serialised in project files).

use serde::{Deserialize, Serialize};

use crate::graph::pipeline::SegmentLabel;
use crate::scene::ImageId;

/// A position clicked in a view: image id and pixel (COLMAP convention).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PixelRef {
    pub image_id: ImageId,
    pub pixel: [f64; 2],
}

/// An edit. Clicks pick the point projecting nearest to the pixel (among points seen in that
/// view) and act on its segment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "snake_case")]
pub enum Command {
    /// Accept the segment under the click and compute its image boundary (seed 004 §5.2).
    ConfirmSegment { at: PixelRef },
    /// Split the segment the stroke crosses: points projecting on either side are seeded,
    /// edges crossing the stroke are cut, and the segment is re-solved as a two-label graph
    /// cut (seed 004 §5.3). A closed stroke separates inside from outside.
    SplitByStroke {
        image_id: ImageId,
        stroke: Vec<[f64; 2]>,
        #[serde(default)]
        closed: bool,
    },
    /// Connect two clicked points and merge their segments.
    MergeByClick { first: PixelRef, second: PixelRef },
    /// The segment under the click is not a leaf (stem, pot or other).
    MarkNonLeaf {
        at: PixelRef,
        #[serde(default = "default_non_leaf")]
        label: SegmentLabel,
    },
    /// The segment under the click is a leaf.
    MarkLeaf { at: PixelRef },
    /// Return the segment's points to their automatic segments and labels.
    ResetSegment { at: PixelRef },
}

fn default_non_leaf() -> SegmentLabel {
    SegmentLabel::Other
}

impl Command {
    /// A short description for history lists.
    pub fn describe(&self) -> String {
        match self {
            Command::ConfirmSegment { at } => format!("confirm segment (view {})", at.image_id),
            Command::SplitByStroke {
                image_id,
                stroke,
                closed,
            } => format!(
                "split by {} stroke of {} points (view {image_id})",
                if *closed { "closed" } else { "open" },
                stroke.len()
            ),
            Command::MergeByClick { first, .. } => {
                format!("merge two segments (view {})", first.image_id)
            }
            Command::MarkNonLeaf { label, .. } => format!("mark as {label:?}").to_lowercase(),
            Command::MarkLeaf { .. } => "mark as leaf".into(),
            Command::ResetSegment { .. } => "reset segment".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_trip_through_json() {
        let commands = vec![
            Command::SplitByStroke {
                image_id: 3,
                stroke: vec![[1.0, 2.0], [3.5, 4.0]],
                closed: false,
            },
            Command::MarkNonLeaf {
                at: PixelRef {
                    image_id: 1,
                    pixel: [10.0, 20.0],
                },
                label: SegmentLabel::Stem,
            },
        ];
        let text = serde_json::to_string(&commands).unwrap();
        assert!(text.contains("\"command\":\"split_by_stroke\""), "{text}");
        let back: Vec<Command> = serde_json::from_str(&text).unwrap();
        assert_eq!(back, commands);
    }
}
