//! Order 2 over a varying bottom with the paper's depth table (section
//! 5.4 of Iwasaki, Dobashi and Nishita, `../shared/papers/004_*`).
//!
//! The scattering maps (`mod.rs`) are built for flat bottoms, and a pixel's
//! order 2 is read between those built for the depths bracketing the
//! bottom where its view ray meets it: the water under the pixel taken as
//! flat. Light that reaches a point from below was scattered between the
//! point and the bottom *along the way it came*, which over a slope is
//! deeper or shallower than under the view ray. Section 5.4 marches every
//! sampling ray `(theta_m, phi_m)` from sampling points `P_s` on the planes
//! to the bottom in advance and keeps the depths `z_Q` in a table, so that
//! eq. 7 can use them.
//!
//! Here, three passes:
//! - `sea.table_samples`: the sampling points. The paper's lie on the
//!   planes in the scene; these lie on the view rays of a coarse grid
//!   across the image (`table_width x table_height`, the paper's 64 x 64),
//!   so that every one is seen and each knows its view direction, as the
//!   paper's per-viewpoint maps do. A flat surface refracts them. The
//!   levels along each view ray are graded from the surface to the bottom
//!   under it (or to `DEEP_OPTICAL_DEPTH` of the clearest channel), so a
//!   shallow column gets all `n_z` of them.
//! - `sea.depth_table`: for every sample, level and direction of the three
//!   sets the scattering maps use (the view's set around the sample's
//!   view), the vertical distance below the level to the bottom along the
//!   way light travelling in that direction came (`z_Q - z_k`).
//! - `sea.bottom_correction`: per sample, the order-2 radiance with the
//!   table's distances minus that with a flat bottom under the view ray (the
//!   same directions, levels and quadrature, so their errors largely
//!   cancel): only the upward directions differ. The per-pixel order 2 adds
//!   it, bilinear across the image, to the flat-bottom lookup.

use crate::camera::pixel_ndc;
use crate::glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use crate::phase::henyey_greenstein;
use crate::sea::{
    bottom_hit, exp_linear3, held_direction, horizon_window, march_to_bottom, order1_path_over, plane_depth,
    plane_reach, set_direction, set_size, set_weight, view_in_water, SeaParams, SET_SUN, SET_UNIFORM, SET_VIEW,
};
use crate::types::CommonParams;
use spirv_std::spirv;

/// At most this many march steps per table entry: light that has crossed
/// `TABLE_OPTICAL_DEPTH` of the clearest channel is cut there.
pub const TABLE_STEPS: u32 = 256;
/// Optical depth (clearest channel) beyond which a sampling ray's bottom
/// is not searched: the light scattered beyond it is `e^-12` of the rest.
pub const TABLE_OPTICAL_DEPTH: f32 = 12.0;

/// Number of table samples across the image (0 without a table).
pub fn table_samples(p: &SeaParams) -> u32 {
    p.table_width * p.table_height
}

/// Directions per sample and level: the maps' `3 N`.
pub fn table_directions(p: &SeaParams) -> u32 {
    3 * set_size(p)
}

/// Direction `m` of the table at a sample seeing along `view`: the maps'
/// held sets (around the refracted sun, uniform), then the view's set
/// around `view`; and which set it is.
pub fn table_direction(p: &SeaParams, view: Vec3, m: u32) -> (Vec3, u32) {
    let n = set_size(p);
    if m < n {
        (held_direction(p, m), SET_SUN)
    } else if m < 2 * n {
        (held_direction(p, m), SET_UNIFORM)
    } else {
        (set_direction(view, m - 2 * n, p.polar, p.azimuths, p.scattering.w), SET_VIEW)
    }
}

/// The image position (pixels, from the top left corner) of table sample `s`.
pub fn sample_position(common: &CommonParams, p: &SeaParams, s: u32) -> Vec2 {
    let (i, j) = (s % p.table_width, s / p.table_width);
    Vec2::new(
        i as f32 * common.width as f32 / (p.table_width - 1) as f32,
        j as f32 * common.height as f32 / (p.table_height - 1) as f32,
    )
}

