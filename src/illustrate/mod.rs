//! Pen-and-ink illustration of plants (seed 001, Deussen 2003, §4), a non-photorealistic render
//! mode on the render core.
//!
//! - `plant`: preprocessing: the skeleton (generalized cylinders with branching order; only up
//!   to `max_branch_order` is drawn), foliage particles (position + leaf normal) reduced to a
//!   budget, and the crown's three shading zones.
//! - `draw`: one frame: the GPU renders view-facing foliage primitives and the branch tubes,
//!   computes the depth-difference buffer (render core, `depth_difference`), and strokes are
//!   extracted: primitive outlines where a primitive lies in front of its neighbours by more
//!   than the threshold, analytic silhouettes of the branches, cross-hatching by error
//!   diffusion of stroke coverage, and the full-shadow zone as thick lines, black areas or
//!   hatching.
//! - `output`: the drawing as a PNG (strokes rasterised anti-aliased) and as an SVG of the same
//!   strokes in layers (shadow, branches, hatching, foliage), so an illustrator can edit it.
//! - `coherence`: how much ink stays put between frames of a slow fly-through.
//!
//! Sizes follow the plant: a style sets the primitive size and the depth threshold in units of
//! the median leaf length, so the same style draws a seedling and a shrub alike.

pub mod coherence;
pub mod draw;
pub mod output;
pub mod plant;

use serde::{Deserialize, Serialize};

pub use draw::{Drawing, DrawingStats, Layer, PreparedSketch, SketchScene, Stroke};
pub use plant::{Particle, SketchBranch, SketchPlant, Zone, read_sketch_plant};

/// Why an illustration failed.
#[derive(Debug, thiserror::Error)]
pub enum IllustrateError {
    #[error("{path}: {message}")]
    Input { path: String, message: String },
    #[error("nothing to draw: {0}")]
    Empty(String),
    #[error("option {name}: {message}")]
    Option { name: &'static str, message: String },
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
    #[error("drawing the strokes: {0}")]
    Raster(String),
}

/// The abstract primitive standing for foliage (seed 001 §4.2, §4.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Primitive {
    /// View-facing discs (Fig. 7).
    Disc,
    /// View-facing ellipses of random orientation with slightly jittered outlines (Tree II).
    Ellipse,
    /// Ellipses of which only the lower half of the outline is drawn (Fig. 8a, the thuja).
    LowerHalf,
}

/// How the full-shadow zone is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShadowStyle {
    /// Outlines drawn twice as thick.
    Thick,
    /// The zone filled black.
    Black,
    /// The zone hatched with diagonal strokes.
    Hatch,
    /// No zones: every outline alike (Fig. 8b).
    None,
}

/// Where branch cross-hatching strokes are placed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Hatching {
    /// Error diffusion over a grid on the branch surface (along and around the stem): strokes
    /// stick to the bark as the camera moves.
    Surface,
    /// Error diffusion over the image pixels of each frame, as the seed does; strokes follow the
    /// stem's projected direction but are placed anew every frame.
    Screen,
}

/// Named styles reproducing the seed's figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    /// Fig. 7a: small discs, low threshold: many leaf outlines.
    Detailed,
    /// Fig. 7b: large discs, high threshold: the crown as a few masses, shadow in black.
    Abstract,
    /// Tree II: random ellipses with sketchy outlines, black shadow.
    Sketchy,
    /// Fig. 8a: lower halves of ellipses with a very small threshold.
    Thuja,
    /// Fig. 8b: every visible outline with a small threshold, no zones.
    Outlines,
}

/// Everything that decides a drawing. Sizes are in model units (the plant's).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IllustrateOptions {
    pub style: Style,
    pub primitive: Primitive,
    /// Diameter of a foliage primitive.
    pub size: f64,
    /// Depth difference above which an outline is drawn.
    pub threshold: f64,
    pub shadow: ShadowStyle,
    pub hatching: Hatching,
    /// Branches up to this order are drawn (0 = the stem only; the seed draws up to 2).
    pub max_branch_order: u32,
    /// Foliage particle budget (the seed reduces 183,000 leaves to 8,800 particles).
    pub max_particles: usize,
    /// Leaf layers between a particle and the light from which it is in full shadow.
    pub full_shadow_layers: f64,
    /// Light elevation above the horizon and azimuth about up (degrees).
    pub light_elevation_deg: f64,
    pub light_azimuth_deg: f64,
    /// Pen width in pixels.
    pub pen_px: f64,
    /// Spacing of hatching strokes in pixels (at the first view's distance).
    pub hatch_spacing_px: f64,
    pub seed: u64,
}

