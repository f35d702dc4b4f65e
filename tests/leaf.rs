//! Leaf reconstruction (and the automatic skeleton) end to end through the CLI on a small
//! synthetic plant: `frond reconstruct` then `frond eval`; the exported glb passes the Khronos glTF validator and
//! opens in a Python glTF reader; missing photos and broken files make notes or clear errors,
//! never a crash.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use assert_cmd::cargo::cargo_bin_cmd;
use frond::synth::{Preset, SynthOptions};
use serde_json::Value;
use tempfile::TempDir;

/// One small broadleaf dataset (a seed not used for tuning) shared by the tests of this file.
fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Broadleaf,
            seed: 11,
            views: 16,
            width: 480,
            height: 360,
            target_points: 30_000,
            ..SynthOptions::default()
        },
    )
}

/// `frond reconstruct` of the shared dataset, once.
fn reconstruction() -> &'static Path {
    static DIR: OnceLock<TempDir> = OnceLock::new();
    common::reconstruction(&DIR, dataset())
}

/// `frond reconstruct INPUT --out OUT`, which must succeed; its report.
fn reconstruct_into(input: &Path, out: &Path) -> Value {
    cargo_bin_cmd!("frond")
        .arg("reconstruct")
        .arg(input)
        .arg("--out")
        .arg(out)
        .assert()
        .success();
    read_json(&out.join("report.json"))
}

