//! Measurement aid: the billboard against the full plant at its switch distance (λ = 4 px)
//! on built-in synthetic plants, per view elevation: the light each sends to the eye (mean,
//! RMS and worst over 16 directions) and the coverage ratio.
//! With `--reference`, each of the two is instead compared with the same view rendered 8×
//! larger and averaged down in linear light (the plant as a well filtered image would show it),
//! over 8 directions: which of the two is wrong where they differ.
//! Usage: `cargo run --release --example billboard_switch -- [--reference] [PRESET:SEED ...]`
//! (default: broadleaf 4, 7, 11, 21, 31 and medium 3, 12, 22, 32).

use anyhow::{Context, Result, bail};
use frond::lod::asset::{AssetPart, PlantAsset, upload_textures};
use frond::lod::billboard::BillboardOptions;
use frond::lod::chain::ChainOptions;
use frond::lod::plant::{
    PlantLod, PlantLodOptions, REFERENCE_VIEWPORT, build_plant_lod, summarize_switch,
};
use frond::lod::select::switch_distance;
use frond::render::{Lighting, Renderer, ViewCamera};
use frond::scene::synthetic::look_at;
use frond::synth::{Preset, generate_plant, plant_model};
use nalgebra::Vector3;

fn main() -> Result<()> {
    let mut plants: Vec<(Preset, u64)> = Vec::new();
    let mut reference = false;
    for arg in std::env::args().skip(1) {
        if arg == "--reference" {
            reference = true;
            continue;
        }
        let (preset, seed) = arg
            .split_once(':')
            .with_context(|| format!("{arg}: expected PRESET:SEED"))?;
        let preset = match preset {
            "broadleaf" => Preset::Broadleaf,
            "medium" => Preset::Medium,
            "smallleaf" => Preset::Smallleaf,
            other => bail!("{other}: not a preset (broadleaf, medium, smallleaf)"),
        };
        plants.push((
            preset,
            seed.parse().with_context(|| format!("{arg}: seed"))?,
        ));
    }
    if plants.is_empty() {
        plants = [4, 7, 11, 21, 31]
            .map(|s| (Preset::Broadleaf, s))
            .into_iter()
            .chain([3, 12, 22, 32].map(|s| (Preset::Medium, s)))
            .collect();
    }
    let mut renderer = Renderer::new().context("starting the renderer")?;
    if reference {
        println!("plant          elevation  full vs 8× %  billboard vs 8× %");
    } else {
        println!("plant          elevation  mean %  RMS %  worst %  coverage");
    }
    for (preset, seed) in plants {
        let asset = PlantAsset::from_model(&plant_model(&generate_plant(preset, seed), 64));
        let options = PlantLodOptions {
            chain: ChainOptions {
                ratios: vec![0.1],
                error_samples: 300,
                seed: 1,
                ..Default::default()
            },
            billboard: Some(BillboardOptions::default()),
            surfels: None,
        };
        let lod = build_plant_lod(&asset, Some(&mut renderer), &options, "built-in plant")?;
        if reference {
            for (elevation, full, billboard) in against_supersampled(&lod, &mut renderer)? {
                println!(
                    "{:<14} {:>6.0}°  {:>+12.1}  {:>+17.1}",
                    format!("{preset:?} {seed}"),
                    elevation,
                    full,
                    billboard
                );
            }
            continue;
        }
        let checks = lod
            .switch_luminance(&mut renderer, 4.0, 16, &[5.0, 30.0, 60.0])?
            .context("no billboard level")?;
        for s in summarize_switch(&checks) {
            println!(
                "{:<14} {:>6.0}°  {:>+7.1}  {:>5.1}  {:>7.1}  {:>8.2}",
                format!("{preset:?} {seed}"),
                s.elevation_deg,
                s.mean_percent,
                s.rms_percent,
                s.worst_percent,
                s.coverage_ratio
            );
        }
    }
    Ok(())
}

/// Summed linear luminance of an sRGB image.
fn light(image: &image::RgbaImage) -> f64 {
    let decode = frond::util::color::srgb_to_linear;
    image
        .pixels()
        .map(|p| 0.2126 * decode(p[0]) + 0.7152 * decode(p[1]) + 0.0722 * decode(p[2]))
        .sum()
}

/// Per elevation (5°, 30°, 60°; 8 directions each), the full plant's and the billboard's light
/// at the billboard's switch distance against the full plant rendered 8× larger (per unit of
/// image area), in percent.
fn against_supersampled(lod: &PlantLod, renderer: &mut Renderer) -> Result<Vec<(f64, f64, f64)>> {
    let billboard = lod
        .levels
        .iter()
        .position(|l| l.is_billboard)
        .context("no billboard level")?;
    let distance = switch_distance(lod.levels[billboard].error_world, &REFERENCE_VIEWPORT, 4.0)
        .max(4.0 * lod.radius as f64);
    let mut scenes = Vec::new();
    for level in [0, billboard] {
        let mut gpu = renderer.new_scene();
        let parts: Vec<&AssetPart> = lod.levels[level].parts.iter().collect();
        let textures = upload_textures(renderer, &mut gpu, &lod.textures, &parts);
        for part in &lod.levels[level].parts {
            let texture = *textures.get(part.texture).context("part without texture")?;
            let handle = renderer.add_mesh(&mut gpu, &part.mesh, texture, 1, part.alpha_test)?;
            renderer.set_shading(&gpu, handle, part.shading())?;
        }
        scenes.push(gpu);
    }
    let focal = REFERENCE_VIEWPORT.height_px / (2.0 * (0.5 * REFERENCE_VIEWPORT.fov_y_rad).tan());
    let centre = lod.center.cast::<f64>();
    let side = ((4.0 * lod.radius as f64 * focal / distance).ceil() as u32).clamp(16, 512);
    let scale = 8u32;
    let mut out = Vec::new();
    for elevation_deg in [5.0f64, 30.0, 60.0] {
        let (mut full, mut star, mut truth) = (0.0, 0.0, 0.0);
        for k in 0..8 {
            let azimuth = std::f64::consts::TAU * k as f64 / 8.0;
            let elevation = elevation_deg.to_radians();
            let eye = centre
                + Vector3::new(
                    azimuth.cos() * elevation.cos(),
                    azimuth.sin() * elevation.cos(),
                    elevation.sin(),
                ) * distance;
            let camera = |side: u32, focal: f64| ViewCamera {
                width: side,
                height: side,
                fx: focal,
                fy: focal,
                cx: 0.5 * side as f64,
                cy: 0.5 * side as f64,
                camera_from_world: look_at(eye, centre),
                near: 0.5 * distance,
                far: 2.0 * distance,
            };
            let lighting = Lighting::default();
            let small = camera(side, focal);
            let large = camera(side * scale, focal * scale as f64);
            full += light(&renderer.render(&scenes[0], &small, &lighting)?.color);
            star += light(&renderer.render(&scenes[1], &small, &lighting)?.color);
            truth += light(&renderer.render(&scenes[0], &large, &lighting)?.color)
                / (scale * scale) as f64;
        }
        out.push((
            elevation_deg,
            100.0 * (full / truth - 1.0),
            100.0 * (star / truth - 1.0),
        ));
    }
    Ok(out)
}
