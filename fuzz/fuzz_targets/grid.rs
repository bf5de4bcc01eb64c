//! A Mitsuba `.vol` grid's bytes, as `[[volume]] grid = { file = ... }` reads them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    let _ = slicelight::volumes::grid::parse_vol("volume[0].grid.file", Path::new("fuzz.vol"), bytes);
});
