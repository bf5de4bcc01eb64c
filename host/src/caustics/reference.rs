//! The caustics reference: a light tracer in f64 that shares none of the
//! method's shortcuts (no table, no interpolation between directions, no
//! illumination volumes, no sample planes).
//!
//! Paths leave each light toward each glass object (uniformly over the cone
//! of directions that sees the object's bounding sphere, or over the disc
//! it casts across a directional light's beam), are traced through the
//! exact scene in f64 with Fresnel reflection and refraction at every glass
//! interface (total internal reflection included, any number of bounces,
//! Russian roulette between reflection and refraction by the Fresnel
//! reflectance, Beer's law inside), and where one that met glass lands on
//! an opaque surface it is connected to the camera: the surface point's
//! radiance `albedo / pi * E` splatted into the pixel it projects to
//! (visible from the eye, not through glass), i.e. the pixel's box-filtered
//! mean. `transmission_only` keeps only the paths the method models:
//! refraction at every interface with the Fresnel transmittance as weight,
//! and paths that meet total internal reflection dropped.
//!
//! In a scattering `[medium]` the same paths give the caustic light
//! shafts (`Splat::Medium`): every segment of a path that met glass,
//! outside the glass, is sampled at `MEDIUM_SAMPLES` stratified points,
//! each connected to the camera (next-event estimation toward the eye): its
//! flux times `sigma_s ds p(cos) e^(-sigma_t r)`, over `r^2` and the pixel's
//! solid angle, is the pixel's mean radiance (the pixel it projects to,
//! unobstructed). No planes, no maps, no interpolation: the method's
//! shortcuts are all absent.
//!
//! A line light emits from its whole segment: each of its paths starts at
//! a uniformly chosen point of it (not at the point lights the kernels see).

use glam::DVec3;
use rayon::prelude::*;
use slicelight_shaders::optics;
use slicelight_shaders::types::{LIGHT_DIRECTIONAL, MATERIAL_GLASS};

use crate::reference::{d3, emitted, nearest, Surface};
use crate::scene::SceneData;

/// Most interfaces a path crosses or reflects at before it is dropped.
const MAX_BOUNCES: u32 = 64;

/// The smooth normal (unit, outward) at `p` on glass triangle `triangle`
/// (BVH order): the vertex normals by barycentric weight, f64.
fn shading_normal(data: &SceneData, triangle: usize, p: DVec3) -> DVec3 {
    let tri = &data.triangles[triangle];
    let g = &data.glass_triangles[tri.glass as usize];
    let (a, b, c) = (d3(tri.v0), d3(tri.v1), d3(tri.v2));
    let n = g.vertices.map(|i| d3(data.glass_vertices[i as usize].normal));
    let cross = (b - a).cross(c - a);
    let area2 = cross.length_squared();
    if area2 <= 0.0 {
        return n[0];
    }
    let w1 = (p - a).cross(c - a).dot(cross) / area2;
    let w2 = (b - a).cross(p - a).dot(cross) / area2;
    (n[0] * (1.0 - w1 - w2) + n[1] * w1 + n[2] * w2).normalize_or(n[0])
}

/// The first interface of a view ray in direction `d` whose first hit
/// `first` is glass: the point hit, the Fresnel reflectance there per
/// channel, and the reflected direction (the same in every channel).
pub(crate) fn glass_reflection(data: &SceneData, o: DVec3, d: DVec3, first: &Surface) -> (DVec3, DVec3, DVec3) {
    let p = o + d * first.t;
    let n = shading_normal(data, first.triangle, p);
    let facing = if n.dot(d) > 0.0 { -n } else { n };
    let ior = data.materials[first.material as usize].ior;
    let r = DVec3::from_array([0, 1, 2].map(|c| interface(d, facing, 1.0 / ior[c] as f64).0));
    (p, r, d - facing * (2.0 * facing.dot(d)))
}

