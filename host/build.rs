use spirv_builder::SpirvBuilder;
use std::path::PathBuf;
fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The manifest folder is read when the script runs, not baked in when it is compiled
    // (`env!`): cargo reuses a compiled build script for a checkout that has moved, or for
    // another clone sharing CARGO_TARGET_DIR, and a baked-in path then names a folder that
    // may no longer exist.
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
    let mut builder = SpirvBuilder::new(manifest.join("../shader-crate"), "spirv-unknown-vulkan1.2");
    builder.build_script.defaults = true;
    let result = builder.build()?;
    let path = result.module.unwrap_single();
    println!("cargo::rustc-env=SLICELIGHT_SPV={}", path.display());
    Ok(())
}
