// The digest of what the kept SPIR-V (`slicelight_shaders.spv`) is compiled
// from: the shader crate's manifest and sources and the pinned toolchain.
// Included by the host's build script, which warns when the kept module is
// stale, and by `cargo xtask shaders`, which writes it next to the module.

use std::path::{Path, PathBuf};

/// The files the digest covers, relative to the workspace root, sorted.
pub fn shader_inputs(root: &Path) -> std::io::Result<Vec<PathBuf>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
        for entry in std::fs::read_dir(dir)? {
            let path = entry?.path();
            if path.is_dir() {
                walk(&path, out)?;
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut files = vec![root.join("rust-toolchain.toml"), root.join("shader-crate/Cargo.toml")];
    walk(&root.join("shader-crate/src"), &mut files)?;
    let mut relative: Vec<PathBuf> =
        files.into_iter().map(|f| f.strip_prefix(root).map(Path::to_path_buf).unwrap_or(f)).collect();
    relative.sort();
    Ok(relative)
}

/// A hex digest (XXH3-128) of the inputs' relative paths and contents.
pub fn shader_digest(root: &Path) -> std::io::Result<String> {
    let mut hasher = twox_hash::XxHash3_128::new();
    for file in shader_inputs(root)? {
        let name = file.to_string_lossy().replace('\\', "/");
        hasher.write(name.as_bytes());
        hasher.write(&[0]);
        let bytes = std::fs::read(root.join(&file))?;
        hasher.write(&(bytes.len() as u64).to_le_bytes());
        hasher.write(&bytes);
    }
    Ok(format!("{:032x}", hasher.finish_128()))
}
