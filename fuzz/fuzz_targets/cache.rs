//! The cache files: a caustics light transport table's header and
//! checksum, and a smoke state file decoded into a fluid. A damaged file
//! must be refused (and traced or simulated again), never trusted or a
//! crash.
#![no_main]

use libfuzzer_sys::fuzz_target;
use slicelight::smoke::{cache, configure, Config, Settings};
use std::sync::LazyLock;

/// The small smoke scene's fluid (tests/data/smoke_small.toml): 8^3 cells.
static SMOKE: LazyLock<(Config, Vec<u32>)> = LazyLock::new(|| {
    let scene: toml::Table = toml::from_str(include_str!("../../tests/data/smoke_small.toml")).expect("the scene");
    let volume = &scene["volume"][0];
    let settings: Settings = volume["smoke"].clone().try_into().expect("the smoke settings");
    let corner = |k: &str| -> glam::Vec3 { volume[k].clone().try_into::<[f32; 3]>().expect("a corner").into() };
    let config = configure("volume[0]", &settings, corner("min"), corner("max")).expect("a valid fluid");
    let cells = vec![1u32; config.params.cells as usize];
    (config, cells)
});

fuzz_target!(|bytes: &[u8]| {
    let key = [7u8; 16];
    let len = bytes.len().saturating_sub(44);
    let _ = slicelight::caustics::cache::sound(bytes, &key, len);
    let (config, cells) = &*SMOKE;
    // The hash the file must carry: its own (bytes 8..16) so that decoding
    // goes past the check and into the arrays.
    let hash = bytes.get(8..16).map_or(0, |b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    let _ = cache::decode(bytes, hash, config, cells);
});