/// Fresnel reflectance for unpolarised light and the refracted direction
/// (None past the critical angle), `n` facing against `d`, `eta` = n_i / n_t.
fn interface(d: DVec3, n: DVec3, eta: f64) -> (f64, Option<DVec3>) {
    let cos_i = (-n.dot(d)).clamp(0.0, 1.0);
    let (cos_t, transmitted) = optics::transmitted_cosine(cos_i, eta);
    let r = optics::reflectance(cos_i, eta);
    (r, transmitted.then(|| (d * eta + n * (eta * cos_i - cos_t)).normalize()))
}

fn is_glass(data: &SceneData, s: &Surface) -> bool {
    s.triangle != usize::MAX && data.materials[s.material as usize].kind == MATERIAL_GLASS
}

pub(crate) fn epsilon(p: DVec3) -> f64 {
    1e-9 * p.abs().max_element().max(1.0)
}

/// A view ray `o + t d` whose first hit `first` is glass, followed in
/// channel `c` through the glass (refraction with the Fresnel transmittance
/// as weight, total internal reflection followed) until it leaves it for
/// good: (the point it leaves the glass from, its direction, the weight,
/// the opaque surface hit from there, or None if it meets nothing more);
/// None if it is lost inside. The method's `glass::trace_through` in f64.
pub(crate) fn through_glass(
    data: &SceneData,
    o: DVec3,
    d: DVec3,
    first: &Surface,
    c: usize,
) -> Option<(DVec3, DVec3, f64, Option<Surface>)> {
    let mut p = o + d * first.t;
    let mut dir = d;
    let mut hit = first.clone();
    let mut inside = false;
    let mut weight = 1.0;
    for _ in 0..MAX_BOUNCES {
        let m = &data.materials[hit.material as usize];
        let n = shading_normal(data, hit.triangle, p);
        let facing = if n.dot(dir) > 0.0 { -n } else { n };
        let ior = m.ior[c] as f64;
        let eta = if inside { ior } else { 1.0 / ior };
        let (r, refracted) = interface(dir, facing, eta);
        match refracted {
            Some(t) => {
                weight *= 1.0 - r;
                dir = t;
                inside = !inside;
            }
            None => dir = dir - facing * (2.0 * facing.dot(dir)),
        }
        let Some(next) = nearest(data, p, dir, epsilon(p), f64::INFINITY) else {
            return (!inside).then_some((p, dir, weight, None));
        };
        if inside {
            if !is_glass(data, &next) {
                return None;
            }
            weight *= (-(m.absorption[c] as f64) * next.t).exp();
        } else if !is_glass(data, &next) {
            return Some((p, dir, weight, Some(next)));
        }
        p += dir * next.t;
        hit = next;
    }
    None
}

/// A small fast generator (SplitMix64) for the light tracer's samples.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Bounding spheres (centre, radius) of the glass objects.
fn glass_objects(data: &SceneData) -> Vec<(DVec3, f64)> {
    let mut objects: Vec<(u32, DVec3, DVec3)> = Vec::new();
    for v in &data.glass_vertices {
        let p = d3(v.position);
        match objects.iter_mut().find(|o| o.0 == v.object) {
            Some(o) => {
                o.1 = o.1.min(p);
                o.2 = o.2.max(p);
            }
            None => objects.push((v.object, p, p)),
        }
    }
    objects.into_iter().map(|(_, lo, hi)| ((lo + hi) * 0.5, (hi - lo).length() * 0.5 * 1.001 + 1e-9)).collect()
}

/// The camera's view of a point: pixel index and the factor that turns a
/// flux landing there into the pixel's mean radiance, `cos(x) / (r^2
/// A_pixel cos^3(camera))` (without the albedo / pi), if the point is in
/// the image and the camera sees it (nothing, glass included, in between).
fn camera_splat(data: &SceneData, x: DVec3, normal: DVec3) -> Option<(usize, f64, f64)> {
    let (index, factor, to_cam, dist) = camera_projection(data, x)?;
    let cos_x = normal.dot(to_cam);
    let eps = epsilon(x);
    if cos_x <= 0.0 || nearest(data, x + normal * eps, to_cam, eps, dist - eps).is_some() {
        return None;
    }
    Some((index, cos_x * factor, dist))
}

