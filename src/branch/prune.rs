//! Side branches the automatic skeleton drew on pieces of leaf: from photos the skeleton's
//! points hold, besides stems and petioles, the rims of leaves that their segments left out
//! and fragments of leaves that no segment took (stereo noise makes a sparse patch of blade
//! read as a tube to the per-point stem test). The skeleton follows them like any other points.
//! A branch is such a piece when, over its length,
//! - it runs along a leaf: most of its axis lies within its radius plus a few point spacings
//!   of a leaf's sheet (a petiole meets its leaf at one end, a rim follows it), or
//! - its cross-sections are flat: the points around its axis, seen along it, spread one way
//!   only (a strip of blade), where a tube's spread both ways (a ring, or an arc of one where
//!   the photos see one side: half a ring gives a width ratio of 0.44 without noise).
//!
//! Only branches that end the tree are removed (a branch carrying others is kept, whatever its
//! points), and removal is repeated while it uncovers new ends, so a chain of pieces goes and a
//! petiole that was found on a noisy strip still carries the leaf branch beyond it.

use nalgebra::{Matrix2, Point3, Vector2, Vector3};
use serde::Serialize;

use super::BranchTree;
use crate::graph::neighbours::Neighbours;

/// When a side branch is a piece of leaf (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LeafPieceTest {
    /// A branch with at least this share of its length near a leaf runs along it.
    pub max_leaf_share: f64,
    /// Near a leaf: within the branch's radius plus this many point spacings of a leaf point.
    pub leaf_reach_spacings: f64,
    /// A branch whose median cross-section width ratio (`√(λ₂/λ₁)` of the points around the
    /// axis, projected across it) is below this is flat.
    pub min_roundness: f64,
    /// Cross-sections gather the points within this many branch radii of the axis sample …
    pub section_radii: f64,
    /// … and at least this many point spacings.
    pub section_spacings: f64,
}

impl Default for LeafPieceTest {
    fn default() -> Self {
        Self {
            max_leaf_share: 0.9,
            leaf_reach_spacings: 3.0,
            min_roundness: 0.4,
            section_radii: 2.5,
            section_spacings: 4.0,
        }
    }
}

/// A cross-section needs this many points to count.
const MIN_SECTION_POINTS: usize = 6;
/// A branch needs this many counted cross-sections for its roundness to be judged.
const MIN_SECTIONS: usize = 3;

/// What the test measured on one branch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchEvidence {
    /// Share of the axis samples near a leaf point.
    pub leaf_share: f64,
    /// Median cross-section width ratio (`None` with too few points around the axis).
    pub roundness: Option<f64>,
}

impl LeafPieceTest {
    /// Whether this evidence makes a branch a piece of leaf.
    pub fn is_leaf_piece(&self, evidence: &BranchEvidence) -> bool {
        evidence.leaf_share >= self.max_leaf_share
            || evidence.roundness.is_some_and(|q| q < self.min_roundness)
    }
}

/// The evidence of each branch of `tree`, in its order: `points` are the skeleton's points,
/// `leaves` the points of leaf sheets, `spacing` the skeleton points' median spacing.
pub fn branch_evidence(
    tree: &BranchTree,
    points: &Neighbours,
    leaves: Option<&Neighbours>,
    spacing: f64,
    test: &LeafPieceTest,
) -> Vec<BranchEvidence> {
    tree.branches
        .iter()
        .map(|branch| {
            let cylinder = &branch.cylinder;
            let length = cylinder.skeleton.length();
            let count = ((length / spacing.max(1e-12)).ceil() as usize).clamp(8, 4096);
            let samples = cylinder.skeleton.sample_by_arc_length(count);
            let last = (samples.len().max(2) - 1) as f64;
            let mut near_leaf = 0usize;
            let mut sections = Vec::new();
            for (k, (point, tangent)) in samples.iter().enumerate() {
                let radius = cylinder.radius_at(k as f64 / last);
                if let Some(leaves) = leaves
                    && leaves.nearest(point).is_some_and(|found| {
                        found.distance() <= radius + test.leaf_reach_spacings * spacing
                    })
                {
                    near_leaf += 1;
                }
                let reach = (test.section_radii * radius).max(test.section_spacings * spacing);
                let around: Vec<Point3<f64>> = points
                    .within_radius_unsorted(point, reach)
                    .iter()
                    .map(|found| points.point(found.index))
                    .collect();
                if let Some(q) = section_roundness(&around, point, tangent) {
                    sections.push(q);
                }
            }
            let roundness = (sections.len() >= MIN_SECTIONS)
                .then(|| crate::util::stats::median(sections.iter().copied()))
                .flatten();
            BranchEvidence {
                leaf_share: near_leaf as f64 / samples.len().max(1) as f64,
                roundness,
            }
        })
        .collect()
}

