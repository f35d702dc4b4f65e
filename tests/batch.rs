//! `frond batch` as a library: three small synthetic plants and a broken one, resumed after
//! deletion and after an interrupted plant.

use std::path::Path;

use frond::batch::{BatchOptions, NoBatchProgress, PlantStatus, read_manifest, run_batch};
use frond::pipeline::{InputOptions, ReconstructOptions};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

fn plant(dir: &Path, seed: u64) {
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed,
        views: 12,
        width: 400,
        height: 300,
        target_points: 20_000,
        ..SynthOptions::default()
    };
    write_dataset(&options, dir, &NoProgress).unwrap();
}

fn modified(path: &Path) -> std::time::SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn a_batch_runs_every_plant_resumes_and_survives_a_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    for seed in 1..=3 {
        plant(&dir.path().join(format!("plants/p{seed}")), seed);
    }
    let manifest = dir.path().join("plants.csv");
    std::fs::write(
        &manifest,
        "plant,input,scale\np1,plants/p1,1\np2,plants/p2,1\np3,plants/p3,1\nbroken,plants/none,\n",
    )
    .unwrap();
    let entries = read_manifest(&manifest).unwrap();
    let options = BatchOptions {
        jobs: 2,
        input: InputOptions::default(),
        reconstruct: ReconstructOptions::default(),
    };
    let out = dir.path().join("out");
    let report = run_batch(&manifest, &entries, &out, &options, &NoBatchProgress).unwrap();
    assert_eq!(
        (report.done, report.skipped, report.failed),
        (3, 0, 1),
        "{report:?}"
    );
    let broken = &report.plants[3];
    assert_eq!(broken.status, PlantStatus::Failed);
    assert!(
        broken.error.as_deref().unwrap().contains("plants/none"),
        "{broken:?}"
    );
    assert!(!out.join("broken").exists());

    // The combined table holds every good plant's rows, in metres, leaf areas among them.
    let table = std::fs::read_to_string(out.join("traits.csv")).unwrap();
    let mut lines = table.lines();
    assert_eq!(
        lines.next(),
        Some("plant,organ_id,organ_type,trait,value,unit")
    );
    for p in ["p1", "p2", "p3"] {
        let leaf_areas = table
            .lines()
            .filter(|l| l.starts_with(&format!("{p},leaf_")) && l.contains(",leaf,area,"))
            .count();
        let count_line = table
            .lines()
            .find(|l| l.starts_with(&format!("{p},plant,plant,leaf_count,")))
            .unwrap();
        let count: f64 = count_line.split(',').nth(4).unwrap().parse().unwrap();
        assert!(leaf_areas >= 5, "{p}: {leaf_areas} leaf areas");
        assert_eq!(leaf_areas as f64, count);
        assert!(table.contains(&format!("{p},plant,plant,height,")));
    }
    assert!(table.lines().skip(1).all(|l| !l.ends_with("model units")));
    let png = image::open(out.join("leaf_area.png")).unwrap();
    assert!(png.width() >= 360);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("batch.json")).unwrap()).unwrap();
    assert_eq!(json["failed"], 1);

    // A second run does nothing for the finished plants.
    let stamp = modified(&out.join("p1/traits.json"));
    let again = run_batch(&manifest, &entries, &out, &options, &NoBatchProgress).unwrap();
    assert_eq!((again.done, again.skipped, again.failed), (0, 3, 1));
    assert_eq!(modified(&out.join("p1/traits.json")), stamp);
    assert_eq!(
        std::fs::read_to_string(out.join("traits.csv")).unwrap(),
        table
    );

    // A deleted plant and an interrupted one (its partial folder left behind, no final
    // folder) are redone; the others are not touched.
    std::fs::remove_dir_all(out.join("p2")).unwrap();
    std::fs::remove_dir_all(out.join("p3")).unwrap();
    std::fs::create_dir_all(out.join(".p3.partial/sfm")).unwrap();
    std::fs::write(out.join(".p3.partial/report.json"), "half written").unwrap();
    let third = run_batch(&manifest, &entries, &out, &options, &NoBatchProgress).unwrap();
    assert_eq!(
        (third.done, third.skipped, third.failed),
        (2, 1, 1),
        "{third:?}"
    );
    assert_eq!(third.plants[0].status, PlantStatus::Skipped);
    assert_eq!(modified(&out.join("p1/traits.json")), stamp);
    assert!(!out.join(".p3.partial").exists());
    assert!(out.join("p3/traits.json").is_file());
    // Deterministic: the redone plants give the same table.
    assert_eq!(
        std::fs::read_to_string(out.join("traits.csv")).unwrap(),
        table
    );
}
