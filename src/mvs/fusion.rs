//! Multi-view consistency and fusion of pairwise depth maps into one point set with
//! visibility, in the manner of COLMAP's stereo fusion: a depth is kept only when the depth
//! maps of other views agree with it (relative depth difference below a threshold), the
//! agreeing estimates are averaged along each view's ray, and the survivors are merged on one
//! voxel grid, a sampled pixel's footprint wide at the object, so each surface patch yields one
//! point and the density is even over the object.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::stereo::RectifiedDepthMap;
use crate::graph::neighbours::Neighbours;
use crate::util::geometry::closest_point_to_lines;
use crate::util::progress::Progress;
use crate::util::stats::median;

/// Fusion settings.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FusionOptions {
    /// Two depths agree when they differ by less than this fraction of the depth.
    pub max_relative_depth_error: f64,
    /// Other depth maps that must agree with a depth for it to be kept (4, as COLMAP's
    /// fusion, which asks for 5 pixels in all).
    pub min_consistent: usize,
    /// Depth maps checked against each depth map: those whose views look most alike (≤ 64).
    pub neighbour_maps: usize,
    /// Every `pixel_step`-th pixel of each depth map (in both directions) starts a point.
    pub pixel_step: usize,
    /// Voxel side of the merge grid in pixel footprints (depth / focal) at the object: sets
    /// the point spacing; samples within one voxel are averaged.
    pub voxel_pixels: f64,
}

impl Default for FusionOptions {
    fn default() -> Self {
        Self {
            max_relative_depth_error: 0.01,
            min_consistent: 4,
            neighbour_maps: 10,
            pixel_step: 2,
            voxel_pixels: 1.5,
        }
    }
}

/// The ball the views converge on: depths outside it are not fused.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RegionOfInterest {
    pub center_world: Point3<f64>,
    pub radius: f64,
}

impl RegionOfInterest {
    pub fn contains(&self, point_world: &Point3<f64>) -> bool {
        (point_world - self.center_world).norm_squared() <= self.radius * self.radius
    }

    /// For an object-centric capture: the point nearest (least squares) to all viewing
    /// axes, and `radius_factor` times the median camera distance to it. `None` when the axes
    /// do not converge in front of most cameras (e.g. a forward-moving camera).
    pub fn converging(
        centers_world: &[Point3<f64>],
        axes_world: &[Vector3<f64>],
        radius_factor: f64,
    ) -> Option<Self> {
        if centers_world.len() < 2 || radius_factor.is_nan() || radius_factor <= 0.0 {
            return None;
        }
        let lines: Vec<_> = centers_world
            .iter()
            .copied()
            .zip(axes_world.iter().copied())
            .collect();
        let center_world = closest_point_to_lines(&lines)?;
        let in_front = centers_world
            .iter()
            .zip(axes_world)
            .filter(|(c, d)| (center_world - **c).dot(d) > 0.0)
            .count();
        if in_front * 4 < centers_world.len() * 3 {
            return None;
        }
        let radius =
            radius_factor * median(centers_world.iter().map(|c| (center_world - c).norm()))?;
        (radius > 0.0).then_some(Self {
            center_world,
            radius,
        })
    }
}

/// Fused points: positions, colours, the views (image positions, sorted) that see each, how
/// many depth estimates each averages, and whether each was found by the thin-organ sweep
/// ([`super::thin`]: a point on a stem's or petiole's centreline, not on a surface stereo
/// matched).
#[derive(Clone, Debug, Default)]
pub struct FusedPoints {
    pub positions_world: Vec<Point3<f64>>,
    pub colors: Vec<[u8; 3]>,
    pub views: Vec<Vec<u32>>,
    pub support: Vec<u32>,
    pub thin_organ: Vec<bool>,
    /// Per point: whether it fills a gap the main partners' points left, from the depth maps
    /// of fill partners ([`super::densify`]); empty when none were asked for.
    pub gap_fill: Vec<bool>,
}

