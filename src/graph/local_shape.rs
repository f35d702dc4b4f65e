//! Local shape of the surface around each point, from the principal components of its k
//! nearest neighbours: how thick (`√(λ₃/λ₂)`) and how elongated (`√(λ₂/λ₁)`) the neighbourhood
//! is. Points on a leaf have flat neighbourhoods; points on a thin stem or petiole have
//! neighbourhoods that wrap around it: thick and elongated.

use nalgebra::Point3;
use rayon::prelude::*;

use super::neighbours::Neighbours;
use super::points::PointSet;
use super::shape::Shape;
use crate::util::stats::{self, median};

/// Local shape features of one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalShape {
    /// `√(λ₃/λ₂)`: 0 on a flat sheet, near 1 on a round blob or thin tube.
    pub thickness: f64,
    /// `√(λ₂/λ₁)`: near 0 along a line, near 1 on an isotropic patch.
    pub elongation: f64,
    pub normal: nalgebra::Vector3<f64>,
}

/// The principal-component shape of the neighbourhood of the tree's point `i`: the point and
/// its `k` nearest neighbours ([`Neighbours::around`]).
pub fn shape_around(neighbours: &Neighbours, i: usize, k: usize) -> Shape {
    let around = neighbours.around(i, k);
    Shape::of(around.iter().map(|n| neighbours.point(n.index)))
}

/// Each point's nearest neighbours in a point set, searched once with one k-d tree and shared
/// by the local features below, each of which reads as many of them as it needs: a feature of
/// `k` neighbours reads the first `k + 1` of a list (the point itself included), the same
/// points [`Neighbours::around`] gives for `k` (up to the order of points exactly as far).
pub struct Neighbourhoods {
    /// Points per list: `k + 1` for the largest `k` searched, at most all the points.
    per_point: usize,
    /// Row `i` (`per_point` entries): point `i`'s neighbours, nearest first.
    indices: Vec<u32>,
}

impl Neighbourhoods {
    /// The `k` nearest neighbours of every point and the point itself; `None` where the points
    /// cannot be indexed (none at all, or more than a `u32` can number).
    pub fn of(points: &PointSet, k: usize) -> Option<Self> {
        Self::of_positions(&points.positions, k)
    }

