//! Caustics from the waves (issue 26): the sunlight the wave surface
//! focuses onto a flat bottom, by the caustics paper's illumination volumes
//! (`../shared/papers/003_*`, eq. 2's flux ratio) with the wave surface as
//! the refracting mesh, as Iwasaki, Dobashi and Nishita (2002) do for
//! underwater caustics.
//!
//! The wave map's grid (`wave_resolution`^2 points over the `wave_size`
//! tile) is a mesh of two triangles per cell on the mean level. At each
//! grid point the sun's ray is refracted at the wave normal there (Snell,
//! index `n`) and travels to the bottom at depth `d`; each triangle's three
//! refracted rays sweep an illumination volume whose cross-section with the
//! bottom is the triangle their ends make. The flux the triangle lets in,
//! relative to what the same horizontal area of a flat surface lets in, is
//! `F = (s . n / n_y) T(s . n) / (s_y T_flat)` (`s` toward the sun, `T` the
//! Fresnel transmittance: a facet facing the sun takes more light), and on
//! the way down the light loses `e^(-c d / |r_y|)` where the flat beam loses
//! `e^(-c d / mu_s)`; spread over the cross-section's area it is the ratio
//! of the bottom's irradiance to the flat sea's (dimensionless, per
//! channel), kept on a map of the tile (the bottom's caustic repeats with
//! the waves), texel `(i, j)` centred on `(i, j)` texel widths.
//!
//! Each cross-section is rasterised by its 4x4 sub-samples per texel, by
//! the scatter primitive (`scatter.rs`: fixed point, the same sums in any
//! order); one that covers none goes to the texel under its centroid; one
//! over `MAX_TEXELS` texels is counted as rejected (word 0) and not drawn.
//! The sum over the map is the light let in: the flux is conserved.
//!
//! What this leaves out: the wave heights (only their slopes refract: the
//! mesh lies on the mean level), light reflected inside the water, and the
//! bottom's own relief (the map is for a flat bottom at `depth`).

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::surface::{grid_slope, slope_normal};
use super::SeaParams;
use crate::glam::{Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::optics::{refract, transmittance};
use crate::scatter::{scatter_add, AtomicWords, REJECTED_WORD};

/// Fixed-point units per unit of the ratio times texel area (`scatter.rs`).
pub const CAUSTIC_SCALE: f32 = 16_777_216.0;

/// Sub-samples per texel each way.
const SUB: u32 = 4;

/// Most texels a cross-section's box may span: two walks over it of
/// `SUB^2` samples each stay within the 65 535 loop iterations in all
/// that lavapipe allows an invocation.
pub const MAX_TEXELS: f32 = 1024.0;

/// Bins of the caustic map: rgb per texel.
pub fn caustic_bins(p: &SeaParams) -> u32 {
    3 * p.wave_resolution * p.wave_resolution
}

/// The refracted sun at grid point `(i, j)`: where its ray meets the bottom
/// (texel coordinates, unwrapped), its relative flux factor `F` and the
/// attenuation ratio per channel (see the module's text).
pub fn refracted_at(p: &SeaParams, waves: &[Vec4], i: u32, j: u32) -> (Vec2, f32, Vec3) {
    let sun = p.sun_direction.xyz();
    let n_w = p.extinction.w;
    let normal = slope_normal(grid_slope(p, waves, i, j));
    let cos_i = sun.dot(normal);
    let (r, through) = refract(-sun, normal, 1.0 / n_w);
    let down = (-r.y).max(1e-3);
    let factor = if cos_i > 0.0 && through {
        cos_i / normal.y * transmittance(cos_i, 1.0 / n_w)
            / (p.sun_direction.w.max(1e-6) * p.beam_irradiance.w.max(1e-6))
    } else {
        0.0
    };
    let d = p.depth;
    let texel = p.wave_size / p.wave_resolution as f32;
    let landed = Vec2::new(i as f32 + r.x * d / down / texel, j as f32 + r.z * d / down / texel);
    let c = p.extinction.xyz();
    let att = (-c * (d * (1.0 / down - 1.0 / p.sun_in_water.w))).exp();
    (landed, factor, att)
}

/// Invocation `index` = triangle `index % 2` of grid cell `index / 2`
/// (cells row by row): its cross-section with the bottom rasterised into
/// the caustic map `words`.
pub fn caustic_triangle<A: AtomicWords + ?Sized>(index: u32, p: &SeaParams, waves: &[Vec4], words: &mut A) {
    let n = p.wave_resolution;
    let cell = index / 2;
    let (i, j) = (cell % n, cell / n);
    // Cell corners (i, j), (i+1, j), (i, j+1), (i+1, j+1): triangles
    // (00, 10, 01) and (10, 11, 01).
    let (a, b, c) =
        if index & 1 == 0 { ((i, j), (i + 1, j), (i, j + 1)) } else { ((i + 1, j), (i + 1, j + 1), (i, j + 1)) };
    let (pa, fa, ta) = refracted_at(p, waves, a.0, a.1);
    let (pb, fb, tb) = refracted_at(p, waves, b.0, b.1);
    let (pc, fc, tc) = refracted_at(p, waves, c.0, c.1);
    // The flux in texel^2 units: the horizontal area (half a texel^2) times
    // the relative factor and attenuation, the mean of the corners'.
    let flux = (ta * fa + tb * fb + tc * fc) * (0.5 / 3.0);
    if !(flux.x > 0.0 || flux.y > 0.0 || flux.z > 0.0) {
        return;
    }
    let lo = pa.min(pb).min(pc);
    let hi = pa.max(pb).max(pc);
    let (i0, j0) = ((lo.x - 0.5).ceil(), (lo.y - 0.5).ceil());
    let (i1, j1) = ((hi.x + 0.5).floor(), (hi.y + 0.5).floor());
    // (Not `is_finite`: its infinite literal is a constant the SPIR-V
    // front end rejects; a NaN fails the comparison.)
    let finite = lo.abs().max_element() < 1e30 && hi.abs().max_element() < 1e30;
    if !finite || (i1 - i0 + 1.0) * (j1 - j0 + 1.0) > MAX_TEXELS {
        words.fetch_add(REJECTED_WORD, 1);
        return;
    }
    let area2 = (pb.x - pa.x) * (pc.y - pa.y) - (pb.y - pa.y) * (pc.x - pa.x);
    let sign = if area2 < 0.0 { -1.0 } else { 1.0 };
    let step = 1.0 / SUB as f32;
    let first = -0.5 + 0.5 * step;
    // First the sub-samples covered in all, then each texel its share.
    let mut count = 0u32;
    let mut pass = 0;
    while pass < 2 {
        let mut y = j0;
        while y <= j1 {
            let mut x = i0;
            while x <= i1 {
                let mut covered = 0u32;
                let mut sy = 0;
                while sy < SUB {
                    let mut sx = 0;
                    while sx < SUB {
                        if inside(pa, pb, pc, sign, x + first + sx as f32 * step, y + first + sy as f32 * step) {
                            covered += 1;
                        }
                        sx += 1;
                    }
                    sy += 1;
                }
                if pass == 0 {
                    count += covered;
                } else if covered > 0 {
                    deposit(p, words, x, y, flux * (covered as f32 / count as f32));
                }
                x += 1.0;
            }
            y += 1.0;
        }
        if count == 0 {
            // Smaller than a sub-sample's spacing, or a focal line: all of
            // it in the texel under the centroid.
            let g = (pa + pb + pc) / 3.0;
            deposit(p, words, g.x.round(), g.y.round(), flux);
            return;
        }
        pass += 1;
    }
}

/// Whether `(x, y)` lies in the triangle `a b c` (`sign`: its orientation).
fn inside(a: Vec2, b: Vec2, c: Vec2, sign: f32, x: f32, y: f32) -> bool {
    let e0 = ((b.x - a.x) * (y - a.y) - (b.y - a.y) * (x - a.x)) * sign;
    let e1 = ((c.x - b.x) * (y - b.y) - (c.y - b.y) * (x - b.x)) * sign;
    let e2 = ((a.x - c.x) * (y - c.y) - (a.y - c.y) * (x - c.x)) * sign;
    e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0
}

/// Adds `v` (rgb) to texel `(x, y)` of the map, wrapped into the tile.
fn deposit<A: AtomicWords + ?Sized>(p: &SeaParams, words: &mut A, x: f32, y: f32, v: Vec3) {
    let n = p.wave_resolution as i32;
    let (i, j) = ((x as i32 % n + n) % n, (y as i32 % n + n) % n);
    let bin = 3 * (j as u32 * p.wave_resolution + i as u32);
    scatter_add(words, bin, v.x, CAUSTIC_SCALE);
    scatter_add(words, bin + 1, v.y, CAUSTIC_SCALE);
    scatter_add(words, bin + 2, v.z, CAUSTIC_SCALE);
}

/// Bin `bin`'s value (f32).
fn read(words: &[u32], bin: u32) -> f32 {
    let low = words[(1 + 2 * bin) as usize];
    let high = words[(2 + 2 * bin) as usize];
    (high as f32 * 4_294_967_296.0 + low as f32) / CAUSTIC_SCALE
}

/// The caustic at the bottom point `(x, z)` (m): the ratio of its
/// irradiance to the flat sea's, per channel, bilinear between texel
/// centres, tiled; 1 without a map (`SeaParams::caustics` 0).
pub fn caustic_at(p: &SeaParams, words: &[u32], x: f32, z: f32) -> Vec3 {
    if p.caustics == 0 {
        return Vec3::ONE;
    }
    let n = p.wave_resolution;
    let (fx, fz) = (wrap(p, x), wrap(p, z));
    let (x0, z0) = ((fx as u32).min(n - 1), (fz as u32).min(n - 1));
    let (ax, az) = (fx - x0 as f32, fz - z0 as f32);
    let (x1, z1) = ((x0 + 1) % n, (z0 + 1) % n);
    let (a, b) = (texel_ratio(p, words, x0, z0), texel_ratio(p, words, x1, z0));
    let (c, d) = (texel_ratio(p, words, x0, z1), texel_ratio(p, words, x1, z1));
    (a * (1.0 - ax) + b * ax) * (1.0 - az) + (c * (1.0 - ax) + d * ax) * az
}

/// A position (m) in texel widths within the tile, in [0, n).
fn wrap(p: &SeaParams, v: f32) -> f32 {
    let u = v / p.wave_size;
    (u - u.floor()) * p.wave_resolution as f32
}

/// Texel `(i, j)`'s ratio (rgb).
pub fn texel_ratio(p: &SeaParams, words: &[u32], i: u32, j: u32) -> Vec3 {
    let b = 3 * (j * p.wave_resolution + i);
    Vec3::new(read(words, b), read(words, b + 1), read(words, b + 2))
}
