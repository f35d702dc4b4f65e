//! A leaf's extent voted over views on its plane. Stereo samples a weakly textured leaf only
//! in patches (its veins, its rim), and the image boundary of one view, held near those
//! points by the spatial prior of [`crate::segment::boundary`], stops inside the leaf. With a
//! weaker prior the graph cut follows the leaf's colour to its edge, and in some views also
//! leaks into what touches it in the image: a neighbouring leaf of the same green, backdrop.
//! Back-projected onto the leaf's plane, the leaf itself lands in the same place from every
//! view, while a leak lands wherever that view's line of sight puts it: it moves with the view
//! unless it lies in the leaf's own plane. A cell of one view's wide region that more of the
//! other views confirm than deny is therefore leaf: a plane-restricted visual hull, voted
//! rather than intersected, and a view where something nearer hides that part of the leaf has
//! no say, so that an occluder does not cut the leaf.

use nalgebra::Point2;
use opencv::core::{Mat, Scalar};
use opencv::prelude::*;

use serde::{Deserialize, Serialize};

use crate::segment::boundary::{BoundaryOptions, largest_outer_contour};
use crate::util::polygon;

/// Settings of the vote across views.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewVoteOptions {
    pub enabled: bool,
    /// The wide regions' spatial prior, nats per pixel and point spacing beyond the points'
    /// reach (the leaf's own boundary uses [`BoundaryOptions::default`]'s 1).
    pub reach_slope: f64,
    /// The wide regions' search window around the points' bounding box, in its longer side
    /// (the leaf's own boundary uses 0.5: a leaf sampled on one end of it reaches farther).
    pub window_margin: f64,
    /// How far (share of the vote grid's extent) another view's region may lie from a cell
    /// and still confirm it: the misalignment between views' back-projections that a
    /// leaf's curvature off its fitted plane causes.
    pub tolerance: f64,
    /// Least candidate views with a wide region on the plane for a vote.
    pub min_views: usize,
}

impl Default for ViewVoteOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            reach_slope: 0.1,
            window_margin: 1.5,
            tolerance: 0.06,
            min_views: 3,
        }
    }
}

impl ViewVoteOptions {
    /// The graph-cut settings of the wide regions, from those of the leaf's own boundary.
    pub fn boundary_options(&self, own: &BoundaryOptions) -> BoundaryOptions {
        BoundaryOptions {
            reach_slope: self.reach_slope,
            window_margin: self.window_margin,
            ..*own
        }
    }
}

/// Cells per side of the vote grid over the regions' joint bounding box.
pub const VOTE_GRID: usize = 128;

/// A square grid of cells over plane coordinates, with one empty cell of margin around the
/// polygons it was made for.
struct PlaneGrid {
    origin: Point2<f64>,
    cell: f64,
    side: usize,
}