    /// [`Neighbourhoods::of`] points given by their positions alone.
    pub fn of_positions(positions: &[Point3<f64>], k: usize) -> Option<Self> {
        if u32::try_from(positions.len()).is_err() {
            return None;
        }
        let neighbours = Neighbours::new(positions.iter().copied()).ok()?;
        let per_point = (k + 1).min(neighbours.len()).max(1);
        let rows: Vec<Vec<u32>> = (0..neighbours.len())
            .into_par_iter()
            .map(|i| {
                let mut row: Vec<u32> = neighbours
                    .around(i, k)
                    .iter()
                    .map(|n| n.index as u32)
                    .collect();
                // Only an empty tree answers short; keep every row `per_point` long.
                row.resize(per_point, i as u32);
                row
            })
            .collect();
        Some(Self {
            per_point,
            indices: rows.concat(),
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.indices.len() / self.per_point
    }

    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// Point `i` and its `k` nearest neighbours (fewer where fewer were searched), nearest
    /// first, by index.
    pub fn around(&self, i: usize, k: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        let row = &self.indices[i * self.per_point..(i + 1) * self.per_point];
        row[..(k + 1).min(self.per_point)]
            .iter()
            .map(|&j| j as usize)
    }

    /// The principal-component shape of point `i`'s neighbourhood of `k` neighbours.
    fn shape(&self, positions: &[Point3<f64>], i: usize, k: usize) -> Shape {
        Shape::of(self.around(i, k).map(|j| positions[j]))
    }

    /// [`local_shapes`] of `points` (the points these neighbourhoods were searched among).
    pub fn shapes(&self, points: &PointSet, k: usize) -> Vec<LocalShape> {
        self.shapes_at(&points.positions, k)
    }

    /// [`Neighbourhoods::shapes`] of the points at `positions`.
    pub fn shapes_at(&self, positions: &[Point3<f64>], k: usize) -> Vec<LocalShape> {
        (0..self.len())
            .into_par_iter()
            .map(|i| {
                let shape = self.shape(positions, i, k);
                if shape.count < 4 {
                    return SHAPE_FALLBACK;
                }
                LocalShape {
                    thickness: shape.flatness(),
                    elongation: shape.width_ratio(),
                    normal: shape.normal(),
                }
            })
            .collect()
    }

    /// [`local_planes`] of `points` (the points these neighbourhoods were searched among).
    pub fn planes(&self, points: &PointSet, k: usize) -> Vec<LocalPlane> {
        (0..self.len())
            .into_par_iter()
            .map(|i| {
                let shape = self.shape(&points.positions, i, k);
                LocalPlane {
                    normal: shape.normal(),
                    rms: shape.eigenvalues[2].sqrt(),
                }
            })
            .collect()
    }

    /// [`Neighbourhoods::planes`] of the points `which` alone, in that order.
    pub fn planes_of(&self, points: &PointSet, which: &[usize], k: usize) -> Vec<LocalPlane> {
        which
            .par_iter()
            .map(|&i| {
                let shape = self.shape(&points.positions, i, k);
                LocalPlane {
                    normal: shape.normal(),
                    rms: shape.eigenvalues[2].sqrt(),
                }
            })
            .collect()
    }

    /// [`normal_coherence`] of the points' `normals` over `k` neighbours.
    pub fn normal_coherence(&self, normals: &[nalgebra::Vector3<f64>], k: usize) -> Vec<f64> {
        (0..self.len())
            .into_par_iter()
            .map(|i| {
                let mut agreement: Vec<f64> = self
                    .around(i, k)
                    .filter(|&j| j != i)
                    .map(|j| normals[j].dot(&normals[i]).abs())
                    .collect();
                if agreement.is_empty() {
                    return 1.0;
                }
                agreement.sort_by(f64::total_cmp);
                agreement[agreement.len() / 2]
            })
            .collect()
    }

    /// [`median_spacing`] of `points` (the points these neighbourhoods were searched among).
    pub fn median_spacing(&self, points: &PointSet) -> f64 {
        let distances: Vec<f64> = (0..self.len())
            .into_par_iter()
            .filter_map(|i| {
                self.around(i, 2)
                    .find(|&j| j != i)
                    .map(|j| (points.positions[j] - points.positions[i]).norm())
            })
            .collect();
        median(distances).unwrap_or(0.0)
    }
}

/// What [`local_shapes`] reports for a point of too few neighbours: a flat patch facing up.
const SHAPE_FALLBACK: LocalShape = LocalShape {
    thickness: 0.0,
    elongation: 1.0,
    normal: nalgebra::Vector3::new(0.0, 0.0, 1.0),
};

/// Local shapes of every point from its `k` nearest neighbours (itself included).
pub fn local_shapes(points: &PointSet, k: usize) -> Vec<LocalShape> {
    match Neighbourhoods::of(points, k) {
        Some(neighbourhoods) => neighbourhoods.shapes(points, k),
        None => vec![SHAPE_FALLBACK; points.len()],
    }
}

/// Unit normals from the principal components of each point's `k` nearest neighbours and
/// itself (unoriented; however few the points, unlike [`local_shapes`]).
pub fn estimate_normals(points: &PointSet, k: usize) -> Vec<nalgebra::Vector3<f64>> {
    local_planes(points, k)
        .into_iter()
        .map(|p| p.normal)
        .collect()
}

/// The best-fit plane of a point's neighbourhood.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalPlane {
    /// Unoriented unit normal.
    pub normal: nalgebra::Vector3<f64>,
    /// RMS distance of the neighbourhood from the plane, `√λ₃` (model units): the surface's
    /// noise where the neighbourhood lies on one smooth surface.
    pub rms: f64,
}

/// Best-fit planes of each point's `k` nearest neighbours and itself (a z-facing plane of zero
/// RMS where the points cannot be indexed).
pub fn local_planes(points: &PointSet, k: usize) -> Vec<LocalPlane> {
    match Neighbourhoods::of(points, k) {
        Some(neighbourhoods) => neighbourhoods.planes(points, k),
        None => vec![
            LocalPlane {
                normal: nalgebra::Vector3::z(),
                rms: 0.0,
            };
            points.len()
        ],
    }
}

/// How consistently the surface around each point faces one way (stems are found where the
/// tube radius is under about twice the point spacing; thicker stems look locally like sheets
/// and are told apart per segment instead): the median, over the point's
/// `k` nearest neighbours, of `|n_i · n_p|` for small-scale normals `normals`. Near 1 on a leaf
/// (even beside another surface, which holds a minority of the neighbours); low on a thin stem,
/// whose normals turn all the way around within the neighbourhood.
pub fn normal_coherence(
    points: &PointSet,
    normals: &[nalgebra::Vector3<f64>],
    k: usize,
) -> Vec<f64> {
    match Neighbourhoods::of(points, k) {
        Some(neighbourhoods) => neighbourhoods.normal_coherence(normals, k),
        None => vec![1.0; points.len()],
    }
}

/// Median distance from each point to its nearest other point (0 for fewer than 2 points).
pub fn median_spacing(points: &PointSet) -> f64 {
    Neighbourhoods::of(points, 2)
        .map_or(0.0, |neighbourhoods| neighbourhoods.median_spacing(points))
}

/// Points simulated on a [`FlatSheet`].
const SIMULATED_SHEET_POINTS: usize = 3000;

/// A flat square sheet in the xy-plane sampled uniformly at random (a Poisson process whose
/// median nearest-neighbour distance is `spacing`), with isotropic Gaussian noise `sigma`.
fn simulated_sheet(spacing: f64, sigma: f64) -> PointSet {
    // A planar Poisson process of density ρ has median nearest-neighbour distance
    // √(ln 2 / (π ρ)).
    let density = std::f64::consts::LN_2 / (std::f64::consts::PI * spacing * spacing);
    let side = (SIMULATED_SHEET_POINTS as f64 / density).sqrt();
    let mut rng = crate::util::rng::Rng::seed_from(0x5eed_5eed);
    let positions: Vec<nalgebra::Point3<f64>> = (0..SIMULATED_SHEET_POINTS)
        .map(|_| {
            let (x, y) = (rng.uniform() * side, rng.uniform() * side);
            nalgebra::Point3::new(
                x + rng.normal() * sigma,
                y + rng.normal() * sigma,
                rng.normal() * sigma,
            )
        })
        .collect();
    let n = positions.len();
    PointSet {
        positions,
        colors: vec![[0; 3]; n],
        views: vec![Vec::new(); n],
        point_ids: (0..n as u64).collect(),
        id_kind: Default::default(),
        thin_organ: Vec::new(),
        gap_fill: Vec::new(),
    }
}

/// Neighbours of the local planes whose RMS [`FlatSheet::like`] matches.
pub const PLANE_NEIGHBOURS: usize = 10;

/// A simulated flat sheet sampled like measured points: at random with their median
/// nearest-neighbour distance, and with the isotropic noise whose median local plane RMS (over
/// [`PLANE_NEIGHBOURS`]) is theirs. What a flat leaf's points would show at that noise, for the
/// tests whose fixed thresholds assume clean normals.
pub struct FlatSheet {
    points: PointSet,
}

impl FlatSheet {
    /// The sheet for a median spacing `spacing` and median plane RMS `plane_rms` (the noise
    /// found by bisection); `None` unless both are positive.
    pub fn like(spacing: f64, plane_rms: f64) -> Option<Self> {
        let measured = spacing > 0.0 && plane_rms > 0.0;
        if !measured {
            return None;
        }
        let sheet_rms = |sigma: f64| {
            let sheet = simulated_sheet(spacing, sigma);
            median(local_planes(&sheet, PLANE_NEIGHBOURS).iter().map(|p| p.rms)).unwrap_or(0.0)
        };
        // The plane RMS grows with the noise: bisect for the noise that gives the measured one.
        let (mut low, mut high) = (0.0, 4.0 * plane_rms);
        for _ in 0..12 {
            let middle = 0.5 * (low + high);
            if sheet_rms(middle) < plane_rms {
                low = middle;
            } else {
                high = middle;
            }
        }
        Some(Self {
            points: simulated_sheet(spacing, 0.5 * (low + high)),
        })
    }

