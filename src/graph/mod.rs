//! The weighted point graph of seed 004 §5.1 and its partition into leaves.
//!
//! A node per 3D point; edges to the K nearest neighbours in 3D ([`neighbours`]), kept only when both
//! ends are seen together in at least one view. Each edge carries
//! `d = (1−α)·d3D/(√2σ3D) + α·d2D/(√2σ2D)` and weight `w = exp(−d²)`, where `d2D` is the
//! largest colour gradient crossed by the edge's projection over the common views. Edges with
//! `d3D ≥ kσ3D` or `d2D ≥ kσ2D` are cut (weight 0): the threshold partition. The components are
//! then split by recursive normalized cuts ([`ncut`]).
//!
//! Takes a [`points::PointSet`] (positions, colours, views) and the views' gradient images;
//! returns a [`PointGraph`] and its partition.

pub mod components;
pub mod gradient;
pub mod lanczos;
pub mod local_shape;
pub mod maxflow;
pub mod ncut;
pub mod neighbours;
pub mod points;
pub mod shape;
#[cfg(test)]
pub(crate) mod test_support;
pub mod visibility;

use nalgebra::{Isometry3, Point2};
use rayon::prelude::*;
use serde::Serialize;

use gradient::GradientImage;
pub use local_shape::estimate_normals;
use points::{PointSet, common_views};

use crate::scene::Camera;

/// Parameters of the graph (seed 004 §5.1 defaults).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct GraphOptions {
    /// K nearest neighbours per point (K = 3).
    pub knn: usize,
    /// Weight of the image term (α = 0.5).
    pub alpha: f64,
    /// Threshold in standard deviations (k = 3).
    pub k: f64,
}

impl Default for GraphOptions {
    fn default() -> Self {
        Self {
            knn: 3,
            alpha: 0.5,
            k: 3.0,
        }
    }
}

/// An undirected edge with its distances and weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    pub a: u32,
    pub b: u32,
    pub d3d: f32,
    /// Largest gradient crossed in any common view (0 when α = 0 and no images were used).
    pub d2d: f32,
    /// `exp(−d²)`, or 0 when the threshold partition cuts the edge.
    pub weight: f32,
}

/// One view's projection data for the 2D term.
pub struct ViewData<'a> {
    pub camera: &'a Camera,
    pub camera_from_world: Isometry3<f64>,
    pub gradient: Option<&'a GradientImage>,
}

/// The graph over a point set.
#[derive(Clone, Debug)]
pub struct PointGraph {
    pub num_nodes: usize,
    pub edges: Vec<Edge>,
    pub sigma_3d: f64,
    pub sigma_2d: f64,
    pub options: GraphOptions,
    /// Edges dropped because their ends share no view.
    pub dropped_not_covisible: usize,
    /// Unoriented unit normal per node (PCA of its [`GRAPH_PLANE_NEIGHBOURS`] nearest neighbours).
    pub normals: Vec<nalgebra::Vector3<f64>>,
    /// RMS distance of each node's [`GRAPH_PLANE_NEIGHBOURS`] nearest neighbours from their plane (model units): the
    /// local surface noise the sheet tests allow for ([`ncut::sheet_tolerance`]).
    pub plane_rms: Vec<f64>,
    /// Median distance from a node to its nearest other node (model units; 0 for fewer than
    /// two nodes): [`local_shape::median_spacing`] of the graph's points.
    pub median_spacing: f64,
}

/// Neighbours of each node's local plane ([`PointGraph::normals`], [`PointGraph::plane_rms`]).
const GRAPH_PLANE_NEIGHBOURS: usize = 10;

/// Root mean square of the values below their 99th percentile (a scale robust to outliers).
fn trimmed_rms(values: &mut [f32]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f32::total_cmp);
    let keep = ((values.len() as f64 * 0.99).ceil() as usize).clamp(1, values.len());
    (values[..keep]
        .iter()
        .map(|v| (*v as f64).powi(2))
        .sum::<f64>()
        / keep as f64)
        .sqrt()
}

/// K-nearest-neighbour pairs `(i, j)` with `i < j`, deduplicated.
pub fn knn_pairs(points: &PointSet, k: usize) -> Vec<(u32, u32)> {
    if points.len() < 2 || k == 0 {
        return Vec::new();
    }
    local_shape::Neighbourhoods::of(points, k).map_or_else(Vec::new, |neighbourhoods| {
        neighbourhood_pairs(&neighbourhoods, k)
    })
}

/// The pairs of [`knn_pairs`] from neighbourhoods searched for at least `k` neighbours.
fn neighbourhood_pairs(neighbourhoods: &local_shape::Neighbourhoods, k: usize) -> Vec<(u32, u32)> {
    let mut pairs: Vec<(u32, u32)> = (0..neighbourhoods.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            neighbourhoods
                .around(i, k)
                .filter(move |&j| j != i)
                .take(k)
                .map(move |j| (i.min(j) as u32, i.max(j) as u32))
        })
        .collect();
    pairs.par_sort_unstable();
    pairs.dedup();
    pairs
}

