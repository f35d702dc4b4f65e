//! The plant's pot: its vertical axis, rim and radius, from the points labelled pot and the
//! points at its wall's heights ([`pot_from_points`]), and whether a segment lies on its wall
//! ([`on_the_wall`]). The segmentation uses it to take pieces of the wall back from the leaves;
//! the skeleton cuts the plant's points at the rim and roots the plant on the soil inside it
//! ([`crate::branch::plant`]).

use nalgebra::{Point3, Vector3};

use super::foreground::{Foreground, PointClass};
use crate::util::geometry::{concentric_circle_centre, distance_from_axis};

/// The pot as far as the skeleton needs it: its vertical axis, rim, soil surface and radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PotShape {
    /// A point on the pot's axis at the height of its rim.
    pub rim_centre: Point3<f64>,
    /// A point on the pot's axis at the height of the soil surface inside it, where the stem
    /// leaves the soil: the median height of the points inside the pot ([`INSIDE_SHARE`] of
    /// its radius from its axis, below its rim); the rim's centre where fewer than
    /// [`MIN_INSIDE_POINTS`] are there to say.
    pub soil_centre: Point3<f64>,
    /// Median distance of the pot's points from its axis.
    pub radius: f64,
    /// Median distance from its axis of the pot's points at its wall's heights (between
    /// [`WALL_BOTTOM`] and [`WALL_TOP`] of the way from its lowest points to its rim, where
    /// neither the soil nor the floor lies); [`PotShape::radius`] where fewer than
    /// [`MIN_WALL_POINTS`] are there. Which segments lie on the wall is asked of this radius
    /// ([`on_the_wall`]): the soil inside the rim pulls the median of all pot points in.
    pub wall_radius: f64,
}

/// A pot needs this many points to set the plant's base.
pub const MIN_POT_POINTS: usize = 50;

/// A pot from the points labelled pot and the points that may lie on its wall (`voters`),
/// given the up direction and a point near the pot's axis; `None` below [`MIN_POT_POINTS`]
/// pot points, where the plant goes on inside the pot below its rim ([`MAX_INSIDE_DEPTH`]), or
/// where the pot points span more than [`MAX_HEIGHT_RADII`] in height.
/// The rim is at the 95th percentile of the pot points' heights and the pot's lowest points at
/// the 5th. The axis is the centre of the wall's concentric circles (one per
/// height band, [`wall_band`]) voted for by the voters ([`robust_circle_centre`]; an orbit sees
/// the wall all round, but stereo may find only an arc of it), or the pot points' mean across
/// the up direction where no centre comes out.
pub fn pot_from_points(
    pot: &[Point3<f64>],
    voters: &[Point3<f64>],
    up: &Vector3<f64>,
    centre: &Point3<f64>,
) -> Option<PotShape> {
    if pot.len() < MIN_POT_POINTS {
        return None;
    }
    let across = |p: &Point3<f64>| {
        let d = p - centre;
        d - up * up.dot(&d)
    };
    let mean = pot.iter().fold(Vector3::zeros(), |a, p| a + across(p)) / pot.len() as f64;
    let u = crate::util::geometry::any_perpendicular(up);
    let v = up.cross(&u);
    let mut heights: Vec<f64> = pot.iter().map(|p| up.dot(&(p - centre))).collect();
    heights.sort_by(f64::total_cmp);
    let low = heights[(heights.len() - 1) * 5 / 100];
    let rim = heights[(heights.len() - 1) * 95 / 100];
    let planar: Vec<(f64, f64, usize)> = voters
        .iter()
        .filter_map(|p| {
            let band = wall_band(up.dot(&(p - centre)), low, rim)?;
            let d = across(p) - mean;
            Some((d.dot(&u), d.dot(&v), band))
        })
        .collect();
    let offset = robust_circle_centre(&planar).map_or(mean, |(x, y)| mean + u * x + v * y);
    // (The median over all pot points: the junk in them lies off the wall.)
    let mut radii: Vec<f64> = pot.iter().map(|p| (across(p) - offset).norm()).collect();
    radii.sort_by(f64::total_cmp);
    let rim_centre = centre + offset + up * rim;
    let radius = radii[radii.len() / 2];
    let mut wall_radii: Vec<f64> = pot
        .iter()
        .filter(|p| wall_band(up.dot(&(*p - centre)), low, rim).is_some())
        .map(|p| (across(p) - offset).norm())
        .collect();
    wall_radii.sort_by(f64::total_cmp);
    let wall_radius = if wall_radii.len() >= MIN_WALL_POINTS {
        wall_radii[wall_radii.len() / 2]
    } else {
        radius
    };
    let inside = inside_depths(
        &rim_centre,
        radius,
        (1.0 - WALL_BOTTOM) * (rim - low),
        voters,
        up,
    );
    // Three quarters of the points inside at most this many radii below the rim.
    let depth = inside
        .as_ref()
        .map(|depths| depths[(depths.len() - 1) * 3 / 4] / radius);
    let soil_depth = inside
        .as_ref()
        .map_or(0.0, |depths| depths[depths.len() / 2]);
    let shape = PotShape {
        rim_centre,
        soil_centre: rim_centre - up * soil_depth,
        radius,
        wall_radius,
    };
    tracing::debug!(?shape, height = rim - low, inside_depth = ?depth, "pot from its points");
    if depth.is_some_and(|depth| depth > MAX_INSIDE_DEPTH)
        || rim - low > MAX_HEIGHT_RADII * shape.radius
    {
        return None;
    }
    Some(shape)
}

