//! `frond synth`: renders a synthetic plant from two rings of views and writes what a user's
//! COLMAP project would hold (images, cameras, semi-dense points with depth-tested tracks and
//! keypoints) plus the exact ground truth under `gt/`.
//!
//! Output layout (`DIR`):
//! - `images/view_NNNN.png`, `sparse/0/{cameras,images,points3D}.bin` (PINHOLE, true poses);
//! - `gt/points.ply`: per point `point_id`, position, true position, `leaf_id` (−1 if not a
//!   leaf), `part` (0 leaf, 1 stem, 2 pot, 3 floor, 4 background), `outlier`;
//! - `gt/leaves/leaf_NNN.ply` (world frame), `gt/leaves.json`, `gt/branches.json`;
//! - `gt/masks/view_NNNN.png`: 16-bit leaf id + 1 per pixel (0 = no leaf);
//! - `gt/surface_samples.ply`: dense samples of the plant's surfaces with `leaf_id` and `part`,
//!   for evaluating reconstructions whose points are not ours (real COLMAP);
//! - `meta.json`.
//!
//! The directory is assembled next to `DIR` and renamed into place, so it appears whole.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use image::{ImageBuffer, Luma, RgbaImage};
use nalgebra::{Isometry3, Point2, Point3};
use rayon::prelude::*;
use serde::Serialize;

use super::plant::{Preset, SynthPlant, generate_plant};
use super::scene::{Backdrop, Part, SynthScene, build_scene};
use crate::render::{Lighting, RenderError, RenderOutput, Renderer, ViewCamera};
use crate::scene::model::{Image, Keypoint, Point3D, Reconstruction, TrackElement};
use crate::scene::ply::{Column, Element, Ply, ScalarType, encode_ply_binary};
use crate::scene::synthetic::look_at;
use crate::scene::{Camera, CameraModelKind, ModelFormat, SceneError, write_model};
use crate::util::atomic::{StagedDir, write_atomic};
use crate::util::geometry::bounding_box;
use crate::util::progress::Progress;
use crate::util::rng::Rng;

/// Options of a synthetic capture.
#[derive(Clone, Debug, Serialize)]
pub struct SynthOptions {
    pub preset: Preset,
    pub seed: u64,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    /// Write semi-dense points and keypoints (false: `--no-points`, for real COLMAP runs).
    pub with_points: bool,
    /// Number of points to keep after visibility filtering.
    pub target_points: usize,
    /// Standard deviation of 3D point noise, as a fraction of the plant height.
    pub position_noise: f64,
    /// Fraction of points displaced far off their surface (bad matches).
    pub outlier_fraction: f64,
    /// Standard deviation of keypoint noise, pixels.
    pub keypoint_noise_px: f64,
    /// A printed checkerboard of squares this many metres wide beside the pot (a scale
    /// reference; `scene::CHECKERBOARD_SQUARES` squares), or none.
    #[serde(default)]
    pub checkerboard: Option<f64>,
    /// What surrounds the plant: a patterned floor and wall, or a cabin's plain dark cloth.
    #[serde(default)]
    pub backdrop: Backdrop,
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            preset: Preset::Broadleaf,
            seed: 1,
            views: 36,
            width: 800,
            height: 600,
            with_points: true,
            target_points: 60_000,
            position_noise: 0.001,
            outlier_fraction: 0.005,
            keypoint_noise_px: 0.3,
            checkerboard: None,
            backdrop: Backdrop::Patterned,
        }
    }
}

/// What a synth run produced.
#[derive(Clone, Debug, Serialize)]
pub struct SynthSummary {
    pub preset: Preset,
    pub seed: u64,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub leaves: usize,
    pub branches: usize,
    pub points: usize,
    pub points_by_part: BTreeMap<String, usize>,
    pub mean_track_length: f64,
    pub plant_height: f64,
    pub renderer: String,
    /// Seconds per stage.
    pub timings: BTreeMap<String, f64>,
}

