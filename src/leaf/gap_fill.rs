//! Gap fills for the leaf stage. `frond densify --fill-partners` adds points from further
//! stereo partners where the main partners' points leave a surface bare
//! ([`PointSet::gap_fill`]): mostly the weakly textured parts of leaves that one partner's
//! depth maps miss. The segmentation never sees them (a second partner's points along leaf
//! rims cost leaf precision there); the leaf stage does, so a leaf that stereo sampled in part
//! gets its points, plane, views and image region from more of its blade, and so does the
//! skeleton, with each fill point classed by what it continues ([`classes`]).
//!
//! Each fill point takes the label of the segmented points that reach it first along chains
//! of fill points: a geodesic Voronoi partition from every segmented point at once, edges no
//! longer than [`EDGE_SPACINGS`] point spacings. A leaf claims a fill point only near its own
//! plane and within its own extent of geodesic distance ([`LeafReach`]); floor, wall,
//! background and pot points claim it for no leaf, so a leaf does not grow across the soil.
//! The plant's other points (stems, and the band of stem-like points along leaf rims that the
//! foreground test leaves unsegmented) neither claim nor block: on photos of broadleaf seed 1
//! letting them block left 4,029 of 396,173 fill points on leaves, all growth stopping at the
//! rims. The labels follow the current segments, so edits carry over: the partition is
//! recomputed from the labels each time leaves are fitted.

use std::cmp::{Ordering, Reverse};
use std::collections::{BTreeMap, BinaryHeap};

use nalgebra::{Matrix3, Point3, Vector3};
use rayon::prelude::*;

use crate::graph::local_shape::median_spacing;
use crate::graph::neighbours::Neighbours;
use crate::graph::points::PointSet;
use crate::segment::foreground::PointClass;
use crate::segment::{Labels, SegmentLabel};

/// Longest step between fill points (and from a segmented point to a fill point), in the
/// segmented points' median spacing: fill points come from a fusion on the same voxel grid,
/// so neighbours on one surface lie about one spacing apart; 2.5 bridges a missing voxel and
/// not the gap between two leaves.
pub const EDGE_SPACINGS: f64 = 2.5;

/// A leaf claims fill points within this share of its extent of its plane (a leaf curves off
/// its plane by about this much at its tip; the fit's height field models the rest).
pub const PLANE_TOLERANCE: f64 = 0.15;

/// ... and never less than this many point spacings (stereo noise on a small leaf).
pub const MIN_PLANE_TOLERANCE_SPACINGS: f64 = 4.0;

/// Where a leaf segment may claim fill points: near its plane (least squares through its
/// points) and within its extent (twice its largest distance from its centroid) of geodesic
/// distance from its points: a leaf sampled on one half reaches its other half, not the next
/// leaf across a shared plane.
#[derive(Clone, Copy, Debug)]
struct LeafReach {
    centroid: Point3<f64>,
    normal: Vector3<f64>,
    tolerance: f64,
    extent: f64,
}

impl LeafReach {
    fn of(points: &[Point3<f64>], spacing: f64) -> Option<Self> {
        if points.len() < 3 {
            return None;
        }
        let n = points.len() as f64;
        let centroid = Point3::from(points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n);
        let mut covariance = Matrix3::zeros();
        for p in points {
            let d = p - centroid;
            covariance += d * d.transpose();
        }
        let eigen = (covariance / n).symmetric_eigen();
        let (smallest, _) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))?;
        let normal = eigen.eigenvectors.column(smallest).into_owned();
        let extent = 2.0
            * points
                .iter()
                .map(|p| (p - centroid).norm())
                .fold(0.0, f64::max);
        (normal.norm() > 0.0 && extent > 0.0).then(|| Self {
            centroid,
            normal: normal.normalize(),
            tolerance: (PLANE_TOLERANCE * extent).max(MIN_PLANE_TOLERANCE_SPACINGS * spacing),
            extent,
        })
    }

    fn admits(&self, p: &Point3<f64>, geodesic: f64) -> bool {
        geodesic <= self.extent && (p - self.centroid).dot(&self.normal).abs() <= self.tolerance
    }
}

/// A tentative claim on a fill point, popped nearest first (ties: lower fill point, then
/// lower label) so the partition is deterministic.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Claim {
    distance: f64,
    fill: u32,
    /// Leaf segment id, or −1 for no leaf.
    label: i32,
}

impl Eq for Claim {}

impl Ord for Claim {
    fn cmp(&self, other: &Self) -> Ordering {
        self.distance
            .total_cmp(&other.distance)
            .then(self.fill.cmp(&other.fill))
            .then(self.label.cmp(&other.label))
    }
}