/// A pot is squat: its points span at most this many of its radii in height (1.5 diameters;
/// the synthetic pots are 1.0–1.7 radii tall, nursery pots about 2.5). Taller, the "pot" is
/// pieces of the plant at one distance from the cameras' axis: on the real Arabidopsis, with a
/// pot test that no longer took its rosette's leaves for pot (tried, not kept), the stereo halo
/// of its lower stem made one 4.4 radii tall (96 mm, radius 22 mm) with its rim 10 cm up the
/// stem, and the stem was cut there.
const MAX_HEIGHT_RADII: f64 = 3.0;

/// The points inside a pot are those within this share of its radius from its axis.
const INSIDE_SHARE: f64 = 0.5;

/// A pot's inside below its rim holds its soil, not the plant: at least three quarters of the
/// points there lie at most this many radii below the rim ([`inside_depths`]). Where more lie
/// deeper, the "pot" is the plant's own points taken for one: on the real Arabidopsis (a pot
/// hidden under its rosette, no floor in its points) pieces of the lower stem's halo at one
/// distance from the cameras' axis made a pot whose rim stood 12 cm up the stem, and the stem
/// went on inside it: three quarters of the points inside lay up to 2.7 radii below the rim.
/// On 17 synthetic plants (broadleaf, medium and compound, from photos and semi-dense) they lie
/// within 0.01–0.17 radii of it: the soil line.
const MAX_INSIDE_DEPTH: f64 = 0.5;

/// Fewer pot points at its wall's heights than this say nothing about its wall's radius.
const MIN_WALL_POINTS: usize = 20;

/// Fewer points inside a pot than this say nothing about its inside.
const MIN_INSIDE_POINTS: usize = 20;

