//! Many plants (`frond batch`): a manifest of plants → one output folder per plant, a combined
//! `traits.csv` of every plant, a `batch.json` summary and a plot of leaf area per plant.
//!
//! Resumable and safe to kill: each plant is built in a hidden `.PLANT.partial` folder and
//! renamed into place when its traits are written, so a plant folder exists only when it is
//! complete; a plant whose folder exists is skipped, an interrupted one is redone. One bad
//! plant does not stop the others. Plants run `jobs` at a time (threads in this process; a
//! cluster runs the Snakemake workflow in `workflow/` instead).

pub mod manifest;
pub mod plot;

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use manifest::{ManifestEntry, read_manifest};

use crate::pipeline::{InputOptions, ReconstructOptions};
use crate::traits::io::{TRAITS_JSON, read_traits, write_traits};
use crate::traits::{TraitRow, TraitTable};
use crate::util::atomic::write_atomic;
use crate::util::progress::Progress;

/// Errors of the batch as a whole (a plant's own failure is recorded in `batch.json`).
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    #[error("{path}: {message}")]
    Manifest { path: String, message: String },
    #[error("writing {path}: {message}")]
    Output { path: String, message: String },
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> BatchError {
    BatchError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// How a batch runs.
#[derive(Clone, Debug)]
pub struct BatchOptions {
    /// Plants at a time (≥ 1).
    pub jobs: usize,
    pub input: InputOptions,
    pub reconstruct: ReconstructOptions,
}

/// What happened to one plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PlantStatus {
    Done,
    Skipped,
    Failed,
}

/// One plant in `batch.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlantRecord {
    pub plant: String,
    pub input: PathBuf,
    pub status: PlantStatus,
    /// The error chain of a failed plant.
    pub error: Option<String>,
    pub seconds: f64,
    pub leaves: Option<usize>,
}

/// `batch.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BatchReport {
    pub format: String,
    pub version: u32,
    pub manifest: PathBuf,
    pub jobs: usize,
    pub done: usize,
    pub skipped: usize,
    pub failed: usize,
    pub seconds: f64,
    pub plants: Vec<PlantRecord>,
    /// Files written beside the plant folders.
    pub files: Vec<String>,
}

pub const BATCH_FORMAT: &str = "frond batch";
pub const BATCH_VERSION: u32 = 1;
pub const BATCH_JSON: &str = "batch.json";
pub const COMBINED_CSV: &str = "traits.csv";
pub const LEAF_AREA_PNG: &str = "leaf_area.png";

/// Progress of a batch: the outer count of plants and each plant's current stage.
pub trait BatchProgress: Sync {
    fn plants(&self, total: usize);
    fn plant_stage(&self, plant: &str, stage: &str);
    fn plant_finished(&self, plant: &str, status: PlantStatus);
}

/// Discards batch progress.
pub struct NoBatchProgress;

impl BatchProgress for NoBatchProgress {
    fn plants(&self, _total: usize) {}
    fn plant_stage(&self, _plant: &str, _stage: &str) {}
    fn plant_finished(&self, _plant: &str, _status: PlantStatus) {}
}

/// A plant's stages as [`Progress`] for the library stages it runs.
struct PlantProgress<'a> {
    plant: &'a str,
    outer: &'a dyn BatchProgress,
}

impl Progress for PlantProgress<'_> {
    fn stage(&self, name: &str, _total: u64) {
        self.outer.plant_stage(self.plant, name);
    }
    fn advance(&self, _units: u64) {}
}

/// The default number of plants at a time: the cores, but no more than memory allows at
/// `per_plant_bytes` each (from /proc/meminfo's MemAvailable where there is one).
pub fn default_jobs(per_plant_bytes: u64) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let available = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kib| kib.parse::<u64>().ok())
        })
        .map(|kib| kib * 1024);
    let by_memory = available.map_or(cores, |bytes| (bytes / per_plant_bytes.max(1)) as usize);
    cores.min(by_memory).max(1)
}

/// Whether a plant's output folder is complete (it has its traits; the folder only appears
/// when everything is written).
pub fn plant_is_complete(out: &Path, plant: &str) -> bool {
    read_traits(&out.join(plant).join(TRAITS_JSON)).is_ok()
}