impl FusedPoints {
    /// Whether point `k` fills a gap (false when the points do not say).
    pub fn is_gap_fill(&self, k: usize) -> bool {
        self.gap_fill.get(k).copied().unwrap_or(false)
    }

    pub fn len(&self) -> usize {
        self.positions_world.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions_world.is_empty()
    }
}

/// What fusion did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FusionStats {
    pub depth_samples: usize,
    pub consistent_samples: usize,
    /// Merge-voxel side (world units).
    pub voxel_size: f64,
    pub points: usize,
}

/// A depth sample that enough other maps agreed with.
struct Candidate {
    position_world: Point3<f64>,
    color: [u8; 3],
    map: u32,
    /// Bit k: neighbour k of `map` agreed.
    agreeing: u64,
    estimates: u32,
}

/// For each map, the other maps whose left views' axes are closest in angle.
fn neighbour_maps(maps: &[RectifiedDepthMap], count: usize) -> Vec<Vec<usize>> {
    let axes: Vec<Vector3<f64>> = maps
        .iter()
        .map(|m| m.camera.rect_from_world.inverse() * Vector3::z())
        .collect();
    let centers: Vec<Point3<f64>> = maps.iter().map(|m| m.camera.center_world).collect();
    (0..maps.len())
        .map(|p| {
            let mut others: Vec<(f64, usize)> = (0..maps.len())
                .filter(|&q| q != p)
                .map(|q| {
                    // Axis angle, with the centre distance breaking ties between maps of
                    // one view.
                    (
                        -axes[p].dot(&axes[q]) + 1e-9 * (centers[p] - centers[q]).norm(),
                        q,
                    )
                })
                .collect();
            others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            others
                .into_iter()
                .take(count.min(64))
                .map(|(_, q)| q)
                .collect()
        })
        .collect()
}

/// Checks every `pixel_step`-th depth of `maps[p]` against its neighbours.
fn consistent_samples(
    p: usize,
    maps: &[RectifiedDepthMap],
    neighbours: &[usize],
    options: &FusionOptions,
    roi: Option<&RegionOfInterest>,
) -> (usize, Vec<Candidate>) {
    let map = &maps[p];
    let step = options.pixel_step.max(1);
    let mut samples = 0;
    let mut out = Vec::new();
    for j in (0..map.camera.height).step_by(step) {
        for i in (0..map.camera.width).step_by(step) {
            let z = map.depth_at(i, j);
            if z.is_nan() || z <= 0.0 {
                continue;
            }
            let point = map.camera.unproject_pixel(i, j, z as f64);
            if roi.is_some_and(|r| !r.contains(&point)) {
                continue;
            }
            samples += 1;
            let mut sum = point.coords;
            let mut agreeing = 0u64;
            let mut estimates = 1u32;
            for (k, &q) in neighbours.iter().enumerate() {
                let other = &maps[q];
                let Some((uv, depth)) = other.camera.project(&point) else {
                    continue;
                };
                let Some((iq, jq)) = other.camera.pixel_of(&uv) else {
                    continue;
                };
                let other_depth = other.depth_at(iq, jq) as f64;
                if other_depth > 0.0
                    && (other_depth - depth).abs() <= options.max_relative_depth_error * depth
                {
                    // The other map's estimate, on the ray from its centre through the point.
                    let center = other.camera.center_world;
                    sum += center.coords + (point - center) * (other_depth / depth);
                    agreeing |= 1 << k;
                    estimates += 1;
                }
            }
            if (estimates - 1) as usize >= options.min_consistent {
                out.push(Candidate {
                    position_world: Point3::from(sum / estimates as f64),
                    color: map.colors[j * map.camera.width + i],
                    map: p as u32,
                    agreeing,
                    estimates,
                });
            }
        }
    }
    (samples, out)
}

