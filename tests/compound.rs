//! Compound leaves end to end: a synthetic `compound` plant (pinnate leaves: leaflets on a
//! rachis) through `frond reconstruct` and `frond eval`. The leaflets are found, grouped on
//! their rachis in `report.json`, `plant.glb` and `plant.obj`, and scored against the truth.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use assert_cmd::cargo::cargo_bin_cmd;
use frond::synth::{Preset, SynthOptions};
use serde_json::Value;
use tempfile::TempDir;

/// One small compound plant (seed 12: five compound leaves of 7–33 leaflets).
fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Compound,
            seed: 12,
            views: 16,
            width: 480,
            height: 360,
            target_points: 30_000,
            ..SynthOptions::default()
        },
    )
}

fn reconstruction() -> &'static Path {
    static DIR: OnceLock<TempDir> = OnceLock::new();
    common::reconstruction(&DIR, dataset())
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_truth_names_each_leaflets_compound_leaf() {
    let leaves = read_json(&dataset().join("gt/leaves.json"));
    let leaves = leaves.as_array().unwrap();
    let mut per_rachis: BTreeMap<u64, usize> = BTreeMap::new();
    for leaf in leaves {
        let rachis = leaf["compound_leaf"]
            .as_u64()
            .expect("every leaf is a leaflet");
        assert_eq!(leaf["branch"].as_u64(), Some(rachis));
        *per_rachis.entry(rachis).or_insert(0) += 1;
    }
    assert_eq!(per_rachis.len(), 5);
    assert!(per_rachis.values().all(|&n| (4..=41).contains(&n)));
}

#[test]
fn leaflets_are_grouped_on_their_rachis_in_every_output() {
    let out = reconstruction();
    let report = read_json(&out.join("report.json"));
    let compound = report["compound_leaves"].as_array().unwrap();
    assert!(compound.len() >= 4, "{} compound leaves", compound.len());
    let skeleton = read_json(&out.join("skeleton.json"));
    let branch_ids: BTreeSet<u64> = skeleton["branches"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["id"].as_u64().unwrap())
        .collect();
    let mut leaflets: BTreeMap<String, String> = BTreeMap::new();
    for c in compound {
        assert!(branch_ids.contains(&c["rachis"].as_u64().unwrap()));
        let group = format!("compound_leaf_{:03}", c["id"].as_u64().unwrap());
        for leaflet in c["leaflets"].as_array().unwrap() {
            let name = format!("leaf_{:03}", leaflet.as_u64().unwrap());
            assert!(
                leaflets.insert(name, group.clone()).is_none(),
                "a leaflet is in one compound leaf"
            );
        }
    }
    // Every attached leaf says where it sits.
    let attached = report["attachment"]["leaves"].as_array().unwrap();
    assert_eq!(
        attached.len() as u64,
        report["counts"]["leaves_fitted"].as_u64().unwrap()
    );

    // plant.glb: each leaflet is a child of its compound leaf's node; other leaves are roots.
    let glb = std::fs::read(out.join("plant.glb")).unwrap();
    let nodes = frond::model::gltf::read_glb_meshes(&glb, &out.join("plant.glb")).unwrap();
    let mut grouped = 0;
    for node in &nodes {
        if let Some(group) = leaflets.get(&node.name) {
            assert_eq!(node.group.as_ref(), Some(group), "{}", node.name);
            grouped += 1;
        } else if node.name.starts_with("leaf_") {
            assert_eq!(node.group, None, "{}", node.name);
        }
    }
    assert_eq!(grouped, leaflets.len());

    // plant.obj: the same groups.
    let obj = std::fs::read_to_string(out.join("plant.obj")).unwrap();
    let lines: Vec<&str> = obj.lines().collect();
    for (name, group) in &leaflets {
        let at = lines
            .iter()
            .position(|l| *l == format!("o {name}"))
            .unwrap_or_else(|| panic!("{name} in plant.obj"));
        assert_eq!(lines[at + 1], format!("g {group}"));
    }
}

#[test]
fn the_traits_name_each_leaflets_compound_leaf() {
    let out = reconstruction();
    let report = read_json(&out.join("report.json"));
    let compound = report["compound_leaves"].as_array().unwrap();
    let expected: BTreeMap<String, u64> = compound
        .iter()
        .flat_map(|c| {
            let id = c["id"].as_u64().unwrap();
            c["leaflets"]
                .as_array()
                .unwrap()
                .iter()
                .map(move |l| (format!("leaf_{:03}", l.as_u64().unwrap()), id))
        })
        .collect();
    let table = std::fs::read_to_string(out.join("traits.csv")).unwrap();
    let mut found: BTreeMap<String, u64> = BTreeMap::new();
    let mut count = None;
    for line in table.lines().skip(1) {
        let fields: Vec<&str> = line.split(',').collect();
        match (fields[1], fields[3]) {
            (organ, "compound_leaf") => {
                found.insert(organ.to_owned(), fields[4].parse::<f64>().unwrap() as u64);
            }
            ("plant", "compound_leaf_count") => count = Some(fields[4].parse::<f64>().unwrap()),
            _ => {}
        }
    }
    assert_eq!(found, expected);
    assert_eq!(count, Some(compound.len() as f64));
}

#[test]
fn eval_scores_the_leaflets_on_their_rachis() {
    let output = cargo_bin_cmd!("frond")
        .arg("eval")
        .arg("--gt")
        .arg(dataset())
        .arg("--pred")
        .arg(reconstruction())
        .arg("--json")
        .output()
        .unwrap();
    assert!(output.status.success());
    let report: Value = serde_json::from_slice(&output.stdout).unwrap();
    let compound = &report["compound"];
    // Measured: 5 of 5 compound leaves found, every one on a true rachis; leaflet recall
    // 0.906; 68 of 96 matched leaflets on the right rachis (0.708).
    assert_eq!(compound["true_compound_leaves"], 5);
    let predicted = compound["predicted_compound_leaves"].as_u64().unwrap();
    assert!(predicted >= 4);
    assert_eq!(
        compound["predicted_on_a_true_rachis"].as_u64(),
        Some(predicted)
    );
    assert!(report["leaves"]["recall"].as_f64().unwrap() >= 0.8);
    assert!(compound["right_rachis_share"].as_f64().unwrap() >= 0.6);
}
