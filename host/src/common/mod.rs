//! The passes every lit scene with geometry shares: the shadow maps (spot
//! and directional lights), the surface (G-buffer and directly lit
//! radiance), and the scattering self-check (a pass run only when asked for).

pub mod scatter_check;
pub mod shadow_maps;
pub mod surface;

use crate::passes::{Family, Pass};

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[&shadow_maps::ShadowMaps, &surface::Surface, &scatter_check::ScatterCheck];

/// The family, as `passes::FAMILIES` registers it (no bench sweep of its
/// own: the shafts sweep times the whole frame).
pub static FAMILY: Family = Family { name: "common", passes: PASSES, bench: None };
