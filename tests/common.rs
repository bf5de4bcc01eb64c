//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The workspace root (the folder holding `scenes/`).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Loads a scene from a TOML string written to a fresh temporary folder.
pub fn scene_from_str(toml: &str) -> slicelight::scene::SceneData {
    scene_with_files(toml, &[])
}

/// Loads a scene from `toml` written beside `files` (name, contents: meshes,
/// light maps) in a fresh temporary folder.
pub fn scene_with_files(toml: &str, files: &[(&str, String)]) -> slicelight::scene::SceneData {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    slicelight::scene::load(&path).unwrap()
}

/// The error loading a scene from `toml` gives (written to a fresh
/// temporary folder), with its causes; panics if the scene loads.
pub fn scene_error(toml: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    match slicelight::scene::load(&path) {
        Ok(_) => panic!("the scene loads, but should be refused:\n{toml}"),
        Err(e) => format!("{e:#}"),
    }
}