impl Style {
    /// The style's options for a plant whose median leaf is `leaf_length` long: primitive size
    /// and threshold in units of the leaf (seed Fig. 7: size 0.15 vs 0.7, threshold 1000 vs
    /// 2000 depth units, i.e. a ≈4.7× larger primitive and a doubled threshold for the abstract
    /// look).
    pub fn options(self, leaf_length: f64) -> IllustrateOptions {
        let base = IllustrateOptions {
            style: self,
            primitive: Primitive::Disc,
            size: 0.3 * leaf_length,
            threshold: 0.15 * leaf_length,
            shadow: ShadowStyle::Thick,
            hatching: Hatching::Surface,
            max_branch_order: 2,
            max_particles: 8000,
            full_shadow_layers: 1.5,
            light_elevation_deg: 55.0,
            light_azimuth_deg: 135.0,
            pen_px: 1.0,
            hatch_spacing_px: 4.0,
            seed: 1,
        };
        match self {
            Style::Detailed => base,
            Style::Abstract => IllustrateOptions {
                size: 1.4 * leaf_length,
                threshold: 0.5 * leaf_length,
                shadow: ShadowStyle::Black,
                pen_px: 1.5,
                ..base
            },
            Style::Sketchy => IllustrateOptions {
                primitive: Primitive::Ellipse,
                size: 0.5 * leaf_length,
                threshold: 0.3 * leaf_length,
                shadow: ShadowStyle::Black,
                ..base
            },
            Style::Thuja => IllustrateOptions {
                primitive: Primitive::LowerHalf,
                size: 0.3 * leaf_length,
                threshold: 0.03 * leaf_length,
                ..base
            },
            Style::Outlines => IllustrateOptions {
                primitive: Primitive::Ellipse,
                size: 0.3 * leaf_length,
                threshold: 0.05 * leaf_length,
                shadow: ShadowStyle::None,
                ..base
            },
        }
    }
}

