//! Frond: image-based plant modeling (Quan et al., seed 004).
//!
//! A COLMAP reconstruction of a plant and its photos go in; an editable 3D plant model (leaves
//! as textured meshes, branches as generalized cylinders) comes out. Stages, in data-flow order:
//!
//! - [`scene`]: COLMAP models (text and binary, every camera model), images, dense points.
//! - [`sfm`]: structure from motion by the installed COLMAP (CPU).
//! - [`mvs`]: semi-dense multi-view stereo on the CPU (pairwise semi-global matching, fusion).
//! - [`graph`]: leaf segmentation (kNN graph with 3D/2D weights, threshold partition,
//!   normalized cuts, foreground separation).
//! - [`edit`]: the editing session (commands, undo/redo, project files); [`segment`]: image
//!   boundaries of segments.
//! - [`leaf`]: the generic leaf and its fit to every leaf segment (seed 004 §6).
//! - [`model`]: the plant model and its exports (glb, OBJ, segmentation.ply).
//! - [`mesh`], [`branch`]: triangle meshes and generalized cylinders shared by every stage.
//! - [`render`]: the headless wgpu render core.
//! - [`synth`]: synthetic plants with ground truth; [`eval`]: scoring reconstructions.
//! - [`util`]: atomic file output, deterministic random numbers, progress reporting.

pub mod branch;
pub mod ecosystem;
pub mod edit;
pub mod eval;
pub mod graph;
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
pub mod util;
