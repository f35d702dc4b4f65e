//! Model-based leaf reconstruction (seed 004 §6): a generic leaf extracted from one sample
//! segment ([`template`]) is fitted to every leaf segment ([`fit`]).
//!
//! [`reconstruct_leaves`] takes a [`LeafInput`] (the scene, its points, the current labels,
//! the plant's axis and branch tips, the per-view cache) and returns a [`LeafReconstruction`]:
//! it picks the sample leaf (the user's, or automatically the most fronto-parallel,
//! best-segmented large leaf), computes each leaf's image boundary in its best views, fits, and
//! collects the leaves, the boundaries it computed, and the segments that could not be posed
//! (with the reason) for the branch stage.

pub mod extent;
pub mod fit;
pub mod gap_fill;
pub mod template;

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use nalgebra::{Point2, Point3};
use serde::{Deserialize, Serialize};

pub use fit::{
    BoundaryView, FitError, FittedLeaf, LeafFitOptions, PlantContext, fit_leaf,
    fit_leaf_best_outline, leaf_frame,
};
pub use template::LeafTemplate;

use crate::graph::points::PointSet;
use crate::scene::{ImageFileStatus, Scene};
use crate::segment::boundary::{Boundary, BoundaryError};
use crate::segment::{Labels, SegmentLabel, ViewCache};
use crate::util::polygon;
use crate::util::progress::Progress;

/// What the leaf stage reads (plain data; see the module docs).
#[derive(Clone, Copy)]
pub struct LeafInput<'a> {
    pub scene: &'a Scene,
    pub points: &'a PointSet,
    pub labels: &'a Labels,
    /// The plant's up direction, axis and branch tips.
    pub plant: &'a PlantContext,
    /// Projections and superpixels per view (shared with the editing session).
    pub views: &'a ViewCache,
}

/// Image boundaries by (segment, view index).
pub type Boundaries = BTreeMap<(u32, usize), Boundary>;

/// Which segment and view the generic leaf is taken from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct TemplateSource {
    pub segment: u32,
    pub view: usize,
}

/// Settings of the leaf stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LeafOptions {
    pub fit: LeafFitOptions,
    /// Widening each leaf's image region by what the other views confirm.
    #[serde(default)]
    pub votes: extent::ViewVoteOptions,
    /// The user's sample leaf; `None` chooses one automatically.
    pub template: Option<TemplatePick>,
}

/// The user's choice of generic leaf: a segment, and optionally the view to take it from
/// (default: the segment's chosen boundary view).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TemplatePick {
    pub segment: u32,
    pub view: Option<usize>,
}

/// A leaf of the plant model.
#[derive(Clone, Debug, Serialize)]
pub struct ReconstructedLeaf {
    /// The segment it was fitted to (its `leaf_NNN` number).
    pub segment: u32,
    /// The view its boundary and texture come from.
    pub view: Option<usize>,
    pub fit: FittedLeaf,
}

/// A leaf segment that got no leaf, and why.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SkippedLeaf {
    pub segment: u32,
    pub points: usize,
    pub reason: String,
    /// Left for the branch stage to pose from its nearest branch (seed 004 §8).
    pub for_branch_stage: bool,
}

/// Seconds per stage of the leaf reconstruction.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct LeafTimings {
    pub template: f64,
    pub boundaries: f64,
    pub fitting: f64,
}

/// Everything the leaf stage produced.
#[derive(Clone, Debug, Serialize)]
pub struct LeafReconstruction {
    pub template_source: Option<TemplateSource>,
    #[serde(skip)]
    pub template: LeafTemplate,
    pub leaves: Vec<ReconstructedLeaf>,
    pub skipped: Vec<SkippedLeaf>,
    /// Views whose photos could not be used for boundaries or textures, and why.
    pub unusable_views: Vec<UnusableView>,
    /// Every image boundary computed on the way, for the caller to keep.
    #[serde(skip)]
    pub boundaries: Boundaries,
    pub timings: LeafTimings,
    /// Gap fills ([`gap_fill`]) the leaves were fitted with: in the input, and on leaf
    /// segments.
    pub gap_fills: usize,
    pub gap_fills_on_leaves: usize,
}

