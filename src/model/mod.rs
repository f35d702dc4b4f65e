//! The plant model (seed 004 §6–7): reconstructed leaves and branches with their meshes and
//! textures, and its exports. The glTF binary export is the evaluation contract: nodes
//! `leaf_NNN` and `branch_NNN` with identity transforms, positions in the input's world frame.
//!
//! Takes leaf meshes with textures and branch meshes ([`PlantModel`]); returns the files
//! written and their counts ([`ExportReport`]).

pub mod gltf;
pub mod plant;

pub use plant::{CompoundGroup, ExportReport, ModelBranch, ModelLeaf, PlantModel};

use std::path::Path;

use nalgebra::Point3;

use crate::scene::ply::{Column, Element, Ply, ScalarType, encode_ply_binary};
use crate::util::atomic::write_atomic;

/// The labelled point cloud of the output contract (`segmentation.ply`): the input points with
/// `x y z red green blue`, `leaf_id` (−1 = not a leaf), `segment_id` (the segment of every
/// label, pot, stem and other as well as leaf, whose label `segments.json` gives; −1 = in no
/// segment) and their ids in the input under the column name given (`point_id` for COLMAP
/// point3D ids).
pub fn segmentation_ply(
    positions: &[Point3<f64>],
    colors: &[[u8; 3]],
    (id_column, point_ids): (&str, &[u64]),
    leaf_ids: &[i64],
    segment_ids: &[i64],
) -> Ply {
    let n = positions.len();
    let coordinate = |name: &str, axis: usize| {
        Column::scalar(
            name,
            ScalarType::F64,
            positions.iter().map(|p| p[axis]).collect(),
        )
    };
    let channel = |name: &str, c: usize| {
        Column::scalar(
            name,
            ScalarType::U8,
            colors.iter().map(|rgb| rgb[c] as f64).collect(),
        )
    };
    Ply {
        comments: vec![
            "frond segmentation: leaf_id -1 = not a leaf, segment_id -1 = in no segment".into(),
        ],
        elements: vec![Element {
            name: "vertex".into(),
            count: n,
            columns: vec![
                coordinate("x", 0),
                coordinate("y", 1),
                coordinate("z", 2),
                channel("red", 0),
                channel("green", 1),
                channel("blue", 2),
                Column::scalar(
                    "leaf_id",
                    ScalarType::I32,
                    leaf_ids.iter().map(|&l| l as f64).collect(),
                ),
                Column::scalar(
                    "segment_id",
                    ScalarType::I32,
                    segment_ids.iter().map(|&s| s as f64).collect(),
                ),
                Column::scalar(
                    id_column,
                    ScalarType::U32,
                    point_ids.iter().map(|&i| i as f64).collect(),
                ),
            ],
        }],
    }
}

/// Writes `segmentation.ply` atomically.
pub fn write_segmentation_ply(path: &Path, ply: &Ply) -> std::io::Result<()> {
    write_atomic(path, &encode_ply_binary(ply))
}
