//! An OBJ mesh's bytes, as a `[[object]] type = "mesh"` file is read.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    let _ = slicelight::scene::geometry::mesh_from_obj("object[0]", Path::new("fuzz.obj"), bytes, 1.0, [0.0; 3]);
});