/// Leaf-stage failures.
#[derive(Debug, thiserror::Error)]
pub enum LeafError {
    #[error(transparent)]
    Boundary(#[from] BoundaryError),
    #[error("leaf reconstruction cancelled")]
    Cancelled,
    #[error("the generic leaf (segment {segment}{}): {message}", view.map(|v| format!(", view {v}")).unwrap_or_default())]
    BadTemplate {
        segment: u32,
        view: Option<usize>,
        message: String,
    },
}

/// A view's photo as RGB (None when it cannot be read: the leaf keeps the generic texture).
fn load_photo(scene: &Scene, view: usize) -> Option<image::RgbImage> {
    use opencv::prelude::*;
    let image = &scene.reconstruction.images()[view];
    let mat = scene.load_image(image).ok()?;
    let (w, h) = (mat.cols() as u32, mat.rows() as u32);
    let bytes = mat.data_bytes().ok()?;
    Some(image::RgbImage::from_fn(w, h, |x, y| {
        let i = ((y * w + x) * 3) as usize;
        image::Rgb([bytes[i + 2], bytes[i + 1], bytes[i]])
    }))
}

fn segment_points(input: &LeafInput, segment: u32) -> Vec<Point3<f64>> {
    input
        .labels
        .members(segment)
        .iter()
        .map(|&p| input.points.positions[p as usize])
        .collect()
}

/// Views of a segment ranked by how well they see it: visible points × |cos| between the
/// leaf normal and the viewing ray (fronto-parallel views first).
fn ranked_views(input: &LeafInput, segment: u32, plant: &PlantContext) -> Vec<(f64, usize)> {
    let members = input.labels.members(segment);
    let points = input.points;
    let positions: Vec<Point3<f64>> = members
        .iter()
        .map(|&p| points.positions[p as usize])
        .collect();
    let Ok((frame, _)) = leaf_frame(&positions, plant) else {
        return Vec::new();
    };
    let mut counts: HashMap<u32, usize> = HashMap::new();
    for &p in &members {
        for &v in &points.views[p as usize] {
            *counts.entry(v).or_insert(0) += 1;
        }
    }
    let images = input.scene.reconstruction.images();
    let mut ranked: Vec<(f64, usize)> = counts
        .into_iter()
        .map(|(v, count)| {
            let centre = images[v as usize].center_world();
            let ray = (frame.origin - centre).normalize();
            (count as f64 * ray.dot(&frame.normal).abs(), v as usize)
        })
        .collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    ranked
}

/// How many of a leaf's best views get an image boundary to choose from.
const BOUNDARY_CANDIDATES: usize = 5;

/// An image polygon back-projected onto a leaf plane, in plane coordinates (None when too
/// oblique: fewer than 80% of its vertices land on the plane at a usable angle).
fn plane_polygon(
    scene: &Scene,
    view: usize,
    polygon: &[[f64; 2]],
    frame: &fit::LeafFrame,
) -> Option<Vec<Point2<f64>>> {
    let model = &scene.reconstruction;
    let image = &model.images()[view];
    let camera = model.camera_of(image);
    let projected: Vec<Point2<f64>> = polygon
        .iter()
        .filter_map(|p| {
            frame.back_project(&Point2::new(p[0], p[1]), camera, &image.camera_from_world)
        })
        .collect();
    (projected.len() >= 3 && projected.len() * 10 >= polygon.len() * 8).then_some(projected)
}

/// Intersection over union of the regions inside each polygon, rasterised on a 64 × 64 grid
/// over their joint bounding box.
fn region_overlaps(polygons: &[Vec<Point2<f64>>]) -> Vec<Vec<f64>> {
    const GRID: usize = 64;
    let (mut lo, mut hi) = (
        Point2::new(f64::INFINITY, f64::INFINITY),
        Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in polygons.iter().flatten() {
        lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
        hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
    }
    let cells: Vec<Vec<bool>> = polygons
        .iter()
        .map(|polygon| {
            (0..GRID * GRID)
                .map(|k| {
                    let q = Point2::new(
                        lo.x + (hi.x - lo.x) * ((k % GRID) as f64 + 0.5) / GRID as f64,
                        lo.y + (hi.y - lo.y) * ((k / GRID) as f64 + 0.5) / GRID as f64,
                    );
                    polygon::inside_polygon(&q, polygon)
                })
                .collect()
        })
        .collect();
    cells
        .iter()
        .map(|a| {
            cells
                .iter()
                .map(|b| {
                    let both = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
                    let either = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
                    if either == 0 {
                        0.0
                    } else {
                        both as f64 / either as f64
                    }
                })
                .collect()
        })
        .collect()
}

/// Of a leaf's candidate regions (back-projected onto its plane, one per view), the largest
/// (seed 004 §6.2: "the largest region is used") among those consistent with the medoid
/// (the region overlapping the others most). A boundary whose graph cut leaked into the
/// background is large but disagrees with the rest, so it cannot win.
fn consensus_region(regions: &[(usize, Vec<Point2<f64>>)]) -> Option<(usize, f64)> {
    const CONSISTENT_IOU: f64 = 0.75;
    let polygons: Vec<Vec<Point2<f64>>> = regions.iter().map(|(_, p)| p.clone()).collect();
    let overlaps = region_overlaps(&polygons);
    let medoid = (0..regions.len()).max_by(|&a, &b| {
        let agreement = |i: usize| -> f64 { overlaps[i].iter().sum() };
        agreement(a).total_cmp(&agreement(b))
    })?;
    (0..regions.len())
        .filter(|&i| i == medoid || overlaps[medoid][i] >= CONSISTENT_IOU)
        .max_by(|&a, &b| {
            polygon::polygon_area(&polygons[a]).total_cmp(&polygon::polygon_area(&polygons[b]))
        })
        .map(|i| {
            let others = regions.len().saturating_sub(1);
            let agreement = if others == 0 {
                1.0
            } else {
                (0..regions.len())
                    .filter(|&j| j != i)
                    .map(|j| overlaps[i][j])
                    .sum::<f64>()
                    / others as f64
            };
            (regions[i].0, agreement)
        })
}

/// Builds the generic leaf from a segment's boundary in a view: the boundary is back-projected
/// onto the leaf's surface, the texture is the photo inside it.
pub fn extract_template(
    input: &LeafInput,
    boundaries: &mut Boundaries,
    source: TemplateSource,
    plant: &PlantContext,
    texture_size: u32,
) -> Result<LeafTemplate, LeafError> {
    let bad = |message: String| LeafError::BadTemplate {
        segment: source.segment,
        view: Some(source.view),
        message,
    };
    let points = segment_points(input, source.segment);
    let (frame, _) = leaf_frame(&points, plant).map_err(|e| bad(e.to_string()))?;
    let samples: Vec<(Point2<f64>, f64)> = points.iter().map(|p| frame.to_plane(p)).collect();
    let length_guess = samples
        .iter()
        .map(|s| s.0.coords.norm())
        .fold(0.0, f64::max)
        * 2.0;
    let heights = fit::HeightField::fit(&samples, length_guess);
    let key = (source.segment, source.view);
    if let std::collections::btree_map::Entry::Vacant(entry) = boundaries.entry(key) {
        entry.insert(input.views.boundary(
            input.scene,
            input.points,
            &input.labels.segment_of,
            source.segment,
            source.view,
        )?);
    }
    let polygon = boundaries[&key].polygon.clone();
    let image = &input.scene.reconstruction.images()[source.view];
    let camera = input.scene.reconstruction.camera_of(image).clone();
    let camera_from_world = image.camera_from_world;
    let outline = plane_polygon(input.scene, source.view, &polygon, &frame).unwrap_or_default();
    if outline.len() < 6 {
        return Err(bad("the view sees the leaf too obliquely".into()));
    }
    let (lo, hi) = outline.iter().fold(
        (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        ),
        |(lo, hi), p| {
            (
                Point2::new(lo.x.min(p.x), lo.y.min(p.y)),
                Point2::new(hi.x.max(p.x), hi.y.max(p.y)),
            )
        },
    );
    let photo = load_photo(input.scene, source.view);
    let size = texture_size.max(8);
    let texture = image::RgbaImage::from_fn(size, size, |i, j| {
        let q = Point2::new(
            lo.x + (i as f64 + 0.5) / size as f64 * (hi.x - lo.x),
            hi.y - (j as f64 + 0.5) / size as f64 * (hi.y - lo.y),
        );
        let inside = polygon::inside_polygon(&q, &outline);
        let world = frame.to_world(&q, heights.at(&q));
        let rgb = photo
            .as_ref()
            .and_then(|photo| {
                let pixel = camera.project(&(camera_from_world * world).coords)?;
                let (x, y) = (pixel.x as u32, pixel.y as u32);
                (x < photo.width() && y < photo.height()).then(|| *photo.get_pixel(x, y))
            })
            .unwrap_or(image::Rgb([70, 130, 55]));
        image::Rgba([rgb[0], rgb[1], rgb[2], if inside { 255 } else { 0 }])
    });
    LeafTemplate::from_outline(&outline, texture).map_err(|e| bad(e.to_string()))
}

/// A view left out of the leaf stage because its photo cannot be used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnusableView {
    pub view: usize,
    pub image_id: u32,
    pub reason: String,
}

/// The boundaries chosen for a set of leaf segments.
#[derive(Clone, Debug, Default)]
pub struct BoundaryChoices {
    pub chosen: HashMap<u32, BoundaryChoice>,
    /// Views without a usable photo (missing, unreadable, wrong size), skipped.
    pub unusable_views: Vec<UnusableView>,
}

/// The nearest depths of the points a view sees, per square cell of [`OCCLUDER_CELL_PX`]
/// pixels, kept so that any one segment's occluders can be read from them: the nearest point
/// of any segment, and the nearest point of a segment other than that one's. A leaf may lie
/// behind whatever is nearer than it and not its own (one table per view serves every leaf).
struct OccluderDepths {
    columns: usize,
    rows: usize,
    /// Per cell: the nearest depth and its segment label.
    nearest: Vec<(f64, i32)>,
    /// Per cell: the nearest depth among points whose label differs from `nearest`'s.
    nearest_other: Vec<f64>,
}

/// Side of an occluder-depth cell, pixels (about two fused point spacings in the image).
const OCCLUDER_CELL_PX: f64 = 4.0;

/// A point hides the leaf when it is nearer than the leaf by more than this share of the
/// leaf's depth (twice the depth agreement of `frond densify`'s fusion).
const OCCLUDER_DEPTH_MARGIN: f64 = 0.02;

impl OccluderDepths {
    fn new(input: &LeafInput, view: usize) -> Self {
        let model = &input.scene.reconstruction;
        let camera = model.camera_of(&model.images()[view]);
        let columns = (camera.width as f64 / OCCLUDER_CELL_PX).ceil().max(1.0) as usize;
        let rows = (camera.height as f64 / OCCLUDER_CELL_PX).ceil().max(1.0) as usize;
        let mut depths = Self::empty(columns, rows);
        for p in input
            .views
            .projected(input.scene, input.points, view)
            .iter()
        {
            let (i, j) = (
                (p.uv_image.x / OCCLUDER_CELL_PX).floor(),
                (p.uv_image.y / OCCLUDER_CELL_PX).floor(),
            );
            if i < 0.0 || j < 0.0 || (i as usize) >= columns || (j as usize) >= rows {
                continue;
            }
            let label = input.labels.segment_of[p.point as usize];
            depths.insert(j as usize * columns + i as usize, p.depth_camera, label);
        }
        depths
    }

