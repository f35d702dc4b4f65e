//! Pieces of one leaf joined across a gap. From photos, stereo samples a small leaf in patches,
//! and the stem test takes a band of its points (a fold, a noisy strip): the leaf then reaches
//! the leaf test as two or three segments a few point spacings apart, often none of which holds
//! half of the leaf, or as most of the leaf and a fragment of it (a tip, a lobe). Region
//! merging (the sheet merge of [`super::automatic`]) needs a shared border in the kNN graph and
//! never sees them. Two leaf segments larger than a crumb are joined when at least one of them
//! is a piece (smaller than half the plant's typical leaf), they lie within a few spacings of
//! each other, their union is no longer than the plant's typical or longer leaves
//! ([`longest_leaf_length`]), and the union is about as smooth a sheet as the rougher of the
//! two alone: pieces of one leaf continue one surface, while neighbouring leaves meet at an
//! angle or at another height and their union is rougher than either. On medium photo plants
//! (seeds 5 and 9, where the rule was found) the union of two pieces of one leaf had 0.93–1.2
//! times the rougher piece's absolute residual, that of two neighbouring leaves 1.25–5.5 times.

use std::collections::HashMap;

use nalgebra::Point3;
use rayon::prelude::*;

use super::automatic::{MIN_SHARE_OF_TYPICAL_LEAF, Segment, SegmentLabel, typical_leaf_points};
use crate::graph::neighbours::Neighbours;
use crate::graph::shape::Shape;

/// A leaf segment with fewer points than this share of the plant's typical leaf
/// ([`typical_leaf_points`]) may be a piece of a leaf: the pieces of a split leaf each hold at
/// most half of it, and true leaves vary about twofold in length around the typical one.
pub const PIECE_SHARE_OF_TYPICAL_LEAF: f64 = 0.5;

/// Two pieces of one leaf lie within this many point spacings of each other (nearest points):
/// the band the stem test takes along a fold or the gap stereo leaves is a few spacings wide.
pub const PIECE_GAP_SPACINGS: f64 = 5.0;

/// The union of two pieces of one leaf is a sheet whose absolute (cubic height-field) residual
/// is at most this many times that of the rougher of the two: one surface continued.
pub const PIECE_UNION_ROUGHNESS: f64 = 1.2;

/// How long the union of two joined segments may be: as long as the plant's typical leaf
/// (the length of the leaf segment of typical size, `typical` points) or as its longer
/// leaves, whichever is longer. The longer leaves' length is the size-weighted upper quartile
/// of the lengths of the leaf segments that are no pieces (`pieces` points or more): the
/// length below which three quarters of their points lie, in segments ordered by length. The
/// plant's leaves vary in length, and a leaf longer than the typical one splits as easily.
/// With the typical leaf's length alone, one segment's, the pieces of longer leaves stayed
/// apart (medium photos, seed 5: two leaves in two pieces each, unions 3 and 9 % longer than
/// that segment, roughness growth 1.02 and 1.05). Infinite without leaf segments to measure.
fn longest_leaf_length(segments: &[Segment], typical: f64, pieces: f64) -> f64 {
    let typical_length = segments
        .iter()
        .filter(|s| s.label == SegmentLabel::Leaf && s.num_points as f64 == typical)
        .map(|s| s.shape.length())
        .next();
    let mut lengths: Vec<(f64, usize)> = segments
        .iter()
        .filter(|s| s.label == SegmentLabel::Leaf && s.num_points as f64 >= pieces)
        .map(|s| (s.shape.length(), s.num_points))
        .collect();
    lengths.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let total: usize = lengths.iter().map(|l| l.1).sum();
    let mut seen = 0;
    let mut upper_quartile = None;
    for (length, size) in lengths {
        seen += size;
        if 4 * seen >= 3 * total {
            upper_quartile = Some(length);
            break;
        }
    }
    match (typical_length, upper_quartile) {
        (Some(a), Some(b)) => a.max(b),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => f64::INFINITY,
    }
}