/// Synth failures.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("invalid options: {0}")]
    Options(String),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> SynthError {
    SynthError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// A candidate or kept point with its ground truth.
#[derive(Clone, Debug)]
struct SampledPoint {
    true_position: Point3<f64>,
    object: usize,
    /// Views (indices) that see the point, with its pixel position in each.
    track: Vec<(usize, Point2<f64>)>,
}

/// Ring elevations (degrees) of the low and high rings.
const RING_ELEVATIONS_DEG: [f64; 2] = [12.0, 38.0];

/// The shared camera and the ring poses: two rings (low and high elevation) looking at the
/// centre of the plant's bounding box, at the smallest distance where every framing point of
/// the plant stays inside 92 % of the frame in every view (the plant fills most of the frame).
pub fn ring_cameras(
    plant: &SynthPlant,
    views: usize,
    width: u32,
    height: u32,
) -> (Camera, Vec<Isometry3<f64>>) {
    let focal = 1.15 * width as f64;
    let camera = Camera::new(
        1,
        CameraModelKind::Pinhole,
        width as u64,
        height as u64,
        vec![focal, focal, width as f64 / 2.0, height as f64 / 2.0],
    )
    .unwrap_or_else(|e| unreachable!("ring camera intrinsics are valid: {e}"));
    let points = plant.framing_points();
    let (lo, hi) = bounding_box(&points);
    let target = nalgebra::center(&lo, &hi);
    let low = views.div_ceil(2);
    let directions: Vec<nalgebra::Vector3<f64>> = [(low, 0, 0.0), (views - low, 1, 0.5)]
        .into_iter()
        .flat_map(|(count, ring, offset)| {
            (0..count).map(move |k| {
                let azimuth = std::f64::consts::TAU * (k as f64 + offset) / count as f64;
                let e = RING_ELEVATIONS_DEG[ring].to_radians();
                nalgebra::Vector3::new(e.cos() * azimuth.cos(), e.cos() * azimuth.sin(), e.sin())
            })
        })
        .collect();
    let poses_at = |distance: f64| -> Vec<Isometry3<f64>> {
        directions
            .iter()
            .map(|d| look_at(target + d * distance, target))
            .collect()
    };
    let fits = |distance: f64| {
        let (w, h) = (width as f64, height as f64);
        poses_at(distance).iter().all(|pose| {
            points.iter().all(|p| {
                camera.project(&(pose * p).coords).is_some_and(|uv| {
                    (uv.x - w / 2.0).abs() <= 0.46 * w && (uv.y - h / 2.0).abs() <= 0.46 * h
                })
            })
        })
    };
    let radius = points
        .iter()
        .map(|p| (p - target).norm())
        .fold(0.0, f64::max);
    // Bisection between a distance that is too close and one where the bounding sphere fits.
    let (mut near, mut far) = (
        0.2 * radius,
        3.0 * radius / (0.46 * height as f64 / focal).atan().sin(),
    );
    for _ in 0..40 {
        let mid = 0.5 * (near + far);
        if fits(mid) {
            far = mid;
        } else {
            near = mid;
        }
    }
    (camera, poses_at(far))
}

/// Projects `point` into view `v` and tests it against the rendered id and depth.
fn visible_in(
    point: &Point3<f64>,
    object_id: u32,
    camera: &ViewCamera,
    render: &RenderOutput,
) -> Option<Point2<f64>> {
    let (uv, depth) = camera.project(point)?;
    if uv.x < 0.0 || uv.y < 0.0 || uv.x >= camera.width as f64 || uv.y >= camera.height as f64 {
        return None;
    }
    let (x, y) = (uv.x as u32, uv.y as u32);
    if render.id_at(x, y) != object_id {
        return None;
    }
    let rendered = render.depth_at(x, y) as f64;
    ((rendered - depth).abs() < 0.004 * depth + 0.001).then_some(uv)
}

fn ply_column_f64(name: &str, values: Vec<f64>) -> Column {
    Column::scalar(name, ScalarType::F64, values)
}

fn write_ply(path: &Path, ply: &Ply) -> Result<(), SynthError> {
    write_atomic(path, &encode_ply_binary(ply)).map_err(|e| output_error(path, e))
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), SynthError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| output_error(path, e))?;
    write_atomic(path, text.as_bytes()).map_err(|e| output_error(path, e))
}

fn write_png(
    path: &Path,
    encode: impl FnOnce(&mut Vec<u8>) -> image::ImageResult<()>,
) -> Result<(), SynthError> {
    let mut bytes = Vec::new();
    encode(&mut bytes).map_err(|e| output_error(path, e))?;
    write_atomic(path, &bytes).map_err(|e| output_error(path, e))
}