    /// The normal coherence ([`normal_coherence`] over `coherence_k` neighbours of normals
    /// from `normal_k` neighbours) that all but a fraction `share` of the sheet's points reach.
    /// Near 1 where the noise is small against the spacing; where it is not, a flat leaf's
    /// normals scatter and a fixed coherence threshold would call it a stem.
    pub fn coherence(&self, normal_k: usize, coherence_k: usize, share: f64) -> f64 {
        let normals: Vec<nalgebra::Vector3<f64>> = local_shapes(&self.points, normal_k)
            .iter()
            .map(|s| s.normal)
            .collect();
        let mut coherence = normal_coherence(&self.points, &normals, coherence_k);
        stats::quantile(&mut coherence, share)
    }

    /// How a flat sheet's neighbourhoods of `k` points look at this spacing and noise: the
    /// elongation ([`LocalShape::elongation`]) all but a fraction `share` of its points reach,
    /// and the thickness ([`LocalShape::thickness`]) all but that fraction stay under. A point
    /// whose neighbourhood is more line-like or thicker than that is not on a sheet.
    pub fn local_shape_bounds(&self, k: usize, share: f64) -> (f64, f64) {
        let shapes = local_shapes(&self.points, k);
        let mut elongation: Vec<f64> = shapes.iter().map(|s| s.elongation).collect();
        let mut thickness: Vec<f64> = shapes.iter().map(|s| s.thickness).collect();
        (
            stats::quantile(&mut elongation, share),
            stats::quantile(&mut thickness, 1.0 - share),
        )
    }