/// A group's absolute roughness: the RMS residual of its cubic height field, in model units
/// (infinite for fewer than 10 points).
fn roughness(positions: &[Point3<f64>], members: &[u32]) -> (Shape, f64) {
    let points = members.iter().map(|&i| positions[i as usize]);
    let shape = Shape::of(points.clone());
    let relative = shape.cubic_sheet_residual(points);
    (shape, relative * shape.length())
}

/// What [`join_leaf_pieces`] measures of a leaf segment.
struct Member {
    /// Search tree over its points (`None` without points).
    tree: Option<Neighbours>,
    /// Bounding sphere: centroid and radius.
    centre: Point3<f64>,
    radius: f64,
    /// Absolute roughness ([`roughness`]).
    rough: f64,
}

impl Member {
    fn of(positions: &[Point3<f64>], members: &[u32]) -> Self {
        let sum = members.iter().fold(nalgebra::Vector3::zeros(), |acc, &i| {
            acc + positions[i as usize].coords
        });
        let centre = Point3::from(sum / members.len().max(1) as f64);
        let radius = members
            .iter()
            .map(|&i| (positions[i as usize] - centre).norm())
            .fold(0.0, f64::max);
        Self {
            tree: Neighbours::new(members.iter().map(|&i| positions[i as usize])).ok(),
            centre,
            radius,
            rough: roughness(positions, members).1,
        }
    }
}

/// Two leaf segments (points and measures) that [`join_leaf_pieces`] may join.
struct Pair<'a> {
    a: (&'a [u32], &'a Member),
    b: (&'a [u32], &'a Member),
}

impl Pair<'_> {
    /// The roughness growth of the union (its roughness over the rougher segment's) where the
    /// pair may be joined: one of them is a piece (fewer than `limit` points), their nearest
    /// points lie within `gap`, the union is no longer than `longest` and grows rough by at
    /// most [`PIECE_UNION_ROUGHNESS`]. `None` otherwise.
    fn union_growth(
        &self,
        positions: &[Point3<f64>],
        limit: f64,
        gap: f64,
        longest: f64,
    ) -> Option<f64> {
        let ((points_a, ma), (points_b, mb)) = (self.a, self.b);
        if points_a.len().min(points_b.len()) as f64 >= limit {
            return None;
        }
        if (ma.centre - mb.centre).norm() > ma.radius + mb.radius + gap
            || !(ma.rough.is_finite() && mb.rough.is_finite())
        {
            return None;
        }
        // The smaller segment's points against the larger one's tree; only those within
        // `gap` of the larger one's bounding sphere can come that near.
        let (small, large) = if points_a.len() <= points_b.len() {
            (points_a, mb)
        } else {
            (points_b, ma)
        };
        let tree = large.tree.as_ref()?;
        let reach = large.radius + gap;
        let near = small.iter().any(|&i| {
            let p = &positions[i as usize];
            (p - large.centre).norm() <= reach && tree.nearest_one(p).distance() <= gap
        });
        if !near {
            return None;
        }
        let union: Vec<u32> = points_a.iter().chain(points_b).copied().collect();
        let (shape, union_rough) = roughness(positions, &union);
        let growth = union_rough / ma.rough.max(mb.rough).max(1e-300);
        (growth <= PIECE_UNION_ROUGHNESS && shape.length() <= longest).then_some(growth)
    }
}