impl IllustrateOptions {
    /// Rejects sizes that cannot draw anything.
    pub fn validate(&self) -> Result<(), IllustrateError> {
        let positive = |name: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(IllustrateError::Option {
                    name,
                    message: format!("must be a positive number, got {v}"),
                })
            }
        };
        positive("size", self.size)?;
        positive("threshold", self.threshold)?;
        positive("pen width", self.pen_px)?;
        positive("hatch spacing", self.hatch_spacing_px)?;
        positive("full shadow layers", self.full_shadow_layers)?;
        if self.max_particles == 0 {
            return Err(IllustrateError::Option {
                name: "max particles",
                message: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// Parses one of the snake_case names of an option enum ([`Style`], [`Primitive`],
/// [`ShadowStyle`], [`Hatching`]); the error lists what is accepted.
pub fn parse_choice<T: serde::de::DeserializeOwned>(
    name: &'static str,
    text: &str,
    accepted: &[&str],
) -> Result<T, IllustrateError> {
    serde_json::from_value(serde_json::Value::String(text.trim().to_owned())).map_err(|_| {
        IllustrateError::Option {
            name,
            message: format!("'{text}' is not one of {}", accepted.join(", ")),
        }
    })
}

/// The names [`parse_choice`] accepts, per enum.
pub const STYLES: &[&str] = &["detailed", "abstract", "sketchy", "thuja", "outlines"];
pub const PRIMITIVES: &[&str] = &["disc", "ellipse", "lower_half"];
pub const SHADOWS: &[&str] = &["thick", "black", "hatch", "none"];
pub const HATCHINGS: &[&str] = &["surface", "screen"];

/// Views of a drawing: the plant framed from `(yaw, pitch)` (degrees; default the orbit's
/// three-quarter view), then `frames − 1` more turning `turn_deg` each about the plant's up
/// (a slow fly-around).
pub fn orbit_views(
    plant: &SketchScene,
    width: u32,
    height: u32,
    view_deg: Option<(f64, f64)>,
    frames: usize,
    turn_deg: f64,
) -> Result<Vec<crate::render::ViewCamera>, IllustrateError> {
    let points = plant.points();
    let mut orbit = crate::render::Orbit::framing(&points, &plant.up_world)
        .ok_or_else(|| IllustrateError::Empty("the plant has no geometry to frame".into()))?;
    if let Some((yaw, pitch)) = view_deg {
        orbit.yaw = yaw.to_radians();
        orbit.pitch = pitch.to_radians().clamp(-1.5, 1.5);
    }
    Ok((0..frames.max(1))
        .map(|k| {
            let mut view = orbit;
            view.yaw += (turn_deg * k as f64).to_radians();
            view.view_camera(width, height)
        })
        .collect())
}

/// Options of a style with the user's overrides applied (`None` keeps the style's value).
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    pub primitive: Option<Primitive>,
    pub size: Option<f64>,
    pub threshold: Option<f64>,
    pub shadow: Option<ShadowStyle>,
    pub hatching: Option<Hatching>,
    pub max_branch_order: Option<u32>,
    pub max_particles: Option<usize>,
    pub seed: Option<u64>,
}

impl Overrides {
    pub fn apply(&self, mut options: IllustrateOptions) -> IllustrateOptions {
        if let Some(v) = self.primitive {
            options.primitive = v;
        }
        if let Some(v) = self.size {
            options.size = v;
        }
        if let Some(v) = self.threshold {
            options.threshold = v;
        }
        if let Some(v) = self.shadow {
            options.shadow = v;
        }
        if let Some(v) = self.hatching {
            options.hatching = v;
        }
        if let Some(v) = self.max_branch_order {
            options.max_branch_order = v;
        }
        if let Some(v) = self.max_particles {
            options.max_particles = v;
        }
        if let Some(v) = self.seed {
            options.seed = v;
        }
        options
    }
}

/// The name and version of the illustration report (`STEM.json` beside the drawing).
pub const REPORT_FORMAT: &str = "frond illustration";
pub const REPORT_VERSION: u32 = 1;

/// What `frond illustrate` wrote and measured.
#[derive(Clone, Debug, Serialize)]
pub struct IllustrationReport {
    pub format: String,
    pub version: u32,
    pub input: String,
    pub options: IllustrateOptions,
    pub median_leaf_length: f64,
    pub branches_drawn: usize,
    pub hatch_cell: f64,
    pub frames: Vec<FrameReport>,
    /// Frame-to-frame coherence of a fly-around (more than one frame).
    pub coherence: Option<coherence::CoherenceReport>,
    pub adapter: String,
}

/// One written frame.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    pub png: String,
    pub svg: Option<String>,
    pub stats: DrawingStats,
    /// Wall-clock seconds to draw it (GPU pass, readback and stroke extraction).
    pub seconds: f64,
}

/// Where frame `k` of `count` goes: `out` itself for a single frame, else `STEM_kkk.EXT`.
pub fn frame_path(out: &std::path::Path, k: usize, count: usize) -> std::path::PathBuf {
    if count <= 1 {
        return out.to_path_buf();
    }
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "drawing".into());
    let ext = out
        .extension()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "png".into());
    out.with_file_name(format!("{stem}_{k:03}.{ext}"))
}

/// Where `illustrate_to_files` writes: the drawing (`STEM_kkk.png` per frame of a
/// fly-around), the first view's SVG, and `STEM.json`.
#[derive(Clone, Copy, Debug)]
pub struct Outputs<'a> {
    pub png: &'a std::path::Path,
    pub svg: Option<&'a std::path::Path>,
}

