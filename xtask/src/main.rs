//! `cargo xtask shaders [--check]`: compiles `shader-crate` to SPIR-V with
//! rust-gpu and keeps the module in `host/spirv/`, where the host embeds it.
//!
//! Keeping the compiled module in the repository lets a fresh machine build
//! and render without compiling rust-gpu's codegen backend (most of a cold
//! build). `--check` compiles into the build folder instead and fails if the
//! kept module differs from it: CI and the README's test command run it, so
//! the kept SPIR-V is always what the sources give.

use clap::{Parser, Subcommand};
use spirv_builder::SpirvBuilder;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[path = "../../host/spirv/digest.rs"]
mod digest;

#[derive(Parser)]
#[command(about = "slicelight's project tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Compile shader-crate to host/spirv/slicelight_shaders.spv (and the
    /// digest of its sources next to it).
    Shaders {
        /// Compile, then fail if the kept module differs from the result
        /// instead of replacing it.
        #[arg(long)]
        check: bool,
    },
}

const MODULE: &str = "host/spirv/slicelight_shaders.spv";
const DIGEST: &str = "host/spirv/slicelight_shaders.digest";

fn root() -> PathBuf {
    // xtask/ sits in the workspace root. `cargo run` names the manifest's
    // folder at run time: checkouts that share a target folder share this
    // binary (cargo does not rebuild it for an identical copy), and the
    // folder it was compiled in would be another checkout's.
    let manifest =
        std::env::var_os("CARGO_MANIFEST_DIR").map_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")), PathBuf::from);
    manifest.parent().expect("xtask is inside the workspace").to_path_buf()
}

fn compile(root: &Path) -> Result<Vec<u8>, String> {
    eprintln!("xtask: compiling shader-crate to SPIR-V (rust-gpu)");
    let result = SpirvBuilder::new(root.join("shader-crate"), "spirv-unknown-vulkan1.2")
        .release(true)
        .build()
        .map_err(|e| format!("shader-crate: {e}"))?;
    let path = result.module.unwrap_single();
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Writes `bytes` to `path` through a temporary file in the same folder, so
/// that the kept module is never half written.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

fn shaders(check: bool) -> Result<(), String> {
    let root = root();
    let module = compile(&root)?;
    let digest = digest::shader_digest(&root).map_err(|e| format!("shader-crate: {e}"))?;
    let (module_path, digest_path) = (root.join(MODULE), root.join(DIGEST));
    if check {
        let kept = std::fs::read(&module_path).map_err(|e| format!("{MODULE}: {e}"))?;
        if kept != module {
            return Err(format!(
                "{MODULE} ({} bytes) differs from what shader-crate compiles to ({} bytes): run `cargo xtask shaders` and commit it",
                kept.len(),
                module.len()
            ));
        }
        let kept_digest = std::fs::read_to_string(&digest_path).map_err(|e| format!("{DIGEST}: {e}"))?;
        if kept_digest.trim() != digest {
            return Err(format!("{DIGEST} is not the digest of shader-crate's sources: run `cargo xtask shaders`"));
        }
        eprintln!("xtask: {MODULE} is up to date ({} bytes)", module.len());
        return Ok(());
    }
    write_atomically(&module_path, &module)?;
    write_atomically(&digest_path, format!("{digest}\n").as_bytes())?;
    eprintln!("xtask: wrote {MODULE} ({} bytes)", module.len());
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.task {
        Task::Shaders { check } => shaders(check),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e}");
            ExitCode::FAILURE
        }
    }
}
