//! `frond sfm`: structure from motion with the installed COLMAP, on the CPU, made fast for
//! captures of one plant. Steps:
//!
//! 1. The photos are checked ([`photos`]): unreadable, truncated and duplicate files are named
//!    and left out; photos of one size share a camera.
//! 2. COLMAP extracts SIFT features (once per size group).
//! 3. Frond chooses the pairs to match by image retrieval over the capture's own visual words
//!    plus file-name neighbours ([`pairs`]) and matches their descriptors itself with blocked
//!    SIMD matrix products ([`matching`]; COLMAP's definition of a match, about 10× faster per
//!    pair than its CPU matcher); COLMAP verifies the matches geometrically
//!    (`matches_importer`). [`Matcher::Exhaustive`], [`Matcher::Sequential`] and
//!    [`Matcher::VocabTree`] run COLMAP's own matchers instead.
//! 4. COLMAP's incremental mapper; in a dense capture from [`keyframes`] only (matched once
//!    more among themselves, relative neighbours included), the other photos then registered
//!    to the model (`image_registrator`) and one `bundle_adjuster` run over all; optionally
//!    its undistortion (Frond's densify reads distorted photos directly, so the pipeline skips
//!    it).
//!
//! Writes one folder:
//! - `database.db`, `colmap.log` (every COLMAP message), `matches.txt` (Frond's matches),
//!   `keyframes.txt` (the photos the mapper built the model from, when not all);
//! - `sparse/0`: the model with the most registered images (COLMAP numbers its models by
//!   discovery; the best is renamed to 0, the others kept as 1, 2, …);
//! - `dense/` (with [`SfmOptions::undistort`]): COLMAP's undistorted workspace;
//! - `sfm.json`: the photos folder, options, steps, timings, registered, unregistered and
//!   rejected photos.
//!
//! The folder is assembled beside its destination and renamed into place. A run that fails
//! after features were extracted keeps what it made in `OUT.failed` (with `sfm.json` saying
//! why) and names that folder in its error; an earlier complete `OUT` is left as it was. Takes
//! a folder of photos and [`SfmOptions`]; returns an [`SfmReport`].

pub mod database;
pub mod keyframes;
pub mod matching;
pub mod pairs;
pub mod photos;

use std::collections::BTreeMap;
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use crate::scene::{SceneError, read_model};
use crate::util::atomic::{StagedDir, write_atomic};
use crate::util::progress::Progress;
use keyframes::{KeyframeOptions, select_keyframes};
use matching::{MatchOptions, match_descriptors};
use pairs::{PairOptions, select_pairs, select_pairs_diverse};
use photos::{PhotoCheck, RejectedPhoto, check_photos};

/// How photos are matched.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Matcher {
    /// Frond's: pairs chosen by retrieval ([`SfmOptions::pairs`]), matched by Frond, verified
    /// by COLMAP.
    Auto,
    /// COLMAP's exhaustive matcher (every pair; the reference Frond's matcher is measured
    /// against).
    Exhaustive,
    /// COLMAP's sequential matcher: neighbours in file-name order (a walk around the plant).
    Sequential,
    /// COLMAP's vocabulary-tree matcher with this tree file (faiss or flann, as the installed
    /// COLMAP expects).
    VocabTree(PathBuf),
}

