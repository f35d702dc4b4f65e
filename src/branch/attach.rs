//! Leaves meet branches (seed 004 §7–8): each reconstructed leaf is joined to its nearest
//! branch by a petiole, leaf segments too small to fit (fewer than 3 points) are posed as the
//! average leaf from their nearest branch, and branches marked "leaf at tip" grow the average
//! leaf scaled by their thickness.

use nalgebra::{Point2, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::compound::LeafOnBranch;
use super::{BranchTree, GeneralizedCylinder, Spline};
use crate::leaf::fit::{Affine2, LeafFrame};
use crate::leaf::{LeafReconstruction, LeafTemplate};
use crate::mesh::{TriMesh, point_triangle_distance};
use crate::util::stats::median;

/// A leaf base within this many radii of its branch's surface needs no petiole.
const TOUCHING_RADII: f64 = 2.0;
/// Petiole radius at the branch, as a share of the branch's radius there, at most this share
/// of the leaf's length.
const PETIOLE_RADIUS_SHARE: f64 = 0.6;
const PETIOLE_RADIUS_PER_LENGTH: f64 = 0.03;

/// A petiole joining a leaf's base to a branch.
#[derive(Clone, Debug, Serialize)]
pub struct Petiole {
    /// The leaf (segment id).
    pub leaf: u32,
    pub branch: u32,
    pub parent_fraction: f64,
    #[serde(skip)]
    pub cylinder: GeneralizedCylinder,
    pub length: f64,
}

impl Petiole {
    /// The petiole as a branch of the model, numbered `id`, hanging from its branch.
    pub fn as_branch(&self, id: u32) -> super::Branch {
        super::Branch {
            id,
            parent: Some(self.branch),
            parent_fraction: self.parent_fraction,
            cylinder: self.cylinder.clone(),
            leaf_at_tip: false,
        }
    }
}

/// Why a synthesized leaf is there.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PosedKind {
    /// A leaf segment with too few points to fit.
    SmallSegment,
    /// A branch marked "leaf at tip".
    BranchTip,
}

/// The average leaf placed by the branch structure.
#[derive(Clone, Debug, Serialize)]
pub struct PosedLeaf {
    pub kind: PosedKind,
    /// The segment (small segments) or the branch (tips).
    pub source: u32,
    pub branch: u32,
    pub base: [f64; 3],
    pub tip: [f64; 3],
    pub length: f64,
    #[serde(skip)]
    pub mesh: TriMesh,
    #[serde(skip)]
    pub texture: image::RgbaImage,
}

/// The average reconstructed leaf: median length and width-to-length ratio of the fits.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AverageLeaf {
    pub length: f64,
    /// Width scale over length scale of the template→leaf map.
    pub aspect: f64,
    /// Median radius of the branches where leaves attach (for scaling tip leaves).
    pub attachment_radius: Option<f64>,
}

/// What attaching leaves produced.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Attachment {
    pub petioles: Vec<Petiole>,
    pub posed: Vec<PosedLeaf>,
    pub average: Option<AverageLeaf>,
    /// Leaves whose base already touches a branch.
    pub touching: usize,
    /// Where every fitted leaf sits on the branch it is attached to (directly or by its
    /// petiole).
    pub on_branches: Vec<LeafOnBranch>,
    /// Branches ended where a leaf's blade begins before the leaves were attached
    /// ([`end_branches_at_blades`]).
    pub blade_ends: BladeEnds,
}