    fn empty(columns: usize, rows: usize) -> Self {
        Self {
            columns,
            rows,
            nearest: vec![(f64::INFINITY, i32::MIN); columns * rows],
            nearest_other: vec![f64::INFINITY; columns * rows],
        }
    }

    /// Adds a point of `label` at `depth` to cell `k`.
    fn insert(&mut self, k: usize, depth: f64, label: i32) {
        let (first_depth, first_label) = self.nearest[k];
        if depth < first_depth {
            // The old nearest is the nearest of everything not labelled `label`.
            if label != first_label {
                self.nearest_other[k] = first_depth;
            }
            self.nearest[k] = (depth, label);
        } else if label != first_label {
            self.nearest_other[k] = self.nearest_other[k].min(depth);
        }
    }

    /// The nearest depth in cell `k` of a point not labelled `segment` (infinite if none).
    fn occluder(&self, k: usize, segment: i32) -> f64 {
        let (first_depth, first_label) = self.nearest[k];
        if first_label == segment {
            self.nearest_other[k]
        } else {
            first_depth
        }
    }

    /// Whether a point of `segment` at `uv_image` and `depth` is behind a point of another
    /// label (or off the image, where the view cannot tell).
    fn hides(&self, segment: u32, uv_image: &Point2<f64>, depth: f64) -> bool {
        let (i, j) = (
            (uv_image.x / OCCLUDER_CELL_PX).floor(),
            (uv_image.y / OCCLUDER_CELL_PX).floor(),
        );
        if i < 0.0 || j < 0.0 || i as usize >= self.columns || j as usize >= self.rows {
            return true;
        }
        let k = j as usize * self.columns + i as usize;
        self.occluder(k, segment as i32) < depth * (1.0 - OCCLUDER_DEPTH_MARGIN)
    }
}

/// Widens a leaf's chosen region (`region`: its view, plane polygon and image boundary) by
/// what its view's wide region (`wide`: one per candidate view, under
/// [`extent::ViewVoteOptions`]' weaker spatial prior, on the same plane) adds and a majority
/// of the other views that see that part of the leaf unhidden confirm: see [`extent`]. Left
/// as it is with fewer than [`extent::ViewVoteOptions::min_views`] wide regions, when the
/// chosen region is not on the plane, when its view has no wide region, or when the vote
/// does not grow it.
fn widen_by_votes(
    input: &LeafInput,
    segment: u32,
    frame: &fit::LeafFrame,
    region: &mut (usize, Vec<Point2<f64>>, Boundary),
    wide: &[(usize, Vec<Point2<f64>>)],
    occluders: &HashMap<usize, OccluderDepths>,
    options: &extent::ViewVoteOptions,
) {
    let view = region.0;
    let Some(own) = wide.iter().find(|r| r.0 == view).map(|r| &r.1) else {
        return;
    };
    let others: Vec<&(usize, Vec<Point2<f64>>)> = wide.iter().filter(|r| r.0 != view).collect();
    if others.len() + 1 < options.min_views || region.1.len() < 3 {
        return;
    }
    let model = &input.scene.reconstruction;
    let hidden = |k: usize, q: &Point2<f64>| {
        let Some(depths) = occluders.get(&others[k].0) else {
            return true;
        };
        let image = &model.images()[others[k].0];
        let point_camera = image.camera_from_world * frame.to_world(q, 0.0);
        match model.camera_of(image).project(&point_camera.coords) {
            Some(uv) if point_camera.z > 0.0 => depths.hides(segment, &uv, point_camera.z),
            _ => true,
        }
    };
    let regions: Vec<Vec<Point2<f64>>> = others.iter().map(|r| r.1.clone()).collect();
    let Some(widened) = extent::confirmed_region(
        &region.1,
        own,
        &regions,
        options.tolerance,
        &hidden,
        extent::VOTE_GRID,
    ) else {
        return;
    };
    if polygon::polygon_area(&widened).abs() <= 1.02 * polygon::polygon_area(&region.1).abs() {
        return;
    }
    let image = &model.images()[view];
    let image_polygon: Option<Vec<[f64; 2]>> = widened
        .iter()
        .map(|q| {
            model
                .project(image, &frame.to_world(q, 0.0))
                .map(|uv| [uv.x, uv.y])
        })
        .collect();
    let Some(image_polygon) = image_polygon else {
        return;
    };
    let outline: Vec<Point2<f64>> = image_polygon
        .iter()
        .map(|p| Point2::new(p[0], p[1]))
        .collect();
    region.2 = Boundary {
        area_px: polygon::polygon_area(&outline).abs(),
        polygon: image_polygon,
        superpixels: region.2.superpixels,
    };
    region.1 = widened;
}

/// The image boundary chosen for a leaf.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BoundaryChoice {
    pub view: usize,
    /// Mean overlap (IoU on the leaf plane) of the chosen region with the other candidate
    /// views' regions: 1 when they all agree; low for a leaf whose boundary is uncertain.
    pub agreement: f64,
    /// Area of the region in the image, pixels².
    pub area_px: f64,
    /// Area over convex-hull area of the region on the leaf plane (of the image polygon when
    /// the plane is seen too obliquely): low for notched or merged-leaf outlines.
    pub solidity: f64,
}

