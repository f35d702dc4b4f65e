//! Measurement aid: the billboard against the full plant at its switch distance (λ = 4 px)
//! on built-in synthetic plants, per view elevation: the light each sends to the eye (mean,
//! RMS and worst over 16 directions) and the coverage ratio.
//! With `--reference`, each of the two is instead compared with the same view rendered 8×
//! larger and averaged down in linear light (the plant as a well filtered image would show it),
//! over 8 directions: which of the two is wrong where they differ.
//! Usage: `cargo run --release --example billboard_switch -- [--reference] [PRESET:SEED ...]`
//! (default: broadleaf 4, 7, 11, 21, 31 and medium 3, 12, 22, 32).

use anyhow::{Context, Result, bail};
use frond::lod::asset::PlantAsset;
use frond::lod::billboard::BillboardOptions;
use frond::lod::chain::ChainOptions;
use frond::lod::plant::{PlantLod, PlantLodOptions, build_plant_lod, summarize_switch};
use frond::render::Renderer;
use frond::synth::{Preset, generate_plant, plant_model};

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

/// Per elevation (5°, 30°, 60°; 8 directions each), the full plant's and the billboard's light
/// at the billboard's switch distance against the full plant rendered 8× larger, in percent.
fn against_supersampled(lod: &PlantLod, renderer: &mut Renderer) -> Result<Vec<(f64, f64, f64)>> {
    let elevations = [5.0, 30.0, 60.0];
    let checks = lod
        .switch_against_supersampled(renderer, 4.0, 8, &elevations, 8)?
        .context("no billboard level")?;
    Ok(elevations
        .iter()
        .map(|&elevation| {
            let at = checks.iter().filter(|c| c.elevation_deg == elevation);
            let (truth, full, billboard) = at.fold((0.0, 0.0, 0.0), |(t, f, b), c| {
                (t + c.truth, f + c.full, b + c.billboard)
            });
            (
                elevation,
                100.0 * (full / truth - 1.0),
                100.0 * (billboard / truth - 1.0),
            )
        })
        .collect())
}
