//! Tuning aid: the sharpness of every photo of a folder relative to the folder's median (the
//! blur check of `frond sfm`), lowest first.
//! Usage: cargo run --release --example photo_sharpness -- PHOTOS_DIR

fn main() -> anyhow::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: photo_sharpness PHOTOS_DIR"))?;
    let photos = frond::sfm::list_photos(std::path::Path::new(&dir))?;
    let mut values = Vec::new();
    for path in &photos {
        let image = image::open(path)?;
        values.push((
            path.display().to_string(),
            frond::sfm::photos::sharpness(&image),
        ));
    }
    let mut sorted: Vec<f64> = values.iter().map(|(_, v)| *v).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    values.sort_by(|a, b| a.1.total_cmp(&b.1));
    for (name, v) in values.iter().take(5) {
        println!("{:.3} {name}", v / median);
    }
    println!(
        "{} photos; lowest {:.3}, highest {:.3} of the median; blurred below {}",
        values.len(),
        sorted[0] / median,
        sorted[sorted.len() - 1] / median,
        frond::sfm::photos::BLUR_FRACTION
    );
    Ok(())
}