/// Where the pinhole camera sees `x`, if in the image (whether anything is
/// in between not tested): pixel index, `1 / (r^2 A_pixel cos^3(camera))`
/// (the factor that turns an intensity there into the pixel's mean
/// radiance), the unit direction toward the camera and the distance.
fn camera_projection(data: &SceneData, x: DVec3) -> Option<(usize, f64, DVec3, f64)> {
    let p = &data.common;
    let cam = d3(p.camera_position);
    let (f, r, u) = (d3(p.camera_forward), d3(p.camera_right), d3(p.camera_up));
    let v = x - cam;
    let z = v.dot(f);
    if z <= 0.0 {
        return None;
    }
    let px = (v.dot(r) / (z * r.length_squared()) + 1.0) * 0.5 * p.width as f64;
    let py = (1.0 - v.dot(u) / (z * u.length_squared())) * 0.5 * p.height as f64;
    if !(px >= 0.0 && py >= 0.0 && px < p.width as f64 && py < p.height as f64) {
        return None;
    }
    let dist = v.length();
    let pixel_area = (2.0 * r.length() / p.width as f64) * (2.0 * u.length() / p.height as f64);
    let index = py as usize * p.width as usize + px as usize;
    Some((index, 1.0 / (dist * dist * pixel_area * (z / dist).powi(3)), -v / dist, dist))
}

/// Points per path segment the medium estimate connects to the camera.
pub const MEDIUM_SAMPLES: u32 = 8;

/// What the light tracer splats: the caustic on the surfaces, or the
/// caustic light the medium scatters toward the eye.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Splat {
    Surfaces,
    Medium,
}

/// The camera's view of a point in the medium (`camera_projection`), if
/// nothing is in between.
fn camera_view(data: &SceneData, x: DVec3) -> Option<(usize, f64, DVec3, f64)> {
    let (index, factor, to_cam, dist) = camera_projection(data, x)?;
    let eps = epsilon(x);
    nearest(data, x, to_cam, eps, dist - eps).is_none().then_some((index, factor, to_cam, dist))
}

/// Splats the light a path segment from `o` along `d` over `[0, length]`
/// (flux `weight` at `o`) scatters toward the camera: `MEDIUM_SAMPLES`
/// stratified points, each `length / MEDIUM_SAMPLES` of it.
fn splat_segment(data: &SceneData, o: DVec3, d: DVec3, length: f64, weight: DVec3, rng: &mut Rng, image: &mut [DVec3]) {
    let c = &data.common;
    let (sigma_t, sigma_s) = (d3(c.sigma_t), d3(c.sigma_s));
    let ds = length / MEDIUM_SAMPLES as f64;
    for k in 0..MEDIUM_SAMPLES {
        let s = (k as f64 + rng.next()) * ds;
        let x = o + d * s;
        if let Some((index, factor, to_cam, dist)) = camera_view(data, x) {
            let f = slicelight_shaders::phase::evaluate(c.phase_kind, d.dot(to_cam) as f32, c.phase_g) as f64;
            image[index] += weight * sigma_s * (-sigma_t * (s + dist)).exp() * (f * factor * ds);
        }
    }
}