/// `frond eval --json [EXTRA] --gt DATASET --pred OUT` on the shared dataset, which must
/// succeed; its report.
fn eval_json(out: &Path, extra: &[&str]) -> Value {
    let output = cargo_bin_cmd!("frond")
        .args(["eval", "--json"])
        .args(extra)
        .arg("--gt")
        .arg(dataset())
        .arg("--pred")
        .arg(out)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn reconstruct_writes_every_output_and_a_report() {
    let out = reconstruction();
    for file in [
        "plant.glb",
        "plant.obj",
        "plant.mtl",
        "plant_atlas_0.png",
        "segmentation.ply",
        "segments.json",
        "skeleton.json",
        "report.json",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let report = read_json(&out.join("report.json"));
    let counts = &report["counts"];
    let fitted = counts["leaves_fitted"].as_u64().unwrap();
    assert!(fitted >= 8, "{counts}");
    // The glb read back (by the gltf crate) holds a leaf node with a mesh for every fitted
    // leaf the report lists, and one per posed leaf besides.
    let glb = std::fs::read(out.join("plant.glb")).unwrap();
    let nodes = frond::model::gltf::read_glb_meshes(&glb, &out.join("plant.glb")).unwrap();
    let leaf_nodes: std::collections::BTreeMap<String, usize> = nodes
        .iter()
        .filter(|n| n.name.starts_with("leaf_"))
        .map(|n| (n.name.clone(), n.mesh.triangles.len()))
        .collect();
    for leaf in report["leaves"].as_array().unwrap() {
        let name = format!("leaf_{:03}", leaf["segment"].as_u64().unwrap());
        assert!(
            leaf_nodes.get(&name).is_some_and(|&t| t > 0),
            "{name} not in the glb"
        );
    }
    assert_eq!(
        leaf_nodes.len() as u64,
        fitted + counts["leaves_posed"].as_u64().unwrap(),
        "{counts}"
    );
    assert!(report["timings"]["total"].as_f64().unwrap() > 0.0);
    assert!(report["timings"]["leaves"]["fitting"].as_f64().unwrap() > 0.0);
    assert!(report["segmentation"]["timings"]["total"].as_f64().unwrap() > 0.0);
    assert!(report["unusable_views"].as_array().unwrap().is_empty());
    assert!(report["parameters"]["leaves"]["fit"]["icp_tolerance"].is_number());
    // Every fitted leaf either touches a branch or gets a petiole to one.
    assert_eq!(
        counts["petioles"].as_u64().unwrap() + counts["leaves_touching_branches"].as_u64().unwrap(),
        fitted,
        "{counts}"
    );
    // Each drawn petiole says how much of it the points show and how much is a guess, and
    // the report sums them.
    let (mut observed, mut bridged) = (0.0, 0.0);
    for petiole in report["attachment"]["petioles"].as_array().unwrap() {
        let length = petiole["length"].as_f64().unwrap();
        assert!(length > 0.0, "{petiole}");
        let seen = petiole["observed_length"].as_f64().unwrap();
        let guessed = petiole["bridged_length"].as_f64().unwrap();
        assert!(seen >= 0.0 && guessed >= 0.0, "{petiole}");
        assert!(
            ((seen + guessed) - length).abs() <= 0.01 * length,
            "{petiole}"
        );
        observed += seen;
        bridged += guessed;
    }
    let support = &report["petiole_support"];
    assert!((support["observed_length"].as_f64().unwrap() - observed).abs() < 1e-9);
    assert!((support["bridged_length"].as_f64().unwrap() - bridged).abs() < 1e-9);
    // The OBJ's faces index existing vertices and use the atlas material.
    let obj = std::fs::read_to_string(out.join("plant.obj")).unwrap();
    let vertices = obj.lines().filter(|l| l.starts_with("v ")).count();
    let max_index = obj
        .lines()
        .filter(|l| l.starts_with("f "))
        .flat_map(|l| l.split_whitespace().skip(1))
        .map(|corner| corner.split('/').next().unwrap().parse::<usize>().unwrap())
        .max()
        .unwrap();
    assert!(max_index <= vertices);
    assert!(obj.contains("usemtl leaf_atlas_0"));
}

#[test]
fn reconstructed_leaves_meet_the_accuracy_targets() {
    let out = reconstruction();
    let eval = eval_json(out, &[]);
    // The automatic skeleton follows the stem and finds the petioles.
    let skeleton = &eval["skeleton"];
    eprintln!("skeleton: {skeleton}");
    // The model's structure is scored too: the skeleton and the petioles drawn to it.
    let whole = &skeleton["with_drawn_petioles"];
    assert!(
        whole["predicted_length"].as_f64().unwrap()
            >= skeleton["length"]["predicted_length"].as_f64().unwrap(),
        "{skeleton}"
    );
    assert!(
        skeleton["stem_distance_in_radii"].as_f64().unwrap() <= 1.0,
        "{skeleton}"
    );
    // Regression floor: on this sparse 16-view dataset the skeleton finds 9 of 10 petioles
    // (0.9). The ≥ 0.8 target is measured on full-size broadleaf datasets (issue 7, still
    // open: 0.78–1.0 over ten seeds, mean 0.89).
    assert!(
        skeleton["branch_recall"].as_f64().unwrap() >= 0.8,
        "{skeleton}"
    );
    stem_ends_at_its_crown(out);
    let recall = eval["leaves"]["recall"].as_f64().unwrap();
    let chamfer = eval["chamfer_relative"]["median"].as_f64().unwrap();
    let area = eval["area_relative_error"]["median"].as_f64().unwrap();
    eprintln!("recall {recall:.3}, median Chamfer {chamfer:.4}, median area error {area:.3}");
    assert!(recall >= 0.9, "recall {recall}");
    // The broadleaf targets: median Chamfer ≤ 2 % of leaf length, area error ≤ 10 %.
    assert!(chamfer <= 0.02, "median Chamfer {chamfer}");
    assert!(area <= 0.10, "median area error {area}");
}

/// The 6 cm stem (radius 14 mm) under the plant's crown of 13–30 cm petioles is measured as
/// the stem: the main axis ends where the crown thins it and the petiole it ran on into is a
/// branch of its own (`branch::skeleton::stem_top`). Measured on this dataset: before, the
/// main axis (stem and petiole, 0.3 m) matched no true branch's length; now the true stem is
/// matched, 66 % long (83 mm for the 50 mm from the soil to the crown: it ends 17 mm up in the
/// crown's knot and wanders on the way). Until the truth was measured from the soil surface
/// (stop 74) its stem counted the 10 mm the generator buries, and this read 38 %; the bound
/// still tells a stem ending in the crown from one running on up a petiole (0.3 m, six times
/// the true stem).
fn stem_ends_at_its_crown(out: &Path) {
    let traits = eval_json(out, &["--traits"]);
    let stem = traits["branches"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["gt_branch"] == 0)
        .unwrap_or_else(|| panic!("the true stem is matched by no branch: {traits}"));
    let error = stem["length_relative_error"].as_f64().unwrap();
    assert!(error <= 0.75, "stem length error {error}: {stem}");
}

#[test]
fn exported_glb_passes_the_khronos_validator_and_a_python_reader() {
    let glb = reconstruction().join("plant.glb");
    let (valid, text) = common::run_checker("node", "scripts/validate_gltf.js", &glb);
    assert!(valid, "validator: {text}");
    assert!(text.contains(": 0 errors"), "{text}");
    let (read, text) = common::run_checker("python3", "scripts/read_gltf.py", &glb);
    assert!(read, "reader: {text}");
    let summary: Value = serde_json::from_str(text.trim()).unwrap();
    let nodes: Vec<&str> = summary["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert!(nodes.iter().any(|n| n.starts_with("leaf_")));
    // The skeleton's branches and the petioles.
    let report = read_json(&reconstruction().join("report.json"));
    let branches = report["counts"]["branches"].as_u64().unwrap()
        + report["counts"]["petioles"].as_u64().unwrap();
    assert_eq!(
        nodes.iter().filter(|n| n.starts_with("branch_")).count() as u64,
        branches
    );
    assert!(
        nodes
            .iter()
            .all(|n| n.starts_with("leaf_") || n.starts_with("branch_"))
    );
    assert!(summary["images"].as_u64().unwrap() >= 1);
    assert!(summary["triangles"].as_u64().unwrap() > 100);
}

#[test]
fn the_checkers_catch_a_broken_glb() {
    let glb = std::fs::read(reconstruction().join("plant.glb")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Point the first index accessor's count far past its buffer view.
    let json_length = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let mut json: Value = serde_json::from_slice(&glb[20..20 + json_length]).unwrap();
    let index = json["meshes"][0]["primitives"][0]["indices"]
        .as_u64()
        .unwrap() as usize;
    json["accessors"][index]["count"] = Value::from(3_000_000u64);
    let mut text = serde_json::to_vec(&json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let mut broken = glb[..12].to_vec();
    broken.extend_from_slice(&(text.len() as u32).to_le_bytes());
    broken.extend_from_slice(&glb[16..20]);
    broken.extend_from_slice(&text);
    broken.extend_from_slice(&glb[20 + json_length..]);
    let total = broken.len() as u32;
    broken[8..12].copy_from_slice(&total.to_le_bytes());
    let path = dir.path().join("broken.glb");
    std::fs::write(&path, broken).unwrap();
    let (valid, text) = common::run_checker("node", "scripts/validate_gltf.js", &path);
    assert!(!valid, "the validator accepted a broken file: {text}");
    let (read, text) = common::run_checker("python3", "scripts/read_gltf.py", &path);
    assert!(!read, "the reader accepted a broken file: {text}");
}

#[test]
fn missing_photos_are_reported_not_fatal() {
    // A copy of the dataset with a third of the photos gone.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("plant");
    copy_dir(dataset(), &copy);
    let mut photos: Vec<PathBuf> = std::fs::read_dir(copy.join("images"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    photos.sort();
    for photo in photos.iter().step_by(3) {
        std::fs::remove_file(photo).unwrap();
    }
    let out = dir.path().join("out");
    let report = reconstruct_into(&copy, &out);
    assert!(report["counts"]["leaves_fitted"].as_u64().unwrap() >= 5);
    let with_images = report["segmentation"]["views_with_images"]
        .as_u64()
        .unwrap();
    assert_eq!(with_images, 16 - 6, "{}", report["segmentation"]);
    // The leaf stage names the views it could not use (those among its candidates).
    for unusable in report["unusable_views"].as_array().unwrap() {
        assert!(
            unusable["reason"].as_str().unwrap().contains("Missing"),
            "{unusable}"
        );
    }
    assert!(!report["unusable_views"].as_array().unwrap().is_empty());
    // Every chosen boundary view has its photo.
    for leaf in report["leaves"].as_array().unwrap() {
        if let Some(image_id) = leaf["image_id"].as_u64() {
            let name = format!("view_{:04}.png", image_id - 1);
            assert!(copy.join("images").join(&name).is_file(), "{name} chosen");
        }
    }
    let (valid, text) =
        common::run_checker("node", "scripts/validate_gltf.js", &out.join("plant.glb"));
    assert!(valid, "{text}");
}

#[test]
fn no_photos_at_all_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("plant");
    copy_dir(dataset(), &copy);
    std::fs::remove_dir_all(copy.join("images")).unwrap();
    let output = cargo_bin_cmd!("frond")
        .arg("reconstruct")
        .arg(&copy)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("image"), "{stderr}");
    assert!(!dir.path().join("out/plant.glb").exists());
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn the_user_picks_the_generic_leaf() {
    let report = read_json(&reconstruction().join("report.json"));
    let automatic = report["template"]["segment"].as_u64().unwrap();
    // Another fitted leaf, with its boundary view, then without a view.
    let other = report["leaves"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["segment"].as_u64() != Some(automatic) && l["image_id"].is_u64())
        .unwrap();
    let segment = other["segment"].as_u64().unwrap();
    let image_id = other["image_id"].as_u64().unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (pick, expected_image) in [
        (format!("{segment}:{image_id}"), Some(image_id)),
        (format!("{segment}"), None),
    ] {
        let out = dir.path().join(pick.replace(':', "_"));
        cargo_bin_cmd!("frond")
            .arg("reconstruct")
            .arg(dataset())
            .args(["--template", &pick, "--out"])
            .arg(&out)
            .assert()
            .success();
        let picked = read_json(&out.join("report.json"));
        assert_eq!(picked["template"]["segment"].as_u64(), Some(segment));
        if let Some(image) = expected_image {
            assert_eq!(picked["template"]["image_id"].as_u64(), Some(image));
        }
        assert!(picked["counts"]["leaves_fitted"].as_u64().unwrap() >= 8);
    }
    // Picks that name nothing are refused with the reason.
    for (pick, message) in [
        ("9999", "no such segment"),
        (
            &format!("{segment}:9999") as &str,
            "no registered image has id 9999",
        ),
        ("leaf", "not a non-negative integer"),
    ] {
        let output = cargo_bin_cmd!("frond")
            .arg("reconstruct")
            .arg(dataset())
            .args(["--template", pick, "--out"])
            .arg(dir.path().join("bad"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success());
        assert!(stderr.contains(message), "{pick}: {stderr}");
    }
}

/// The README's "Reconstruction output" section (up to the next top-level bullet).
fn readme_output_section() -> String {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let start = readme
        .find("- **Reconstruction output**")
        .expect("README has a Reconstruction output section");
    let rest = &readme[start..];
    let end = rest[2..].find("\n- **").map_or(rest.len(), |e| e + 2);
    rest[..end].to_owned()
}

/// Keys of a JSON object (and of the first element of the arrays named in `nested`).
fn keys(value: &Value, nested: &[&str]) -> Vec<String> {
    let object = value.as_object().unwrap();
    let mut keys: Vec<String> = object.keys().cloned().collect();
    for name in nested {
        if let Some(first) = object[*name].as_array().and_then(|a| a.first()) {
            keys.extend(first.as_object().unwrap().keys().cloned());
        }
    }
    keys
}

/// `segmentation.ply`'s `segment_id` names every point's segment: its points per segment are
/// the `points` of that segment in `segments.json`, and a point has a `leaf_id` exactly when
/// its segment is labelled leaf there, the same id.
#[test]
fn the_segment_of_every_point_agrees_with_segments_json() {
    let out = reconstruction();
    let ply = frond::scene::ply::read_ply(&out.join("segmentation.ply")).unwrap();
    let vertex = ply.element("vertex").unwrap();
    let leaf_ids = &vertex.column("leaf_id").unwrap().values;
    let segment_ids = &vertex.column("segment_id").unwrap().values;
    let segments = read_json(&out.join("segments.json"));
    let mut count_of: std::collections::BTreeMap<i64, u64> = Default::default();
    for &s in segment_ids {
        *count_of.entry(s as i64).or_default() += 1;
    }
    let records = segments["segments"].as_array().unwrap();
    let labels: std::collections::BTreeMap<i64, &str> = records
        .iter()
        .map(|r| (r["id"].as_i64().unwrap(), r["label"].as_str().unwrap()))
        .collect();
    for record in records {
        let id = record["id"].as_i64().unwrap();
        assert_eq!(
            count_of.get(&id).copied().unwrap_or(0),
            record["points"].as_u64().unwrap(),
            "segment {id}"
        );
    }
    assert!(labels.values().any(|l| *l != "leaf"), "{labels:?}");
    for (&leaf, &segment) in leaf_ids.iter().zip(segment_ids) {
        let label = labels.get(&(segment as i64)).copied();
        if label == Some("leaf") {
            assert_eq!(leaf, segment);
        } else {
            assert_eq!(leaf, -1.0, "segment {segment} ({label:?})");
        }
    }
}

#[test]
fn the_readme_names_every_field_the_outputs_hold() {
    let out = reconstruction();
    let section = readme_output_section();
    let mut missing = Vec::new();
    let mut check = |file: &str, names: Vec<String>| {
        for name in names {
            if !section.contains(&format!("`{name}`")) {
                missing.push(format!("{file}: {name}"));
            }
        }
    };
    let segments = read_json(&out.join("segments.json"));
    check("segments.json", keys(&segments, &["segments"]));
    check("segments.json edits", keys(&segments["edits"], &[]));
    let skeleton = read_json(&out.join("skeleton.json"));
    check("skeleton.json", keys(&skeleton, &["branches"]));
    let report = read_json(&out.join("report.json"));
    check("report.json", keys(&report, &[]));
    check("report.json preparation", keys(&report["preparation"], &[]));
    let ply = frond::scene::ply::read_ply(&out.join("segmentation.ply")).unwrap();
    let columns: Vec<String> = ply
        .element("vertex")
        .unwrap()
        .columns
        .iter()
        .map(|c| c.name.clone())
        .collect();
    check("segmentation.ply", columns);
    assert!(missing.is_empty(), "the README does not name: {missing:#?}");
    // And the versions it states are the ones written.
    assert!(section.contains(&format!(
        "`format` \"frond segments\", `version` {}",
        segments["version"]
    )));
    assert!(section.contains(&format!(
        "`format` \"frond skeleton\", `version` {}",
        skeleton["version"]
    )));
    assert!(section.contains(&format!(
        "`format` \"frond report\", `version` {}",
        report["version"]
    )));
}

#[test]
fn every_output_file_reads_back_through_its_one_reader_type() {
    let out = reconstruction();
    // Each typed reader sees every field the writer wrote: written again, it is the file.
    let report = frond::pipeline::ReconstructionReport::read(&out.join("report.json")).unwrap();
    assert_eq!(
        serde_json::to_value(&report).unwrap(),
        read_json(&out.join("report.json"))
    );
    let segments = frond::pipeline::SegmentsFile::read(&out.join("segments.json")).unwrap();
    assert_eq!(
        serde_json::to_value(&segments).unwrap(),
        read_json(&out.join("segments.json"))
    );
    let skeleton = frond::branch::plant::SkeletonFile::read(&out.join("skeleton.json")).unwrap();
    assert_eq!(
        serde_json::to_value(&skeleton).unwrap(),
        read_json(&out.join("skeleton.json"))
    );
    // A file of another kind is refused with its path.
    let error = frond::pipeline::ReconstructionReport::read(&out.join("segments.json"))
        .unwrap_err()
        .to_string();
    assert!(error.contains("segments.json"), "{error}");
}

/// `frond reconstruct` ends with the plant's traits in model units; `frond traits` with a
/// scale rewrites them in metres; `frond eval --traits` compares them with the truth's.
#[test]
fn reconstruct_writes_traits_and_traits_follow_the_scale() {
    let out = reconstruction();
    let table = read_json(&out.join("traits.json"));
    assert_eq!(table["format"], "frond traits");
    assert!(table["scale"].is_null());
    let csv = std::fs::read_to_string(out.join("traits.csv")).unwrap();
    assert!(csv.starts_with("plant,organ_id,organ_type,trait,value,unit\n"));
    let value = |text: &str, organ: &str, name: &str| -> (f64, String) {
        let line = text
            .lines()
            .find(|l| {
                let f: Vec<&str> = l.split(',').collect();
                f.len() == 6 && f[1] == organ && f[3] == name
            })
            .unwrap_or_else(|| panic!("no {organ} {name}"));
        let f: Vec<&str> = line.split(',').collect();
        (f[4].parse().unwrap(), f[5].to_owned())
    };
    let (area, unit) = value(&csv, "plant", "total_leaf_area");
    assert_eq!(unit, "model units^2");
    let (count, _) = value(&csv, "plant", "leaf_count");
    let report = read_json(&out.join("report.json"));
    assert!(count >= report["counts"]["leaves_fitted"].as_f64().unwrap());

    let scaled = tempfile::tempdir().unwrap();
    cargo_bin_cmd!("frond")
        .args([
            "traits",
            "--scale",
            "0.5",
            "--plant",
            "pot 7, left",
            "--out",
        ])
        .arg(scaled.path())
        .arg(out)
        .assert()
        .success();
    let scaled_csv = std::fs::read_to_string(scaled.path().join("traits.csv")).unwrap();
    // The plant id with a comma is quoted; values are scaled by 0.5 (lengths) and 0.25 (areas).
    assert!(
        scaled_csv
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("\"pot 7, left\",")
    );
    let scaled_value = |organ: &str, name: &str| -> (f64, String) {
        let line = scaled_csv
            .lines()
            .find(|l| l.contains(&format!(",{organ},")) && l.contains(&format!(",{name},")))
            .unwrap();
        let f: Vec<&str> = line.rsplitn(3, ',').collect();
        (f[1].parse().unwrap(), f[0].to_owned())
    };
    let (metric_area, unit) = scaled_value("plant", "total_leaf_area");
    assert_eq!(unit, "m2");
    assert!((metric_area - 0.25 * area).abs() <= 1e-9 * area.max(1.0));
    let (height, _) = value(&csv, "plant", "height");
    let (metric_height, unit) = scaled_value("plant", "height");
    assert_eq!(unit, "m");
    assert!((metric_height - 0.5 * height).abs() <= 1e-9);
    let bad = cargo_bin_cmd!("frond")
        .args(["traits", "--scale-from", "0,0,0:1,1"])
        .arg(out)
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("expected X1,Y1,Z1:X2,Y2,Z2:METRES"));

    // Against the truth: the synthetic world is metric, so model units are metres here.
    let accuracy = eval_json(out, &["--traits"]);
    eprintln!(
        "{}",
        serde_json::to_string(&accuracy["leaf_area_relative_error"]).unwrap()
    );
    let median = |key: &str| accuracy[key]["median"].as_f64().unwrap();
    assert!(
        accuracy["leaves"].as_array().unwrap().len() >= 8,
        "{accuracy}"
    );
    assert!(median("leaf_area_relative_error") <= 0.05, "{accuracy}");
    assert!(median("leaf_inclination_error_deg") <= 5.0, "{accuracy}");
    assert!(median("leaf_length_relative_error") <= 0.05, "{accuracy}");
}

/// `frond phyllotaxis`: the truth's organ sequence along its main stem, written as measures
/// (radians and millimetres, ROMI's measures.json), aligned with the reconstruction's.
#[test]
fn the_stem_sequence_is_aligned_with_the_truths() {
    let out = reconstruction();
    let truth = cargo_bin_cmd!("frond")
        .args(["phyllotaxis", "--truth", "--json"])
        .arg(dataset())
        .output()
        .unwrap();
    assert!(truth.status.success(), "{truth:?}");
    let truth: Value = serde_json::from_slice(&truth.stdout).unwrap();
    let sequence = &truth["sequence"];
    let numbers = |key: &str, factor: f64| -> Vec<f64> {
        sequence[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() * factor)
            .collect()
    };
    let angles = numbers("angles_deg", std::f64::consts::PI / 180.0);
    let internodes = numbers("internodes", 1000.0);
    let organs = sequence["organs"].as_array().unwrap().len();
    assert_eq!(angles.len() + 1, organs);
    assert!(organs >= 3, "{sequence}");
    // The truth's leaves hang from their petioles, none from the stem: its branches alone make
    // the same sequence, and its leaves none.
    let branches = cargo_bin_cmd!("frond")
        .args(["phyllotaxis", "--truth", "--json", "--organs", "branches"])
        .arg(dataset())
        .output()
        .unwrap();
    assert!(branches.status.success(), "{branches:?}");
    let branches: Value = serde_json::from_slice(&branches.stdout).unwrap();
    assert_eq!(branches["organs"], "branches");
    assert_eq!(&branches["sequence"], sequence);
    let leaves = cargo_bin_cmd!("frond")
        .args(["phyllotaxis", "--truth", "--organs", "leaves"])
        .arg(dataset())
        .output()
        .unwrap();
    let message = String::from_utf8_lossy(&leaves.stderr);
    assert!(
        !leaves.status.success() && message.contains("of the kind asked for"),
        "{message}"
    );
    let dir = tempfile::tempdir().unwrap();
    let measures = dir.path().join("measures.json");
    std::fs::write(
        &measures,
        serde_json::json!({"angles": angles, "internodes": internodes}).to_string(),
    )
    .unwrap();
    // Millimetres need a scale.
    let unscaled = cargo_bin_cmd!("frond")
        .arg("phyllotaxis")
        .arg(out)
        .arg("--measures")
        .arg(&measures)
        .output()
        .unwrap();
    let message = String::from_utf8_lossy(&unscaled.stderr);
    assert!(
        !unscaled.status.success() && message.contains("give a scale"),
        "{message}"
    );
    // The semi-dense scene is the truth's metric world.
    let compared = cargo_bin_cmd!("frond")
        .arg("phyllotaxis")
        .arg(out)
        .arg("--measures")
        .arg(&measures)
        .args(["--scale", "1", "--json"])
        .output()
        .unwrap();
    assert!(compared.status.success(), "{compared:?}");
    let compared: Value = serde_json::from_slice(&compared.stdout).unwrap();
    let comparison = &compared["comparison"];
    eprintln!(
        "organs {} predicted / {} measured; paired medians {} mm, {} deg; matched share {}",
        comparison["organs_predicted"],
        comparison["organs_measured"],
        comparison["median_paired_internode_error_mm"],
        comparison["median_paired_angle_error_deg"],
        comparison["matched_share"]
    );
    assert_eq!(
        comparison["organs_measured"].as_u64().unwrap() as usize,
        organs
    );
    // Every measured interval is accounted for exactly once, in order.
    let covered: Vec<u64> = comparison["steps"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| {
            let m = s["measured"].as_array().unwrap();
            m[0].as_u64().unwrap()..m[1].as_u64().unwrap()
        })
        .collect();
    assert_eq!(covered, (0..angles.len() as u64).collect::<Vec<_>>());
}

/// A capture in which no stem is visible (the dataset with every stem and petiole point taken
/// out of its model) gives the leaves and no branch, with the reason in the report: never a
/// skeleton made of the pot or the soil.
#[test]
fn without_a_visible_stem_the_plant_is_leaves_only() {
    use frond::scene::{Reconstruction, read_model, write_model};
    use frond::synth::Part;
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("plant");
    copy_dir(dataset(), &copy);
    let truth = frond::eval::read_labelled_points(&copy.join("gt/points.ply")).unwrap();
    let (ids, parts) = (truth.point_ids.unwrap(), truth.parts.unwrap());
    let stem: std::collections::HashSet<u64> = ids
        .iter()
        .zip(&parts)
        .filter(|(_, part)| **part == Part::Stem)
        .map(|(id, _)| *id)
        .collect();
    assert!(stem.len() > 500, "{} stem points", stem.len());
    let model_dir = copy.join("sparse/0");
    let (model, format) = read_model(&model_dir).unwrap();
    let points: Vec<_> = model
        .points()
        .iter()
        .filter(|p| !stem.contains(&p.id))
        .cloned()
        .collect();
    let images: Vec<_> = model
        .images()
        .iter()
        .cloned()
        .map(|mut image| {
            for keypoint in &mut image.keypoints {
                if keypoint.point3d_id.is_some_and(|id| stem.contains(&id)) {
                    keypoint.point3d_id = None;
                }
            }
            image
        })
        .collect();
    let stemless = Reconstruction::from_parts(model.cameras().to_vec(), images, points).unwrap();
    write_model(&model_dir, &stemless, format).unwrap();

    let out = dir.path().join("out");
    let report = reconstruct_into(&copy, &out);
    assert_eq!(report["counts"]["branches"], 0, "{}", report["skeleton"]);
    let reason = report["skeleton_error"].as_str().unwrap_or_default();
    assert!(
        reason.contains("no stem visible") || reason.contains("too few"),
        "{reason:?}"
    );
    assert!(
        report["counts"]["leaves_fitted"].as_u64().unwrap() >= 8,
        "{}",
        report["counts"]
    );
    let skeleton = read_json(&out.join("skeleton.json"));
    assert_eq!(skeleton["branches"].as_array().unwrap().len(), 0);
}

/// The generic leaf's automatic candidates are tried best first and passed over when the
/// photos cannot give them (a candidate whose best view shows no outline used to fail the whole
/// reconstruction). Here every photo of a small-leaved plant is a flat grey, so no candidate has
/// an image boundary: the elliptic generic leaf stands in (`template` null) and the leaves are
/// still fitted from their points.
#[test]
fn a_generic_leaf_candidate_the_photos_cannot_give_is_passed_over() {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    let data = common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Smallleaf,
            seed: 2,
            views: 16,
            width: 480,
            height: 360,
            ..SynthOptions::default()
        },
    );
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("plant");
    copy_dir(data, &copy);
    for entry in std::fs::read_dir(copy.join("images")).unwrap() {
        let path = entry.unwrap().path();
        let (width, height) = image::image_dimensions(&path).unwrap();
        image::RgbImage::from_pixel(width, height, image::Rgb([128, 128, 128]))
            .save(&path)
            .unwrap();
    }
    let out = dir.path().join("out");
    let report = reconstruct_into(&copy, &out);
    assert!(report["template"].is_null(), "{}", report["template"]);
    assert!(report["counts"]["leaves_fitted"].as_u64().unwrap() > 0);
}
