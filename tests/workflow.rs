//! The Snakemake workflow (`workflow/Snakefile`) with the project's pinned Snakemake
//! (`scripts/setup.sh` installs it into .tools/snakemake): three small synthetic plants run
//! locally and gathered into one table; a second run does nothing; deleting one plant's
//! outputs redoes only that plant; the Slurm and Kubernetes profiles dry-run.

use std::path::{Path, PathBuf};
use std::process::Command;

use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Whether the pinned Snakemake is installed; on CI (CI=true) its absence is a failure.
fn snakemake_available() -> bool {
    let found = root()
        .join(".tools/snakemake/snakemake/__init__.py")
        .is_file();
    if !found && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "Snakemake is not in .tools/snakemake on CI: scripts/setup.sh should have installed it"
        );
    }
    if !found {
        eprintln!("skipping: Snakemake is not installed (run scripts/setup.sh)");
    }
    found
}

/// Runs the workflow in `dir` with extra arguments; returns its output, panics on failure.
fn snakemake(dir: &Path, args: &[&str]) -> String {
    let output = Command::new("bash")
        .arg(root().join("scripts/snakemake.sh"))
        .arg("-s")
        .arg(root().join("workflow/Snakefile"))
        .args(args)
        .arg("--config")
        .arg("manifest=plants.csv")
        .arg("out=results")
        .arg(format!("frond={}", env!("CARGO_BIN_EXE_frond")))
        .current_dir(dir)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        output.status.success(),
        "snakemake {args:?} failed:\n{text}"
    );
    text
}

/// The number of jobs of `rule` in Snakemake's "Job stats" table (0 when absent).
fn jobs_of(output: &str, rule: &str) -> usize {
    output
        .lines()
        .skip_while(|l| !l.starts_with("Job stats:"))
        .find_map(|l| {
            let mut fields = l.split_whitespace();
            (fields.next() == Some(rule))
                .then(|| fields.next().and_then(|n| n.parse().ok()))
                .flatten()
        })
        .unwrap_or(0)
}

fn modified(path: &Path) -> std::time::SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn the_workflow_runs_plants_gathers_them_and_redoes_only_what_is_missing() {
    if !snakemake_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for seed in 1..=3u64 {
        let options = SynthOptions {
            preset: Preset::Broadleaf,
            seed,
            views: 24,
            width: 400,
            height: 300,
            target_points: 20_000,
            ..SynthOptions::default()
        };
        write_dataset(
            &options,
            &dir.path().join(format!("plants/p{seed}")),
            &NoProgress,
        )
        .unwrap();
    }
    std::fs::write(
        dir.path().join("plants.csv"),
        "plant,input,scale\np1,plants/p1,1\np2,plants/p2,1\np3,plants/p3,1\n",
    )
    .unwrap();

    let first = snakemake(dir.path(), &["--cores", "2"]);
    for rule in ["densify", "reconstruct", "traits"] {
        assert_eq!(jobs_of(&first, rule), 3, "{rule}:\n{first}");
    }
    assert_eq!(jobs_of(&first, "gather"), 1, "{first}");
    let results = dir.path().join("results");
    let table = std::fs::read_to_string(results.join("traits.csv")).unwrap();
    assert!(table.starts_with("plant,organ_id,organ_type,trait,value,unit\n"));
    for p in ["p1", "p2", "p3"] {
        let own = std::fs::read_to_string(results.join(p).join("traits.csv")).unwrap();
        // Every plant's rows, as its own table has them, are in the gathered table.
        for row in own.lines().skip(1) {
            assert!(table.contains(row), "{p}: {row}");
        }
        let areas = own.lines().filter(|l| l.contains(",leaf,area,")).count();
        assert!(areas >= 5, "{p}: {areas} leaves");
        assert!(own.lines().skip(1).all(|l| l.starts_with(&format!("{p},"))));
    }
    assert!(results.join("leaf_area.png").is_file());

    // A second run does nothing.
    let stamp = modified(&results.join("traits.csv"));
    let second = snakemake(dir.path(), &["--cores", "2"]);
    assert!(second.contains("Nothing to be done"), "{second}");
    assert_eq!(modified(&results.join("traits.csv")), stamp);

    // Deleting one plant's outputs redoes that plant only (and the gathering).
    let p1_traits = modified(&results.join("p1/traits.json"));
    std::fs::remove_dir_all(results.join("p2")).unwrap();
    let third = snakemake(dir.path(), &["--cores", "2"]);
    for rule in ["densify", "reconstruct", "traits", "gather"] {
        assert_eq!(jobs_of(&third, rule), 1, "{rule}:\n{third}");
    }
    assert_eq!(modified(&results.join("p1/traits.json")), p1_traits);
    assert_eq!(
        std::fs::read_to_string(results.join("traits.csv")).unwrap(),
        table
    );
}

#[test]
fn the_cluster_profiles_plan_every_stage_of_a_photo_plant_and_a_colmap_plant() {
    if !snakemake_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let colmap = dir.path().join("plants/c1");
    write_dataset(
        &SynthOptions {
            views: 8,
            width: 200,
            height: 150,
            target_points: 2_000,
            ..SynthOptions::default()
        },
        &colmap,
        &NoProgress,
    )
    .unwrap();
    // A folder of photos (no model): the workflow plans structure from motion for it.
    let photos = dir.path().join("plants/photos1");
    std::fs::create_dir_all(&photos).unwrap();
    for entry in std::fs::read_dir(colmap.join("images")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, photos.join(path.file_name().unwrap())).unwrap();
    }
    std::fs::write(
        dir.path().join("plants.csv"),
        "plant,input\nc1,plants/c1\nph1,plants/photos1\n",
    )
    .unwrap();
    let profiles = root().join("workflow/profiles");
    for (profile, extra) in [
        ("slurm", Vec::new()),
        // The volume's prefix, pointed at the test folder (on the cluster: /mnt/frond).
        (
            "kubernetes",
            vec![
                "--default-storage-prefix".to_owned(),
                dir.path().display().to_string(),
            ],
        ),
    ] {
        let mut args = vec![
            "-n".to_owned(),
            "--profile".to_owned(),
            profiles.join(profile).display().to_string(),
        ];
        args.extend(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let plan = snakemake(dir.path(), &args);
        assert_eq!(jobs_of(&plan, "sfm"), 1, "{profile}:\n{plan}");
        assert_eq!(jobs_of(&plan, "densify"), 2, "{profile}:\n{plan}");
        assert_eq!(jobs_of(&plan, "traits"), 2, "{profile}:\n{plan}");
        assert_eq!(jobs_of(&plan, "gather"), 1, "{profile}:\n{plan}");
        assert!(
            !dir.path().join("results").exists(),
            "a dry run wrote results"
        );
    }
}
