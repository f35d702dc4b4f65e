//! The organ sequence along a plant's main stem: the organs inserted on it (child branches
//! and leaves attached to it directly) in insertion order, with the internode between
//! successive organs and their signed divergence angle around the stem.
//!
//! Signed angles are what phyllotaxis measures: the turn from one organ's direction to the
//! next, counter-clockwise about the stem's tangent (base → tip), in [0°, 360°). A spiral of
//! 137.5° reads 137.5° in one sense and 222.5° in the other; unsigned angles cannot tell a
//! spiral from its mirror or a 90° step from a 270° one.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::{
    LeafOrgan, PlantOrgans, branch_length, initial_direction, leaf_traits, polyline_at, positive,
};
use crate::branch::plant::SkeletonRecord;

/// What an inserted organ is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OrganKind {
    Branch,
    Leaf,
}

/// One organ on the main stem.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InsertedOrgan {
    pub kind: OrganKind,
    /// The branch or leaf id.
    pub id: u32,
    /// Distance from the stem's base along the stem (model units).
    pub position: f64,
}

/// The organ sequence of a main stem.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StemSequence {
    /// The main stem's branch id.
    pub stem: u32,
    /// The stem's length (model units).
    pub stem_length: f64,
    pub organs: Vec<InsertedOrgan>,
    /// `organs.len() - 1` internodes (model units).
    pub internodes: Vec<f64>,
    /// `organs.len() - 1` signed divergence angles, degrees in [0, 360), counter-clockwise
    /// about the stem tangent (base → tip); `None` where an organ runs along the stem.
    pub angles_deg: Vec<Option<f64>>,
}

/// The main stem: the longest root branch.
pub fn main_stem(branches: &[SkeletonRecord]) -> Option<&SkeletonRecord> {
    branches
        .iter()
        .filter(|b| b.parent.is_none())
        .max_by(|a, b| branch_length(a).total_cmp(&branch_length(b)))
}

/// An organ inserted on an axis, with its initial direction (world frame).
pub(crate) struct Inserted {
    /// Where along the axis (0 = base, 1 = tip).
    pub fraction: f64,
    pub kind: OrganKind,
    pub id: u32,
    pub direction: Vector3<f64>,
}

/// The organs inserted on `axis`: its child branches and the leaves attached to it directly
/// (`leaf_direction` gives a leaf's base → tip direction), in insertion order (ties by kind
/// and id).
pub(crate) fn inserted_on(
    axis: &SkeletonRecord,
    organs: &PlantOrgans,
    leaf_direction: impl Fn(&LeafOrgan) -> Option<Vector3<f64>>,
) -> Vec<Inserted> {
    let mut inserted: Vec<Inserted> = Vec::new();
    for child in organs.branches.iter().filter(|b| b.parent == Some(axis.id)) {
        if let Some(direction) = initial_direction(child) {
            inserted.push(Inserted {
                fraction: child.parent_fraction,
                kind: OrganKind::Branch,
                id: child.id,
                direction,
            });
        }
    }
    for leaf in &organs.leaves {
        if let Some((branch, fraction)) = leaf.branch
            && branch == axis.id
            && let Some(direction) = leaf_direction(leaf)
        {
            inserted.push(Inserted {
                fraction,
                kind: OrganKind::Leaf,
                id: leaf.id,
                direction,
            });
        }
    }
    inserted.sort_by(|a, b| {
        a.fraction
            .total_cmp(&b.fraction)
            .then(a.kind.cmp(&b.kind))
            .then(a.id.cmp(&b.id))
    });
    inserted
}

/// The internode (model units) from organ `a` to the next organ `b` on `axis`, and their
/// signed divergence angle about the axis's tangent halfway between them (`None` where the
/// axis has no tangent or an organ runs along it).
pub(crate) fn interval(axis: &SkeletonRecord, a: &Inserted, b: &Inserted) -> (f64, Option<f64>) {
    let internode = (b.fraction - a.fraction) * branch_length(axis);
    let angle = polyline_at(&axis.centerline, 0.5 * (a.fraction + b.fraction))
        .and_then(|(_, tangent)| signed_angle_deg(&a.direction, &b.direction, &tangent));
    (internode, angle)
}

/// Which organs on the main stem make its sequence.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SequenceOrgans {
    /// Child branches and leaves attached to the stem directly.
    #[default]
    All,
    /// Child branches only: the stem's fruits, pedicels and side shoots, what ROMI's manual
    /// Arabidopsis measures count (the angle and internode between successive fruits, no
    /// leaves; a rosette's leaves all sit at the stem's foot).
    Branches,
    /// Leaves attached to the stem directly only.
    Leaves,
}

