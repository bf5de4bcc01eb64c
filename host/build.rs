//! The host embeds the SPIR-V kept in `host/spirv/` (built from
//! `shader-crate` by `cargo xtask shaders`), so building and rendering needs
//! no SPIR-V compiler. This script only warns when the kept module is older
//! than the shader sources (their digest differs from the one written next
//! to it); the test command and CI rebuild and check it.

use std::path::PathBuf;

#[path = "spirv/digest.rs"]
mod digest;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Read when the script runs, not baked in when it is compiled: cargo
    // reuses a compiled build script for a moved checkout or another clone
    // sharing CARGO_TARGET_DIR.
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
    let root = manifest.join("..");
    println!("cargo::rerun-if-changed=spirv/slicelight_shaders.spv");
    println!("cargo::rerun-if-changed=spirv/slicelight_shaders.digest");
    for file in digest::shader_inputs(&root)? {
        println!("cargo::rerun-if-changed={}", root.join(file).display());
    }
    println!("cargo::rerun-if-changed={}", root.join("shader-crate/src").display());
    let kept = std::fs::read_to_string(manifest.join("spirv/slicelight_shaders.digest")).unwrap_or_default();
    if kept.trim() != digest::shader_digest(&root)? {
        println!(
            "cargo::warning=host/spirv/slicelight_shaders.spv is older than shader-crate's sources: \
             run `cargo xtask shaders` to rebuild it (the GPU backend runs the kept module)"
        );
    }
    Ok(())
}