/// Follows one path of flux `weight` (W per channel; with `channel`, that
/// channel alone) from `o` in direction `d`, and splats it where it lands
/// (`Splat::Surfaces`) or along the way after glass (`Splat::Medium`).
#[allow(clippy::too_many_arguments)]
fn trace_path(
    data: &SceneData,
    mut o: DVec3,
    mut d: DVec3,
    mut weight: DVec3,
    channel: Option<usize>,
    transmission_only: bool,
    splat: Splat,
    rng: &mut Rng,
    image: &mut [DVec3],
) {
    let sigma_t = d3(data.common.sigma_t);
    let mut inside: Option<u32> = None;
    let mut met_glass = false;
    for _ in 0..MAX_BOUNCES {
        let eps = epsilon(o);
        let hit = nearest(data, o, d, eps, f64::INFINITY);
        if splat == Splat::Medium && met_glass && inside.is_none() {
            // Light escaping the scene: its medium up to 40 optical depths.
            let far = 40.0 / sigma_t.min_element().max(1e-9);
            splat_segment(data, o, d, hit.as_ref().map_or(far, |h| h.t.min(far)), weight, rng, image);
        }
        let Some(hit) = hit else {
            return;
        };
        let p = o + d * hit.t;
        match inside {
            Some(m) => weight *= (-d3(data.materials[m as usize].absorption) * hit.t).exp(),
            None => weight *= (-sigma_t * hit.t).exp(),
        }
        if !is_glass(data, &hit) {
            if inside.is_some() || !met_glass || splat == Splat::Medium {
                return;
            }
            let normal = if hit.normal.dot(d) > 0.0 { -hit.normal } else { hit.normal };
            if let Some((index, factor, dist)) = camera_splat(data, p, normal) {
                let radiance = weight * hit.albedo * (factor / std::f64::consts::PI) * (-sigma_t * dist).exp();
                image[index] += radiance;
            }
            return;
        }
        met_glass = true;
        let m = &data.materials[hit.material as usize];
        let ior = d3(m.ior)[channel.unwrap_or(0)];
        let n = shading_normal(data, hit.triangle, p);
        let facing = if n.dot(d) > 0.0 { -n } else { n };
        let eta = if inside.is_some() { ior } else { 1.0 / ior };
        let (r, refracted) = interface(d, facing, eta);
        let reflect = d - facing * (2.0 * facing.dot(d));
        if transmission_only {
            let Some(t) = refracted else {
                return;
            };
            weight *= 1.0 - r;
            d = t;
            inside = if inside.is_some() { None } else { Some(hit.material) };
        } else if refracted.is_none() || rng.next() < r {
            d = reflect;
        } else {
            d = refracted.unwrap_or(reflect);
            inside = if inside.is_some() { None } else { Some(hit.material) };
        }
        o = p;
    }
}

/// Where the light tracer's paths start: a light, or a whole line light.
#[derive(Clone, Copy)]
enum Source {
    Light(usize),
    Line(usize),
}

/// A direction from `pos` uniform over the cone that sees the sphere
/// (`center`, `radius`; every direction from inside it), and the cone's
/// solid angle, sr.
fn toward_sphere(pos: DVec3, center: DVec3, radius: f64, rng: &mut Rng) -> (DVec3, f64) {
    let to = center - pos;
    let dist = to.length();
    let cos_max = if dist > radius { (1.0 - (radius / dist).powi(2)).sqrt() } else { -1.0 };
    let axis = if dist > 0.0 { to / dist } else { DVec3::Y };
    let (e1, e2) = axis.any_orthonormal_pair();
    let cos = 1.0 - rng.next() * (1.0 - cos_max);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = std::f64::consts::TAU * rng.next();
    (axis * cos + (e1 * phi.cos() + e2 * phi.sin()) * sin, std::f64::consts::TAU * (1.0 - cos_max))
}

/// The caustic light (paths that met glass, then an opaque surface) each
/// pixel sees, W/(m^2 sr) per channel, from `paths` paths per light, glass
/// object and channel traced as described in the module docs.
pub fn caustic_image(data: &SceneData, paths: u64, seed: u64, transmission_only: bool) -> Vec<DVec3> {
    light_trace(data, paths, seed, transmission_only, Splat::Surfaces)
}