/// The depths below the rim (`rim_centre`, on the pot's axis), ascending, of the `points`
/// inside a pot of `radius` (within [`INSIDE_SHARE`] of it from the axis, below the rim by at
/// most `height`: the pot's height without its foot, where the floor the foreground takes for
/// plant lies, see [`WALL_BOTTOM`]); `None` with fewer than [`MIN_INSIDE_POINTS`] such points
/// or a pot without radius. The pot's test ([`MAX_INSIDE_DEPTH`]) takes their third quartile,
/// its soil surface their median.
fn inside_depths(
    rim_centre: &Point3<f64>,
    radius: f64,
    height: f64,
    points: &[Point3<f64>],
    up: &Vector3<f64>,
) -> Option<Vec<f64>> {
    if radius.is_nan() || radius <= 0.0 {
        return None;
    }
    let mut depths: Vec<f64> = points
        .iter()
        .filter_map(|p| {
            let depth = up.dot(&(rim_centre - p));
            let across = distance_from_axis(p, rim_centre, up);
            (depth > 0.0 && depth <= height && across < INSIDE_SHARE * radius).then_some(depth)
        })
        .collect();
    if depths.len() < MIN_INSIDE_POINTS {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    Some(depths)
}

/// Height bands of a pot's wall fitted together ([`banded_circle_centre`]).
const WALL_BANDS: usize = 4;

/// Where the wall's voters start, as a share of the pot's height (from its lowest points to its
/// rim): the lowest seventh, where the wall meets the floor, is left out. The floor's texture
/// that the foreground step takes for plant lies there in every direction, and it outvoted a
/// wall seen on one side only: from photos of broadleaf seed 2, where stereo found a third of
/// the wall, the axis came out 124 mm from the true one, and 1.4 mm without the floor (the
/// other five plants of seeds 1–3 and 11–13: 0.1–6.3 mm before, 0.2–2.1 mm after).
const WALL_BOTTOM: f64 = 0.14;

/// Where the wall's voters end, as a share of the pot's height: the soil and whatever leans
/// over the rim stay out.
const WALL_TOP: f64 = 0.7;

/// The wall band ([`WALL_BANDS`] of equal height between [`WALL_BOTTOM`] and [`WALL_TOP`] of
/// the way from `low` to `rim`) a point at `height` votes in; `None` at the floor, the soil
/// and the rim.
fn wall_band(height: f64, low: f64, rim: f64) -> Option<usize> {
    let bottom = low + WALL_BOTTOM * (rim - low);
    let top = low + WALL_TOP * (rim - low);
    if !(height >= bottom && height <= top && top > bottom) {
        return None;
    }
    let band = ((height - bottom) / (top - bottom) * WALL_BANDS as f64) as usize;
    Some(band.min(WALL_BANDS - 1))
}

/// [`concentric_circle_centre`] with one circle per wall band.
fn banded_circle_centre(points: &[(f64, f64, usize)]) -> Option<(f64, f64)> {
    concentric_circle_centre(points, WALL_BANDS)
}

/// The centre of a pot's wall among outliers (floor, soil, pieces of plant taken for pot),
/// from points `(x, y, band)`: a Hough vote over a grid of centres (61 × 61 over the points'
/// bounding box widened by half its size each way), each scoring, per band, the most
/// populated ring of width 1/100 of the box (two adjacent bins) around it; then the banded
/// least-squares fit ([`banded_circle_centre`]) to the points on the winning rings, kept
/// where it stays within two grid steps of the vote. `None` without points or extent.
fn robust_circle_centre(points: &[(f64, f64, usize)]) -> Option<(f64, f64)> {
    const GRID: usize = 61;
    const RING_BINS: usize = 200;
    const MAX_VOTERS: usize = 2000;
    let (mut min, mut max) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in points {
        min = (min.0.min(p.0), min.1.min(p.1));
        max = (max.0.max(p.0), max.1.max(p.1));
    }
    let size = (max.0 - min.0).max(max.1 - min.1);
    if !size.is_finite() || size <= 0.0 {
        return None;
    }
    let stride = points.len().div_ceil(MAX_VOTERS).max(1);
    let voters: Vec<&(f64, f64, usize)> = points.iter().step_by(stride).collect();
    let step = 2.0 * size / (GRID - 1) as f64;
    let ring = size / 100.0;
    let origin = (min.0 - 0.5 * size, min.1 - 0.5 * size);
    let mut histogram = vec![0u32; WALL_BANDS * RING_BINS];
    // (score, centre, best ring per band)
    let mut best: Option<(u32, (f64, f64), [usize; WALL_BANDS])> = None;
    for gx in 0..GRID {
        for gy in 0..GRID {
            let centre = (origin.0 + gx as f64 * step, origin.1 + gy as f64 * step);
            histogram.iter_mut().for_each(|h| *h = 0);
            for p in &voters {
                let bin = ((p.0 - centre.0).hypot(p.1 - centre.1) / ring) as usize;
                if bin < RING_BINS {
                    histogram[p.2.min(WALL_BANDS - 1) * RING_BINS + bin] += 1;
                }
            }
            let mut score = 0;
            let mut rings = [0usize; WALL_BANDS];
            for (band, ring_of_band) in rings.iter_mut().enumerate() {
                let row = &histogram[band * RING_BINS..(band + 1) * RING_BINS];
                let (bin, count) = row
                    .windows(2)
                    .enumerate()
                    .map(|(k, w)| (k, w[0] + w[1]))
                    .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
                    .unwrap_or((0, 0));
                score += count;
                *ring_of_band = bin;
            }
            if best.is_none_or(|b| score > b.0) {
                best = Some((score, centre, rings));
            }
        }
    }
    let (_, voted, rings) = best?;
    let on_rings: Vec<(f64, f64, usize)> = points
        .iter()
        .filter(|p| {
            let distance = (p.0 - voted.0).hypot(p.1 - voted.1) / ring;
            let low = rings[p.2.min(WALL_BANDS - 1)] as f64;
            distance >= low - 1.0 && distance < low + 3.0
        })
        .copied()
        .collect();
    Some(match banded_circle_centre(&on_rings) {
        Some(fitted) if (fitted.0 - voted.0).hypot(fitted.1 - voted.1) <= 2.0 * step => fitted,
        _ => voted,
    })
}

/// Whether a segment's points lie on the pot's wall: their mean distance from the pot's axis is
/// within [`WALL_RADIUS_TOLERANCE`] of the wall's radius ([`PotShape::wall_radius`]), they
/// spread across it by less than [`WALL_RADIAL_SPREAD`] of that distance (a surface of
/// revolution about the axis, as the segmentation's own pot test asks about the cameras' axis)
/// or about a taper ([`spread_about_a_taper`]), and their centroid is below the rim or they lie
/// on the rim's lip ([`RIM_LIP`]). A leaf may hang over the rim, but its points are spread over
/// distances from the axis and it starts above the rim; a piece of the wall that the leaf test
/// took as a sheet is low and at one distance (from photos of broadleaf seeds 1, 2, 11 and 13:
/// one such "leaf" each, 2,254–4,468 points, 6–8 cm below the rim, mean distance 0.98–1.01 pot
/// radii, spread 5–9 %; every true leaf of seeds 1–3 and 11–13 starts above the rim).
pub fn on_the_wall(points: &[Point3<f64>], pot: &PotShape, up: &Vector3<f64>) -> bool {
    if points.is_empty() || pot.wall_radius <= 0.0 {
        return false;
    }
    let n = points.len() as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let (lowest, highest) =
        points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                let height = up.dot(&(p - pot.rim_centre));
                (lo.min(height), hi.max(height))
            });
    let below_the_rim = up.dot(&(centroid - pot.rim_centre.coords)) < 0.0;
    let on_the_lip = lowest <= 0.0 && highest <= RIM_LIP * pot.wall_radius;
    if !below_the_rim && !on_the_lip {
        return false;
    }
    let (mean, spread) = radial_mean_and_spread(points, &pot.rim_centre, up);
    let spread =
        spread_about_a_taper(points, &pot.rim_centre, up).map_or(spread, |s| s.min(spread));
    (mean - pot.wall_radius).abs() <= WALL_RADIUS_TOLERANCE * pot.wall_radius
        && spread < WALL_RADIAL_SPREAD * mean
}