/// Views seeing a surface more obliquely than this (cosine of the angle between the viewing
/// ray and the surface normal) do not judge its edges: their projection is squeezed onto the
/// silhouette, where gradients are high whatever the edge connects.
pub const MIN_VIEW_INCIDENCE: f64 = 0.3;

impl PointGraph {
    /// Builds the graph: kNN edges, co-visibility filter, 3D and 2D distances, σ estimates,
    /// weights and the threshold partition. `views[v]` describes view index `v` of the point
    /// set; views without a gradient image do not contribute to `d2D`.
    pub fn build(points: &PointSet, views: &[ViewData<'_>], options: GraphOptions) -> Self {
        // One neighbour search serves the edges, the local planes and the spacing.
        let neighbourhoods =
            local_shape::Neighbourhoods::of(points, options.knn.max(GRAPH_PLANE_NEIGHBOURS));
        let (pairs, planes, median_spacing) = match &neighbourhoods {
            Some(around) => (
                neighbourhood_pairs(around, options.knn),
                around.planes(points, GRAPH_PLANE_NEIGHBOURS),
                around.median_spacing(points),
            ),
            // No tree over these points: no edges, and `local_planes`' fallback planes.
            None => (
                Vec::new(),
                local_shape::local_planes(points, GRAPH_PLANE_NEIGHBOURS),
                0.0,
            ),
        };
        let use_images = options.alpha > 0.0;
        let normals: Vec<nalgebra::Vector3<f64>> = planes.iter().map(|p| p.normal).collect();
        let plane_rms: Vec<f64> = planes.iter().map(|p| p.rms).collect();
        let depth_maps = use_images.then(|| visibility::SplatDepthMaps::build(points, views, 2.0));
        // Per edge: (a, b, d3D, d2D, Σg², #g) over the gradient samples of all common views.
        type Measured = Option<(u32, u32, f32, f32, f64, usize)>;
        let measured: Vec<Measured> = pairs
            .par_iter()
            .map_init(Vec::new, |common, &(a, b)| {
                common_views(&points.views[a as usize], &points.views[b as usize], common);
                if common.is_empty() {
                    return None;
                }
                let pa = &points.positions[a as usize];
                let pb = &points.positions[b as usize];
                let d3d = (pa - pb).norm() as f32;
                if !use_images {
                    return Some((a, b, d3d, 0.0, 0.0, 0));
                }
                let mut d2d: Option<f32> = None;
                let (mut sum_squares, mut count) = (0.0, 0);
                let (na, nb) = (normals[a as usize], normals[b as usize]);
                let normal = if na.dot(&nb) >= 0.0 { na + nb } else { na - nb };
                let normal = normal.try_normalize(1e-12).unwrap_or(na);
                let middle = nalgebra::center(pa, pb);
                let frontal = |view: &ViewData| {
                    let ray =
                        view.camera_from_world.inverse() * nalgebra::Point3::origin() - middle;
                    ray.try_normalize(1e-12)
                        .is_some_and(|r| r.dot(&normal).abs() >= MIN_VIEW_INCIDENCE)
                };
                let unoccluded = |v: u32, view: &ViewData| {
                    depth_maps
                        .as_ref()
                        .is_none_or(|maps| maps.sees(v as usize, view, &middle, 0.01))
                };
                let usable: Vec<u32> = common
                    .iter()
                    .copied()
                    .filter(|&v| {
                        views
                            .get(v as usize)
                            .is_some_and(|view| frontal(view) && unoccluded(v, view))
                    })
                    .collect();
                let judged = if usable.is_empty() {
                    common.as_slice()
                } else {
                    usable.as_slice()
                };
                for &v in judged {
                    let Some(view) = views.get(v as usize) else {
                        continue;
                    };
                    let Some(gradient) = view.gradient else {
                        continue;
                    };
                    let project = |p: &nalgebra::Point3<f64>| -> Option<Point2<f64>> {
                        view.camera.project(&(view.camera_from_world * p).coords)
                    };
                    if let (Some(ua), Some(ub)) = (project(pa), project(pb))
                        && let Some(samples) = gradient.sample_along(&ua, &ub)
                    {
                        d2d = Some(d2d.map_or(samples.max, |d| d.max(samples.max)));
                        sum_squares += samples.sum_squares;
                        count += samples.count;
                    }
                }
                // With images in use, an edge no view can measure cannot be judged: drop it.
                d2d.map(|d2d| (a, b, d3d, d2d, sum_squares, count))
            })
            .collect();
        let dropped_not_covisible = measured.iter().filter(|m| m.is_none()).count();
        // σ2D: the scale of the colour gradient g itself (seed 004: "the variance of the
        // colour gradient"), over every sample the edges' segments visited.
        let (gradient_squares, gradient_count) = measured
            .iter()
            .flatten()
            .fold((0.0, 0usize), |(s, c), m| (s + m.4, c + m.5));
        let sigma_2d = if gradient_count > 0 {
            (gradient_squares / gradient_count as f64).sqrt()
        } else {
            0.0
        };
        let mut edges: Vec<Edge> = measured
            .into_iter()
            .flatten()
            .map(|(a, b, d3d, d2d, _, _)| Edge {
                a,
                b,
                d3d,
                d2d,
                weight: 0.0,
            })
            .collect();
        let sigma_3d = trimmed_rms(&mut edges.iter().map(|e| e.d3d).collect::<Vec<_>>());
        let mut graph = Self {
            num_nodes: points.len(),
            edges: Vec::new(),
            sigma_3d,
            sigma_2d,
            options,
            dropped_not_covisible,
            normals,
            plane_rms,
            median_spacing,
        };
        for e in &mut edges {
            e.weight = graph.weight(e.d3d as f64, e.d2d as f64) as f32;
        }
        graph.edges = edges;
        graph
    }

    /// `exp(−d²)` with the threshold partition applied (seed 004 §5.1).
    pub fn weight(&self, d3d: f64, d2d: f64) -> f64 {
        let alpha = self.options.alpha;
        let s3 = self.sigma_3d.max(1e-12);
        let s2 = self.sigma_2d.max(1e-12);
        if d3d >= self.options.k * s3 || (alpha > 0.0 && d2d >= self.options.k * s2) {
            return 0.0;
        }
        let d = (1.0 - alpha) * d3d / (std::f64::consts::SQRT_2 * s3)
            + alpha * d2d / (std::f64::consts::SQRT_2 * s2);
        (-d * d).exp()
    }

    /// The combined distance `d(p, q)` of an edge (∞ for thresholded edges).
    pub fn distance(&self, edge: &Edge) -> f64 {
        if edge.weight <= 0.0 {
            f64::INFINITY
        } else {
            (-(edge.weight as f64).ln()).sqrt()
        }
    }

    /// Adjacency (CSR) over the edges with positive weight.
    pub fn adjacency(&self) -> components::Adjacency {
        components::Adjacency::from_edges(
            self.num_nodes,
            self.edges
                .iter()
                .filter(|e| e.weight > 0.0)
                .map(|e| (e.a, e.b, e.weight as f64)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn grid(n: usize, spacing: f64, offset: f64) -> PointSet {
        let mut set = PointSet::default();
        for i in 0..n {
            for j in 0..n {
                set.positions.push(Point3::new(
                    offset + i as f64 * spacing,
                    j as f64 * spacing,
                    0.0,
                ));
                set.colors.push([0, 0, 0]);
                set.views.push(vec![0]);
                set.point_ids.push(set.point_ids.len() as u64);
            }
        }
        set
    }

    #[test]
    fn knn_pairs_are_unique_and_local() {
        let points = grid(10, 1.0, 0.0);
        let pairs = knn_pairs(&points, 3);
        assert!(pairs.windows(2).all(|w| w[0] < w[1]));
        for (a, b) in &pairs {
            let d = (points.positions[*a as usize] - points.positions[*b as usize]).norm();
            assert!(d <= 2f64.sqrt() + 1e-9, "{d}");
        }
        assert!(pairs.len() >= 100);
    }

    #[test]
    fn three_d_threshold_cuts_the_gap_between_two_patches() {
        let mut points = grid(8, 0.01, 0.0);
        let other = grid(8, 0.01, 0.2);
        points.positions.extend(other.positions);
        points.colors.extend(other.colors);
        points.views.extend(other.views);
        points.point_ids.extend(other.point_ids);
        let graph = PointGraph::build(
            &points,
            &[],
            GraphOptions {
                alpha: 0.0,
                ..Default::default()
            },
        );
        let adjacency = graph.adjacency();
        let labels = adjacency.components();
        assert_eq!(labels.count, 2);
        // Within a patch weights are high.
        assert!(
            graph
                .edges
                .iter()
                .filter(|e| e.weight > 0.0)
                .all(|e| e.weight > 0.3)
        );
    }

    #[test]
    fn edges_without_a_common_view_are_dropped() {
        let mut points = grid(4, 1.0, 0.0);
        for (i, v) in points.views.iter_mut().enumerate() {
            *v = vec![i as u32];
        }
        let graph = PointGraph::build(
            &points,
            &[],
            GraphOptions {
                alpha: 0.0,
                ..Default::default()
            },
        );
        assert!(graph.edges.is_empty());
        assert!(graph.dropped_not_covisible > 0);
    }
}
