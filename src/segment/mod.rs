//! Segmentation of the plant's points into leaves (seed 004 §5).
//!
//! - [`automatic`]: the automatic segmentation (§5.1): foreground → kNN graph with joint
//!   3D/2D weights ([`crate::graph`]) → threshold partition → recursive normalized cut →
//!   leaf / stem / pot / other segments. Takes a [`crate::scene::Scene`]; returns a
//!   [`Segmentation`] (points, foreground, segments, the graph the edits re-cut).
//! - [`borders`]: leaf rims the stem test took, given back to their leaves.
//! - [`foreground`]: plant / pot / floor / background separation and the plant's up axis.
//! - [`labels`]: the current labels (segment per point, state per segment) as plain data; the
//!   editing session changes them, later stages read them.
//! - [`views`]: per-view projections and superpixels, cached; a segment's boundary in a view.
//! - [`colour`]: the plant's leaf and stem colours, measured on it; a segment's colour as
//!   evidence of what it is.
//! - [`pieces`]: small leaf segments a gap apart joined as pieces of one leaf.
//! - [`boundary`]: image boundaries (§5.4): watershed superpixels and a two-label graph cut.

pub mod automatic;
pub mod borders;
pub mod boundary;
pub mod colour;
pub mod foreground;
pub mod labels;
pub mod photometric;
pub mod pieces;
pub mod pot;
pub mod views;

pub use automatic::{
    Segment, SegmentError, SegmentLabel, SegmentOptions, SegmentTimings, Segmentation,
    segment_scene,
};
pub use labels::{Labels, SegmentState};
pub use views::{Projected, ViewCache};