/// Draws `plant` from every view and writes the PNGs (and the first view's SVG), each
/// atomically, then `STEM.json` (the report, also returned). `progress` advances per frame.
pub fn illustrate_to_files(
    renderer: &mut crate::render::Renderer,
    plant: &SketchScene,
    input: &str,
    options: &IllustrateOptions,
    views: &[crate::render::ViewCamera],
    outputs: Outputs<'_>,
    progress: &dyn crate::util::progress::Progress,
) -> Result<IllustrationReport, IllustrateError> {
    let (out, svg) = (outputs.png, outputs.svg);
    use crate::util::atomic::write_atomic;
    let write = |path: &std::path::Path, bytes: &[u8]| {
        write_atomic(path, bytes).map_err(|e| IllustrateError::Input {
            path: path.display().to_string(),
            message: format!("writing: {e}"),
        })
    };
    let first = views
        .first()
        .ok_or_else(|| IllustrateError::Empty("no view to draw from".into()))?;
    let prepared = PreparedSketch::new(plant, options, first)?;
    progress.stage("drawing", views.len() as u64);
    let mut frames = Vec::with_capacity(views.len());
    // A fly-around keeps its frames (and their rasters) for the coherence measurement.
    let (mut kept, mut kept_rasters) = (Vec::new(), Vec::new());
    for (k, view) in views.iter().enumerate() {
        let start = std::time::Instant::now();
        let drawing = prepared.draw(renderer, view)?;
        let raster = drawing.raster()?;
        let seconds = start.elapsed().as_secs_f64();
        let png_path = frame_path(out, k, views.len());
        write(&png_path, &output::png_bytes(&raster)?)?;
        let svg_path = match (k, svg) {
            (0, Some(path)) => {
                write(path, drawing.svg()?.as_bytes())?;
                Some(path.display().to_string())
            }
            _ => None,
        };
        frames.push(FrameReport {
            png: png_path.display().to_string(),
            svg: svg_path,
            stats: drawing.stats.clone(),
            seconds,
        });
        if views.len() > 1 {
            kept.push(drawing);
            kept_rasters.push(raster);
        }
        progress.advance(1);
    }
    let report = IllustrationReport {
        format: REPORT_FORMAT.into(),
        version: REPORT_VERSION,
        input: input.to_owned(),
        options: options.clone(),
        median_leaf_length: plant.median_leaf_length(),
        branches_drawn: plant
            .plants
            .iter()
            .flat_map(|p| &p.branches)
            .filter(|b| b.order <= options.max_branch_order)
            .count(),
        hatch_cell: prepared.hatch_cell,
        frames,
        coherence: if kept.len() > 1 {
            Some(coherence::coherence(&kept, &kept_rasters)?)
        } else {
            None
        },
        adapter: renderer.adapter_description(),
    };
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| IllustrateError::Raster(e.to_string()))?;
    write(&out.with_extension("json"), json.as_bytes())?;
    Ok(report)
}

/// A scene written by `frond scene` as a drawing: every instance's master (read once per
/// master) moved to its place, and the terrain, which hides what stands behind it. Each plant's
/// up becomes the world's +z, the terrain's up.
pub fn read_sketch_scene(path: &std::path::Path) -> Result<SketchScene, IllustrateError> {
    let scene =
        crate::ecosystem::EcosystemScene::read(path).map_err(|e| IllustrateError::Input {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
    let mut masters = Vec::with_capacity(scene.plants.len());
    for k in 0..scene.plants.len() {
        masters.push(SketchPlant::from_glb(&scene.plant_path(path, k))?);
    }
    let mut plants = Vec::with_capacity(scene.instances.len());
    for instance in &scene.instances {
        let Some(master) = masters.get(instance.plant) else {
            return Err(IllustrateError::Input {
                path: path.display().to_string(),
                message: format!(
                    "an instance names plant {} of {}",
                    instance.plant,
                    masters.len()
                ),
            });
        };
        let world_from_plant = instance.world_from_plant(&scene.plants[instance.plant]);
        let mut plant = master.transformed(&world_from_plant);
        plant.up_world = nalgebra::Vector3::z();
        plants.push(plant);
    }
    Ok(SketchScene {
        plants,
        terrain: Some(scene.terrain.mesh(1.0)),
        up_world: nalgebra::Vector3::z(),
    })
}
