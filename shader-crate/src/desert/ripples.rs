//! Wind ripples as bump textures on the dunes (the survey's 5.2, Fig. 10):
//! the ripple field's normals precomputed at its full resolution and at
//! each halving down to 32 texels a side, tiled over the terrain, and for
//! each quadrilateral (here: each triangle, half of one) the resolution its
//! distance from the eye calls for, "not mipmapping, since every
//! quadrilateral's texture differs"; or (`LOD_BLEND`) each point between
//! the two levels around its own distance, which leaves no seam where
//! neighbouring triangles take different levels. The shading normal is the
//! dune's, tilted by the ripple's slope (Blinn's bump mapping, the paper's
//! [17]).

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

/// `RippleRecord::lod`: always the full resolution.
pub const LOD_FULL: u32 = 0;
/// `RippleRecord::lod`: each triangle at one level, by its centre's
/// distance (the paper's choice per quadrilateral).
pub const LOD_TRIANGLE: u32 = 1;
/// `RippleRecord::lod`: each point between two levels, by its own distance.
pub const LOD_BLEND: u32 = 2;

/// The level a triangle at `distance` (m) from the eye takes: the coarsest
/// whose texel is no wider than the pixel's footprint there (so that no
/// detail the pixel could show is dropped).
pub fn lod_level(common: &CommonParams, r: &RippleRecord, distance: f32) -> u32 {
    if r.lod == LOD_FULL {
        return 0;
    }
    let ratio = footprint_texels(common, r, distance);
    let mut level = 0;
    let mut width = 2.0;
    while level + 1 < r.levels && width <= ratio {
        level += 1;
        width *= 2.0;
    }
    level
}

/// A pixel's footprint at `distance` (m) from the eye, in texels of the
/// full resolution.
fn footprint_texels(common: &CommonParams, r: &RippleRecord, distance: f32) -> f32 {
    // The pixel's angular size: the image plane's half-height at unit
    // distance over half the rows.
    let pixel = 2.0 * common.camera_up.xyz().length() / common.height as f32;
    distance * pixel / r.texel
}

/// The level of detail at `distance` (m), continuous (`LOD_BLEND`): `log2`
/// of the pixel's footprint in texels, within the levels, as a GPU's
/// trilinear filtering takes it. Its whole part is `lod_level`'s choice;
/// blending that level and the next by the fraction keeps the level
/// continuous in distance, so no seam shows where neighbouring triangles
/// would take different levels. (Measured against the full resolution
/// averaged over each pixel at 180x120, `ripple_lod_against_full_resolution`:
/// 1.63 % RMS of the 8-bit range, the per-triangle choice 1.73 %; blending
/// one level finer, `log2 - 1`, 1.98 %, since it aliases.)
pub fn lod_blend(common: &CommonParams, r: &RippleRecord, distance: f32) -> f32 {
    let ratio = footprint_texels(common, r, distance);
    if ratio <= 1.0 || r.levels < 2 {
        return 0.0;
    }
    ratio.log2().min((r.levels - 1) as f32)
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
    let ripple = if r.lod == LOD_BLEND {
        // The two levels around the point's own level of detail.
        let lambda = lod_blend(common, r, (point - eye).length());
        let level = (lambda as u32).min(r.levels - 1);
        let t = lambda - level as f32;
        let finer = ripple_normal(r, normals, point.x, point.z, level);
        if t > 0.0 && level + 1 < r.levels {
            (finer * (1.0 - t) + ripple_normal(r, normals, point.x, point.z, level + 1) * t).normalize()
        } else {
            finer
        }
    } else {
        let centre = (triangle.v0.xyz() + triangle.v1.xyz() + triangle.v2.xyz()) / 3.0;
        ripple_normal(r, normals, point.x, point.z, lod_level(common, r, (centre - eye).length()))
    };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blended_shading_normal_has_no_step_where_the_level_changes() {
        // Three levels (8, 4 and 2 texels a side) of unrelated normals; the
        // eye moved across the distances where the footprint is 2 and 4
        // texels (the whole part of the level changes there). The normal
        // moves by no more than the distance's change calls for: a choice
        // of one level would jump by the difference of two levels' normals.
        let mut normals = Vec::new();
        let mut state = 7u32;
        for side in [8u32, 4, 2] {
            for _ in 0..side * side {
                state = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
                let a = (state >> 8) as f32 / 16_777_216.0 * core::f32::consts::TAU;
                normals.push(Vec3::new(0.4 * a.cos(), 1.0, 0.4 * a.sin()).normalize().extend(0.0));
            }
        }
        let r = RippleRecord {
            inverse_size: 1.0,
            texel: 1.0 / 8.0,
            resolution: 8,
            levels: 3,
            lod: LOD_BLEND,
            ..Default::default()
        };
        // A pixel of 1e-3 rad: footprint `distance * 1e-3` m.
        let common =
            CommonParams { camera_up: Vec4::new(0.0, 0.5e-3 * 1000.0, 0.0, 0.0), height: 1000, ..Default::default() };
        let point = Vec3::new(0.37, 0.0, 0.61);
        // A triangle centred on the point, so that the per-triangle choice
        // would change level at the same distances.
        let triangle =
            GpuTriangle { v0: point.extend(1.0), v1: point.extend(1.0), v2: point.extend(1.0), ..Default::default() };
        let at = |distance: f32| {
            let eye = point + Vec3::new(0.0, 0.6, 0.8) * distance;
            rippled(&common, &[r], &normals, 1, &triangle, eye, point, Vec3::Y)
        };
        for footprint_texels in [2.0f32, 4.0] {
            let d = footprint_texels * r.texel / 1e-3;
            let (below, above) = (at(d * (1.0 - 1e-4)), at(d * (1.0 + 1e-4)));
            assert!((below - above).length() < 1e-3, "{footprint_texels}: {below} {above}");
            // The levels themselves differ there by far more.
            let l = footprint_texels.log2() as u32;
            let step =
                ripple_normal(&r, &normals, point.x, point.z, l - 1) - ripple_normal(&r, &normals, point.x, point.z, l);
            assert!(step.length() > 1e-2, "{step}");
        }
        // Near the eye, the full resolution; far, the coarsest level; and
        // the whole part is the per-triangle choice.
        assert_eq!(lod_blend(&common, &r, 0.1), 0.0);
        assert_eq!(lod_blend(&common, &r, 1e6), 2.0);
        for distance in [100.0f32, 250.0, 300.0, 600.0, 900.0] {
            assert_eq!(lod_blend(&common, &r, distance) as u32, lod_level(&common, &r, distance), "{distance}");
        }
    }
}