/// The light tracer: `paths` paths per light, glass object and channel,
/// splatted as `splat` says (`Splat::Medium`: the caustic light the medium
/// scatters toward the eye, the caustic shafts, W/(m^2 sr) per channel).
fn light_trace(data: &SceneData, paths: u64, seed: u64, transmission_only: bool, splat: Splat) -> Vec<DVec3> {
    let pixels = data.pixel_count() as usize;
    let dispersive =
        data.materials.iter().any(|m| m.kind == MATERIAL_GLASS && slicelight_shaders::glass::dispersive(m));
    let channels: Vec<Option<usize>> = if dispersive { vec![Some(0), Some(1), Some(2)] } else { vec![None] };
    let objects = glass_objects(data);
    let tasks = 64u64;
    // Every light but the line lights' points, then the line lights.
    let sources: Vec<Source> = (0..data.lights.len())
        .filter(|i| !data.is_line_point(*i))
        .map(Source::Light)
        .chain((0..data.line_lights.len()).map(Source::Line))
        .collect();
    let mut jobs = Vec::new();
    for (li, _) in sources.iter().enumerate() {
        for (oi, _) in objects.iter().enumerate() {
            for &c in &channels {
                for t in 0..tasks {
                    jobs.push((li, oi, c, t));
                }
            }
        }
    }
    jobs.par_iter()
        .fold(
            || vec![DVec3::ZERO; pixels],
            |mut image, &(li, oi, channel, task)| {
                let (center, radius) = objects[oi];
                let count = paths / tasks + u64::from(task < paths % tasks);
                let mut rng =
                    Rng(seed ^ (li as u64) << 48 ^ (oi as u64) << 40 ^ (task << 8) ^ channel.unwrap_or(7) as u64);
                let mask = match channel {
                    Some(c) => DVec3::from_array(std::array::from_fn(|k| if k == c { 1.0 } else { 0.0 })),
                    None => DVec3::ONE,
                };
                for _ in 0..count {
                    let light = match sources[li] {
                        Source::Light(i) => &data.lights[i],
                        Source::Line(k) => {
                            // A point of the segment, uniformly; the
                            // segment's intensity `per_metre * length` in
                            // every direction of the cone toward the object.
                            let line = &data.line_lights[k];
                            let (a, b) = (line.from.as_dvec3(), line.to.as_dvec3());
                            let pos = a + (b - a) * rng.next();
                            let (d, solid_angle) = toward_sphere(pos, center, radius, &mut rng);
                            let flux = line.per_metre.as_dvec3() * ((b - a).length() * solid_angle / paths as f64);
                            trace_path(
                                data,
                                pos,
                                d,
                                flux * mask,
                                channel,
                                transmission_only,
                                splat,
                                &mut rng,
                                &mut image,
                            );
                            continue;
                        }
                    };
                    let (o, d, flux) = if light.kind == LIGHT_DIRECTIONAL {
                        // Uniform over the disc the bounding sphere casts across the beam.
                        let axis = d3(light.axis_z);
                        let (e1, e2) = axis.any_orthonormal_pair();
                        let (a, b) = (rng.next(), rng.next());
                        let rad = radius * a.sqrt();
                        let phi = std::f64::consts::TAU * b;
                        let q = center + (e1 * phi.cos() + e2 * phi.sin()) * rad;
                        let depth = (q - d3(light.position)).dot(axis);
                        let o = q - axis * depth;
                        let local = DVec3::new(
                            (o - d3(light.position)).dot(d3(light.axis_x)),
                            (o - d3(light.position)).dot(d3(light.axis_y)),
                            0.0,
                        );
                        let e = emitted(data, light, local);
                        (o, axis, e * (std::f64::consts::PI * radius * radius / paths as f64))
                    } else {
                        let pos = d3(light.position);
                        let (d, solid_angle) = toward_sphere(pos, center, radius, &mut rng);
                        let local =
                            DVec3::new(d.dot(d3(light.axis_x)), d.dot(d3(light.axis_y)), d.dot(d3(light.axis_z)));
                        (pos, d, emitted(data, light, local) * (solid_angle / paths as f64))
                    };
                    if flux == DVec3::ZERO {
                        continue;
                    }
                    trace_path(data, o, d, flux * mask, channel, transmission_only, splat, &mut rng, &mut image);
                }
                image
            },
        )
        .reduce(
            || vec![DVec3::ZERO; pixels],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        )
}

/// The light tracer's image (`splat`: the caustic on surfaces, or the
/// caustic shafts) at convergence: paths (per light, object and channel)
/// start at `start` and double, each image an independent estimate with
/// twice the paths of the last, until two successive ones differ by less
/// than `tolerance` RMS relative to the peak, or `max_paths` is reached.
/// Returns the last image and its path count.
pub fn light_trace_converged(
    data: &SceneData,
    start: u64,
    max_paths: u64,
    tolerance: f64,
    transmission_only: bool,
    splat: Splat,
) -> (Vec<DVec3>, u64) {
    crate::reference::converged(start, max_paths, tolerance, |paths, round| {
        light_trace(data, paths, round, transmission_only, splat)
    })
}
