//! The reference renderer: f64, no shadow maps (shadow rays are cast against
//! the actual spheres and triangles), no tables. It shares the scene and the
//! pixel positions with the kernels and nothing of their method, so the
//! difference between the two is the method's error.
//!
//! It renders eq. 1 of the 2002 shafts-of-light paper at the same sub-pixel
//! positions as the kernels (`camera::sample_offset`; the pixel centre at one
//! sample per pixel), averaged with the same box filter: the
//! attenuated surface radiance `I_o exp(-sigma_t T)` plus the in-scattered
//! light of eq. 2, integrated by a stratified ray march (jittered samples, f64
//! sums, a shadow ray per sample and light) over the same range as the
//! shafts pass: from the eye to the surface or to the far end of the scene's
//! bounds (`depth_far`), whichever is nearer. The sample count doubles until
//! the image stops changing (see `render_converged`).

use glam::{DVec3, Vec4, Vec4Swizzles};
use rayon::prelude::*;
use slicelight_shaders::camera::sample_offset;
use slicelight_shaders::optics;
use slicelight_shaders::types::{GpuLight, LIGHT_DIRECTIONAL, LIGHT_POINT, MATERIAL_GLASS, PROJECTION_FISHEYE};

use crate::sea::reference::{grid_depth, CausticReference, HeightField, SeaReference, ShaftReference};
use crate::sky::reference::SkyReference;

/// Relative tolerance of the sky's adaptive quadratures (see `sky_reference`;
/// the `reference_converges` test measures its error: below 1e-4 of the sky's peak).
pub const SKY_TOLERANCE: f64 = 1e-6;

/// Relative tolerance of the sea's adaptive quadratures (`sea_reference`):
/// against 1e-6 it changes orders 1 and 2 by 9e-8 of their values (test
/// `reference_tolerance_is_converged`, which allows 1e-3), at ~0.2 s per pixel.
pub const SEA_TOLERANCE: f64 = 1e-4;
/// Tolerance of order 2 over a varying bottom (`order2_over`, about a
/// second a pixel at this): within 2e-3 of 1e-4's (test
/// `shore_order2_against_the_height_field_quadrature`).
pub const SEA_HEIGHT_FIELD_TOLERANCE: f64 = 1e-3;

use crate::scene::SceneData;

pub(crate) fn d3(v: Vec4) -> DVec3 {
    v.xyz().as_dvec3()
}

#[derive(Clone)]
pub(crate) struct Surface {
    pub t: f64,
    /// Unit geometric normal, not turned to face the ray.
    pub normal: DVec3,
    pub albedo: DVec3,
    pub material: u32,
    /// The triangle hit (BVH order), `usize::MAX` for a sphere.
    pub triangle: usize,
}

/// Where the ray `o + t d` (`inv = 1 / d`) enters and leaves the box
/// `[lo, hi]` within `[t_min, t_max]`, f64 slab test; it misses unless
/// `near <= far`.
pub(crate) fn box_span(o: DVec3, inv: DVec3, lo: DVec3, hi: DVec3, t_min: f64, t_max: f64) -> (f64, f64) {
    let a = (lo - o) * inv;
    let b = (hi - o) * inv;
    (a.min(b).max_element().max(t_min), a.max(b).min_element().min(t_max))
}

/// Whether the ray meets the box `[lo, hi]` within `[t_min, t_max]` (`box_span`).
fn hits_box(o: DVec3, inv: DVec3, lo: DVec3, hi: DVec3, t_min: f64, t_max: f64) -> bool {
    let (near, far) = box_span(o, inv, lo, hi, t_min, t_max);
    // A NaN (origin on a face, ray parallel to it) fails the test; the boxes
    // are padded beyond their triangles, so no hit is lost.
    near <= far
}