/// The template laid flat in a frame with its base at the origin, scaled to `length` and
/// `aspect`, as a mesh with the template's texture.
fn average_leaf_mesh(
    template: &LeafTemplate,
    base: &Point3<f64>,
    direction: &Vector3<f64>,
    up: &Vector3<f64>,
    length: f64,
    aspect: f64,
) -> Option<(TriMesh, Point3<f64>)> {
    let x_axis = direction.try_normalize(1e-12)?;
    let y_axis = up
        .cross(&x_axis)
        .try_normalize(1e-9)
        .unwrap_or_else(|| super::any_perpendicular(&x_axis));
    let normal = x_axis.cross(&y_axis);
    let frame = LeafFrame {
        origin: *base,
        x_axis,
        y_axis,
        normal,
    };
    let base_y = template.midrib[0].y;
    let affine = Affine2 {
        matrix: nalgebra::Matrix2::new(length, 0.0, 0.0, length * aspect),
        translation: nalgebra::Vector2::new(0.0, -length * aspect * base_y),
    };
    let (mut mesh, flat) = template.mesh(12, 7);
    for (vertex, p) in mesh.positions.iter_mut().zip(&flat) {
        *vertex = frame.to_world(&affine.apply(p), 0.0).cast::<f32>();
    }
    mesh.compute_normals();
    let tip_y = template.midrib[template.midrib.len() - 1].y;
    let tip = frame.to_world(&affine.apply(&Point2::new(1.0, tip_y)), 0.0);
    Some((mesh, tip))
}

/// Joins leaves to branches (see the module docs). `small_segments` are the leaf segments
/// the leaf stage left for the branch stage, with their points; `up` is the plant's up.
pub fn attach_leaves(
    tree: &BranchTree,
    leaves: &LeafReconstruction,
    small_segments: &[(u32, Vec<Point3<f64>>)],
    up: &Vector3<f64>,
) -> Attachment {
    let mut attachment = Attachment::default();
    if tree.branches.is_empty() {
        return attachment;
    }
    let mut attachment_radii = Vec::new();
    for leaf in &leaves.leaves {
        let base = Point3::from(leaf.fit.base);
        let Some(anchor) = tree.closest(&base) else {
            continue;
        };
        attachment_radii.push(anchor.radius);
        attachment.on_branches.push(LeafOnBranch {
            leaf: leaf.segment,
            branch: anchor.branch,
            parent_fraction: anchor.fraction,
            base_world: leaf.fit.base,
            tip_world: leaf.fit.tip,
        });
        if anchor.distance <= TOUCHING_RADII * anchor.radius.max(1e-9) {
            attachment.touching += 1;
            continue;
        }
        let radius_start = (PETIOLE_RADIUS_SHARE * anchor.radius)
            .min(PETIOLE_RADIUS_PER_LENGTH * leaf.fit.length)
            .max(1e-6);
        let Ok(skeleton) = Spline::new(vec![anchor.position, base]) else {
            continue;
        };
        let cylinder = GeneralizedCylinder::new(skeleton, radius_start, 0.75 * radius_start);
        attachment.petioles.push(Petiole {
            leaf: leaf.segment,
            branch: anchor.branch,
            parent_fraction: anchor.fraction,
            length: cylinder.length(),
            cylinder,
        });
    }
    let lengths: Vec<f64> = leaves.leaves.iter().map(|l| l.fit.length).collect();
    let aspects: Vec<f64> = leaves
        .leaves
        .iter()
        .map(|l| {
            let m = &l.fit.affine.matrix;
            m.column(1).norm() / m.column(0).norm().max(1e-12)
        })
        .collect();
    let (Some(length), Some(aspect)) = (median(lengths), median(aspects)) else {
        return attachment;
    };
    let average = AverageLeaf {
        length,
        aspect,
        attachment_radius: median(attachment_radii),
    };
    attachment.average = Some(average);

    // Small segments: the average leaf from the nearest branch toward the points.
    for (segment, points) in small_segments {
        if points.is_empty() {
            continue;
        }
        let centroid = Point3::from(
            points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len() as f64,
        );
        if !centroid.iter().all(|c| c.is_finite()) {
            continue;
        }
        let Some(anchor) = tree.closest(&centroid) else {
            continue;
        };
        let toward = centroid - anchor.position;
        let direction = if toward.norm() > 1e-9 {
            toward
        } else {
            // On the branch: straight out, perpendicular to it.
            up.cross(&anchor.tangent)
        };
        let Some(direction) = direction.try_normalize(1e-12) else {
            continue;
        };
        let base = anchor.position + direction * anchor.radius;
        if let Some((mesh, tip)) =
            average_leaf_mesh(&leaves.template, &base, &direction, up, length, aspect)
        {
            attachment.posed.push(PosedLeaf {
                kind: PosedKind::SmallSegment,
                source: *segment,
                branch: anchor.branch,
                base: base.into(),
                tip: tip.into(),
                length,
                mesh,
                texture: leaves.template.texture.clone(),
            });
        }
    }

    // Tips: the average leaf scaled by the branch's thickness, along the branch's direction.
    for branch in tree.branches.iter().filter(|b| b.leaf_at_tip) {
        let Some(tip_point) = tree.point_on(branch.id, 1.0) else {
            continue;
        };
        let scale = average
            .attachment_radius
            .filter(|r| *r > 0.0)
            .map_or(1.0, |r| (tip_point.radius / r).clamp(0.25, 2.0));
        let leaf_length = length * scale;
        if let Some((mesh, tip)) = average_leaf_mesh(
            &leaves.template,
            &tip_point.position,
            &tip_point.tangent,
            up,
            leaf_length,
            aspect,
        ) {
            attachment.posed.push(PosedLeaf {
                kind: PosedKind::BranchTip,
                source: branch.id,
                branch: branch.id,
                base: tip_point.position.into(),
                tip: tip.into(),
                length: leaf_length,
                mesh,
                texture: leaves.template.texture.clone(),
            });
        }
    }
    attachment
}

