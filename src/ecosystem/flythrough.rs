//! Offscreen fly-through of a plant scene: per frame, frustum culling of every instance's
//! bounding sphere, screen-space-error LOD selection (seed 000 eqs. 17–19, with hysteresis
//! and dwell), instanced draws grouped by (master, level, part), and the frame's cost.
//! `Mode::Both` renders the same path with LOD and with every plant at full detail, so the
//! speed-up, the triangle ratio and the image difference are measured in one run.

use std::path::Path;
use std::time::Instant;

use image::{Rgba, RgbaImage};
use nalgebra::{Isometry3, Point3, Vector3};
use serde::Serialize;

use super::{EcosystemError, EcosystemScene};
use crate::lod::asset::PlantAsset;
use crate::lod::plant::{PlantLod, PlantLodOptions, build_plant_lod};
use crate::lod::select::{
    LodSelector, LodState, SelectionOptions, Viewport, projected_error_px, view_depth,
};
use crate::render::{
    InstanceBatch, InstanceTransform, Lighting, MeshHandle, RenderError, Renderer, ViewCamera,
};
use crate::scene::synthetic::look_at;
use crate::util::progress::Progress;

/// What to render.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// LOD selection (the product).
    Lod,
    /// Every plant at full detail (the baseline).
    Full,
    /// Both, on the same path, in one run.
    Both,
}

/// Settings of [`run_flythrough`].
#[derive(Clone, Debug)]
pub struct FlythroughOptions {
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub fov_y_deg: f64,
    /// Seconds the path takes (LOD dwell times are measured on this clock).
    pub duration_s: f64,
    pub selection: SelectionOptions,
    pub mode: Mode,
    /// LOD chains for masters stored without one.
    pub lod: PlantLodOptions,
    /// Writes each frame's PNG into the output folder.
    pub save_frames: bool,
}

impl Default for FlythroughOptions {
    fn default() -> Self {
        Self {
            frames: 8,
            width: 1280,
            height: 720,
            fov_y_deg: 60.0,
            duration_s: 8.0,
            selection: SelectionOptions::default(),
            mode: Mode::Both,
            lod: PlantLodOptions::default(),
            save_frames: false,
        }
    }
}

/// One rendered frame.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRecord {
    pub mode: Mode,
    pub frame: usize,
    /// CPU time of culling, selection and batching.
    pub cpu_ms: f64,
    /// Upload, draw and GPU completion.
    pub gpu_ms: f64,
    pub total_ms: f64,
    pub draw_calls: usize,
    pub instances_drawn: usize,
    pub instances_culled: usize,
    pub triangles: usize,
    /// Largest projected error of a drawn level (eq. 18 at the nearest point of the plant's
    /// bounding sphere), pixels.
    pub max_error_px: f64,
    /// Level switches this frame.
    pub switches: usize,
}

/// Summary of one mode.
#[derive(Clone, Debug, Serialize)]
pub struct ModeSummary {
    pub mode: Mode,
    pub frames: usize,
    pub mean_ms: f64,
    pub median_ms: f64,
    pub mean_triangles: f64,
    pub mean_draw_calls: f64,
    pub max_error_px: f64,
    /// Largest number of switches of one plant within any 1 s window.
    pub max_switches_per_plant_per_second: usize,
}

/// What a fly-through measured.
#[derive(Clone, Debug, Serialize)]
pub struct FlythroughReport {
    pub adapter: String,
    pub width: u32,
    pub height: u32,
    pub instances: usize,
    pub masters: usize,
    /// Per master: triangles and μ (m) of each level.
    pub master_levels: Vec<Vec<(usize, f64)>>,
    pub prepare_s: f64,
    pub summaries: Vec<ModeSummary>,
    /// Full-detail mean frame time over LOD mean frame time (Mode::Both).
    pub speedup: Option<f64>,
    /// Full-detail mean triangles over LOD mean triangles (Mode::Both).
    pub triangle_ratio: Option<f64>,
    /// Mean fraction of pixels whose colour differs by more than 10 % between the LOD and the
    /// full-detail frame (Mode::Both).
    pub mean_differing_pixels: Option<f64>,
    pub frames: Vec<FrameRecord>,
}