/// Table samples kernel: element `index` of two per sample, `2s`: where the
/// sample's camera ray meets the (flat) surface, w the depth of the bottom
/// under the refracted ray (m); `2s + 1`: the upward direction toward the
/// eye in the water, w 1 (0 where the ray misses the sea: above the horizon
/// or from a camera below the surface).
pub fn table_sample_texel(index: u32, common: &CommonParams, p: &SeaParams, grid: &[f32]) -> Vec4 {
    let at = sample_position(common, p, index / 2);
    let ndc = pixel_ndc(common, 0, 0, at);
    let origin = common.camera_position.xyz();
    let dir =
        (common.camera_forward.xyz() + common.camera_right.xyz() * ndc.x + common.camera_up.xyz() * ndc.y).normalize();
    if dir.y >= 0.0 || origin.y <= p.level {
        return Vec4::ZERO;
    }
    let hit = origin + dir * ((p.level - origin.y) / dir.y);
    let view = view_in_water(dir, Vec3::Y, p.extinction.w);
    if index % 2 == 1 {
        return view.extend(1.0);
    }
    let (depth, _) = bottom_hit(p, grid, hit.x, hit.z, view);
    hit.extend(depth)
}

/// The levels of a sample whose view ray meets the bottom `depth` m down:
/// `plane_depth`'s grading, the same depths in every channel, down to the
/// bottom or to `DEEP_OPTICAL_DEPTH` of the clearest channel.
pub fn level_params(p: &SeaParams, depth: f32) -> SeaParams {
    let reach = plane_reach(p.extinction.xyz(), depth).max_element();
    SeaParams { depth, plane_depth: Vec4::splat(reach), ..*p }
}

/// Depth table kernel (section 5.4): entry `index` = (sample, level,
/// direction), the vertical distance (m) from the level on the sample's
/// view ray down to the bottom along the way light travelling in the
/// direction came; 0 for a downward direction (its light came from above)
/// or a sample off the sea.
pub fn depth_table_texel(index: u32, p: &SeaParams, grid: &[f32], samples: &[Vec4]) -> f32 {
    let n3 = table_directions(p);
    let (s, k, m) = (index / (n3 * p.planes), (index / n3) % p.planes, index % n3);
    let (point, view) = (samples[(2 * s) as usize], samples[(2 * s + 1) as usize]);
    if view.w == 0.0 {
        return 0.0;
    }
    let view = view.xyz();
    let (dir, _) = table_direction(p, view, m);
    if dir.y <= 0.0 {
        return 0.0;
    }
    let q = level_params(p, point.w);
    let z = plane_depth(&q, k).x;
    let along = z / view.y;
    let (x, zh) = (point.x - view.x * along, point.z - view.z * along);
    let mu = dir.y.max(1e-4);
    let reach = TABLE_OPTICAL_DEPTH / p.extinction.xyz().min_element().max(1e-6);
    let t_max = ((p.bottom_grid.w - z).max(0.0) / mu).min(reach);
    let t = march_to_bottom(p, grid, x, zh, z, dir, t_max, TABLE_STEPS);
    if t < 0.0 {
        t_max * mu
    } else {
        t * mu
    }
}

/// The order-2 source difference at level `k` of a sample: the maps'
/// direction sum (`scattering_source`'s weights) over the upward
/// directions, with the table's distances to the bottom minus with the flat
/// bottom `depth` under the view ray, W/(m^3 sr).
fn source_difference(p: &SeaParams, q: &SeaParams, k: u32, view: Vec3, table: &[f32], base: usize) -> Vec3 {
    let g = p.scattering.w;
    let sun = p.sun_in_water.xyz();
    let z = plane_depth(q, k);
    let flat = (Vec3::splat(q.depth) - z).max(Vec3::ZERO);
    let mut sum = Vec3::ZERO;
    let mut m = 0;
    while m < table_directions(p) {
        let (dir, set) = table_direction(p, view, m);
        if dir.y > 0.0 {
            let below = Vec3::splat(table[base + m as usize]);
            let (ps, pv) = (henyey_greenstein(sun.dot(dir), g), henyey_greenstein(dir.dot(view), g));
            let weight = set_weight(ps, pv, horizon_window(dir.y), set);
            let difference = order1_path_over(z, dir.y, below, q) - order1_path_over(z, dir.y, flat, q);
            sum += difference * (ps * pv * weight);
        }
        m += 1;
    }
    let b = p.scattering.xyz();
    b * b * p.beam_irradiance.xyz() * sum / set_size(p) as f32
}