    /// Mean `|n · z|` of the sheet's normals from `normal_k` neighbours against its true normal:
    /// how far noise alone lowers a leaf's facing.
    pub fn facing(&self, normal_k: usize) -> f64 {
        let normals = local_planes(&self.points, normal_k);
        normals.iter().map(|p| p.normal.z.abs()).sum::<f64>() / normals.len().max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::test_support::{patch, tube};
    use nalgebra::{Point3, Vector3};

    fn set(positions: Vec<Point3<f64>>) -> PointSet {
        let n = positions.len();
        PointSet {
            positions,
            colors: vec![[0; 3]; n],
            views: vec![vec![0]; n],
            point_ids: (0..n as u64).collect(),
            id_kind: Default::default(),
            thin_organ: Vec::new(),
            gap_fill: Vec::new(),
        }
    }

    #[test]
    fn tubes_are_incoherent_and_sheets_coherent() {
        // A tube whose radius is under twice the point spacing: its neighbourhoods wrap around.
        let tube = set(tube(Point3::origin(), 0.0025, 0.2, 0.0015));
        let normals: Vec<_> = local_shapes(&tube, 8).iter().map(|s| s.normal).collect();
        let coherence = normal_coherence(&tube, &normals, 20);
        let low = coherence.iter().filter(|&&c| c < 0.9).count();
        assert!(
            low as f64 > 0.9 * tube.len() as f64,
            "{low} of {}",
            tube.len()
        );

        let sheet = set(patch(
            Point3::origin(),
            Vector3::x(),
            Vector3::y(),
            40,
            0.0015,
        ));
        let normals: Vec<_> = local_shapes(&sheet, 8).iter().map(|s| s.normal).collect();
        let coherence = normal_coherence(&sheet, &normals, 20);
        assert!(coherence.iter().all(|&c| c > 0.99));
    }

    #[test]
    fn a_flat_sheets_neighbourhoods_bound_lines_out_and_let_sheets_in() {
        let spacing = 0.002;
        let sheet = FlatSheet::like(spacing, 0.0003).unwrap();
        let (min_elongation, max_thickness) = sheet.local_shape_bounds(8, 0.05);
        assert!(
            min_elongation > 0.2 && min_elongation < 0.9,
            "{min_elongation}"
        );
        assert!(
            max_thickness > 0.0 && max_thickness < 0.6,
            "{max_thickness}"
        );
        // A twig sampled as a line of points is too narrow for a sheet.
        let line = set((0..40)
            .map(|k| Point3::new(k as f64 * spacing, 0.0001 * (k % 3) as f64, 0.0))
            .collect());
        let line_shapes = local_shapes(&line, 8);
        assert!(line_shapes.iter().all(|s| s.elongation < min_elongation));
        // Most points of a bent sheet sampled at that spacing pass both bounds.
        let bent = set((0..900)
            .map(|k| {
                let (x, y) = ((k % 30) as f64 * spacing, (k / 30) as f64 * spacing);
                Point3::new(x, y, 2.0 * x * x)
            })
            .collect());
        let passing = local_shapes(&bent, 8)
            .iter()
            .filter(|s| s.elongation >= min_elongation && s.thickness <= max_thickness)
            .count();
        assert!(
            passing * 10 >= bent.len() * 9,
            "{passing} of {}",
            bent.len()
        );
    }

    #[test]
    fn one_neighbour_search_gives_every_feature_of_fewer_neighbours() {
        // A noisy sheet beside a tube, at random (no two points exactly as far from a third).
        let mut rng = crate::util::rng::Rng::seed_from(5);
        let mut positions: Vec<Point3<f64>> = (0..600)
            .map(|_| {
                Point3::new(
                    rng.uniform() * 0.05,
                    rng.uniform() * 0.05,
                    rng.normal() * 2e-4,
                )
            })
            .collect();
        positions.extend(
            tube(Point3::new(0.07, 0.02, 0.0), 0.002, 0.03, 0.001)
                .into_iter()
                .map(|p| p + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 1e-5),
        );
        let points = set(positions);
        let tree = Neighbours::new(points.positions.iter().copied()).unwrap();
        let shared = Neighbourhoods::of(&points, 20).unwrap();
        assert_eq!(shared.len(), points.len());
        for k in [1, 2, 8, 10, 20] {
            for i in 0..points.len() {
                let own: Vec<usize> = tree.around(i, k).iter().map(|n| n.index).collect();
                assert_eq!(
                    shared.around(i, k).collect::<Vec<_>>(),
                    own,
                    "point {i}, k {k}"
                );
            }
        }
        // More than were searched: all that were.
        assert_eq!(shared.around(0, 50).count(), 21);
        assert_eq!(shared.shapes(&points, 8), local_shapes(&points, 8));
        assert_eq!(shared.planes(&points, 10), local_planes(&points, 10));
        let normals: Vec<Vector3<f64>> =
            shared.shapes(&points, 8).iter().map(|s| s.normal).collect();
        assert_eq!(
            shared.normal_coherence(&normals, 20),
            normal_coherence(&points, &normals, 20)
        );
        assert_eq!(shared.median_spacing(&points), median_spacing(&points));
        // Some points' planes alone, in the order asked; the same search from positions alone.
        let which = [599, 3, 640, 0, 3];
        let all_planes = shared.planes(&points, 10);
        let some: Vec<LocalPlane> = which.iter().map(|&i| all_planes[i]).collect();
        assert_eq!(shared.planes_of(&points, &which, 10), some);
        let from_positions = Neighbourhoods::of_positions(&points.positions, 20).unwrap();
        assert_eq!(from_positions.indices, shared.indices);
        assert_eq!(
            from_positions.shapes_at(&points.positions, 8),
            shared.shapes(&points, 8)
        );
        // Fewer points than neighbours wanted: every list holds them all.
        let few = set(points.positions[..5].to_vec());
        let all = Neighbourhoods::of(&few, 20).unwrap();
        assert!((0..5).all(|i| all.around(i, 20).count() == 5));
        assert!(Neighbourhoods::of(&set(Vec::new()), 20).is_none_or(|n| n.is_empty()));
    }

    #[test]
    fn median_spacing_of_a_grid_is_its_step() {
        let grid = set(patch(
            Point3::origin(),
            Vector3::x(),
            Vector3::y(),
            20,
            0.002,
        ));
        assert!((median_spacing(&grid) - 0.002).abs() < 1e-9);
        assert_eq!(median_spacing(&set(vec![Point3::origin()])), 0.0);
    }

    #[test]
    fn a_flat_sheet_like_noisy_points_has_their_plane_rms_and_scattered_normals() {
        assert!(FlatSheet::like(0.0, 0.001).is_none());
        assert!(FlatSheet::like(0.001, 0.0).is_none());
        let spacing = 0.0015;
        let mut coherences = Vec::new();
        let mut facings = Vec::new();
        for rms in [0.0001, 0.0003, 0.0005] {
            let sheet = FlatSheet::like(spacing, rms).expect("sheet");
            // The bisection found the noise that gives the asked plane RMS.
            let measured = median(
                local_planes(&sheet.points, PLANE_NEIGHBOURS)
                    .iter()
                    .map(|p| p.rms),
            )
            .expect("points");
            assert!((measured - rms).abs() < 0.05 * rms, "{measured} for {rms}");
            // And its spacing is the asked one, give or take what the noise adds.
            let simulated_spacing = median_spacing(&sheet.points);
            assert!(
                (simulated_spacing - spacing).abs() < 0.25 * spacing,
                "{simulated_spacing}"
            );
            coherences.push(sheet.coherence(8, 20, 0.05));
            facings.push(sheet.facing(PLANE_NEIGHBOURS));
        }
        // Low noise: a flat sheet is coherent and faces one way; more noise lowers both.
        assert!(coherences[0] > 0.95, "{coherences:?}");
        assert!(
            coherences[0] > coherences[1] && coherences[1] > coherences[2],
            "{coherences:?}"
        );
        assert!(facings[0] > 0.99, "{facings:?}");
        assert!(
            facings[0] > facings[1] && facings[1] > facings[2],
            "{facings:?}"
        );
    }
}
