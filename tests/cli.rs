//! The `frond` command line on the bundled fixture and on bad input.

use std::path::{Path, PathBuf};

use assert_cmd::Command;
use frond::scene::synthetic::{generate, toy_scene_spec};
use frond::scene::{ModelFormat, read_model};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

fn frond() -> Command {
    Command::cargo_bin("frond").expect("frond binary is built")
}

#[test]
fn bundled_fixture_is_what_the_generator_makes() {
    let (model, format) = read_model(&fixture("toy_scene/sparse/0")).unwrap();
    assert_eq!(format, ModelFormat::Binary);
    assert_eq!(model, generate(&toy_scene_spec()));
    // The text copy was written by real COLMAP (scripts/make_fixtures.sh).
    let (colmap_text, format) = read_model(&fixture("toy_scene_colmap_txt")).unwrap();
    assert_eq!(format, ModelFormat::Text);
    assert_eq!(colmap_text.points().len(), model.points().len());
    for point in model.points() {
        let other = colmap_text.point(point.id).unwrap();
        assert!((other.position_world - point.position_world).norm() < 1e-12);
    }
}

#[test]
fn info_reports_the_fixture_as_json() {
    let output = frond()
        .args(["info", "--json"])
        .arg(fixture("toy_scene"))
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let spec = toy_scene_spec();
    assert_eq!(json["images"]["registered"], spec.num_images);
    assert_eq!(json["images"]["files_present"], spec.num_images);
    assert_eq!(json["points"]["count"], spec.num_points);
    assert_eq!(json["camera_models"]["SIMPLE_RADIAL"], 1);
    let stored = json["reprojection"]["stored_mean_px"].as_f64().unwrap();
    let recomputed = json["reprojection"]["recomputed_mean_px"].as_f64().unwrap();
    assert!(
        (stored - recomputed).abs() < 1e-9,
        "{stored} vs {recomputed}"
    );
    assert_eq!(json["source"]["layout"], "project");
}

#[test]
fn info_text_output_names_the_essentials() {
    let output = frond()
        .arg("info")
        .arg(fixture("toy_scene"))
        .output()
        .unwrap();
    assert!(output.status.success());
    let text = String::from_utf8(output.stdout).unwrap();
    for needle in [
        "cameras:",
        "images:",
        "points:",
        "reprojection:",
        "bounds:",
        "SIMPLE_RADIAL",
    ] {
        assert!(text.contains(needle), "missing {needle} in\n{text}");
    }
}

#[test]
fn convert_round_trips_through_text() {
    let dir = tempfile::tempdir().unwrap();
    let text_dir = dir.path().join("txt");
    let bin_dir = dir.path().join("bin");
    frond()
        .args(["convert"])
        .arg(fixture("toy_scene"))
        .arg(&text_dir)
        .args(["--format", "txt"])
        .assert()
        .success();
    frond()
        .args(["convert"])
        .arg(&text_dir)
        .arg(&bin_dir)
        .args(["--format", "bin"])
        .assert()
        .success();
    let (original, _) = read_model(&fixture("toy_scene/sparse/0")).unwrap();
    let (text, _) = read_model(&text_dir).unwrap();
    let (binary, _) = read_model(&bin_dir).unwrap();
    assert_eq!(text, original);
    assert_eq!(binary, original);
    assert_eq!(
        std::fs::read(bin_dir.join("points3D.bin")).unwrap(),
        std::fs::read(fixture("toy_scene/sparse/0/points3D.bin")).unwrap()
    );
}

#[test]
fn bad_input_fails_with_a_message_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let output = frond().arg("info").arg(dir.path()).output().unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("no COLMAP model found"), "{stderr}");

    let model_dir = dir.path().join("m");
    std::fs::create_dir_all(&model_dir).unwrap();
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        std::fs::copy(fixture("toy_scene/sparse/0").join(f), model_dir.join(f)).unwrap();
    }
    let points = model_dir.join("points3D.bin");
    let bytes = std::fs::read(&points).unwrap();
    std::fs::write(&points, &bytes[..bytes.len() / 2]).unwrap();
    let output = frond().arg("info").arg(&model_dir).output().unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("points3D.bin: byte"), "{stderr}");
    assert!(stderr.contains("truncated"), "{stderr}");
}

/// Runs a command that must fail and returns its standard error.
fn failure_stderr(command: &mut Command) -> String {
    let assert = command.assert().failure();
    String::from_utf8_lossy(&assert.get_output().stderr).into_owned()
}

#[test]
fn photos_in_too_few_or_unreadable_fail_with_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for name in ["a.jpg", "b.jpg"] {
        std::fs::write(photos.join(name), b"not a photo").unwrap();
    }
    // `sfm` and `reconstruct` on a photos folder both refuse two photos, naming the folder.
    for subcommand in ["sfm", "reconstruct"] {
        let out = dir.path().join("out");
        let stderr = failure_stderr(frond().arg(subcommand).arg(&photos).arg("--out").arg(&out));
        assert!(stderr.contains("holds 2 photos"), "{stderr}");
        assert!(stderr.contains("photos"), "{stderr}");
        assert!(!out.join("sfm/sparse").exists());
    }
    // densify and eval --dense name what is wrong with their inputs.
    let dense = dir.path().join("dense");
    for (option, value, message) in [
        ("--max-image-size", "10", "--max-image-size"),
        ("--block-size", "4", "--block-size must be odd"),
    ] {
        let stderr = failure_stderr(
            frond()
                .args(["densify", option, value])
                .arg(fixture("toy_scene"))
                .arg("--out")
                .arg(&dense),
        );
        assert!(stderr.contains(message), "{stderr}");
        assert!(!dense.exists());
    }
    let stderr = failure_stderr(
        frond()
            .arg("eval")
            .arg("--gt")
            .arg(dir.path())
            .arg("--dense")
            .arg(fixture("toy_scene")),
    );
    assert!(stderr.contains("ground truth"), "{stderr}");
}
