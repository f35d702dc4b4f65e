//! Small shared utilities: atomic file output, sRGB transfer functions, deterministic random numbers, polygons,
//! order statistics, small geometric solvers.
//!
//! Each takes and returns plain values; none knows about plants.

pub mod atomic;
pub mod color;
pub mod geometry;
pub mod id_hash;
pub mod polygon;
pub mod polyline;
pub mod progress;
pub mod rng;
pub mod stats;
pub mod union_find;