/// How far points' distances from the vertical axis through `axis_point` spread (standard
/// deviation) about a line fitted to them against height, where that line widens upward as a
/// pot's wall does, by at most [`MAX_WALL_SLOPE`]; `None` where it narrows upward (a leaf
/// hanging out over a rim spreads outward as it goes down), widens faster (a leaf lying over
/// the soil and rising toward the rim) or the points span no height. A whole wall from the floor to the
/// rim spreads by its taper alone: on photos of broadleaf seeds 4, 7, 23 and 24 one such
/// "leaf" each (1,206–2,072 points, from the floor to the rim) spread 10–14 % of its mean
/// distance about the axis, and 1.1–1.5 % about its taper (0.20–0.35 wider per unit of
/// height); it was fitted and attached to the stem, and its foot on the floor made the plant
/// 41–52 % too tall.
pub fn spread_about_a_taper(
    points: &[Point3<f64>],
    axis_point: &Point3<f64>,
    up: &Vector3<f64>,
) -> Option<f64> {
    let rows: Vec<(f64, f64)> = points
        .iter()
        .map(|p| {
            (
                up.dot(&(p - axis_point)),
                distance_from_axis(p, axis_point, up),
            )
        })
        .collect();
    let n = rows.len() as f64;
    let (mean_h, mean_r) = rows
        .iter()
        .fold((0.0, 0.0), |(h, r), row| (h + row.0 / n, r + row.1 / n));
    let (shh, shr) = rows.iter().fold((0.0, 0.0), |(shh, shr), (h, r)| {
        (
            shh + (h - mean_h).powi(2),
            shr + (h - mean_h) * (r - mean_r),
        )
    });
    if shh.is_nan() || shh <= 0.0 {
        return None;
    }
    let slope = shr / shh;
    if !(0.0..=MAX_WALL_SLOPE).contains(&slope) {
        return None;
    }
    let residual = rows
        .iter()
        .map(|(h, r)| (r - mean_r - slope * (h - mean_h)).powi(2))
        .sum::<f64>()
        / n;
    Some(residual.sqrt())
}

/// A pot's wall stands nearer vertical than horizontal: its distance from the axis grows by at
/// most this per unit of height (45°). The synthetic pots' walls grow by 0.20–0.35 (measured on
/// the four whole walls of [`spread_about_a_taper`]); a rosette's leaf lying over the soil and
/// rising 20° toward the rim grows by 2.7.
const MAX_WALL_SLOPE: f64 = 1.0;

/// The mean distance of points from the vertical axis through `axis_point` (along `up`) and
/// the standard deviation of those distances: a surface of revolution about the axis has a
/// small spread. `(NaN, NaN)` for no points.
pub fn radial_mean_and_spread(
    points: &[Point3<f64>],
    axis_point: &Point3<f64>,
    up: &Vector3<f64>,
) -> (f64, f64) {
    let radial: Vec<f64> = points
        .iter()
        .map(|p| distance_from_axis(p, axis_point, up))
        .collect();
    let n = radial.len() as f64;
    let mean = radial.iter().sum::<f64>() / n;
    let spread = (radial.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, spread)
}

/// A plant grows out of its pot, so its leaves stand above the rim: at most this share of its
/// leaf points lie more than [`BELOW_RIM_RADII`] of the pot's radius below the rim
/// ([`leaves_above_the_rim`]). On 12 synthetic plants (broadleaf and medium from photos;
/// medium, compound, broadleaf and smallleaf semi-dense) 0–0.4 %; on two COLMAP runs of the
/// real Arabidopsis the "pots" that pieces of its lower stem's halo made (rims 7–10 cm up the
/// stem) had 16 % and 34 % of its leaf points below their rims: the rosette and the lower
/// stem's leaves. A plant whose leaves hang far down the outside of its pot has no pot for
/// Frond; it is rooted on its soil line, as a plant without a pot is.
pub const MAX_LEAF_SHARE_BELOW_RIM: f64 = 0.05;

/// How far below a pot's rim (in its radii) a leaf point counts as below it: leaves resting on
/// the rim dip a little below it.
const BELOW_RIM_RADII: f64 = 0.1;

/// Whether at most [`MAX_LEAF_SHARE_BELOW_RIM`] of the plant's leaf points (`leaves`) lie below
/// the pot's rim; true without leaf points.
pub fn leaves_above_the_rim(pot: &PotShape, leaves: &[Point3<f64>], up: &Vector3<f64>) -> bool {
    let below = leaves
        .iter()
        .filter(|p| up.dot(&(*p - pot.rim_centre)) < -BELOW_RIM_RADII * pot.radius)
        .count();
    below as f64 <= MAX_LEAF_SHARE_BELOW_RIM * leaves.len() as f64
}

/// How far points reach around the vertical axis through `axis_point` (along `up`): the
/// standard deviation of their arc length about it, each point's angle from the points' mean
/// direction from the axis times their mean distance from it. A piece of a surface of
/// revolution reaches around the axis further than its distances from it spread; a blob beside
/// the axis (a piece of a stem, a leaf) reaches around about as far as it spreads. `NaN` for
/// no points; 0 when they all lie on the axis.
pub fn tangential_spread(
    points: &[Point3<f64>],
    axis_point: &Point3<f64>,
    up: &Vector3<f64>,
) -> f64 {
    let radial: Vec<Vector3<f64>> = points
        .iter()
        .map(|p| {
            let d = p - axis_point;
            d - up * up.dot(&d)
        })
        .collect();
    let n = radial.len() as f64;
    let mean_radius = radial.iter().map(|r| r.norm()).sum::<f64>() / n;
    let Some(mean_direction) = radial
        .iter()
        .filter_map(|r| r.try_normalize(1e-12))
        .sum::<Vector3<f64>>()
        .try_normalize(1e-12)
    else {
        return if points.is_empty() { f64::NAN } else { 0.0 };
    };
    let side = up.cross(&mean_direction);
    let arcs: Vec<f64> = radial
        .iter()
        .map(|r| r.dot(&side).atan2(r.dot(&mean_direction)) * mean_radius)
        .collect();
    let mean_arc = arcs.iter().sum::<f64>() / n;
    (arcs.iter().map(|a| (a - mean_arc).powi(2)).sum::<f64>() / n).sqrt()
}

