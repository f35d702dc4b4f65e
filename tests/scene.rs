//! `frond scene` + `frond render`: a small field of synthetic plants, rendered along the
//! fly-through with LOD and at full detail in one run.

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;

#[test]
fn a_small_scene_renders_with_fewer_triangles_under_the_error_bound() {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("field");
    let made = cargo_bin_cmd!("frond")
        .args([
            "scene",
            "--count",
            "60",
            "--size",
            "8x8",
            "--variants",
            "3",
            "--masters",
            "2",
        ])
        .arg("--out")
        .arg(&scene_dir)
        .output()
        .unwrap();
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let scene: Value =
        serde_json::from_str(&std::fs::read_to_string(scene_dir.join("scene.json")).unwrap())
            .unwrap();
    let instances = scene["instances"].as_array().unwrap().len();
    assert_eq!(instances, 60);
    assert_eq!(scene["plants"].as_array().unwrap().len(), 2);
    for plant in scene["plants"].as_array().unwrap() {
        assert!(scene_dir.join(plant["file"].as_str().unwrap()).is_file());
    }

    let out = dir.path().join("render");
    let rendered = cargo_bin_cmd!("frond")
        .args([
            "render",
            "--frames",
            "3",
            "--size",
            "320x180",
            "--save-frames",
        ])
        .arg("--scene")
        .arg(scene_dir.join("scene.json"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        rendered.status.success(),
        "{}",
        String::from_utf8_lossy(&rendered.stderr)
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("render_report.json")).unwrap())
            .unwrap();
    let frames = report["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 6);
    for frame in frames {
        let drawn = frame["instances_drawn"].as_u64().unwrap();
        let culled = frame["instances_culled"].as_u64().unwrap();
        assert_eq!(drawn + culled, 60);
    }
    let summaries = report["summaries"].as_array().unwrap();
    let (lod, full) = (&summaries[0], &summaries[1]);
    assert_eq!(lod["mode"], "lod");
    assert!(lod["mean_triangles"].as_f64().unwrap() < full["mean_triangles"].as_f64().unwrap());
    assert!(lod["max_switches_per_plant_per_second"].as_u64().unwrap() <= 1);
    assert!(report["triangle_ratio"].as_f64().unwrap() > 1.0);
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(csv.lines().count(), 7);
    // The levels chosen for a 4 px error look like full detail: measured from the frames
    // themselves, each LOD frame differs from the full-detail frame of the same camera in
    // at most 2 % of its pixels (by more than 10 % in a channel; 0.4–1.6 % measured here), and
    // the LOD frames are not the full-detail ones.
    let mut any_difference = false;
    for frame in 0..3 {
        let read = |mode: &str| {
            image::open(out.join(format!("frame_{frame:04}_{mode}.png")))
                .unwrap()
                .to_rgba8()
        };
        let (lod_frame, full_frame) = (read("lod"), read("full"));
        assert_eq!(lod_frame.dimensions(), full_frame.dimensions());
        let differing = lod_frame
            .pixels()
            .zip(full_frame.pixels())
            .filter(|(a, b)| (0..3).any(|c| (a[c] as i32 - b[c] as i32).abs() > 25))
            .count();
        let fraction = differing as f64 / (lod_frame.width() * lod_frame.height()) as f64;
        eprintln!("frame {frame}: {:.2} % of pixels differ", 100.0 * fraction);
        assert!(fraction <= 0.02, "frame {frame}: {fraction}");
        any_difference |= lod_frame != full_frame;
    }
    assert!(
        any_difference,
        "the LOD frames equal the full-detail frames"
    );
}

#[test]
fn render_names_a_broken_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.json");
    std::fs::write(&path, "{\"version\": 1, \"instances\": [").unwrap();
    let run = cargo_bin_cmd!("frond")
        .arg("render")
        .arg("--scene")
        .arg(&path)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("scene.json"), "{stderr}");
}