/// Image boundaries of leaf segments (seed 004 §5.4/§6.2): for each, the boundaries in its
/// best views (most points seen, most frontal), the chosen one by [`consensus_region`],
/// widened by what the other views confirm (`votes`, see [`extent`]).
/// Superpixels and boundaries are computed in parallel; every boundary computed is added to
/// `boundaries`.
pub fn choose_boundaries(
    input: &LeafInput,
    boundaries: &mut Boundaries,
    segments: &[u32],
    plant: &PlantContext,
    votes: &extent::ViewVoteOptions,
    progress: &dyn Progress,
) -> Result<BoundaryChoices, LeafError> {
    use rayon::prelude::*;
    // Views whose photo is missing, unreadable or of the wrong size take no part (checked from
    // the file header; a photo that then fails to decode is dropped below).
    let images = input.scene.reconstruction.images();
    let mut unusable: BTreeMap<usize, String> = images
        .par_iter()
        .enumerate()
        .filter_map(|(view, image)| match input.scene.image_file_status(image) {
            ImageFileStatus::Present => None,
            status => Some((view, format!("{}: {status:?}", image.name))),
        })
        .collect();
    let ranked: Vec<(u32, Option<fit::LeafFrame>, Vec<usize>)> = segments
        .par_iter()
        .map(|&segment| {
            let points = segment_points(input, segment);
            let frame = leaf_frame(&points, plant).ok().map(|f| f.0);
            let views = ranked_views(input, segment, plant)
                .into_iter()
                .map(|(_, view)| view)
                .filter(|view| !unusable.contains_key(view))
                .take(BOUNDARY_CANDIDATES)
                .collect();
            (segment, frame, views)
        })
        .collect();
    let mut views: Vec<usize> = ranked.iter().flat_map(|c| c.2.clone()).collect();
    views.sort_unstable();
    views.dedup();
    progress.stage("superpixels", views.len() as u64);
    let failed: Vec<(usize, String)> = views
        .par_iter()
        .filter_map(|&view| {
            if progress.is_cancelled() {
                return None;
            }
            let result = input.views.oversegmentation(input.scene, view);
            progress.advance(1);
            result.err().map(|e| (view, e.to_string()))
        })
        .collect();
    for (view, reason) in failed {
        tracing::warn!("view {view} left out of the leaf boundaries: {reason}");
        unusable.insert(view, reason);
    }
    let unusable_views: Vec<UnusableView> = unusable
        .iter()
        .map(|(&view, reason)| UnusableView {
            view,
            image_id: images[view].id,
            reason: reason.clone(),
        })
        .collect();
    let candidates: Vec<(u32, Option<fit::LeafFrame>, Vec<usize>)> = ranked
        .into_iter()
        .map(|(segment, frame, views)| {
            let views = views
                .into_iter()
                .filter(|view| !unusable.contains_key(view))
                .collect();
            (segment, frame, views)
        })
        .collect();
    progress.stage("leaf boundaries", segments.len() as u64);
    type Regions = Vec<(usize, Vec<Point2<f64>>, Boundary)>;
    // One per candidate view: the wide region on the leaf's plane.
    type WideRegions = Vec<(usize, Vec<Point2<f64>>)>;
    let wide_options = votes
        .enabled
        .then(|| votes.boundary_options(input.views.options()));
    let computed: Vec<(u32, Regions, WideRegions)> = candidates
        .par_iter()
        .map(|(segment, frame, views)| {
            let mut regions = Vec::new();
            let mut wide_regions = Vec::new();
            if progress.is_cancelled() {
                return (*segment, regions, wide_regions);
            }
            for &view in views {
                // A view where the graph cut finds nothing simply is not a candidate.
                let Ok(boundary) = input.views.boundary(
                    input.scene,
                    input.points,
                    &input.labels.segment_of,
                    *segment,
                    view,
                ) else {
                    continue;
                };
                let region = frame
                    .as_ref()
                    .and_then(|frame| plane_polygon(input.scene, view, &boundary.polygon, frame));
                regions.push((view, region.unwrap_or_default(), boundary));
                // The same view under the weaker prior, for the vote across views.
                if let (Some(options), Some(frame)) = (&wide_options, frame.as_ref())
                    && let Ok(wide) = input.views.boundary_with(
                        input.scene,
                        input.points,
                        &input.labels.segment_of,
                        *segment,
                        view,
                        options,
                    )
                    && let Some(on_plane) = plane_polygon(input.scene, view, &wide.polygon, frame)
                {
                    wide_regions.push((view, on_plane));
                }
            }
            progress.advance(1);
            (*segment, regions, wide_regions)
        })
        .collect();
    let frames: HashMap<u32, fit::LeafFrame> = candidates
        .iter()
        .filter_map(|(segment, frame, _)| frame.map(|f| (*segment, f)))
        .collect();
    // One occluder table per view that votes on some leaf, built in parallel.
    let mut voting_views: Vec<usize> = computed
        .iter()
        .filter(|c| c.2.len() >= votes.min_views)
        .flat_map(|c| c.2.iter().map(|r| r.0))
        .collect();
    voting_views.sort_unstable();
    voting_views.dedup();
    let occluders: HashMap<usize, OccluderDepths> = voting_views
        .par_iter()
        .map(|&view| (view, OccluderDepths::new(input, view)))
        .collect();
    let mut chosen = HashMap::new();
    for (segment, mut regions, wide_regions) in computed {
        let on_plane: Vec<(usize, Vec<Point2<f64>>)> = regions
            .iter()
            .filter(|r| r.1.len() >= 3)
            .map(|r| (r.0, r.1.clone()))
            .collect();
        let choice = consensus_region(&on_plane).or_else(|| {
            // Seen only too obliquely for the plane: the largest image region.
            regions
                .iter()
                .max_by(|a, b| a.2.area_px.total_cmp(&b.2.area_px))
                .map(|r| (r.0, 1.0))
        });
        if let Some((view, _)) = choice
            && let Some(frame) = frames.get(&segment)
            && let Some(r) = regions.iter_mut().find(|r| r.0 == view)
        {
            widen_by_votes(input, segment, frame, r, &wide_regions, &occluders, votes);
        }
        if let Some((view, agreement)) = choice
            && let Some(r) = regions.iter().find(|r| r.0 == view)
        {
            let solidity = if r.1.len() >= 3 {
                polygon::solidity(&r.1)
            } else {
                let image: Vec<Point2<f64>> =
                    r.2.polygon
                        .iter()
                        .map(|p| Point2::new(p[0], p[1]))
                        .collect();
                polygon::solidity(&image)
            };
            chosen.insert(
                segment,
                BoundaryChoice {
                    view,
                    agreement,
                    area_px: r.2.area_px,
                    solidity,
                },
            );
        }
        for (view, _, boundary) in regions {
            boundaries.insert((segment, view), boundary);
        }
    }
    Ok(BoundaryChoices {
        chosen,
        unusable_views,
    })
}