/// The points that vote for the pot's wall ([`pot_from_points`]): every point of the plant's
/// foreground (plant or stem class). Labels often give only pieces of the wall; what else
/// stands at the wall's heights is outvoted by the wall.
pub fn wall_voters(positions: &[Point3<f64>], foreground: &Foreground) -> Vec<Point3<f64>> {
    positions
        .iter()
        .zip(&foreground.class)
        .filter(|(_, c)| matches!(c, PointClass::Plant | PointClass::Stem))
        .map(|(p, _)| *p)
        .collect()
}

/// How far (a share of the pot's radius) a wall segment's mean distance from the axis may be
/// from the pot's radius: pots taper (the synthetic ones by 17 % from rim to foot).
pub const WALL_RADIUS_TOLERANCE: f64 = 0.3;

/// The largest spread of a wall segment's distances from the axis, as a share of their mean.
pub const WALL_RADIAL_SPREAD: f64 = 0.1;

/// A segment reaching from below the rim to at most this share of the wall's radius above it
/// lies on the rim's lip: a strip of the rim at the wall's radius is pot even where its
/// centroid is just above the rim. On photos of medium 3 (stop 81) a rim strip fitted as a
/// leaf (102 points, 1.09 wall radii from the axis, spread 2.3 %) reached from 0.009 wall
/// radii below the rim to 0.067 above it; a leaf that starts on the rim and rises from it
/// reaches higher, and one lying along it spreads over distances from the axis.
pub const RIM_LIP: f64 = 0.1;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wall_is_low_at_one_distance_from_the_axis() {
        let up = Vector3::z();
        let pot = PotShape {
            rim_centre: Point3::new(0.0, 0.0, 0.12),
            soil_centre: Point3::new(0.0, 0.0, 0.11),
            radius: 0.085,
            wall_radius: 0.085,
        };
        let ring = |r: f64, z: f64, a0: f64, a1: f64| -> Vec<Point3<f64>> {
            (0..50)
                .map(|k| {
                    let a = a0 + (a1 - a0) * k as f64 / 49.0;
                    Point3::new(r * a.cos(), r * a.sin(), z + 0.001 * (k % 7) as f64)
                })
                .collect()
        };
        // An arc of the wall, a third of the way up; the same arc 3 cm above the rim.
        let mut piece = ring(0.08, 0.04, 0.0, 1.0);
        piece.extend(ring(0.082, 0.06, 0.0, 1.0));
        assert!(on_the_wall(&piece, &pot, &up));
        let lifted: Vec<Point3<f64>> = piece.iter().map(|p| p + up * 0.11).collect();
        assert!(!on_the_wall(&lifted, &pot, &up));
        // Soil inside the rim (nearer the axis) and a leaf hanging down outside the wall
        // (spread over distances from the axis).
        let mut soil = ring(0.02, 0.1, 0.0, 6.0);
        soil.extend(ring(0.05, 0.1, 0.0, 6.0));
        assert!(!on_the_wall(&soil, &pot, &up));
        let hanging: Vec<Point3<f64>> = (0..50)
            .map(|k| {
                let t = k as f64 / 49.0;
                Point3::new(0.09 + 0.1 * t, 0.0, 0.12 - 0.08 * t)
            })
            .collect();
        assert!(!on_the_wall(&hanging, &pot, &up));
        assert!(!on_the_wall(&[], &pot, &up));
        // The whole wall of an arc from the floor to the rim, tapering from 0.066 to 0.1:
        // spread 12 % of its mean distance about the axis, which its taper explains.
        let tapered: Vec<Point3<f64>> = (0..400)
            .map(|k| {
                let z = 0.12 * (k % 40) as f64 / 39.0;
                let a = 0.02 * (k / 40) as f64;
                let r = 0.066 + 0.034 * z / 0.12;
                Point3::new(r * a.cos(), r * a.sin(), z)
            })
            .collect();
        let (mean, spread) = radial_mean_and_spread(&tapered, &pot.rim_centre, &up);
        assert!(spread > WALL_RADIAL_SPREAD * mean, "{spread} {mean}");
        assert!(on_the_wall(&tapered, &pot, &up));
        // The same sheet widening downward (a leaf spreading out over the rim) is not wall.
        let flared: Vec<Point3<f64>> = tapered
            .iter()
            .map(|p| Point3::new(p.x, p.y, 0.12 - p.z))
            .collect();
        assert!(!on_the_wall(&flared, &pot, &up));
        // A rosette's leaf inside the pot, lying over the soil and rising 14° toward the rim
        // (from 0.065 to 0.105 from the axis): no wall, however well a line fits it.
        let rising: Vec<Point3<f64>> = (0..400)
            .map(|k| {
                let r = 0.065 + 0.04 * (k % 40) as f64 / 39.0;
                let a = 0.02 * (k / 40) as f64;
                Point3::new(r * a.cos(), r * a.sin(), 0.105 + 0.25 * (r - 0.065))
            })
            .collect();
        assert!(!on_the_wall(&rising, &pot, &up));
    }

    #[test]
    fn a_pot_the_plant_goes_on_inside_below_its_rim_is_no_pot() {
        let up = Vector3::z();
        let mut rng = crate::util::rng::Rng::seed_from(3);
        // A wall of radius 0.08 from the floor (z = 0) to its rim (z = 0.12), all round.
        let wall: Vec<Point3<f64>> = (0..400)
            .map(|_| {
                let a = rng.range(0.0, std::f64::consts::TAU);
                Point3::new(0.08 * a.cos(), 0.08 * a.sin(), rng.range(0.0, 0.12))
            })
            .collect();
        // Soil a centimetre below the rim, and a stem standing on it.
        let soil = soil_disc(&mut rng, 200);
        let stem = |from: f64| -> Vec<Point3<f64>> {
            (0..1000)
                .map(|k| {
                    let z = from + (0.5 - from) * k as f64 / 999.0;
                    Point3::new(rng_free_jitter(k), rng_free_jitter(k + 7), z)
                })
                .collect()
        };
        let voters = |stem: Vec<Point3<f64>>| -> Vec<Point3<f64>> {
            wall.iter().chain(&soil).copied().chain(stem).collect()
        };
        let centre = Point3::new(0.0, 0.0, 0.3);
        let pot = pot_from_points(&wall, &voters(stem(0.11)), &up, &centre).expect("a pot");
        assert!((pot.rim_centre.z - 0.12).abs() < 0.01, "{pot:?}");
        assert!(pot.rim_centre.coords.xy().norm() < 0.005, "{pot:?}");
        // The stem leaves the soil on the pot's axis, not at the rim's height.
        assert!((pot.soil_centre.z - 0.11).abs() < 0.002, "{pot:?}");
        assert!(
            (pot.soil_centre - pot.rim_centre).xy().norm() < 1e-12,
            "{pot:?}"
        );
        // The same wall with the stem going on inside it down to the floor: what was taken
        // for the pot's wall is not one (the plant does not grow under its soil).
        assert_eq!(
            pot_from_points(&wall, &voters(stem(0.0)), &up, &centre),
            None
        );
    }

    #[test]
    fn an_arc_reaches_round_the_axis_and_a_blob_beside_it_does_not() {
        let up = Vector3::z();
        let axis = Point3::new(0.1, -0.2, 0.0);
        // 101 points evenly along an arc of 60° at radius 0.5 about the axis, at any heights:
        // arc lengths uniform over 0.5·π/3, standard deviation that over √12 (within the
        // discrete sum's 1 %).
        let arc: Vec<Point3<f64>> = (0..=100)
            .map(|k| {
                let a = 1.0 + std::f64::consts::FRAC_PI_3 * (k as f64 / 100.0 - 0.5);
                axis + Vector3::new(0.5 * a.cos(), 0.5 * a.sin(), 0.01 * k as f64)
            })
            .collect();
        let expected = 0.5 * std::f64::consts::FRAC_PI_3 / 12f64.sqrt();
        let spread = tangential_spread(&arc, &axis, &up);
        assert!(
            (spread / expected - 1.0).abs() < 0.01,
            "{spread} {expected}"
        );
        // The arc turned to centre on the angle π, where atan2 wraps: the same.
        let turn = std::f64::consts::PI - 1.0;
        let across_pi: Vec<Point3<f64>> = arc
            .iter()
            .map(|p| {
                let d = p - axis;
                let (sin, cos) = turn.sin_cos();
                axis + Vector3::new(d.x * cos - d.y * sin, d.x * sin + d.y * cos, d.z)
            })
            .collect();
        let turned = tangential_spread(&across_pi, &axis, &up);
        assert!((turned / spread - 1.0).abs() < 1e-9, "{turned} {spread}");
        // A square blob 2 cm across, 0.5 from the axis: it reaches round the axis about as far
        // as it spreads across (uniform over 2 cm: 0.02/√12).
        let blob: Vec<Point3<f64>> = (0..=20)
            .flat_map(|i| {
                (0..=20).map(move |j| {
                    axis + Vector3::new(
                        0.5 + 0.001 * (i as f64 - 10.0),
                        0.001 * (j as f64 - 10.0),
                        0.0,
                    )
                })
            })
            .collect();
        let across = 0.02 / 12f64.sqrt();
        let spread = tangential_spread(&blob, &axis, &up);
        assert!((spread / across - 1.0).abs() < 0.15, "{spread} {across}");
        assert!(tangential_spread(&[], &axis, &up).is_nan());
        assert_eq!(tangential_spread(&[axis, axis], &axis, &up), 0.0);
    }

    #[test]
    fn leaves_stand_above_the_rim_of_their_pot() {
        let up = Vector3::z();
        let pot = PotShape {
            rim_centre: Point3::new(0.0, 0.0, 0.12),
            soil_centre: Point3::new(0.0, 0.0, 0.11),
            radius: 0.08,
            wall_radius: 0.08,
        };
        // 100 leaf points: the crown above the rim, a few resting on it (down to 0.1 radius
        // below it), and `hanging` of them 3 cm below it outside the wall.
        let leaves = |hanging: usize| -> Vec<Point3<f64>> {
            (0..100)
                .map(|k| match k {
                    k if k < hanging => Point3::new(0.12, 0.0, 0.09),
                    k if k < hanging + 10 => Point3::new(0.085, 0.0, 0.12 - 0.0079),
                    _ => Point3::new(0.0, 0.05, 0.2 + 0.001 * k as f64),
                })
                .collect()
        };
        assert!(leaves_above_the_rim(&pot, &leaves(0), &up));
        assert!(leaves_above_the_rim(&pot, &leaves(5), &up));
        // A sixth of the leaves below the rim (the Arabidopsis's rosette under a "pot" its
        // stem's halo made): no pot.
        assert!(!leaves_above_the_rim(&pot, &leaves(16), &up));
        assert!(leaves_above_the_rim(&pot, &[], &up));
    }

    #[test]
    fn a_pot_taller_than_three_radii_is_no_pot() {
        let up = Vector3::z();
        let mut rng = crate::util::rng::Rng::seed_from(5);
        // Walls of radius 0.03 around a stem, with soil at their top: 1.5 radii tall is a pot,
        // 4 radii tall (pieces of a plant at one distance from the cameras' axis) is not.
        let wall = |height: f64, rng: &mut crate::util::rng::Rng| -> Vec<Point3<f64>> {
            (0..400)
                .map(|_| {
                    let a = rng.range(0.0, std::f64::consts::TAU);
                    Point3::new(0.03 * a.cos(), 0.03 * a.sin(), rng.range(0.0, height))
                })
                .collect()
        };
        let centre = Point3::new(0.0, 0.0, 0.3);
        for (height, is_pot) in [(0.045, true), (0.12, false)] {
            let pot = wall(height, &mut rng);
            let voters: Vec<Point3<f64>> = pot
                .iter()
                .copied()
                .chain((0..200).map(|k| {
                    let a = k as f64 * 0.7;
                    Point3::new(0.02 * a.cos(), 0.02 * a.sin(), height - 0.001)
                }))
                .collect();
            let found = pot_from_points(&pot, &voters, &up, &centre);
            assert_eq!(found.is_some(), is_pot, "{height}: {found:?}");
        }
    }

    /// `n` points of soil inside a rim of radius 0.07, at z = 0.11 ± 2 mm.
    fn soil_disc(rng: &mut crate::util::rng::Rng, n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|_| {
                let (r, a) = (0.07 * rng.range(0.0, 1.0f64).sqrt(), rng.range(0.0, 6.3));
                Point3::new(r * a.cos(), r * a.sin(), 0.11 + rng.range(-0.002, 0.002))
            })
            .collect()
    }

    /// A point of a pot's wall tapering from radius 0.075 at the floor (z = 0) to 0.09 at the
    /// rim (z = 0.12), its axis through the origin; above the rim the radius stays 0.09.
    fn tapered_wall(z: f64, angle: f64) -> Point3<f64> {
        let radius = 0.075 + 0.015 * z.min(0.12) / 0.12;
        Point3::new(radius * angle.cos(), radius * angle.sin(), z)
    }

    /// That pot seen all round (400 wall points) with its soil a little below the rim,
    /// sampled twice as densely as the wall (as stereo sees a pot from above).
    fn tapered_pot(seed: u64) -> Vec<Point3<f64>> {
        let mut rng = crate::util::rng::Rng::seed_from(seed);
        let mut pot: Vec<Point3<f64>> = (0..400)
            .map(|_| tapered_wall(rng.range(0.0, 0.12), rng.range(0.0, 6.3)))
            .collect();
        pot.extend(soil_disc(&mut rng, 800));
        pot
    }

    /// Deterministic jitter within 2 mm.
    fn rng_free_jitter(k: usize) -> f64 {
        0.002 * ((k as f64 * 12.9898).sin() * 43_758.545).fract()
    }

    #[test]
    fn a_tapered_wall_is_centred_from_a_third_of_its_arc_among_outliers() {
        let (cx, cy) = (0.3, -0.2);
        let mut rng = crate::util::rng::Rng::seed_from(5);
        // A third of a cone's wall, radius 0.08 at the bottom band to 0.096 at the top.
        let mut points: Vec<(f64, f64, usize)> = (0..600)
            .map(|k| {
                let band = k % WALL_BANDS;
                let angle = rng.range(0.2, 2.3);
                let radius = (0.08 + 0.004 * band as f64) * (1.0 + 0.01 * rng.range(-1.0, 1.0));
                (cx + radius * angle.cos(), cy + radius * angle.sin(), band)
            })
            .collect();
        let exact = banded_circle_centre(&points).expect("a centre");
        assert!((exact.0 - cx).hypot(exact.1 - cy) < 0.002, "{exact:?}");
        // A fifth as many outliers scattered inside and beyond the wall.
        for k in 0..120 {
            points.push((
                cx + rng.range(-0.3, 0.3),
                cy + rng.range(-0.3, 0.3),
                k % WALL_BANDS,
            ));
        }
        let robust = robust_circle_centre(&points).expect("a centre");
        assert!((robust.0 - cx).hypot(robust.1 - cy) < 0.005, "{robust:?}");
        // Collinear points fix no centre.
        let line: Vec<(f64, f64, usize)> = (0..10).map(|k| (k as f64, 2.0 * k as f64, 0)).collect();
        assert_eq!(banded_circle_centre(&line), None);
    }

    #[test]
    fn the_wall_radius_is_measured_on_the_wall_not_pulled_in_by_the_soil() {
        // A pot on the floor (z = 0), its axis through the origin, its wall tapering from 0.075
        // at the floor to 0.09 at the rim (z = 0.12), seen all round; its soil a little below
        // the rim, sampled twice as densely as the wall (as stereo sees a pot from above).
        let pot = tapered_pot(23);
        let wall = tapered_wall;
        let up = Vector3::z();
        let shape = pot_from_points(&pot, &pot, &up, &Point3::new(0.0, 0.0, 0.06)).expect("a pot");
        // The soil (radius 0 to 0.07) pulls the median of all the points well inside the wall;
        // the wall's own radius is that of its middle heights.
        assert!(shape.radius < 0.065, "{shape:?}");
        assert!((shape.wall_radius - 0.081).abs() < 0.004, "{shape:?}");
        // A strip of the wall near the rim (0.086-0.088 from the axis, 1-3 cm below it) is
        // wall; measured against the median of all points it was not (1.4 of those radii).
        let strip: Vec<Point3<f64>> = (0..60)
            .map(|k| wall(0.085 + 0.015 * (k % 6) as f64 / 5.0, 0.5 + 0.01 * k as f64))
            .collect();
        assert!(on_the_wall(&strip, &shape, &up));
        let pulled_in = PotShape {
            wall_radius: shape.radius,
            ..shape
        };
        assert!(!on_the_wall(&strip, &pulled_in, &up));
    }

    #[test]
    fn a_strip_on_the_rims_lip_is_pot_and_one_rising_above_it_is_not() {
        // The pot of the wall-radius test; strips of an arc at the rim's radius.
        let pot = tapered_pot(29);
        let wall = tapered_wall;
        let up = Vector3::z();
        let shape = pot_from_points(&pot, &pot, &up, &Point3::new(0.0, 0.0, 0.06)).expect("a pot");
        let rim = shape.rim_centre.z;
        let strip = |from: f64, to: f64| -> Vec<Point3<f64>> {
            (0..80)
                .map(|k| {
                    let t = (k % 8) as f64 / 7.0;
                    wall(
                        rim + (from + (to - from) * t) * shape.wall_radius,
                        0.5 + 0.01 * k as f64,
                    )
                })
                .collect()
        };
        // From just below the rim to 0.07 wall radii above it, the centroid above the rim.
        let lip = strip(-0.01, 0.07);
        assert!(on_the_wall(&lip, &shape, &up), "{shape:?}");
        // The same arc reaching 0.3 wall radii above the rim, or wholly above it, is not.
        assert!(!on_the_wall(&strip(-0.01, 0.3), &shape, &up));
        assert!(!on_the_wall(&strip(0.01, 0.07), &shape, &up));
        // Wholly below the rim it is wall as before.
        assert!(on_the_wall(&strip(-0.2, -0.05), &shape, &up));
    }

    #[test]
    fn a_pot_seen_on_one_side_is_centred_despite_the_floor_around_it() {
        // A pot on the floor (z = 0), its axis through the origin, its wall tapering from 0.075
        // at the floor to 0.09 at the rim (z = 0.12), of which stereo found an arc of 80°.
        let mut rng = crate::util::rng::Rng::seed_from(11);
        let arc: Vec<Point3<f64>> = (0..300)
            .map(|_| tapered_wall(rng.range(0.0, 0.12), rng.range(2.0, 3.4)))
            .collect();
        // Soil inside the rim, a little below it.
        let soil = soil_disc(&mut rng, 200);
        // The floor's blotches, taken for plant, all around: 120 blobs of 100 points within
        // 0.3 of the axis, at the floor's height give or take its noise. With them among the
        // voters (the wall's voters starting at the floor) the axis came out 89 mm off.
        let mut floor = Vec::new();
        for _ in 0..120 {
            let (bx, by) = (rng.range(-0.3, 0.3), rng.range(-0.3, 0.3));
            floor.extend((0..100).map(|_| {
                Point3::new(
                    bx + rng.range(-0.01, 0.01),
                    by + rng.range(-0.01, 0.01),
                    rng.range(-0.004, 0.004),
                )
            }));
        }
        let mut pot = arc.clone();
        pot.extend(soil.iter().take(50));
        pot.extend(floor.iter().take(60));
        let mut voters = arc;
        voters.extend(soil);
        voters.extend(floor);
        let up = Vector3::z();
        let look_at = Point3::new(0.03, -0.02, 0.2);
        let shape = pot_from_points(&pot, &voters, &up, &look_at).expect("a pot");
        let miss = shape.rim_centre.x.hypot(shape.rim_centre.y);
        assert!(miss < 0.003, "axis {miss} from the truth: {shape:?}");
        assert!((shape.rim_centre.z - 0.12).abs() < 0.01, "{shape:?}");
        // Too few pot points: no pot.
        assert_eq!(
            pot_from_points(&pot[..MIN_POT_POINTS - 1], &voters, &up, &look_at),
            None
        );
    }
}