fn encode_rgb_png(image: &RgbaImage, out: &mut Vec<u8>) -> image::ImageResult<()> {
    let rgb = image::DynamicImage::ImageRgba8(image.clone()).to_rgb8();
    rgb.write_to(&mut std::io::Cursor::new(out), image::ImageFormat::Png)
}

/// Renders and writes a synthetic dataset into `out` (replaced if it exists).
pub fn write_dataset(
    options: &SynthOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SynthSummary, SynthError> {
    if options.views < 2 {
        return Err(SynthError::Options("need at least 2 views".into()));
    }
    if options.width < 16 || options.height < 16 {
        return Err(SynthError::Options("images must be at least 16x16".into()));
    }
    let mut timings = BTreeMap::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, timings: &mut BTreeMap<String, f64>| {
        timings.insert(name.to_owned(), clock.elapsed().as_secs_f64());
        clock = Instant::now();
    };

    progress.stage("generating plant", 0);
    let plant = generate_plant(options.preset, options.seed);
    let (camera, poses) = ring_cameras(&plant, options.views, options.width, options.height);
    let camera_distance = (poses[0].inverse() * Point3::origin()).coords.norm();
    let backdrop_radius = (2.2 * camera_distance).max(1.5);
    let scene = build_scene(
        &plant,
        backdrop_radius,
        options.seed,
        options.checkerboard,
        options.backdrop,
    );
    lap("generate", &mut timings);

    // Render every view.
    progress.stage("rendering views", options.views as u64);
    let mut renderer = Renderer::new()?;
    let renderer_name = renderer.adapter_description();
    let gpu_scene = upload_scene(&renderer, &scene)?;
    let view_cameras: Vec<ViewCamera> = poses
        .iter()
        .map(|pose| ViewCamera::from_colmap(&camera, pose, 0.02, 4.0 * backdrop_radius))
        .collect::<Result<_, _>>()?;
    let lighting = Lighting::default();
    let mut renders = Vec::with_capacity(options.views);
    for view in &view_cameras {
        renders.push(renderer.render(&gpu_scene, view, &lighting)?);
        progress.advance(1);
    }
    drop(gpu_scene);
    lap("render", &mut timings);

    // Assemble in a sibling folder, then rename into place.
    let staging = StagedDir::new(out).map_err(|e| output_error(out, e))?;
    let root = staging.path();
    for dir in ["images", "sparse/0", "gt/leaves", "gt/masks"] {
        std::fs::create_dir_all(root.join(dir)).map_err(|e| output_error(&root.join(dir), e))?;
    }

    // Points.
    let points = if options.with_points {
        progress.stage("sampling points", 0);
        sample_points(options, &scene, &view_cameras, &renders)
    } else {
        Vec::new()
    };
    lap("sample_points", &mut timings);

    progress.stage("writing dataset", options.views as u64);
    let names: Vec<String> = (0..options.views)
        .map(|v| format!("view_{v:04}.png"))
        .collect();
    let model = build_model(
        options,
        &camera,
        &poses,
        &names,
        &points,
        &renders,
        plant.height,
    );
    write_model(
        &root.join("sparse/0"),
        &model.reconstruction,
        ModelFormat::Binary,
    )?;
    names.par_iter().zip(renders.par_iter()).try_for_each(
        |(name, render)| -> Result<(), SynthError> {
            write_png(&root.join("images").join(name), |out| {
                encode_rgb_png(&render.color, out)
            })?;
            let mask: ImageBuffer<Luma<u16>, Vec<u16>> =
                ImageBuffer::from_fn(render.width, render.height, |x, y| {
                    let id = render.id_at(x, y);
                    Luma([leaf_mask_value(&scene, id)])
                });
            write_png(&root.join("gt/masks").join(name), |out| {
                mask.write_to(&mut std::io::Cursor::new(out), image::ImageFormat::Png)
            })?;
            progress.advance(1);
            Ok(())
        },
    )?;
    write_ground_truth(root, options, &plant, &scene, &points, &model)?;
    lap("write", &mut timings);

    let mut points_by_part = BTreeMap::new();
    for p in &points {
        *points_by_part
            .entry(scene.objects[p.object].part.name().to_owned())
            .or_insert(0) += 1;
    }
    let summary = SynthSummary {
        preset: options.preset,
        seed: options.seed,
        views: options.views,
        width: options.width,
        height: options.height,
        leaves: plant.leaves.len(),
        branches: plant.branches.branches.len(),
        points: points.len(),
        points_by_part,
        mean_track_length: if points.is_empty() {
            0.0
        } else {
            points.iter().map(|p| p.track.len()).sum::<usize>() as f64 / points.len() as f64
        },
        plant_height: plant.height,
        renderer: renderer_name,
        timings,
    };
    write_json(
        &root.join("meta.json"),
        &serde_json::json!({
            "generator": format!("frond {}", env!("CARGO_PKG_VERSION")),
            "options": options,
            "summary": summary,
            "plant": {
                "center": [plant.center.x, plant.center.y, plant.center.z],
                "radius": plant.radius,
                "height": plant.height,
                "pot": plant.pot,
            },
            "camera_distance": camera_distance,
            "backdrop_radius": backdrop_radius,
            "parts": Part::ALL.iter().map(|p| (*p as u8, p.name())).collect::<Vec<_>>(),
        }),
    )?;

    // Move into place.
    staging.commit().map_err(|e| output_error(out, e))?;
    Ok(summary)
}

/// Leaf id + 1 for leaf objects, 0 otherwise.
fn leaf_mask_value(scene: &SynthScene, object_id: u32) -> u16 {
    if object_id == 0 {
        return 0;
    }
    let leaf = super::scene::leaf_object_id(0);
    let count = scene
        .objects
        .iter()
        .filter(|o| o.part == Part::Leaf)
        .count() as u32;
    if object_id >= leaf && object_id < leaf + count {
        (object_id - leaf + 1).min(u16::MAX as u32) as u16
    } else {
        0
    }
}

fn upload_scene(
    renderer: &Renderer,
    scene: &SynthScene,
) -> Result<crate::render::GpuScene, RenderError> {
    let mut gpu = renderer.new_scene();
    let handles: Vec<_> = scene
        .textures
        .iter()
        .map(|t| renderer.add_texture(&mut gpu, t))
        .collect();
    for object in &scene.objects {
        renderer.add_mesh(
            &mut gpu,
            &object.mesh,
            handles[object.texture],
            object.object_id,
            false,
        )?;
    }
    Ok(gpu)
}

/// Share of the point budget per part, as multi-view stereo on a plant capture yields it:
/// most points on the plant, a minority on pot, floor and backdrop.
fn point_share(part: Part) -> f64 {
    match part {
        Part::Leaf | Part::Stem => 0.72,
        Part::Pot => 0.08,
        Part::Floor => 0.13,
        Part::Background => 0.07,
    }
}

/// Which budget a part draws from (leaves and stems share the plant's).
fn budget_group(part: Part) -> usize {
    match part {
        Part::Leaf | Part::Stem => 0,
        Part::Pot => 1,
        Part::Floor => 2,
        Part::Background => 3,
    }
}

/// Samples surface points uniformly by area within each part group, keeps those seen in at
/// least two views (depth-tested against the renders), then thins each group to its share of
/// the target count.
fn sample_points(
    options: &SynthOptions,
    scene: &SynthScene,
    cameras: &[ViewCamera],
    renders: &[RenderOutput],
) -> Vec<SampledPoint> {
    let mut group_area = [0.0f64; 4];
    for object in &scene.objects {
        group_area[budget_group(object.part)] += object.mesh.area();
    }
    let quota = |part: Part| (point_share(part) * options.target_points as f64) as usize;
    // Oversample: hidden samples are discarded by the visibility test.
    let oversample = 3.0;
    let candidates: Vec<(usize, Point3<f64>)> = scene
        .objects
        .iter()
        .enumerate()
        .flat_map(|(i, object)| {
            let group = budget_group(object.part);
            let share = object.mesh.area() / group_area[group].max(1e-12);
            let count = ((oversample * quota(object.part) as f64 * share).round() as usize).max(1);
            let mut rng = Rng::stream(options.seed ^ 0x9017, i as u64);
            object
                .mesh
                .sample_surface(count, &mut rng)
                .into_iter()
                .map(move |s| (i, s.position.cast::<f64>()))
                .collect::<Vec<_>>()
        })
        .collect();
    let kept: Vec<SampledPoint> = candidates
        .par_iter()
        .filter_map(|&(object, position)| {
            let object_id = scene.objects[object].object_id;
            let track: Vec<(usize, Point2<f64>)> = cameras
                .iter()
                .zip(renders)
                .enumerate()
                .filter_map(|(v, (camera, render))| {
                    visible_in(&position, object_id, camera, render).map(|uv| (v, uv))
                })
                .collect();
            (track.len() >= 2).then_some(SampledPoint {
                true_position: position,
                object,
                track,
            })
        })
        .collect();
    let mut rng = Rng::seed_from(options.seed ^ 0x7411);
    let mut candidates_per_group = [0usize; 4];
    for (object, _) in &candidates {
        candidates_per_group[budget_group(scene.objects[*object].part)] += 1;
    }
    let mut by_group: [Vec<SampledPoint>; 4] = Default::default();
    for point in kept {
        by_group[budget_group(scene.objects[point.object].part)].push(point);
    }
    let mut points = Vec::new();
    for (group, mut members) in by_group.into_iter().enumerate() {
        let part = [Part::Leaf, Part::Pot, Part::Floor, Part::Background][group];
        rng.shuffle(&mut members);
        // Even spacing, as multi-view stereo's regularly resampled image points have: thin the
        // visible samples to a Poisson-disk set whose density meets the quota.
        let visible_area =
            group_area[group] * members.len() as f64 / candidates_per_group[group].max(1) as f64;
        let radius = 0.7 * (visible_area / quota(part).max(1) as f64).sqrt();
        let mut members = poisson_disk_thin(members, radius);
        if members.len() > quota(part) {
            members.truncate(quota(part));
        }
        points.extend(members);
    }
    // A stable, spatially meaningful order: by object, then along x.
    points.sort_by(|a, b| {
        a.object
            .cmp(&b.object)
            .then(a.true_position.x.total_cmp(&b.true_position.x))
    });
    points
}

/// Keeps points (in the given order) that lie at least `radius` from every point kept before
/// them (dart throwing with a grid hash).
fn poisson_disk_thin(points: Vec<SampledPoint>, radius: f64) -> Vec<SampledPoint> {
    if radius <= 0.0 || !radius.is_finite() {
        return points;
    }
    let cell = |p: &Point3<f64>| {
        [
            (p.x / radius).floor() as i64,
            (p.y / radius).floor() as i64,
            (p.z / radius).floor() as i64,
        ]
    };
    let mut grid: std::collections::HashMap<[i64; 3], Vec<Point3<f64>>> =
        std::collections::HashMap::new();
    let mut kept = Vec::with_capacity(points.len());
    for point in points {
        let c = cell(&point.true_position);
        let mut free = true;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(others) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz])
                        && others
                            .iter()
                            .any(|o| (o - point.true_position).norm() < radius)
                    {
                        free = false;
                        break 'search;
                    }
                }
            }
        }
        if free {
            grid.entry(c).or_default().push(point.true_position);
            kept.push(point);
        }
    }
    kept
}