/// Fuses depth maps into points (see the module docs). Deterministic.
pub fn fuse(
    maps: &[RectifiedDepthMap],
    options: &FusionOptions,
    roi: Option<&RegionOfInterest>,
    progress: &dyn Progress,
) -> (FusedPoints, FusionStats) {
    let neighbours = neighbour_maps(maps, options.neighbour_maps);
    progress.stage("fusing depth maps", maps.len() as u64);
    let per_map: Vec<(usize, Vec<Candidate>)> = (0..maps.len())
        .into_par_iter()
        .map(|p| {
            let result = consistent_samples(p, maps, &neighbours[p], options, roi);
            progress.advance(1);
            result
        })
        .collect();
    let mut stats = FusionStats {
        depth_samples: per_map.iter().map(|(n, _)| n).sum(),
        ..FusionStats::default()
    };
    let candidates: Vec<Candidate> = per_map.into_iter().flat_map(|(_, c)| c).collect();
    stats.consistent_samples = candidates.len();

    // Voxel side: the footprint of one sampled pixel at the region of interest's centre (one
    // grid, so the point density is even over the object), else at the median candidate.
    let step = options.voxel_pixels.max(0.5);
    let footprints: Vec<f64> = match roi {
        Some(roi) => maps
            .iter()
            .map(|m| (roi.center_world - m.camera.center_world).norm() / m.camera.focal_px)
            .collect(),
        None => candidates
            .iter()
            .step_by(97)
            .map(|c| {
                let map = &maps[c.map as usize];
                (c.position_world - map.camera.center_world).norm() / map.camera.focal_px
            })
            .collect(),
    };
    let Some(footprint) = median(footprints) else {
        return (FusedPoints::default(), stats);
    };
    let voxel = footprint * step;
    stats.voxel_size = voxel;
    let key = |p: &Point3<f64>| {
        [
            (p.x / voxel).floor() as i64,
            (p.y / voxel).floor() as i64,
            (p.z / voxel).floor() as i64,
        ]
    };
    let mut order: Vec<([i64; 3], usize)> = candidates
        .iter()
        .enumerate()
        .map(|(c, candidate)| (key(&candidate.position_world), c))
        .collect();
    order.par_sort_unstable();

    let mut fused = FusedPoints::default();
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && order[end].0 == order[start].0 {
            end += 1;
        }
        let mut sum = Vector3::zeros();
        let mut color_sum = [0u64; 3];
        let mut weight = 0u64;
        let mut views = Vec::new();
        for &(_, c) in &order[start..end] {
            let candidate = &candidates[c];
            let w = candidate.estimates as u64;
            sum += candidate.position_world.coords * w as f64;
            for (s, v) in color_sum.iter_mut().zip(candidate.color) {
                *s += v as u64 * w;
            }
            weight += w;
            let map = &maps[candidate.map as usize];
            views.extend([map.pair.left as u32, map.pair.right as u32]);
            for (k, &q) in neighbours[candidate.map as usize].iter().enumerate() {
                if candidate.agreeing & (1 << k) != 0 {
                    views.extend([maps[q].pair.left as u32, maps[q].pair.right as u32]);
                }
            }
        }
        views.sort_unstable();
        views.dedup();
        fused
            .positions_world
            .push(Point3::from(sum / weight as f64));
        fused
            .colors
            .push(color_sum.map(|s| ((s + weight / 2) / weight) as u8));
        fused.views.push(views);
        fused.support.push(weight as u32);
        fused.thin_organ.push(false);
        start = end;
    }
    stats.points = fused.len();
    (fused, stats)
}

/// The free-space check ([`seen_through`]): a fused point is dropped when depth maps see
/// past it, in front of what they see, at least `min_maps` times and in more than `share` of
/// the maps that see the point or past it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FreeSpaceOptions {
    /// Maps that must see past a point before it can be dropped (0: no check).
    pub min_maps: usize,
    /// Share of the maps with a depth there (on the point or past it) that must see past it.
    pub share: f64,
}

impl Default for FreeSpaceOptions {
    fn default() -> Self {
        Self {
            min_maps: 2,
            share: 0.5,
        }
    }
}

