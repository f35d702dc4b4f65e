//! Compound leaves: leaflets on a rachis. A pinnately compound leaf (ash, rose, sumac, a fern
//! frond) is reconstructed as its parts: each leaflet is a leaf, the rachis a branch the
//! leaflets hang on. This module says which branches are rachises and which leaves are their
//! leaflets, from how the leaves sit on each branch:
//! - a rachis is a branch, or the end of a branch past its last child branch (a child from
//!   the branch's last tenth continues it instead), that carries at least [`MIN_LEAFLETS`]
//!   leaves; child branches whose subtree is no longer than two median lengths of the leaves
//!   on the branch and carries fewer than [`MIN_LEAFLETS`] leaves are its petiolules, and
//!   their leaves its leaflets;
//! - its leaflets spread in *one plane through the rachis* (leaves spiralled around a twig or
//!   a stem do not), on *both sides* of it (at least a quarter on the less populated side).
//!
//! How many leaflets stand in opposite pairs is measured ([`Arrangement::paired`]) but not
//! asked for: compound leaves with alternate leaflets exist, and a leaflet whose partner was
//! not found has none (on semi-dense points of seeds 1–6, rachises the skeleton found had
//! 0–100 % of their leaflets paired). A twig with spiralled leaves fails the plane test, one
//! with all its leaves on one side the two-sides test; a flat twig with leaves on both sides
//! passes both (botanists tell such a twig from a compound leaf by the bud in the leaf's
//! axil, which photos do not show) and is reported as a compound leaf.
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
/// Smallest share of the leaflets on the rachis's less populated side.
const MIN_SIDE_SHARE: f64 = 0.25;
/// A child branch starting past this fraction of its parent continues the parent.
const CONTINUATION_FRACTION: f64 = 0.9;
/// Longest petiolule subtree, in median leaf lengths.
const SPUR_LEAF_LENGTHS: f64 = 2.0;
/// Largest mean out-of-plane sine ([`Arrangement::out_of_plane`]) of a rachis's leaflets: on
/// the true plants of seeds 1–3, rachises measure 0.11–0.23 and smallleaf twigs 0.44–0.65.
const MAX_OUT_OF_PLANE: f64 = 0.35;

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

impl LeafOnBranch {
    /// Base-to-tip distance.
    pub fn length(&self) -> f64 {
        (Point3::from(self.tip_world) - Point3::from(self.base_world)).norm()
    }
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
    /// Mean |sin| of the angle between each leaf's sideways direction and the plane through
    /// the branch that the leaves spread in: near 0 for leaflets on both sides of a rachis,
    /// about 0.4 or more for leaves spiralled around a stem.
    pub out_of_plane: f64,
}

/// A compound leaf: a rachis and its leaflets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompoundLeaf {
    /// Numbered from 0 in rachis order.
    pub id: u32,
    /// The rachis's branch id.
    pub rachis: u32,
    /// Where along that branch the rachis starts (0 unless the skeleton drew the rachis as
    /// the continuation of a stem or branch: then past that branch's last child branch).
    pub rachis_from: f64,
    /// Short leaf-bearing branches on the rachis (petiolules, or leaflet midribs the skeleton
    /// took for branches).
    pub petiolules: Vec<u32>,
    /// The leaflets (leaf ids), from the rachis's base to its tip.
    pub leaflets: Vec<u32>,
    pub arrangement: Arrangement,
}

/// The arrangement of `leaves` (all on `branch`) on it; `None` for fewer than two leaves or a
/// branch the tree does not hold.
pub fn arrangement(tree: &BranchTree, branch: u32, leaves: &[LeafOnBranch]) -> Option<Arrangement> {
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
    let out_of_plane = directions
        .iter()
        .map(|(_, across)| {
            across
                .try_normalize(1e-12)
                .map_or(0.0, |a| a.dot(&normal).abs())
        })
        .sum::<f64>()
        / directions.len() as f64;
    let sides: Vec<f64> = directions
        .iter()
        .map(|(tangent, across)| tangent.cross(&normal).dot(across).signum())
        .collect();
    let reach = PAIR_DISTANCE_PER_LEAFLET_LENGTH
        * median(leaves.iter().map(LeafOnBranch::length)).unwrap_or(0.0);
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
        out_of_plane,
    })
}

