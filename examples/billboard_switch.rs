//! Measurement aid: the billboard against the full plant at its switch distance (λ = 4 px)
//! on built-in synthetic plants, per view elevation: the light each sends to the eye (mean,
//! RMS and worst over 16 directions) and the coverage ratio.
//! Usage: `cargo run --release --example billboard_switch -- [PRESET:SEED ...]`
//! (default: broadleaf 4, 7, 11, 21, 31 and medium 3, 12, 22, 32).

use anyhow::{Context, Result, bail};
use frond::lod::asset::PlantAsset;
use frond::lod::billboard::BillboardOptions;
use frond::lod::chain::ChainOptions;
use frond::lod::plant::{PlantLodOptions, build_plant_lod, summarize_switch};
use frond::render::Renderer;
use frond::synth::{Preset, generate_plant, plant_model};

fn main() -> Result<()> {
    let mut plants: Vec<(Preset, u64)> = Vec::new();
    for arg in std::env::args().skip(1) {
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
    println!("plant          elevation  mean %  RMS %  worst %  coverage");
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
