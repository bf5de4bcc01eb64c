//! The passes every lit scene with geometry shares: the shadow maps (spot
//! and directional lights), the surface (G-buffer and directly lit
//! radiance), and the scattering self-check (a pass run only when asked for).

pub mod scatter_check;
pub mod shadow_maps;
pub mod surface;

use crate::passes::{Family, Frame, Pass, SHADOW_MAPS};
use crate::scene::SceneData;
use slicelight_shaders::common::surface::LightInputs;

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[&shadow_maps::ShadowMaps, &surface::Surface, &scatter_check::ScatterCheck];

/// The family, as `passes::FAMILIES` registers it (no bench sweep of its
/// own: the shafts sweep times the whole frame).
pub static FAMILY: Family = Family { name: "common", passes: PASSES, kernels: &[], bench: None };

/// What the lights' terms read on the CPU (`LightInputs`): the light maps,
/// this frame's shadow maps, and the lights' transmittance volumes through
/// the scene's volumes where `volume_light` ran this frame (else none, and
/// every light passes whole).
pub fn light_inputs<'a>(scene: &'a SceneData, frame: &'a Frame) -> LightInputs<'a> {
    let depths = frame.get(&crate::volumes::OPTICAL_DEPTHS);
    LightInputs {
        light_map: &scene.light_map,
        shadow: frame.get(&SHADOW_MAPS),
        grids: if depths.is_empty() { &[] } else { &scene.volumes.grids },
        depths,
    }
}