/// Bottom correction kernel: per sample, the order-2 radiance below the
/// surface toward its eye with the depth table's bottom minus that with a
/// flat bottom under its view ray (rgb, W/(m^2 sr)); `accumulate_planes`'
/// quadrature (the source linear between levels against the known
/// exponential, the attenuation map `e^(-c z/mu_v)`), signed.
pub fn bottom_correction_texel(s: u32, p: &SeaParams, samples: &[Vec4], table: &[f32]) -> Vec4 {
    let (point, view) = (samples[(2 * s) as usize], samples[(2 * s + 1) as usize]);
    if view.w == 0.0 {
        return Vec4::ZERO;
    }
    let view = view.xyz();
    let q = level_params(p, point.w);
    let c = p.extinction.xyz();
    let mu_v = view.y.max(1e-6);
    let kappa = c * (1.0 / p.sun_in_water.w + 1.0 / mu_v);
    let n3 = table_directions(p) as usize;
    let base = s as usize * p.planes as usize * n3;
    let mut z_a = plane_depth(&q, 0);
    let mut h_a = source_difference(p, &q, 0, view, table, base) * (-c * z_a / mu_v).exp() / mu_v;
    let mut sum = Vec3::ZERO;
    let mut k = 1;
    while k < p.planes {
        let z_b = plane_depth(&q, k);
        let h_b = source_difference(p, &q, k, view, table, base + k as usize * n3) * (-c * z_b / mu_v).exp() / mu_v;
        sum += exp_linear3(z_b - z_a, h_a, h_b, kappa);
        z_a = z_b;
        h_a = h_b;
        k += 1;
    }
    sum.extend(0.0)
}

/// The bottom correction at image position `at` (pixels): bilinear between
/// the four samples around it.
pub fn correction_at(p: &SeaParams, common: &CommonParams, correction: &[Vec4], at: Vec2) -> Vec3 {
    let fx = (at.x / common.width as f32 * (p.table_width - 1) as f32).clamp(0.0, (p.table_width - 1) as f32);
    let fy = (at.y / common.height as f32 * (p.table_height - 1) as f32).clamp(0.0, (p.table_height - 1) as f32);
    let (i, j) = ((fx as u32).min(p.table_width - 2), (fy as u32).min(p.table_height - 2));
    let (ax, ay) = (fx - i as f32, fy - j as f32);
    let w = p.table_width as usize;
    let base = j as usize * w + i as usize;
    let (a, b) = (correction[base].xyz(), correction[base + 1].xyz());
    let (c, d) = (correction[base + w].xyz(), correction[base + w + 1].xyz());
    (a * (1.0 - ax) + b * ax) * (1.0 - ay) + (c * (1.0 - ax) + d * ax) * ay
}

#[spirv(compute(threads(64)))]
pub fn table_samples_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 36)] samples: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < 2 * table_samples(p) {
        samples[index as usize] = table_sample_texel(index, &common[0], p, bottom);
    }
}

#[spirv(compute(threads(64)))]
pub fn depth_table_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 28)] bottom: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 36)] samples: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 37)] table: &mut [f32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < table_samples(p) * p.planes * table_directions(p) {
        table[index as usize] = depth_table_texel(index, p, bottom, samples);
    }
}

#[spirv(compute(threads(64)))]
pub fn bottom_correction_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 19)] params: &[SeaParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 36)] samples: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 37)] table: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 38)] correction: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < table_samples(p) {
        correction[index as usize] = bottom_correction_texel(index, p, samples, table);
    }
}