/// How the depth maps see one point: how many put their nearest surface on it (within the
/// fusion's depth tolerance) and how many see past it (their nearest surface there lies
/// farther, so the point stands in space they look through).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sightings {
    pub on: u32,
    pub past: u32,
}

/// For each point, how the depth maps see it ([`Sightings`]). A map's surface at the point's
/// pixel is the nearest valid depth of the 3×3 pixels around it, so a thin organ a pixel off
/// in one map still stands in front; a pixel without any depth says nothing. Stereo fattens a
/// thin organ's disparity into the textureless background beside it, and nearby views fatten
/// alike, so the halo passes the multi-view agreement of [`fuse`]; views from other sides
/// look through the halo to the organ or what lies behind it.
pub fn seen_through(
    points_world: &[Point3<f64>],
    maps: &[RectifiedDepthMap],
    max_relative_depth_error: f64,
    confirmed: Option<&Confirmed>,
) -> Vec<Sightings> {
    points_world
        .par_iter()
        .map(|point| {
            let mut seen = Sightings::default();
            let mut behind = Vec::new();
            for map in maps {
                let Some((uv, depth)) = map.camera.project(point) else {
                    continue;
                };
                let Some((i, j)) = map.camera.pixel_of(&uv) else {
                    continue;
                };
                let mut nearest = (f64::INFINITY, i, j);
                for jj in j.saturating_sub(1)..=(j + 1).min(map.camera.height - 1) {
                    for ii in i.saturating_sub(1)..=(i + 1).min(map.camera.width - 1) {
                        let z = map.depth_at(ii, jj) as f64;
                        if z > 0.0 && z < nearest.0 {
                            nearest = (z, ii, jj);
                        }
                    }
                }
                let (surface, ii, jj) = nearest;
                if !surface.is_finite() {
                    continue;
                }
                let tolerance = max_relative_depth_error * depth;
                if surface > depth + tolerance {
                    seen.past += 1;
                    if confirmed.is_some() {
                        behind.push(map.camera.unproject_pixel(ii, jj, surface));
                    }
                } else if surface >= depth - tolerance {
                    seen.on += 1;
                }
            }
            // Confirming is a search per map: done only where the point would otherwise go
            // (confirming only lowers `past`, so elsewhere the decision is the same).
            if let Some(c) = confirmed
                && in_free_space(&seen, &c.options)
            {
                seen.past = behind.iter().filter(|p| c.holds(p)).count() as u32;
            }
            seen
        })
        .collect()
}

/// Surfaces the fusion confirmed: its points, and how near one a depth must lie to be on it;
/// only points the unconfirmed sightings would drop under `options` are confirmed.
pub struct Confirmed {
    pub points: Neighbours,
    pub radius: f64,
    pub options: FreeSpaceOptions,
}

impl Confirmed {
    fn holds(&self, point_world: &Point3<f64>) -> bool {
        self.points
            .nearest(point_world)
            .is_some_and(|n| n.distance() <= self.radius)
    }
}