/// The COLMAP model of a capture and the per-point ground truth in the same order.
struct CaptureModel {
    reconstruction: Reconstruction,
    /// Stored (noisy) positions, one per point.
    positions: Vec<Point3<f64>>,
    outlier: Vec<bool>,
}

fn build_model(
    options: &SynthOptions,
    camera: &Camera,
    poses: &[Isometry3<f64>],
    names: &[String],
    points: &[SampledPoint],
    renders: &[RenderOutput],
    plant_height: f64,
) -> CaptureModel {
    let mut keypoints: Vec<Vec<Keypoint>> = vec![Vec::new(); poses.len()];
    let mut model_points = Vec::with_capacity(points.len());
    let mut positions = Vec::with_capacity(points.len());
    let mut outlier = Vec::with_capacity(points.len());
    for (index, point) in points.iter().enumerate() {
        let mut rng = Rng::stream(options.seed ^ 0x3d, index as u64);
        let id = index as u64 + 1;
        let sigma = options.position_noise * plant_height;
        let mut position = point.true_position
            + nalgebra::Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma;
        let is_outlier = rng.chance(options.outlier_fraction);
        if is_outlier {
            let direction = nalgebra::Vector3::new(rng.normal(), rng.normal(), rng.normal())
                .try_normalize(1e-12)
                .unwrap_or_else(nalgebra::Vector3::z);
            position += direction * rng.range(0.01, 0.05) * plant_height;
        }
        let mut track = Vec::with_capacity(point.track.len());
        let mut color = [0.0f64; 3];
        let mut error = 0.0;
        for &(view, uv) in &point.track {
            let noisy =
                uv + nalgebra::Vector2::new(rng.normal(), rng.normal()) * options.keypoint_noise_px;
            let pixel = renders[view].color.get_pixel(
                (uv.x as u32).min(renders[view].width - 1),
                (uv.y as u32).min(renders[view].height - 1),
            );
            for c in 0..3 {
                color[c] += pixel[c] as f64;
            }
            let camera_point = poses[view] * position;
            if let Some(projected) = camera.project(&camera_point.coords) {
                error += (projected - noisy).norm();
            }
            track.push(TrackElement {
                image_id: view as u32 + 1,
                keypoint_index: keypoints[view].len() as u32,
            });
            keypoints[view].push(Keypoint {
                uv_image: noisy,
                point3d_id: Some(id),
            });
        }
        let n = point.track.len() as f64;
        model_points.push(Point3D {
            id,
            position_world: position,
            color: color.map(|c| (c / n).round().clamp(0.0, 255.0) as u8),
            error: error / n,
            track,
        });
        positions.push(position);
        outlier.push(is_outlier);
    }
    let images = poses
        .iter()
        .zip(names)
        .zip(keypoints)
        .enumerate()
        .map(|(v, ((pose, name), keypoints))| Image {
            id: v as u32 + 1,
            camera_id: camera.id,
            name: name.clone(),
            camera_from_world: *pose,
            keypoints,
        })
        .collect();
    let reconstruction = Reconstruction::from_parts(vec![camera.clone()], images, model_points)
        .unwrap_or_else(|e| unreachable!("synthetic model is consistent: {e}"));
    CaptureModel {
        reconstruction,
        positions,
        outlier,
    }
}

