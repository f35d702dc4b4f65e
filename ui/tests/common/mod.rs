//! Shared by the GUI's test binaries.

use std::path::{Path, PathBuf};

use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

/// Writes a small synthetic broadleaf plant with its photos (8 views of 480×360, 12,000
/// points) into `dir`/plant.
pub fn write_synthetic_plant(dir: &Path) -> PathBuf {
    let root = dir.join("plant");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 43,
        views: 8,
        width: 480,
        height: 360,
        target_points: 12_000,
        ..SynthOptions::default()
    };
    write_dataset(&options, &root, &NoProgress).unwrap();
    root
}
