//! Semi-dense multi-view stereo on the CPU (`frond densify`): the paper's input is a
//! quasi-dense point cloud with visibility (seed 004 §4, after Lhuillier and Quan 2005); sparse
//! structure-from-motion leaves a few hundred points on a plant, far too few to segment leaves.
//!
//! Pipeline: [`pairs`] picks each view's stereo partner from the sparse model's shared points
//! and triangulation angles; [`rectify`] re-projects both views (any camera model) onto a
//! common plane; [`stereo`] matches them with semi-global matching over the disparity range
//! of their shared sparse points; [`fusion`] keeps depths that other views' depth maps agree
//! with and merges them on a voxel grid. The result is written as a dense workspace that
//! `frond reconstruct` reads: `sparse/` (cameras, poses and the fused points with tracks),
//! `images/`, `fused.ply` + `fused.ply.vis` (COLMAP's formats; `fused.ply` also says which
//! points the thin-organ sweep found, `thin_organ`, and which fill gaps from the fill
//! partners' depth maps, `gap_fill`) and `densify.json`.
//!
//! Takes a [`Scene`](crate::scene::Scene) with a sparse model and its photos; returns
//! [`FusedPoints`] and a [`DensifyReport`], and writes the dense workspace.

pub mod backdrop;
pub mod fusion;
pub mod pairs;
pub mod rectify;
pub mod stereo;
pub mod thin;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

pub use backdrop::{BackdropModel, BackdropOptions};
pub use fusion::{FreeSpaceOptions, FusedPoints, FusionOptions, FusionStats, RegionOfInterest};
pub use pairs::{PairOptions, StereoPair};
pub use stereo::{RectifiedDepthMap, StereoOptions};
pub use thin::{ThinOptions, ThinStats};

use crate::scene::model::{Image, Keypoint, Point3D, TrackElement};
use crate::scene::ply::{Column, Element, Ply, ScalarType, encode_ply_binary};
use crate::scene::{ImageId, ModelFormat, Reconstruction, Scene, SceneError, write_model};
use crate::util::atomic::{StagedDir, write_atomic};
use crate::util::progress::Progress;
use rectify::RectifiedPair;
use stereo::LoadedView;

/// Everything `densify` can be told.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct DensifyOptions {
    /// Photos are matched with their longest side at most this many pixels.
    pub max_image_size: u32,
    /// Fuse only depths within this many median camera distances of the point the views
    /// converge on (object-centric captures; 0 or no convergence: everything).
    pub roi_radius: f64,
    pub pairs: PairOptions,
    pub stereo: StereoOptions,
    pub fusion: FusionOptions,
    /// The thin-organ sweep ([`thin`]), whose points are added to the fused ones.
    pub thin: ThinOptions,
    /// Fused points that depth maps see past are dropped ([`fusion::seen_through`]).
    pub free_space: FreeSpaceOptions,
    /// Fused points that photos see the plain backdrop through are dropped ([`backdrop`]).
    pub backdrop: BackdropOptions,
}

impl Default for DensifyOptions {
    fn default() -> Self {
        Self {
            max_image_size: 1000,
            roi_radius: 1.0,
            pairs: PairOptions::default(),
            stereo: StereoOptions::default(),
            fusion: FusionOptions::default(),
            thin: ThinOptions::default(),
            free_space: FreeSpaceOptions::default(),
            backdrop: BackdropOptions::default(),
        }
    }
}

/// Why densification failed.
#[derive(Debug, thiserror::Error)]
pub enum MvsError {
    #[error("the model has {0} registered images; dense stereo needs at least 2")]
    TooFewImages(usize),
    #[error(
        "the model has no 3D points: dense stereo takes each pair's depth range from the sparse points (run COLMAP's mapper first)"
    )]
    NoSparsePoints,
    #[error(
        "no view pair shares {min_shared} sparse points at a triangulation angle between {min_deg}° and {max_deg}°"
    )]
    NoPairs {
        min_shared: usize,
        min_deg: f64,
        max_deg: f64,
    },
    #[error("no pair produced depths: {0}")]
    NoDepth(String),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("image {image_id} ('{name}'): {message}")]
    Image {
        image_id: ImageId,
        name: String,
        message: String,
    },
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

/// A pair that gave no depth map, and why.
#[derive(Clone, Debug, Serialize)]
pub struct SkippedPair {
    pub left: ImageId,
    pub right: ImageId,
    pub reason: String,
}

