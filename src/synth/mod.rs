//! Synthetic plants with exact ground truth: the round-trip test bed every stage is measured
//! on. A procedural plant (seed 004 §8's plant types as presets) is rendered from the views a
//! user would take, turned into the COLMAP project a user would have, and stored with the truth
//! (per-point leaf ids and parts, leaf meshes, branch skeletons, per-view leaf masks).

pub mod dataset;
pub mod leaf;
pub mod plant;
pub mod scene;
pub mod texture;

pub use dataset::{SynthError, SynthOptions, SynthSummary, write_dataset};
pub use plant::{Preset, SynthPlant, generate_plant};
pub use scene::Part;
