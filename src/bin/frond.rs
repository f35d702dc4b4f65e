//! `frond`: the command-line interface. Thin: parses arguments, calls the library, reports.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use frond::eval::{EvalOptions, GroundTruth, Prediction, align_to_ground_truth, evaluate};
use frond::pipeline::ReconstructOptions;
use frond::scene::{ModelFormat, Scene, SceneSource, stats, write_model};
use frond::segment::SegmentOptions;
use frond::synth::{Backdrop, Preset, SynthOptions, write_dataset};
use frond::util::progress::Progress;

#[derive(Parser)]
#[command(
    name = "frond",
    version,
    about = "Image-based plant modeling from COLMAP reconstructions"
)]
struct Cli {
    /// More log output (-v info, -vv debug); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Summarise a COLMAP reconstruction: cameras, images, points, reprojection error, bounds.
    Info {
        #[command(flatten)]
        scene: SceneArgs,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Convert a COLMAP model between text and binary.
    Convert {
        /// A model folder or any project layout `info` accepts.
        input: PathBuf,
        /// Output model folder (created if needed).
        output: PathBuf,
        #[arg(long, value_enum)]
        format: FormatArg,
    },
    /// Render a synthetic plant and write the COLMAP project a user would have, with ground truth.
    Synth {
        /// broadleaf (8–20 large leaves), medium (60–120), smallleaf (hundreds), compound
        /// (3–12 pinnately compound leaves of 7–41 leaflets).
        #[arg(long, default_value = "broadleaf")]
        preset: Preset,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Number of views (two rings).
        #[arg(long, default_value_t = 36)]
        views: usize,
        /// Image size WIDTHxHEIGHT.
        #[arg(long, default_value = "800x600", value_parser = parse_size)]
        size: (u32, u32),
        /// Points kept after visibility filtering.
        #[arg(long, default_value_t = 60_000)]
        points: usize,
        /// 3D point noise (standard deviation) as a fraction of the plant height.
        #[arg(long, default_value_t = 0.001)]
        noise: f64,
        /// Fraction of outlier points.
        #[arg(long, default_value_t = 0.005)]
        outliers: f64,
        /// Leave points3D empty (to run the images through real COLMAP).
        #[arg(long)]
        no_points: bool,
        /// Lay a printed checkerboard (9×7 squares of this many metres) beside the pot, a
        /// scale reference for `frond traits --scale-checkerboard`.
        #[arg(long)]
        checkerboard: Option<f64>,
        /// patterned (terrazzo floor, patterned wall: texture behind every organ) or studio
        /// (a phenotyping cabin's plain dark cloth on floor and wall, as in real scanners).
        #[arg(long, default_value = "patterned")]
        backdrop: Backdrop,
        #[arg(long)]
        out: PathBuf,
    },
    /// Structure from motion with the installed COLMAP on the CPU: photo checks, features,
    /// pairs chosen by image retrieval and matched by Frond, COLMAP's geometric verification,
    /// mapping, undistortion. Writes database.db, matches.txt, sparse/0 (the largest model),
    /// dense/ (undistorted workspace for `frond densify`; --no-undistort skips it), colmap.log
    /// and sfm.json. A failed run keeps what it made in OUT.failed.
    Sfm {
        /// Folder of photos (png, jpg, tif, bmp).
        photos: PathBuf,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        params: SfmArgs,
    },
    /// Semi-dense multi-view stereo on the CPU: pairwise semi-global matching of rectified
    /// views, multi-view consistency and fusion. Writes a dense workspace (sparse/ with the
    /// fused points and their tracks, images/, fused.ply, fused.ply.vis, densify.json).
    Densify {
        #[command(flatten)]
        scene: SceneArgs,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        params: DensifyArgs,
    },
    /// Segment the plant's points into leaves (kNN graph, 3D/2D weights, normalized cuts).
    Segment {
        #[command(flatten)]
        scene: SceneArgs,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        params: SegmentArgs,
    },
    /// Reconstruct a plant from a COLMAP folder, or from a folder of photos (then `sfm` and
    /// `densify` run first, into OUT/sfm and OUT/dense; a COLMAP folder whose points are too
    /// sparse for the leaf graph is densified into OUT/dense first): foreground, segmentation,
    /// image boundaries, leaf fitting, branches, export (plant.glb, plant.obj,
    /// segmentation.ply, segments.json, skeleton.json, report.json).
    Reconstruct {
        #[command(flatten)]
        scene: SceneArgs,
        #[command(flatten)]
        sfm: SfmArgs,
        #[command(flatten)]
        dense: DensifyArgs,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        params: SegmentArgs,
        /// Leaf fitting: `full` (flat fit, boundary warp, deformation), `one-view` (full, but
        /// each leaf's image region from its chosen view alone, not widened by what the other
        /// views confirm), `no-warp` (no affine ICP to the image boundary) or `flat` (PCA
        /// plane and scaling only).
        #[arg(long, value_enum, default_value = "full")]
        fit: FitMode,
        /// The generic leaf: `SEGMENT` (its best view) or `SEGMENT:IMAGE_ID` (a COLMAP image
        /// id); default: the most frontal, best-segmented large leaf.
        #[arg(long, value_parser = parse_template_pick)]
        template: Option<(u32, Option<u32>)>,
        /// Segment a COLMAP folder's points as they are, however sparse.
        #[arg(long)]
        no_densify: bool,
        /// The scale of the traits written at the end (traits.csv, traits.json).
        #[command(flatten)]
        scale: ScaleArgs,
    },
    /// Re-apply a project's edits headlessly, fit the leaves and write what `reconstruct`
    /// writes.
    Replay {
        /// The project file (*.frond).
        project: PathBuf,
        /// Output folder (default: next to the project, named after it with `_out`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Build a plant's levels of detail (simplified levels and a star billboard, each with its
    /// error) and write them as glTF with MSFT_lod.
    Lod {
        /// A plant glb (`frond reconstruct`'s plant.glb, or any glTF binary).
        input: PathBuf,
        /// Output glb.
        #[arg(long)]
        out: PathBuf,
        /// Screen-space error bound λ in pixels for the switch distances and coverages.
        #[arg(long, default_value_t = 4.0)]
        threshold_px: f64,
        /// Triangle fractions of the simplified levels, finest first.
        #[arg(long, value_delimiter = ',', default_value = "0.5,0.25,0.1,0.04,0.015")]
        ratios: Vec<f64>,
        /// Texel height of each billboard tile (0: no billboard level).
        #[arg(long, default_value_t = 256)]
        billboard_tile: u32,
        /// A surfel level of about this many splats before the billboard (0: none); with a
        /// billboard, also compares both with full detail at several on-screen sizes.
        #[arg(long, default_value_t = 0)]
        surfels: usize,
        /// frond (half-edge collapse, better silhouettes) or meshopt (meshoptimizer, faster).
        #[arg(long, value_enum, default_value = "frond")]
        simplifier: SimplifierArg,
        #[arg(long)]
        json: bool,
    },
    /// Place many plants on a terrain (density-map half-toning, approximate instancing into a
    /// few masters) and write the scene: scene.json and plants/master_NN.glb.
    Scene {
        /// Output folder (replaced atomically).
        #[arg(long)]
        out: PathBuf,
        /// Plant glbs to place (default: built-in synthetic plants, see --variants).
        #[arg(long = "plant")]
        plants: Vec<PathBuf>,
        /// Number of built-in synthetic plants (broadleaf and medium, alternating) when no
        /// --plant is given.
        #[arg(long, default_value_t = 12)]
        variants: usize,
        /// Number of plants to place.
        #[arg(long, default_value_t = 1000)]
        count: usize,
        /// Field size in metres, WIDTHxDEPTH.
        #[arg(long, default_value = "40x40", value_parser = parse_field_size)]
        size: (f64, f64),
        /// Grey height map (PNG); default: seeded fractal noise.
        #[arg(long)]
        heightmap: Option<PathBuf>,
        /// Altitude of a white height-map pixel, metres.
        #[arg(long, default_value_t = 2.0)]
        height_scale: f64,
        /// Grey density map (PNG, black = no plants); default: seeded fractal noise.
        #[arg(long)]
        density: Option<PathBuf>,
        /// Master plants after approximate instancing (seed 003: 10–20 per species).
        #[arg(long, default_value_t = 8)]
        masters: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Render a fly-through of a scene offscreen and print per-frame time, draw calls and
    /// triangles (with LOD, at full detail, or both for the speed-up).
    Render {
        /// scene.json written by `frond scene`.
        #[arg(long)]
        scene: PathBuf,
        #[arg(long, default_value_t = 8)]
        frames: usize,
        /// Output folder: frames.csv, render_report.json (and PNGs with --save-frames).
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum, default_value = "both")]
        mode: RenderModeArg,
        /// Image size WIDTHxHEIGHT.
        #[arg(long, default_value = "1280x720", value_parser = parse_size)]
        size: (u32, u32),
        /// Screen-space error bound λ, pixels.
        #[arg(long, default_value_t = 4.0)]
        threshold_px: f64,
        #[arg(long)]
        save_frames: bool,
    },
    /// Score a reconstruction (segmentation.ply, plant.glb) against synthetic ground truth.
    Eval {
        /// The synthetic dataset (with gt/).
        #[arg(long)]
        gt: PathBuf,
        /// The reconstruction's output folder.
        #[arg(long, required_unless_present = "dense")]
        pred: Option<PathBuf>,
        /// Score a dense workspace's points instead (`frond densify` output, or any folder
        /// with fused.ply): points on the plant and their distance to its true surface,
        /// aligned to the truth by the workspace's cameras.
        #[arg(long, conflicts_with_all = ["pred", "pred_model"])]
        dense: Option<PathBuf>,
        /// The COLMAP model the prediction was made from, when it is not the dataset's own
        /// (real COLMAP): the prediction is aligned to the truth by its camera centres.
        #[arg(long)]
        pred_model: Option<PathBuf>,
        /// Score the plant's traits instead (leaf area, length, inclination, branch length;
        /// the truth's traits computed by the same code from its meshes and branches).
        #[arg(long, conflicts_with = "dense")]
        traits: bool,
        #[arg(long)]
        json: bool,
    },
    /// Reconstruct and measure many plants: a manifest (CSV: plant,input[,scale,scale_from,
    /// no_densify]) -> one folder per plant, a combined traits.csv, leaf_area.png and
    /// batch.json. Resumable: complete plants are skipped, interrupted ones redone.
    Batch {
        /// The manifest CSV.
        manifest: PathBuf,
        #[arg(long, required_unless_present = "list")]
        out: Option<PathBuf>,
        /// Print the manifest's plants as JSON (plant, input, photos, scale, no_densify) and
        /// stop: what the Snakemake workflow reads.
        #[arg(long)]
        list: bool,
        /// Plants at a time (default: the cores, fewer when memory is short: 1.5 GiB
        /// per plant).
        #[arg(long)]
        jobs: Option<usize>,
        #[command(flatten)]
        sfm: SfmArgs,
        #[command(flatten)]
        dense: DensifyArgs,
    },
    /// Combine plants' traits.json files into one long table (CSV) and a leaf-area plot.
    Gather {
        /// traits.json files, one per plant.
        #[arg(required = true)]
        tables: Vec<PathBuf>,
        #[arg(long)]
        out: PathBuf,
        /// The leaf-area plot (PNG).
        #[arg(long)]
        plot: PathBuf,
    },
    /// Approximate instancing below the plant (seed 003 on leaves): leaves clustered by shape
    /// into a few master leaves; prints unique meshes, memory and the geometric and pixel
    /// error against the exact leaves for each number of masters, and with --out writes the
    /// instanced plant (nodes sharing master meshes) at the fewest masters within
    /// --max-pixel-error.
    Instancing {
        /// A plant glb (`plant.glb` of a reconstruction, or any glb with leaf nodes).
        input: PathBuf,
        /// Numbers of masters to try.
        #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64")]
        masters: Vec<usize>,
        /// Side of the square views the pixel error is measured on.
        #[arg(long, default_value_t = 320)]
        size: u32,
        /// Write the instanced plant here (glb).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Pixel error allowed for --out (share of the exact leaves' pixels).
        #[arg(long, default_value_t = 0.05)]
        max_pixel_error: f64,
        /// Instance twigs (each tube without child tubes with its leaves) instead of leaves.
        #[arg(long)]
        twigs: bool,
        #[arg(long)]
        json: bool,
    },
    /// Pen-and-ink drawing of a plant (seed 001): branch silhouettes and cross-hatching up to
    /// second-order branches, foliage as abstract primitives outlined where the depth buffer
    /// jumps, shading zones from the light. Writes a PNG and, with --svg, the same strokes as
    /// an editable SVG; with --frames, a slow fly-around and its frame-to-frame coherence.
    Illustrate {
        /// A plant: a glb, a `frond reconstruct` folder or a synthetic dataset (its truth).
        #[arg(required_unless_present = "scene", conflicts_with = "scene")]
        input: Option<PathBuf>,
        /// A scene written by `frond scene` instead of one plant (its terrain hides what is
        /// behind it).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// The drawing (PNG). With --frames N, frames go to STEM_000.png … beside it.
        #[arg(long)]
        out: PathBuf,
        /// Also write the strokes as SVG (layers: shadow, branches, hatching, foliage).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// detailed, abstract, sketchy, thuja or outlines (the seed's figures 7a, 7b, tree II,
        /// 8a, 8b).
        #[arg(long, default_value = "detailed")]
        style: String,
        /// Foliage primitive: disc, ellipse or lower_half (default: the style's).
        #[arg(long)]
        primitive: Option<String>,
        /// Primitive diameter in model units (default: the style's, in units of the median
        /// leaf length).
        #[arg(long)]
        primitive_size: Option<f64>,
        /// Depth difference (model units) above which an outline is drawn.
        #[arg(long)]
        threshold: Option<f64>,
        /// Full-shadow zone: thick, black, hatch or none.
        #[arg(long)]
        shadow: Option<String>,
        /// Branch hatching: surface (sticks to the bark) or screen (the seed's, per frame).
        #[arg(long)]
        hatching: Option<String>,
        /// Highest branch order drawn (0 = the stem).
        #[arg(long)]
        max_branch_order: Option<u32>,
        /// Foliage particle budget.
        #[arg(long)]
        max_particles: Option<usize>,
        /// Image size WIDTHxHEIGHT.
        #[arg(long, default_value = "1200x900", value_parser = parse_size)]
        size: (u32, u32),
        /// View direction YAW,PITCH in degrees (default: three-quarter view from above).
        #[arg(long, value_parser = parse_view)]
        view: Option<(f64, f64)>,
        /// Draw a fly-around of this many frames and report its coherence.
        #[arg(long, default_value_t = 1)]
        frames: usize,
        /// Degrees the camera turns between frames.
        #[arg(long, default_value_t = 0.5)]
        turn: f64,
        #[arg(long)]
        seed: Option<u64>,
    },
    /// The organ sequence along a reconstruction's main stem (internodes and signed
    /// divergence angles), and with --measures its alignment to measured ones (ROMI's
    /// measures.json) with organ-count, internode and angle errors.
    Phyllotaxis {
        /// A `frond reconstruct` output folder.
        reconstruction: PathBuf,
        /// Measured sequence: JSON with `angles` (radians) and `internodes` (millimetres), one
        /// per interval between successive organs. Needs a scale.
        #[arg(long)]
        measures: Option<PathBuf>,
        #[command(flatten)]
        scale: ScaleArgs,
        /// Read a synthetic dataset's ground truth (gt/branches.json, gt/leaves; metres)
        /// instead of a reconstruction.
        #[arg(long, conflicts_with_all = ["scale", "scale_from", "scale_checkerboard", "scale_orbit"])]
        truth: bool,
        /// Which organs on the main stem make the sequence: `branches` compares with measures
        /// of fruits along an inflorescence (ROMI's), which count no leaves.
        #[arg(long, value_enum, default_value = "all")]
        organs: SequenceOrgansArg,
        #[arg(long)]
        json: bool,
    },
    /// Measure a reconstruction's organs: `traits.csv` (long form: plant, organ_id,
    /// organ_type, trait, value, unit) and `traits.json`, written into the folder (or --out).
    Traits {
        /// A `frond reconstruct` output folder (or, with --truth, a synthetic dataset).
        reconstruction: PathBuf,
        /// Plant id in the table (default: the folder's name).
        #[arg(long)]
        plant: Option<String>,
        #[command(flatten)]
        scale: ScaleArgs,
        /// Measure a synthetic dataset's ground truth (gt/leaves, gt/branches.json; metres)
        /// by the same code, e.g. to compare tables.
        #[arg(long, conflicts_with_all = ["scale", "scale_from", "scale_checkerboard", "scale_orbit"])]
        truth: bool,
        /// Where to write the two files (default: the reconstruction folder).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// How model units become metres (COLMAP models are up to scale; without a scale every
/// length is in "model units").
#[derive(Args, Clone, Debug, Default)]
struct ScaleArgs {
    /// Metres per model unit.
    #[arg(long, conflicts_with = "scale_from")]
    scale: Option<f64>,
    /// A known distance between two model points: X1,Y1,Z1:X2,Y2,Z2:METRES (e.g. two
    /// corners of a marker or the ends of a ruler picked in the model).
    #[arg(long, conflicts_with = "scale_checkerboard")]
    scale_from: Option<String>,
    /// A printed checkerboard in the photos: COLSxROWS:SQUARE_METRES, counting inner
    /// corners (e.g. 8x6:0.02 for a board of 9×7 squares of 2 cm), found by OpenCV in the
    /// photos of the reconstruction's scene.
    #[arg(long, conflicts_with_all = ["scale", "scale_orbit"])]
    scale_checkerboard: Option<String>,
    /// The cameras travelled a circle of this radius in metres (a turntable, a rail orbit,
    /// ROMI's plant imager at 0.3): the circle is fitted to the scene's camera centres.
    #[arg(long, conflicts_with_all = ["scale", "scale_from"])]
    scale_orbit: Option<f64>,
}

/// The scene a reconstruction folder was made from (its report.json says which).
fn reconstruction_scene(reconstruction: &Path) -> Result<(PathBuf, Scene)> {
    let report_path = reconstruction.join("report.json");
    let report = frond::pipeline::ReconstructionReport::read(&report_path)
        .with_context(|| format!("reading {}", report_path.display()))?;
    let scene_path = report
        .preparation
        .as_ref()
        .map(|p| p.scene.clone())
        .unwrap_or(report.input.clone());
    let scene = Scene::open(&scene_path)
        .with_context(|| format!("opening the scene {}", scene_path.display()))?;
    Ok((scene_path, scene))
}

impl ScaleArgs {
    /// The scale asked for; a checkerboard is looked for in the photos of the scene the
    /// reconstruction in `reconstruction` was made from (its report.json says which).
    fn scale(&self, reconstruction: &Path) -> Result<Option<frond::traits::Scale>> {
        if let Some(text) = &self.scale_checkerboard {
            let (inner, square) = frond::traits::marker::parse_checkerboard(text)?;
            let (scene_path, scene) = reconstruction_scene(reconstruction)?;
            let (scale, found) = frond::traits::marker::checkerboard_scale(&scene, inner, square)
                .with_context(|| {
                format!("--scale-checkerboard {text} in {}", scene_path.display())
            })?;
            eprintln!(
                "checkerboard in {} photos: {:.6} m per model unit (spread {:.2} %)",
                found.views.len(),
                found.metres_per_unit,
                100.0 * found.relative_spread
            );
            return Ok(Some(scale));
        }
        if let Some(radius) = self.scale_orbit {
            let (scene_path, scene) = reconstruction_scene(reconstruction)?;
            let centres: Vec<_> = scene
                .reconstruction
                .images()
                .iter()
                .map(|image| image.center_world())
                .collect();
            let (scale, residual) = frond::traits::Scale::from_camera_orbit(&centres, radius)
                .with_context(|| {
                    format!(
                        "--scale-orbit {radius} on the cameras of {}",
                        scene_path.display()
                    )
                })?;
            eprintln!("{}", scale.source);
            if residual > 0.05 {
                eprintln!(
                    "warning: the cameras are {:.1} % of the radius off the fitted circle; is the path a circle?",
                    100.0 * residual
                );
            }
            return Ok(Some(scale));
        }
        Ok(match (&self.scale, &self.scale_from) {
            (Some(f), _) => Some(frond::traits::Scale::factor(*f)?),
            (None, Some(text)) => Some(
                frond::traits::Scale::parse_two_points(text)
                    .with_context(|| format!("--scale-from {text}"))?,
            ),
            (None, None) => None,
        })
    }
}

fn phyllotaxis(
    reconstruction: &Path,
    measures: Option<&Path>,
    scale: &ScaleArgs,
    truth: bool,
    which: frond::traits::phyllotaxis::SequenceOrgans,
    json: bool,
) -> Result<()> {
    let name = plant_name(reconstruction);
    let (organs, scale) = if truth {
        let organs = frond::traits::io::read_ground_truth(reconstruction, &name)
            .with_context(|| format!("reading the ground truth of {}", reconstruction.display()))?;
        let mut metres = frond::traits::Scale::factor(1.0)?;
        metres.source = "synthetic ground truth (metres)".into();
        (organs, Some(metres))
    } else {
        let organs = frond::traits::io::read_reconstruction(reconstruction, &name)
            .with_context(|| format!("reading the reconstruction {}", reconstruction.display()))?;
        (organs, scale.scale(reconstruction)?)
    };
    let Some(sequence) = frond::traits::phyllotaxis::stem_sequence_of(&organs, which) else {
        bail!(
            "{}: no main stem with at least two organs of the kind asked for on it",
            reconstruction.display()
        );
    };
    let comparison = match measures {
        Some(path) => {
            let measures = frond::traits::measures::Measures::read(path)?;
            let scale = scale.as_ref().with_context(|| {
                format!(
                    "{} is in millimetres: give a scale (--scale, --scale-from, --scale-checkerboard or --scale-orbit)",
                    path.display()
                )
            })?;
            Some(frond::traits::measures::compare(
                &sequence,
                1000.0 * scale.metres_per_unit,
                &measures,
            ))
        }
        None => None,
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "scale": scale,
                "organs": which,
                "sequence": sequence,
                "comparison": comparison,
            }))?
        );
        return Ok(());
    }
    let (factor, unit) = match &scale {
        Some(s) => (1000.0 * s.metres_per_unit, "mm"),
        None => (1.0, "model units"),
    };
    println!(
        "main stem branch_{:03}: {:.1} {unit}, {} organs",
        sequence.stem,
        sequence.stem_length * factor,
        sequence.organs.len()
    );
    let internodes: Vec<String> = sequence
        .internodes
        .iter()
        .map(|v| format!("{:.1}", v * factor))
        .collect();
    println!("internodes ({unit}): {}", internodes.join(", "));
    let angles: Vec<String> = sequence
        .angles_deg
        .iter()
        .map(|v| v.map_or("–".into(), |v| format!("{v:.0}")))
        .collect();
    println!(
        "divergence angles (deg, counter-clockwise about the stem; – along it): {}",
        angles.join(", ")
    );
    if let Some(comparison) = comparison {
        print!("{}", comparison.to_text());
    }
    Ok(())
}