/// What a densify run did (written as `densify.json`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct DensifyReport {
    pub images: usize,
    pub pairs: usize,
    pub pairs_matched: usize,
    pub skipped: Vec<SkippedPair>,
    /// Mean rectified image size of the matched pairs.
    pub mean_rectified_pixels: f64,
    pub region_of_interest: Option<RegionOfInterest>,
    pub depth_pixels: usize,
    pub fusion: FusionStats,
    /// The thin-organ sweep, when it ran (its points are in the output, after the fused ones).
    pub thin: Option<ThinStats>,
    /// Depth maps of fill partners (0: none were asked for).
    pub fill_maps: usize,
    /// Points added where the main maps left gaps ([`FusedPoints::gap_fill`]).
    pub gap_fill_points: usize,
    /// Stereo points dropped as lying in space the depth maps see through
    /// ([`FreeSpaceOptions`]).
    #[serde(default)]
    pub free_space_dropped: usize,
    /// What the photos' borders said about the backdrop (none when carving is off).
    pub backdrop: Option<BackdropModel>,
    /// Stereo points dropped as lying where photos see the plain backdrop
    /// ([`BackdropOptions`]).
    pub backdrop_dropped: usize,
    pub mean_views_per_point: f64,
    pub timings: BTreeMap<String, f64>,
}

fn image_error(image: &Image, message: impl std::fmt::Display) -> MvsError {
    MvsError::Image {
        image_id: image.id,
        name: image.name.clone(),
        message: message.to_string(),
    }
}

/// The disparities of the sparse points `left` and `right` both observe (else those `left`
/// observes) in a rectified pair; only those in the region of interest when it holds enough.
fn sparse_disparities(
    model: &Reconstruction,
    pair: &StereoPair,
    rectified: &RectifiedPair,
    roi: Option<&RegionOfInterest>,
) -> Vec<f64> {
    let images = model.images();
    let (left_id, right_id) = (images[pair.left].id, images[pair.right].id);
    let seen_by = |point: &Point3D, id: ImageId| point.track.iter().any(|t| t.image_id == id);
    let collect = |both: bool, roi: Option<&RegionOfInterest>| -> Vec<f64> {
        model
            .points()
            .iter()
            .filter(|p| seen_by(p, left_id) && (!both || seen_by(p, right_id)))
            .filter(|p| roi.is_none_or(|r| r.contains(&p.position_world)))
            .filter_map(|p| rectified.disparity_of(&p.position_world))
            .collect()
    };
    [(true, roi), (false, roi), (true, None), (false, None)]
        .into_iter()
        .map(|(both, roi)| collect(both, roi))
        .find(|d| d.len() >= 10)
        .unwrap_or_else(|| collect(false, None))
}

