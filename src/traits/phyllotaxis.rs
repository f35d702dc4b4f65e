//! The organ sequence along a plant's main stem: the organs inserted on it (child branches
//! and leaves attached to it directly) in insertion order, with the internode between
//! successive organs and their signed divergence angle around the stem.
//!
//! Signed angles are what phyllotaxis measures: the turn from one organ's direction to the
//! next, counter-clockwise about the stem's tangent (base → tip), in [0°, 360°). A spiral of
//! 137.5° reads 137.5° in one sense and 222.5° in the other; unsigned angles cannot tell a
//! spiral from its mirror or a 90° step from a 270° one.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{PlantOrgans, branch_length, initial_direction, leaf_traits, polyline_at, positive};
use crate::branch::plant::SkeletonRecord;

/// What an inserted organ is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
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
    /// about the stem tangent (base → tip).
    pub angles_deg: Vec<f64>,
}

/// The main stem: the longest root branch.
pub fn main_stem(branches: &[SkeletonRecord]) -> Option<&SkeletonRecord> {
    branches
        .iter()
        .filter(|b| b.parent.is_none())
        .max_by(|a, b| branch_length(a).total_cmp(&branch_length(b)))
}

/// The organ sequence along the main stem; `None` without a stem of positive length or with
/// fewer than two organs on it whose direction is known.
pub fn stem_sequence(organs: &PlantOrgans) -> Option<StemSequence> {
    let stem = main_stem(&organs.branches)?;
    let length = branch_length(stem);
    if !positive(length) {
        return None;
    }
    let up = organs
        .up_world
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::z);
    // (fraction, kind, id, direction)
    let mut inserted: Vec<(f64, OrganKind, u32, Vector3<f64>)> = Vec::new();
    for child in organs.branches.iter().filter(|b| b.parent == Some(stem.id)) {
        if let Some(d) = initial_direction(child) {
            inserted.push((child.parent_fraction, OrganKind::Branch, child.id, d));
        }
    }
    let stem_base = stem
        .centerline
        .first()
        .map(|c| nalgebra::Point3::from(*c))?;
    for leaf in &organs.leaves {
        let Some((branch, fraction)) = leaf.branch else {
            continue;
        };
        if branch != stem.id {
            continue;
        }
        if let Some(t) = leaf_traits(&leaf.mesh, leaf.base_world, &stem_base, &up)
            && let Some(d) = (t.tip_world - t.base_world).try_normalize(1e-15)
        {
            inserted.push((fraction, OrganKind::Leaf, leaf.id, d));
        }
    }
    if inserted.len() < 2 {
        return None;
    }
    inserted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
    let mut internodes = Vec::with_capacity(inserted.len() - 1);
    let mut angles_deg = Vec::with_capacity(inserted.len() - 1);
    for pair in inserted.windows(2) {
        internodes.push((pair[1].0 - pair[0].0) * length);
        let at = 0.5 * (pair[0].0 + pair[1].0);
        let tangent = polyline_at(&stem.centerline, at).map_or(up, |(_, t)| t);
        angles_deg.push(signed_angle_deg(&pair[0].3, &pair[1].3, &tangent).unwrap_or(0.0));
    }
    Some(StemSequence {
        stem: stem.id,
        stem_length: length,
        organs: inserted
            .iter()
            .map(|(fraction, kind, id, _)| InsertedOrgan {
                kind: *kind,
                id: *id,
                position: fraction * length,
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
            assert!((angle - 137.5).abs() < 1e-6, "{angle}");
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
            assert!((angle - 222.5).abs() < 1e-6, "{angle}");
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