fn plant_name(folder: &Path) -> String {
    let canonical = folder
        .canonicalize()
        .unwrap_or_else(|_| folder.to_path_buf());
    canonical
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "plant".to_owned())
}

/// Measures a reconstruction folder (or, with `truth`, a synthetic dataset's ground truth, in
/// metres) and writes traits.csv and traits.json into `out` (default: the folder).
fn traits(
    folder: &Path,
    plant: Option<&str>,
    scale: Option<frond::traits::Scale>,
    truth: bool,
    out: Option<&Path>,
) -> Result<frond::traits::TraitTable> {
    let name = plant.map_or_else(|| plant_name(folder), str::to_owned);
    let (organs, scale) = if truth {
        let organs = frond::traits::io::read_ground_truth(folder, &name)
            .with_context(|| format!("reading the ground truth of {}", folder.display()))?;
        let metres = frond::traits::Scale {
            metres_per_unit: 1.0,
            source: "synthetic ground truth (metres)".into(),
        };
        (organs, Some(metres))
    } else {
        let organs = frond::traits::io::read_reconstruction(folder, &name)
            .with_context(|| format!("reading {}", folder.display()))?;
        (organs, scale)
    };
    let table = frond::traits::plant_traits(&organs, scale.as_ref());
    let dir = out.unwrap_or(folder);
    frond::traits::io::write_traits(dir, &table)
        .with_context(|| format!("writing traits into {}", dir.display()))?;
    Ok(table)
}

