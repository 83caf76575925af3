//! What every command-line test does: run the binary this package built and read its answer.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `seasonstereo ARGS…` to the end.
pub fn seasonstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// Its standard error, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Its exit code (a test fails when it was killed instead).
pub fn code(o: &Output) -> i32 {
    o.status.code().expect("exited, not killed")
}

/// Overwrites the compressed data of the image's TIFF tiles for which `hit(row, col)` holds (a
/// damaged download): reading a window that touches one fails to decode.
pub fn damage_tiles(path: &std::path::Path, hit: impl Fn(usize, usize) -> bool) {
    use tiff::tags::Tag;
    let file = std::fs::File::open(path).unwrap();
    let mut decoder = tiff::decoder::Decoder::new(file).unwrap();
    let (width, _) = decoder.dimensions().unwrap();
    let tile_width = decoder.get_tag_u32(Tag::TileWidth).unwrap();
    let across = width.div_ceil(tile_width) as usize;
    let offsets = decoder.get_tag_u64_vec(Tag::TileOffsets).unwrap();
    let counts = decoder.get_tag_u64_vec(Tag::TileByteCounts).unwrap();
    let mut bytes = std::fs::read(path).unwrap();
    for (i, (&offset, &count)) in offsets.iter().zip(&counts).enumerate() {
        if hit(i / across, i % across) {
            bytes[offset as usize..(offset + count) as usize].fill(0xA5);
        }
    }
    std::fs::write(path, bytes).unwrap();
}
