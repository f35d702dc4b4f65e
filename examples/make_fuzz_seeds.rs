//! Writes valid COLMAP files (every kind, both formats) as seed corpora for `scripts/fuzz.sh`.
//! Each seed's first byte selects the parser, as in `fuzz/fuzz_targets/*.rs`.

use std::path::PathBuf;

use anyhow::Result;
use frond::scene::synthetic::{SyntheticModelSpec, generate};
use frond::scene::{CameraModelKind, io_binary, io_text};

fn main() -> Result<()> {
    let root = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fuzz/corpus".into()),
    );
    let binary_dir = root.join("colmap_binary");
    let text_dir = root.join("colmap_text");
    std::fs::create_dir_all(&binary_dir)?;
    std::fs::create_dir_all(&text_dir)?;
    for (i, kind) in CameraModelKind::ALL.iter().enumerate() {
        let model = generate(&SyntheticModelSpec {
            num_points: 12,
            num_images: 3,
            unmatched_keypoints_per_image: 2,
            camera_model: *kind,
            rig_pairs: i % 3 == 0,
            seed: i as u64,
            ..Default::default()
        });
        let binary = [
            io_binary::encode_cameras(model.cameras()),
            io_binary::encode_images(model.images()),
            io_binary::encode_points(model.points()),
            io_binary::encode_rigs(model.rigs()),
            io_binary::encode_frames(model.frames()),
        ];
        for (selector, bytes) in binary.iter().enumerate() {
            let mut seed = vec![selector as u8];
            seed.extend_from_slice(bytes);
            std::fs::write(binary_dir.join(format!("seed_{i}_{selector}")), seed)?;
        }
        let text = [
            io_text::encode_cameras(model.cameras()),
            io_text::encode_images(model.images()),
            io_text::encode_points(model.points()),
            io_text::encode_rigs(model.rigs()),
            io_text::encode_frames(model.frames()),
        ];
        for (selector, content) in text.iter().enumerate() {
            let mut seed = vec![selector as u8];
            seed.extend_from_slice(content.as_bytes());
            std::fs::write(text_dir.join(format!("seed_{i}_{selector}")), seed)?;
        }
    }
    println!("wrote seeds to {}", root.display());
    Ok(())
}