/// A branch sample this near a fitted leaf's surface, as a share of the leaf's length, lies
/// on its blade ([`end_branches_at_blades`]).
const ON_BLADE_SHARE: f64 = 0.05;
/// Within this share of a leaf's length of its base a branch is where the leaf meets it, not
/// on its blade.
const BASE_SHARE: f64 = 0.1;
/// Samples along each branch (equally spaced by arc length) for [`end_branches_at_blades`].
const BLADE_SAMPLES: usize = 200;

/// What [`end_branches_at_blades`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BladeEnds {
    /// Branches whose end was cut back to where the blade begins.
    pub trimmed: usize,
    /// Branches that lay on a blade from base to tip and were dropped.
    pub removed: usize,
    /// Length taken off, world units.
    pub length: f64,
}

/// A fitted leaf's surface with the bounding sphere that culls distance queries.
struct Blade<'a> {
    mesh: &'a TriMesh,
    centre: Point3<f32>,
    radius: f32,
    base: Point3<f64>,
    near: f64,
    margin: f64,
}

impl Blade<'_> {
    /// Whether `p` lies on the blade: within `near` of its surface, farther than `margin` from
    /// its base.
    fn holds(&self, p: &Point3<f64>) -> bool {
        if (p - self.base).norm() < self.margin {
            return false;
        }
        let q = p.cast::<f32>();
        if (q - self.centre).norm() - self.radius > self.near as f32 {
            return false;
        }
        (0..self.mesh.triangles.len()).any(|t| {
            let [a, b, c] = self.mesh.corners(t);
            f64::from(point_triangle_distance(&q, &a, &b, &c)) <= self.near
        })
    }
}