/// Options of an SfM run.
#[derive(Clone, Debug, Serialize)]
pub struct SfmOptions {
    pub matcher: Matcher,
    /// Which pairs [`Matcher::Auto`] matches.
    pub pairs: PairOptions,
    /// What [`Matcher::Auto`] counts as a match.
    pub matching: MatchOptions,
    /// Which photos [`Matcher::Auto`] builds the model from; the others are registered to it.
    pub keyframes: KeyframeOptions,
    /// COLMAP camera model name (SIMPLE_RADIAL, OPENCV, …).
    pub camera_model: String,
    /// One camera (lens and focal length) per photo size; `false`: one per photo.
    pub single_camera: bool,
    /// Write COLMAP's undistorted workspace (`dense/`).
    pub undistort: bool,
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
            pairs: PairOptions::default(),
            matching: MatchOptions::default(),
            keyframes: KeyframeOptions::default(),
            camera_model: "SIMPLE_RADIAL".to_owned(),
            single_camera: true,
            undistort: true,
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
    #[error(transparent)]
    Database(#[from] database::DatabaseError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
    #[error("structure from motion was cancelled")]
    Cancelled,
    #[error("{source}\nwhat was made is kept in {kept} (sfm.json, colmap.log, database.db)")]
    Kept {
        source: Box<SfmError>,
        kept: PathBuf,
    },
}

impl SfmError {
    /// The error itself, without where its partial output was kept.
    pub fn cause(&self) -> &SfmError {
        match self {
            SfmError::Kept { source, .. } => source.cause(),
            other => other,
        }
    }
}

/// What an SfM run did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SfmReport {
    pub photos: usize,
    pub matcher: String,
    /// Photos left out before COLMAP (unreadable, truncated, duplicates).
    pub rejected: Vec<RejectedPhoto>,
    /// Usable photos much less sharp than the capture's median (kept; a likely reason when
    /// they are not registered).
    pub blurred: Vec<photos::BlurredPhoto>,
    /// Cameras (one per photo size with a shared camera).
    pub cameras: usize,
    /// Pairs whose descriptors were matched (Frond's matcher; 0 for COLMAP's).
    pub pairs_matched: usize,
    /// Pairs with a verified two-view geometry, and their inlier matches.
    pub pairs_verified: usize,
    pub inlier_matches: usize,
    /// Photos the retrieval pairs left unregistered, matched with every other photo in a
    /// second pass (Frond's matcher).
    pub second_pass_photos: usize,
    /// Photos the incremental mapper built the model from (Frond's matcher, dense captures;
    /// the others were registered to it and adjusted with it): 0 when every photo was.
    pub keyframes: usize,
    pub registered: usize,
    pub unregistered: Vec<String>,
    pub points: usize,
    pub models: usize,
    pub mean_track_length: f64,
    /// Mean over points of COLMAP's reprojection error, pixels.
    pub mean_reprojection_error_px: f64,
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

/// Runs one COLMAP command, appending its output to `log` and passing each line of its
/// standard output to `on_line` as it comes (for progress).
fn run_colmap(
    options: &SfmOptions,
    step: &str,
    args: &[String],
    log: &Path,
    on_line: &mut dyn FnMut(&str),
) -> Result<f64, SfmError> {
    let started = Instant::now();
    tracing::info!("colmap {}", args.join(" "));
    let mut child = Command::new(&options.colmap)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|_| SfmError::ColmapMissing(options.colmap.clone()))?;
    let stderr = child.stderr.take();
    let stderr_reader = std::thread::spawn(move || {
        let mut text = String::new();
        if let Some(mut stderr) = stderr {
            let _ = stderr.read_to_string(&mut text);
        }
        text
    });
    let mut text = format!("== colmap {}\n", args.join(" "));
    if let Some(stdout) = child.stdout.take() {
        for line in std::io::BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            on_line(&line);
            text.push_str(&line);
            text.push('\n');
        }
    }
    let status = child.wait().map_err(|e| SfmError::Colmap {
        step: step.to_owned(),
        status: e.to_string(),
        log_tail: String::new(),
    })?;
    text.push_str(&stderr_reader.join().unwrap_or_default());
    let mut previous = std::fs::read(log).unwrap_or_default();
    previous.extend_from_slice(text.as_bytes());
    write_atomic(log, &previous).map_err(|e| output_error(log, e))?;
    if !status.success() {
        return Err(SfmError::Colmap {
            step: step.to_owned(),
            status: status.to_string(),
            log_tail: tail(&text, 15),
        });
    }
    Ok(started.elapsed().as_secs_f64())
}

