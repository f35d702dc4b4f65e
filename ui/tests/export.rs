//! The GUI's export and the batch reconstruction (`frond reconstruct`'s library call) of the
//! same input write the same files: byte-identical `segmentation.ply`, `plant.glb` and
//! `skeleton.json`, equal `segments.json`, and equal `report.json` once timings are set aside.

mod common;

use std::path::Path;

use frond::pipeline::{InputOptions, ReconstructOptions, open_input, reconstruct};
use frond::util::progress::NoProgress;
use frond_ui::workspace::Workspace;
use serde_json::Value;

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A JSON value with every timing (keys `timings`, `seconds`, `total`) removed.
fn without_timings(mut value: Value) -> Value {
    fn strip(value: &mut Value) {
        match value {
            Value::Object(map) => {
                map.retain(|key, _| !matches!(key.as_str(), "timings" | "seconds"));
                map.values_mut().for_each(strip);
            }
            Value::Array(items) => items.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut value);
    value
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&read(path)).unwrap()
}

#[test]
fn gui_export_and_batch_reconstruction_write_the_same_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = common::write_synthetic_plant(dir.path());

    let batch = dir.path().join("batch");
    let (scene, preparation) =
        open_input(&input, &InputOptions::default(), &batch, &NoProgress).unwrap();
    let done = reconstruct(
        &scene,
        &ReconstructOptions::default(),
        Some(&preparation),
        &batch,
        &NoProgress,
    )
    .unwrap();
    assert!(done.report.counts.leaves_fitted > 0);

    let mut workspace = Workspace::open(&input, &NoProgress).unwrap();
    let gui = dir.path().join("gui");
    workspace.export(&gui, &NoProgress).unwrap();

    for file in [
        "segmentation.ply",
        "plant.glb",
        "skeleton.json",
        "plant.obj",
    ] {
        assert!(
            read(&batch.join(file)) == read(&gui.join(file)),
            "{file} differs between the batch and the GUI export"
        );
    }
    assert_eq!(
        json(&batch.join("segments.json")),
        json(&gui.join("segments.json"))
    );
    let (batch_report, gui_report) = (
        without_timings(json(&batch.join("report.json"))),
        without_timings(json(&gui.join("report.json"))),
    );
    assert_eq!(batch_report, gui_report);
    // The report is more than its timings: the comparison saw the leaves and the files.
    assert!(!batch_report["leaves"].as_array().unwrap().is_empty());
    assert!(
        batch_report["files"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f == "skeleton.json")
    );
}
