//! Image-space segmentation (seed 004 §5.4): per-view superpixels and the boundary of a
//! segment's region in a view.

pub mod boundary;
