//! slicelight's host: scene loading, the CPU and GPU backends, the pass plan,
//! image output. The render binary (`src/main.rs`) and the tests in the
//! top-level `tests/` folder use it.

pub mod bench;
pub mod bench_caustics;
pub mod bench_sea;
pub mod bench_sky;
pub mod bvh;
pub mod caustics_reference;
pub mod cpu;
pub mod gpu;
pub mod metrics;
pub mod output;
pub mod passes;
pub mod reference;
pub mod render;
pub mod scene;
pub mod sea_reference;
pub mod sky_reference;
pub mod waves;

pub use slicelight_shaders as shaders;