/// Fly-through failures.
#[derive(Debug, thiserror::Error)]
pub enum FlythroughError {
    #[error(transparent)]
    Scene(#[from] EcosystemError),
    #[error(transparent)]
    Lod(#[from] crate::lod::plant::LodError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
}

/// A master on the GPU: per level, the instanced mesh of each part.
struct GpuMaster {
    levels: Vec<Vec<MeshHandle>>,
    selector: LodSelector,
    errors: Vec<f64>,
    center: Point3<f64>,
    radius: f64,
}

/// Ground texture: a seeded mottled green-brown.
fn ground_texture(seed: u64) -> RgbaImage {
    let noise = super::terrain::fractal_noise(128, 4, seed);
    RgbaImage::from_fn(128, 128, |x, y| {
        let t = noise.get_pixel(x, y)[0] as f32 / 255.0;
        let mix = |a: f32, b: f32| (a + (b - a) * t).round() as u8;
        Rgba([mix(96.0, 122.0), mix(104.0, 92.0), mix(58.0, 64.0), 255])
    })
}

/// The camera at time `t` ∈ [0, 1]: a dolly from outside one corner across the field, 2.5 m
/// above the ground, looking along the diagonal and 12° down.
pub fn path_camera(scene: &EcosystemScene, t: f64, options: &FlythroughOptions) -> ViewCamera {
    let [sx, sy] = scene.terrain.size_m;
    let start = Point3::new(-0.05 * sx, -0.05 * sy, 0.0);
    let end = Point3::new(0.55 * sx, 0.55 * sy, 0.0);
    let mut eye = start + (end - start) * t.clamp(0.0, 1.0);
    let ground = scene
        .terrain
        .height(eye.x.clamp(0.0, sx), eye.y.clamp(0.0, sy));
    eye.z = ground + 2.5;
    let forward = Vector3::new(sx, sy, 0.0).normalize();
    let pitch = 12f64.to_radians();
    let direction = forward * pitch.cos() - Vector3::z() * pitch.sin();
    let focal = 0.5 * options.height as f64 / (0.5 * options.fov_y_deg.to_radians()).tan();
    ViewCamera {
        width: options.width,
        height: options.height,
        fx: focal,
        fy: focal,
        cx: 0.5 * options.width as f64,
        cy: 0.5 * options.height as f64,
        camera_from_world: look_at(eye, eye + direction),
        near: 0.05,
        far: 2.0 * (sx * sx + sy * sy).sqrt(),
    }
}

/// Whether a sphere (world frame) intersects the camera's view frustum.
fn sphere_visible(camera: &ViewCamera, center_world: &Point3<f64>, radius: f64) -> bool {
    let p = camera.camera_from_world * center_world;
    if p.z < camera.near - radius || p.z > camera.far + radius {
        return false;
    }
    let (w, h) = (camera.width as f64, camera.height as f64);
    // Side planes through the eye: inside iff n·p ≥ 0.
    let planes = [
        Vector3::new(camera.fx, 0.0, camera.cx),
        Vector3::new(-camera.fx, 0.0, w - camera.cx),
        Vector3::new(0.0, camera.fy, camera.cy),
        Vector3::new(0.0, -camera.fy, h - camera.cy),
    ];
    planes
        .iter()
        .all(|n| n.normalize().dot(&p.coords) >= -radius)
}

fn column_major(m: &nalgebra::Matrix4<f64>) -> InstanceTransform {
    let mut out = [0.0f32; 16];
    for (o, v) in out.iter_mut().zip(m.iter()) {
        *o = *v as f32;
    }
    out
}

/// Loads every master (building its LOD chain when its glb has none), uploads it and the
/// terrain, and renders the fly-through. Frames and `report.json` are the caller's to write;
/// frame PNGs go to `out` when asked for.
pub fn run_flythrough(
    scene: &EcosystemScene,
    scene_path: &Path,
    out: &Path,
    options: &FlythroughOptions,
    progress: &dyn Progress,
) -> Result<FlythroughReport, FlythroughError> {
    let prepare = Instant::now();
    let mut renderer = Renderer::new()?;
    let viewport = Viewport {
        height_px: options.height as f64,
        fov_y_rad: options.fov_y_deg.to_radians(),
    };
    let mut gpu = renderer.new_scene();
    progress.stage("preparing plants", scene.plants.len() as u64);
    let mut masters = Vec::with_capacity(scene.plants.len());
    let mut master_levels = Vec::with_capacity(scene.plants.len());
    for plant in 0..scene.plants.len() {
        let path = scene.plant_path(scene_path, plant);
        let mut lod = PlantLod::read_glb(&path, options.lod.chain.error_samples)?;
        if lod.levels.len() == 1 {
            let asset = PlantAsset {
                parts: lod.levels[0].parts.clone(),
                textures: lod.textures.clone(),
            };
            lod = build_plant_lod(
                &asset,
                Some(&mut renderer),
                &options.lod,
                &path.display().to_string(),
            )?;
        }
        let parts: Vec<_> = lod.levels.iter().flat_map(|l| &l.parts).collect();
        let textures =
            crate::lod::asset::upload_textures(&renderer, &mut gpu, &lod.textures, &parts);
        let mut levels = Vec::with_capacity(lod.levels.len());
        for level in &lod.levels {
            let mut handles = Vec::with_capacity(level.parts.len());
            for part in &level.parts {
                let handle = renderer.add_instanced_mesh(
                    &mut gpu,
                    &part.mesh,
                    textures[part.texture],
                    1 + plant as u32,
                    part.alpha_test,
                )?;
                if part.shading != Default::default() {
                    renderer.set_shading(&gpu, handle, part.shading())?;
                }
                handles.push(handle);
            }
            levels.push(handles);
        }
        let errors = lod.errors();
        master_levels.push(
            lod.levels
                .iter()
                .map(|l| (l.triangles, l.error_world))
                .collect(),
        );
        masters.push(GpuMaster {
            levels,
            selector: LodSelector::new(&errors, &viewport, options.selection),
            errors,
            center: lod.center.cast::<f64>(),
            radius: lod.radius as f64,
        });
        progress.advance(1);
    }
    let ground = renderer.add_texture(&mut gpu, &ground_texture(scene.seed));
    renderer.add_mesh(&mut gpu, &scene.terrain.mesh(4.0), ground, 100_000, false)?;
    // Per instance, once: its GPU transform and world bounding sphere.
    struct Placement {
        plant: usize,
        transform: InstanceTransform,
        center: Point3<f64>,
        radius: f64,
        scale: f64,
    }
    let placements: Vec<Placement> = scene
        .instances
        .iter()
        .map(|i| {
            let world_from_plant = i.world_from_plant(&scene.plants[i.plant]);
            let master = &masters[i.plant];
            Placement {
                plant: i.plant,
                transform: column_major(&world_from_plant.to_homogeneous()),
                center: world_from_plant * master.center,
                radius: master.radius * i.scale,
                scale: i.scale,
            }
        })
        .collect();
    let prepare_s = prepare.elapsed().as_secs_f64();

    let modes: Vec<Mode> = match options.mode {
        Mode::Both => vec![Mode::Lod, Mode::Full],
        m => vec![m],
    };
    let frames = options.frames.max(1);
    let mut records = Vec::new();
    let mut images: Vec<Vec<RgbaImage>> = Vec::new();
    let mut max_switches_per_second: Vec<usize> = Vec::new();
    for &mode in &modes {
        progress.stage(
            match mode {
                Mode::Lod => "rendering with LOD",
                _ => "rendering full detail",
            },
            frames as u64,
        );
        let mut states = vec![LodState::default(); placements.len()];
        let mut switches_of: Vec<Vec<f64>> = vec![Vec::new(); placements.len()];
        let mut mode_images = Vec::new();
        for frame in 0..frames {
            let t = if frames == 1 {
                0.0
            } else {
                frame as f64 / (frames - 1) as f64
            };
            let time_s = t * options.duration_s;
            let camera = path_camera(scene, t, options);
            let world_from_camera: Isometry3<f64> = camera.camera_from_world.inverse();
            let eye = Point3::from(world_from_camera.translation.vector);
            let forward = world_from_camera.rotation * Vector3::z();
            let cpu = Instant::now();
            // (master, level) → transforms.
            let mut buckets: Vec<Vec<Vec<InstanceTransform>>> = masters
                .iter()
                .map(|m| vec![Vec::new(); m.levels.len()])
                .collect();
            let (mut culled, mut drawn, mut max_error_px, mut switches) = (0, 0, 0.0f64, 0);
            for (k, placement) in placements.iter().enumerate() {
                let (center, radius, scale) = (placement.center, placement.radius, placement.scale);
                let master = &masters[placement.plant];
                if !sphere_visible(&camera, &center, radius) {
                    culled += 1;
                    continue;
                }
                // The plant's nearest point bounds its projected error (eq. 18).
                let nearest = (view_depth(&center, &eye, &forward) - radius).max(camera.near);
                let level = match mode {
                    Mode::Lod => {
                        let before = states[k].level;
                        let level = master
                            .selector
                            .select(&mut states[k], nearest / scale, time_s);
                        if level != before && frame > 0 {
                            switches += 1;
                            switches_of[k].push(time_s);
                        }
                        level
                    }
                    _ => 0,
                };
                max_error_px = max_error_px.max(projected_error_px(
                    master.errors[level] * scale,
                    nearest,
                    &viewport,
                ));
                buckets[placement.plant][level].push(placement.transform);
                drawn += 1;
            }
            let mut transforms = Vec::new();
            let mut batches = Vec::new();
            for (plant, levels) in buckets.iter().enumerate() {
                for (level, list) in levels.iter().enumerate() {
                    if list.is_empty() {
                        continue;
                    }
                    let range = transforms.len() as u32..(transforms.len() + list.len()) as u32;
                    transforms.extend_from_slice(list);
                    for &mesh in &masters[plant].levels[level] {
                        batches.push(InstanceBatch {
                            mesh,
                            instances: range.clone(),
                        });
                    }
                }
            }
            let cpu_ms = 1e3 * cpu.elapsed().as_secs_f64();
            let read_color = options.save_frames || options.mode == Mode::Both;
            let (stats, color) = renderer.render_instanced(
                &gpu,
                &camera,
                &Lighting::default(),
                &transforms,
                &batches,
                read_color,
            )?;
            if let Some(color) = color {
                if options.save_frames {
                    let name = format!(
                        "frame_{frame:04}_{}.png",
                        if mode == Mode::Lod { "lod" } else { "full" }
                    );
                    let path = out.join(name);
                    let mut png = Vec::new();
                    color
                        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                        .and_then(|_| {
                            crate::util::atomic::write_atomic(&path, &png)
                                .map_err(image::ImageError::IoError)
                        })
                        .map_err(|e| FlythroughError::Io {
                            path: path.display().to_string(),
                            message: e.to_string(),
                        })?;
                }
                mode_images.push(color);
            }
            records.push(FrameRecord {
                mode,
                frame,
                cpu_ms,
                gpu_ms: 1e3 * stats.seconds,
                total_ms: cpu_ms + 1e3 * stats.seconds,
                draw_calls: stats.draw_calls,
                instances_drawn: drawn,
                instances_culled: culled,
                triangles: stats.triangles,
                max_error_px,
                switches,
            });
            progress.advance(1);
        }
        images.push(mode_images);
        max_switches_per_second.push(
            switches_of
                .iter()
                .map(|times| {
                    // Switch times are in frame order: the most within any window of 1 s.
                    (0..times.len())
                        .map(|i| {
                            times[i..]
                                .iter()
                                .take_while(|&&t| t - times[i] < 1.0)
                                .count()
                        })
                        .max()
                        .unwrap_or(0)
                })
                .max()
                .unwrap_or(0),
        );
    }
    let mut summaries = Vec::new();
    for (m, &mode) in modes.iter().enumerate() {
        let of_mode: Vec<&FrameRecord> = records.iter().filter(|r| r.mode == mode).collect();
        let n = of_mode.len().max(1) as f64;
        let mut times: Vec<f64> = of_mode.iter().map(|r| r.total_ms).collect();
        times.sort_by(f64::total_cmp);
        summaries.push(ModeSummary {
            mode,
            frames: of_mode.len(),
            mean_ms: of_mode.iter().map(|r| r.total_ms).sum::<f64>() / n,
            median_ms: crate::util::stats::quantile_sorted(&times, 0.5),
            mean_triangles: of_mode.iter().map(|r| r.triangles as f64).sum::<f64>() / n,
            mean_draw_calls: of_mode.iter().map(|r| r.draw_calls as f64).sum::<f64>() / n,
            max_error_px: of_mode.iter().map(|r| r.max_error_px).fold(0.0, f64::max),
            max_switches_per_plant_per_second: max_switches_per_second[m],
        });
    }
    let both = options.mode == Mode::Both && summaries.len() == 2;
    let speedup = both.then(|| summaries[1].mean_ms / summaries[0].mean_ms.max(1e-9));
    let triangle_ratio =
        both.then(|| summaries[1].mean_triangles / summaries[0].mean_triangles.max(1.0));
    let mean_differing_pixels = (both && images.len() == 2).then(|| {
        let fractions: Vec<f64> = images[0]
            .iter()
            .zip(&images[1])
            .map(|(a, b)| {
                let differing = a
                    .pixels()
                    .zip(b.pixels())
                    .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 25))
                    .count();
                differing as f64 / (a.width() * a.height()).max(1) as f64
            })
            .collect();
        fractions.iter().sum::<f64>() / fractions.len().max(1) as f64
    });
    Ok(FlythroughReport {
        adapter: renderer.adapter_description(),
        width: options.width,
        height: options.height,
        instances: scene.instances.len(),
        masters: scene.plants.len(),
        master_levels,
        prepare_s,
        summaries,
        speedup,
        triangle_ratio,
        mean_differing_pixels,
        frames: records,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> ViewCamera {
        ViewCamera {
            width: 200,
            height: 100,
            fx: 100.0,
            fy: 100.0,
            cx: 100.0,
            cy: 50.0,
            camera_from_world: Isometry3::identity(),
            near: 0.1,
            far: 50.0,
        }
    }

    #[test]
    fn frustum_culling_keeps_exactly_the_spheres_that_reach_the_view() {
        let camera = camera();
        // In front, centred.
        assert!(sphere_visible(&camera, &Point3::new(0.0, 0.0, 5.0), 0.1));
        // Behind the eye, beyond the far plane.
        assert!(!sphere_visible(&camera, &Point3::new(0.0, 0.0, -1.0), 0.5));
        assert!(!sphere_visible(&camera, &Point3::new(0.0, 0.0, 51.0), 0.5));
        // The right edge is at x = z (cx = fx): a sphere just outside is culled, one whose
        // edge reaches inside is kept.
        let z = 10.0;
        let outside = Point3::new(z + 0.3 * 2f64.sqrt() + 0.01, 0.0, z);
        assert!(!sphere_visible(&camera, &outside, 0.3));
        assert!(sphere_visible(&camera, &outside, 0.4));
        // The top edge at y = −z/2.
        assert!(!sphere_visible(
            &camera,
            &Point3::new(0.0, -0.5 * z - 1.0, z),
            0.3
        ));
        assert!(sphere_visible(
            &camera,
            &Point3::new(0.0, -0.5 * z - 0.2, z),
            0.3
        ));
        // Every kept sphere projects near the image (its centre within its projected radius).
        for k in 0..200 {
            let p = Point3::new((k % 20) as f64 - 10.0, (k / 20) as f64 - 5.0, 4.0);
            if sphere_visible(&camera, &p, 0.2) {
                let (uv, _) = camera.project(&p).unwrap();
                let margin = 0.2 * camera.fx / p.z * 1.5 + 1.0;
                assert!(
                    uv.x > -margin
                        && uv.x < 200.0 + margin
                        && uv.y > -margin
                        && uv.y < 100.0 + margin
                );
            }
        }
    }
}
