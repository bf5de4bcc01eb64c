//! slicelight's host.
//!
//! The framework: scene loading (`scene`), the pass registry and the frame's
//! buffers (`passes`), the CPU and GPU backends (`cpu`, `gpu`), the renderer
//! (`render`), the reference renderer that combines the families'
//! references (`reference`), error measures (`metrics`), the bench harness
//! (`bench`) and output (`output`). It names no family except where each is
//! registered once (`passes::PASSES` and the module list below).
//!
//! A family is one folder here and one in `shader-crate/src/` with the same
//! name: its passes (`mod.rs`), its settings (the serde form of its scene
//! section and their validation), its reference, its bench sweep, its cache.
//! `common` holds the passes every scene with geometry shares (shadow maps,
//! the surface, the scattering self-check).
//!
//! The render binary (`src/main.rs`) and the tests in the top-level `tests/`
//! folder use it.

#[macro_use]
pub mod passes;

pub mod bench;
pub mod bvh;
pub mod cpu;
pub mod gpu;
pub mod metrics;
pub mod output;
pub mod reference;
pub mod render;
pub mod scene;
pub mod view;

// The families.
pub mod caustics;
pub mod common;
pub mod desert;
pub mod sea;
pub mod shafts;
pub mod sky;
pub mod smoke;
pub mod volumes;

pub use slicelight_shaders as shaders;
