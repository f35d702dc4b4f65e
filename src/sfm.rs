//! `frond sfm`: structure from motion by the installed COLMAP, on the CPU. Runs feature
//! extraction (one shared camera by default), matching (exhaustive up to 60 photos, sequential
//! beyond, or a vocabulary tree when given one), the incremental mapper and undistortion, and
//! writes one folder:
//!
//! - `database.db`, `colmap.log` (every COLMAP message);
//! - `sparse/0`: the model with the most registered images (COLMAP numbers its models by
//!   discovery; the best is renamed to 0, the others kept as 1, 2, …);
//! - `dense/`: COLMAP's undistorted workspace (`images/`, `sparse/`) for `frond densify`;
//! - `sfm.json`: steps, timings, registered and unregistered photos.
//!
//! The folder is assembled beside its destination and renamed into place. Takes a folder of
//! photos and [`SfmOptions`]; returns an [`SfmReport`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use serde::Serialize;

use crate::scene::{SceneError, read_model};
use crate::util::atomic::{StagedDir, write_atomic};
use crate::util::progress::Progress;

/// How photos are matched.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Matcher {
    /// Exhaustive up to 60 photos, sequential beyond.
    Auto,
    Exhaustive,
    /// Neighbours in file-name order (a walk around the plant).
    Sequential,
    /// COLMAP's vocabulary-tree matcher with this tree file (faiss or flann, as the installed
    /// COLMAP expects).
    VocabTree(PathBuf),
}

/// Options of an SfM run.
#[derive(Clone, Debug, Serialize)]
pub struct SfmOptions {
    pub matcher: Matcher,
    /// COLMAP camera model name (SIMPLE_RADIAL, OPENCV, …).
    pub camera_model: String,
    /// One camera (lens and focal length) for every photo.
    pub single_camera: bool,
    /// Undistorted images have their longest side at most this (0: as taken).
    pub max_image_size: u32,
    pub threads: usize,
    /// The `colmap` executable.
    pub colmap: PathBuf,
}

impl Default for SfmOptions {
    fn default() -> Self {
        Self {
            matcher: Matcher::Auto,
            camera_model: "SIMPLE_RADIAL".to_owned(),
            single_camera: true,
            max_image_size: 0,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            colmap: PathBuf::from("colmap"),
        }
    }
}

/// Why SfM failed.
#[derive(Debug, thiserror::Error)]
pub enum SfmError {
    #[error("COLMAP ('{0}') could not be started: is it installed? (scripts/setup.sh installs it)")]
    ColmapMissing(PathBuf),
    #[error("{path}: {message}")]
    Photos { path: PathBuf, message: String },
    #[error("COLMAP {step} failed ({status}); last messages:\n{log_tail}")]
    Colmap {
        step: String,
        status: String,
        log_tail: String,
    },
    #[error(
        "COLMAP registered {registered} of {total} photos (need at least 3): the photos may overlap too little, be blurred, or show too little texture"
    )]
    TooFewRegistered { registered: usize, total: usize },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

/// What an SfM run did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SfmReport {
    pub photos: usize,
    pub matcher: String,
    pub registered: usize,
    pub unregistered: Vec<String>,
    pub points: usize,
    pub models: usize,
    pub mean_track_length: f64,
    pub timings: BTreeMap<String, f64>,
}

const PHOTO_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "tif", "tiff", "bmp"];