/// The candidates for the generic leaf (seed 004 §6.1: a sample leaf), best first: among the
/// largest leaf segments with a boundary, the one seen most frontally in its chosen view,
/// with the most points, the largest image region and the most solid boundary most
/// consistent across views; segments over twice the median leaf segment's size are passed
/// over while others remain.
pub fn template_candidates(
    input: &LeafInput,
    plant: &PlantContext,
    boundaries: &HashMap<u32, BoundaryChoice>,
) -> Vec<TemplateSource> {
    let sizes_by_segment = input.labels.sizes();
    let size_of = |segment: u32| sizes_by_segment.get(segment as usize).copied().unwrap_or(0);
    let mut sizes: Vec<(usize, u32)> = boundaries
        .keys()
        .map(|&segment| (size_of(segment), segment))
        .filter(|(n, _)| *n >= 50)
        .collect();
    sizes.sort_by(|a, b| b.cmp(a));
    // A segment far larger than the typical leaf is more likely two merged leaves than one
    // large leaf: keep those out unless nothing else is left.
    let mut leaf_sizes: Vec<usize> = input
        .labels
        .segments
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_some_and(|s| s.label == SegmentLabel::Leaf))
        .map(|(id, _)| size_of(id as u32))
        .filter(|&n| n > 0)
        .collect();
    leaf_sizes.sort_unstable();
    if let Some(&median) = leaf_sizes.get(leaf_sizes.len() / 2) {
        let typical: Vec<(usize, u32)> = sizes
            .iter()
            .copied()
            .filter(|&(n, _)| n <= MAX_TEMPLATE_SIZE_RATIO * median)
            .collect();
        if !typical.is_empty() {
            sizes = typical;
        }
    }
    let images = input.scene.reconstruction.images();
    let mut scored: Vec<(f64, TemplateSource)> = Vec::new();
    for &(count, segment) in sizes.iter().take(TEMPLATE_CANDIDATES) {
        let choice = boundaries[&segment];
        let Ok((frame, _)) = leaf_frame(&segment_points(input, segment), plant) else {
            continue;
        };
        let ray = (frame.origin - images[choice.view].center_world()).normalize();
        let cosine = ray.dot(&frame.normal).abs();
        // Frontal, agreed on by the candidate views, whole (solid), and large.
        let score = cosine
            * choice.agreement
            * choice.solidity.powi(2)
            * choice.area_px.sqrt()
            * (count as f64).sqrt();
        scored.push((
            score,
            TemplateSource {
                segment,
                view: choice.view,
            },
        ));
    }
    scored.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.segment.cmp(&b.1.segment)));
    scored.into_iter().map(|(_, source)| source).collect()
}

