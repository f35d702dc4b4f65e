//! Compound leaves: leaflets on a rachis. A pinnately compound leaf (ash, rose, sumac, a fern
//! frond) is reconstructed as its parts: each leaflet is a leaf, the rachis a branch the
//! leaflets hang on. This module says which branches are rachises and which leaves are their
//! leaflets, from how the leaves sit on each branch:
//! - a rachis is a terminal branch (no child branch) that grows from another branch;
//! - it carries at least [`MIN_LEAFLETS`] leaves;
//! - its leaflets stand in *opposite pairs*: most leaflets have a partner on the other side of
//!   the rachis at the same place along it (within a quarter of the median leaflet length).
//!
//! A twig with alternate or spiralled leaves fails the pairing test: its leaves stand one by
//! one along it. The test cannot tell an opposite-leaved twig from a compound leaf (botanists
//! tell them apart by the bud in the leaf's axil, which photos do not show); such twigs are
//! reported as compound leaves.
//!
//! Takes a branch tree and where each leaf sits on it; returns the compound leaves.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::BranchTree;
use crate::util::stats::median;

/// Fewest leaflets that make a compound leaf.
pub const MIN_LEAFLETS: usize = 5;
/// Two leaflets on opposite sides are a pair when their bases lie within this share of the
/// median leaflet length along the rachis.
const PAIR_DISTANCE_PER_LEAFLET_LENGTH: f64 = 0.1;
/// Share of leaflets (the terminal leaflet aside) that must have a partner.
const MIN_PAIRED: f64 = 0.7;

/// Where a leaf sits on the branch it is attached to.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeafOnBranch {
    /// The leaf (segment id).
    pub leaf: u32,
    pub branch: u32,
    /// Arc-length fraction along the branch where the leaf attaches.
    pub parent_fraction: f64,
    pub base_world: [f64; 3],
    pub tip_world: [f64; 3],
}

/// How the leaves on one branch are arranged.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Arrangement {
    pub leaves: usize,
    /// Share of the leaves (the one nearest the tip aside) with a partner on the other side.
    pub paired: f64,
    /// Leaves on the left and on the right of the branch (seen from above its leaves).
    pub left: usize,
    pub right: usize,
}

/// A compound leaf: a rachis and its leaflets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompoundLeaf {
    /// Numbered from 0 in rachis order.
    pub id: u32,
    /// The rachis's branch id.
    pub rachis: u32,
    /// The leaflets (leaf ids), from the rachis's base to its tip.
    pub leaflets: Vec<u32>,
    pub arrangement: Arrangement,
}

/// The arrangement of `leaves` (all on `branch`) on it; `None` for fewer than two leaves or a
/// branch the tree does not hold.
pub fn arrangement(
    tree: &BranchTree,
    branch: u32,
    leaves: &[&LeafOnBranch],
) -> Option<Arrangement> {
    let cylinder = &tree.get(branch)?.cylinder;
    if leaves.len() < 2 {
        return None;
    }
    let length = cylinder.length();
    // Which side of the branch each leaf points to: the sign of its direction along the
    // branch's sideways axis, the cross product of the tangent and the leaves' mean "up" (the
    // normal of the plane through the branch that the leaves spread in).
    let mut directions = Vec::with_capacity(leaves.len());
    for leaf in leaves {
        let point = tree.point_on(branch, leaf.parent_fraction)?;
        let outward = Point3::from(leaf.tip_world) - point.position;
        let across = outward - point.tangent * point.tangent.dot(&outward);
        directions.push((point.tangent, across));
    }
    // The plane's normal: the direction least spanned by the leaves' sideways vectors and the
    // tangents together (smallest eigenvector of their scatter).
    let mut scatter = nalgebra::Matrix3::zeros();
    for (tangent, across) in &directions {
        let a = across.try_normalize(1e-12).unwrap_or_else(Vector3::zeros);
        scatter += a * a.transpose() + tangent * tangent.transpose();
    }
    let eigen = scatter.symmetric_eigen();
    let smallest = eigen.eigenvalues.imin();
    let normal: Vector3<f64> = eigen.eigenvectors.column(smallest).into();
    let sides: Vec<f64> = directions
        .iter()
        .map(|(tangent, across)| tangent.cross(&normal).dot(across).signum())
        .collect();
    let lengths: Vec<f64> = leaves
        .iter()
        .map(|l| (Point3::from(l.tip_world) - Point3::from(l.base_world)).norm())
        .collect();
    let reach = PAIR_DISTANCE_PER_LEAFLET_LENGTH * median(lengths.iter().copied()).unwrap_or(0.0);
    let tip_most = leaves
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.parent_fraction.total_cmp(&b.1.parent_fraction))
        .map_or(0, |(i, _)| i);
    let mut paired = 0;
    for (i, leaf) in leaves.iter().enumerate() {
        if i == tip_most {
            continue;
        }
        let partner = leaves.iter().enumerate().any(|(j, other)| {
            j != i
                && sides[j] != sides[i]
                && (other.parent_fraction - leaf.parent_fraction).abs() * length <= reach
        });
        paired += usize::from(partner);
    }
    Some(Arrangement {
        leaves: leaves.len(),
        paired: paired as f64 / (leaves.len() - 1) as f64,
        left: sides.iter().filter(|s| **s > 0.0).count(),
        right: sides.iter().filter(|s| **s <= 0.0).count(),
    })
}