#[derive(Clone, Copy, ValueEnum)]
enum SequenceOrgansArg {
    /// Child branches and leaves attached to the stem directly.
    All,
    /// Child branches only (fruits, pedicels, side shoots).
    Branches,
    /// Leaves attached to the stem directly only.
    Leaves,
}

impl From<SequenceOrgansArg> for frond::traits::phyllotaxis::SequenceOrgans {
    fn from(arg: SequenceOrgansArg) -> Self {
        match arg {
            SequenceOrgansArg::All => Self::All,
            SequenceOrgansArg::Branches => Self::Branches,
            SequenceOrgansArg::Leaves => Self::Leaves,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum SimplifierArg {
    Frond,
    Meshopt,
}

#[derive(Clone, Copy, ValueEnum)]
enum RenderModeArg {
    /// Screen-space-error LOD selection.
    Lod,
    /// Every plant at full detail.
    Full,
    /// Both on the same path, for the speed-up.
    Both,
}

#[derive(Clone, Copy, ValueEnum)]
enum MatcherArg {
    /// Frond's: pairs chosen by image retrieval and file-name order, matched by Frond,
    /// verified by COLMAP.
    Auto,
    /// COLMAP's exhaustive matcher (every pair).
    Exhaustive,
    /// COLMAP's sequential matcher (file-name neighbours).
    Sequential,
}

/// Structure-from-motion parameters.
#[derive(Args, Clone)]
struct SfmArgs {
    #[arg(long, value_enum, default_value = "auto")]
    matcher: MatcherArg,
    /// Use COLMAP's vocabulary-tree matcher with this tree file (large photo sets).
    #[arg(long, conflicts_with = "matcher")]
    vocab_tree: Option<PathBuf>,
    /// COLMAP camera model of the photos.
    #[arg(long, default_value = "SIMPLE_RADIAL")]
    camera_model: String,
    /// One camera per photo instead of one shared camera.
    #[arg(long)]
    camera_per_photo: bool,
    /// Longest side of the undistorted images (0: as taken).
    #[arg(long, default_value_t = 0)]
    undistorted_size: u32,
    /// Do not write COLMAP's undistorted workspace (dense/); `frond densify --model
    /// OUT/sparse/0 --images PHOTOS` reads the distorted photos directly.
    #[arg(long)]
    no_undistort: bool,
    /// With the auto matcher: the most similar photos matched with each photo.
    #[arg(long, default_value_t = frond::sfm::pairs::PairOptions::default().retrieved)]
    retrieved: usize,
    /// With the auto matcher: neighbours on each side in file-name order matched with each
    /// photo.
    #[arg(long, default_value_t = frond::sfm::pairs::PairOptions::default().sequential)]
    sequential: usize,
    /// With the auto matcher: a photo whose camera is turned less than this (degrees) from a
    /// keyframe's is registered to the model the keyframes build instead of building it
    /// (dense captures map in a fraction of the time); 0 maps every photo incrementally.
    #[arg(long, default_value_t = frond::sfm::keyframes::KeyframeOptions::default().max_angle_deg)]
    keyframe_angle: f64,
}

impl SfmArgs {
    fn options(&self) -> Result<frond::sfm::SfmOptions> {
        if frond::scene::CameraModelKind::from_name(&self.camera_model).is_none() {
            bail!(
                "--camera-model {}: not a COLMAP camera model",
                self.camera_model
            );
        }
        Ok(frond::sfm::SfmOptions {
            matcher: match (&self.vocab_tree, self.matcher) {
                (Some(tree), _) => frond::sfm::Matcher::VocabTree(tree.clone()),
                (None, MatcherArg::Auto) => frond::sfm::Matcher::Auto,
                (None, MatcherArg::Exhaustive) => frond::sfm::Matcher::Exhaustive,
                (None, MatcherArg::Sequential) => frond::sfm::Matcher::Sequential,
            },
            pairs: frond::sfm::pairs::PairOptions {
                retrieved: self.retrieved,
                sequential: self.sequential,
                ..Default::default()
            },
            keyframes: frond::sfm::keyframes::KeyframeOptions {
                max_angle_deg: self.keyframe_angle,
            },
            camera_model: self.camera_model.clone(),
            single_camera: !self.camera_per_photo,
            undistort: !self.no_undistort,
            max_image_size: self.undistorted_size,
            ..frond::sfm::SfmOptions::default()
        })
    }
}

/// Dense stereo parameters.
#[derive(Args, Clone, Copy)]
struct DensifyArgs {
    /// Longest image side used for matching (larger photos are downsized), pixels.
    #[arg(long, default_value_t = 1000)]
    max_image_size: u32,
    /// Fuse only depths within this many median camera distances of the point the views
    /// converge on (0: everything).
    #[arg(long, default_value_t = 1.0)]
    roi_radius: f64,
    /// Semi-global matching block side in pixels (odd; smaller keeps thin stems sharper,
    /// larger is smoother on weak texture).
    #[arg(long, default_value_t = 5)]
    block_size: i32,
    /// Semi-global matching: connected disparity regions smaller than this many pixels are
    /// removed as speckles (0: keep all; small leaves seen a few pixels wide need less than
    /// the default).
    #[arg(long, default_value_t = 100)]
    speckle_window: i32,
    /// Semi-global matching: the best matching cost must beat the second best by this
    /// percentage (lower keeps more depths on weakly textured leaves, for the multi-view
    /// consistency check to sort out).
    #[arg(long, default_value_t = 10)]
    uniqueness: i32,
    /// Stereo partners per view (each gives the view one depth map) whose points every stage
    /// uses. 2 covers weakly textured leaves more completely but adds points along leaf rims
    /// that the skeleton draws as branches (see the README's "Two stereo partners"); the fill
    /// partners below give the leaves that coverage without it.
    #[arg(long, default_value_t = 1)]
    partners: usize,
    /// Further stereo partners per view whose depth maps only fill the gaps the main
    /// partners' points leave (weakly textured leaves); the segmentation leaves those points
    /// out, the leaves and the skeleton use them (see the README's "Gap fills"; 0: none).
    #[arg(long, default_value_t = 1)]
    fill_partners: usize,
    /// Other depth maps that must agree with a depth for it to be kept.
    #[arg(long, default_value_t = 4)]
    min_consistent: usize,
    /// Depths agree when they differ by less than this fraction.
    #[arg(long, default_value_t = 0.01)]
    max_depth_error: f64,
    /// Start a point at every N-th pixel of each depth map (in both directions).
    #[arg(long, default_value_t = 2)]
    pixel_step: usize,
    /// Point spacing: the merge voxel's side in pixel footprints at the object.
    #[arg(long, default_value_t = 1.5)]
    voxel_pixels: f64,
    /// Skip the thin-organ sweep (stems and petioles found as bars in the photos and
    /// triangulated across views).
    #[arg(long)]
    no_thin: bool,
    /// Thin-organ sweep: least colour contrast (RGB distance) of a bar against both sides.
    #[arg(long, default_value_t = 14.0)]
    thin_contrast: f64,
    /// Thin-organ sweep: neighbour views that must see the bar at the same depth.
    #[arg(long, default_value_t = 3)]
    thin_views: usize,
    /// Thin-organ sweep: also sweep bars whose centreline curve is at least this many pixels
    /// but shorter than an organ's (stems seen between leaves, twigs of small-leaved plants);
    /// their points are not marked as thin organs (0: off; 4 was measured).
    #[arg(long, default_value_t = 0)]
    thin_short_bars: usize,
    /// Free-space check: a stereo point is dropped when at least this many depth maps see
    /// past it onto a surface the fusion confirmed, as views from other sides see past the
    /// halo stereo smears beside thin stems against a plain backdrop (0: off).
    #[arg(long, default_value_t = 2)]
    free_space_maps: usize,
    /// Free-space check: and when those are more than this share of the maps with a depth
    /// on the point or past it.
    #[arg(long, default_value_t = 0.5)]
    free_space_share: f64,
    /// Backdrop carving: when the photos' borders show a plain backdrop (a cabin's cloth), a
    /// stereo point is dropped when at least this many photos see that backdrop where it
    /// projects, as they do through the halo beside thin stems (0: off; a patterned
    /// background turns it off by itself).
    #[arg(long, default_value_t = 2)]
    backdrop_views: usize,
}

impl DensifyArgs {
    fn options(&self) -> Result<frond::mvs::DensifyOptions> {
        if self.max_image_size < 64 {
            bail!("--max-image-size must be at least 64 pixels");
        }
        if self.partners == 0 || self.pixel_step == 0 {
            bail!("--partners and --pixel-step must be at least 1");
        }
        if !(self.max_depth_error > 0.0 && self.max_depth_error < 1.0) {
            bail!("--max-depth-error must lie in (0, 1)");
        }
        if self.roi_radius.is_nan() || self.roi_radius < 0.0 {
            bail!("--roi-radius must be 0 or more");
        }
        let mut options = frond::mvs::DensifyOptions {
            max_image_size: self.max_image_size,
            roi_radius: self.roi_radius,
            ..Default::default()
        };
        options.pairs.partners_per_view = self.partners;
        options.pairs.fill_partners_per_view = self.fill_partners;
        if self.block_size < 1 || self.block_size > 21 || self.block_size % 2 == 0 {
            bail!("--block-size must be odd, 1 to 21");
        }
        options.stereo.block_size = self.block_size;
        if self.speckle_window < 0 {
            bail!("--speckle-window must be 0 or more");
        }
        options.stereo.speckle_window = self.speckle_window;
        if !(0..=100).contains(&self.uniqueness) {
            bail!("--uniqueness must be 0 to 100");
        }
        options.stereo.uniqueness_ratio = self.uniqueness;
        options.fusion.min_consistent = self.min_consistent;
        options.fusion.max_relative_depth_error = self.max_depth_error;
        options.free_space.min_maps = self.free_space_maps;
        if !(0.0..=1.0).contains(&self.free_space_share) {
            bail!("--free-space-share must be between 0 and 1");
        }
        options.free_space.share = self.free_space_share;
        options.backdrop.min_views = self.backdrop_views;
        options.fusion.pixel_step = self.pixel_step;
        if self.voxel_pixels.is_nan() || self.voxel_pixels < 0.5 {
            bail!("--voxel-pixels must be at least 0.5");
        }
        options.fusion.voxel_pixels = self.voxel_pixels;
        options.thin.enabled = !self.no_thin;
        if !(self.thin_contrast > 0.0 && self.thin_contrast.is_finite()) {
            bail!("--thin-contrast must be positive");
        }
        options.thin.min_contrast = self.thin_contrast;
        if self.thin_views == 0 || self.thin_views > options.thin.neighbour_views {
            bail!("--thin-views must be 1 to {}", options.thin.neighbour_views);
        }
        options.thin.min_supporting = self.thin_views;
        options.thin.min_short_curve_pixels = self.thin_short_bars;
        Ok(options)
    }
}

/// Segmentation parameters (seed 004 §5.1 defaults).
#[derive(Args, Clone, Copy)]
struct SegmentArgs {
    /// Weight of the image term α (0 = 3D distance only).
    #[arg(long, default_value_t = 0.5)]
    alpha: f64,
    /// Threshold k, in standard deviations of the 3D and 2D distances.
    #[arg(long, default_value_t = 3.0)]
    k: f64,
    /// Nearest neighbours per point K.
    #[arg(long, default_value_t = 3)]
    knn: usize,
    /// Region merging: join two segments whose union is one smooth sheet when at least this
    /// many kNN pairs × √(smaller segment's points) connect them (0 joins every touching pair
    /// that forms a sheet; a large value turns merging off).
    #[arg(long, default_value_t = frond::graph::ncut::NcutOptions::default().min_merge_contact)]
    merge_contact: f64,
}

impl SegmentArgs {
    fn options(&self) -> Result<SegmentOptions> {
        if !(0.0..=1.0).contains(&self.alpha) {
            bail!("--alpha must lie in [0, 1], got {}", self.alpha);
        }
        if self.k <= 0.0 || !self.k.is_finite() {
            bail!("--k must be positive, got {}", self.k);
        }
        if self.knn == 0 {
            bail!("--knn must be at least 1");
        }
        if self.merge_contact < 0.0 || self.merge_contact.is_nan() {
            bail!(
                "--merge-contact must be zero or positive, got {}",
                self.merge_contact
            );
        }
        let mut options = SegmentOptions::default();
        options.graph.alpha = self.alpha;
        options.graph.k = self.k;
        options.graph.knn = self.knn;
        options.ncut.min_merge_contact = self.merge_contact;
        Ok(options)
    }
}

fn parse_view(text: &str) -> Result<(f64, f64), String> {
    let (yaw, pitch) = text
        .split_once(',')
        .ok_or_else(|| format!("'{text}' is not YAW,PITCH (degrees)"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{v}' is not a number of degrees"))
    };
    Ok((parse(yaw)?, parse(pitch)?))
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once('x')
        .ok_or_else(|| format!("'{text}' is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("'{v}' is not a size"))
    };
    Ok((parse(w)?, parse(h)?))
}

/// Shows library progress on an indicatif bar.
struct BarProgress {
    bar: ProgressBar,
}

impl BarProgress {
    fn new() -> Self {
        let bar = ProgressBar::new(0);
        bar.enable_steady_tick(Duration::from_millis(200));
        Self { bar }
    }
}

impl Progress for BarProgress {
    fn stage(&self, name: &str, total: u64) {
        let template = if total > 0 {
            "{msg:24} [{bar:30}] {pos}/{len} [{elapsed}]"
        } else {
            "{spinner} {msg:24} [{elapsed}]"
        };
        self.bar.set_style(
            ProgressStyle::with_template(template)
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.set_message(name.to_owned());
    }
    fn advance(&self, units: u64) {
        self.bar.inc(units);
    }
}

/// Shows a batch's progress: a bar over plants, and each running plant's stage.
struct BatchBar {
    bar: ProgressBar,
    running: std::sync::Mutex<std::collections::BTreeMap<String, String>>,
}

impl BatchBar {
    fn show(&self) {
        if let Ok(running) = self.running.lock() {
            let message: Vec<String> = running.iter().map(|(p, s)| format!("{p}: {s}")).collect();
            self.bar.set_message(message.join(" | "));
        }
    }
}

impl frond::batch::BatchProgress for BatchBar {
    fn plants(&self, total: usize) {
        self.bar.set_length(total as u64);
    }
    fn plant_stage(&self, plant: &str, stage: &str) {
        if let Ok(mut running) = self.running.lock() {
            running.insert(plant.to_owned(), stage.to_owned());
        }
        self.show();
    }
    fn plant_finished(&self, plant: &str, status: frond::batch::PlantStatus) {
        if let Ok(mut running) = self.running.lock() {
            running.remove(plant);
        }
        self.bar.inc(1);
        self.bar
            .println(format!("{plant}: {status:?}").to_lowercase());
        self.show();
    }
}

fn batch(
    manifest: &Path,
    out: &Path,
    jobs: Option<usize>,
    input: frond::pipeline::InputOptions,
) -> Result<()> {
    let entries = frond::batch::read_manifest(manifest)?;
    let options = frond::batch::BatchOptions {
        jobs: jobs.unwrap_or_else(|| frond::batch::default_jobs(3 << 29)),
        input,
        reconstruct: ReconstructOptions::default(),
    };
    let bar = ProgressBar::new(entries.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("plants [{bar:30}] {pos}/{len} [{elapsed}] {wide_msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    let progress = BatchBar {
        bar,
        running: Default::default(),
    };
    let report = frond::batch::run_batch(manifest, &entries, out, &options, &progress)
        .with_context(|| format!("batch {} into {}", manifest.display(), out.display()))?;
    progress.bar.finish_and_clear();
    for plant in report.plants.iter().filter(|p| p.error.is_some()) {
        eprintln!(
            "{} failed: {}",
            plant.plant,
            plant.error.as_deref().unwrap_or("")
        );
    }
    eprintln!(
        "{} done, {} skipped, {} failed of {} plants in {:.1} s ({} at a time) -> {}",
        report.done,
        report.skipped,
        report.failed,
        report.plants.len(),
        report.seconds,
        report.jobs,
        out.display()
    );
    if report.failed > 0 {
        bail!(
            "{} of {} plants failed (see {})",
            report.failed,
            report.plants.len(),
            out.join("batch.json").display()
        );
    }
    Ok(())
}

/// Where the scene is: a folder in any supported layout, or an explicit model (+ images).
#[derive(Args)]
struct SceneArgs {
    /// COLMAP project folder (images/ + sparse/0), dense/0 workspace, or model folder.
    path: Option<PathBuf>,
    /// Explicit model folder (cameras, images, points3D as .bin or .txt).
    #[arg(long, conflicts_with = "path")]
    model: Option<PathBuf>,
    /// Explicit images folder (with --model, or to override the one found).
    #[arg(long)]
    images: Option<PathBuf>,
}

#[derive(Clone, Copy, ValueEnum)]
enum FitMode {
    Full,
    OneView,
    NoWarp,
    Flat,
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Txt,
    Bin,
}

impl From<FormatArg> for ModelFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Txt => ModelFormat::Text,
            FormatArg::Bin => ModelFormat::Binary,
        }
    }
}

impl SceneArgs {
    fn source(&self) -> Result<SceneSource> {
        let mut source = match (&self.path, &self.model) {
            (Some(path), None) => SceneSource::locate(path)
                .with_context(|| format!("finding a COLMAP model in {}", path.display()))?,
            (None, Some(model)) => SceneSource::explicit(model, self.images.as_deref())
                .with_context(|| format!("opening model {}", model.display()))?,
            _ => bail!("give a scene folder or --model"),
        };
        if let Some(images) = &self.images {
            if !images.is_dir() {
                bail!("images folder {} does not exist", images.display());
            }
            source.images_dir = Some(images.clone());
        }
        Ok(source)
    }
}

fn spinner(message: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(message.to_owned());
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

fn load_scene(source: SceneSource) -> Result<Scene> {
    let bar = spinner(&format!("reading {}", source.model_dir.display()));
    let model_dir = source.model_dir.clone();
    let scene = Scene::from_source(source)
        .with_context(|| format!("reading COLMAP model {}", model_dir.display()));
    bar.finish_and_clear();
    scene
}

fn info(scene_args: &SceneArgs, json: bool) -> Result<()> {
    let scene = load_scene(scene_args.source()?)?;
    let bar = spinner("checking images and reprojection errors");
    let summary = stats::summarize(&scene);
    bar.finish_and_clear();
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", summary.to_text());
    }
    Ok(())
}

fn convert(input: &Path, output: &Path, format: ModelFormat) -> Result<()> {
    let source = SceneSource::locate(input)
        .with_context(|| format!("finding a COLMAP model in {}", input.display()))?;
    let scene = load_scene(source)?;
    write_model(output, &scene.reconstruction, format)
        .with_context(|| format!("writing {format} model to {}", output.display()))?;
    eprintln!(
        "wrote {} model ({} cameras, {} images, {} points) to {}",
        format,
        scene.reconstruction.cameras().len(),
        scene.reconstruction.images().len(),
        scene.reconstruction.points().len(),
        output.display()
    );
    Ok(())
}

fn synth(options: &SynthOptions, out: &Path) -> Result<()> {
    let progress = BarProgress::new();
    let summary = write_dataset(options, out, &progress)
        .with_context(|| format!("writing synthetic dataset {}", out.display()))?;
    progress.bar.finish_and_clear();
    eprintln!(
        "wrote {} ({} {}, seed {}): {} leaves, {} branches, {} views, {} points (mean track {:.1}) on {}",
        out.display(),
        summary.preset,
        format_args!("{}x{}", summary.width, summary.height),
        summary.seed,
        summary.leaves,
        summary.branches,
        summary.views,
        summary.points,
        summary.mean_track_length,
        summary.renderer
    );
    let timings: Vec<String> = summary
        .timings
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    eprintln!("timings: {}", timings.join(", "));
    Ok(())
}

fn eval(gt: &Path, pred: &Path, pred_model: Option<&Path>, json: bool) -> Result<()> {
    let truth =
        GroundTruth::load(gt).with_context(|| format!("reading ground truth {}", gt.display()))?;
    let mut prediction =
        Prediction::load(pred).with_context(|| format!("reading prediction {}", pred.display()))?;
    let alignment = match pred_model {
        Some(model) => {
            let (similarity, report) = align_to_ground_truth(gt, model)?;
            prediction.transform(&similarity);
            Some(report)
        }
        None => None,
    };
    let report = evaluate(&truth, &prediction, alignment, &EvalOptions::default())?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    Ok(())
}

/// `frond eval --dense`: point accuracy of a dense workspace against the truth.
fn eval_dense(gt: &Path, dense: &Path, json: bool) -> Result<()> {
    let truth =
        GroundTruth::load(gt).with_context(|| format!("reading ground truth {}", gt.display()))?;
    let source = SceneSource::locate(dense)
        .with_context(|| format!("finding a dense workspace in {}", dense.display()))?;
    let model_dir = source.model_dir.clone();
    let scene = load_scene(source)?;
    let positions: Vec<nalgebra::Point3<f64>> = match &scene.dense {
        Some(points) => points.positions_world.iter().map(|p| p.cast()).collect(),
        None => scene
            .reconstruction
            .points()
            .iter()
            .map(|p| p.position_world)
            .collect(),
    };
    let (similarity, alignment) = align_to_ground_truth(gt, &model_dir)?;
    let aligned: Vec<_> = positions.iter().map(|p| similarity.apply(p)).collect();
    let accuracy = frond::eval::dense::point_accuracy(&truth, &aligned, 0.02)?;
    let thin = frond::eval::dense::thin_organ_accuracy(&truth, &aligned, 0.002)?;
    if json {
        let value = serde_json::json!({
            "alignment": alignment,
            "points": accuracy,
            "thin_organs": thin,
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!(
            "{} points, {} on the plant ({} on leaves; {}/{} leaves with ≥ 20 points)\n\
             distance to the true surface: median {:.3} mm = {:.3} % of the plant height, 90th percentile {:.3} mm\n\
             aligned by {} cameras (RMS residual {:.2} mm)",
            accuracy.points,
            accuracy.plant_points,
            accuracy.leaf_points,
            accuracy.leaves_covered,
            accuracy.leaves_total,
            accuracy.median_error * 1e3,
            accuracy.median_error_fraction_of_height * 100.0,
            accuracy.p90_error * 1e3,
            alignment.cameras_matched,
            alignment.rms_camera_residual * 1e3,
        );
        println!(
            "stems and petioles: {:.1} % of {:.3} m of centreline with a point within radius + {:.0} mm, \
             {:.0} points per metre, median {:.2} mm from the true surface\n\
             halo: {:.1} % of the {} points in the plant's space lie farther than two pixel footprints \
             ({:.2} mm) from every true surface",
            thin.centerline_coverage * 100.0,
            thin.centerline_length,
            thin.near * 1e3,
            thin.points_per_metre,
            thin.median_surface_distance * 1e3,
            thin.halo_fraction * 100.0,
            thin.points_in_plant_space,
            2.0 * thin.pixel_footprint * 1e3,
        );
    }
    Ok(())
}

/// `frond segment`: the automatic segmentation's `segmentation.ply` and `segments.json`.
fn run_segmentation(scene_args: &SceneArgs, params: &SegmentArgs, out: &Path) -> Result<()> {
    let options = params.options()?;
    let scene = load_scene(scene_args.source()?)?;
    let progress = BarProgress::new();
    let segmentation = frond::segment::segment_scene(&scene, &options, &progress)
        .with_context(|| format!("segmenting {}", scene.source.model_dir.display()))?;
    progress.bar.finish_and_clear();
    frond::pipeline::write_automatic_segmentation(&scene, &segmentation, out)
        .with_context(|| format!("writing segmentation to {}", out.display()))?;
    let t = &segmentation.timings;
    eprintln!(
        "{} points ({} on the plant), {} segments, {} leaves -> {}",
        segmentation.points.len(),
        segmentation
            .class_counts()
            .get("plant")
            .copied()
            .unwrap_or(0),
        segmentation.segments.len(),
        segmentation.num_leaves(),
        out.display()
    );
    eprintln!(
        "timings: foreground {:.2} s, gradients {:.2} s, graph {:.2} s, partition {:.2} s, total {:.2} s",
        t.foreground, t.gradients, t.graph, t.partition, t.total
    );
    Ok(())
}

/// `SEGMENT` or `SEGMENT:IMAGE_ID`.
fn parse_template_pick(text: &str) -> Result<(u32, Option<u32>), String> {
    let number = |part: &str, what: &str| {
        part.trim()
            .parse::<u32>()
            .map_err(|_| format!("{what} '{part}' is not a non-negative integer"))
    };
    match text.split_once(':') {
        None => Ok((number(text, "segment")?, None)),
        Some((segment, image)) => Ok((
            number(segment, "segment")?,
            Some(number(image, "image id")?),
        )),
    }
}

fn reconstruct(
    scene_args: &SceneArgs,
    input: &frond::pipeline::InputOptions,
    params: &SegmentArgs,
    fit: FitMode,
    template: Option<(u32, Option<u32>)>,
    out: &Path,
) -> Result<()> {
    let progress = BarProgress::new();
    let (scene, preparation) = match (&scene_args.path, &scene_args.model) {
        (Some(path), None) => frond::pipeline::open_input(path, input, out, &progress)
            .with_context(|| format!("opening {}", path.display()))?,
        _ => {
            let source = scene_args.source()?;
            let given = source.model_dir.clone();
            let scene = load_scene(source)?;
            frond::pipeline::open_scene(scene, &given, input, out, &progress)
                .with_context(|| format!("opening {}", given.display()))?
        }
    };
    progress.bar.finish_and_clear();
    eprintln!("{}", preparation.note);
    let mut options = ReconstructOptions {
        segmentation: params.options()?,
        ..Default::default()
    };
    match fit {
        FitMode::Full => {}
        FitMode::OneView => options.leaves.votes.enabled = false,
        FitMode::NoWarp => options.leaves.fit.use_boundary = false,
        FitMode::Flat => {
            options.leaves.fit.use_boundary = false;
            options.leaves.fit.deform = false;
        }
    }
    if let Some((segment, image_id)) = template {
        let view = match image_id {
            None => None,
            Some(id) => Some(scene.reconstruction.image_position(id).with_context(|| {
                format!("--template {segment}:{id}: no registered image has id {id}")
            })?),
        };
        options.leaves.template = Some(frond::leaf::TemplatePick { segment, view });
    }
    let progress = BarProgress::new();
    let done = frond::pipeline::reconstruct(&scene, &options, Some(&preparation), out, &progress)
        .with_context(|| {
        format!(
            "reconstructing {} into {}",
            scene.source.model_dir.display(),
            out.display()
        )
    })?;
    progress.bar.finish_and_clear();
    let report = &done.report;
    let counts = &report.counts;
    eprintln!(
        "{} points, {} segments; {} leaves fitted ({} skipped), {} branches, {} triangles -> {}",
        counts.points,
        counts.segments,
        counts.leaves_fitted,
        counts.leaves_skipped,
        counts.branches,
        counts.triangles,
        out.display()
    );
    let t = &report.timings;
    eprintln!(
        "timings: segmentation {:.2} s, skeleton {:.2} s, generic leaf {:.2} s, boundaries {:.2} s, fitting {:.2} s, export {:.2} s",
        report.segmentation["timings"]["total"]
            .as_f64()
            .unwrap_or(0.0),
        t.skeleton,
        t.leaves.template,
        t.leaves.boundaries,
        t.leaves.fitting,
        t.export
    );
    Ok(())
}

fn replay(project: &Path, out: Option<&Path>) -> Result<()> {
    let progress = BarProgress::new();
    let mut session = frond::edit::open_project(project, &progress)
        .with_context(|| format!("replaying {}", project.display()))?;
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| {
        let stem = project
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        project.with_file_name(format!("{stem}_out"))
    });
    let options = frond::leaf::LeafOptions::default();
    let leaves = session
        .fit_leaves(&options, &progress)
        .context("reconstructing the leaves")?;
    let report =
        frond::pipeline::write_plant(&session.plant_state(), &leaves, &options, None, &out)
            .with_context(|| format!("writing {}", out.display()))?;
    progress.bar.finish_and_clear();
    eprintln!(
        "replayed {} of {} edits; {} leaves fitted, {} branches -> {}",
        report.edits.applied,
        report.edits.history,
        report.counts.leaves_fitted,
        report.counts.branches,
        out.display()
    );
    Ok(())
}

/// `frond sfm`: COLMAP on a folder of photos.
fn sfm(
    photos: &Path,
    options: &frond::sfm::SfmOptions,
    out: &Path,
) -> Result<frond::sfm::SfmReport> {
    let progress = BarProgress::new();
    let report = frond::sfm::run_sfm(photos, out, options, &progress)
        .with_context(|| format!("structure from motion on {}", photos.display()))?;
    progress.bar.finish_and_clear();
    print_sfm(&report, out);
    Ok(report)
}

fn print_sfm(report: &frond::sfm::SfmReport, out: &Path) {
    println!(
        "COLMAP registered {}/{} photos ({} matching), {} points, {:.1} s; wrote {}",
        report.registered,
        report.photos,
        report.matcher,
        report.points,
        report.timings.values().sum::<f64>(),
        out.display()
    );
    let timings: Vec<String> = report
        .timings
        .iter()
        .map(|(step, seconds)| format!("{step} {seconds:.1} s"))
        .collect();
    println!(
        "{} pairs matched, {} verified; mean reprojection error {:.2} px; {}",
        report.pairs_matched,
        report.pairs_verified,
        report.mean_reprojection_error_px,
        timings.join(", ")
    );
    for rejected in &report.rejected {
        eprintln!("left out {}: {}", rejected.photo, rejected.reason);
    }
    for blurred in &report.blurred {
        eprintln!(
            "blurred? {}: {:.0} % of the capture's median sharpness{}",
            blurred.photo,
            100.0 * blurred.relative_sharpness,
            if report.unregistered.contains(&blurred.photo) {
                " (not registered)"
            } else {
                ""
            }
        );
    }
    if !report.unregistered.is_empty() {
        eprintln!("not registered: {}", report.unregistered.join(", "));
    }
}

/// `frond densify`: dense workspace from a COLMAP scene.
fn densify(scene_args: &SceneArgs, options: &frond::mvs::DensifyOptions, out: &Path) -> Result<()> {
    let scene = load_scene(scene_args.source()?)?;
    let progress = BarProgress::new();
    let (report, points) = frond::pipeline::densify_workspace(&scene, options, out, &progress)
        .with_context(|| {
            format!(
                "densifying {} into {}",
                scene.source.model_dir.display(),
                out.display()
            )
        })?;
    progress.bar.finish_and_clear();
    println!(
        "{} points ({:.1} views each) from {}/{} pairs, {:.1} s; wrote {}",
        points,
        report.mean_views_per_point,
        report.pairs_matched,
        report.pairs,
        report.timings.values().sum::<f64>(),
        out.display()
    );
    Ok(())
}

fn parse_field_size(text: &str) -> Result<(f64, f64), String> {
    let (w, h) = text
        .split_once('x')
        .ok_or_else(|| format!("'{text}' is not WIDTHxDEPTH"))?;
    let parse = |v: &str| match v.trim().parse::<f64>() {
        Ok(x) if x > 0.0 && x.is_finite() => Ok(x),
        _ => Err(format!("'{v}' is not a positive size in metres")),
    };
    Ok((parse(w)?, parse(h)?))
}

fn read_grey(path: &Path) -> Result<image::GrayImage> {
    Ok(image::open(path)
        .with_context(|| format!("reading {}", path.display()))?
        .to_luma8())
}

fn scene_command(
    out: &Path,
    plants: &[PathBuf],
    variants: usize,
    options: &frond::ecosystem::SceneOptions,
) -> Result<()> {
    use frond::ecosystem::folder::{PlantSources, write_scene_folder};
    let sources = if plants.is_empty() {
        PlantSources::BuiltIn(variants)
    } else {
        PlantSources::Files(plants.to_vec())
    };
    let progress = BarProgress::new();
    let scene = write_scene_folder(out, &sources, options, &progress)
        .with_context(|| format!("writing the scene {}", out.display()))?;
    progress.bar.finish_and_clear();
    let q = &scene.quantization;
    println!(
        "{}: {} plants on {:.0}×{:.0} m, {} source plants → {} masters ({:.0} instances per master, RMS log-size change {:.3})",
        out.join("scene.json").display(),
        scene.instances.len(),
        scene.terrain.size_m[0],
        scene.terrain.size_m[1],
        q.source_plants,
        q.masters,
        q.reduction,
        q.rms_log_change
    );
    Ok(())
}

fn render_command(
    scene_path: &Path,
    frames: usize,
    out: &Path,
    mode: RenderModeArg,
    size: (u32, u32),
    threshold_px: f64,
    save_frames: bool,
) -> Result<()> {
    use frond::ecosystem::flythrough::{FlythroughOptions, Mode, run_flythrough};
    if !(threshold_px.is_finite() && threshold_px > 0.0) {
        bail!("--threshold-px must be positive, got {threshold_px}");
    }
    let scene = frond::ecosystem::EcosystemScene::read(scene_path)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut options = FlythroughOptions {
        frames,
        width: size.0,
        height: size.1,
        mode: match mode {
            RenderModeArg::Lod => Mode::Lod,
            RenderModeArg::Full => Mode::Full,
            RenderModeArg::Both => Mode::Both,
        },
        save_frames,
        ..Default::default()
    };
    options.selection.threshold_px = threshold_px;
    let progress = BarProgress::new();
    let report = run_flythrough(&scene, scene_path, out, &options, &progress)
        .with_context(|| format!("rendering {}", scene_path.display()))?;
    progress.bar.finish_and_clear();
    let mut csv = String::from(
        "mode,frame,total_ms,cpu_ms,gpu_ms,draw_calls,instances_drawn,instances_culled,triangles,max_error_px,switches\n",
    );
    for r in &report.frames {
        let mode = serde_json::to_value(r.mode)?;
        csv.push_str(&format!(
            "{},{},{:.2},{:.2},{:.2},{},{},{},{},{:.3},{}\n",
            mode.as_str().unwrap_or("?"),
            r.frame,
            r.total_ms,
            r.cpu_ms,
            r.gpu_ms,
            r.draw_calls,
            r.instances_drawn,
            r.instances_culled,
            r.triangles,
            r.max_error_px,
            r.switches
        ));
        println!(
            "{:>4} frame {:>3}: {:>9.1} ms  {:>5} draws  {:>5} plants drawn ({} culled)  {:>10} triangles  max error {:.2} px",
            mode.as_str().unwrap_or("?"),
            r.frame,
            r.total_ms,
            r.draw_calls,
            r.instances_drawn,
            r.instances_culled,
            r.triangles,
            r.max_error_px
        );
    }
    frond::util::atomic::write_atomic(&out.join("frames.csv"), csv.as_bytes())?;
    frond::util::atomic::write_atomic(
        &out.join("render_report.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    println!(
        "{} plants, {} masters, {}x{} on {}; prepared in {:.1} s",
        report.instances,
        report.masters,
        report.width,
        report.height,
        report.adapter,
        report.prepare_s
    );
    for s in &report.summaries {
        println!(
            "{:?}: mean {:.1} ms (median {:.1}), {:.0} triangles, {:.0} draw calls, max error {:.2} px, ≤ {} switches per plant per second",
            s.mode,
            s.mean_ms,
            s.median_ms,
            s.mean_triangles,
            s.mean_draw_calls,
            s.max_error_px,
            s.max_switches_per_plant_per_second
        );
    }
    if let (Some(speedup), Some(ratio)) = (report.speedup, report.triangle_ratio) {
        println!(
            "LOD vs full detail: {speedup:.1}× faster, {ratio:.1}× fewer triangles, {:.2} % of pixels differ by > 10 %",
            100.0 * report.mean_differing_pixels.unwrap_or(0.0)
        );
    }
    Ok(())
}

fn lod(
    input: &Path,
    out: &Path,
    threshold_px: f64,
    ratios: &[f64],
    (billboard_tile, surfels): (u32, usize),
    simplifier: frond::lod::chain::Simplifier,
    json: bool,
) -> Result<()> {
    use frond::lod::plant::{PlantLodOptions, build_plant_lod};
    if !(threshold_px.is_finite() && threshold_px > 0.0) {
        bail!("--threshold-px must be positive, got {threshold_px}");
    }
    if let Some(bad) = ratios.iter().find(|r| !(**r > 0.0 && **r < 1.0)) {
        bail!("--ratios: {bad} is not a fraction in (0, 1)");
    }
    let asset = frond::lod::asset::PlantAsset::read_glb(input)
        .with_context(|| format!("reading {}", input.display()))?;
    let options = PlantLodOptions {
        chain: frond::lod::chain::ChainOptions {
            simplifier,
            ratios: ratios.to_vec(),
            ..Default::default()
        },
        billboard: (billboard_tile > 0).then(|| frond::lod::billboard::BillboardOptions {
            tile_height: billboard_tile,
            ..Default::default()
        }),
        surfels: (surfels > 0).then_some(surfels),
    };
    let mut renderer = match options.billboard {
        Some(_) => Some(frond::render::Renderer::new().context("starting the renderer")?),
        None => None,
    };
    let clock = std::time::Instant::now();
    let chain = build_plant_lod(
        &asset,
        renderer.as_mut(),
        &options,
        &input.display().to_string(),
    )
    .with_context(|| format!("building the levels of detail of {}", input.display()))?;
    let seconds = clock.elapsed().as_secs_f64();
    frond::util::atomic::write_atomic(out, &chain.to_glb(threshold_px))
        .with_context(|| format!("writing {}", out.display()))?;
    let summary = chain.summary(threshold_px);
    // The billboard against the full plant where it takes over (16 directions, 5° and 30°
    // above the horizon, the render core's default light).
    let switch = match renderer.as_mut() {
        Some(renderer) => chain
            .switch_luminance(renderer, threshold_px, 16, &[5.0, 30.0])
            .context("measuring the billboard's brightness at its switch distance")?,
        None => None,
    };
    // The surfel level against the billboard, both against full detail.
    let far = match (
        renderer.as_mut(),
        chain.levels.iter().find(|l| l.is_billboard),
    ) {
        (Some(renderer), Some(billboard)) if surfels > 0 => {
            let level = frond::lod::surfel::surfel_level(&asset, surfels, 1)
                .context("the plant has no surface for surfels")?;
            Some(
                frond::lod::surfel::compare_far_levels(
                    renderer,
                    &asset,
                    &level,
                    (&billboard.parts, &chain.textures),
                    &[12.0, 24.0, 48.0, 96.0, 192.0],
                )
                .context("comparing the far levels")?,
            )
        }
        _ => None,
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "input": input, "output": out, "seconds": seconds,
                "radius_m": chain.radius, "levels": summary,
                "billboard_switch_luminance": switch,
                "billboard_switch_summary": switch.as_deref().map(frond::lod::plant::summarize_switch),
                "far_levels": far
            }))?
        );
        return Ok(());
    }
    println!(
        "{}: {} levels in {seconds:.2} s (bounding radius {:.3} m), written to {}",
        input.display(),
        summary.len(),
        chain.radius,
        out.display()
    );
    println!(
        "level  triangles  error (mm)  switch at (m, 1080p 60°, {threshold_px} px)  screen coverage"
    );
    for (i, level) in summary.iter().enumerate() {
        println!(
            "{:>5}{} {:>9}  {:>10.3}  {:>38.2}  {:>15.5}",
            i,
            if level.is_billboard { "B" } else { " " },
            level.triangles,
            1e3 * level.error_m,
            level.switch_distance_m,
            level.screen_coverage
        );
    }
    if let Some(checks) = switch.filter(|c| !c.is_empty()) {
        println!("billboard at its switch distance against the full plant:");
        for s in frond::lod::plant::summarize_switch(&checks) {
            println!(
                "  {:>4.0}° up, {} directions: luminance {:+.1} % mean, {:.1} % RMS, {:.1} % worst; \
                 coverage {:.2}×",
                s.elevation_deg,
                s.directions,
                s.mean_percent,
                s.rms_percent,
                s.worst_percent,
                s.coverage_ratio
            );
        }
    }
    if let Some(rows) = far {
        println!(
            "far levels against full detail: diameter (px)  colour difference surfels / billboard  GPU ms full / surfels / billboard"
        );
        for r in rows {
            println!(
                "{:>10.0}  {:>8.3} / {:.3}  {:>8.2} / {:.2} / {:.2}",
                r.diameter_px,
                r.surfel_difference,
                r.billboard_difference,
                r.full_ms,
                r.surfel_ms,
                r.billboard_ms
            );
        }
    }
    Ok(())
}

fn init_logging(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    init_logging(cli.verbose);
    match &cli.command {
        Command::Info { scene, json } => info(scene, *json),
        Command::Convert {
            input,
            output,
            format,
        } => convert(input, output, (*format).into()),
        Command::Synth {
            preset,
            seed,
            views,
            size,
            points,
            noise,
            outliers,
            no_points,
            checkerboard,
            backdrop,
            out,
        } => synth(
            &SynthOptions {
                checkerboard: *checkerboard,
                backdrop: *backdrop,
                preset: *preset,
                seed: *seed,
                views: *views,
                width: size.0,
                height: size.1,
                with_points: !*no_points,
                target_points: *points,
                position_noise: *noise,
                outlier_fraction: *outliers,
                ..SynthOptions::default()
            },
            out,
        ),
        Command::Sfm {
            photos,
            out,
            params,
        } => sfm(photos, &params.options()?, out).map(|_| ()),
        Command::Densify { scene, out, params } => densify(scene, &params.options()?, out),
        Command::Segment { scene, out, params } => run_segmentation(scene, params, out),
        Command::Reconstruct {
            scene,
            sfm: sfm_args,
            dense,
            out,
            params,
            fit,
            template,
            no_densify,
            scale,
        } => {
            let input = frond::pipeline::InputOptions {
                sfm: sfm_args.options()?,
                densify: dense.options()?,
                auto_densify: !*no_densify,
            };
            reconstruct(scene, &input, params, *fit, *template, out)?;
            let table = traits(out, None, scale.scale(out)?, false, None)?;
            eprintln!(
                "{} trait rows -> {}",
                table.rows.len(),
                out.join("traits.csv").display()
            );
            Ok(())
        }
        Command::Replay { project, out } => replay(project, out.as_deref()),
        Command::Scene {
            out,
            plants,
            variants,
            count,
            size,
            heightmap,
            height_scale,
            density,
            masters,
            seed,
        } => {
            let options = frond::ecosystem::SceneOptions {
                count: *count,
                size_m: [size.0, size.1],
                heightmap: heightmap.as_deref().map(read_grey).transpose()?,
                height_scale_m: *height_scale,
                density: density.as_deref().map(read_grey).transpose()?,
                masters: *masters,
                seed: *seed,
                ..Default::default()
            };
            scene_command(out, plants, *variants, &options)
        }
        Command::Render {
            scene,
            frames,
            out,
            mode,
            size,
            threshold_px,
            save_frames,
        } => render_command(
            scene,
            *frames,
            out,
            *mode,
            *size,
            *threshold_px,
            *save_frames,
        ),
        Command::Lod {
            input,
            out,
            threshold_px,
            ratios,
            billboard_tile,
            surfels,
            simplifier,
            json,
        } => lod(
            input,
            out,
            *threshold_px,
            ratios,
            (*billboard_tile, *surfels),
            match simplifier {
                SimplifierArg::Frond => frond::lod::chain::Simplifier::Frond,
                SimplifierArg::Meshopt => frond::lod::chain::Simplifier::Meshopt,
            },
            *json,
        ),
        Command::Eval {
            gt,
            pred,
            pred_model,
            dense: None,
            traits: true,
            json,
        } => {
            let pred = pred.as_deref().context("--traits needs --pred")?;
            let accuracy =
                frond::traits::accuracy::evaluate_traits(gt, pred, pred_model.as_deref())
                    .with_context(|| format!("scoring the traits of {}", pred.display()))?;
            if *json {
                println!("{}", serde_json::to_string_pretty(&accuracy)?);
            } else {
                print!("{}", accuracy.to_text());
            }
            Ok(())
        }
        Command::Batch {
            manifest,
            list: true,
            ..
        } => {
            let entries = frond::batch::read_manifest(manifest)?;
            let plants: Vec<serde_json::Value> = entries
                .iter()
                .map(|e| {
                    serde_json::json!({
                        "plant": e.plant,
                        "input": e.input,
                        "photos": frond::pipeline::is_photo_folder(&e.input),
                        "scale": e.scale.as_ref().map(|s| s.metres_per_unit),
                        "checkerboard": e.checkerboard.as_ref().map(|(inner, square)| {
                            format!("{}x{}:{square}", inner.0, inner.1)
                        }),
                        "no_densify": e.no_densify,
                    })
                })
                .collect();
            println!("{}", serde_json::to_string_pretty(&plants)?);
            Ok(())
        }
        Command::Gather { tables, out, plot } => {
            let mut read = Vec::with_capacity(tables.len());
            for path in tables {
                read.push(
                    frond::traits::io::read_traits(path)
                        .with_context(|| format!("reading {}", path.display()))?,
                );
            }
            frond::batch::write_combined(&read, out, plot)?;
            eprintln!("{} plants -> {}", read.len(), out.display());
            Ok(())
        }
        Command::Batch {
            manifest,
            out,
            jobs,
            sfm: sfm_args,
            dense,
            ..
        } => batch(
            manifest,
            out.as_deref().context("--out is required")?,
            *jobs,
            frond::pipeline::InputOptions {
                sfm: sfm_args.options()?,
                densify: dense.options()?,
                auto_densify: true,
            },
        ),
        Command::Instancing {
            input,
            masters,
            size,
            out,
            max_pixel_error,
            twigs,
            json,
        } => {
            use frond::lod::leaf_instancing as li;
            if masters.is_empty() || masters.contains(&0) {
                bail!("--masters needs positive counts, got {masters:?}");
            }
            if !(max_pixel_error.is_finite() && *max_pixel_error >= 0.0) {
                bail!("--max-pixel-error must be a share >= 0, got {max_pixel_error}");
            }
            let plant = li::read_glb_leaves(input)
                .with_context(|| format!("reading {}", input.display()))?;
            if plant.leaves.is_empty() {
                bail!(
                    "{} has no leaves (nodes named leaf* or cut-out materials)",
                    input.display()
                );
            }
            let twig_list = if *twigs {
                li::twigs(&plant)
            } else {
                Vec::new()
            };
            if *twigs && twig_list.is_empty() {
                bail!(
                    "{} has no twigs (tubes without child tubes that carry leaves)",
                    input.display()
                );
            }
            let items: Vec<_> = if *twigs {
                twig_list.iter().map(|t| t.mesh(&plant)).collect()
            } else {
                plant.leaves.clone()
            };
            let what = if *twigs { "twig" } else { "leaf" };
            let mut renderer = frond::render::Renderer::new().context("starting the renderer")?;
            let curve =
                li::instancing_curve(&mut renderer, &items, &plant.up_world, masters, *size)
                    .with_context(|| format!("measuring the instanced {what}s"))?;
            let chosen = curve
                .iter()
                .filter(|row| row.pixel_error <= *max_pixel_error)
                .min_by_key(|row| row.unique_meshes)
                .or(curve.last());
            if let (Some(out), Some(row)) = (out, chosen) {
                let instancing = li::instance_leaves(&items, row.masters_asked);
                let glb = if *twigs {
                    li::write_instanced_twigs_glb(&plant, &twig_list, &instancing)
                } else {
                    li::write_instanced_glb(&plant, &instancing)
                };
                frond::util::atomic::write_atomic(out, &glb)
                    .with_context(|| format!("writing {}", out.display()))?;
                eprintln!(
                    "{} {what}s as {} masters ({:.1} % pixel error) -> {}",
                    row.leaves,
                    row.unique_meshes,
                    100.0 * row.pixel_error,
                    out.display()
                );
            }
            if *json {
                println!("{}", serde_json::to_string_pretty(&curve)?);
            } else {
                println!(
                    "{} {what}s; masters  memory  max error  median error  pixel error   \
                     (errors in median {what} lengths)",
                    items.len()
                );
                for row in &curve {
                    println!(
                        "{:>7}  {:>5.1} %  {:>9.3}  {:>12.3}  {:>9.2} %",
                        row.unique_meshes,
                        100.0 * row.memory_ratio,
                        row.max_error_lengths,
                        row.median_error_lengths,
                        100.0 * row.pixel_error
                    );
                }
            }
            Ok(())
        }
        Command::Illustrate {
            input,
            scene,
            out,
            svg,
            style,
            primitive,
            primitive_size,
            threshold,
            shadow,
            hatching,
            max_branch_order,
            max_particles,
            size,
            view,
            frames,
            turn,
            seed,
        } => {
            use frond::illustrate::{self as ill, parse_choice};
            let (input, plant) = match (input, scene) {
                (_, Some(scene)) => (scene, ill::read_sketch_scene(scene)?),
                (Some(input), None) => (
                    input,
                    ill::SketchScene::single(ill::read_sketch_plant(input)?),
                ),
                (None, None) => bail!("give a plant (glb or folder) or --scene scene.json"),
            };
            let style: ill::Style = parse_choice("--style", style, ill::STYLES)?;
            let overrides = ill::Overrides {
                primitive: primitive
                    .as_deref()
                    .map(|t| parse_choice("--primitive", t, ill::PRIMITIVES))
                    .transpose()?,
                size: *primitive_size,
                threshold: *threshold,
                shadow: shadow
                    .as_deref()
                    .map(|t| parse_choice("--shadow", t, ill::SHADOWS))
                    .transpose()?,
                hatching: hatching
                    .as_deref()
                    .map(|t| parse_choice("--hatching", t, ill::HATCHINGS))
                    .transpose()?,
                max_branch_order: *max_branch_order,
                max_particles: *max_particles,
                seed: *seed,
            };
            let options = overrides.apply(style.options(plant.median_leaf_length()));
            options.validate()?;
            let views = ill::orbit_views(&plant, size.0, size.1, *view, *frames, *turn)?;
            let mut renderer = frond::render::Renderer::new()?;
            let progress = BarProgress::new();
            let report = ill::illustrate_to_files(
                &mut renderer,
                &plant,
                &input.display().to_string(),
                &options,
                &views,
                ill::Outputs {
                    png: out,
                    svg: svg.as_deref(),
                },
                &progress,
            )
            .with_context(|| format!("drawing {}", input.display()))?;
            progress.bar.finish_and_clear();
            if let Some(first) = report.frames.first() {
                let s = &first.stats;
                eprintln!(
                    "{} particles ({} lit, {} half shadow, {} full shadow), {} branches; {} strokes \
                     (branches {}, hatching {}, foliage {}, shadow {}) -> {}",
                    s.particles,
                    s.particles_by_zone[0],
                    s.particles_by_zone[1],
                    s.particles_by_zone[2],
                    s.branches_drawn,
                    s.strokes,
                    s.strokes_by_layer[1],
                    s.strokes_by_layer[2],
                    s.strokes_by_layer[3],
                    s.strokes_by_layer[0],
                    first.png
                );
            }
            if let Some(c) = &report.coherence {
                let layers: Vec<String> = c
                    .by_layer
                    .iter()
                    .map(|(name, l)| format!("{name} {:.1} %", 100.0 * l.mean_stable_ink))
                    .collect();
                eprintln!(
                    "coherence over {} frames ({:.2} px of motion per frame): {:.1} % of the ink \
                     stays put (worst pair {:.1} %); {}",
                    c.frames,
                    c.all.mean_motion_px,
                    100.0 * c.all.mean_stable_ink,
                    100.0 * c.all.min_stable_ink,
                    layers.join(", ")
                );
            }
            Ok(())
        }
        Command::Phyllotaxis {
            reconstruction,
            measures,
            scale,
            truth,
            organs,
            json,
        } => phyllotaxis(
            reconstruction,
            measures.as_deref(),
            scale,
            *truth,
            (*organs).into(),
            *json,
        ),
        Command::Traits {
            reconstruction,
            plant,
            scale,
            truth,
            out,
        } => {
            let scale = if *truth {
                None
            } else {
                scale.scale(reconstruction)?
            };
            let table = traits(
                reconstruction,
                plant.as_deref(),
                scale,
                *truth,
                out.as_deref(),
            )?;
            let leaves = table.value("plant", "leaf_count").unwrap_or(0.0);
            let unit = if table.scale.is_some() {
                "m"
            } else {
                "model units"
            };
            eprintln!(
                "{} rows ({} leaves, lengths in {unit}) -> {}",
                table.rows.len(),
                leaves,
                out.as_deref()
                    .unwrap_or(reconstruction)
                    .join("traits.csv")
                    .display()
            );
            Ok(())
        }
        Command::Eval {
            gt,
            pred,
            pred_model,
            dense,
            json,
            ..
        } => match (pred, dense) {
            (_, Some(dense)) => eval_dense(gt, dense, *json),
            (Some(pred), None) => eval(gt, pred, pred_model.as_deref(), *json),
            (None, None) => bail!("give --pred or --dense"),
        },
    }
}