/// Nearest intersection beyond `t_min`, in f64. Triangles are found through
/// the scene's BVH (its boxes padded beyond the triangles, so the walk
/// skips only what cannot be hit), each tested exactly in f64.
pub(crate) fn nearest(data: &SceneData, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<Surface> {
    let mut best: Option<Surface> = None;
    let mut limit = t_max;
    let albedo = |material: u32| d3(data.materials[material as usize].albedo);
    for s in &data.spheres {
        let c = d3(s.center_radius);
        let r = s.center_radius.w as f64;
        let oc = c - o;
        let tc = oc.dot(d);
        let d2 = (oc - d * tc).length_squared();
        if d2 > r * r {
            continue;
        }
        let half = (r * r - d2).sqrt();
        for t in [tc - half, tc + half] {
            if t > t_min && t < limit {
                limit = t;
                best = Some(Surface {
                    t,
                    normal: (o + d * t - c).normalize(),
                    albedo: albedo(s.material),
                    material: s.material,
                    triangle: usize::MAX,
                });
                break;
            }
        }
    }
    let inv = DVec3::ONE / d;
    let mut n = 0;
    while n < data.bvh_nodes.len() {
        let node = &data.bvh_nodes[n];
        if !hits_box(o, inv, d3(node.bounds_min), d3(node.bounds_max), t_min, limit) {
            n = node.skip as usize;
            continue;
        }
        if node.count == 0 {
            n += 1;
            continue;
        }
        for (k, tri) in data.triangles[node.first as usize..(node.first + node.count) as usize].iter().enumerate() {
            let (a, b, c) = (d3(tri.v0), d3(tri.v1), d3(tri.v2));
            let nrm = (b - a).cross(c - a);
            let denom = nrm.dot(d);
            if denom.abs() < 1e-300 {
                continue;
            }
            let t = nrm.dot(a - o) / denom;
            if !(t > t_min && t < limit) {
                continue;
            }
            let p = o + d * t;
            // Inside test by the signs of the sub-triangle areas.
            let inside = nrm.dot((b - a).cross(p - a)) >= 0.0
                && nrm.dot((c - b).cross(p - b)) >= 0.0
                && nrm.dot((a - c).cross(p - c)) >= 0.0;
            if inside {
                limit = t;
                best = Some(Surface {
                    t,
                    normal: nrm.normalize(),
                    albedo: albedo(tri.material),
                    material: tri.material,
                    triangle: node.first as usize + k,
                });
            }
        }
        n = node.skip as usize;
    }
    best
}

/// Whether the segment from `p` toward the light is free of geometry.
pub(crate) fn sees_light(data: &SceneData, p: DVec3, to_light: DVec3, distance: f64) -> bool {
    // Start a hair off the point, relative to its magnitude, so that the
    // surface it lies on does not shadow itself; stop a hair short of the
    // light, relative to its distance. (The start does not grow with the
    // distance: a sun's entry plane can be 400 km off, where 1e-7 of it
    // would skip 4 cm of the ray.)
    let start = 1e-7 * (1.0 + p.length());
    let end = distance - 1e-7 * (1.0 + p.length()).max(distance);
    nearest(data, p, to_light, start, end).is_none()
}

/// Light map and cone profile, evaluated directly from the light's definition.
pub(crate) fn emitted(data: &SceneData, light: &GpuLight, local: DVec3) -> DVec3 {
    let power = d3(light.power);
    if light.kind == LIGHT_POINT {
        return power;
    }
    let (u, v) = if light.kind == LIGHT_DIRECTIONAL {
        if local.z < 0.0 {
            return DVec3::ZERO;
        }
        let u = 0.5 + 0.5 * local.x / light.half_extent_x as f64;
        let v = 0.5 + 0.5 * local.y / light.half_extent_y as f64;
        if light.bounded != 0 && !((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)) {
            return DVec3::ZERO;
        }
        (u, v)
    } else {
        if local.z <= 0.0 {
            return DVec3::ZERO;
        }
        let angle = (local.x.hypot(local.y)).atan2(local.z);
        let (cut, beam) = (light.cutoff as f64, light.beam as f64);
        if angle > cut {
            return DVec3::ZERO;
        }
        let profile = if beam >= cut { 1.0 } else { ((cut - angle) / (cut - beam)).clamp(0.0, 1.0) };
        let s = 0.5 / (local.z * cut.tan());
        return power * profile * light_map(data, light, 0.5 + local.x * s, 0.5 + local.y * s);
    };
    power * light_map(data, light, u, v)
}

/// Bilinear light-map lookup in f64 (the light map is an input, like the
/// geometry: its filtering is part of the scene's definition).
fn light_map(data: &SceneData, light: &GpuLight, u: f64, v: f64) -> DVec3 {
    let (w, h) = (light.light_map_width as usize, light.light_map_height as usize);
    if w == 0 {
        return DVec3::ONE;
    }
    let fx = (u * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
    let fy = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let at = |x: usize, y: usize| d3(data.light_map[light.light_map_offset as usize + y * w + x]);
    let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
    let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
    top * (1.0 - ty) + bottom * ty
}

/// The view ray through sub-pixel sample `sample` of pixel `(x, y)`, in
/// f64, at the kernels' sample position (`camera::sample_offset`); `None`
/// outside a fisheye's image circle.
pub(crate) fn camera_ray(data: &SceneData, x: u32, y: u32, sample: u32) -> Option<(DVec3, DVec3)> {
    let p = &data.common;
    let offset = sample_offset(sample, p.samples_per_pixel).as_dvec2();
    if p.projection == PROJECTION_FISHEYE {
        // Equidistant: the angle from the view direction is 90 degrees times
        // the distance from the image centre over the inscribed circle's radius.
        let size = p.width.min(p.height) as f64;
        let cx = (2.0 * (x as f64 + offset.x) - p.width as f64) / size;
        let cy = (p.height as f64 - 2.0 * (y as f64 + offset.y)) / size;
        let radius = cx.hypot(cy);
        if radius > 1.0 {
            return None;
        }
        let theta = radius * std::f64::consts::FRAC_PI_2;
        let side = if radius > 0.0 { (d3(p.camera_right) * cx + d3(p.camera_up) * cy) / radius } else { DVec3::ZERO };
        let d = (d3(p.camera_forward) * theta.cos() + side * theta.sin()).normalize();
        return Some((d3(p.camera_position), d));
    }
    let ndc_x = 2.0 * (x as f64 + offset.x) / p.width as f64 - 1.0;
    let ndc_y = 1.0 - 2.0 * (y as f64 + offset.y) / p.height as f64;
    let o = d3(p.camera_position);
    let d = (d3(p.camera_forward) + d3(p.camera_right) * ndc_x + d3(p.camera_up) * ndc_y).normalize();
    Some((o, d))
}

/// A point in a light's frame, the unit direction from it toward the light,
/// and the distance the light travels to it (from a spotlight, or from a
/// directional light's entry plane), metres.
pub(crate) fn toward_light(light: &GpuLight, point: DVec3) -> (DVec3, DVec3, f64) {
    let rel = point - d3(light.position);
    let local = DVec3::new(rel.dot(d3(light.axis_x)), rel.dot(d3(light.axis_y)), rel.dot(d3(light.axis_z)));
    if light.kind == LIGHT_DIRECTIONAL {
        (local, -d3(light.axis_z), local.z)
    } else {
        let s = rel.length();
        (local, -rel / s.max(1e-300), s)
    }
}

/// The inverse-square falloff of a spot or point light at `distance` (m),
/// 1 for a directional light. The kernels' point light has radius
/// `LIGHT_RADIUS` in `1/s^2`.
pub(crate) fn falloff(light: &GpuLight, distance: f64) -> f64 {
    if light.kind == LIGHT_DIRECTIONAL {
        1.0
    } else {
        let r = distance.max(slicelight_shaders::shafts::LIGHT_RADIUS as f64);
        1.0 / (r * r)
    }
}

/// Whether the reference renders what the scene holds: an error naming
/// the part it leaves out.
pub fn supports(data: &SceneData) -> anyhow::Result<()> {
    let p = &data.sea.params;
    if data.sea.enabled && p.underwater != 0 {
        // Objects wholly above the water: seen through Snell's window and
        // shading the water's light (`sea_radiance_under`).
        let lowest = crate::scene::geometry::bounds(&data.spheres, &data.triangles).map_or(f32::INFINITY, |b| b.0.y);
        if lowest <= p.level {
            anyhow::bail!(
                "reference: objects under the water seen from below are not in the reference (objects wholly above \
                 the surface are): an object reaches down to y = {lowest} m, the water's level is {} m",
                p.level
            );
        }
        if p.bottom_nx >= 2 {
            anyhow::bail!("reference: an eye under the water over a varying bottom (sea.bottom) is not in the reference; use depth_m");
        }
    }
    Ok(())
}

/// Attenuated surface radiance at one sub-pixel sample, and the distance to
/// the surface (infinite where the ray meets none), f64.
fn surface_and_distance(data: &SceneData, x: u32, y: u32, sample: u32) -> (DVec3, f64) {
    let p = &data.common;
    let Some((o, d)) = camera_ray(data, x, y, sample) else {
        return (DVec3::ZERO, f64::INFINITY);
    };
    if data.sea.enabled && data.sea.params.underwater != 0 {
        return (sea_radiance_under(data, o, d), f64::INFINITY);
    }
    let Some(hit) = nearest(data, o, d, 0.0, f64::INFINITY) else {
        if data.sea.enabled && d.y < 0.0 {
            return (sea_radiance(data, o, d), f64::INFINITY);
        }
        // The sky (if any) where the ray meets no surface.
        let sky = data.sky.enabled.then(|| SkyReference::new(&data.sky.params, SKY_TOLERANCE).radiance(d));
        return (sky.unwrap_or(DVec3::ZERO), f64::INFINITY);
    };
    let sigma_t = d3(p.sigma_t);
    // The air between the eye and the surface (aerial perspective).
    let air = |radiance: DVec3| {
        if data.sky.enabled && data.sky.aerial {
            let (light, through) = SkyReference::new(&data.sky.params, SKY_TOLERANCE).segment(d, hit.t);
            radiance * through + light
        } else {
            radiance
        }
    };
    if data.materials[hit.material as usize].kind == MATERIAL_GLASS {
        return (air(glass_seen(data, o, d, &hit)), hit.t);
    }
    // A terrain's ripples at their full resolution (the LOD's truth).
    let hit = crate::desert::reference::rippled(data, o, d, hit.clone());
    // The sky's own light on a surface seen directly.
    let normal = if hit.normal.dot(d) > 0.0 { -hit.normal } else { hit.normal };
    let sky = crate::sky::reference::sky_light(data, o + d * hit.t, normal, hit.albedo);
    (air((direct(data, o, d, &hit) + sky) * (-sigma_t * hit.t).exp()), hit.t)
}

/// The light toward `o` along the ray `o + t d` whose first hit `hit` is
/// glass, f64. Through the glass: the opaque surface behind, lit directly
/// (and by the sky's light under a sky), per channel; or, under a sky, the
/// sky where the ray leaves the glass for good. Reflected at the first
/// interface: the opaque surface the mirrored ray meets, lit the same way,
/// or the sky (a second glass is not followed). The `[medium]` attenuates
/// the way to the surfaces, not to the sky (as the sky seen directly).
fn glass_seen(data: &SceneData, o: DVec3, d: DVec3, hit: &Surface) -> DVec3 {
    let sigma_t = d3(data.common.sigma_t);
    let mut radiance = DVec3::ZERO;
    let (q, r, mirrored) = crate::caustics::reference::glass_reflection(data, o, d, hit);
    let mut sky = open_sky(data, q, mirrored) * r;
    if let Some(seen) = object_in_air(data, q, mirrored) {
        radiance += seen * r;
    }
    for c in 0..3 {
        match crate::caustics::reference::through_glass(data, o, d, hit, c) {
            Some((q, dir, weight, Some(behind))) => {
                // Lit by the lights and, under a sky, by the sky.
                let at = q + dir * behind.t;
                let normal = if behind.normal.dot(dir) > 0.0 { -behind.normal } else { behind.normal };
                let sky_light = crate::sky::reference::sky_light(data, at, normal, behind.albedo);
                let l = (direct(data, q, dir, &behind) + sky_light) * (-sigma_t * behind.t).exp();
                radiance[c] += l[c] * weight;
            }
            Some((q, dir, weight, None)) => sky[c] += open_sky(data, q, dir)[c] * weight,
            None => {}
        }
    }
    radiance * (-sigma_t * hit.t).exp() + sky
}

/// What lies along `dir` from `from` if nothing is in the way: the sky
/// (and the sun's disk), or with a `[sea]` under an eye above it the sea
/// (`sea_radiance`, as a view ray that meets the water directly) where the
/// ray goes down; else 0. Not attenuated by a `[medium]` on the way out,
/// as the sky seen directly is not.
fn open_sky(data: &SceneData, from: DVec3, dir: DVec3) -> DVec3 {
    if !data.sky.enabled {
        return DVec3::ZERO;
    }
    let sea = data.sea.enabled && dir.y < 0.0;
    if sea && (data.sea.params.underwater != 0 || from.y <= data.sea.params.level as f64) {
        return DVec3::ZERO;
    }
    if nearest(data, from, dir, crate::caustics::reference::epsilon(from), f64::INFINITY).is_some() {
        return DVec3::ZERO;
    }
    if sea {
        return sea_radiance_mirroring(data, from, dir, false);
    }
    SkyReference::new(&data.sky.params, SKY_TOLERANCE).radiance(dir)
}

/// Points per line light of the reference's direct light: the midpoint
/// rule over the segment, each point one shadow ray. Where the segment is
/// partly hidden the error is at most 1/256 of the line's irradiance (one
/// piece seen or not); elsewhere it falls as the square of the piece's
/// length. The method sees the line as `points` point lights.
pub const LINE_REFERENCE_POINTS: usize = 256;

/// Radiance leaving the opaque surface `hit` of the ray `o + t d` toward
/// its origin, lit directly by every light (shadow rays), f64. A line light
/// is integrated along its segment (`LINE_REFERENCE_POINTS`), not taken as
/// the point lights the kernels see.
pub(crate) fn direct(data: &SceneData, o: DVec3, d: DVec3, hit: &Surface) -> DVec3 {
    let point = o + d * hit.t;
    let normal = if hit.normal.dot(d) > 0.0 { -hit.normal } else { hit.normal };
    let mut irradiance = DVec3::ZERO;
    for (i, light) in data.lights.iter().enumerate() {
        if data.is_line_point(i) {
            continue;
        }
        let (local, to_light, distance) = toward_light(light, point);
        let falloff = if light.kind == LIGHT_DIRECTIONAL { 1.0 } else { 1.0 / (distance * distance) };
        irradiance += incident(data, point, normal, to_light, distance, falloff, || emitted(data, light, local));
    }
    for line in &data.line_lights {
        let (a, b) = (line.from.as_dvec3(), line.to.as_dvec3());
        let piece = line.per_metre.as_dvec3() * ((b - a).length() / LINE_REFERENCE_POINTS as f64);
        for k in 0..LINE_REFERENCE_POINTS {
            let rel = a + (b - a) * ((k as f64 + 0.5) / LINE_REFERENCE_POINTS as f64) - point;
            let distance = rel.length();
            let falloff = 1.0 / (distance * distance);
            irradiance += incident(data, point, normal, rel / distance.max(1e-300), distance, falloff, || piece);
        }
    }
    hit.albedo * irradiance / std::f64::consts::PI
}

/// Irradiance at `point` (unit `normal`) from a light `distance` away
/// toward `to_light` emitting `intensity()` that way (W/sr, or W/m^2 for a
/// directional light with `falloff` 1), if it sees the light.
fn incident(
    data: &SceneData,
    point: DVec3,
    normal: DVec3,
    to_light: DVec3,
    distance: f64,
    falloff: f64,
    intensity: impl Fn() -> DVec3,
) -> DVec3 {
    let cos = normal.dot(to_light);
    if cos <= 0.0 {
        return DVec3::ZERO;
    }
    let e = intensity();
    // A directional light's shadow ray ends at its entry plane.
    if e == DVec3::ZERO || !sees_light(data, point, to_light, distance) {
        return DVec3::ZERO;
    }
    let attenuation = (-d3(data.common.sigma_t) * distance).exp();
    let clouds = crate::volumes::reference::transmittance_toward(data, point, to_light, distance);
    e * attenuation * clouds * (cos * falloff)
}

/// The sea along the view ray `(o, d)` (downward, from above the surface),
/// f64: the sky and sun reflected (the sky's reference), and orders 1, 2 and
/// the bottom below the refracting surface (the sea's quadrature), times
/// `(1 - R)/n^2`. The surface normal is the scene's (the wave map's at the
/// hit, or up).
pub fn sea_radiance(data: &SceneData, o: DVec3, d: DVec3) -> DVec3 {
    sea_radiance_mirroring(data, o, d, true)
}

/// `sea_radiance`, the surface mirroring glass (`glass`) or, seen from
/// glass (`open_sky`), only opaque objects: glass mirrored by the sea seen
/// through glass is a third meeting with the water and the glass, which
/// the method leaves out (`sea_along` mirrors no object), and under waves
/// each level of it multiplies the reference's rays by about 270 (every
/// slope and sun direction of `rough_reflection`).
fn sea_radiance_mirroring(data: &SceneData, o: DVec3, d: DVec3, glass: bool) -> DVec3 {
    let seen = |from: DVec3, w: DVec3| if glass { seen_in_air(data, from, w) } else { object_in_air(data, from, w) };
    let p = &data.sea.params;
    let t = (p.level as f64 - o.y) / d.y;
    let hit = o + d * t;
    let mut normal =
        slicelight_shaders::sea::surface_normal(p, &data.sea.waves, hit.x as f32, hit.z as f32).as_dvec3().normalize();
    if normal.dot(d) >= 0.0 {
        normal = DVec3::Y;
    }
    let n = p.extinction.w as f64;
    let cos_i = -d.dot(normal);
    let sky_reference = SkyReference::new(&data.sky.params, SKY_TOLERANCE);
    // The clouds' shadow at the surface point (the sun's transmittance
    // through the volumes, marched in f64): on the light below and on the
    // sun reflected there.
    let clouds = match p.sun_light {
        0 => DVec3::ONE,
        l => {
            let (_, to_light, distance) = toward_light(&data.lights[l as usize - 1], hit);
            crate::volumes::reference::transmittance_toward(data, hit, to_light, distance)
        }
    };
    // Waves: the map's slope at the hit, roughened by the unresolved waves
    // (`crate::sea::reference::rough_reflection`); the light below is taken
    // along the view refracted at the map's normal, times the mean
    // transmission. A flat sea: one mirror.
    let (sky, r) = if p.waves == slicelight_shaders::sea::WAVES_NORMAL_MAP {
        let slope = glam::DVec2::new(-normal.x / normal.y, -normal.z / normal.y);
        let rough = p.roughness.truncate().as_dvec3();
        let objects = |w: DVec3| seen(hit, w);
        let shade = clouds * sun_over_water(data, hit);
        let (light, r) = crate::sea::reference::rough_reflection(
            &sky_reference,
            &data.sky.params,
            d,
            slope,
            rough,
            n,
            shade,
            &objects,
        );
        (light / r.max(1e-300), r)
    } else {
        let r = optics::reflectance(cos_i, 1.0 / n);
        let reflected = d + normal * (2.0 * cos_i);
        let reflected = DVec3::new(reflected.x, reflected.y.abs(), reflected.z).normalize();
        let without_sun = sky_reference.sky_without_sun(reflected);
        let mirrored = seen(hit, reflected)
            .unwrap_or_else(|| without_sun + (sky_reference.radiance(reflected) - without_sun) * clouds);
        (mirrored, r)
    };
    // Snell: the refracted ray, reversed, is the direction light leaves the water toward the eye.
    let eta = 1.0 / n;
    let (cos_t, _) = optics::transmitted_cosine(cos_i, eta);
    let mut view = -(d * eta + normal * (eta * cos_i - cos_t)).normalize();
    if view.y < 1e-4 {
        view = DVec3::new(view.x, 1e-4, view.z).normalize();
    }
    // A varying bottom: order 1 and the bottom's reflection are exact with
    // the depth where the view ray meets it (the bottom's tilt enters eq.
    // 9's cosine); order 2 is integrated over the real height field
    // (`order2_over`: every direction marched to the bottom), not over the
    // method's locally flat water.
    let grid = &data.sea.bottom;
    let (depth, cos_gamma) = slicelight_shaders::sea::bottom_hit(p, grid, hit.x as f32, hit.z as f32, view.as_vec3());
    let local = slicelight_shaders::sea::SeaParams { depth, ..*p };
    let sea = SeaReference::new(&local, SEA_TOLERANCE);
    // The waves' caustic where the view ray meets the bottom (photon
    // traced): a flat bottom's own map, a varying bottom's from the maps at
    // the shaft planes' depths (`ShaftReference`), as the renderer reads them.
    let q = hit - view * (depth as f64 / view.y);
    let focus = if p.bottom_nx >= 2 {
        shaft_reference(data).map_or(DVec3::ONE, |s| s.at(q.x, depth as f64, q.z))
    } else {
        caustic_reference(data).map_or(DVec3::ONE, |c| c.at(q.x, q.z))
    };
    let bottom = sea.bottom(view) * (cos_gamma as f64 / sea.mu_s) * focus;
    let second = if !data.sea.second_order {
        DVec3::ZERO
    } else if p.bottom_nx >= 2 {
        let height = grid_depth(p, grid);
        let field = HeightField::of_sea(p, &height);
        SeaReference::new(p, SEA_HEIGHT_FIELD_TOLERANCE).order2_over(&field, (hit.x, hit.z), view)
    } else {
        sea.order2(view)
    };
    let below = (sea.order1(view) + second + bottom) * clouds;
    sky * r + below * ((1.0 - r) / (n * n))
}

/// The sea seen by an eye under it along the view ray `(o, d)`, f64, over
/// a flat bottom, with objects only above the water (`supports`): orders 1
/// and 2 gathered along the ray by quadrature (`SeaReference::order1_segment`,
/// `order2_segment`; order 1 point by point where the waves focus the sun
/// or objects shade it, `order1_focused`), and at its end, attenuated, the
/// bottom lit by the refracted sun, or the surface from below at the
/// scene's normal (the wave map's at the point, or up): through it (`(1 -
/// R) n^2`) the object the refracted ray meets, lit by the lights and the
/// sky (`direct`, `sky::reference::sky_light`), or the sky and sun (the
/// sky's reference), and the water below reflected (`R` times the sea's
/// quadrature toward the surface, as an eye above the water sees it).
/// Order 2, the bottom and the reflected water keep the unshaded beam, as
/// the method's do.
pub fn sea_radiance_under(data: &SceneData, o: DVec3, d: DVec3) -> DVec3 {
    let p = &data.sea.params;
    let z_e = (p.level as f64 - o.y).max(0.0);
    let n = p.extinction.w as f64;
    let sea = SeaReference::new(p, SEA_TOLERANCE);
    let deep = p.depth >= slicelight_shaders::sea::DEEP;
    let length = if d.y > 0.0 {
        z_e / d.y
    } else if d.y < 0.0 && !deep {
        (p.depth as f64 - z_e) / -d.y
    } else {
        f64::INFINITY
    };
    let clouds_at = |point: DVec3| match p.sun_light {
        0 => DVec3::ONE,
        l => {
            let (_, to_light, distance) = toward_light(&data.lights[l as usize - 1], point);
            crate::volumes::reference::transmittance_toward(data, point, to_light, distance)
        }
    };
    let above = DVec3::new(o.x, p.level as f64, o.z);
    // Order 1 through the waves' focusing where the renderer builds shafts
    // (photon traced, read per point of a fine quadrature), else the flat beam.
    let shafts = shaft_reference(data);
    let mut along = if shafts.is_some() || data.has_geometry() {
        // Shadows: 1 cm steps; the shafts: a quarter of a wave texel.
        let step = match shafts {
            Some(_) => p.wave_size as f64 / p.wave_resolution as f64 / 4.0,
            None => 0.01,
        };
        sea.order1_focused(o, p.level as f64, d, length, step, &|x: DVec3| {
            let focus = shafts.as_ref().map_or(DVec3::ONE, |s| s.at(x.x, p.level as f64 - x.y, x.z));
            focus * sun_in_water_visible(data, x)
        })
    } else {
        sea.order1_segment(z_e, d, length)
    };
    if data.sea.second_order {
        along += sea.order2_segment(z_e, d, length);
    }
    let mut light = along * clouds_at(above);
    if !length.is_finite() {
        return light;
    }
    let att = (-sea.c * length).exp();
    let end = o + d * length;
    let end_above = DVec3::new(end.x, p.level as f64, end.z);
    let caustic = caustic_reference(data);
    let focus = |q: DVec3| caustic.as_ref().map_or(DVec3::ONE, |c| c.at(q.x, q.z));
    if d.y < 0.0 {
        return light + sea.bottom_leaving(p.depth as f64, sea.mu_s) * focus(end) * att * clouds_at(end_above);
    }
    let mut normal =
        slicelight_shaders::sea::surface_normal(p, &data.sea.waves, end.x as f32, end.z as f32).as_dvec3().normalize();
    if normal.dot(d) <= 0.0 {
        normal = DVec3::Y;
    }
    let cos_i = d.dot(normal);
    let r = optics::reflectance(cos_i, n);
    if r < 1.0 {
        // Snell from the water side: the ray leaves toward the sky.
        let (cos_t, _) = optics::transmitted_cosine(cos_i, n);
        let out = (d * n + (-normal) * (n * cos_i - cos_t)).normalize();
        let out = DVec3::new(out.x, out.y.abs(), out.z).normalize();
        let air = seen_in_air(data, end, out).unwrap_or_else(|| {
            let sky = SkyReference::new(&data.sky.params, SKY_TOLERANCE);
            let without_sun = sky.sky_without_sun(out);
            without_sun + (sky.radiance(out) - without_sun) * clouds_at(end)
        });
        light += air * ((1.0 - r) * n * n) * att;
    }
    let mut up = -(d - normal * (2.0 * d.dot(normal)));
    if up.y < 1e-4 {
        up = DVec3::new(up.x, 1e-4, up.z).normalize();
    }
    let mut below = sea.order1(up) + sea.bottom(up) * focus(end - up * (p.depth as f64 / up.y));
    if data.sea.second_order {
        below += sea.order2(up);
    }
    light + below * r * att * clouds_at(end)
}

/// What the ray from `from` along `dir` meets in the air over the sea
/// (from the water's surface: through Snell's window, or mirrored): an
/// opaque object lit (`object_in_air`), or glass with what lies beyond it
/// and what it mirrors (`glass_seen`); `None` where it meets nothing.
pub fn seen_in_air(data: &SceneData, from: DVec3, dir: DVec3) -> Option<DVec3> {
    let eps = crate::caustics::reference::epsilon(from);
    let hit = nearest(data, from, dir, eps, f64::INFINITY)?;
    if data.materials[hit.material as usize].kind == MATERIAL_GLASS {
        return Some(glass_seen(data, from, dir, &hit));
    }
    object_in_air(data, from, dir)
}

/// The light of the object (not glass) that the ray from `from` along
/// `dir` meets (from the water's surface into the air, from glass by
/// reflection), lit as one seen directly (`direct` and the sky's light,
/// the `[medium]` on the way); `None` where it meets nothing or glass.
pub fn object_in_air(data: &SceneData, from: DVec3, dir: DVec3) -> Option<DVec3> {
    let eps = crate::caustics::reference::epsilon(from);
    let hit = nearest(data, from, dir, eps, f64::INFINITY)
        .filter(|hit| data.materials[hit.material as usize].kind != MATERIAL_GLASS)?;
    let at = from + dir * hit.t;
    let normal = if hit.normal.dot(dir) > 0.0 { -hit.normal } else { hit.normal };
    let sky_light = crate::sky::reference::sky_light(data, at, normal, hit.albedo);
    Some((direct(data, from, dir, &hit) + sky_light) * (-d3(data.common.sigma_t) * hit.t).exp())
}

/// 1 where no object hides the sun from the point `x` of the water's
/// surface, else 0 (its glint there).
pub fn sun_over_water(data: &SceneData, x: DVec3) -> f64 {
    let sun = data.sea.params.sun_direction.xyz().as_dvec3().normalize();
    let eps = crate::caustics::reference::epsilon(x);
    if sun.y > 0.0 && nearest(data, x, sun, eps, f64::INFINITY).is_some() {
        0.0
    } else {
        1.0
    }
}

/// 1 where the refracted sun reaches the point `x` in the water, 0 where
/// an object is in the way: up the refracted beam to the surface, then
/// toward the sun in the air (the method's `under::sun_visibility`).
fn sun_in_water_visible(data: &SceneData, x: DVec3) -> f64 {
    let p = &data.sea.params;
    let up = -p.sun_in_water.xyz().as_dvec3().normalize();
    let t_s = (p.level as f64 - x.y).max(0.0) / up.y.max(1e-12);
    let eps = crate::caustics::reference::epsilon(x);
    if t_s > eps && nearest(data, x, up, eps, t_s).is_some() {
        return 0.0;
    }
    sun_over_water(data, x + up * t_s)
}

/// The scene's waves' caustic for the reference (`CausticReference`),
/// traced once and kept for the scenes that share the sea's parameters and
/// wave slopes (`cached`).
fn caustic_reference(data: &SceneData) -> Option<std::sync::Arc<CausticReference>> {
    static CACHE: Cache<CausticReference> = std::sync::Mutex::new(Vec::new());
    cached(&CACHE, data, || CausticReference::new(&data.sea.params, &data.sea.waves))
}

/// The scene's shafts' caustics for the reference (`ShaftReference`:
/// about 4 million photons, 4 to 64 per wave texel), kept as
/// `caustic_reference` keeps its.
fn shaft_reference(data: &SceneData) -> Option<std::sync::Arc<ShaftReference>> {
    static CACHE: Cache<ShaftReference> = std::sync::Mutex::new(Vec::new());
    let n = data.sea.params.wave_resolution as f64;
    let side = ((4.0e6f64).sqrt() / n).round().clamp(4.0, 8.0) as usize;
    cached(&CACHE, data, || ShaftReference::new(&data.sea.params, &data.sea.waves, side))
}

type Cache<T> = std::sync::Mutex<Vec<((Vec<u8>, Vec<u32>), std::sync::Arc<T>)>>;

/// What `make` builds for the scene's sea, kept per the sea's parameters
/// and a sample of its wave slopes (which change with the scene's time),
/// the last four.
fn cached<T>(cache: &Cache<T>, data: &SceneData, make: impl FnOnce() -> Option<T>) -> Option<std::sync::Arc<T>> {
    let p = &data.sea.params;
    let waves = &data.sea.waves;
    let stride = (waves.len() / 256).max(1);
    let sample = waves.iter().step_by(stride).flat_map(|v| v.to_array().map(f32::to_bits)).collect();
    let key = (bytemuck::bytes_of(p).to_vec(), sample);
    let mut cache = cache.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, c)) = cache.iter().find(|(k, _)| *k == key) {
        return Some(c.clone());
    }
    let c = std::sync::Arc::new(make()?);
    cache.push((key, c.clone()));
    if cache.len() > 4 {
        cache.remove(0);
    }
    Some(c)
}