#[derive(Serialize)]
struct LeafRecord {
    id: u32,
    shape: super::leaf::LeafShape,
    /// Midrib arc length, metres (the leaf length that distances are divided by).
    length: f64,
    width: f64,
    area: f64,
    branch: u32,
    /// The compound leaf (its rachis's branch id) a leaflet belongs to; absent for simple
    /// leaves.
    #[serde(skip_serializing_if = "Option::is_none")]
    compound_leaf: Option<u32>,
    normal: [f64; 3],
    base: [f64; 3],
    tip: [f64; 3],
    points: usize,
    mesh: String,
}

fn write_ground_truth(
    root: &Path,
    options: &SynthOptions,
    plant: &SynthPlant,
    scene: &SynthScene,
    points: &[SampledPoint],
    model: &CaptureModel,
) -> Result<(), SynthError> {
    let gt = root.join("gt");
    // Per-point truth, in points3D order.
    let n = points.len();
    let object = |i: usize| &scene.objects[points[i].object];
    let ply = Ply {
        comments: vec!["frond synthetic ground truth".into()],
        elements: vec![Element {
            name: "vertex".into(),
            count: n,
            columns: vec![
                ply_column_f64("x", model.positions.iter().map(|p| p.x).collect()),
                ply_column_f64("y", model.positions.iter().map(|p| p.y).collect()),
                ply_column_f64("z", model.positions.iter().map(|p| p.z).collect()),
                Column::scalar(
                    "point_id",
                    ScalarType::U32,
                    (1..=n).map(|i| i as f64).collect(),
                ),
                Column::scalar(
                    "leaf_id",
                    ScalarType::I32,
                    (0..n).map(|i| object(i).leaf_id as f64).collect(),
                ),
                Column::scalar(
                    "part",
                    ScalarType::U8,
                    (0..n).map(|i| object(i).part as u8 as f64).collect(),
                ),
                Column::scalar(
                    "branch_id",
                    ScalarType::I32,
                    (0..n).map(|i| object(i).branch_id as f64).collect(),
                ),
                Column::scalar(
                    "outlier",
                    ScalarType::U8,
                    model.outlier.iter().map(|&o| o as u8 as f64).collect(),
                ),
                ply_column_f64("true_x", points.iter().map(|p| p.true_position.x).collect()),
                ply_column_f64("true_y", points.iter().map(|p| p.true_position.y).collect()),
                ply_column_f64("true_z", points.iter().map(|p| p.true_position.z).collect()),
            ],
        }],
    };
    write_ply(&gt.join("points.ply"), &ply)?;

    // Leaves.
    let mut leaf_points = vec![0usize; plant.leaves.len()];
    for p in points {
        let leaf = scene.objects[p.object].leaf_id;
        if leaf >= 0 {
            leaf_points[leaf as usize] += 1;
        }
    }
    let mut records = Vec::with_capacity(plant.leaves.len());
    for leaf in &plant.leaves {
        let name = format!("leaves/leaf_{:03}.ply", leaf.id);
        leaf.mesh
            .write_ply(&gt.join(&name))
            .map_err(SynthError::Scene)?;
        let normal = leaf.world_from_leaf.rotation * nalgebra::Vector3::z();
        let base = leaf.world_from_leaf * leaf.geometry.point(0.0, 0.0);
        let tip = leaf.world_from_leaf * leaf.geometry.point(1.0, 0.0);
        records.push(LeafRecord {
            id: leaf.id,
            shape: leaf.geometry.shape,
            length: leaf.geometry.midrib_length(),
            width: leaf.geometry.width,
            area: leaf.mesh.area(),
            branch: leaf.branch,
            compound_leaf: leaf.compound_leaf,
            normal: [normal.x, normal.y, normal.z],
            base: [base.x, base.y, base.z],
            tip: [tip.x, tip.y, tip.z],
            points: leaf_points[leaf.id as usize],
            mesh: name,
        });
    }
    write_json(&gt.join("leaves.json"), &records)?;

    // Centrelines every ~5 mm, for distance metrics.
    let branches = crate::branch::plant::skeleton_records(&plant.branches, 0.005, 2);
    write_json(
        &gt.join("branches.json"),
        &crate::branch::plant::SkeletonFile::new(branches),
    )?;

    // Dense surface samples of the plant (leaves and stems), ~2 mm apart.
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    let mut zs = Vec::new();
    let mut leaf_ids = Vec::new();
    let mut parts = Vec::new();
    for (i, object) in scene.objects.iter().enumerate() {
        if !object.part.is_plant() && object.part != Part::Pot {
            continue;
        }
        let count = ((object.mesh.area() / (0.002 * 0.002)) as usize).clamp(20, 200_000);
        let mut rng = Rng::stream(options.seed ^ 0x5a, i as u64);
        for s in object.mesh.sample_surface(count, &mut rng) {
            xs.push(s.position.x as f64);
            ys.push(s.position.y as f64);
            zs.push(s.position.z as f64);
            leaf_ids.push(object.leaf_id as f64);
            parts.push(object.part as u8 as f64);
        }
    }
    let count = xs.len();
    let samples = Ply {
        comments: vec!["frond synthetic plant surface samples".into()],
        elements: vec![Element {
            name: "vertex".into(),
            count,
            columns: vec![
                Column::scalar("x", ScalarType::F32, xs),
                Column::scalar("y", ScalarType::F32, ys),
                Column::scalar("z", ScalarType::F32, zs),
                Column::scalar("leaf_id", ScalarType::I32, leaf_ids),
                Column::scalar("part", ScalarType::U8, parts),
            ],
        }],
    };
    write_ply(&gt.join("surface_samples.ply"), &samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_cameras_frame_the_plant_tightly_in_every_view() {
        for preset in Preset::ALL {
            let plant = generate_plant(preset, 4);
            let (camera, poses) = ring_cameras(&plant, 36, 800, 600);
            assert_eq!(poses.len(), 36);
            let points = plant.framing_points();
            // The farthest-out point of any view reaches 92 % of the half-frame: tight framing.
            let mut reach: f64 = 0.0;
            for pose in &poses {
                for p in &points {
                    let uv = camera.project(&(pose * p).coords).unwrap();
                    assert!(uv.x >= 0.0 && uv.x <= 800.0 && uv.y >= 0.0 && uv.y <= 600.0);
                    reach = reach.max(
                        ((uv.x - 400.0) / 400.0)
                            .abs()
                            .max(((uv.y - 300.0) / 300.0).abs()),
                    );
                }
            }
            assert!((reach - 0.92).abs() < 0.005, "{preset}: reach {reach}");
        }
    }
}
