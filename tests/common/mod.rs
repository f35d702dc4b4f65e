//! Helpers shared by integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use frond::synth::{SynthOptions, write_dataset};
use frond::util::progress::NoProgress;
use tempfile::TempDir;

/// A synthetic dataset written once per test binary into `cell` (as `<tempdir>/plant`).
pub fn synth_dataset(
    cell: &'static OnceLock<(TempDir, PathBuf)>,
    options: SynthOptions,
) -> &'static Path {
    &cell
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let root = dir.path().join("plant");
            write_dataset(&options, &root, &NoProgress).unwrap();
            (dir, root)
        })
        .1
}

/// `frond reconstruct INPUT --out <tempdir>` once per test binary into `cell`; the output
/// folder.
pub fn reconstruction(cell: &'static OnceLock<TempDir>, input: &Path) -> &'static Path {
    cell.get_or_init(|| {
        let out = tempfile::tempdir().unwrap();
        assert_cmd::cargo::cargo_bin_cmd!("frond")
            .arg("reconstruct")
            .arg(input)
            .arg("--out")
            .arg(out.path())
            .assert()
            .success();
        out
    })
    .path()
}

/// `../shared/data/<relative>` (real third-party data beside the checkout).
pub fn shared_data(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(relative)
}

/// Whether `colmap` runs here; on CI (CI=true) its absence is a failure.
pub fn colmap_available() -> bool {
    let found = Command::new("colmap").arg("help").output().is_ok();
    if !found && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("colmap is not on PATH on CI: scripts/setup.sh should have installed it");
    }
    if !found {
        eprintln!("skipping: colmap is not on PATH (run scripts/setup.sh)");
    }
    found
}

/// Runs colmap and returns stdout + stderr; panics with the output on failure.
pub fn run_colmap(args: &[&str]) -> String {
    let output = Command::new("colmap")
        .args(args)
        .output()
        .expect("colmap runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(output.status.success(), "colmap {args:?} failed:\n{text}");
    text
}

/// The "Name: value" statistics `colmap model_analyzer` prints.
pub fn analyze(dir: &Path) -> std::collections::HashMap<String, f64> {
    let text = run_colmap(&["model_analyzer", "--path", dir.to_str().unwrap()]);
    text.lines()
        .filter_map(|line| {
            let (key, value) = line.rsplit_once(": ")?;
            let key = key.rsplit("] ").next().unwrap_or(key).trim().to_owned();
            let value = value.trim().trim_end_matches("px").parse().ok()?;
            Some((key, value))
        })
        .collect()
}

/// Runs `program script file` (a checker script of the repository); returns whether it
/// accepted the file and its output. Panics when the checker cannot start (exit code 2).
pub fn run_checker(program: &str, script: &str, file: &Path) -> (bool, String) {
    let output = Command::new(program)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join(script))
        .arg(file)
        .output()
        .unwrap_or_else(|e| panic!("{program} does not run ({e}): run scripts/setup.sh"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert_ne!(
        output.status.code(),
        Some(2),
        "{script} could not start: {text}"
    );
    (output.status.success(), text)
}
