//! Fuzzes every binary reader: the first byte picks the file kind, the rest is its content.
#![no_main]

use std::path::Path;

use frond::scene::{dense, io_binary, ply};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else {
        return;
    };
    let path = Path::new("fuzz.bin");
    match kind % 6 {
        0 => drop(io_binary::parse_cameras(body, path)),
        1 => drop(io_binary::parse_images(body, path)),
        2 => drop(io_binary::parse_points(body, path)),
        3 => drop(io_binary::parse_rigs(body, path)),
        4 => drop(io_binary::parse_frames(body, path)),
        _ => {
            drop(ply::parse_ply(body, path));
            let model = frond::scene::Reconstruction::default();
            drop(dense::parse_visibility(body, path, 3, &model));
        }
    }
});
