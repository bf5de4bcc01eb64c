//! Wind ripples as bump textures on the dunes (the survey's 5.2, Fig. 10):
//! the ripple field's normals precomputed at its full resolution and at
//! each halving down to 32 texels a side, tiled over the terrain, and for
//! each quadrilateral (here: each triangle, half of one) the resolution its
//! distance from the eye calls for, "not mipmapping, since every
//! quadrilateral's texture differs". The shading normal is the dune's,
//! tilted by the ripple's slope (Blinn's bump mapping, the paper's [17]).

use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::types::{CommonParams, GpuTriangle};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// The ripple textures of a scene's terrains (records indexed by a
/// material's `ripples - 1`).
#[derive(Copy, Clone)]
pub struct Ripples<'a> {
    pub records: &'a [RippleRecord],
    pub normals: &'a [Vec4],
}

/// One terrain's ripple texture.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct RippleRecord {
    /// The tile's origin (x, z; m) and the inverse of its side (1/m).
    pub origin_x: f32,
    pub origin_z: f32,
    pub inverse_size: f32,
    /// The tile's side over the full resolution: a texel's width, m.
    pub texel: f32,
    /// Texels a side at full resolution (a power of two) and levels (the
    /// full resolution and each halving, to 32 at the coarsest).
    pub resolution: u32,
    pub levels: u32,
    /// The full resolution's first normal in the normals buffer; each
    /// coarser level follows the one before.
    pub offset: u32,
    /// 1: the level by distance (the paper's LOD); 0: always the full
    /// resolution (what LOD is measured against).
    pub lod: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)` of 4-byte scalars, 32 bytes, no padding.
    unsafe impl bytemuck::Zeroable for super::RippleRecord {}
    unsafe impl bytemuck::Pod for super::RippleRecord {}
}

/// The level a triangle at `distance` (m) from the eye takes: the coarsest
/// whose texel is no wider than the pixel's footprint there (so that no
/// detail the pixel could show is dropped).
pub fn lod_level(common: &CommonParams, r: &RippleRecord, distance: f32) -> u32 {
    if r.lod == 0 {
        return 0;
    }
    // The pixel's angular size: the image plane's half-height at unit
    // distance over half the rows.
    let pixel = 2.0 * common.camera_up.xyz().length() / common.height as f32;
    let ratio = distance * pixel / r.texel;
    let mut level = 0;
    let mut width = 2.0;
    while level + 1 < r.levels && width <= ratio {
        level += 1;
        width *= 2.0;
    }
    level
}

/// The ripple normal (unit, y up for a level field) at `(x, z)` (m) at
/// `level`, bilinear between the four texels around it, wrapping.
pub fn ripple_normal(r: &RippleRecord, normals: &[Vec4], x: f32, z: f32, level: u32) -> Vec3 {
    let n = r.resolution >> level;
    let mut offset = r.offset;
    let mut k = 0;
    while k < level {
        let side = r.resolution >> k;
        offset += side * side;
        k += 1;
    }
    let u = (x - r.origin_x) * r.inverse_size;
    let v = (z - r.origin_z) * r.inverse_size;
    let fx = (u - u.floor()) * n as f32 - 0.5;
    let fz = (v - v.floor()) * n as f32 - 0.5;
    let (x0, z0) = (fx.floor(), fz.floor());
    let (tx, tz) = (fx - x0, fz - z0);
    let (i0, i1, j0, j1) = (wrap(x0, n), wrap(x0 + 1.0, n), wrap(z0, n), wrap(z0 + 1.0, n));
    // (No closures over the buffer here: a closure capturing a runtime
    // array is a type naga rejects.)
    let a = normals[(offset + j0 * n + i0) as usize].xyz() * (1.0 - tx)
        + normals[(offset + j0 * n + i1) as usize].xyz() * tx;
    let b = normals[(offset + j1 * n + i0) as usize].xyz() * (1.0 - tx)
        + normals[(offset + j1 * n + i1) as usize].xyz() * tx;
    (a * (1.0 - tz) + b * tz).normalize()
}

/// Texel `i` (a whole number, possibly outside) wrapped into `0..n`.
fn wrap(i: f32, n: u32) -> u32 {
    let mut j = i as i32;
    let m = n as i32;
    while j < 0 {
        j += m;
    }
    while j >= m {
        j -= m;
    }
    j as u32
}

/// `n` (the dune's unit normal) tilted by the ripple normal `r` of a level
/// field: the ripple's slopes `dh/dx = -r.x / r.y`, `dh/dz = -r.z / r.y`
/// along the dune's own tangents in x and z.
pub fn bumped_normal(n: Vec3, r: Vec3) -> Vec3 {
    let tx = Vec3::X - n * n.x;
    let tz = Vec3::Z - n * n.z;
    let tx = if tx.length_squared() > 1e-12 { tx.normalize() } else { Vec3::X };
    let tz = if tz.length_squared() > 1e-12 { tz.normalize() } else { Vec3::Z };
    let y = r.y.max(1e-3);
    (n + tx * (r.x / y) + tz * (r.z / y)).normalize()
}

/// The shading normal at `point` on triangle `triangle` (its unit normal
/// `n`, toward the viewer) of a material with ripples `record` (index + 1;
/// 0: none), seen from `eye`.
#[allow(clippy::too_many_arguments)]
pub fn rippled(
    common: &CommonParams,
    records: &[RippleRecord],
    normals: &[Vec4],
    record: u32,
    triangle: &GpuTriangle,
    eye: Vec3,
    point: Vec3,
    n: Vec3,
) -> Vec3 {
    if record == 0 {
        return n;
    }
    let r = &records[(record - 1) as usize];
    let centre = (triangle.v0.xyz() + triangle.v1.xyz() + triangle.v2.xyz()) / 3.0;
    let level = lod_level(common, r, (centre - eye).length());
    let ripple = ripple_normal(r, normals, point.x, point.z, level);
    // A normal turned toward a viewer below the surface: tilt its mirror.
    let m = if n.y < 0.0 { -bumped_normal(-n, ripple) } else { bumped_normal(n, ripple) };
    // A tilt past the view's grazing angle would show the eye a facet's
    // back: such a normal is laid back to just face the eye.
    let view = (point - eye).normalize();
    let along = m.dot(view);
    if along > -1e-3 {
        (m - view * (along + 1e-3)).normalize()
    } else {
        m
    }
}