impl PartialOrd for Claim {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// What a segmented point claims fill points for.
fn claim_of(labels: &Labels, classes: &[PointClass], i: usize) -> Option<i32> {
    match labels.label_of_point(i) {
        Some(SegmentLabel::Leaf) => Some(labels.segment_of[i]),
        Some(SegmentLabel::Pot) => Some(-1),
        _ => match classes.get(i) {
            Some(PointClass::Floor | PointClass::Wall | PointClass::Background) => Some(-1),
            _ => None,
        },
    }
}

/// A fill point's neighbourhood: the fill points within one edge (index, distance), and the
/// nearest segmented point within one edge of each claim (label, distance).
struct Around {
    fill_neighbours: Vec<(u32, f64)>,
    seeds: Vec<(i32, f64)>,
}

/// The leaf segment of each fill point under `labels` and the foreground `classes` (both of
/// `points`), −1 for none (see the module docs).
pub fn assign(
    points: &PointSet,
    labels: &Labels,
    classes: &[PointClass],
    fills: &PointSet,
) -> Vec<i32> {
    let mut assigned = vec![-1; fills.len()];
    let n = points.len().min(labels.segment_of.len());
    if fills.is_empty() || n == 0 {
        return assigned;
    }
    let spacing = median_spacing(points);
    if spacing.is_nan() || spacing <= 0.0 {
        return assigned;
    }
    // Each segmented point's claim: its leaf, no leaf, or none.
    let source: Vec<Option<i32>> = (0..n).map(|i| claim_of(labels, classes, i)).collect();
    let mut by_leaf: BTreeMap<i32, Vec<Point3<f64>>> = BTreeMap::new();
    for (i, s) in source.iter().enumerate() {
        if let Some(s) = s.filter(|&s| s >= 0) {
            by_leaf.entry(s).or_default().push(points.positions[i]);
        }
    }
    let reach: BTreeMap<i32, LeafReach> = by_leaf
        .iter()
        .filter_map(|(&s, p)| LeafReach::of(p, spacing).map(|r| (s, r)))
        .collect();
    let Ok(index) = Neighbours::new(
        points.positions[..n]
            .iter()
            .chain(&fills.positions)
            .copied(),
    ) else {
        return assigned;
    };
    let radius = EDGE_SPACINGS * spacing;
    // Per fill point: its fill neighbours and the nearest segmented point of each claim.
    let around: Vec<Around> = fills
        .positions
        .par_iter()
        .map(|p| {
            let mut fill_neighbours = Vec::new();
            let mut seeds: Vec<(i32, f64)> = Vec::new();
            for found in index.within_radius(p, radius) {
                let d = found.distance();
                if found.index >= n {
                    fill_neighbours.push(((found.index - n) as u32, d));
                } else if let Some(label) = source[found.index]
                    && !seeds.iter().any(|(l, _)| *l == label)
                {
                    seeds.push((label, d));
                }
            }
            Around {
                fill_neighbours,
                seeds,
            }
        })
        .collect();
    let mut heap = BinaryHeap::new();
    for (f, a) in around.iter().enumerate() {
        for &(label, distance) in &a.seeds {
            heap.push(Reverse(Claim {
                distance,
                fill: f as u32,
                label,
            }));
        }
    }
    let mut settled = vec![false; fills.len()];
    while let Some(Reverse(claim)) = heap.pop() {
        let f = claim.fill as usize;
        if settled[f] {
            continue;
        }
        if claim.label >= 0
            && !reach
                .get(&claim.label)
                .is_some_and(|r| r.admits(&fills.positions[f], claim.distance))
        {
            continue;
        }
        settled[f] = true;
        assigned[f] = claim.label;
        for &(g, d) in &around[f].fill_neighbours {
            if !settled[g as usize] {
                heap.push(Reverse(Claim {
                    distance: claim.distance + d,
                    fill: g,
                    label: claim.label,
                }));
            }
        }
    }
    let on_leaves = assigned.iter().filter(|&&s| s >= 0).count();
    let elsewhere = settled.iter().filter(|&&s| s).count() - on_leaves;
    tracing::debug!(
        "gap fills: {on_leaves} on leaves, {elsewhere} nearer other points, {} out of reach (spacing {spacing:.3e})",
        fills.len() - on_leaves - elsewhere
    );
    assigned
}

/// The foreground class of each fill point for the skeleton, given the leaf [`assign`] gave it
/// (`assigned`): a fill point on a leaf is a plant point (its leaf's sheet), any other takes the
/// class of the nearest segmented point within one edge ([`EDGE_SPACINGS`]), and is an outlier
/// beyond: a fill in a gap of a stem continues the stem, one in a gap of the floor the floor.
pub fn classes(
    points: &PointSet,
    classes: &[PointClass],
    fills: &PointSet,
    assigned: &[i32],
) -> Vec<PointClass> {
    let n = points.len().min(classes.len());
    let spacing = median_spacing(points);
    let index = Neighbours::new(points.positions[..n].iter().copied()).ok();
    fills
        .positions
        .par_iter()
        .enumerate()
        .map(|(k, p)| {
            if assigned.get(k).is_some_and(|&s| s >= 0) {
                return PointClass::Plant;
            }
            index
                .as_ref()
                .filter(|_| spacing > 0.0)
                .and_then(|index| index.nearest(p))
                .filter(|nearest| nearest.distance() <= EDGE_SPACINGS * spacing)
                .map_or(PointClass::Outlier, |nearest| classes[nearest.index])
        })
        .collect()
}

/// The points followed by the fill points (marked as gap fills), and the labels with each
/// fill point in the leaf [`assign`] gives it.
pub fn with_gap_fills(
    points: &PointSet,
    labels: &Labels,
    classes: &[PointClass],
    fills: &PointSet,
) -> (PointSet, Labels) {
    let assigned = assign(points, labels, classes, fills);
    let n = points.len();
    let mut all = points.subset(&(0..n).collect::<Vec<_>>());
    all.positions.extend(&fills.positions);
    all.colors.extend(&fills.colors);
    all.views.extend(fills.views.iter().cloned());
    all.point_ids.extend(&fills.point_ids);
    if !all.thin_organ.is_empty() || !fills.thin_organ.is_empty() {
        all.thin_organ = (0..n)
            .map(|i| points.is_thin_organ(i))
            .chain((0..fills.len()).map(|i| fills.is_thin_organ(i)))
            .collect();
    }
    all.gap_fill = (0..n)
        .map(|i| points.is_gap_fill(i))
        .chain(std::iter::repeat_n(true, fills.len()))
        .collect();
    let mut labels = labels.clone();
    labels.segment_of.resize(n, -1);
    labels.segment_of.extend(assigned);
    (all, labels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment::labels::SegmentState;

    /// A square grid of `side`² points at spacing 1 in the plane z = `z`, offset by `x0`.
    fn grid(side: usize, x0: f64, z: f64) -> Vec<Point3<f64>> {
        (0..side * side)
            .map(|k| Point3::new(x0 + (k % side) as f64, (k / side) as f64, z))
            .collect()
    }

    fn set(positions: Vec<Point3<f64>>) -> PointSet {
        PointSet {
            colors: vec![[0, 160, 0]; positions.len()],
            views: vec![vec![0]; positions.len()],
            point_ids: (0..positions.len() as u64).collect(),
            positions,
            ..PointSet::default()
        }
    }

    fn labels(segment_of: Vec<i32>, kinds: &[SegmentLabel]) -> Labels {
        Labels {
            segment_of,
            segments: kinds
                .iter()
                .map(|&label| {
                    Some(SegmentState {
                        label,
                        confirmed: false,
                    })
                })
                .collect(),
        }
    }

    #[test]
    fn a_leaf_sampled_on_one_half_takes_the_fills_of_its_other_half_and_no_others() {
        // Leaf 0: a sheet at z = 0 of which stereo sampled columns 0–7; fills continue it over
        // columns 8–21 to the floor, sampled at columns 22–24 in the same plane: the leaf takes
        // the fills nearer to it than to the floor (x < 14.5), the floor the rest. A stem (not
        // a leaf, not the floor) stands at x = 40 with fills around it, and a second sheet of
        // fills lies 10 units above the leaf (another leaf, not sampled).
        let mut main: Vec<Point3<f64>> = grid(20, 0.0, 0.0)
            .into_iter()
            .filter(|p| p.x < 8.0)
            .collect();
        let sampled = main.len();
        main.extend(grid(20, 22.0, 0.0).into_iter().filter(|p| p.x < 25.0));
        let floor = main.len() - sampled;
        main.extend(grid(3, 40.0, 0.0));
        let mut fills: Vec<Point3<f64>> = (0..20 * 14)
            .map(|k| Point3::new(8.0 + (k % 14) as f64, (k / 14) as f64, 0.0))
            .collect();
        let between = fills.len();
        fills.extend(grid(3, 43.0, 0.0));
        fills.extend(grid(20, 0.0, 10.0));
        let mut segment_of = vec![0; sampled];
        segment_of.extend(vec![-1; floor]);
        segment_of.extend(vec![1; 9]);
        let mut classes = vec![PointClass::Plant; sampled];
        classes.extend(vec![PointClass::Floor; floor]);
        classes.extend(vec![PointClass::Stem; 9]);
        let labels = labels(segment_of, &[SegmentLabel::Leaf, SegmentLabel::Stem]);
        let assigned = assign(&set(main.clone()), &labels, &classes, &set(fills.clone()));
        for (k, &s) in assigned[..between].iter().enumerate() {
            let x = fills[k].x;
            assert_eq!(s, if x < 14.5 { 0 } else { -1 }, "fill at x = {x}");
        }
        assert!(assigned[between..].iter().all(|&s| s == -1));

        let (all, extended) =
            with_gap_fills(&set(main.clone()), &labels, &classes, &set(fills.clone()));
        assert_eq!(all.len(), main.len() + fills.len());
        assert_eq!(extended.members(0).len(), sampled + 20 * 7);
        assert!(!all.is_gap_fill(0) && all.is_gap_fill(main.len()));
    }

    #[test]
    fn a_leaf_does_not_grow_off_its_plane_or_past_its_extent() {
        // Leaf 0 sampled on a 12×12 patch at z = 0 (extent 2 · 5.5√2 ≈ 15.6, plane tolerance
        // 4 spacings); fills continue it flat for 4 columns, then climb steeply (a leaf joined
        // at its edge, 2 up per step), and a long flat run of fills leaves along y = −1.
        let main = grid(12, 0.0, 0.0);
        let mut fills: Vec<Point3<f64>> = (0..12 * 4)
            .map(|k| Point3::new(12.0 + (k % 4) as f64, (k / 4) as f64, 0.0))
            .collect();
        let flat = fills.len();
        fills.extend((0..12 * 6).map(|k| {
            let step = (k % 6) as f64;
            Point3::new(16.0 + 0.3 * step, (k / 6) as f64, 2.0 + 2.0 * step)
        }));
        let steep = fills.len() - flat;
        fills.extend((0..60).map(|x| Point3::new(x as f64, -1.0, 0.0)));
        let labels = labels(vec![0; main.len()], &[SegmentLabel::Leaf]);
        let classes = vec![PointClass::Plant; main.len()];
        let assigned = assign(&set(main.clone()), &labels, &classes, &set(fills.clone()));
        assert!(assigned[..flat].iter().all(|&s| s == 0), "{assigned:?}");
        for k in flat..flat + steep {
            let height = fills[k].z;
            assert_eq!(
                assigned[k] == 0,
                height <= 4.0,
                "fill {k} at height {height}"
            );
        }
        // The run is claimed up to about the leaf's extent of path length, not to x = 59.
        let run = &assigned[flat + steep..];
        assert!(run[..20].iter().all(|&s| s == 0), "{run:?}");
        assert!(run[30..].iter().all(|&s| s == -1), "{run:?}");
    }

    #[test]
    fn fills_off_the_leaves_take_the_class_of_what_they_continue() {
        // A stem sampled at x = 0..4 and a floor patch at x = 20..24; fills continue each
        // (x = 5, 6 and x = 25), one lies on a leaf (assigned 0), one floats far from all.
        let main: Vec<Point3<f64>> = (0..5)
            .map(|x| Point3::new(x as f64, 0.0, 0.0))
            .chain((20..25).map(|x| Point3::new(x as f64, 0.0, 0.0)))
            .collect();
        let mut point_classes = vec![PointClass::Stem; 5];
        point_classes.extend(vec![PointClass::Floor; 5]);
        let fills = set(vec![
            Point3::new(5.0, 0.0, 0.0),
            Point3::new(6.0, 0.0, 0.0),
            Point3::new(25.0, 0.0, 0.0),
            Point3::new(21.0, 1.0, 0.0),
            Point3::new(50.0, 50.0, 0.0),
        ]);
        let assigned = [-1, -1, -1, 0, -1];
        let got = classes(&set(main), &point_classes, &fills, &assigned);
        assert_eq!(
            got,
            vec![
                PointClass::Stem,
                // 2 from the stem's end: within 2.5 spacings.
                PointClass::Stem,
                PointClass::Floor,
                PointClass::Plant,
                PointClass::Outlier,
            ]
        );
    }

    #[test]
    fn no_fills_or_no_leaves_assign_nothing() {
        let main = set(grid(5, 0.0, 0.0));
        let none = labels(vec![-1; main.len()], &[]);
        let classes = vec![PointClass::Plant; main.len()];
        assert!(assign(&main, &none, &classes, &PointSet::default()).is_empty());
        let fills = set(grid(5, 5.0, 0.0));
        assert!(
            assign(&main, &none, &classes, &fills)
                .iter()
                .all(|&s| s == -1)
        );
        assert!(
            assign(&PointSet::default(), &none, &[], &fills)
                .iter()
                .all(|&s| s == -1)
        );
    }
}
