//! Small shared utilities: atomic file output, deterministic random numbers.

pub mod atomic;
pub mod id_hash;
pub mod progress;
pub mod rng;
