//! An image's bytes (PNG or OpenEXR, the formats a scene may name), decoded
//! as a `[[terrain]] heights = { file = ... }` height field and as a light
//! map. The image crate's default limits (512 MiB per decode) bound what a
//! header may make it allocate.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    for format in [image::ImageFormat::Png, image::ImageFormat::OpenExr] {
        if let Ok(img) = image::load_from_memory_with_format(bytes, format) {
            let _ = slicelight::desert::heights_from_image("terrain[0].heights", Path::new("fuzz"), &img, 1.0, false);
            let _ = slicelight::scene::lights::light_map_from_image(&img);
        }
    }
});
