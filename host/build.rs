use spirv_builder::SpirvBuilder;
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut builder =
        SpirvBuilder::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shader-crate"), "spirv-unknown-vulkan1.2");
    builder.build_script.defaults = true;
    let result = builder.build()?;
    let path = result.module.unwrap_single();
    println!("cargo::rustc-env=SLICELIGHT_SPV={}", path.display());
    Ok(())
}