/// Why one plant failed (recorded in `batch.json`; the batch goes on).
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    #[error("opening {input}: {source}")]
    Open {
        input: String,
        source: Box<crate::pipeline::PipelineError>,
    },
    #[error("reconstructing {input}: {source}")]
    Reconstruct {
        input: String,
        source: Box<crate::pipeline::PipelineError>,
    },
    #[error(transparent)]
    Traits(#[from] crate::traits::TraitsError),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> PlantError {
    PlantError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Reconstructs one plant into `dir` (created) and writes its traits. Returns the leaf count.
pub fn run_plant(
    entry: &ManifestEntry,
    options: &BatchOptions,
    dir: &Path,
    progress: &dyn Progress,
) -> Result<usize, PlantError> {
    std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    let mut input = options.input.clone();
    if entry.no_densify {
        input.auto_densify = false;
    }
    let input_name = entry.input.display().to_string();
    let (scene, preparation) = crate::pipeline::open_input(&entry.input, &input, dir, progress)
        .map_err(|source| PlantError::Open {
            input: input_name.clone(),
            source: Box::new(source),
        })?;
    crate::pipeline::reconstruct(
        &scene,
        &options.reconstruct,
        Some(&preparation),
        dir,
        progress,
    )
    .map_err(|source| PlantError::Reconstruct {
        input: input_name,
        source: Box::new(source),
    })?;
    progress.stage("traits", 0);
    let scale = match entry.checkerboard {
        Some((inner, square)) => {
            Some(crate::traits::marker::checkerboard_scale(&scene, inner, square)?.0)
        }
        None => entry.scale.clone(),
    };
    let organs = crate::traits::io::read_reconstruction(dir, &entry.plant)?;
    let table = crate::traits::plant_traits(&organs, scale.as_ref());
    write_traits(dir, &table)?;
    Ok(organs.leaves.len())
}

/// Runs every plant of a manifest into `out` (see the module documentation).
pub fn run_batch(
    manifest_path: &Path,
    entries: &[ManifestEntry],
    out: &Path,
    options: &BatchOptions,
    progress: &dyn BatchProgress,
) -> Result<BatchReport, BatchError> {
    let clock = Instant::now();
    std::fs::create_dir_all(out).map_err(|e| output_error(out, e))?;
    progress.plants(entries.len());
    let records: Mutex<Vec<Option<PlantRecord>>> = Mutex::new(vec![None; entries.len()]);
    let next = AtomicUsize::new(0);
    let jobs = options.jobs.max(1).min(entries.len().max(1));
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::SeqCst);
                    let Some(entry) = entries.get(k) else {
                        break;
                    };
                    let record = one_plant(entry, out, options, progress);
                    progress.plant_finished(&entry.plant, record.status);
                    if let Ok(mut slots) = records.lock() {
                        slots[k] = Some(record);
                    }
                }
            });
        }
    });
    let plants: Vec<PlantRecord> = records
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect();
    // The combined table and the plot, from every complete plant in manifest order.
    let tables: Vec<TraitTable> = plants
        .iter()
        .filter(|record| record.status != PlantStatus::Failed)
        .filter_map(|record| read_traits(&out.join(&record.plant).join(TRAITS_JSON)).ok())
        .collect();
    let files = write_combined(&tables, &out.join(COMBINED_CSV), &out.join(LEAF_AREA_PNG))?
        .iter()
        .map(|p| p.strip_prefix(out).unwrap_or(p).display().to_string())
        .collect();
    let count = |s: PlantStatus| plants.iter().filter(|p| p.status == s).count();
    let report = BatchReport {
        format: BATCH_FORMAT.into(),
        version: BATCH_VERSION,
        manifest: manifest_path.to_path_buf(),
        jobs,
        done: count(PlantStatus::Done),
        skipped: count(PlantStatus::Skipped),
        failed: count(PlantStatus::Failed),
        seconds: clock.elapsed().as_secs_f64(),
        plants,
        files,
    };
    let json_path = out.join(BATCH_JSON);
    let text = serde_json::to_string_pretty(&report).map_err(|e| output_error(&json_path, e))?;
    write_atomic(&json_path, text.as_bytes()).map_err(|e| output_error(&json_path, e))?;
    Ok(report)
}

