//! Fuzzes every text reader: the first byte picks the file kind, the rest is its content.
#![no_main]

use std::path::Path;

use frond::scene::io_text;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(body) else {
        return;
    };
    let path = Path::new("fuzz.txt");
    match kind % 5 {
        0 => drop(io_text::parse_cameras(text, path)),
        1 => drop(io_text::parse_images(text, path)),
        2 => drop(io_text::parse_points(text, path)),
        3 => drop(io_text::parse_rigs(text, path)),
        _ => drop(io_text::parse_frames(text, path)),
    }
});
