//! Frond: image-based plant modeling (Quan et al., seed 004).
//!
//! A COLMAP reconstruction of a plant and its photos (or the photos alone) go in; an editable
//! 3D plant model (leaves as textured meshes, branches as generalized cylinders) comes out.
//! Data flows one way; each stage takes plain data and returns plain data:
//!
//! - [`scene`]: COLMAP models (text and binary, every camera model), images, dense points.
//! - [`sfm`]: structure from motion by the installed COLMAP (CPU); [`mvs`]: semi-dense
//!   multi-view stereo on the CPU (pairwise semi-global matching, fusion).
//! - [`graph`]: the kNN graph with 3D/2D weights, neighbourhoods, normalized cuts, max-flow.
//! - [`segment`]: the automatic leaf segmentation (foreground, threshold partition, normalized
//!   cut), the current labels as plain data, per-view projections and image boundaries.
//! - [`leaf`]: the generic leaf and its fit to every leaf segment (seed 004 §6).
//! - [`branch`]: generalized cylinders, the automatic skeleton, leaf attachment (§7).
//! - [`model`]: the plant model and its exports (glb, OBJ, segmentation.ply).
//! - [`pipeline`]: the whole reconstruction as one call (photos or a COLMAP folder → scene →
//!   segmentation → skeleton → leaves → plant → files) and the writers of its files; the CLI
//!   and the GUI call it.
//! - [`edit`]: the editing session on top of the pipeline (commands, undo/redo, projects).
//! - [`mesh`]: triangle meshes; [`lod`]: levels of detail; [`render`]: the headless wgpu
//!   render core; [`ecosystem`]: plant scenes.
//! - [`synth`]: synthetic plants with ground truth; [`eval`]: scoring reconstructions.
//! - [`util`]: atomic file output, deterministic random numbers, statistics, progress.

pub mod batch;
pub mod branch;
pub mod ecosystem;
pub mod edit;
pub mod eval;
pub mod graph;
pub mod illustrate;
pub mod leaf;
pub mod lod;
pub mod mesh;
pub mod model;
pub mod mvs;
pub mod pipeline;
pub mod render;
pub mod scene;
pub mod segment;
pub mod sfm;
pub mod synth;
pub mod traits;
pub mod util;
