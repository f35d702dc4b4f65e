//! Synthetic plants with exact ground truth: the round-trip test bed every stage is measured
//! on. A procedural plant (seed 004 §8's plant types as presets) is rendered from the views a
//! user would take, turned into the COLMAP project a user would have, and stored with the truth
//! (per-point leaf ids and parts, leaf meshes, branch skeletons, per-view leaf masks).
//!
//! Takes a preset, a seed and capture options; returns a plant with its truth and writes the
//! dataset folder.

pub mod dataset;
pub mod leaf;
pub mod plant;
pub mod scene;
pub mod texture;

pub use dataset::{SynthError, SynthOptions, SynthSummary, write_dataset};
pub use plant::{Preset, SynthPlant, generate_plant};
pub use scene::{Backdrop, Part};

use crate::model::{ModelLeaf, PlantModel};
use crate::util::rng::Rng;

/// A synthetic plant as an exportable model (its leaves with textures of `texture_size`²
/// texels, its branches meshed as exported branches are); the pot is left out. Deterministic
/// in the plant's seed.
pub fn plant_model(plant: &SynthPlant, texture_size: u32) -> PlantModel {
    PlantModel {
        leaves: plant
            .leaves
            .iter()
            .map(|leaf| ModelLeaf {
                id: leaf.id,
                mesh: leaf.mesh.clone(),
                texture: texture::leaf_texture(
                    &leaf.look,
                    texture_size,
                    &mut Rng::stream(plant.seed, leaf.id as u64),
                ),
            })
            .collect(),
        branches: crate::branch::plant::model_branches(&plant.branches),
        compound_leaves: compound_groups(plant),
        up: Some([0.0, 0.0, 1.0]),
    }
}

/// The true compound leaves, numbered in rachis order.
fn compound_groups(plant: &SynthPlant) -> Vec<crate::model::CompoundGroup> {
    let mut groups: Vec<crate::model::CompoundGroup> = Vec::new();
    for leaf in &plant.leaves {
        let Some(rachis) = leaf.compound_leaf else {
            continue;
        };
        match groups.iter_mut().find(|g| g.rachis == rachis) {
            Some(group) => group.leaflets.push(leaf.id),
            None => groups.push(crate::model::CompoundGroup {
                id: groups.len() as u32,
                rachis,
                leaflets: vec![leaf.id],
                branches: vec![rachis],
            }),
        }
    }
    groups
}