/// Attenuated surface radiance of one pixel (the mean over its sub-pixel samples), f64.
pub fn surface_pixel(data: &SceneData, x: u32, y: u32) -> DVec3 {
    let spp = data.samples_per_pixel();
    (0..spp).map(|s| surface_and_distance(data, x, y, s).0).sum::<DVec3>() / spp as f64
}

/// The medium's phase function in f64 (`phase_f64`).
fn phase(data: &SceneData, cos: f64) -> f64 {
    phase_f64(data.common.phase_kind, data.common.phase_g as f64, cos)
}

/// Phase function `kind` (`types::PHASE_*`, asymmetry `g` for
/// Henyey-Greenstein) in f64, from its closed form (normalised, 1/sr).
pub(crate) fn phase_f64(kind: u32, g: f64, cos: f64) -> f64 {
    use slicelight_shaders::types::{PHASE_DOBASHI, PHASE_HENYEY_GREENSTEIN, PHASE_RAYLEIGH};
    let pi = std::f64::consts::PI;
    match kind {
        PHASE_HENYEY_GREENSTEIN => (1.0 - g * g) / (4.0 * pi * (1.0 + g * g - 2.0 * g * cos).powf(1.5)),
        PHASE_RAYLEIGH => 3.0 * (1.0 + cos * cos) / (16.0 * pi),
        PHASE_DOBASHI => (1.0 + 9.0 * (0.5 * (1.0 + cos)).powi(8)) / (8.0 * pi),
        _ => 1.0 / (4.0 * pi),
    }
}