/// The photo files directly in `dir`, sorted by name.
pub fn list_photos(dir: &Path) -> Result<Vec<PathBuf>, SfmError> {
    let entries = std::fs::read_dir(dir).map_err(|e| SfmError::Photos {
        path: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut photos: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension().is_some_and(|x| {
                    PHOTO_EXTENSIONS.contains(&x.to_string_lossy().to_lowercase().as_str())
                })
        })
        .collect();
    photos.sort();
    Ok(photos)
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> SfmError {
    SfmError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn tail(text: &str, lines: usize) -> String {
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// Runs one COLMAP command, appending its output to `log`.
fn run_colmap(
    options: &SfmOptions,
    step: &str,
    args: &[String],
    log: &Path,
) -> Result<f64, SfmError> {
    let started = Instant::now();
    tracing::info!("colmap {}", args.join(" "));
    let output = Command::new(&options.colmap)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|_| SfmError::ColmapMissing(options.colmap.clone()))?;
    let mut text = format!("== colmap {}\n", args.join(" "));
    text.push_str(&String::from_utf8_lossy(&output.stdout));
    text.push_str(&String::from_utf8_lossy(&output.stderr));
    let mut previous = std::fs::read(log).unwrap_or_default();
    previous.extend_from_slice(text.as_bytes());
    write_atomic(log, &previous).map_err(|e| output_error(log, e))?;
    if !output.status.success() {
        return Err(SfmError::Colmap {
            step: step.to_owned(),
            status: output.status.to_string(),
            log_tail: tail(&text, 15),
        });
    }
    Ok(started.elapsed().as_secs_f64())
}

fn path_arg(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// Runs COLMAP on the photos in `photos` and writes `out` (see the module docs).
pub fn run_sfm(
    photos: &Path,
    out: &Path,
    options: &SfmOptions,
    progress: &dyn Progress,
) -> Result<SfmReport, SfmError> {
    let files = list_photos(photos)?;
    if files.len() < 3 {
        return Err(SfmError::Photos {
            path: photos.to_path_buf(),
            message: format!(
                "holds {} photos ({}); structure from motion needs at least 3",
                files.len(),
                PHOTO_EXTENSIONS.join(", ")
            ),
        });
    }
    let photos = std::fs::canonicalize(photos).map_err(|e| SfmError::Photos {
        path: photos.to_path_buf(),
        message: e.to_string(),
    })?;
    let matcher = match &options.matcher {
        Matcher::Auto if files.len() <= 60 => Matcher::Exhaustive,
        Matcher::Auto => Matcher::Sequential,
        other => other.clone(),
    };
    let mut report = SfmReport {
        photos: files.len(),
        matcher: format!("{matcher:?}"),
        ..SfmReport::default()
    };
    let staging = StagedDir::new(out).map_err(|e| output_error(out, e))?;
    let root = staging.path().to_path_buf();
    let database = root.join("database.db");
    let log = root.join("colmap.log");
    let threads = options.threads.max(1).to_string();
    let s = |v: &str| v.to_owned();

    progress.stage("structure from motion", 5);
    let extract = vec![
        s("feature_extractor"),
        s("--database_path"),
        path_arg(&database),
        s("--image_path"),
        path_arg(&photos),
        s("--ImageReader.camera_model"),
        options.camera_model.clone(),
        s("--ImageReader.single_camera"),
        s(if options.single_camera { "1" } else { "0" }),
        s("--SiftExtraction.use_gpu"),
        s("0"),
        s("--SiftExtraction.num_threads"),
        threads.clone(),
    ];
    let seconds = run_colmap(options, "feature extraction", &extract, &log)?;
    report.timings.insert("features".into(), seconds);
    progress.advance(1);

    let mut matching = match &matcher {
        Matcher::Exhaustive | Matcher::Auto => vec![s("exhaustive_matcher")],
        Matcher::Sequential => vec![s("sequential_matcher")],
        Matcher::VocabTree(tree) => vec![
            s("vocab_tree_matcher"),
            s("--VocabTreeMatching.vocab_tree_path"),
            path_arg(tree),
        ],
    };
    matching.extend([
        s("--database_path"),
        path_arg(&database),
        s("--SiftMatching.use_gpu"),
        s("0"),
        s("--SiftMatching.num_threads"),
        threads.clone(),
    ]);
    let seconds = run_colmap(options, "matching", &matching, &log)?;
    report.timings.insert("matching".into(), seconds);
    progress.advance(1);

    let mapped = root.join("mapped");
    std::fs::create_dir_all(&mapped).map_err(|e| output_error(&mapped, e))?;
    let mapper = vec![
        s("mapper"),
        s("--database_path"),
        path_arg(&database),
        s("--image_path"),
        path_arg(&photos),
        s("--output_path"),
        path_arg(&mapped),
        s("--Mapper.num_threads"),
        threads,
    ];
    let seconds = match run_colmap(options, "mapping", &mapper, &log) {
        Ok(seconds) => seconds,
        // The mapper gives up when no image pair can start a model.
        Err(SfmError::Colmap { log_tail, .. })
            if log_tail.contains("failed to create sparse model") =>
        {
            return Err(SfmError::TooFewRegistered {
                registered: 0,
                total: files.len(),
            });
        }
        Err(e) => return Err(e),
    };
    report.timings.insert("mapping".into(), seconds);
    progress.advance(1);

    // The model with the most registered images becomes sparse/0.
    let mut models = Vec::new();
    if let Ok(entries) = std::fs::read_dir(&mapped) {
        for entry in entries.flatten() {
            let path = entry.path();
            if let Ok((model, _)) = read_model(&path) {
                models.push((model.images().len(), path, model));
            }
        }
    }
    models.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    report.models = models.len();
    let Some((registered, _, best)) = models.first() else {
        return Err(SfmError::TooFewRegistered {
            registered: 0,
            total: files.len(),
        });
    };
    if *registered < 3 {
        return Err(SfmError::TooFewRegistered {
            registered: *registered,
            total: files.len(),
        });
    }
    report.registered = *registered;
    report.points = best.points().len();
    report.mean_track_length = if best.points().is_empty() {
        0.0
    } else {
        best.points().iter().map(|p| p.track.len()).sum::<usize>() as f64
            / best.points().len() as f64
    };
    let names: std::collections::HashSet<&str> =
        best.images().iter().map(|i| i.name.as_str()).collect();
    report.unregistered = files
        .iter()
        .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
        .filter(|n| !names.contains(n.as_str()))
        .collect();
    let sparse = root.join("sparse");
    std::fs::create_dir_all(&sparse).map_err(|e| output_error(&sparse, e))?;
    for (k, (_, path, _)) in models.iter().enumerate() {
        let target = sparse.join(k.to_string());
        std::fs::rename(path, &target).map_err(|e| output_error(&target, e))?;
    }
    std::fs::remove_dir_all(&mapped).map_err(|e| output_error(&mapped, e))?;

    let mut undistort = vec![
        s("image_undistorter"),
        s("--image_path"),
        path_arg(&photos),
        s("--input_path"),
        path_arg(&sparse.join("0")),
        s("--output_path"),
        path_arg(&root.join("dense")),
        s("--output_type"),
        s("COLMAP"),
    ];
    if options.max_image_size > 0 {
        undistort.extend([s("--max_image_size"), options.max_image_size.to_string()]);
    }
    let seconds = run_colmap(options, "undistortion", &undistort, &log)?;
    report.timings.insert("undistortion".into(), seconds);
    progress.advance(1);

    let json_path = root.join("sfm.json");
    let json = serde_json::json!({
        "generator": concat!("frond ", env!("CARGO_PKG_VERSION")),
        "photos_dir": photos,
        "options": options,
        "report": report,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| output_error(&json_path, e))?;
    write_atomic(&json_path, text.as_bytes()).map_err(|e| output_error(&json_path, e))?;
    staging.commit().map_err(|e| output_error(out, e))?;
    progress.advance(1);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::progress::NoProgress;

    #[test]
    fn photos_are_listed_by_extension_and_too_few_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b.PNG", "a.jpg", "notes.txt", "c.tiff"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        std::fs::create_dir(dir.path().join("sub.png")).unwrap();
        let photos = list_photos(dir.path()).unwrap();
        let names: Vec<_> = photos
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a.jpg", "b.PNG", "c.tiff"]);
        std::fs::remove_file(dir.path().join("c.tiff")).unwrap();
        let out = dir.path().join("out");
        let err = run_sfm(dir.path(), &out, &SfmOptions::default(), &NoProgress).unwrap_err();
        assert!(err.to_string().contains("holds 2 photos"), "{err}");
        assert!(!out.exists());
    }

    #[test]
    fn a_missing_colmap_is_named() {
        let dir = tempfile::tempdir().unwrap();
        for k in 0..3 {
            std::fs::write(dir.path().join(format!("{k}.png")), b"x").unwrap();
        }
        let options = SfmOptions {
            colmap: PathBuf::from("/nonexistent/colmap"),
            ..SfmOptions::default()
        };
        let out = dir.path().join("out");
        let err = run_sfm(dir.path(), &out, &options, &NoProgress).unwrap_err();
        assert!(matches!(err, SfmError::ColmapMissing(_)), "{err}");
        assert!(!out.exists(), "a failed run leaves no output");
    }
}
