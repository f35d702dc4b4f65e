//! Small shared utilities: atomic file output, deterministic random numbers, polygons.

pub mod atomic;
pub mod id_hash;
pub mod polygon;
pub mod polyline;
pub mod progress;
pub mod rng;
