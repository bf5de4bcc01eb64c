//! The kernels every lit scene with geometry shares: the shadow maps, the
//! surface (G-buffer and direct light), and the scattering self-check.

pub mod scatter_check;
pub mod shadow_maps;
pub mod surface;