/// Writes the combined long table of several plants (CSV, header once) and, when any leaf
/// has an area, the leaf-area plot (values in cm² when every table has a scale). Returns the
/// files written.
pub fn write_combined(
    tables: &[TraitTable],
    csv_path: &Path,
    png_path: &Path,
) -> Result<Vec<PathBuf>, BatchError> {
    let rows: Vec<TraitRow> = tables.iter().flat_map(|t| t.rows.iter().cloned()).collect();
    write_atomic(csv_path, crate::traits::io::csv_text(&rows).as_bytes())
        .map_err(|e| output_error(csv_path, e))?;
    let mut files = vec![csv_path.to_path_buf()];
    let metric = !tables.is_empty() && tables.iter().all(|t| t.scale.is_some());
    match plot::leaf_area_plot(&rows, metric) {
        Ok(png) => {
            write_atomic(png_path, &png).map_err(|e| output_error(png_path, e))?;
            files.push(png_path.to_path_buf());
        }
        Err(e) => tracing::warn!("no leaf area plot: {e}"),
    }
    Ok(files)
}

fn one_plant(
    entry: &ManifestEntry,
    out: &Path,
    options: &BatchOptions,
    progress: &dyn BatchProgress,
) -> PlantRecord {
    let clock = Instant::now();
    let record = |status, error, leaves| PlantRecord {
        plant: entry.plant.clone(),
        input: entry.input.clone(),
        status,
        error,
        seconds: clock.elapsed().as_secs_f64(),
        leaves,
    };
    let final_dir = out.join(&entry.plant);
    if plant_is_complete(out, &entry.plant) {
        let leaves = read_traits(&final_dir.join(TRAITS_JSON))
            .ok()
            .and_then(|t| t.value("plant", "leaf_count"))
            .map(|n| n as usize);
        return record(PlantStatus::Skipped, None, leaves);
    }
    // A plant folder is only ever made complete (renamed into place with its traits); one
    // without readable traits is someone else's work and is left alone.
    if final_dir.exists() {
        return record(
            PlantStatus::Failed,
            Some(format!(
                "{} exists but holds no readable traits.json from frond; move it away (or delete it) to run this plant",
                final_dir.display()
            )),
            None,
        );
    }
    let partial = out.join(format!(".{}.partial", entry.plant));
    let attempt = || -> Result<usize, PlantError> {
        // An interrupted run of this plant (the batch's own hidden folder) is redone.
        if partial.exists() {
            std::fs::remove_dir_all(&partial).map_err(|e| io_error(&partial, e))?;
        }
        let plant_progress = PlantProgress {
            plant: &entry.plant,
            outer: progress,
        };
        let leaves = run_plant(entry, options, &partial, &plant_progress)?;
        std::fs::rename(&partial, &final_dir).map_err(|e| io_error(&final_dir, e))?;
        Ok(leaves)
    };
    match attempt() {
        Ok(leaves) => record(PlantStatus::Done, None, Some(leaves)),
        Err(e) => {
            tracing::warn!("plant {} failed: {e}", entry.plant);
            record(PlantStatus::Failed, Some(e.to_string()), None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_foreign_folder_in_a_plants_place_is_left_alone_and_named() {
        let out = tempfile::tempdir().unwrap();
        std::fs::create_dir(out.path().join("p1")).unwrap();
        std::fs::write(out.path().join("p1/notes.txt"), "my measurements").unwrap();
        let entry = ManifestEntry {
            plant: "p1".into(),
            input: out.path().join("nowhere"),
            scale: None,
            checkerboard: None,
            no_densify: false,
        };
        let options = BatchOptions {
            jobs: 1,
            input: InputOptions::default(),
            reconstruct: ReconstructOptions::default(),
        };
        let record = one_plant(&entry, out.path(), &options, &NoBatchProgress);
        assert_eq!(record.status, PlantStatus::Failed);
        assert!(
            record.error.as_deref().unwrap().contains("move it away"),
            "{record:?}"
        );
        assert_eq!(
            std::fs::read_to_string(out.path().join("p1/notes.txt")).unwrap(),
            "my measurements"
        );
    }
}
