//! The passes every lit scene with geometry shares: the shadow maps (spot
//! and directional lights), the surface (G-buffer and directly lit
//! radiance), and the scattering self-check (a pass run only when asked for).

pub mod scatter_check;
pub mod shadow_maps;
pub mod surface;

use crate::passes::Pass;

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[&shadow_maps::ShadowMaps, &surface::Surface, &scatter_check::ScatterCheck];