/// Hash of (pixel, sample) to [0, 1): the jitter of the stratified samples.
fn jitter(pixel: u32, sample: u32, round: u32) -> f64 {
    let mut h = (pixel as u64) << 32 | sample as u64;
    h ^= (round as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    unit_from_hash(h)
}

/// A 64-bit key mixed (SplitMix64's finaliser) into a number in [0, 1):
/// the references' jitter.
pub(crate) fn unit_from_hash(mut h: u64) -> f64 {
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 31;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// In-scattered radiance along the ray of one sub-pixel sample (eq. 2,
/// summed over lights), with `samples` stratified samples over the ray up to
/// `t_surface`, f64. Every sample casts a shadow ray to every light that
/// lights it; with volumes, the light toward it and the view from it pass
/// through them (nested marches of the analytic field).
pub fn inscatter_pixel(data: &SceneData, x: u32, y: u32, sub: u32, t_surface: f64, samples: u32) -> DVec3 {
    let p = &data.common;
    let sigma_s = d3(p.sigma_s);
    if sigma_s == DVec3::ZERO {
        return DVec3::ZERO;
    }
    let sigma_t = d3(p.sigma_t);
    let Some((o, d)) = camera_ray(data, x, y, sub) else {
        return DVec3::ZERO;
    };
    let cos_view = d.dot(d3(p.camera_forward));
    let range = &data.shafts.params;
    let t0 = range.depth_near as f64 / cos_view;
    let t1 = (range.depth_far as f64 / cos_view).min(t_surface);
    if t1 <= t0 {
        return DVec3::ZERO;
    }
    let dt = (t1 - t0) / samples as f64;
    let pixel = (y * p.width + x).wrapping_mul(p.samples_per_pixel).wrapping_add(sub);
    let mut sum = DVec3::ZERO;
    for k in 0..samples {
        let t = t0 + (k as f64 + jitter(pixel, k, samples)) * dt;
        let point = o + d * t;
        // The volumes in front of the sample hide its light (1 without).
        let view = crate::volumes::reference::transmittance_strata(data, o, d, t, 32);
        for light in &data.lights {
            let (local, to_light, distance) = toward_light(light, point);
            let e = emitted(data, light, local);
            if e == DVec3::ZERO {
                continue;
            }
            let falloff = falloff(light, distance);
            if !sees_light(data, point, to_light, distance) {
                continue;
            }
            let attenuation = (-sigma_t * (distance + t)).exp();
            let clouds = crate::volumes::reference::transmittance_strata(data, point, to_light, distance, 32);
            sum += e * sigma_s * attenuation * clouds * (phase(data, to_light.dot(d)) * falloff) * view;
        }
    }
    sum * dt
}

/// The reference at convergence at the given pixels (row-major indices),
/// rgb in f64: the surface term once, plus the in-scattering, both seen
/// through the volumes (`volumes::reference`) if any, whose ray-march
/// sample count starts at 64 and doubles until the values change by less
/// than `tolerance` RMS, relative to their peak (or 65536 samples are
/// reached). Returns the values and the final sample count.
pub fn render_converged_at(data: &SceneData, pixels: &[u32], tolerance: f64) -> (Vec<DVec3>, u32) {
    let w = data.width();
    let spp = data.samples_per_pixel();
    crate::sky::reference::prepare(data);
    // Every (pixel, sub-pixel sample), each traced and shaded once.
    let rays: Vec<(u32, u32)> = pixels.iter().flat_map(|&i| (0..spp).map(move |s| (i, s))).collect();
    let surfaces: Vec<(DVec3, f64)> =
        rays.par_iter().map(|&(i, s)| surface_and_distance(data, i % w, i / w, s)).collect();
    // The box filter: the mean of each pixel's `spp` consecutive values.
    let filter = |values: Vec<DVec3>| -> Vec<DVec3> {
        values.chunks(spp as usize).map(|c| c.iter().sum::<DVec3>() / spp as f64).collect()
    };
    let with_inscatter = |samples: u32| -> Vec<DVec3> {
        filter(
            rays.par_iter()
                .zip(&surfaces)
                .map(|(&(i, s), &(surface, t))| {
                    // The fog's light, each sample seen through the volumes
                    // in front of it.
                    let fog = inscatter_pixel(data, i % w, i / w, s, t, samples);
                    match camera_ray(data, i % w, i / w, s).filter(|_| data.volumes.enabled) {
                        // The surface behind the volumes is seen through them.
                        Some((o, d)) => {
                            let ray = i as u64 * spp as u64 + s as u64;
                            let (l, through) = crate::volumes::reference::volume_ray(data, o, d, t, samples, ray);
                            surface * through + fog + l
                        }
                        None => surface + fog,
                    }
                })
                .collect(),
        )
    };
    if !data.scatters() && !data.volumes.enabled {
        return (filter(surfaces.iter().map(|s| s.0).collect()), 0);
    }
    let (image, samples) = converged(64, 65536, tolerance, |samples, _| with_inscatter(samples as u32));
    if !(data.volumes.enabled && data.volumes.params.all_orders()) {
        return (image, samples as u32);
    }
    // Multiple scattering: the volumes' orders 2 and up by random walks,
    // per sub-pixel ray, through the same box filter.
    let views: Vec<(DVec3, DVec3, f64)> = rays
        .iter()
        .zip(&surfaces)
        .map(|(&(i, s), &(_, t))| {
            camera_ray(data, i % w, i / w, s).map_or((DVec3::ZERO, DVec3::Z, 0.0), |(o, d)| (o, d, t))
        })
        .collect();
    let base: Vec<DVec3> = image.iter().flat_map(|p| std::iter::repeat_n(*p, spp as usize)).collect();
    let (higher, walks) = crate::volumes::montecarlo::converged(data, &views, &base, tolerance);
    eprintln!("reference: orders 2 and up by {walks} random walks per ray");
    let higher = filter(higher);
    (image.iter().zip(higher).map(|(a, b)| *a + b).collect(), samples as u32)
}

/// The references' convergence: `estimate(count, round)` with `count`
/// starting at `start` and doubling (round 1, 2, ...), until two successive
/// images differ by less than `tolerance` RMS relative to the peak
/// (`metrics::relative_error`), or `count` reaches `max`. Returns the last
/// image and its count.
pub fn converged(
    start: u64,
    max: u64,
    tolerance: f64,
    mut estimate: impl FnMut(u64, u64) -> Vec<DVec3>,
) -> (Vec<DVec3>, u64) {
    let mut count = start.max(1);
    let mut round = 1;
    let mut image = estimate(count, round);
    while count < max {
        count *= 2;
        round += 1;
        let next = estimate(count, round);
        let change = crate::metrics::relative_error(&image, &next).0;
        image = next;
        if change < tolerance {
            break;
        }
    }
    (image, count)
}

/// The whole reference image at convergence (see `render_converged_at`).
pub fn render_converged(data: &SceneData, tolerance: f64) -> (Vec<DVec3>, u32) {
    let all: Vec<u32> = (0..data.pixel_count()).collect();
    render_converged_at(data, &all, tolerance)
}

/// The reference image's surface term alone (no in-scattering), rgb in f64.
pub fn render_surfaces(data: &SceneData) -> Vec<DVec3> {
    let w = data.width();
    crate::sky::reference::prepare(data);
    (0..data.pixel_count()).into_par_iter().map(|i| surface_pixel(data, i % w, i / w)).collect()
}