/// Computes one depth map per stereo pair and fuses them (see the module docs).
/// Deterministic for given inputs and options.
///
/// With fill partners ([`PairOptions::fill_partners_per_view`]) the main partners' maps are
/// fused alone first, exactly as without them (same points, same thin-organ sweep), and then
/// all maps together; a point of the second fusion is added, marked as a gap fill
/// ([`FusedPoints::gap_fill`]), only where the first left the surface bare (fewer than
/// [`MAX_MAIN_AROUND`] of its points, the thin-organ sweep's included, within two voxels).
/// Measured (README: *Gap fills*): a second partner covers weakly textured leaves that one
/// misses, and also adds points along leaf rims that cost the segmentation's leaf precision,
/// which is why the segmentation leaves gap fills out.
pub fn densify(
    scene: &Scene,
    options: &DensifyOptions,
    progress: &dyn Progress,
) -> Result<(FusedPoints, DensifyReport), MvsError> {
    let (maps, loaded, mut report) = depth_maps_and_views(scene, options, progress)?;
    let (maps, fill_maps) = if options.pairs.fill_partners_per_view > 0 {
        let main: std::collections::HashSet<(usize, usize)> =
            pairs::select_pairs(&scene.reconstruction, &options.pairs)
                .iter()
                .map(|p| (p.left, p.right))
                .collect();
        main_and_fill(maps, |m| main.contains(&(m.pair.left, m.pair.right)))
    } else {
        (maps, Vec::new())
    };
    let started = Instant::now();
    let (mut fused, stats) = fusion::fuse(
        &maps,
        &options.fusion,
        report.region_of_interest.as_ref(),
        progress,
    );
    let voxel = stats.voxel_size;
    report.fusion = stats;
    report
        .timings
        .insert("fusion".to_owned(), started.elapsed().as_secs_f64());
    if options.thin.enabled {
        let started = Instant::now();
        progress.stage("thin organs", 0);
        let (thin, stats) = thin::sweep(
            &scene.reconstruction,
            &loaded,
            report.region_of_interest.as_ref(),
            voxel,
            &options.thin,
        )
        .map_err(|e| MvsError::NoDepth(format!("thin-organ sweep: {e}")))?;
        let (thin, stats) = thin::where_stereo_is_sparse(thin, stats, &fused, voxel);
        fused.positions_world.extend(thin.positions_world);
        fused.colors.extend(thin.colors);
        fused.views.extend(thin.views);
        fused.support.extend(thin.support);
        fused.thin_organ.extend(thin.thin_organ);
        report.thin = Some(stats);
        report
            .timings
            .insert("thin".to_owned(), started.elapsed().as_secs_f64());
    }
    let mut all = maps;
    if !fill_maps.is_empty() {
        let started = Instant::now();
        report.fill_maps = fill_maps.len();
        all.extend(fill_maps);
        let (all_fused, _) = fusion::fuse(
            &all,
            &options.fusion,
            report.region_of_interest.as_ref(),
            progress,
        );
        let fills = where_main_is_sparse(all_fused, &fused, voxel);
        report.gap_fill_points = fills.len();
        fused.gap_fill = vec![false; fused.len()];
        fused
            .gap_fill
            .extend(std::iter::repeat_n(true, fills.len()));
        fused.positions_world.extend(fills.positions_world);
        fused.colors.extend(fills.colors);
        fused.views.extend(fills.views);
        fused.support.extend(fills.support);
        fused.thin_organ.extend(fills.thin_organ);
        report
            .timings
            .insert("fill".to_owned(), started.elapsed().as_secs_f64());
    }
    if options.free_space.min_maps > 0 {
        let started = Instant::now();
        progress.stage("free space", 0);
        // A map sees past a point only to a surface the fusion confirmed (a fused point
        // within two voxels): where stereo smoothed a textureless leaf into what lies behind
        // it, that depth is no surface.
        let confirmed =
            crate::graph::neighbours::Neighbours::new(fused.positions_world.iter().copied())
                .ok()
                .map(|points| fusion::Confirmed {
                    points,
                    radius: 2.0 * voxel,
                    options: options.free_space,
                });
        let seen = fusion::seen_through(
            &fused.positions_world,
            &all,
            options.fusion.max_relative_depth_error,
            confirmed.as_ref(),
        );
        // The thin-organ sweep's points are exempt: stereo that lost an organ a few pixels
        // wide sees the background through it, which is why the sweep found it.
        let keep: Vec<bool> = seen
            .iter()
            .zip(&fused.thin_organ)
            .map(|(s, &thin)| thin || !fusion::in_free_space(s, &options.free_space))
            .collect();
        report.free_space_dropped = keep.iter().filter(|&&k| !k).count();
        fused = thin::select(fused, &keep);
        report
            .timings
            .insert("free_space".to_owned(), started.elapsed().as_secs_f64());
    }
    if options.backdrop.min_views > 0 {
        let started = Instant::now();
        progress.stage("backdrop", 0);
        let views: Vec<backdrop::CarvingView> = loaded
            .iter()
            .map(|(position, view)| {
                backdrop::CarvingView::new(&scene.reconstruction, *position, view).map_err(|e| {
                    image_error(
                        &scene.reconstruction.images()[*position],
                        format!("reading its pixels: {e}"),
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        // Border pixels whose rays cross the box the fused points span may show the plant.
        let plant = backdrop::PlantBox::of(&fused.positions_world);
        let model = BackdropModel::learn(
            views.iter().map(|v| (v.rgb.as_slice(), v.width, v.height)),
            |index, x, y| {
                plant.is_some_and(|b| {
                    views[index]
                        .ray(x, y)
                        .is_none_or(|(origin, direction)| b.crossed_by(&origin, &direction))
                })
            },
            &options.backdrop,
        );
        let sightings = backdrop::backdrop_sightings(&fused.positions_world, &views, &model);
        // The thin-organ sweep's points are exempt, as from the free-space check.
        let keep: Vec<bool> = sightings
            .iter()
            .zip(&fused.thin_organ)
            .map(|(&seen, &thin)| thin || (seen as usize) < options.backdrop.min_views)
            .collect();
        report.backdrop_dropped = keep.iter().filter(|&&k| !k).count();
        report.backdrop = Some(model);
        fused = thin::select(fused, &keep);
        report
            .timings
            .insert("backdrop".to_owned(), started.elapsed().as_secs_f64());
    }
    report.mean_views_per_point = if fused.is_empty() {
        0.0
    } else {
        fused.views.iter().map(Vec::len).sum::<usize>() as f64 / fused.len() as f64
    };
    Ok((fused, report))
}

/// The main partners' maps and the fill partners' (each in order); when every main pair
/// failed, the fill partners' maps are all there is and become the main ones.
fn main_and_fill<T>(maps: Vec<T>, is_main: impl Fn(&T) -> bool) -> (Vec<T>, Vec<T>) {
    let (main, fill): (Vec<T>, Vec<T>) = maps.into_iter().partition(|m| is_main(m));
    if main.is_empty() {
        (fill, Vec::new())
    } else {
        (main, fill)
    }
}

/// A surface patch the main maps sampled has about π·2² ≈ 12 of their points within two
/// voxels of any point on it (as for [`thin::where_stereo_is_sparse`]); a point of all maps'
/// fusion with fewer than this many main points there fills a gap.
pub const MAX_MAIN_AROUND: usize = 4;

/// The points of `all` that lie where `main` is sparse (see [`MAX_MAIN_AROUND`]), in order.
fn where_main_is_sparse(all: FusedPoints, main: &FusedPoints, voxel: f64) -> FusedPoints {
    let keep: Vec<bool> =
        match crate::graph::neighbours::Neighbours::new(main.positions_world.iter().copied()) {
            Ok(index) => all
                .positions_world
                .par_iter()
                .map(|p| index.count_within(p, 2.0 * voxel, |_| true).0 < MAX_MAIN_AROUND)
                .collect(),
            Err(_) => vec![true; all.len()],
        };
    thin::select(all, &keep)
}

/// The stereo half of [`densify`]: view pairs, region of interest, and one depth map per
/// matched pair (in pair order).
pub fn depth_maps(
    scene: &Scene,
    options: &DensifyOptions,
    progress: &dyn Progress,
) -> Result<(Vec<RectifiedDepthMap>, DensifyReport), MvsError> {
    depth_maps_and_views(scene, options, progress).map(|(maps, _, report)| (maps, report))
}

/// Depth maps, the views they were matched on (model image position, downsized photo) and
/// the report so far.
type DepthMapsAndViews = (
    Vec<RectifiedDepthMap>,
    Vec<(usize, LoadedView)>,
    DensifyReport,
);

/// [`depth_maps`] and the views it loaded (model image position, downsized photo).
fn depth_maps_and_views(
    scene: &Scene,
    options: &DensifyOptions,
    progress: &dyn Progress,
) -> Result<DepthMapsAndViews, MvsError> {
    let model = &scene.reconstruction;
    let images = model.images();
    if images.len() < 2 {
        return Err(MvsError::TooFewImages(images.len()));
    }
    if model.points().is_empty() {
        return Err(MvsError::NoSparsePoints);
    }
    let mut report = DensifyReport {
        images: images.len(),
        ..DensifyReport::default()
    };
    let mut clock = Instant::now();
    let mut lap = |name: &str, report: &mut DensifyReport| {
        report
            .timings
            .insert(name.to_owned(), clock.elapsed().as_secs_f64());
        clock = Instant::now();
    };

    let roi = RegionOfInterest::converging(
        &images.iter().map(Image::center_world).collect::<Vec<_>>(),
        &images
            .iter()
            .map(Image::view_direction_world)
            .collect::<Vec<_>>(),
        options.roi_radius,
    );
    report.region_of_interest = roi;
    let pairs = pairs::select_pairs(
        model,
        &PairOptions {
            partners_per_view: options.pairs.partners_per_view
                + options.pairs.fill_partners_per_view,
            ..options.pairs
        },
    );
    if pairs.is_empty() {
        return Err(MvsError::NoPairs {
            min_shared: options.pairs.min_shared_points,
            min_deg: options.pairs.min_angle_deg,
            max_deg: options.pairs.max_angle_deg,
        });
    }
    report.pairs = pairs.len();
    lap("pairs", &mut report);

    // Load every view a pair uses, downsized for matching.
    let mut used: Vec<usize> = pairs.iter().flat_map(|p| [p.left, p.right]).collect();
    used.sort_unstable();
    used.dedup();
    progress.stage("loading images", used.len() as u64);
    let loaded: Vec<(usize, LoadedView)> = used
        .par_iter()
        .map(|&v| {
            let image = &images[v];
            let bgr = scene.load_image(image)?;
            let view = stereo::load_view(bgr, options.max_image_size)
                .map_err(|e| image_error(image, format!("OpenCV could not resize it: {e}")))?;
            progress.advance(1);
            Ok((v, view))
        })
        .collect::<Result<_, MvsError>>()?;
    let view_of = |v: usize| -> &LoadedView {
        let k = loaded.partition_point(|(u, _)| *u < v);
        &loaded[k].1
    };
    lap("load", &mut report);

    progress.stage("stereo matching", pairs.len() as u64);
    let outcomes: Vec<Result<RectifiedDepthMap, SkippedPair>> = pairs
        .par_iter()
        .map(|pair| {
            let result = match_one(scene, pair, view_of, roi.as_ref(), options);
            progress.advance(1);
            result
        })
        .collect();
    let mut maps = Vec::new();
    for outcome in outcomes {
        match outcome {
            Ok(map) => maps.push(map),
            Err(skipped) => {
                tracing::warn!(
                    "pair {}–{} skipped: {}",
                    skipped.left,
                    skipped.right,
                    skipped.reason
                );
                report.skipped.push(skipped);
            }
        }
    }
    if maps.is_empty() {
        let reasons: Vec<String> = report
            .skipped
            .iter()
            .take(3)
            .map(|s| format!("{}–{}: {}", s.left, s.right, s.reason))
            .collect();
        return Err(MvsError::NoDepth(reasons.join("; ")));
    }
    report.pairs_matched = maps.len();
    report.mean_rectified_pixels = maps
        .iter()
        .map(|m| (m.camera.width * m.camera.height) as f64)
        .sum::<f64>()
        / maps.len() as f64;
    report.depth_pixels = maps.iter().map(RectifiedDepthMap::valid_pixels).sum();
    lap("stereo", &mut report);

    Ok((maps, loaded, report))
}

/// Rectifies and matches one pair.
fn match_one<'a>(
    scene: &Scene,
    pair: &StereoPair,
    view_of: impl Fn(usize) -> &'a LoadedView,
    roi: Option<&RegionOfInterest>,
    options: &DensifyOptions,
) -> Result<RectifiedDepthMap, SkippedPair> {
    let model = &scene.reconstruction;
    let images = model.images();
    let (left, right) = (&images[pair.left], &images[pair.right]);
    let skip = |reason: String| SkippedPair {
        left: left.id,
        right: right.id,
        reason,
    };
    let (left_camera, right_camera) = (model.camera_of(left), model.camera_of(right));
    let (left_view, right_view) = (view_of(pair.left), view_of(pair.right));
    let scale = left_view.scale.0.min(right_view.scale.0);
    let max_side = (2 * options.max_image_size) as usize;
    let mut rectified =
        RectifiedPair::new((left, left_camera), (right, right_camera), scale, max_side)
            .ok_or_else(|| {
                skip("the views cannot be rectified (baseline along the view)".into())
            })?;
    let mut disparities = sparse_disparities(model, pair, &rectified, roi);
    // Slide the partner's window so that the sparse points' median disparity is 0: disparities
    // stay small next to the image width, and both windows show the same part of the scene.
    if let Some(median) = crate::util::stats::median(disparities.iter().copied()) {
        let shift = median.round();
        rectified.shift_partner_window(shift);
        for d in &mut disparities {
            *d -= shift;
        }
    }
    let range = stereo::disparity_range(
        &disparities,
        options.stereo.range_margin,
        options.stereo.max_disparities,
    )
    .ok_or_else(|| skip("no sparse point in front of both views".into()))?;
    // Semi-global matching reads out of bounds (and OpenCV 4.6 can abort) when the largest
    // disparity plus half a block reaches the image width.
    let widest = range.0.abs().max((range.0 + range.1).abs()) + options.stereo.block_size;
    if widest as usize >= rectified.left.width {
        return Err(skip(format!(
            "disparity range {}..{} is too wide for {} px wide rectified images",
            range.0,
            range.0 + range.1,
            rectified.left.width
        )));
    }
    let left_table = rectified
        .left
        .resampling_table(left, left_camera, left_view.scale);
    let right_table = rectified
        .right
        .resampling_table(right, right_camera, right_view.scale);
    stereo::match_pair(
        *pair,
        &rectified,
        (left_view, right_view),
        (&left_table, &right_table),
        range,
        &options.stereo,
    )
    .map_err(|e| skip(format!("OpenCV stereo matching failed: {e}")))
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> MvsError {
    MvsError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// The fused points as a COLMAP model ([`dense_model`]), with what the model cannot hold.
#[derive(Clone, Debug)]
pub struct DenseModel {
    pub model: Reconstruction,
    /// Per point of `model` (in order): the image positions that see it.
    pub visibility: Vec<Vec<u32>>,
    /// Per point of `model`: whether the thin-organ sweep found it (`fused.ply`'s
    /// `thin_organ`).
    pub thin_organ: Vec<bool>,
    /// Per point of `model`: whether it fills a gap of the main partners' points
    /// ([`FusedPoints::gap_fill`], `fused.ply`'s `gap_fill`).
    pub gap_fill: Vec<bool>,
}

/// The fused points as a COLMAP model: the scene's cameras and poses, one keypoint per
/// observation (the point's projection) and the points with their tracks. Observations that
/// do not project into their image are dropped; so are points left with fewer than 2.
pub fn dense_model(model: &Reconstruction, fused: &FusedPoints) -> Result<DenseModel, MvsError> {
    let mut images: Vec<Image> = model
        .images()
        .iter()
        .map(|image| Image {
            keypoints: Vec::new(),
            ..image.clone()
        })
        .collect();
    let mut points = Vec::with_capacity(fused.len());
    let mut visibility = Vec::with_capacity(fused.len());
    let mut thin_organ = Vec::with_capacity(fused.len());
    let mut gap_fill = Vec::with_capacity(fused.len());
    for (k, position) in fused.positions_world.iter().enumerate() {
        let observations: Vec<(u32, nalgebra::Point2<f64>)> = fused.views[k]
            .iter()
            .filter_map(|&v| {
                let image = &model.images()[v as usize];
                let camera = model.camera_of(image);
                let uv = camera.project(&(image.camera_from_world * position).coords)?;
                camera.contains(&uv).then_some((v, uv))
            })
            .collect();
        if observations.len() < 2 {
            continue;
        }
        let id = points.len() as u64 + 1;
        let mut track = Vec::with_capacity(observations.len());
        for &(v, uv) in &observations {
            let image = &mut images[v as usize];
            track.push(TrackElement {
                image_id: image.id,
                keypoint_index: image.keypoints.len() as u32,
            });
            image.keypoints.push(Keypoint {
                uv_image: uv,
                point3d_id: Some(id),
            });
        }
        visibility.push(observations.iter().map(|(v, _)| *v).collect());
        thin_organ.push(fused.thin_organ.get(k).copied().unwrap_or(false));
        gap_fill.push(fused.is_gap_fill(k));
        points.push(Point3D {
            id,
            position_world: *position,
            color: fused.colors[k],
            error: -1.0,
            track,
        });
    }
    let dense = Reconstruction::from_parts_with_rigs(
        model.cameras().to_vec(),
        images,
        points,
        model.rigs().to_vec(),
        model.frames().to_vec(),
    )
    .map_err(|e| MvsError::NoDepth(format!("the fused model is inconsistent: {e}")))?;
    Ok(DenseModel {
        model: dense,
        visibility,
        thin_organ,
        gap_fill,
    })
}

/// `fused.ply`: binary PLY with float positions, 8-bit colours, `thin_organ` (1: found by
/// the thin-organ sweep, see [`DenseModel::thin_organ`]) and `gap_fill` (1: a fill partner's
/// point, see [`DenseModel::gap_fill`]).
fn fused_ply(model: &Reconstruction, thin_organ: &[bool], gap_fill: &[bool]) -> Vec<u8> {
    let flag = |flags: &[bool]| -> Vec<f64> {
        (0..model.points().len())
            .map(|k| f64::from(u8::from(flags.get(k).copied().unwrap_or(false))))
            .collect()
    };
    let points = model.points();
    let coordinate =
        |axis: usize| -> Vec<f64> { points.iter().map(|p| p.position_world[axis]).collect() };
    let channel = |c: usize| -> Vec<f64> { points.iter().map(|p| p.color[c] as f64).collect() };
    let ply = Ply {
        elements: vec![Element {
            name: "vertex".to_owned(),
            count: points.len(),
            columns: vec![
                Column::scalar("x", ScalarType::F32, coordinate(0)),
                Column::scalar("y", ScalarType::F32, coordinate(1)),
                Column::scalar("z", ScalarType::F32, coordinate(2)),
                Column::scalar("red", ScalarType::U8, channel(0)),
                Column::scalar("green", ScalarType::U8, channel(1)),
                Column::scalar("blue", ScalarType::U8, channel(2)),
                Column::scalar("thin_organ", ScalarType::U8, flag(thin_organ)),
                Column::scalar("gap_fill", ScalarType::U8, flag(gap_fill)),
            ],
        }],
        comments: vec!["frond densify: semi-dense points fused from pairwise stereo".to_owned()],
    };
    encode_ply_binary(&ply)
}

/// `fused.ply.vis`: u64 point count, then per point a u32 count and the u32 positions of the
/// images (in model order) that see it.
fn fused_visibility(visibility: &[Vec<u32>]) -> Vec<u8> {
    let mut bytes =
        Vec::with_capacity(8 + visibility.iter().map(|v| 4 + 4 * v.len()).sum::<usize>());
    bytes.extend_from_slice(&(visibility.len() as u64).to_le_bytes());
    for views in visibility {
        bytes.extend_from_slice(&(views.len() as u32).to_le_bytes());
        for v in views {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    bytes
}

/// Links (or copies, across file systems) the scene's images into `dir`.
fn link_images(scene: &Scene, dir: &Path) -> Result<(), MvsError> {
    for image in scene.reconstruction.images() {
        let source = scene
            .image_path(image)
            .ok_or_else(|| image_error(image, "the scene has no images folder"))?;
        let target = dir.join(&image.name);
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(|e| output_error(parent, e))?;
        }
        let source = std::fs::canonicalize(&source).map_err(|e| image_error(image, e))?;
        if std::fs::hard_link(&source, &target).is_err() {
            std::fs::copy(&source, &target).map_err(|e| output_error(&target, e))?;
        }
    }
    Ok(())
}

/// Writes the dense workspace `out` (see the module docs) atomically: it is assembled next to
/// `out` and renamed into place.
pub fn write_workspace(
    scene: &Scene,
    fused: &FusedPoints,
    report: &DensifyReport,
    options: &DensifyOptions,
    out: &Path,
) -> Result<Reconstruction, MvsError> {
    let DenseModel {
        model: dense,
        visibility,
        thin_organ,
        gap_fill,
    } = dense_model(&scene.reconstruction, fused)?;
    let staging = StagedDir::new(out).map_err(|e| output_error(out, e))?;
    let root = staging.path();
    let sparse = root.join("sparse");
    std::fs::create_dir_all(&sparse).map_err(|e| output_error(&sparse, e))?;
    write_model(&sparse, &dense, ModelFormat::Binary)?;
    link_images(scene, &root.join("images"))?;
    let ply_path = root.join("fused.ply");
    write_atomic(&ply_path, &fused_ply(&dense, &thin_organ, &gap_fill))
        .map_err(|e| output_error(&ply_path, e))?;
    let vis_path = root.join("fused.ply.vis");
    write_atomic(&vis_path, &fused_visibility(&visibility))
        .map_err(|e| output_error(&vis_path, e))?;
    let json_path = root.join("densify.json");
    let json = serde_json::json!({
        "generator": concat!("frond ", env!("CARGO_PKG_VERSION")),
        "input": scene.source.model_dir,
        "options": options,
        "report": report,
        "points_written": dense.points().len(),
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| output_error(&json_path, e))?;
    write_atomic(&json_path, text.as_bytes()).map_err(|e| output_error(&json_path, e))?;
    staging.commit().map_err(|e| output_error(out, e))?;
    Ok(dense)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_maps_stand_in_when_every_main_pair_failed() {
        let (main, fill) = main_and_fill(vec![1, 2, 3, 4, 5], |m| m % 2 == 1);
        assert_eq!((main, fill), (vec![1, 3, 5], vec![2, 4]));
        let (main, fill) = main_and_fill(vec![2, 4], |m| m % 2 == 1);
        assert_eq!((main, fill), (vec![2, 4], Vec::<i32>::new()));
        let (main, fill) = main_and_fill(Vec::<i32>::new(), |_| true);
        assert!(main.is_empty() && fill.is_empty());
    }
}