/// Checks that a user's generic-leaf pick names a non-empty segment and an existing view.
fn check_template_pick(input: &LeafInput, pick: TemplatePick) -> Result<(), LeafError> {
    let bad = |message: String| LeafError::BadTemplate {
        segment: pick.segment,
        view: pick.view,
        message,
    };
    let exists = input.labels.state(pick.segment).is_some();
    if !exists || input.labels.members(pick.segment).is_empty() {
        return Err(bad(format!(
            "no such segment (the labels have {})",
            input.labels.segments.len()
        )));
    }
    let views = input.scene.reconstruction.images().len();
    if let Some(view) = pick.view
        && view >= views
    {
        return Err(bad(format!("no such view (the model has {views})")));
    }
    Ok(())
}

/// Generic leaves besides the chosen one (the next candidates that work) whose outlines a
/// leaf may take when they fit its image boundary better.
///
/// Measured (semi-dense broadleaf, median leaf length error pooled over leaves): seeds 11–13
/// 3.5 → 2.3 % (seed 12, whose generic leaf is ovate and two of whose leaves are elliptic,
/// 5.0 → 2.0 %), seeds 1–3 2.1 → 2.0 %, seeds 21–23 and 31–33 1.62 → 1.68 %; medium seeds
/// 11–13 6.57 → 6.29 %; 5 alternatives were worse than 2 on each of broadleaf seeds 1–3.
const GENERIC_ALTERNATIVES: usize = 2;

