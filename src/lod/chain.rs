//! A plant's LOD chain: the full model (L0) and simplified levels, each with its geometric
//! error μ (world units) and triangle count, as screen-space-error selection needs them
//! (seed 000 eqs. 17–19).

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use serde::Serialize;

use super::simplify::{SimplifyError, SimplifyOptions, simplify, simplify_meshopt};
use crate::mesh::{TriMesh, point_triangle_distance};
use crate::util::rng::Rng;

/// One level of detail: the simplified parts, in the order given.
#[derive(Clone, Debug)]
pub struct LodLevel {
    pub parts: Vec<TriMesh>,
    /// μ: symmetric Hausdorff distance to the full model, from samples (0 for L0).
    pub error_world: f64,
    pub triangles: usize,
}

/// Which simplifier makes the levels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Simplifier {
    /// Ours: half-edge collapse, quadric error × visual importance, borders kept (better plant
    /// silhouettes and Chamfer error at equal budgets).
    #[default]
    Frond,
    /// meshoptimizer (about 4× faster).
    Meshopt,
}

/// Settings of [`build_chain`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChainOptions {
    pub simplifier: Simplifier,
    /// Triangle fractions of the simplified levels, finest first.
    pub ratios: Vec<f64>,
    /// Surface samples per direction for each level's error.
    pub error_samples: usize,
    pub seed: u64,
}

impl Default for ChainOptions {
    fn default() -> Self {
        Self {
            simplifier: Simplifier::Frond,
            ratios: vec![0.5, 0.25, 0.1, 0.04],
            error_samples: 4000,
            seed: 1,
        }
    }
}

/// Triangles with the nearest centroids, searched first for an upper bound.
const CANDIDATE_TRIANGLES: usize = 24;

/// Largest distance from surface samples of `from` (and its vertices) to the surface of
/// `to`. Each distance is exact: the nearest of the triangles with the nearest centroids
/// gives an upper bound d, and every triangle whose centroid lies within d plus the largest
/// triangle's circumradius is then checked.
fn one_sided_deviation(from: &TriMesh, to: &TriMesh, samples: usize, rng: &mut Rng) -> f64 {
    if to.triangles.is_empty() || from.triangles.is_empty() {
        return f64::INFINITY;
    }
    let mut reach = 0.0f32;
    let centroids: Vec<[f32; 3]> = (0..to.triangles.len())
        .map(|t| {
            let [a, b, c] = to.corners(t);
            let m = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            reach = reach
                .max((a - m).norm())
                .max((b - m).norm())
                .max((c - m).norm());
            [m.x, m.y, m.z]
        })
        .collect();
    let Ok(tree) = ImmutableKdTree::<f32, 3>::new_from_slice(&centroids) else {
        return f64::INFINITY;
    };
    let wanted =
        NonZero::new(CANDIDATE_TRIANGLES.min(centroids.len())).unwrap_or(NonZero::<usize>::MIN);
    let to_triangle = |p: &Point3<f32>, t: u32| {
        let [a, b, c] = to.corners(t as usize);
        point_triangle_distance(p, &a, &b, &c)
    };
    let distance = |p: &Point3<f32>| {
        let query = [p.x, p.y, p.z];
        let bound = tree
            .query(&query)
            .nearest_n::<SquaredEuclidean<f32>>(wanted)
            .execute()
            .iter()
            .map(|found| to_triangle(p, found.item))
            .fold(f32::INFINITY, f32::min);
        let radius = bound + reach;
        tree.query(&query)
            .within::<SquaredEuclidean<f32>>(radius * radius)
            .unsorted()
            .execute()
            .iter()
            .map(|found| to_triangle(p, found.item))
            .fold(bound, f32::min)
    };
    let sampled = from
        .sample_surface(samples, rng)
        .iter()
        .map(|s| distance(&s.position))
        .fold(0.0f32, f32::max);
    let vertices = from.positions.iter().map(&distance).fold(0.0f32, f32::max);
    sampled.max(vertices) as f64
}

/// Symmetric Hausdorff distance between two surfaces, estimated from surface samples and
/// vertices (see `one_sided_deviation`).
pub fn surface_deviation(a: &TriMesh, b: &TriMesh, samples: usize, seed: u64) -> f64 {
    let mut rng = Rng::seed_from(seed);
    let ab = one_sided_deviation(a, b, samples, &mut rng);
    let ba = one_sided_deviation(b, a, samples, &mut rng);
    ab.max(ba)
}

/// Builds the chain: L0 = `mesh`, then one level per ratio simplified from the full model.
/// Levels that would not have fewer triangles than the previous one are left out.
pub fn build_chain(mesh: &TriMesh, options: &ChainOptions) -> Result<Vec<LodLevel>, SimplifyError> {
    build_part_chain(std::slice::from_ref(mesh), options)
}