/// The compound leaves among `leaves` on `tree` (see the module docs).
pub fn compound_leaves(tree: &BranchTree, leaves: &[LeafOnBranch]) -> Vec<CompoundLeaf> {
    let mut out = Vec::new();
    for branch in &tree.branches {
        if branch.parent.is_none() || tree.branches.iter().any(|b| b.parent == Some(branch.id)) {
            continue;
        }
        let mut on: Vec<&LeafOnBranch> = leaves.iter().filter(|l| l.branch == branch.id).collect();
        if on.len() < MIN_LEAFLETS {
            continue;
        }
        on.sort_by(|a, b| {
            a.parent_fraction
                .total_cmp(&b.parent_fraction)
                .then(a.leaf.cmp(&b.leaf))
        });
        let Some(arrangement) = arrangement(tree, branch.id, &on) else {
            continue;
        };
        if arrangement.paired >= MIN_PAIRED {
            out.push(CompoundLeaf {
                id: out.len() as u32,
                rachis: branch.id,
                leaflets: on.iter().map(|l| l.leaf).collect(),
                arrangement,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{Preset, generate_plant};

    /// Where each true leaf sits on its true branch.
    fn true_leaves(plant: &crate::synth::SynthPlant) -> Vec<LeafOnBranch> {
        plant
            .leaves
            .iter()
            .filter_map(|leaf| {
                let base = leaf.world_from_leaf * leaf.geometry.point(0.0, 0.0);
                let tip = leaf.world_from_leaf * leaf.geometry.point(1.0, 0.0);
                let branch = plant.branches.get(leaf.branch)?;
                let (fraction, _) = branch.cylinder.skeleton.closest_fraction(&base);
                Some(LeafOnBranch {
                    leaf: leaf.id,
                    branch: leaf.branch,
                    parent_fraction: fraction,
                    base_world: base.into(),
                    tip_world: tip.into(),
                })
            })
            .collect()
    }

    #[test]
    fn arrangements_on_the_true_plants() {
        for preset in Preset::ALL {
            for seed in 1..4 {
                let plant = generate_plant(preset, seed);
                let leaves = true_leaves(&plant);
                for branch in &plant.branches.branches {
                    let on: Vec<&LeafOnBranch> =
                        leaves.iter().filter(|l| l.branch == branch.id).collect();
                    if on.len() >= MIN_LEAFLETS {
                        eprintln!(
                            "{preset} {seed} branch {}: {:?}",
                            branch.id,
                            arrangement(&plant.branches, branch.id, &on)
                        );
                    }
                }
                eprintln!(
                    "{preset} {seed}: {} compound",
                    compound_leaves(&plant.branches, &leaves).len()
                );
            }
        }
    }
}
