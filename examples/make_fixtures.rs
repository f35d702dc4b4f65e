//! Regenerates `fixtures/toy_scene`: a small COLMAP project (binary `sparse/0` + rendered
//! `images/`) made by Frond's synthetic model generator. Run via `scripts/make_fixtures.sh`,
//! which also has real COLMAP convert it to text (`fixtures/toy_scene_colmap_txt`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use frond::scene::synthetic::{generate, render_point_splats, toy_scene_spec};
use frond::scene::{ModelFormat, write_model};

fn main() -> Result<()> {
    let root = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fixtures/toy_scene".into()),
    );
    let model = generate(&toy_scene_spec());
    write_model(&root.join("sparse/0"), &model, ModelFormat::Binary)
        .with_context(|| format!("writing {}", root.display()))?;
    render_point_splats(&model, &root.join("images"))
        .with_context(|| format!("rendering images into {}", root.display()))?;
    println!(
        "wrote {} ({} images, {} points)",
        root.display(),
        model.images().len(),
        model.points().len()
    );
    Ok(())
}