fn merged(parts: &[TriMesh]) -> TriMesh {
    let mut mesh = TriMesh::default();
    for part in parts {
        mesh.append(part);
    }
    mesh
}

/// [`build_chain`] for a model of several parts (materials): every non-empty part is
/// simplified to the level's fraction of its own triangles (at least one), so no part
/// vanishes and parts never merge; μ is measured on all parts together.
pub fn build_part_chain(
    parts: &[TriMesh],
    options: &ChainOptions,
) -> Result<Vec<LodLevel>, SimplifyError> {
    let full = merged(parts);
    let mut levels = vec![LodLevel {
        parts: parts.to_vec(),
        error_world: 0.0,
        triangles: full.triangles.len(),
    }];
    for (i, &ratio) in options.ratios.iter().enumerate() {
        let mut simplified = Vec::with_capacity(parts.len());
        for part in parts {
            if part.triangles.is_empty() {
                simplified.push(part.clone());
                continue;
            }
            let target =
                ((part.triangles.len() as f64 * ratio.clamp(0.0, 1.0)).round() as usize).max(1);
            simplified.push(match options.simplifier {
                Simplifier::Frond => simplify(part, &SimplifyOptions::to_triangles(target))?.mesh,
                Simplifier::Meshopt => simplify_meshopt(part, target)?,
            });
        }
        let level = merged(&simplified);
        let previous = levels.last().map_or(usize::MAX, |l| l.triangles);
        if level.triangles.len() >= previous || level.triangles.is_empty() {
            continue;
        }
        let error_world = surface_deviation(
            &full,
            &level,
            options.error_samples,
            options.seed.wrapping_add(i as u64),
        );
        levels.push(LodLevel {
            triangles: level.triangles.len(),
            parts: simplified,
            error_world,
        });
    }
    Ok(levels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::geometry::{bounding_spheres, distance_to_mesh};
    use crate::lod::test_meshes::grid;

    fn wavy_sheet(n: usize) -> TriMesh {
        grid(n, |x, y| 0.1 * (4.0 * x).sin() * (3.0 * y).cos())
    }

    #[test]
    fn levels_get_coarser_and_their_error_grows() {
        let mesh = wavy_sheet(48);
        let chain = build_chain(&mesh, &ChainOptions::default()).unwrap();
        assert_eq!(chain.len(), 5);
        assert_eq!(chain[0].error_world, 0.0);
        for pair in chain.windows(2) {
            assert!(pair[1].triangles < pair[0].triangles);
            assert!(
                pair[1].error_world >= pair[0].error_world,
                "{} {}",
                pair[0].error_world,
                pair[1].error_world
            );
        }
        let coarsest = chain.last().unwrap();
        assert!(
            coarsest.error_world > 0.0 && coarsest.error_world < 0.05,
            "{}",
            coarsest.error_world
        );
    }

    #[test]
    fn the_meshopt_chain_is_coarser_per_level_with_its_own_errors() {
        let mesh = wavy_sheet(32);
        let options = ChainOptions {
            simplifier: Simplifier::Meshopt,
            ratios: vec![0.25, 0.05],
            ..Default::default()
        };
        let chain = build_chain(&mesh, &options).unwrap();
        assert_eq!(chain.len(), 3);
        for (level, ratio) in chain[1..].iter().zip([0.25, 0.05]) {
            let target = mesh.triangles.len() as f64 * ratio;
            assert!(
                level.triangles as f64 <= 1.05 * target + 2.0,
                "{}",
                level.triangles
            );
            assert!(level.error_world > 0.0 && level.error_world < 0.05);
            level.parts[0].validate().unwrap();
        }
    }

    #[test]
    fn the_error_matches_brute_force_vertex_distances() {
        let mesh = wavy_sheet(32);
        let coarse = simplify(&mesh, &SimplifyOptions::to_triangles(150))
            .unwrap()
            .mesh;
        let estimate = surface_deviation(&mesh, &coarse, 2000, 3);
        // Exact (brute force) largest distance of the full model's vertices to the coarse one.
        let spheres = bounding_spheres(&coarse);
        let exact = mesh
            .positions
            .iter()
            .map(|p| distance_to_mesh(p, &coarse, &spheres))
            .fold(0.0f32, f32::max) as f64;
        // The samples include the vertices, so the estimate is at least the exact value; the
        // coarse mesh's own samples may add more, but not much on a smooth sheet.
        assert!(estimate >= exact - 1e-7, "{estimate} < {exact}");
        assert!(estimate <= 1.5 * exact + 1e-5, "{estimate} vs {exact}");
        assert_eq!(
            surface_deviation(&mesh, &TriMesh::default(), 10, 1),
            f64::INFINITY
        );
    }
}
