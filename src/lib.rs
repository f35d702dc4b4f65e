//! Frond: image-based plant modeling (Quan et al., seed 004).
//!
//! A COLMAP reconstruction of a plant and its photos go in; an editable 3D plant model (leaves
//! as textured meshes, branches as generalized cylinders) comes out. Stages, in data-flow order:
//!
//! - [`scene`]: COLMAP models (text and binary, every camera model), images, dense points.
//! - [`util`]: atomic file output and deterministic random numbers shared by all stages.

pub mod scene;
pub mod util;