/// How many of the largest leaves compete to be the generic leaf.
const TEMPLATE_CANDIDATES: usize = 6;

/// Segments with more than this many times the median leaf segment's points do not compete
/// to be the generic leaf (likely merged leaves).
const MAX_TEMPLATE_SIZE_RATIO: usize = 2;

/// Reconstructs every leaf segment (seed 004 §6.2): boundaries, generic leaf,
/// then the fits, in parallel, grouped by the view whose photo textures them (one photo in
/// memory per worker).
pub fn reconstruct_leaves(
    input: &LeafInput,
    options: &LeafOptions,
    progress: &dyn Progress,
) -> Result<LeafReconstruction, LeafError> {
    use rayon::prelude::*;
    let plant = input.plant;
    let mut timings = LeafTimings::default();
    let mut computed = Boundaries::new();
    let sizes = input.labels.sizes();
    let leaf_segments: Vec<u32> = input.labels.leaf_segments();

    if let Some(pick) = options.template {
        check_template_pick(input, pick)?;
    }

    let clock = Instant::now();
    let boundaries = if options.fit.use_boundary {
        choose_boundaries(
            input,
            &mut computed,
            &leaf_segments,
            plant,
            &options.votes,
            progress,
        )?
    } else {
        // Only the generic leaf needs a boundary.
        let mut largest: Vec<(usize, u32)> = leaf_segments
            .iter()
            .map(|&s| (sizes[s as usize], s))
            .collect();
        largest.sort_by(|a, b| b.cmp(a));
        let mut some: Vec<u32> = largest
            .iter()
            .take(TEMPLATE_CANDIDATES)
            .map(|&(_, s)| s)
            .collect();
        if let Some(pick) = options.template
            && !some.contains(&pick.segment)
        {
            some.push(pick.segment);
        }
        choose_boundaries(input, &mut computed, &some, plant, &options.votes, progress)?
    };
    timings.boundaries = clock.elapsed().as_secs_f64();
    if progress.is_cancelled() {
        return Err(LeafError::Cancelled);
    }

    progress.stage("generic leaf", 0);
    let clock = Instant::now();
    let picked = match options.template {
        Some(TemplatePick {
            segment,
            view: Some(view),
        }) => Some(TemplateSource { segment, view }),
        Some(TemplatePick {
            segment,
            view: None,
        }) => match boundaries.chosen.get(&segment) {
            Some(choice) => Some(TemplateSource {
                segment,
                view: choice.view,
            }),
            None => {
                return Err(LeafError::BadTemplate {
                    segment,
                    view: None,
                    message: "no view gives it an image boundary; pick a view".into(),
                });
            }
        },
        None => None,
    };
    // The user's pick must work; automatic candidates are tried best first, and one the
    // photos cannot give (seen too obliquely, too small) is passed over. Without a pick, the
    // next candidates that work are kept as alternatives.
    let mut alternatives: Vec<LeafTemplate> = Vec::new();
    let chosen = match picked {
        Some(source) => Some((
            source,
            extract_template(input, &mut computed, source, plant, 256)?,
        )),
        None => {
            let mut found = None;
            for candidate in template_candidates(input, plant, &boundaries.chosen) {
                if found.is_some() && alternatives.len() >= GENERIC_ALTERNATIVES {
                    break;
                }
                match extract_template(input, &mut computed, candidate, plant, 256) {
                    Ok(template) if found.is_none() => found = Some((candidate, template)),
                    Ok(template) => alternatives.push(template),
                    Err(e) => tracing::info!("generic leaf candidate passed over: {e}"),
                }
            }
            found
        }
    };
    let source = chosen.as_ref().map(|(source, _)| *source);
    let template = match chosen {
        Some((_, template)) => template,
        None => {
            // No candidate has an image boundary the photos can give: an elliptic generic
            // leaf.
            let ellipse: Vec<Point2<f64>> = (0..64)
                .map(|k| {
                    let t = std::f64::consts::TAU * k as f64 / 64.0;
                    Point2::new(0.5 + 0.5 * t.cos(), 0.22 * t.sin())
                })
                .collect();
            LeafTemplate::from_outline(&ellipse, LeafTemplate::plain_texture(64)).map_err(|e| {
                LeafError::BadTemplate {
                    segment: 0,
                    view: None,
                    message: e.to_string(),
                }
            })?
        }
    };
    timings.template = clock.elapsed().as_secs_f64();
    let templates: Vec<&LeafTemplate> = std::iter::once(&template).chain(&alternatives).collect();

    progress.stage("fitting leaves", leaf_segments.len() as u64);
    let clock = Instant::now();
    let mut by_view: std::collections::BTreeMap<Option<usize>, Vec<(usize, u32)>> =
        std::collections::BTreeMap::new();
    for (order, &segment) in leaf_segments.iter().enumerate() {
        let view = options
            .fit
            .use_boundary
            .then(|| boundaries.chosen.get(&segment).map(|c| c.view))
            .flatten();
        by_view.entry(view).or_default().push((order, segment));
    }
    /// Segments in fitting order that share one boundary view (one photo load per group).
    type ViewGroup = (Option<usize>, Vec<(usize, u32)>);
    /// One segment's fit, with the order it was listed in.
    struct Outcome {
        order: usize,
        segment: u32,
        view: Option<usize>,
        points: usize,
        fitted: Result<FittedLeaf, FitError>,
    }
    let groups: Vec<ViewGroup> = by_view.into_iter().collect();
    let model = &input.scene.reconstruction;
    let known: &Boundaries = &computed;
    let mut results: Vec<Outcome> = groups
        .par_iter()
        .flat_map_iter(|(view, members)| {
            let photo = view
                .filter(|_| !progress.is_cancelled())
                .and_then(|v| load_photo(input.scene, v));
            members
                .iter()
                .filter(|_| !progress.is_cancelled())
                .map(|&(order, segment)| {
                    let points = segment_points(input, segment);
                    let boundary_view = view.and_then(|v| {
                        let boundary = known.get(&(segment, v))?;
                        Some(BoundaryView {
                            polygon: &boundary.polygon,
                            camera: model.camera_of(&model.images()[v]),
                            camera_from_world: model.images()[v].camera_from_world,
                            image: photo.as_ref(),
                        })
                    });
                    let fitted = fit_leaf_best_outline(
                        &points,
                        &templates,
                        plant,
                        boundary_view.as_ref(),
                        &options.fit,
                    );
                    progress.advance(1);
                    Outcome {
                        order,
                        segment,
                        view: *view,
                        points: points.len(),
                        fitted,
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect();
    if progress.is_cancelled() {
        return Err(LeafError::Cancelled);
    }
    results.sort_by_key(|r| r.order);
    let mut leaves = Vec::new();
    let mut skipped = Vec::new();
    for Outcome {
        segment,
        view,
        points,
        fitted,
        ..
    } in results
    {
        match fitted {
            Ok(fit) => leaves.push(ReconstructedLeaf { segment, view, fit }),
            Err(e) => skipped.push(SkippedLeaf {
                segment,
                points,
                for_branch_stage: matches!(e, FitError::TooFewPoints(_)),
                reason: e.to_string(),
            }),
        }
    }
    timings.fitting = clock.elapsed().as_secs_f64();
    Ok(LeafReconstruction {
        template_source: source,
        template,
        leaves,
        skipped,
        unusable_views: boundaries.unusable_views,
        boundaries: computed,
        timings,
        gap_fills: 0,
        gap_fills_on_leaves: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// One table per view answers every segment's question: the nearest depth in a cell of
        /// a point with another label, as a direct minimum over those points gives it.
        #[test]
        fn one_table_gives_each_segment_its_nearest_other_point(
            points in prop::collection::vec((0usize..3, 0.1f64..10.0, -1i32..4), 0..60),
        ) {
            let mut depths = OccluderDepths::empty(3, 1);
            for &(cell, depth, label) in &points {
                depths.insert(cell, depth, label);
            }
            for cell in 0..3 {
                for segment in -1..5 {
                    let direct = points
                        .iter()
                        .filter(|p| p.0 == cell && p.2 != segment)
                        .map(|p| p.1)
                        .fold(f64::INFINITY, f64::min);
                    prop_assert_eq!(depths.occluder(cell, segment), direct);
                }
            }
        }
    }
}