/// Whether [`FreeSpaceOptions`] drops a point seen so.
pub fn in_free_space(seen: &Sightings, options: &FreeSpaceOptions) -> bool {
    options.min_maps > 0
        && seen.past as usize >= options.min_maps
        && seen.past as f64 > options.share * (seen.on + seen.past) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mvs::pairs::StereoPair;
    use crate::mvs::pairs::tests::ring_model;
    use crate::mvs::rectify::RectifiedPair;
    use crate::util::progress::NoProgress;

    const RADIUS: f64 = 0.5;

    /// Exact depth maps, one per ring neighbour pair rectified at `scale` of the 640 × 480
    /// photos, of the surface `hit` gives: the distance along a ray (origin, direction) to
    /// its first crossing, in units of the direction's length.
    fn exact_maps(
        num_views: usize,
        scale: f64,
        hit: impl Fn(&Vector3<f64>, &Vector3<f64>) -> Option<f64>,
    ) -> Vec<RectifiedDepthMap> {
        let model = ring_model(num_views, 20);
        let images = model.images();
        let camera = model.camera_of(&images[0]);
        (0..num_views)
            .map(|left| {
                let right = (left + 1) % num_views;
                let rectified = RectifiedPair::new(
                    (&images[left], camera),
                    (&images[right], camera),
                    scale,
                    4000,
                )
                .unwrap();
                let rect = rectified.left.clone();
                let mut depth = vec![0.0f32; rect.width * rect.height];
                for j in 0..rect.height {
                    for i in 0..rect.width {
                        // Along the pixel's ray scaled to rectified depth 1.
                        let direction = rect.unproject_pixel(i, j, 1.0) - rect.center_world;
                        if let Some(t) = hit(&rect.center_world.coords, &direction) {
                            depth[j * rect.width + i] = t as f32;
                        }
                    }
                }
                RectifiedDepthMap {
                    pair: StereoPair {
                        left,
                        right,
                        shared_points: 20,
                        angle_deg: 360.0 / num_views as f64,
                    },
                    colors: vec![[10, 200, 30]; depth.len()],
                    camera: rect,
                    depth,
                    disparity_range: (0, 16),
                }
            })
            .collect()
    }

    /// The nearer root of a t² + b t + c = 0, when there is one.
    fn nearer_root(a: f64, b: f64, c: f64) -> Option<f64> {
        let disc = b * b - 4.0 * a * c;
        (disc > 0.0 && a > 0.0).then(|| (-b - disc.sqrt()) / (2.0 * a))
    }

    /// Exact depth maps of a ball of radius 0.5 at the origin, one per ring neighbour pair.
    fn sphere_maps(num_views: usize) -> Vec<RectifiedDepthMap> {
        exact_maps(num_views, 0.25, |origin, direction| {
            nearer_root(
                direction.norm_squared(),
                2.0 * origin.dot(direction),
                origin.norm_squared() - RADIUS * RADIUS,
            )
        })
    }

    /// Radius of the thin stem of [`stem_and_backdrop_maps`] (at full photo size its
    /// diameter is about 5 pixels).
    const STEM_RADIUS: f64 = 0.02;

    fn worst_surface_error(fused: &FusedPoints) -> f64 {
        fused
            .positions_world
            .iter()
            .map(|p| (p.coords.norm() - RADIUS).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn exact_depths_fuse_onto_the_surface_with_visibility() {
        let maps = sphere_maps(24);
        let (fused, stats) = fuse(&maps, &FusionOptions::default(), None, &NoProgress);
        assert!(fused.len() > 500, "{stats:?}");
        // Merged points sit on the sphere to well under one voxel.
        let worst = worst_surface_error(&fused);
        assert!(
            worst < 0.5 * stats.voxel_size,
            "{worst} vs voxel {}",
            stats.voxel_size
        );
        for (p, views) in fused.positions_world.iter().zip(&fused.views) {
            assert!(views.len() >= 3 && views.windows(2).all(|w| w[0] < w[1]));
            // Every listed view sees the point (up to 10° past grazing, where a hidden point's
            // depth matches the rim's), or is the partner of the view of an agreeing map
            // (these exact maps do not check the partner; stereo matching does).
            let sees = |v: usize| {
                let angle = std::f64::consts::TAU * v as f64 / 24.0;
                let camera = Point3::new(4.0 * angle.cos(), 4.0 * angle.sin(), 0.0);
                p.coords.normalize().dot(&(camera - p).normalize()) > -(10f64.to_radians().sin())
            };
            for &v in views {
                let v = v as usize;
                assert!(
                    sees(v) || sees((v + 23) % 24),
                    "view {v} sees {p} from behind"
                );
            }
        }
        // Deterministic.
        let (again, _) = fuse(&maps, &FusionOptions::default(), None, &NoProgress);
        assert_eq!(again.positions_world, fused.positions_world);
        assert_eq!(again.views, fused.views);
    }

    #[test]
    fn a_wrong_depth_map_is_outvoted_and_the_region_of_interest_crops() {
        let mut maps = sphere_maps(24);
        for z in &mut maps[5].depth {
            *z *= 1.2;
        }
        let (fused, _) = fuse(&maps, &FusionOptions::default(), None, &NoProgress);
        let worst = worst_surface_error(&fused);
        assert!(
            worst < 0.02 * RADIUS,
            "a 20 % depth error survived: {worst}"
        );
        let small = RegionOfInterest {
            center_world: Point3::origin(),
            radius: 0.3,
        };
        let (cropped, _) = fuse(&maps, &FusionOptions::default(), Some(&small), &NoProgress);
        assert!(cropped.is_empty());
    }

    /// A thin upright stem (radius [`STEM_RADIUS`], from z = −0.5 to 0.5) on the ring's axis,
    /// at full photo size, before a backdrop: a cylinder of radius 6 around the
    /// ring of cameras (at radius 4), seen from inside.
    fn stem_and_backdrop_maps(num_views: usize) -> Vec<RectifiedDepthMap> {
        exact_maps(num_views, 1.0, |origin, direction| {
            let a = direction.x * direction.x + direction.y * direction.y;
            let b = 2.0 * (origin.x * direction.x + origin.y * direction.y);
            let stem_c = origin.x * origin.x + origin.y * origin.y - STEM_RADIUS * STEM_RADIUS;
            let stem =
                nearer_root(a, b, stem_c).filter(|t| (origin.z + t * direction.z).abs() <= 0.5);
            let c = origin.x * origin.x + origin.y * origin.y - 36.0;
            // From inside, the crossing ahead is the farther root.
            let backdrop = (a > 0.0).then(|| (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a));
            stem.or(backdrop)
        })
    }

    /// Points on the stem's surface and on the backdrop (what fusion confirms; the backdrop's
    /// about 0.1 apart), and a sheet
    /// of halo: points at the stem's depth seen from view 0 (at +x), 3 to 15 stem radii to
    /// either side of it, as stereo smears the stem's disparity into a plain background.
    fn stem_backdrop_and_halo() -> [Vec<Point3<f64>>; 3] {
        let mut stem = Vec::new();
        let mut backdrop = Vec::new();
        let mut halo = Vec::new();
        for k in 0..40 {
            let z = -0.45 + 0.9 * k as f64 / 39.0;
            for a in 0..24 {
                let angle = std::f64::consts::TAU * a as f64 / 24.0;
                stem.push(Point3::new(
                    STEM_RADIUS * angle.cos(),
                    STEM_RADIUS * angle.sin(),
                    z,
                ));
            }
            for a in 0..360 {
                let angle = std::f64::consts::TAU * a as f64 / 360.0;
                backdrop.push(Point3::new(6.0 * angle.cos(), 6.0 * angle.sin(), 5.0 * z));
            }
            for side in [-1.0, 1.0] {
                for step in 3..=15 {
                    halo.push(Point3::new(
                        STEM_RADIUS,
                        side * STEM_RADIUS * step as f64,
                        z,
                    ));
                }
            }
        }
        [stem, backdrop, halo]
    }

    #[test]
    fn a_halo_beside_a_thin_stem_is_seen_through_from_other_sides() {
        let maps = stem_and_backdrop_maps(24);
        let [stem, backdrop, halo] = stem_backdrop_and_halo();
        let all: Vec<Point3<f64>> = [&stem[..], &backdrop[..], &halo[..]].concat();
        // Two of the backdrop's point spacings, as densify's two voxels.
        let confirmed = Confirmed {
            points: Neighbours::new(all.iter().copied()).unwrap(),
            radius: 0.2,
            options: FreeSpaceOptions::default(),
        };
        let seen = seen_through(&all, &maps, 0.01, Some(&confirmed));
        let options = FreeSpaceOptions::default();
        let dropped = |range: std::ops::Range<usize>| {
            seen[range]
                .iter()
                .filter(|s| in_free_space(s, &options))
                .count()
        };
        let (n_stem, n_backdrop) = (stem.len(), backdrop.len());
        let stem_dropped = dropped(0..n_stem);
        let backdrop_dropped = dropped(n_stem..n_stem + n_backdrop);
        let halo_dropped = dropped(n_stem + n_backdrop..all.len());
        assert_eq!(stem_dropped, 0, "stem points dropped");
        assert_eq!(backdrop_dropped, 0, "backdrop points dropped");
        assert!(
            halo_dropped * 10 >= halo.len() * 9,
            "{halo_dropped} of {} halo points dropped",
            halo.len()
        );
        // No check, nothing dropped; deterministic.
        let off = FreeSpaceOptions {
            min_maps: 0,
            ..options
        };
        assert!(seen.iter().all(|s| !in_free_space(s, &off)));
        assert_eq!(seen_through(&all, &maps, 0.01, Some(&confirmed)), seen);
    }

    #[test]
    fn seeing_past_a_point_counts_only_onto_a_confirmed_surface() {
        // The backdrop unconfirmed (no fused points on it), as where stereo smoothed a
        // textureless leaf into the depths behind it: what the maps see there is no evidence.
        let maps = stem_and_backdrop_maps(24);
        let [stem, _, halo] = stem_backdrop_and_halo();
        let all: Vec<Point3<f64>> = [&stem[..], &halo[..]].concat();
        let confirmed = Confirmed {
            points: Neighbours::new(all.iter().copied()).unwrap(),
            radius: 0.02,
            options: FreeSpaceOptions::default(),
        };
        let seen = seen_through(&halo, &maps, 0.01, Some(&confirmed));
        let unconfirmed = seen_through(&halo, &maps, 0.01, None);
        let past = |s: &[Sightings]| s.iter().map(|s| s.past).sum::<u32>();
        assert!(
            past(&seen) * 2 < past(&unconfirmed),
            "{} vs {}",
            past(&seen),
            past(&unconfirmed)
        );
        // Points right beside the stem are still seen past onto it from the far side.
        assert!(seen.iter().any(|s| s.past > 0));
    }

    #[test]
    fn a_point_hidden_inside_or_seen_by_no_map_is_kept() {
        let maps = sphere_maps(24);
        let options = FreeSpaceOptions::default();
        // Inside the ball every map's surface lies in front: no map sees past it.
        let inside = seen_through(&[Point3::new(0.1, -0.2, 0.05)], &maps, 0.01, None);
        assert_eq!(inside[0].past, 0);
        assert!(!in_free_space(&inside[0], &options));
        // Far above the ring no map has a depth there: nothing is known, nothing dropped.
        let above = seen_through(&[Point3::new(0.0, 0.0, 3.0)], &maps, 0.01, None);
        assert_eq!(above[0], Sightings::default());
        // Floating in front of the ball, the maps behind which it stands see past it.
        let floating = seen_through(&[Point3::new(0.8, 0.0, 0.0)], &maps, 0.01, None);
        assert!(in_free_space(&floating[0], &options), "{:?}", floating[0]);
    }

    #[test]
    fn views_of_a_ring_converge_on_its_centre() {
        let model = ring_model(12, 10);
        let centers: Vec<_> = model.images().iter().map(|i| i.center_world()).collect();
        let axes: Vec<_> = model
            .images()
            .iter()
            .map(|i| i.view_direction_world())
            .collect();
        let roi = RegionOfInterest::converging(&centers, &axes, 0.5).unwrap();
        assert!(roi.center_world.coords.norm() < 1e-9);
        assert!((roi.radius - 2.0).abs() < 1e-9);
        // Parallel axes (a camera moving sideways) converge nowhere.
        let parallel: Vec<_> = (0..5).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        assert!(RegionOfInterest::converging(&parallel, &[Vector3::z(); 5], 1.0).is_none());
    }
}