fn path_arg(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// The number in `[k/n]` at the start of a COLMAP progress line such as
/// `Processed file [3/36]`.
fn bracket_count(line: &str) -> Option<u64> {
    let inner = line.split('[').nth(1)?.split(']').next()?;
    inner.split('/').next()?.trim().parse().ok()
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
    progress.stage("structure from motion: checking photos", files.len() as u64);
    let started = Instant::now();
    let check = check_photos(&files);
    progress.advance(files.len() as u64);
    for rejected in &check.rejected {
        tracing::warn!("{}: {}, left out", rejected.photo, rejected.reason);
    }
    if check.usable() < 3 {
        return Err(SfmError::Photos {
            path: photos.clone(),
            message: format!(
                "{} of {} photos are usable; structure from motion needs at least 3. Left out:\n{}",
                check.usable(),
                files.len(),
                check.rejected_summary()
            ),
        });
    }
    let mut report = SfmReport {
        photos: files.len(),
        matcher: format!("{:?}", options.matcher),
        rejected: check.rejected.clone(),
        blurred: check.blurred.clone(),
        ..SfmReport::default()
    };
    if !check.blurred.is_empty() {
        tracing::warn!(
            "{} photos are much less sharp than the rest (blurred?): {}",
            check.blurred.len(),
            check
                .blurred
                .iter()
                .map(|b| format!(
                    "{} ({:.0} % of the median sharpness)",
                    b.photo,
                    100.0 * b.relative_sharpness
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    report
        .timings
        .insert("check".into(), started.elapsed().as_secs_f64());
    let staging = StagedDir::new(out).map_err(|e| output_error(out, e))?;
    let root = staging.path().to_path_buf();
    match run_steps(&photos, &check, &root, options, progress, &mut report) {
        Ok(()) => {
            write_sfm_json(&root, &photos, options, &report, None)?;
            staging.commit().map_err(|e| output_error(out, e))?;
            Ok(report)
        }
        Err(SfmError::Cancelled) => Err(SfmError::Cancelled),
        Err(error) if root.join("database.db").is_file() => {
            // Keep what was made beside the output, without touching an earlier result.
            let kept = failed_folder(out);
            let written = write_sfm_json(&root, &photos, options, &report, Some(&error));
            let moved = written.and_then(|()| {
                let failed = StagedDir::new(&kept).map_err(|e| output_error(&kept, e))?;
                std::fs::remove_dir(failed.path()).map_err(|e| output_error(&kept, e))?;
                std::fs::rename(&root, failed.path()).map_err(|e| output_error(&kept, e))?;
                std::fs::create_dir(&root).map_err(|e| output_error(&root, e))?;
                failed.commit().map_err(|e| output_error(&kept, e))
            });
            match moved {
                Ok(()) => Err(SfmError::Kept {
                    source: Box::new(error),
                    kept,
                }),
                Err(e) => {
                    tracing::warn!("could not keep the partial output: {e}");
                    Err(error)
                }
            }
        }
        Err(error) => Err(error),
    }
}

/// `OUT.failed` beside `OUT`.
fn failed_folder(out: &Path) -> PathBuf {
    let mut name = out
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_else(|| "sfm".into());
    name.push(".failed");
    out.with_file_name(name)
}

fn write_sfm_json(
    root: &Path,
    photos: &Path,
    options: &SfmOptions,
    report: &SfmReport,
    error: Option<&SfmError>,
) -> Result<(), SfmError> {
    let json_path = root.join("sfm.json");
    let json = serde_json::json!({
        "generator": concat!("frond ", env!("CARGO_PKG_VERSION")),
        "status": if error.is_some() { "failed" } else { "done" },
        "error": error.map(|e| e.to_string()),
        "photos_dir": photos,
        "options": options,
        "report": report,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| output_error(&json_path, e))?;
    write_atomic(&json_path, text.as_bytes()).map_err(|e| output_error(&json_path, e))
}

fn check_cancelled(progress: &dyn Progress) -> Result<(), SfmError> {
    if progress.is_cancelled() {
        Err(SfmError::Cancelled)
    } else {
        Ok(())
    }
}

/// Extraction, matching, mapping and undistortion into `root`.
fn run_steps(
    photos: &Path,
    check: &PhotoCheck,
    root: &Path,
    options: &SfmOptions,
    progress: &dyn Progress,
    report: &mut SfmReport,
) -> Result<(), SfmError> {
    let database = root.join("database.db");
    let log = root.join("colmap.log");
    let threads = options.threads.max(1).to_string();
    let s = |v: &str| v.to_owned();
    let usable = check.usable();

    // Features: one extraction per photo size, so each size gets its own shared camera.
    progress.stage("structure from motion: extracting features", usable as u64);
    let groups: Vec<Vec<String>> = if options.single_camera {
        check.groups.iter().map(|g| g.photos.clone()).collect()
    } else {
        let mut all: Vec<String> = check.groups.iter().flat_map(|g| g.photos.clone()).collect();
        all.sort();
        vec![all]
    };
    report.cameras = if options.single_camera {
        groups.len()
    } else {
        usable
    };
    if groups.len() > 1 {
        let sizes: Vec<String> = check
            .groups
            .iter()
            .map(|g| format!("{}×{} ({})", g.width, g.height, g.photos.len()))
            .collect();
        tracing::warn!(
            "the photos have {} sizes: {}; each size gets its own camera",
            sizes.len(),
            sizes.join(", ")
        );
    }
    let mut seconds = 0.0;
    let mut done_before = 0u64;
    for (k, group) in groups.iter().enumerate() {
        let list = root.join(format!("photos_{k}.txt"));
        write_atomic(&list, (group.join("\n") + "\n").as_bytes())
            .map_err(|e| output_error(&list, e))?;
        let extract = vec![
            s("feature_extractor"),
            s("--database_path"),
            path_arg(&database),
            s("--image_path"),
            path_arg(photos),
            s("--image_list_path"),
            path_arg(&list),
            s("--ImageReader.camera_model"),
            options.camera_model.clone(),
            s("--ImageReader.single_camera"),
            s(if options.single_camera { "1" } else { "0" }),
            s("--SiftExtraction.use_gpu"),
            s("0"),
            s("--SiftExtraction.num_threads"),
            threads.clone(),
        ];
        let mut done = done_before;
        seconds += run_colmap(options, "feature extraction", &extract, &log, &mut |line| {
            if line.starts_with("Processed file") && bracket_count(line).is_some() {
                done += 1;
                progress.advance(1);
            }
        })?;
        done_before = done;
        check_cancelled(progress)?;
    }
    report.timings.insert("features".into(), seconds);

    let mut frond = None;
    let mut keyframes: Option<Vec<String>> = None;
    // COLMAP's match lists separate the two photo names by a space.
    let spaced = check
        .groups
        .iter()
        .flat_map(|g| &g.photos)
        .find(|name| name.contains(char::is_whitespace));
    if let (Matcher::Auto, Some(name)) = (&options.matcher, spaced) {
        tracing::warn!(
            "'{name}': COLMAP's match lists cannot name photos with spaces; matching with COLMAP's exhaustive matcher instead (slower; rename the photos to use Frond's)"
        );
        report.matcher = "Exhaustive (photo names with spaces)".into();
        colmap_matching(&database, &log, options, progress, report)?;
    } else if options.matcher == Matcher::Auto {
        progress.stage("structure from motion: choosing pairs", 1);
        let started = Instant::now();
        let matcher = FrondMatcher::open(&database, options)?;
        let pairs = matcher.retrieval_pairs(options);
        progress.advance(1);
        add_timing(report, "pairs", started.elapsed().as_secs_f64());
        tracing::info!(
            "matching {} of {} pairs",
            pairs.len(),
            usable * usable.saturating_sub(1) / 2
        );
        let matcher = frond.insert(matcher);
        matcher.match_and_verify(&pairs, &database, &log, options, progress, report)?;
        check_cancelled(progress)?;
        // A dense capture: the mapper builds the model from keyframes, matched among
        // themselves as a sparser capture would be.
        let chosen = matcher.keyframes(&database, options)?;
        if chosen.len() < matcher.images.len() {
            let pairs = matcher.pairs_among(&chosen, options, true);
            tracing::info!(
                "{} of {} photos are keyframes; matching {} more pairs among them",
                chosen.len(),
                matcher.images.len(),
                pairs.len()
            );
            if !pairs.is_empty() {
                matcher.match_and_verify(&pairs, &database, &log, options, progress, report)?;
            }
            report.keyframes = chosen.len();
            keyframes = Some(
                chosen
                    .iter()
                    .map(|&i| matcher.images[i].name.clone())
                    .collect(),
            );
        }
    } else {
        colmap_matching(&database, &log, options, progress, report)?;
    }
    check_cancelled(progress)?;

    let mapped = root.join("mapped");
    let mut models = map(
        photos,
        &database,
        &mapped,
        &log,
        options,
        progress,
        usable,
        keyframes.as_deref(),
        report,
    )?;
    let usable_names: Vec<&String> = check.groups.iter().flat_map(|g| &g.photos).collect();
    let unregistered = |models: &[(usize, PathBuf, crate::scene::Reconstruction)]| {
        let registered: std::collections::HashSet<&str> = models
            .first()
            .map(|(_, _, best)| best.images().iter().map(|i| i.name.as_str()).collect())
            .unwrap_or_default();
        usable_names
            .iter()
            .filter(|n| !registered.contains(n.as_str()))
            .map(|n| n.to_string())
            .collect::<Vec<String>>()
    };
    // Photos the retrieval pairs did not register are matched with every other photo, and the
    // mapper runs again.
    if let Some(matcher) = &mut frond {
        let missing = unregistered(&models);
        let pairs = matcher.pairs_with(&missing);
        if !missing.is_empty() && !pairs.is_empty() {
            tracing::info!(
                "{} photos not registered: matching them with every other photo ({} more pairs)",
                missing.len(),
                pairs.len()
            );
            report.second_pass_photos = missing.len();
            matcher.match_and_verify(&pairs, &database, &log, options, progress, report)?;
            check_cancelled(progress)?;
            // The first mapping is set aside and kept if the second registers fewer photos
            // (COLMAP's mapper is not deterministic on several threads).
            let first = root.join("mapped_first_pass");
            std::fs::rename(&mapped, &first).map_err(|e| output_error(&first, e))?;
            // The photos registered only now build the model too.
            let keyframes = keyframes.as_ref().map(|list| {
                let mut list = list.clone();
                list.extend(missing.iter().cloned());
                list.sort();
                list
            });
            let second = map(
                photos,
                &database,
                &mapped,
                &log,
                options,
                progress,
                usable,
                keyframes.as_deref(),
                report,
            )?;
            let registered = |m: &[(usize, PathBuf, crate::scene::Reconstruction)]| {
                m.first().map_or(0, |(n, _, _)| *n)
            };
            if registered(&second) >= registered(&models) {
                models = second;
                std::fs::remove_dir_all(&first).map_err(|e| output_error(&first, e))?;
            } else {
                tracing::warn!(
                    "the second mapping registered {} photos, the first {}: keeping the first",
                    registered(&second),
                    registered(&models)
                );
                std::fs::remove_dir_all(&mapped).map_err(|e| output_error(&mapped, e))?;
                std::fs::rename(&first, &mapped).map_err(|e| output_error(&mapped, e))?;
            }
        }
    }
    report.models = models.len();
    report.unregistered = unregistered(&models);
    let sparse = root.join("sparse");
    std::fs::create_dir_all(&sparse).map_err(|e| output_error(&sparse, e))?;
    for (k, (_, path, _)) in models.iter().enumerate() {
        let target = sparse.join(k.to_string());
        std::fs::rename(path, &target).map_err(|e| output_error(&target, e))?;
    }
    std::fs::remove_dir_all(&mapped).map_err(|e| output_error(&mapped, e))?;
    let Some((registered, _, best)) = models.first() else {
        return Err(SfmError::TooFewRegistered {
            registered: 0,
            total: usable,
        });
    };
    report.registered = *registered;
    if *registered < 3 {
        return Err(SfmError::TooFewRegistered {
            registered: *registered,
            total: usable,
        });
    }
    if !report.unregistered.is_empty() {
        let blurred: Vec<&str> = report
            .blurred
            .iter()
            .filter(|b| report.unregistered.contains(&b.photo))
            .map(|b| b.photo.as_str())
            .collect();
        tracing::warn!(
            "{} of {usable} photos not registered in the main model (sparse/0): {}{}{}",
            report.unregistered.len(),
            report.unregistered.join(", "),
            if blurred.is_empty() {
                String::new()
            } else {
                format!("; blurred among them: {}", blurred.join(", "))
            },
            if models.len() > 1 {
                format!("; {} smaller models kept as sparse/1…", models.len() - 1)
            } else {
                String::new()
            }
        );
    }
    report.points = best.points().len();
    let tracks: usize = best.points().iter().map(|p| p.track.len()).sum();
    report.mean_track_length = tracks as f64 / best.points().len().max(1) as f64;
    let errors: Vec<f64> = best
        .points()
        .iter()
        .map(|p| p.error)
        .filter(|e| *e >= 0.0)
        .collect();
    report.mean_reprojection_error_px = errors.iter().sum::<f64>() / errors.len().max(1) as f64;

    if options.undistort {
        progress.stage("structure from motion: undistorting", 1);
        let mut undistort = vec![
            s("image_undistorter"),
            s("--image_path"),
            path_arg(photos),
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
        let seconds = run_colmap(options, "undistortion", &undistort, &log, &mut |_| {})?;
        report.timings.insert("undistortion".into(), seconds);
        progress.advance(1);
    }
    Ok(())
}

/// COLMAP's incremental mapper into `mapped` (emptied first): the models it made, the one
/// with the most registered images first (none when no pair could start a model). With
/// `keyframes`, the mapper builds the models from those photos only; the others are then
/// registered to the main model (`image_registrator`) and one bundle adjustment refines it.
#[allow(clippy::too_many_arguments)]
fn map(
    photos: &Path,
    database: &Path,
    mapped: &Path,
    log: &Path,
    options: &SfmOptions,
    progress: &dyn Progress,
    usable: usize,
    keyframes: Option<&[String]>,
    report: &mut SfmReport,
) -> Result<Vec<(usize, PathBuf, crate::scene::Reconstruction)>, SfmError> {
    progress.stage("structure from motion: mapping", usable as u64);
    if mapped.exists() {
        std::fs::remove_dir_all(mapped).map_err(|e| output_error(mapped, e))?;
    }
    std::fs::create_dir_all(mapped).map_err(|e| output_error(mapped, e))?;
    let s = |v: &str| v.to_owned();
    let mut mapper = vec![
        s("mapper"),
        s("--database_path"),
        path_arg(database),
        s("--image_path"),
        path_arg(photos),
        s("--output_path"),
        path_arg(mapped),
        s("--Mapper.num_threads"),
        options.threads.max(1).to_string(),
    ];
    if let Some(list) = keyframes {
        let path = database.with_file_name("keyframes.txt");
        write_atomic(&path, (list.join("\n") + "\n").as_bytes())
            .map_err(|e| output_error(&path, e))?;
        mapper.extend([s("--image_list_path"), path_arg(&path)]);
    }
    let mut registered_so_far = 0u64;
    let mut on_line = |line: &str| {
        if line.starts_with("Registering image #")
            && let Some(count) = line
                .rsplit('(')
                .next()
                .and_then(|c| c.trim_end_matches(')').trim().parse::<u64>().ok())
            && count > registered_so_far
        {
            progress.advance(count - registered_so_far);
            registered_so_far = count;
        }
    };
    let mapping = run_colmap(options, "mapping", &mapper, log, &mut on_line);
    match mapping {
        Ok(seconds) => add_timing(report, "mapping", seconds),
        // The mapper gives up when no image pair can start a model.
        Err(SfmError::Colmap { log_tail, .. })
            if log_tail.contains("failed to create sparse model") =>
        {
            return Ok(Vec::new());
        }
        Err(e) => return Err(e),
    }
    check_cancelled(progress)?;
    let mut models = Vec::new();
    if let Ok(entries) = std::fs::read_dir(mapped) {
        for entry in entries.flatten() {
            let path = entry.path();
            if let Ok((model, _)) = read_model(&path) {
                models.push((model.images().len(), path, model));
            }
        }
    }
    models.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    if keyframes.is_none() || models.is_empty() {
        return Ok(models);
    }
    // The photos that are not keyframes join the main model by their poses alone (each from
    // its 2D–3D matches); one bundle adjustment then refines every pose, point and the
    // cameras.
    let main = models[0].1.clone();
    let registered = mapped.join("registered.tmp");
    let adjusted = mapped.join("adjusted.tmp");
    for dir in [&registered, &adjusted] {
        std::fs::create_dir_all(dir).map_err(|e| output_error(dir, e))?;
    }
    let threads = options.threads.max(1).to_string();
    let register = vec![
        s("image_registrator"),
        s("--database_path"),
        path_arg(database),
        s("--input_path"),
        path_arg(&main),
        s("--output_path"),
        path_arg(&registered),
        s("--Mapper.num_threads"),
        threads.clone(),
    ];
    let seconds = run_colmap(options, "registration", &register, log, &mut on_line)?;
    add_timing(report, "registration", seconds);
    check_cancelled(progress)?;
    let adjust = vec![
        s("bundle_adjuster"),
        s("--input_path"),
        path_arg(&registered),
        s("--output_path"),
        path_arg(&adjusted),
    ];
    let seconds = run_colmap(options, "bundle adjustment", &adjust, log, &mut |_| {})?;
    add_timing(report, "bundle adjustment", seconds);
    check_cancelled(progress)?;
    std::fs::remove_dir_all(&main).map_err(|e| output_error(&main, e))?;
    std::fs::rename(&adjusted, &main).map_err(|e| output_error(&main, e))?;
    std::fs::remove_dir_all(&registered).map_err(|e| output_error(&registered, e))?;
    let (model, _) = read_model(&main)?;
    models[0] = (model.images().len(), main, model);
    models.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    Ok(models)
}

/// COLMAP's own matcher ([`Matcher::Exhaustive`], [`Matcher::Sequential`],
/// [`Matcher::VocabTree`]) on the database, geometric verification included.
fn colmap_matching(
    database: &Path,
    log: &Path,
    options: &SfmOptions,
    progress: &dyn Progress,
    report: &mut SfmReport,
) -> Result<(), SfmError> {
    let s = |v: &str| v.to_owned();
    let mut matching = match &options.matcher {
        Matcher::Sequential => vec![s("sequential_matcher")],
        Matcher::VocabTree(tree) => vec![
            s("vocab_tree_matcher"),
            s("--VocabTreeMatching.vocab_tree_path"),
            path_arg(tree),
        ],
        Matcher::Exhaustive | Matcher::Auto => vec![s("exhaustive_matcher")],
    };
    matching.extend([
        s("--database_path"),
        path_arg(database),
        s("--SiftMatching.use_gpu"),
        s("0"),
        s("--SiftMatching.num_threads"),
        options.threads.max(1).to_string(),
    ]);
    progress.stage("structure from motion: matching (COLMAP)", 0);
    let seconds = run_colmap(options, "matching", &matching, log, &mut |_| {})?;
    add_timing(report, "matching", seconds);
    let (pairs, inliers) = database::verified_pairs(database)?;
    report.pairs_verified = pairs;
    report.inlier_matches = inliers;
    Ok(())
}

fn add_timing(report: &mut SfmReport, step: &str, seconds: f64) {
    *report.timings.entry(step.to_owned()).or_default() += seconds;
}

/// Frond's matcher over a COLMAP database: the photos' descriptors, the pairs matched so far.
struct FrondMatcher {
    images: Vec<database::DatabaseImage>,
    matched: std::collections::BTreeSet<(usize, usize)>,
    pool: rayon::ThreadPool,
    passes: usize,
}

impl FrondMatcher {
    fn open(database: &Path, options: &SfmOptions) -> Result<Self, SfmError> {
        // As many threads as COLMAP is given.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(options.threads.max(1))
            .build()
            .map_err(|e| output_error(database, format!("no threads for matching: {e}")))?;
        Ok(Self {
            images: database::read_images(database)?,
            matched: Default::default(),
            pool,
            passes: 0,
        })
    }

    /// The first pass's pairs: preemptive retrieval and file-name neighbours.
    fn retrieval_pairs(&self, options: &SfmOptions) -> Vec<(usize, usize)> {
        let all: Vec<usize> = (0..self.images.len()).collect();
        self.pairs_among(&all, options, false)
    }

    /// The keyframes among the photos (indices into `images`, ascending), from the verified
    /// pairs in the database ([`keyframes`]).
    fn keyframes(&self, database: &Path, options: &SfmOptions) -> Result<Vec<usize>, SfmError> {
        let index: std::collections::HashMap<u32, usize> = self
            .images
            .iter()
            .enumerate()
            .map(|(k, image)| (image.image_id, k))
            .collect();
        let pairs: Vec<(usize, usize, usize, Option<f64>)> =
            database::verified_geometries(database)?
                .into_iter()
                .filter_map(|pair| {
                    let (a, b) = pair.image_ids;
                    Some((
                        *index.get(&a)?,
                        *index.get(&b)?,
                        pair.inliers,
                        pair.rotation_deg,
                    ))
                })
                .collect();
        Ok(select_keyframes(
            self.images.len(),
            &pairs,
            &options.keyframes,
        ))
    }

    /// The pairs the retrieval chooses among `subset` alone (as if it were the capture), with
    /// relative neighbours when `diverse` ([`select_pairs_diverse`]), less those matched
    /// already.
    fn pairs_among(
        &self,
        subset: &[usize],
        options: &SfmOptions,
        diverse: bool,
    ) -> Vec<(usize, usize)> {
        let samples: Vec<matching::Descriptors> = subset
            .iter()
            .map(|&k| {
                let image = &self.images[k];
                pairs::preemptive_sample(
                    &image.descriptors,
                    &image.scales,
                    options.pairs.preemptive_features,
                )
            })
            .collect();
        let local = self.pool.install(|| {
            if diverse {
                select_pairs_diverse(&samples, &options.pairs, &options.matching)
            } else {
                select_pairs(&samples, &options.pairs, &options.matching)
            }
        });
        local
            .into_iter()
            .map(|(a, b)| (subset[a], subset[b]))
            .filter(|pair| !self.matched.contains(pair))
            .collect()
    }

    /// Every pair not matched yet that holds one of `photos`.
    fn pairs_with(&self, photos: &[String]) -> Vec<(usize, usize)> {
        let wanted: std::collections::HashSet<&str> = photos.iter().map(String::as_str).collect();
        let n = self.images.len();
        (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .filter(|&(i, j)| {
                (wanted.contains(self.images[i].name.as_str())
                    || wanted.contains(self.images[j].name.as_str()))
                    && !self.matched.contains(&(i, j))
            })
            .collect()
    }

    /// Matches `pairs`, writes them to `matches.txt` (`matches_2.txt`, … for later passes)
    /// beside the database, and has COLMAP verify them.
    fn match_and_verify(
        &mut self,
        pairs: &[(usize, usize)],
        database: &Path,
        log: &Path,
        options: &SfmOptions,
        progress: &dyn Progress,
        report: &mut SfmReport,
    ) -> Result<(), SfmError> {
        self.passes += 1;
        progress.stage("structure from motion: matching pairs", pairs.len() as u64);
        let started = Instant::now();
        let images = &self.images;
        let matched: Vec<Option<Vec<(u32, u32)>>> = self.pool.install(|| {
            pairs
                .par_iter()
                .map(|&(i, j)| {
                    if progress.is_cancelled() {
                        return None;
                    }
                    let found = match_descriptors(
                        &images[i].descriptors,
                        &images[j].descriptors,
                        &options.matching,
                    );
                    progress.advance(1);
                    Some(found)
                })
                .collect()
        });
        check_cancelled(progress)?;
        self.matched.extend(pairs.iter().copied());
        report.pairs_matched += pairs.len();
        // COLMAP verifies pairs with at least this many matches (its min_num_inliers).
        const MIN_MATCHES: usize = 15;
        let mut text = String::new();
        let mut written = 0usize;
        for (&(i, j), found) in pairs.iter().zip(&matched) {
            let Some(found) = found else { continue };
            if found.len() < MIN_MATCHES {
                continue;
            }
            written += 1;
            text.push_str(&format!("{} {}\n", images[i].name, images[j].name));
            for (a, b) in found {
                text.push_str(&format!("{a} {b}\n"));
            }
            text.push('\n');
        }
        let name = match self.passes {
            1 => "matches.txt".to_owned(),
            k => format!("matches_{k}.txt"),
        };
        let list = database.with_file_name(name);
        write_atomic(&list, text.as_bytes()).map_err(|e| output_error(&list, e))?;
        add_timing(report, "matching", started.elapsed().as_secs_f64());
        if written == 0 {
            return Ok(());
        }

        progress.stage("structure from motion: verifying pairs", written as u64);
        let threads = options.threads.max(1).to_string();
        let verify: Vec<String> = [
            "matches_importer",
            "--database_path",
            &path_arg(database),
            "--match_list_path",
            &path_arg(&list),
            "--match_type",
            "raw",
            "--SiftMatching.use_gpu",
            "0",
            "--SiftMatching.num_threads",
            &threads,
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        let seconds = run_colmap(options, "verification", &verify, log, &mut |line| {
            if line.contains(" - ") {
                progress.advance(1);
            }
        })?;
        add_timing(report, "verification", seconds);
        let (verified, inliers) = database::verified_pairs(database)?;
        report.pairs_verified = verified;
        report.inlier_matches = inliers;
        Ok(())
    }
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
        for k in 0..3u8 {
            image::GrayImage::from_fn(32, 32, |x, y| image::Luma([k * 50 + (x ^ y) as u8]))
                .save(dir.path().join(format!("{k}.png")))
                .unwrap();
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