/// Width ratio `√(λ₂/λ₁)` of `around` projected on the plane through `centre` across
/// `tangent`: 1 for a full ring, about 0.44 for half of one, near 0 for a strip. `None` for
/// fewer than [`MIN_SECTION_POINTS`] points or no spread.
fn section_roundness(
    around: &[Point3<f64>],
    centre: &Point3<f64>,
    tangent: &Vector3<f64>,
) -> Option<f64> {
    if around.len() < MIN_SECTION_POINTS {
        return None;
    }
    let axis = tangent.try_normalize(1e-12)?;
    let u = crate::util::geometry::any_perpendicular(&axis);
    let v = axis.cross(&u);
    let projected: Vec<Vector2<f64>> = around
        .iter()
        .map(|p| {
            let d = p - centre;
            Vector2::new(d.dot(&u), d.dot(&v))
        })
        .collect();
    let mean = projected.iter().sum::<Vector2<f64>>() / projected.len() as f64;
    let covariance = projected
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum::<Matrix2<f64>>()
        / projected.len() as f64;
    let eigen = covariance.symmetric_eigenvalues();
    let (small, large) = (eigen.min(), eigen.max());
    (large > 0.0).then(|| (small.max(0.0) / large).sqrt())
}

/// Removes the side branches that are pieces of leaf and end the tree, repeatedly (see the
/// module docs). Root branches are never removed. Returns how many branches were removed.
pub fn prune_leaf_pieces(
    tree: &mut BranchTree,
    evidence: &[BranchEvidence],
    test: &LeafPieceTest,
) -> usize {
    let piece: std::collections::HashMap<u32, bool> = tree
        .branches
        .iter()
        .zip(evidence)
        .map(|(branch, e)| (branch.id, branch.parent.is_some() && test.is_leaf_piece(e)))
        .collect();
    let mut removed = 0;
    loop {
        let parents: std::collections::HashSet<u32> =
            tree.branches.iter().filter_map(|b| b.parent).collect();
        let before = tree.branches.len();
        tree.branches
            .retain(|b| parents.contains(&b.id) || !piece.get(&b.id).copied().unwrap_or(false));
        let gone = before - tree.branches.len();
        if gone == 0 {
            return removed;
        }
        removed += gone;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::branch::{Branch, GeneralizedCylinder, Spline};

    const SPACING: f64 = 0.001;

    fn branch(id: u32, parent: Option<u32>, a: [f64; 3], b: [f64; 3], radius: f64) -> Branch {
        let (a, b) = (Point3::from(a), Point3::from(b));
        Branch {
            id,
            parent,
            parent_fraction: 1.0,
            cylinder: GeneralizedCylinder::new(Spline::new(vec![a, b]).unwrap(), radius, radius),
            leaf_at_tip: false,
        }
    }

    /// Rings of points around the segment a–b, a point spacing apart along it and around.
    fn tube(a: [f64; 3], b: [f64; 3], radius: f64, arc: f64) -> Vec<Point3<f64>> {
        let (a, b) = (Point3::from(a), Point3::from(b));
        let axis = (b - a).normalize();
        let u = crate::util::geometry::any_perpendicular(&axis);
        let v = axis.cross(&u);
        let rings = ((b - a).norm() / SPACING) as usize;
        let around = ((arc * radius / SPACING).ceil() as usize).max(3);
        let mut out = Vec::new();
        for i in 0..=rings {
            for j in 0..around {
                let angle = arc * j as f64 / around as f64;
                out.push(
                    a + (b - a) * (i as f64 / rings as f64)
                        + (u * angle.cos() + v * angle.sin()) * radius,
                );
            }
        }
        out
    }

    /// A flat grid of points over x0..x1 × y0..y1 at height z, a point spacing apart.
    fn sheet(x: (f64, f64), y: (f64, f64), z: f64) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        let (nx, ny) = (
            ((x.1 - x.0) / SPACING) as usize,
            ((y.1 - y.0) / SPACING) as usize,
        );
        for i in 0..=nx {
            for j in 0..=ny {
                out.push(Point3::new(
                    x.0 + i as f64 * SPACING,
                    y.0 + j as f64 * SPACING,
                    z,
                ));
            }
        }
        out
    }

    #[test]
    fn cross_sections_tell_a_tube_half_a_tube_and_a_strip_apart() {
        let centre = Point3::new(0.0, 0.0, 0.005);
        let along = Vector3::z();
        let roundness =
            |points: &[Point3<f64>]| section_roundness(points, &centre, &along).unwrap();
        let full = tube([0.0; 3], [0.0, 0.0, 0.01], 0.003, std::f64::consts::TAU);
        let half = tube([0.0; 3], [0.0, 0.0, 0.01], 0.003, std::f64::consts::PI);
        let strip: Vec<Point3<f64>> = sheet((-0.005, 0.005), (0.0, 0.01), 0.0)
            .into_iter()
            .map(|p| Point3::new(p.x, 0.0002 * (p.y * 1e4).sin(), p.y))
            .collect();
        assert!(roundness(&full) > 0.95, "{}", roundness(&full));
        let q = roundness(&half);
        assert!((0.38..0.5).contains(&q), "{q}");
        assert!(roundness(&strip) < 0.1, "{}", roundness(&strip));
        assert_eq!(section_roundness(&full[..3], &centre, &along), None);
    }

    #[test]
    fn a_rim_along_a_leaf_and_a_strip_of_blade_are_pruned_and_a_petiole_is_not() {
        let tau = std::f64::consts::TAU;
        // Stem 0; petiole 1 ends at a leaf's base; rim 2 follows the leaf's edge; strip 3 is a
        // flat band of blade; strip 4 is as flat but carries the tube 5.
        let tree = BranchTree {
            branches: vec![
                branch(0, None, [0.0, 0.0, 0.0], [0.0, 0.0, 0.1], 0.005),
                branch(1, Some(0), [0.0, 0.0, 0.1], [0.1, 0.0, 0.15], 0.003),
                branch(2, Some(0), [0.1, 0.033, 0.15], [0.2, 0.033, 0.15], 0.002),
                branch(3, Some(0), [0.0, 0.0, 0.05], [-0.1, 0.0, 0.05], 0.002),
                branch(4, Some(0), [0.0, 0.0, 0.03], [0.0, -0.1, 0.03], 0.002),
                branch(5, Some(4), [0.0, -0.1, 0.03], [0.0, -0.1, 0.1], 0.003),
            ],
        };
        let mut points = tube([0.0, 0.0, 0.0], [0.0, 0.0, 0.1], 0.005, tau);
        points.extend(tube([0.0, 0.0, 0.1], [0.1, 0.0, 0.15], 0.003, tau));
        points.extend(tube([0.0, -0.1, 0.03], [0.0, -0.1, 0.1], 0.003, tau));
        points.extend(tube([0.1, 0.033, 0.15], [0.2, 0.033, 0.15], 0.002, tau));
        points.extend(sheet((-0.1, 0.0), (-0.006, 0.006), 0.05));
        points.extend(
            sheet((-0.006, 0.006), (-0.1, 0.0), 0.0)
                .into_iter()
                .map(|p| Point3::new(p.x, p.y, 0.03)),
        );
        let leaf = sheet((0.1, 0.2), (-0.03, 0.03), 0.15);
        let test = LeafPieceTest::default();
        let points = Neighbours::new(points).unwrap();
        let leaves = Neighbours::new(leaf).unwrap();
        let evidence = branch_evidence(&tree, &points, Some(&leaves), SPACING, &test);
        assert!(evidence[1].leaf_share < 0.2, "{:?}", evidence[1]);
        assert!(evidence[1].roundness.unwrap() > 0.8, "{:?}", evidence[1]);
        assert!(evidence[2].leaf_share > 0.95, "{:?}", evidence[2]);
        assert!(evidence[2].roundness.unwrap() > 0.8, "{:?}", evidence[2]);
        for flat in [3, 4] {
            assert_eq!(evidence[flat].leaf_share, 0.0);
            assert!(
                evidence[flat].roundness.unwrap() < 0.2,
                "{:?}",
                evidence[flat]
            );
        }

        let mut pruned = tree.clone();
        assert_eq!(prune_leaf_pieces(&mut pruned, &evidence, &test), 2);
        let kept: Vec<u32> = pruned.branches.iter().map(|b| b.id).collect();
        assert_eq!(kept, vec![0, 1, 4, 5]);
        // With the tube 5 a piece too, the strip 4 it hung from goes after it.
        let mut all = evidence.clone();
        all[5].leaf_share = 1.0;
        let mut pruned = tree.clone();
        assert_eq!(prune_leaf_pieces(&mut pruned, &all, &test), 4);
        assert_eq!(
            pruned.branches.iter().map(|b| b.id).collect::<Vec<_>>(),
            vec![0, 1]
        );
    }
}