impl SequenceOrgans {
    fn takes(self, kind: OrganKind) -> bool {
        match self {
            SequenceOrgans::All => true,
            SequenceOrgans::Branches => kind == OrganKind::Branch,
            SequenceOrgans::Leaves => kind == OrganKind::Leaf,
        }
    }
}

/// The organ sequence along the main stem; `None` without a stem of positive length or with
/// fewer than two organs on it whose direction is known.
pub fn stem_sequence(organs: &PlantOrgans) -> Option<StemSequence> {
    stem_sequence_of(organs, SequenceOrgans::All)
}

/// The sequence of the organs of the kinds `which` takes along the main stem; `None` as for
/// [`stem_sequence`].
pub fn stem_sequence_of(organs: &PlantOrgans, which: SequenceOrgans) -> Option<StemSequence> {
    let stem = main_stem(&organs.branches)?;
    let length = branch_length(stem);
    if !positive(length) {
        return None;
    }
    let up = organs
        .up_world
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::z);
    let stem_base = Point3::from(*stem.centerline.first()?);
    let mut inserted = inserted_on(stem, organs, |leaf| {
        let t = leaf_traits(&leaf.mesh, leaf.base_world, &stem_base, &up)?;
        (t.tip_world - t.base_world).try_normalize(1e-15)
    });
    inserted.retain(|o| which.takes(o.kind));
    if inserted.len() < 2 {
        return None;
    }
    let (internodes, angles_deg) = inserted
        .windows(2)
        .map(|pair| interval(stem, &pair[0], &pair[1]))
        .unzip();
    Some(StemSequence {
        stem: stem.id,
        stem_length: length,
        organs: inserted
            .iter()
            .map(|o| InsertedOrgan {
                kind: o.kind,
                id: o.id,
                position: o.fraction * length,
            })
            .collect(),
        internodes,
        angles_deg,
    })
}

