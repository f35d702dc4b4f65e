//! Writes the colour-gradient image of one view as an 8-bit PNG (scaled so that 3σ is white),
//! to look at what the 2D term of the segmentation sees.
//! Usage: `cargo run --example dump_gradient -- DATASET VIEW_INDEX OUT.png`.

use anyhow::{Context, Result};
use frond::graph::gradient::GradientImage;
use frond::scene::Scene;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::open(std::path::Path::new(args.get(1).context("dataset")?))?;
    let index: usize = args.get(2).context("view index")?.parse()?;
    let image = scene
        .reconstruction
        .images()
        .get(index)
        .context("no such view")?;
    let gradient = GradientImage::for_image(&scene, image)?;
    let rms = (gradient
        .data
        .iter()
        .map(|g| (*g as f64).powi(2))
        .sum::<f64>()
        / gradient.data.len() as f64)
        .sqrt();
    let out = image::GrayImage::from_fn(gradient.width, gradient.height, |x, y| {
        let g = gradient.data[(y * gradient.width + x) as usize] as f64;
        image::Luma([(255.0 * g / (3.0 * rms)).min(255.0) as u8])
    });
    out.save(args.get(3).context("output")?)?;
    println!("rms gradient {rms:.2}");
    Ok(())
}