/// Joins pieces of one leaf (see the module docs) among the leaf-labelled `segments`, in place,
/// smoothest union first and again until nothing joins (a leaf in three pieces becomes one):
/// the later segment's points go to the earlier one, the emptied segment is removed and the ids
/// and `point_segment` (segment index per point) renumbered. `spacing` is the points' median
/// spacing. Returns the number of joins.
pub fn join_leaf_pieces(
    segments: &mut Vec<Segment>,
    point_segment: &mut [Option<u32>],
    positions: &[Point3<f64>],
    spacing: f64,
) -> usize {
    if spacing.is_nan() || spacing <= 0.0 {
        return 0;
    }
    let typical = typical_leaf_points(segments);
    let limit = PIECE_SHARE_OF_TYPICAL_LEAF * typical;
    let least = MIN_SHARE_OF_TYPICAL_LEAF * typical;
    let longest = longest_leaf_length(segments, typical, limit);
    let gap = PIECE_GAP_SPACINGS * spacing;
    let mut joins = 0;
    // Per segment, kept until a join changes it: its points' search tree, bounding sphere
    // (centroid, radius, to skip pairs that cannot come near) and roughness.
    let mut cache: Vec<Option<Member>> = (0..segments.len()).map(|_| None).collect();
    let mut verdicts: HashMap<(usize, usize), Option<f64>> = HashMap::new();
    loop {
        // Leaf segments above the crumb floor; of any two joined, one is a piece.
        let members: Vec<usize> = (0..segments.len())
            .filter(|&s| {
                let size = segments[s].points.len() as f64;
                segments[s].label == SegmentLabel::Leaf && size >= least.max(1.0)
            })
            .collect();
        for &s in &members {
            if cache[s].is_none() {
                cache[s] = Some(Member::of(positions, &segments[s].points));
            }
        }
        // Candidate joins, smoothest union first. A pair's verdict depends on its two
        // segments alone: one kept from an earlier round holds until a join changes either.
        let mut fresh: Vec<(usize, usize)> = Vec::new();
        for (k, &a) in members.iter().enumerate() {
            for &b in &members[k + 1..] {
                if !verdicts.contains_key(&(a, b)) {
                    fresh.push((a, b));
                }
            }
        }
        let judged: Vec<Option<f64>> = fresh
            .par_iter()
            .map(|&(a, b)| {
                let (Some(ma), Some(mb)) = (&cache[a], &cache[b]) else {
                    return None;
                };
                let pair = Pair {
                    a: (&segments[a].points, ma),
                    b: (&segments[b].points, mb),
                };
                pair.union_growth(positions, limit, gap, longest)
            })
            .collect();
        verdicts.extend(fresh.into_iter().zip(judged));
        let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
        for (k, &a) in members.iter().enumerate() {
            for &b in &members[k + 1..] {
                if let Some(Some(growth)) = verdicts.get(&(a, b)) {
                    candidates.push((*growth, a, b));
                }
            }
        }
        candidates.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
        let mut touched = vec![false; segments.len()];
        let mut any = false;
        for (_, a, b) in candidates {
            if touched[a] || touched[b] {
                continue;
            }
            let taken = std::mem::take(&mut segments[b].points);
            segments[a].points.extend(taken);
            segments[a].points.sort_unstable();
            touched[a] = true;
            touched[b] = true;
            joins += 1;
            any = true;
        }
        if !any {
            break;
        }
        verdicts.retain(|&(a, b), _| !(touched[a] || touched[b]));
        for (s, segment) in segments.iter_mut().enumerate() {
            if touched[s] {
                cache[s] = None;
                if !segment.points.is_empty() {
                    segment.shape =
                        Shape::of(segment.points.iter().map(|&i| positions[i as usize]));
                    segment.num_points = segment.points.len();
                }
            }
        }
    }
    if joins == 0 {
        return 0;
    }
    // Drop the emptied segments and renumber: every point first follows its segment's new
    // index, then each kept segment claims its points (those of the pieces it took included).
    let mut new_index = vec![None; segments.len()];
    let mut next = 0u32;
    for (s, segment) in segments.iter().enumerate() {
        if !segment.points.is_empty() {
            new_index[s] = Some(next);
            next += 1;
        }
    }
    for slot in point_segment.iter_mut() {
        if let Some(old) = *slot {
            *slot = new_index.get(old as usize).copied().flatten();
        }
    }
    segments.retain(|segment| !segment.points.is_empty());
    for (id, segment) in segments.iter_mut().enumerate() {
        segment.id = id as u32;
        for &i in &segment.points {
            if let Some(slot) = point_segment.get_mut(i as usize) {
                *slot = Some(segment.id);
            }
        }
    }
    joins
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic noise in [−1, 1] from an index.
    fn jitter(i: usize) -> f64 {
        let x = (i as u64)
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((x >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// The bend of the test leaves (mm of rise per mm² along the length, over `a`).
    const BEND: f64 = 0.02;

    /// Grid points (1 mm apart) of an elliptic leaf with half-axes `a`, `b` (mm), bent along its
    /// length by `bend`, lifted by `height` and moved by `shift` (mm), leaving out
    /// `|x − gap_at| < gap/2`; 0.1 mm of noise across the blade. Metres.
    fn leaf(
        a: f64,
        b: f64,
        shift: [f64; 2],
        height: f64,
        gap_at: f64,
        gap: f64,
        bend: f64,
    ) -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let (na, nb) = (a.ceil() as i32, b.ceil() as i32);
        for i in -na..=na {
            for j in -nb..=nb {
                let (x, y) = (f64::from(i), f64::from(j));
                if (x / a).powi(2) + (y / b).powi(2) > 1.0 || (x - gap_at).abs() < gap / 2.0 {
                    continue;
                }
                let z = height
                    + bend * x * x / a
                    + 0.1 * jitter(points.len() + (1000.0 * (shift[0] + height)) as usize);
                points.push(Point3::new(x + shift[0], y + shift[1], z) * 1e-3);
            }
        }
        points
    }

    /// Leaf segments over `groups` of points (one point set), with `point_segment` filled.
    fn segments_of(
        groups: &[Vec<Point3<f64>>],
    ) -> (Vec<Segment>, Vec<Option<u32>>, Vec<Point3<f64>>) {
        let mut positions = Vec::new();
        let mut segments = Vec::new();
        let mut point_segment = Vec::new();
        for (id, group) in groups.iter().enumerate() {
            let start = positions.len() as u32;
            positions.extend(group.iter().copied());
            let points: Vec<u32> = (start..positions.len() as u32).collect();
            point_segment.extend(std::iter::repeat_n(Some(id as u32), group.len()));
            segments.push(Segment {
                id: id as u32,
                label: SegmentLabel::Leaf,
                leaf_id: None,
                num_points: points.len(),
                shape: Shape::of(group.iter().copied()),
                points,
            });
        }
        (segments, point_segment, positions)
    }

    /// Two large leaves set the plant's typical leaf (about 1,500 points each).
    fn typical_leaves() -> Vec<Vec<Point3<f64>>> {
        vec![
            leaf(30.0, 16.0, [100.0, 0.0], 0.0, 1e9, 0.0, BEND),
            leaf(30.0, 16.0, [-100.0, 0.0], 0.0, 1e9, 0.0, BEND),
        ]
    }

    fn halves(points: Vec<Point3<f64>>) -> [Vec<Point3<f64>>; 2] {
        let (left, right): (Vec<_>, Vec<_>) = points.into_iter().partition(|p| p.x < 0.0);
        [left, right]
    }

    #[test]
    fn pieces_of_one_leaf_split_by_a_band_are_joined() {
        // A small leaf (about 300 points) with a 3 mm band across its middle taken out.
        let [left, right] = halves(leaf(12.0, 8.0, [0.0, 0.0], 0.0, 0.0, 3.0, BEND));
        let (n_left, n_right) = (left.len(), right.len());
        let mut groups = typical_leaves();
        groups.push(left);
        groups.push(right);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        let joins = join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3);
        assert_eq!(joins, 1);
        assert_eq!(segments.len(), 3);
        let joined = &segments[2];
        assert_eq!(joined.num_points, n_left + n_right);
        assert_eq!(joined.points.len(), n_left + n_right);
        for (s, segment) in segments.iter().enumerate() {
            assert_eq!(segment.id as usize, s);
            for &i in &segment.points {
                assert_eq!(point_segment[i as usize], Some(s as u32));
            }
        }
    }

    #[test]
    fn a_leaf_in_three_pieces_becomes_one_over_two_rounds() {
        // Bands 3 mm wide taken out at x = ±5 mm: three pieces, the outer two 13 mm apart.
        // One round joins the middle piece to one side; the pair it leaves is judged again
        // in the next round (the union changed), and the third piece joins it.
        let points: Vec<Point3<f64>> = leaf(18.0, 8.0, [0.0, 0.0], 0.0, -5.0, 3.0, BEND)
            .into_iter()
            .filter(|p| (p.x * 1e3 - 5.0).abs() >= 1.5)
            .collect();
        let (left, rest): (Vec<_>, Vec<_>) = points.into_iter().partition(|p| p.x < -0.005);
        let (right, middle): (Vec<_>, Vec<_>) = rest.into_iter().partition(|p| p.x > 0.005);
        let total = left.len() + middle.len() + right.len();
        let mut groups = typical_leaves();
        groups.extend([left, middle, right]);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        let joins = join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3);
        assert_eq!(joins, 2);
        assert_eq!(segments.len(), 3);
        assert_eq!(segments[2].num_points, total);
        for (s, segment) in segments.iter().enumerate() {
            for &i in &segment.points {
                assert_eq!(point_segment[i as usize], Some(s as u32));
            }
        }
    }

    #[test]
    fn a_neighbouring_leaf_at_another_height_is_not_joined() {
        // Two small leaves side by side, 3 mm apart across and 3 mm apart in height (nearer
        // than the gap): two leaves of one whorl, not one leaf.
        let near = leaf(12.0, 6.0, [0.0, 0.0], 0.0, 1e9, 0.0, BEND);
        let far = leaf(12.0, 6.0, [0.0, 15.0], 3.0, 1e9, 0.0, BEND);
        let closest = near
            .iter()
            .flat_map(|p| far.iter().map(move |q| (p - q).norm()))
            .fold(f64::INFINITY, f64::min);
        assert!(closest < PIECE_GAP_SPACINGS * 1e-3, "{closest}");
        let mut groups = typical_leaves();
        groups.push(near);
        groups.push(far);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        let before = point_segment.clone();
        assert_eq!(
            join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3),
            0
        );
        assert_eq!(segments.len(), 4);
        assert_eq!(point_segment, before);
    }

    #[test]
    fn pieces_farther_apart_than_the_gap_are_not_joined() {
        let [left, right] = halves(leaf(12.0, 8.0, [0.0, 0.0], 0.0, 0.0, 8.0, BEND));
        let mut groups = typical_leaves();
        groups.push(left);
        groups.push(right);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        assert_eq!(
            join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3),
            0
        );
    }

    #[test]
    fn a_union_longer_than_the_typical_leaf_is_not_joined() {
        // Two narrow leaflets end to end across a 3 mm rachis, in one plane: each a piece by
        // size, together longer than the typical leaf.
        let mut groups = typical_leaves();
        groups.push(leaf(20.0, 3.0, [-21.5, 40.0], 0.0, 1e9, 0.0, 0.0));
        groups.push(leaf(20.0, 3.0, [21.5, 40.0], 0.0, 1e9, 0.0, 0.0));
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        assert_eq!(
            join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3),
            0
        );
    }

    #[test]
    fn pieces_of_a_leaf_longer_than_the_typical_one_are_joined() {
        // Whole leaves of 60 mm (the typical one) and of 80 mm; a narrow 70 mm leaf split
        // across its middle: each half is a piece, the union longer than the typical leaf
        // but no longer than the plant's longer leaves.
        let mut groups = typical_leaves();
        groups.push(leaf(30.0, 16.0, [0.0, -100.0], 0.0, 1e9, 0.0, BEND));
        groups.push(leaf(40.0, 16.0, [100.0, 100.0], 0.0, 1e9, 0.0, BEND));
        groups.push(leaf(40.0, 16.0, [-100.0, 100.0], 0.0, 1e9, 0.0, BEND));
        let [left, right] = halves(leaf(35.0, 6.0, [0.0, 0.0], 0.0, 0.0, 3.0, BEND));
        let (n_left, n_right) = (left.len(), right.len());
        groups.push(left);
        groups.push(right);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        let typical = typical_leaf_points(&segments);
        let typical_length = segments
            .iter()
            .find(|s| s.num_points as f64 == typical)
            .map(|s| s.shape.length())
            .unwrap();
        let union = Shape::of(
            positions[positions.len() - n_left - n_right..]
                .iter()
                .copied(),
        );
        assert!(union.length() > typical_length, "{}", union.length());
        assert!(
            (n_left.max(n_right) as f64) < PIECE_SHARE_OF_TYPICAL_LEAF * typical,
            "{n_left} {n_right} {typical}"
        );
        let joins = join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3);
        assert_eq!(joins, 1);
        assert_eq!(segments.len(), 6);
        assert_eq!(segments[5].num_points, n_left + n_right);
    }

    #[test]
    fn a_fragment_beside_the_rest_of_its_leaf_is_joined() {
        // A typical-size leaf whose tip (past x = 18 mm) stereo cut off by a 3 mm band: most
        // of the leaf in one segment, its tip a piece beside it.
        let whole = leaf(30.0, 16.0, [0.0, 0.0], 0.0, 18.0, 3.0, BEND);
        let (body, tip): (Vec<_>, Vec<_>) = whole.into_iter().partition(|p| p.x < 0.018);
        let (n_body, n_tip) = (body.len(), tip.len());
        let mut groups = typical_leaves();
        groups.push(body);
        groups.push(tip);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        let typical = typical_leaf_points(&segments);
        assert!(
            (n_body as f64) >= PIECE_SHARE_OF_TYPICAL_LEAF * typical,
            "{n_body}"
        );
        assert!(
            (n_tip as f64) < PIECE_SHARE_OF_TYPICAL_LEAF * typical,
            "{n_tip}"
        );
        let joins = join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3);
        assert_eq!(joins, 1);
        assert_eq!(segments.len(), 3);
        assert_eq!(segments[2].num_points, n_body + n_tip);
    }

    #[test]
    fn a_small_leaf_beside_a_large_one_at_an_angle_is_not_joined() {
        // A small leaf 3 mm beside a large leaf's side, rising from it at 40° (both along x):
        // two leaves, though their union is no longer than the large one.
        let large = leaf(30.0, 16.0, [0.0, 0.0], 0.0, 1e9, 0.0, BEND);
        let (sin, cos) = 40f64.to_radians().sin_cos();
        let small: Vec<Point3<f64>> = leaf(12.0, 6.0, [0.0, 0.0], 0.0, 1e9, 0.0, 0.0)
            .into_iter()
            .map(|p| {
                let (x, across) = (p.x * 1e3, p.y * 1e3 + 6.0);
                let base = BEND * x * x / 30.0;
                Point3::new(x, 19.0 + across * cos, base + across * sin + p.z * 1e3) * 1e-3
            })
            .collect();
        let closest = small
            .iter()
            .flat_map(|p| large.iter().map(move |q| (p - q).norm()))
            .fold(f64::INFINITY, f64::min);
        assert!(closest < PIECE_GAP_SPACINGS * 1e-3, "{closest}");
        let mut groups = typical_leaves();
        groups.push(large);
        groups.push(small);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        assert_eq!(
            join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3),
            0
        );
        assert_eq!(segments.len(), 4);
    }

    #[test]
    fn crumbs_are_not_joined_into_a_leaf() {
        // Two crumbs of about 30 points each (2 % of the typical leaf) beside each other.
        let [left, right] = halves(leaf(4.0, 3.0, [0.0, 0.0], 0.0, 0.0, 1.5, BEND));
        assert!(left.len() < 40 && right.len() < 40);
        let mut groups = typical_leaves();
        groups.push(left);
        groups.push(right);
        let (mut segments, mut point_segment, positions) = segments_of(&groups);
        assert_eq!(
            join_leaf_pieces(&mut segments, &mut point_segment, &positions, 1e-3),
            0
        );
    }
}
