//! Levels of detail for reconstructed plants (seeds 000, 002, 003): simplified levels,
//! screen-space-error selection.

pub mod chain;
pub mod select;
pub mod simplify;
