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

use super::surface::level_offset;
use super::surface::{level_slope, slope_normal, top_level};
use super::SeaParams;
use crate::caustics::{SubRows, Triangle2};
use crate::glam::{Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::optics::{refract, transmittance};
use crate::scatter::{scatter_add, AtomicWords, REJECTED_WORD};

/// Fixed-point units per unit of the ratio times texel area (`scatter.rs`).
pub const CAUSTIC_SCALE: f32 = 16_777_216.0;

// Sub-samples: 4x4 per texel on the bottom's map and the shaft planes'
// (`caustics::SubRows`, which the glass caustics' maps use too). 2x2 on
// the shaft planes cost a third less but left 14 % RMS per texel against
// the photon tracer 0.7 m down, more than the caustic's contrast there,
// 10 %; 4x4 leaves 8 %.

/// Most texels a cross-section's box may span: two walks over it of
/// 16 samples each stay within the 65 535 loop iterations in all
/// that lavapipe allows an invocation.
pub const MAX_TEXELS: f32 = 1024.0;

/// The largest shaft plane's side, texels: the mip resolve's coarsest
/// texel averages all of a plane's (`shaft_mip_texel`), and 128^2 stays
/// within lavapipe's loop limit.
pub const MAX_SHAFT_RESOLUTION: u32 = 128;

/// One of the maps the caustic pass draws: the bottom's, or a shaft
/// plane's (`caustic_map`).
#[derive(Copy, Clone, Debug)]
pub struct CausticMap {
    /// The wave pyramid's level its mesh takes its slopes from, and its
    /// side in texels (`wave_resolution >> level`).
    pub level: u32,
    pub resolution: u32,
    /// The plane's depth below the mean level, m.
    pub depth: f32,
    /// Its first bin in the words.
    pub first_bin: u32,
}

/// Texels of the bottom's map (0 without one).
pub fn bottom_map_texels(p: &SeaParams) -> u32 {
    if p.caustics != 0 {
        p.wave_resolution * p.wave_resolution
    } else {
        0
    }
}

/// A shaft plane's side, texels.
pub fn shaft_resolution(p: &SeaParams) -> u32 {
    p.wave_resolution >> p.shaft_level
}

/// Texels of every map the caustic pass draws: the bottom's, then each
/// shaft plane's.
fn caustic_texels(p: &SeaParams) -> u32 {
    let m = shaft_resolution(p);
    bottom_map_texels(p) + p.shaft_planes * m * m
}

/// Bins of the caustic words: rgb per texel of every map.
pub fn caustic_bins(p: &SeaParams) -> u32 {
    3 * caustic_texels(p)
}

/// Invocations of the caustic pass: two triangles per texel of every map.
pub fn caustic_triangles(p: &SeaParams) -> u32 {
    2 * caustic_texels(p)
}

/// Shaft plane `k`'s depth, m: evenly from the surface (plane 0) to
/// `shaft_depth`.
pub fn shaft_plane_depth(p: &SeaParams, k: u32) -> f32 {
    p.shaft_depth * k as f32 / (p.shaft_planes.max(2) - 1) as f32
}

/// The map texel `index` (over every map, as their texels are laid out)
/// lies on, and the texel's index within it. A map's grid points are
/// numbered as its texels.
pub fn map_of_texel(p: &SeaParams, index: u32) -> (CausticMap, u32) {
    let bottom = bottom_map_texels(p);
    if index < bottom {
        let map = CausticMap { level: 0, resolution: p.wave_resolution, depth: p.depth, first_bin: 0 };
        return (map, index);
    }
    let m = shaft_resolution(p);
    let rest = index - bottom;
    let k = rest / (m * m);
    let map = CausticMap {
        level: p.shaft_level,
        resolution: m,
        depth: shaft_plane_depth(p, k),
        first_bin: 3 * (bottom + k * m * m),
    };
    (map, rest % (m * m))
}

/// The map invocation `index` draws into, and its triangle there (two a
/// texel, laid out as the texels).
pub fn caustic_map(p: &SeaParams, index: u32) -> (CausticMap, u32) {
    let (map, texel) = map_of_texel(p, index / 2);
    (map, 2 * texel + index % 2)
}

/// Grid points of every map's mesh, one refracted ray each
/// (`sea.caustic_rays`): as many as the maps' texels.
pub fn caustic_points(p: &SeaParams) -> u32 {
    caustic_texels(p)
}

/// The refracted sun at grid point `(i, j)` of `map`'s mesh: how far its
/// ray lands from the point on the map's plane (texels) and its flux
/// relative to the flat beam's, `F` times the attenuation ratio, per
/// channel (see the module's text).
pub fn refracted_at(p: &SeaParams, waves: &[Vec4], map: &CausticMap, i: u32, j: u32) -> (Vec2, Vec3) {
    let sun = p.sun_direction.xyz();
    let n_w = p.extinction.w;
    let normal = slope_normal(level_slope(p, waves, map.level, i, j));
    let cos_i = sun.dot(normal);
    let (r, through) = refract(-sun, normal, 1.0 / n_w);
    let down = (-r.y).max(1e-3);
    let factor = if cos_i > 0.0 && through {
        cos_i / normal.y * transmittance(cos_i, 1.0 / n_w)
            / (p.sun_direction.w.max(1e-6) * p.beam_irradiance.w.max(1e-6))
    } else {
        0.0
    };
    let d = map.depth;
    let texel = p.wave_size / map.resolution as f32;
    let offset = Vec2::new(r.x * d / down / texel, r.z * d / down / texel);
    let c = p.extinction.xyz();
    let att = (-c * (d * (1.0 / down - 1.0 / p.sun_in_water.w))).exp();
    (offset, att * factor)
}

/// Invocation `index` of `sea.caustic_rays`: grid point `index` (numbered
/// as `map_of_texel`'s texels) refracts the sun once, for the six
/// triangles around it (`caustic_triangle`): `(offset.x, offset.y, 0, 0)`
/// and `(flux, 0)` of `refracted_at`.
pub fn caustic_ray(index: u32, p: &SeaParams, waves: &[Vec4]) -> (Vec4, Vec4) {
    let (map, t) = map_of_texel(p, index);
    let n = map.resolution;
    let (offset, flux) = refracted_at(p, waves, &map, t % n, t / n);
    (Vec4::new(offset.x, offset.y, 0.0, 0.0), flux.extend(0.0))
}

/// Grid point `(i, j)` of `map` (`i, j <= n`: the tile repeats) from the
/// rays `sea.caustic_rays` refracted: where it lands on the plane (texel
/// coordinates, unwrapped) and its flux factor per channel.
fn landed(rays: &[Vec4], map: &CausticMap, i: u32, j: u32) -> (Vec2, Vec3) {
    let n = map.resolution;
    let (wi, wj) = (if i == n { 0 } else { i }, if j == n { 0 } else { j });
    let at = 2 * (map.first_bin / 3 + wj * n + wi) as usize;
    let (o, f) = (rays[at], rays[at + 1]);
    (Vec2::new(i as f32 + o.x, j as f32 + o.y), f.xyz())
}

/// Invocation `index`: triangle `t % 2` of grid cell `t / 2` (cells row by
/// row) of the map `caustic_map` gives: its cross-section with the map's
/// plane rasterised into the caustic words.
pub fn caustic_triangle<A: AtomicWords + ?Sized>(index: u32, p: &SeaParams, rays: &[Vec4], words: &mut A) {
    let (map, t) = caustic_map(p, index);
    let n = map.resolution;
    let cell = t / 2;
    let (i, j) = (cell % n, cell / n);
    // Cell corners (i, j), (i+1, j), (i, j+1), (i+1, j+1): triangles
    // (00, 10, 01) and (10, 11, 01).
    let (a, b, c) =
        if t & 1 == 0 { ((i, j), (i + 1, j), (i, j + 1)) } else { ((i + 1, j), (i + 1, j + 1), (i, j + 1)) };
    let (pa, fa) = landed(rays, &map, a.0, a.1);
    let (pb, fb) = landed(rays, &map, b.0, b.1);
    let (pc, fc) = landed(rays, &map, c.0, c.1);
    // The flux in texel^2 units: the horizontal area (half a texel^2) times
    // the relative factor and attenuation, the mean of the corners'.
    let flux = (fa + fb + fc) * (0.5 / 3.0);
    if !(flux.x > 0.0 || flux.y > 0.0 || flux.z > 0.0) {
        return;
    }
    let t = Triangle2::new(pa.x, pa.y, pb.x, pb.y, pc.x, pc.y);
    let lo = pa.min(pb).min(pc);
    let hi = pa.max(pb).max(pc);
    let (i0, j0) = ((lo.x - 0.5).ceil(), (lo.y - 0.5).ceil());
    let (i1, j1) = ((hi.x + 0.5).floor(), (hi.y + 0.5).floor());
    // Each corner tested (`min` and `max` pass a NaN over: the box alone
    // would let a NaN corner through).
    if !t.is_finite() || (i1 - i0 + 1.0) * (j1 - j0 + 1.0) > MAX_TEXELS {
        words.fetch_add(REJECTED_WORD, 1);
        return;
    }
    let (w, h) = (i1 - i0 + 1.0, j1 - j0 + 1.0);
    if w * h <= 4.0 {
        // Most cross-sections span at most 2x2 texels: one walk, each
        // texel's count kept (the same counts and shares as the two walks
        // below, so the same sums).
        let wide = w as u32;
        let cells = (w * h) as u32;
        let rows = (SubRows::new(&t, j0), SubRows::new(&t, j0 + 1.0));
        let c0 = cell_coverage(&t, &rows, i0, j0, wide, 0);
        let c1 = if cells > 1 { cell_coverage(&t, &rows, i0, j0, wide, 1) } else { 0 };
        let c2 = if cells > 2 { cell_coverage(&t, &rows, i0, j0, wide, 2) } else { 0 };
        let c3 = if cells > 3 { cell_coverage(&t, &rows, i0, j0, wide, 3) } else { 0 };
        let count = c0 + c1 + c2 + c3;
        if count == 0 {
            deposit_at_centroid(&map, words, &t, flux);
            return;
        }
        let mut c = 0;
        while c < cells {
            let k = if c == 0 {
                c0
            } else if c == 1 {
                c1
            } else if c == 2 {
                c2
            } else {
                c3
            };
            if k > 0 {
                let (x, y) = (i0 + (c % wide) as f32, j0 + (c / wide) as f32);
                deposit(&map, words, x, y, flux * (k as f32 / count as f32));
            }
            c += 1;
        }
        return;
    }
    // First the sub-samples covered in all, then each texel its share.
    let mut count = 0u32;
    let mut pass = 0;
    while pass < 2 {
        let mut y = j0;
        while y <= j1 {
            let rows = SubRows::new(&t, y);
            let mut x = i0;
            while x <= i1 {
                let covered = rows.covered(x);
                if pass == 0 {
                    count += covered;
                } else if covered > 0 {
                    deposit(&map, words, x, y, flux * (covered as f32 / count as f32));
                }
                x += 1.0;
            }
            y += 1.0;
        }
        if count == 0 {
            deposit_at_centroid(&map, words, &t, flux);
            return;
        }
        pass += 1;
    }
}

/// Of a cross-section's box `wide` texels across from `(i0, j0)`, the
/// sub-samples texel `c` (row by row) holds; `rows`: the box's first two
/// texel rows' sub-sample rows (a box one texel wide may be four high).
fn cell_coverage(t: &Triangle2, rows: &(SubRows, SubRows), i0: f32, j0: f32, wide: u32, c: u32) -> u32 {
    let (x, dy) = (i0 + (c % wide) as f32, c / wide);
    if dy == 0 {
        rows.0.covered(x)
    } else if dy == 1 {
        rows.1.covered(x)
    } else {
        SubRows::new(t, j0 + dy as f32).covered(x)
    }
}

/// A cross-section that covers no sub-sample (smaller than their spacing,
/// or a focal line): all of it in the texel under its centroid.
fn deposit_at_centroid<A: AtomicWords + ?Sized>(map: &CausticMap, words: &mut A, t: &Triangle2, flux: Vec3) {
    let (x, y) = ((t.ax + t.bx + t.cx) / 3.0, (t.az + t.bz + t.cz) / 3.0);
    deposit(map, words, x.round(), y.round(), flux);
}

/// Adds `v` (rgb) to texel `(x, y)` of `map`, wrapped into the tile.
fn deposit<A: AtomicWords + ?Sized>(map: &CausticMap, words: &mut A, x: f32, y: f32, v: Vec3) {
    let n = map.resolution as i32;
    let (i, j) = ((x as i32 % n + n) % n, (y as i32 % n + n) % n);
    let bin = map.first_bin + 3 * (j as u32 * map.resolution + i as u32);
    scatter_add(words, bin, v.x, CAUSTIC_SCALE);
    scatter_add(words, bin + 1, v.y, CAUSTIC_SCALE);
    scatter_add(words, bin + 2, v.z, CAUSTIC_SCALE);
}

/// Bin `bin`'s value (f32).
pub fn read(words: &[u32], bin: u32) -> f32 {
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

/// Texel `(i, j)`'s ratio (rgb) on the bottom's map.
pub fn texel_ratio(p: &SeaParams, words: &[u32], i: u32, j: u32) -> Vec3 {
    read_rgb(words, 3 * (j * p.wave_resolution + i))
}

/// The three bins from `bin` (one texel's rgb).
fn read_rgb(words: &[u32], bin: u32) -> Vec3 {
    Vec3::new(read(words, bin), read(words, bin + 1), read(words, bin + 2))
}

/// Texels of one shaft plane's mip chain (`m^2 + (m/2)^2 + ... + 1`).
pub fn shaft_mip_len(p: &SeaParams) -> u32 {
    let m = shaft_resolution(p);
    level_offset(m, top_level(m)) + 1
}

/// Texels of the shaft maps (every plane's chain; 0 without shafts).
pub fn shaft_map_len(p: &SeaParams) -> u32 {
    p.shaft_planes * shaft_mip_len(p)
}

/// Texel `index` of the shaft maps (`sea.shafts`): plane `k`'s chain holds
/// its caustic (rgb ratios, from the words) at level 0 and, at level `l`,
/// the box average of the `2^l x 2^l` level-0 texels under each texel, so
/// that a view ray's step reads the caustic averaged over its footprint
/// (`shaft_at`). w: 0.
pub fn shaft_mip_texel(index: u32, p: &SeaParams, words: &[u32]) -> Vec4 {
    let len = shaft_mip_len(p);
    let (k, r) = (index / len, index % len);
    let m = shaft_resolution(p);
    let top = top_level(m);
    let mut l = 0;
    while l < top && level_offset(m, l + 1) <= r {
        l += 1;
    }
    let s = m >> l;
    let local = r - level_offset(m, l);
    let (i, j) = (local % s, local / s);
    let span = 1u32 << l;
    let first = 3 * (bottom_map_texels(p) + k * m * m);
    let mut sum = Vec3::ZERO;
    let mut b = 0;
    while b < span {
        let mut a = 0;
        while a < span {
            sum += read_rgb(words, first + 3 * ((j * span + b) * m + i * span + a));
            a += 1;
        }
        b += 1;
    }
    (sum / (span * span) as f32).extend(0.0)
}

/// How far (m) a point moving a metre along the unit `dir` moves across
/// the shafts: the caustic at depth `z` is, near a plane, that plane's
/// carried along the refracted sun `s`, so what the shafts show of a
/// point is where its line along `s` crosses a plane, which moves
/// horizontally by `|dir_h - s_h dir_y / s_y|` per metre (0 looking along
/// the sun's beam or against it).
pub fn shaft_drift(p: &SeaParams, dir: Vec3) -> f32 {
    let s = p.sun_in_water.xyz();
    let k = dir.y / s.y.min(-1e-6);
    Vec2::new(dir.x - s.x * k, dir.z - s.z * k).length()
}

/// The waves' focusing of the sun at the point `point` (scene
/// coordinates, under the surface): the ratio of the refracted sun's
/// irradiance there to the flat sea's beam's (rgb; 1 without shafts),
/// averaged over a footprint `width` m across the shafts (the mip level
/// nearest it), bilinear between texel centres; between the two shaft
/// planes around its depth, each read where the refracted sun's line
/// through the point crosses it (so shafts stay sharp between planes),
/// linear in depth; below the last plane, that plane's mean (the
/// caustic's detail there is left unresolved).
pub fn shaft_at(p: &SeaParams, shafts: &[Vec4], point: Vec3, width: f32) -> Vec3 {
    if p.shaft_planes == 0 {
        return Vec3::ONE;
    }
    let m = shaft_resolution(p);
    let top = top_level(m);
    let texel = p.wave_size / m as f32;
    let lod = if width > texel { ((width / texel).log2() + 0.5) as u32 } else { 0 };
    let last = p.shaft_planes - 1;
    let z = p.level - point.y;
    let u = z / p.shaft_depth.max(1e-6) * last as f32;
    if u > last as f32 {
        return mip_bilinear(p, shafts, last, top, point.x, point.z);
    }
    let u = u.max(0.0);
    let k = (u as u32).min(last - 1);
    let w = u - k as f32;
    let lod = lod.min(top);
    // Along the refracted sun to each plane: `dz` deeper is `dz / -s_y` along `s`.
    let s = p.sun_in_water.xyz();
    let along = Vec2::new(s.x, s.z) / (-s.y).max(1e-6);
    let (za, zb) = (shaft_plane_depth(p, k), shaft_plane_depth(p, k + 1));
    let qa = Vec2::new(point.x, point.z) + along * (za - z);
    let qb = Vec2::new(point.x, point.z) + along * (zb - z);
    let a = mip_bilinear(p, shafts, k, lod, qa.x, qa.y);
    let b = mip_bilinear(p, shafts, k + 1, lod, qb.x, qb.y);
    a * (1.0 - w) + b * w
}

/// Plane `k`'s level `l` at the horizontal point `(x, z)` (m), bilinear
/// between its texel centres, tiled. The plane's texel `i` of level 0 is
/// centred over the pyramid level's grid point, `(i + delta)` of its
/// texels with `delta = (1 - 2^-L)/2` for `L = shaft_level`; level `l`'s
/// texel `j` averages level 0's `j 2^l ..`, centred at `j 2^l + (2^l - 1)/2`.
fn mip_bilinear(p: &SeaParams, shafts: &[Vec4], k: u32, l: u32, x: f32, z: f32) -> Vec3 {
    let m = shaft_resolution(p);
    let s = m >> l;
    let base = k * shaft_mip_len(p) + level_offset(m, l);
    let delta = 0.5 - 0.5 / (1u32 << p.shaft_level) as f32;
    let scale = (1u32 << l) as f32;
    // Reciprocals of powers of two (the level's scale; `s`, which is one
    // since the wave map's side is): multiplying by them is exact, as the
    // divisions were, and this is the underwater frame's hottest function.
    let (inv_scale, inv_s) = (1.0 / scale, 1.0 / s as f32);
    // (Functions, not closures: a closure capturing a storage buffer's
    // slice is a type the SPIR-V front end rejects.)
    let fx = mip_coord(x / p.wave_size, m, s, delta, scale, inv_scale, inv_s);
    let fz = mip_coord(z / p.wave_size, m, s, delta, scale, inv_scale, inv_s);
    let (x0, z0) = ((fx as u32).min(s - 1), (fz as u32).min(s - 1));
    let (ax, az) = (fx - x0 as f32, fz - z0 as f32);
    // The next texel, wrapped (`x0 < s`: a comparison, not a division).
    let (x1, z1) = (if x0 + 1 == s { 0 } else { x0 + 1 }, if z0 + 1 == s { 0 } else { z0 + 1 });
    let t00 = shafts[(base + z0 * s + x0) as usize].xyz();
    let t10 = shafts[(base + z0 * s + x1) as usize].xyz();
    let t01 = shafts[(base + z1 * s + x0) as usize].xyz();
    let t11 = shafts[(base + z1 * s + x1) as usize].xyz();
    (t00 * (1.0 - ax) + t10 * ax) * (1.0 - az) + (t01 * (1.0 - ax) + t11 * ax) * az
}

/// A position in tiles `u` as a continuous texel coordinate of a level
/// `s` texels wide (`mip_bilinear`), wrapped into `[0, s)`.
/// `inv_scale` and `inv_s` are `1 / scale` and `1 / s`, both powers of two.
fn mip_coord(u: f32, m: u32, s: u32, delta: f32, scale: f32, inv_scale: f32, inv_s: f32) -> f32 {
    let f0 = (u - u.floor()) * m as f32 - delta;
    let f = (f0 - (scale - 1.0) * 0.5) * inv_scale;
    f - (f * inv_s).floor() * s as f32
}