/// Ends every branch that runs on over a fitted leaf's blade where the blade begins (seed 004
/// §7: a leaf hangs from the end of its petiole). From photos the skeleton follows leaf points
/// the segmentation left out of their leaf (a leaf's unlabelled edge, a piece of a leaf too
/// small to be one) past the leaf's base and across its blade; measured on broadleaf seeds 1,
/// 7, 8, 21 and 22, 100–330 mm per plant of skeleton off every true stem and petiole lay on a
/// leaf, most of it on the last 30 % of a branch. A branch sample is on a blade when it lies
/// within [`ON_BLADE_SHARE`] of the leaf's length of its surface and farther than
/// [`BASE_SHARE`] of it from its base. A branch without children loses the run of samples on
/// blades that ends at its tip; one on blades from base to tip is dropped, and its parent is
/// looked at again. The stem (a branch without parent) is never dropped.
pub fn end_branches_at_blades(
    tree: &BranchTree,
    leaves: &LeafReconstruction,
) -> (BranchTree, BladeEnds) {
    let mut ends = BladeEnds::default();
    let blades: Vec<Blade> = leaves
        .leaves
        .iter()
        .filter(|l| !l.fit.mesh.triangles.is_empty() && l.fit.length > 0.0)
        .filter_map(|l| {
            let mesh = &l.fit.mesh;
            let (lo, hi) = mesh.bounds()?;
            let centre = nalgebra::center(&lo, &hi);
            let radius = mesh
                .positions
                .iter()
                .map(|p| (p - centre).norm())
                .fold(0.0f32, f32::max);
            Some(Blade {
                mesh,
                centre,
                radius,
                base: Point3::from(l.fit.base),
                near: ON_BLADE_SHARE * l.fit.length,
                margin: BASE_SHARE * l.fit.length,
            })
        })
        .collect();
    let mut tree = tree.clone();
    if blades.is_empty() {
        return (tree, ends);
    }
    let mut visited = std::collections::BTreeSet::new();
    loop {
        let next = tree.branches.iter().find(|b| {
            !visited.contains(&b.id) && !tree.branches.iter().any(|c| c.parent == Some(b.id))
        });
        let Some(branch) = next else {
            break;
        };
        let (id, parent, cylinder) = (branch.id, branch.parent, branch.cylinder.clone());
        visited.insert(id);
        let length = cylinder.length();
        let samples = cylinder.skeleton.sample_by_arc_length(BLADE_SAMPLES);
        let last = samples.len() - 1;
        // The run of samples on blades that ends at the tip, or that ends short of it by at
        // most its blade's margin (a branch overshooting the blade's edge into its halo).
        let holder = |p: &Point3<f64>| blades.iter().find(|b| b.holds(p));
        let step = length / last.max(1) as f64;
        let overshoot = samples
            .iter()
            .rev()
            .take_while(|(p, _)| holder(p).is_none())
            .count();
        let Some(first_held) = samples.get(last.saturating_sub(overshoot)) else {
            continue;
        };
        let within_margin =
            holder(&first_held.0).is_some_and(|blade| overshoot as f64 * step <= blade.margin);
        if overshoot > last || !within_margin {
            continue;
        }
        let on_blade = overshoot
            + samples
                .iter()
                .rev()
                .skip(overshoot)
                .take_while(|(p, _)| holder(p).is_some())
                .count();
        if on_blade < 2 {
            continue;
        }
        if on_blade > last {
            if let Some(parent) = parent {
                ends.removed += 1;
                ends.length += length;
                tree.branches.retain(|b| b.id != id);
                // The parent may now end on a blade too.
                visited.remove(&parent);
            }
            continue;
        }
        let fraction = (last + 1 - on_blade) as f64 / last as f64;
        let skeleton = &cylinder.skeleton;
        let cut = skeleton.point_at_fraction(fraction);
        let mut control: Vec<Point3<f64>> = skeleton
            .control_points()
            .iter()
            .copied()
            .filter(|p| skeleton.closest_fraction(p).0 < fraction - 1e-9)
            .collect();
        control.push(cut);
        let Ok(shortened) = Spline::new(control) else {
            continue;
        };
        let radius_end = cylinder.radius_at(fraction);
        let radius_start = cylinder.radius_start;
        let kept = shortened.length();
        if let Some(b) = tree.branches.iter_mut().find(|b| b.id == id) {
            b.cylinder = GeneralizedCylinder::new(shortened, radius_start, radius_end);
            ends.trimmed += 1;
            ends.length += (length - kept).max(0.0);
        }
    }
    (tree, ends)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::branch::Branch;
    use crate::leaf::fit::{FittedLeaf, HeightField};
    use crate::leaf::{LeafTimings, ReconstructedLeaf};

    fn template() -> LeafTemplate {
        let outline: Vec<Point2<f64>> = (0..64)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 64.0;
                Point2::new(0.5 + 0.5 * t.cos(), 0.2 * t.sin())
            })
            .collect();
        LeafTemplate::from_outline(&outline, LeafTemplate::plain_texture(8)).unwrap()
    }

    /// A vertical stem 0.5 long, radius 0.01 → 0.005, tip leaf wanted.
    fn stem() -> BranchTree {
        BranchTree {
            branches: vec![Branch {
                id: 0,
                parent: None,
                parent_fraction: 0.0,
                cylinder: GeneralizedCylinder::new(
                    Spline::new(vec![Point3::origin(), Point3::new(0.0, 0.0, 0.5)]).unwrap(),
                    0.01,
                    0.005,
                ),
                leaf_at_tip: true,
            }],
        }
    }

    fn fitted(base: [f64; 3], length: f64) -> FittedLeaf {
        FittedLeaf {
            frame: LeafFrame {
                origin: Point3::from(base),
                x_axis: Vector3::x(),
                y_axis: Vector3::y(),
                normal: Vector3::z(),
            },
            affine: Affine2 {
                matrix: nalgebra::Matrix2::new(length, 0.0, 0.0, 0.5 * length),
                translation: nalgebra::Vector2::zeros(),
            },
            heights: HeightField::flat(),
            mesh: TriMesh::default(),
            texture: image::RgbaImage::new(1, 1),
            points: 100,
            point_residual: 0.0,
            icp: None,
            boundary_area: None,
            outline_area: 0.0,
            length,
            base,
            tip: [base[0] + length, base[1], base[2]],
            area: 0.0,
            textured_fraction: 0.0,
            notes: Vec::new(),
        }
    }

    fn reconstruction(leaves: Vec<FittedLeaf>) -> LeafReconstruction {
        LeafReconstruction {
            template_source: None,
            template: template(),
            leaves: leaves
                .into_iter()
                .enumerate()
                .map(|(k, fit)| ReconstructedLeaf {
                    segment: k as u32,
                    view: None,
                    fit,
                })
                .collect(),
            gap_fills: 0,
            gap_fills_on_leaves: 0,
            skipped: Vec::new(),
            unusable_views: Vec::new(),
            boundaries: Default::default(),
            timings: LeafTimings::default(),
        }
    }

    #[test]
    fn petioles_join_leaf_bases_to_the_nearest_branch_point() {
        let leaves = reconstruction(vec![
            fitted([0.1, 0.0, 0.3], 0.1),
            // Touching the stem: no petiole.
            fitted([0.012, 0.0, 0.2], 0.08),
        ]);
        let attachment = attach_leaves(&stem(), &leaves, &[], &Vector3::z());
        assert_eq!(attachment.petioles.len(), 1);
        assert_eq!(attachment.touching, 1);
        let petiole = &attachment.petioles[0];
        assert_eq!((petiole.leaf, petiole.branch), (0, 0));
        assert!((petiole.parent_fraction - 0.6).abs() < 1e-3);
        assert!((petiole.length - 0.1).abs() < 1e-3);
        let ends = petiole.cylinder.skeleton.control_points();
        assert!((ends[1] - Point3::new(0.1, 0.0, 0.3)).norm() < 1e-12);
        // min(0.6 × the stem's radius there (0.007), 3 % of the leaf's length).
        assert!((petiole.cylinder.radius_start - 0.003).abs() < 1e-12);
    }

    #[test]
    fn small_segments_and_tips_get_the_average_leaf() {
        let leaves = reconstruction(vec![
            fitted([0.1, 0.0, 0.3], 0.1),
            fitted([0.0, 0.1, 0.2], 0.12),
            fitted([-0.1, 0.0, 0.25], 0.14),
        ]);
        let small = vec![(7, vec![Point3::new(0.0, -0.05, 0.4)])];
        let attachment = attach_leaves(&stem(), &leaves, &small, &Vector3::z());
        let average = attachment.average.unwrap();
        assert!((average.length - 0.12).abs() < 1e-12);
        assert!((average.aspect - 0.5).abs() < 1e-12);
        assert_eq!(attachment.posed.len(), 2);
        let posed = &attachment.posed[0];
        assert_eq!((posed.kind, posed.source), (PosedKind::SmallSegment, 7));
        // From the stem toward the point, the average length.
        let (base, tip) = (Point3::from(posed.base), Point3::from(posed.tip));
        assert!((base - Point3::new(0.0, -0.01 * 0.2 - 0.005 * 0.8, 0.4)).norm() < 1e-3);
        assert!(((tip - base).norm() - 0.12).abs() < 1e-6);
        assert!((tip - base).normalize().dot(&-Vector3::y()) > 0.999);
        assert!(!posed.mesh.triangles.is_empty());
        // The tip leaf grows along the stem, scaled by tip radius / attachment radius.
        let tip_leaf = &attachment.posed[1];
        assert_eq!(tip_leaf.kind, PosedKind::BranchTip);
        let expected = 0.12 * (0.005 / average.attachment_radius.unwrap()).clamp(0.25, 2.0);
        assert!((tip_leaf.length - expected).abs() < 1e-12);
        assert!((Point3::from(tip_leaf.base) - Point3::new(0.0, 0.0, 0.5)).norm() < 1e-9);
        assert!(Point3::from(tip_leaf.tip).z > 0.5 + 0.9 * expected);
    }

    #[test]
    fn no_branches_no_attachment() {
        let leaves = reconstruction(vec![fitted([0.1, 0.0, 0.3], 0.1)]);
        let attachment = attach_leaves(&BranchTree::default(), &leaves, &[], &Vector3::z());
        assert!(attachment.petioles.is_empty() && attachment.posed.is_empty());
    }

    /// A flat blade over x ∈ [x0, x0 + length], y ∈ [−length/4, length/4] at height z, its
    /// base at (x0, 0, z).
    fn blade(x0: f64, z: f64, length: f64) -> FittedLeaf {
        let mut leaf = fitted([x0, 0.0, z], length);
        let (x1, w) = ((x0 + length) as f32, (0.25 * length) as f32);
        let (x0, z) = (x0 as f32, z as f32);
        leaf.mesh = TriMesh {
            positions: vec![
                Point3::new(x0, -w, z),
                Point3::new(x1, -w, z),
                Point3::new(x1, w, z),
                Point3::new(x0, w, z),
            ],
            normals: Vec::new(),
            uvs: Vec::new(),
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        leaf
    }

    fn straight(id: u32, parent: Option<u32>, from: [f64; 3], to: [f64; 3]) -> Branch {
        Branch {
            id,
            parent,
            parent_fraction: 0.6,
            cylinder: GeneralizedCylinder::new(
                Spline::new(vec![Point3::from(from), Point3::from(to)]).unwrap(),
                0.004,
                0.002,
            ),
            leaf_at_tip: false,
        }
    }

    #[test]
    fn branches_end_where_a_leaf_blade_begins() {
        // A leaf 0.1 long with its base at x = 0.1 on the side branch's line (z = 0.3).
        let leaves = reconstruction(vec![blade(0.1, 0.3, 0.1)]);
        let mut tree = stem();
        tree.branches[0].leaf_at_tip = false;
        // Runs over the blade and 4 mm past its edge (within the 10 mm margin).
        tree.branches
            .push(straight(1, Some(0), [0.0, 0.0, 0.3], [0.204, 0.0, 0.3]));
        // Lies on the blade from end to end.
        tree.branches.push(straight(
            2,
            Some(0),
            [0.13, 0.01, 0.301],
            [0.18, 0.01, 0.301],
        ));
        // Passes 3 cm above the blade (farther than 5 % of its length): kept whole.
        tree.branches
            .push(straight(3, Some(0), [0.0, 0.0, 0.33], [0.2, 0.0, 0.33]));
        let (ended, ends) = end_branches_at_blades(&tree, &leaves);
        assert_eq!((ends.trimmed, ends.removed), (1, 1), "{ends:?}");
        assert!(ended.get(2).is_none());
        let cut = ended.get(1).unwrap();
        // Cut where the blade begins: 10 mm (the base margin) past the leaf's base.
        let length = cut.cylinder.length();
        assert!((length - 0.11).abs() < 0.002, "{length}");
        assert!(cut.cylinder.radius_end < 0.004 && cut.cylinder.radius_end > 0.002);
        assert_eq!(ended.get(3), tree.get(3));
        assert_eq!(ended.get(0), tree.get(0));
        let expected = (0.204 - length) + 0.05;
        assert!((ends.length - expected).abs() < 0.002, "{ends:?}");
        // A branch overshooting the blade by more than the margin is left alone, as is
        // every branch without fitted leaves.
        let mut far = stem();
        far.branches
            .push(straight(1, Some(0), [0.0, 0.0, 0.3], [0.25, 0.0, 0.3]));
        assert_eq!(
            end_branches_at_blades(&far, &leaves).1,
            BladeEnds::default()
        );
        let none = reconstruction(Vec::new());
        assert_eq!(end_branches_at_blades(&tree, &none).0, tree);
    }
}
