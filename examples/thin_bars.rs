//! Tuning aid: draws the centreline pixels the thin-organ sweep starts from in one photo
//! (red over the darkened photo). Usage: `cargo run --release --example thin_bars -- IN.png OUT.png`.
use anyhow::{Context, Result};
use frond::mvs::ThinOptions;
use frond::mvs::thin::centreline_pixels;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let input = args.get(1).context("usage: IN.png OUT.png")?;
    let output = args.get(2).context("usage: IN.png OUT.png")?;
    let image = image::open(input)?.to_rgb8();
    let (w, h) = (image.width() as usize, image.height() as usize);
    let rgb: Vec<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    let line = centreline_pixels(&rgb, w, h, &ThinOptions::default());
    let mut out = image.clone();
    for p in out.pixels_mut() {
        p.0 = p.0.map(|c| c / 3);
    }
    for k in &line {
        out.put_pixel((k % w) as u32, (k / w) as u32, image::Rgb([255, 0, 0]));
    }
    out.save(output)?;
    println!(
        "{} centreline pixels ({:.1} % of the image)",
        line.len(),
        100.0 * line.len() as f64 / (w * h) as f64
    );
    Ok(())
}