/// The counter-clockwise angle about `axis` from `a` to `b`, both projected on the plane
/// normal to `axis`, degrees in [0, 360); `None` when either lies along the axis.
pub fn signed_angle_deg(a: &Vector3<f64>, b: &Vector3<f64>, axis: &Vector3<f64>) -> Option<f64> {
    let axis = axis.try_normalize(1e-15)?;
    let project = |d: &Vector3<f64>| (d - axis * d.dot(&axis)).try_normalize(1e-9);
    let (a, b) = (project(a)?, project(b)?);
    let angle = axis.dot(&a.cross(&b)).atan2(a.dot(&b)).to_degrees();
    Some(angle.rem_euclid(360.0) % 360.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traits::PlantOrgans;

    fn branch(id: u32, parent: Option<u32>, fraction: f64, line: Vec<[f64; 3]>) -> SkeletonRecord {
        let length = line
            .windows(2)
            .map(|w| (nalgebra::Point3::from(w[1]) - nalgebra::Point3::from(w[0])).norm())
            .sum();
        SkeletonRecord {
            id,
            parent,
            parent_fraction: fraction,
            control_points: line.clone(),
            radius_start: 0.01,
            radius_end: 0.01,
            length,
            centerline: line,
            observed_length: None,
            bridged_length: None,
        }
    }

    #[test]
    fn a_spiral_reads_its_divergence_angle_in_one_sense_and_its_mirror_in_the_other() {
        // A vertical stem 1 long with 6 branches every 0.15, each turned 137.5° (counter-
        // clockwise seen from above) from the one below; inserted out of order.
        let stem: Vec<[f64; 3]> = (0..=20).map(|k| [0.0, 0.0, k as f64 * 0.05]).collect();
        let mut branches = vec![branch(0, None, 0.0, stem)];
        for id in [3u32, 1, 5, 2, 6, 4] {
            let order = (id - 1) as f64;
            let z = 0.1 + 0.15 * order;
            let phi = (137.5 * order).to_radians();
            let line: Vec<[f64; 3]> = (0..=10)
                .map(|s| {
                    let r = s as f64 * 0.02;
                    [r * phi.cos(), r * phi.sin(), z + 0.3 * r]
                })
                .collect();
            branches.push(branch(id, Some(0), z, line));
        }
        let organs = PlantOrgans {
            plant: "spiral".into(),
            up_world: Vector3::z(),
            leaves: Vec::new(),
            branches: branches.clone(),
        };
        let sequence = stem_sequence(&organs).unwrap();
        assert_eq!(
            sequence.organs.iter().map(|o| o.id).collect::<Vec<_>>(),
            vec![1, 2, 3, 4, 5, 6]
        );
        for internode in &sequence.internodes {
            assert!((internode - 0.15).abs() < 1e-9, "{internode}");
        }
        for angle in &sequence.angles_deg {
            assert!((angle.unwrap() - 137.5).abs() < 1e-6, "{angle:?}");
        }
        // Its mirror image turns the other way.
        let mirrored: Vec<SkeletonRecord> = branches
            .into_iter()
            .map(|mut b| {
                for c in b.centerline.iter_mut() {
                    c[1] = -c[1];
                }
                b
            })
            .collect();
        let organs = PlantOrgans {
            branches: mirrored,
            ..organs
        };
        let sequence = stem_sequence(&organs).unwrap();
        for angle in &sequence.angles_deg {
            assert!((angle.unwrap() - 222.5).abs() < 1e-6, "{angle:?}");
        }
    }

    #[test]
    fn no_stem_or_a_single_organ_has_no_sequence() {
        let organs = PlantOrgans {
            plant: "empty".into(),
            up_world: Vector3::z(),
            leaves: Vec::new(),
            branches: Vec::new(),
        };
        assert!(stem_sequence(&organs).is_none());
        let stem: Vec<[f64; 3]> = vec![[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let organs = PlantOrgans {
            branches: vec![
                branch(0, None, 0.0, stem),
                branch(1, Some(0), 0.5, vec![[0.0, 0.0, 0.5], [0.1, 0.0, 0.6]]),
            ],
            ..organs
        };
        assert!(stem_sequence(&organs).is_none());
    }

    #[test]
    fn the_sequence_takes_the_organs_of_the_kinds_asked_for() {
        // A vertical stem 1 long: leaves at 0.1 (towards −x) and 0.5 (−y), branches at 0.3
        // (+x) and 0.7 (+y).
        let stem: Vec<[f64; 3]> = vec![[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let leaf = |id: u32, z: f64, along: Vector3<f64>| crate::traits::LeafOrgan {
            id,
            mesh: crate::traits::tests::rectangle(
                Point3::new(0.0, 0.0, z),
                along,
                Vector3::z(),
                0.2,
                0.05,
            ),
            base_world: Some(Point3::new(0.0, 0.0, z)),
            branch: Some((0, z)),
            synthesized: false,
            compound_leaf: None,
        };
        let organs = PlantOrgans {
            plant: "kinds".into(),
            up_world: Vector3::z(),
            leaves: vec![leaf(10, 0.1, -Vector3::x()), leaf(11, 0.5, -Vector3::y())],
            branches: vec![
                branch(0, None, 0.0, stem),
                branch(1, Some(0), 0.3, vec![[0.0, 0.0, 0.3], [0.2, 0.0, 0.4]]),
                branch(2, Some(0), 0.7, vec![[0.0, 0.0, 0.7], [0.0, 0.2, 0.8]]),
            ],
        };
        let ids = |s: &StemSequence| s.organs.iter().map(|o| o.id).collect::<Vec<_>>();
        let all = stem_sequence_of(&organs, SequenceOrgans::All).unwrap();
        assert_eq!(ids(&all), vec![10, 1, 11, 2]);
        assert_eq!(all, stem_sequence(&organs).unwrap());
        for (which, expected, kind) in [
            (SequenceOrgans::Branches, vec![1, 2], OrganKind::Branch),
            (SequenceOrgans::Leaves, vec![10, 11], OrganKind::Leaf),
        ] {
            let sequence = stem_sequence_of(&organs, which).unwrap();
            assert_eq!(ids(&sequence), expected);
            assert!(sequence.organs.iter().all(|o| o.kind == kind));
            // Successive organs of the kind, 0.4 apart and a quarter turn counter-clockwise.
            assert_eq!(sequence.internodes.len(), 1);
            assert!((sequence.internodes[0] - 0.4).abs() < 1e-9, "{sequence:?}");
            let angle = sequence.angles_deg[0].unwrap();
            assert!((angle - 90.0).abs() < 1e-6, "{which:?}: {angle}");
        }
        // One branch alone makes no sequence, whatever the leaves.
        let one_branch = PlantOrgans {
            branches: organs.branches[..2].to_vec(),
            ..organs.clone()
        };
        assert!(stem_sequence_of(&one_branch, SequenceOrgans::Branches).is_none());
        assert!(stem_sequence_of(&one_branch, SequenceOrgans::All).is_some());
    }

    #[test]
    fn signed_angles_cover_the_whole_turn() {
        let z = Vector3::z();
        let x = Vector3::x();
        let at = |deg: f64| {
            let r = deg.to_radians();
            Vector3::new(r.cos(), r.sin(), 0.4)
        };
        for deg in [0.0, 45.0, 137.5, 180.0, 222.5, 300.0, 359.0] {
            let got = signed_angle_deg(&x, &at(deg), &z).unwrap();
            let diff = (got - deg).abs().min(360.0 - (got - deg).abs());
            assert!(diff < 1e-9, "{deg}: {got}");
        }
        assert!(signed_angle_deg(&z, &x, &z).is_none());
    }
}