impl PlaneGrid {
    fn over<'a>(polygons: impl Iterator<Item = &'a Vec<Point2<f64>>>, side: usize) -> Option<Self> {
        let side = side.max(8);
        let (mut lo, mut hi) = (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in polygons.flatten() {
            lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if !(hi.x > lo.x && hi.y > lo.y) {
            return None;
        }
        let cell = (hi.x - lo.x).max(hi.y - lo.y) / (side - 2) as f64;
        Some(Self {
            origin: Point2::new(lo.x - cell, lo.y - cell),
            cell,
            side,
        })
    }

    fn centre(&self, i: usize, j: usize) -> Point2<f64> {
        Point2::new(
            self.origin.x + (i as f64 + 0.5) * self.cell,
            self.origin.y + (j as f64 + 0.5) * self.cell,
        )
    }

    /// Cells whose centre lies inside `polygon` (none for fewer than three vertices).
    fn rasterise(&self, polygon: &[Point2<f64>]) -> Vec<bool> {
        let mut cells = vec![false; self.side * self.side];
        if polygon.len() >= 3 {
            for j in 0..self.side {
                for i in 0..self.side {
                    cells[j * self.side + i] = polygon::inside_polygon(&self.centre(i, j), polygon);
                }
            }
        }
        cells
    }

    /// `cells` grown by `radius` cells (a disc).
    fn dilate(&self, cells: &[bool], radius: usize) -> Option<Vec<bool>> {
        if radius == 0 {
            return Some(cells.to_vec());
        }
        let mask = self.mask(cells)?;
        let r = radius as i32;
        let kernel = opencv::imgproc::get_structuring_element_def(
            opencv::imgproc::MORPH_ELLIPSE,
            opencv::core::Size::new(2 * r + 1, 2 * r + 1),
        )
        .ok()?;
        let mut grown = Mat::default();
        opencv::imgproc::dilate_def(&mask, &mut grown, &kernel).ok()?;
        Some(grown.data_bytes().ok()?.iter().map(|&v| v > 0).collect())
    }

    fn mask(&self, cells: &[bool]) -> Option<Mat> {
        let mut mask = Mat::new_rows_cols_with_default(
            self.side as i32,
            self.side as i32,
            opencv::core::CV_8UC1,
            Scalar::all(0.0),
        )
        .ok()?;
        let data = mask.data_bytes_mut().ok()?;
        for (d, &c) in data.iter_mut().zip(cells) {
            *d = if c { 255 } else { 0 };
        }
        Some(mask)
    }

    /// The outer contour (plane coordinates) of the largest connected set of `cells`.
    fn outline(&self, cells: &[bool]) -> Option<Vec<Point2<f64>>> {
        let contour = largest_outer_contour(&self.mask(cells)?).ok()??;
        let centres: Vec<Point2<f64>> = contour
            .iter()
            .map(|p| Point2::new(p.x as f64, p.y as f64))
            .collect();
        if centres.len() < 3 {
            return None;
        }
        // Contour vertices are cell centres; the region's edge is half a cell outside them.
        let edge = polygon::offset_polygon(&centres, 0.5);
        Some(
            edge.iter()
                .map(|p| {
                    Point2::new(
                        self.origin.x + (p.x + 0.5) * self.cell,
                        self.origin.y + (p.y + 0.5) * self.cell,
                    )
                })
                .collect(),
        )
    }
}

/// The outer contour (plane coordinates) of the largest connected set of grid cells that lie
/// inside `keep`, or inside `own` and confirmed by a majority of the `others` that have a say
/// on them. `own` is one view's region, `others` the other views' regions on the same plane;
/// another view confirms a cell when its region lies within `tolerance` (a share of the
/// grid's extent) of it, the misalignment that a leaf's curvature off its fitted plane causes
/// between views, and has no say where `hidden(k, cell)` (the leaf there is behind something
/// in the `k`-th other view). A cell needs at least one confirmation; the outline stays
/// `own`'s. `None` without a region or when OpenCV fails.
pub fn confirmed_region(
    keep: &[Point2<f64>],
    own: &[Point2<f64>],
    others: &[Vec<Point2<f64>>],
    tolerance: f64,
    hidden: &dyn Fn(usize, &Point2<f64>) -> bool,
    side: usize,
) -> Option<Vec<Point2<f64>>> {
    let keep = keep.to_vec();
    let own = own.to_vec();
    let grid = PlaneGrid::over([&keep, &own].into_iter().chain(others.iter()), side)?;
    let radius = (tolerance.max(0.0) * grid.side as f64).round() as usize;
    let covered: Vec<Vec<bool>> = others
        .iter()
        .map(|region| grid.dilate(&grid.rasterise(region), radius))
        .collect::<Option<_>>()?;
    let kept = grid.rasterise(&keep);
    let owned = grid.rasterise(&own);
    let cells: Vec<bool> = (0..kept.len())
        .map(|k| {
            if kept[k] {
                return true;
            }
            if !owned[k] {
                return false;
            }
            let centre = grid.centre(k % grid.side, k / grid.side);
            let (mut voters, mut confirmations) = (0usize, 0usize);
            for (i, cover) in covered.iter().enumerate() {
                if hidden(i, &centre) {
                    continue;
                }
                voters += 1;
                confirmations += usize::from(cover[k]);
            }
            confirmations >= 1 && confirmations > voters / 2
        })
        .collect();
    grid.outline(&cells)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rectangle(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point2<f64>> {
        vec![
            Point2::new(x0, y0),
            Point2::new(x1, y0),
            Point2::new(x1, y1),
            Point2::new(x0, y1),
        ]
    }

    #[test]
    fn the_own_region_grows_where_the_other_views_confirm_it() {
        // A unit leaf; kept: its lower half. The own view's wide region covers the leaf and
        // leaks 0.5 to the right; three other views see the whole leaf shifted down by 0.1
        // (the leaf curves off its plane), and one of them leaks to the right as well.
        let keep = rectangle(0.0, 0.0, 1.0, 0.5);
        let own = rectangle(0.0, 0.0, 1.5, 1.0);
        let others = vec![
            rectangle(0.0, -0.1, 1.0, 0.9),
            rectangle(0.02, -0.1, 1.02, 0.9),
            rectangle(0.0, -0.1, 1.4, 0.9),
        ];
        let seen = |_: usize, _: &Point2<f64>| false;
        let area = |keep: &[Point2<f64>], others: &[Vec<Point2<f64>>], tolerance: f64| {
            let region = confirmed_region(keep, &own, others, tolerance, &seen, VOTE_GRID).unwrap();
            polygon::polygon_area(&region).abs()
        };
        // Within the tolerance (0.08 of the grid's extent 1.6: 0.13) the shift is forgiven: the
        // full leaf, and the tolerance's width of the leak (area 1.13), not all of it (1.5).
        let widened = area(&keep, &others, 0.08);
        assert!((0.98..1.16).contains(&widened), "area {widened}");
        // Without tolerance the shifted views confirm only what they share with the leaf.
        let strict = area(&keep, &others, 0.0);
        assert!((0.87..0.93).contains(&strict), "area {strict}");
        // One other view that does not see the leaf's upper half outvotes the one that does.
        let blind = rectangle(0.0, -0.1, 1.0, 0.4);
        let split = vec![others[0].clone(), blind];
        let tie = area(&keep, &split, 0.08);
        assert!(tie < 0.7, "area {tie}");
        // Unless it sees that half behind something: then it has no say.
        let hidden = |k: usize, q: &Point2<f64>| k == 1 && q.y > 0.5;
        let region = confirmed_region(&keep, &own, &split, 0.08, &hidden, VOTE_GRID).unwrap();
        let behind = polygon::polygon_area(&region).abs();
        assert!((0.98..1.2).contains(&behind), "area {behind}");
        // With no other view nothing is confirmed: the kept half alone.
        let alone = area(&keep, &[], 0.08);
        assert!((alone - 0.5).abs() < 0.03, "area {alone}");
    }

    #[test]
    fn no_region_gives_none() {
        let seen = |_: usize, _: &Point2<f64>| false;
        assert!(confirmed_region(&[], &[], &[], 0.05, &seen, VOTE_GRID).is_none());
        let point = vec![Point2::new(1.0, 1.0); 3];
        assert!(confirmed_region(&point, &point, &[], 0.05, &seen, VOTE_GRID).is_none());
    }
}
