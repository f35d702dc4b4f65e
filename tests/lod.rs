//! `frond lod`: a plant glb in, a glb with MSFT_lod out, accepted by the Khronos validator and
//! read back level by level.

mod common;

use assert_cmd::cargo::cargo_bin_cmd;
use frond::lod::plant::PlantLod;
use frond::synth::{Preset, generate_plant, plant_model};
use serde_json::Value;

#[test]
fn lod_writes_msft_lod_that_the_khronos_validator_accepts() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("plant.glb");
    let plant = generate_plant(Preset::Medium, 7);
    std::fs::write(&input, plant_model(&plant, 32).to_glb()).unwrap();
    let output = dir.path().join("plant_lod.glb");
    let run = cargo_bin_cmd!("frond")
        .arg("lod")
        .arg(&input)
        .arg("--out")
        .arg(&output)
        .args([
            "--ratios",
            "0.3,0.1,0.03",
            "--billboard-tile",
            "64",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).unwrap();
    let levels = report["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 5, "{report}");
    assert_eq!(levels[4]["is_billboard"], true);
    assert_eq!(levels[4]["triangles"], 12);
    // The billboard's brightness where it takes over is measured from 16 directions at two
    // elevations.
    let summary = report["billboard_switch_summary"].as_array().unwrap();
    assert_eq!(summary.len(), 2, "{report}");
    for s in summary {
        assert_eq!(s["directions"], 16);
        assert!(s["rms_percent"].as_f64().unwrap().is_finite());
    }

    let (valid, text) = common::run_checker("node", "scripts/validate_gltf.js", &output);
    assert!(valid && text.contains(": 0 errors"), "validator: {text}");

    let lod = PlantLod::read_glb(&output, 200).unwrap();
    assert_eq!(lod.levels.len(), 5);
    for (level, stated) in lod.levels.iter().zip(levels) {
        assert_eq!(
            level.triangles as u64,
            stated["triangles"].as_u64().unwrap()
        );
        assert!((level.error_world - stated["error_m"].as_f64().unwrap()).abs() < 1e-9);
    }
    // Each simplified level keeps at most about its share of the full model's triangles.
    let full = lod.levels[0].triangles as f64;
    for (level, ratio) in lod.levels[1..4].iter().zip([0.3, 0.1, 0.03]) {
        assert!(level.triangles as f64 <= ratio * full * 1.05 + 8.0);
    }
}

#[test]
fn lod_names_the_file_it_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("not_a_plant.glb");
    std::fs::write(&input, b"glTF but not really").unwrap();
    let run = cargo_bin_cmd!("frond")
        .arg("lod")
        .arg(&input)
        .arg("--out")
        .arg(dir.path().join("out.glb"))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("not_a_plant.glb"), "{stderr}");
    assert!(!dir.path().join("out.glb").exists());
}