/// The compound leaves among `leaves` on `tree` (see the module docs).
pub fn compound_leaves(tree: &BranchTree, leaves: &[LeafOnBranch]) -> Vec<CompoundLeaf> {
    let Some(plant_leaf_length) = median(leaves.iter().map(LeafOnBranch::length)) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for branch in &tree.branches {
        // The scale of petiolules: the leaves on this branch (leaflets vary in size from one
        // compound leaf to the next), else the plant's.
        let leaf_length = median(
            leaves
                .iter()
                .filter(|l| l.branch == branch.id)
                .map(LeafOnBranch::length),
        )
        .unwrap_or(plant_leaf_length);
        // A child whose subtree is short (at most two leaf lengths) and carries fewer than
        // MIN_LEAFLETS leaves is a petiolule (or a leaflet midrib the skeleton took for a
        // branch): part of the compound leaf, its leaves leaflets where it meets the rachis.
        // The rachis starts past the last other child.
        let mut spurs: Vec<(f64, Vec<u32>)> = Vec::new();
        let mut from: f64 = 0.0;
        for child in tree.branches.iter().filter(|b| b.parent == Some(branch.id)) {
            let subtree = tree.subtree(child.id);
            let length: f64 = subtree
                .iter()
                .filter_map(|&id| tree.get(id))
                .map(|b| b.cylinder.length())
                .sum();
            let carried = leaves
                .iter()
                .filter(|l| subtree.contains(&l.branch))
                .count();
            if length <= SPUR_LEAF_LENGTHS * leaf_length && carried < MIN_LEAFLETS {
                spurs.push((child.parent_fraction, subtree));
            } else if child.parent_fraction < CONTINUATION_FRACTION {
                // (A child from the branch's very end continues it: it leaves the branch's
                // leaves on one side.)
                from = from.max(child.parent_fraction);
            }
        }
        if branch.parent.is_none() && from == 0.0 {
            // A root branch without side branches is a stem, not a leaf.
            continue;
        }
        spurs.retain(|(fraction, _)| *fraction > from);
        let mut on: Vec<LeafOnBranch> = leaves
            .iter()
            .filter(|l| l.branch == branch.id && l.parent_fraction > from)
            .copied()
            .chain(leaves.iter().filter_map(|l| {
                let (fraction, _) = spurs.iter().find(|(_, ids)| ids.contains(&l.branch))?;
                Some(LeafOnBranch {
                    branch: branch.id,
                    parent_fraction: *fraction,
                    ..*l
                })
            }))
            .collect();
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
        tracing::debug!(
            branch = branch.id,
            from,
            ?arrangement,
            "compound leaf candidate"
        );
        let smaller_side = arrangement.left.min(arrangement.right) as f64;
        if smaller_side >= MIN_SIDE_SHARE * arrangement.leaves as f64
            && arrangement.out_of_plane <= MAX_OUT_OF_PLANE
        {
            out.push(CompoundLeaf {
                id: out.len() as u32,
                rachis: branch.id,
                rachis_from: from,
                petiolules: spurs
                    .iter()
                    .flat_map(|(_, ids)| ids.iter().copied())
                    .collect(),
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
    fn true_rachises_are_compound_leaves_and_true_twigs_are_not() {
        for preset in Preset::ALL {
            for seed in 1..4 {
                let plant = generate_plant(preset, seed);
                let leaves = true_leaves(&plant);
                let found = compound_leaves(&plant.branches, &leaves);
                let mut rachises: Vec<u32> = plant
                    .leaves
                    .iter()
                    .filter_map(|l| l.compound_leaf)
                    .collect();
                rachises.dedup();
                let found_rachises: Vec<u32> = found.iter().map(|c| c.rachis).collect();
                assert_eq!(found_rachises, rachises, "{preset} seed {seed}");
                for compound in &found {
                    for &leaflet in &compound.leaflets {
                        let leaf = &plant.leaves[leaflet as usize];
                        assert_eq!(leaf.compound_leaf, Some(compound.rachis));
                    }
                    let a = compound.arrangement;
                    assert_eq!(a.left + a.right, a.leaves);
                    assert!(a.left.abs_diff(a.right) <= 1, "{a:?}");
                    // Measured on seeds 1–3: true rachises 0.11–0.23; smallleaf twigs (leaves
                    // all round) 0.44–0.65.
                    assert!(a.out_of_plane < 0.25, "{a:?}");
                }
            }
        }
    }

    #[test]
    fn leaves_one_by_one_along_a_twig_are_not_a_compound_leaf() {
        let spline = super::super::Spline::new(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.1, 0.0, 0.0),
            Point3::new(0.2, 0.0, 0.02),
        ])
        .expect("distinct points");
        let stem = spline.clone();
        let tree = BranchTree {
            branches: vec![
                super::super::Branch {
                    id: 0,
                    parent: None,
                    parent_fraction: 0.0,
                    cylinder: super::super::GeneralizedCylinder::new(stem, 0.005, 0.004),
                    leaf_at_tip: false,
                },
                super::super::Branch {
                    id: 1,
                    parent: Some(0),
                    parent_fraction: 0.5,
                    cylinder: super::super::GeneralizedCylinder::new(spline, 0.002, 0.001),
                    leaf_at_tip: false,
                },
            ],
        };
        let leaf = |k: usize, fraction: f64, side: f64| {
            let point = tree.point_on(1, fraction).expect("branch 1");
            let base = point.position + Vector3::new(0.0, 0.002 * side, 0.0);
            let tip = base + Vector3::new(0.01, 0.04 * side, 0.0);
            LeafOnBranch {
                leaf: k as u32,
                branch: 1,
                parent_fraction: fraction,
                base_world: base.into(),
                tip_world: tip.into(),
            }
        };
        // Opposite pairs: a compound leaf.
        let pairs: Vec<LeafOnBranch> = (0..8)
            .map(|k| {
                leaf(
                    k,
                    0.2 + 0.1 * (k / 2) as f64,
                    if k % 2 == 0 { 1.0 } else { -1.0 },
                )
            })
            .collect();
        let found = compound_leaves(&tree, &pairs);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].rachis, 1);
        assert_eq!(found[0].leaflets, (0..8).collect::<Vec<u32>>());
        assert!(found[0].arrangement.paired > 0.99);
        // Alternate leaflets, half a spacing apart: compound, none of them paired.
        let alternate: Vec<LeafOnBranch> = (0..8)
            .map(|k| {
                leaf(
                    k,
                    0.2 + 0.05 * k as f64,
                    if k % 2 == 0 { 1.0 } else { -1.0 },
                )
            })
            .collect();
        let found = compound_leaves(&tree, &alternate);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].arrangement.paired, 0.0);
        // All on one side, or spiralled around the twig: not compound.
        let one_side: Vec<LeafOnBranch> = (0..8)
            .map(|k| leaf(k, 0.2 + 0.05 * k as f64, 1.0))
            .collect();
        assert!(compound_leaves(&tree, &one_side).is_empty());
        let spiral: Vec<LeafOnBranch> = (0..8)
            .map(|k| {
                let mut l = leaf(k, 0.2 + 0.05 * k as f64, 1.0);
                let point = tree.point_on(1, l.parent_fraction).expect("branch 1");
                let angle = k as f64 * 2.4;
                let out = Vector3::new(0.0, angle.cos(), angle.sin()) * 0.04;
                l.tip_world = (point.position + out + Vector3::new(0.01, 0.0, 0.0)).into();
                l
            })
            .collect();
        assert!(compound_leaves(&tree, &spiral).is_empty());
        // Too few leaflets: not compound.
        assert!(compound_leaves(&tree, &pairs[..4]).is_empty());
        // On the stem below its branch (fraction 0.5): not a rachis. Past it, where the
        // skeleton drew a rachis as the stem's continuation: a rachis from there.
        let on_stem = |shift: f64| -> Vec<LeafOnBranch> {
            pairs
                .iter()
                .map(|l| LeafOnBranch {
                    branch: 0,
                    parent_fraction: l.parent_fraction + shift,
                    ..*l
                })
                .collect()
        };
        assert!(compound_leaves(&tree, &on_stem(0.0)).is_empty());
        let found = compound_leaves(&tree, &on_stem(0.35));
        assert_eq!(found.len(), 1);
        assert_eq!((found[0].rachis, found[0].rachis_from), (0, 0.5));
        // A short leaf-bearing spur on the rachis is a petiolule: its leaf is a leaflet.
        let mut with_spur = tree.clone();
        let spur = super::super::Spline::new(vec![
            tree.point_on(1, 0.9).expect("branch 1").position,
            Point3::new(0.19, 0.01, 0.02),
        ])
        .expect("distinct points");
        with_spur.branches.push(super::super::Branch {
            id: 2,
            parent: Some(1),
            parent_fraction: 0.9,
            cylinder: super::super::GeneralizedCylinder::new(spur, 0.001, 0.001),
            leaf_at_tip: false,
        });
        let mut leaves = pairs.clone();
        leaves.push(LeafOnBranch {
            leaf: 8,
            branch: 2,
            parent_fraction: 1.0,
            ..leaf(8, 0.9, 1.0)
        });
        leaves.push(leaf(9, 0.9, -1.0));
        let found = compound_leaves(&with_spur, &leaves);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].petiolules, vec![2]);
        assert_eq!(found[0].leaflets, (0..10).collect::<Vec<u32>>());
    }
}
