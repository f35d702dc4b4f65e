//! Small shared utilities: atomic file output, deterministic random numbers.

pub mod atomic;
pub mod rng;
