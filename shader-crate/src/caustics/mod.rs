//! Refractive caustics with light transport tables (Iwasaki, Yoshimoto,
//! Dobashi and Nishita 2005; `shared/papers/003_*`).
//!
//! Four kernels, one per stage of the paper:
//! - `caustics_table_kernel` (section 4): for every vertex of a glass mesh
//!   and every sampling direction of eq. 3 over the hemisphere above it, the
//!   ray refracted in at the vertex, traced through the object (`glass.rs`)
//!   until it leaves: exit position, exit direction and transmittance
//!   (the light transport function, eq. 1), or a flag (total internal
//!   reflection, self-occlusion, lost).
//! - `caustics_lookup_kernel` (section 5.1): for every light and every
//!   vertex the light reaches, the exit ray for the light's actual
//!   direction: the four table directions around it, bilinear
//!   interpolation of the exit position and transmittance, quaternion
//!   interpolation (rotation about the axis between two directions by a
//!   fraction of their angle) of the exit direction.
//! - `caustics_maps_kernel` (section 5.1-5.2, eq. 2): every lit triangle's
//!   three exit rays sweep an illumination volume; its cross-section with
//!   each horizontal sample plane is a triangle, rasterised into that
//!   plane's caustics map with the flux it carries, by the scatter
//!   primitive (`scatter.rs`).
//! - `caustics_kernel` (per pixel): the caustic light at the surface a
//!   pixel sees (directly or through glass): the irradiance interpolated
//!   between the two sample planes around it, times `albedo / pi`
//!   (`caustic_light`), which the surface pass reads where it shades that
//!   surface and leaves in the G-buffer; this kernel unpacks it.
//!
//! # Units and the flux ratio
//! A lit triangle of area `S` whose normal makes the angle `theta` with the
//! light receives the flux `Phi = E_perp S cos(theta)` (W; `E_perp` the
//! irradiance normal to the light's rays: `I / r^2` for a point or spot
//! light, `E` for a directional one), of which the fraction `F_t` (the
//! interpolated transmittance, per channel) leaves the glass. Spread over
//! the cross-section of area `S_p` it is the flux density `F_t Phi / S_p`
//! (W/m^2 of the plane): eq. 2's `L_in cos(theta) F_t F_p` with
//! `F_p = S / S_p`. The rasteriser deposits it over the texels whose
//! centres the cross-section covers, `F_t Phi / (k A_texel)` each for `k`
//! covered texels, and, when it covers none (a cross-section smaller than a
//! texel, or a focal line where `S_p -> 0`), all of it into the texel under
//! its centroid, `F_t Phi / A_texel`: the map receives exactly the flux
//! each volume carries, never more, and the density stays bounded by one
//! texel's worth.
//!
//! A receiver of unit normal `n` at a point where the rays cross the plane
//! in mean direction `w` gets the irradiance `density * |n . w| / |w_y|`.
//! Each texel keeps, besides the density per channel, the density-weighted
//! sums of `w_x / |w_y|` and `w_z / |w_y|` (positive and negative parts in
//! separate bins, as the scatter primitive adds non-negative numbers), from
//! which the mean direction is rebuilt. Only rays going down cross the
//! planes (light from above the receivers).

use crate::camera::camera_ray;
use crate::common::surface::{channel_part, shadow_ray_visibility, Receiver};
use crate::geometry::{trace_object, Geometry, NO_HIT};
use crate::glam::{Quat, UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::glass::{pick, surface_epsilon, trace_through, Glass, PATH_LOST, PATH_OCCLUDED, PATH_OUT};
use crate::light::{atan2_accurate, emitted, light_local, phi_given, transmittance};
use crate::optics;
use crate::phase;
use crate::scatter::{scatter_add, AtomicWords, REJECTED_WORD};
use crate::types::{
    CommonParams, GBufferTexel, GlassTriangle, GlassVertex, GpuBvhNode, GpuLight, GpuMaterial, GpuSphere, GpuTriangle,
    LIGHT_DIRECTIONAL,
};
use core::f32::consts::{FRAC_1_PI, FRAC_PI_2, TAU};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;
use spirv_std::spirv;

/// Bins per caustics-map texel: density in r, g, b (W/m^2 of the plane),
/// then the density-weighted `+w_x/|w_y|`, `-w_x/|w_y|`, `+w_z/|w_y|`,
/// `-w_z/|w_y|`.
pub const MAP_BINS: u32 = 7;
/// Largest `|w_x / w_y|` kept (rays within 89 degrees of the vertical).
pub const MAX_SLOPE: f32 = 64.0;

/// The caustics passes' parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CausticsParams {
    /// The lowest sample plane's corner: x, y (its height), z, metres; w:
    /// the texel size, metres.
    pub map_origin: Vec4,
    /// Rings of sampling directions away from the normal (eq. 3's `phi`
    /// from 0 to 90 degrees in `rings` steps) and azimuths per ring: the
    /// table has `1 + rings * azimuths` directions per vertex.
    pub rings: u32,
    pub azimuths: u32,
    pub directions: u32,
    /// 3 when some glass disperses (each channel its own path), else 1.
    pub channels: u32,
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// Lights (the first `light_count` of the scene's) whose caustics are drawn.
    pub light_count: u32,
    /// Horizontal sample planes, `plane_spacing` apart from `map_origin.y` up.
    pub planes: u32,
    pub map_width: u32,
    pub map_height: u32,
    pub plane_spacing: f32,
    /// Fixed-point units per W/m^2 of the maps' bins (see `scatter.rs`).
    pub scale: f32,
    /// 1: table entries packed into `PACKED_WORDS` 32-bit words of 16-bit
    /// fields (section 6); 0: `ENTRY_WORDS` words of f32.
    pub compressed: u32,
    /// Words per table entry (`PACKED_WORDS` or `ENTRY_WORDS`).
    pub entry_words: u32,
    /// Intervals along each view ray through the shaft maps
    /// (`caustic_shafts_pixel`; 0 in the receivers' maps).
    pub shaft_steps: u32,
    pub _pad: u32,
    /// Shaft maps: the x-z box all their planes cover (min x, min z, max
    /// x, max z, metres).
    pub bounds: Vec4,
    /// Shaft maps: each plane's own square of `map_width` x `map_height`
    /// texels (corner x, corner z, texel size, metres; w unused), over
    /// where the light crosses that plane: a bundle narrowing to a focus
    /// gets texels as fine as it is narrow. The receivers' maps use
    /// `map_origin` for every plane.
    pub rects: [Vec4; MAX_SHAFT_PLANES as usize],
}

impl Default for CausticsParams {
    /// All zero: no planes, no maps.
    fn default() -> Self {
        CausticsParams {
            map_origin: Vec4::ZERO,
            rings: 0,
            azimuths: 0,
            directions: 0,
            channels: 0,
            vertex_count: 0,
            triangle_count: 0,
            light_count: 0,
            planes: 0,
            map_width: 0,
            map_height: 0,
            plane_spacing: 0.0,
            scale: 0.0,
            compressed: 0,
            entry_words: 0,
            shaft_steps: 0,
            _pad: 0,
            bounds: Vec4::ZERO,
            rects: [Vec4::ZERO; MAX_SHAFT_PLANES as usize],
        }
    }
}

/// Most shaft planes (`CausticsParams::rects`).
pub const MAX_SHAFT_PLANES: u32 = 64;

/// Plane `k`'s corner (x, z) and texel size (metres; w unused): its own
/// for the shaft maps, `map_origin`'s for the receivers'.
pub fn plane_rect(params: &CausticsParams, k: u32) -> Vec4 {
    if params.shaft_steps > 0 {
        params.rects[k as usize]
    } else {
        Vec4::new(params.map_origin.x, params.map_origin.z, params.map_origin.w, 0.0)
    }
}

/// Words of an uncompressed table entry (a `TableEntry`'s twelve f32s).
pub const ENTRY_WORDS: u32 = 12;
/// Words of a compressed entry (section 6): the point nearest the vertex
/// and the exit distance as 16-bit fractions of the object's size around
/// the vertex, the exit direction as two 16-bit angles, the transmittance
/// as three 16-bit fractions, the status.
pub const PACKED_WORDS: u32 = 5;

fn unit16(x: f32) -> u32 {
    (x.clamp(0.0, 1.0) * 65535.0 + 0.5) as u32
}

fn from16(w: u32) -> f32 {
    (w & 0xffff) as f32 / 65535.0
}

/// Writes entry `e` of `vertex` into table slot `slot`, its point nearest
/// the vertex relative to the vertex and it and the exit direction turned
/// back by the object's rotation (so the table holds for the object
/// wherever it stands and however it is turned); section 6 when
/// compressed: 16 bits per coordinate of the point nearest the vertex and
/// the exit distance, relative to the vertex within +- the object's
/// diagonal `vertex.normal.w`; 16 bits per angle of the exit direction,
/// azimuth around +y and polar angle from it; 16 bits per channel of
/// transmittance).
pub fn store_entry(table: &mut [u32], params: &CausticsParams, slot: u32, e: &TableEntry, vertex: &GlassVertex) {
    let base = (slot * params.entry_words) as usize;
    // As the object was defined: turned back by its rotation.
    let undo = object_rotation(vertex).conjugate();
    let relative = undo.mul_vec3(e.position.xyz() - vertex.position.xyz());
    let d = undo.mul_vec3(e.direction.xyz());
    if params.compressed == 0 {
        store4(table, base, relative.extend(e.position.w));
        store4(table, base + 4, d.extend(e.direction.w));
        store4(table, base + 8, e.transmittance);
        return;
    }
    let size = vertex.normal.w;
    let a = relative / size * 0.5 + 0.5;
    let s = e.direction.w / size * 0.5 + 0.5;
    let mut azimuth = d.z.atan2(d.x);
    if azimuth < 0.0 {
        azimuth += TAU;
    }
    let polar = d.y.clamp(-1.0, 1.0).acos();
    table[base] = unit16(a.x) | unit16(a.y) << 16;
    table[base + 1] = unit16(a.z) | unit16(s) << 16;
    table[base + 2] = unit16(azimuth / TAU) | unit16(polar / core::f32::consts::PI) << 16;
    table[base + 3] = unit16(e.transmittance.x) | unit16(e.transmittance.y) << 16;
    table[base + 4] = unit16(e.transmittance.z) | (e.position.w as u32) << 16;
}

fn store4(table: &mut [u32], at: usize, v: Vec4) {
    table[at] = v.x.to_bits();
    table[at + 1] = v.y.to_bits();
    table[at + 2] = v.z.to_bits();
    table[at + 3] = v.w.to_bits();
}

fn load4(table: &[u32], at: usize) -> Vec4 {
    Vec4::new(
        f32::from_bits(table[at]),
        f32::from_bits(table[at + 1]),
        f32::from_bits(table[at + 2]),
        f32::from_bits(table[at + 3]),
    )
}

/// Reads table slot `slot` of `vertex` (see `store_entry`).
pub fn load_entry(table: &[u32], params: &CausticsParams, slot: u32, vertex: &GlassVertex) -> TableEntry {
    let base = (slot * params.entry_words) as usize;
    let turn = object_rotation(vertex);
    if params.compressed == 0 {
        let p = load4(table, base);
        let d = load4(table, base + 4);
        return TableEntry {
            position: (vertex.position.xyz() + turn.mul_vec3(p.xyz())).extend(p.w),
            direction: turn.mul_vec3(d.xyz()).extend(d.w),
            transmittance: load4(table, base + 8),
        };
    }
    let size = vertex.normal.w;
    let (w0, w1, w2, w3, w4) = (table[base], table[base + 1], table[base + 2], table[base + 3], table[base + 4]);
    let a = (Vec3::new(from16(w0), from16(w0 >> 16), from16(w1)) * 2.0 - 1.0) * size;
    let s = (from16(w1 >> 16) * 2.0 - 1.0) * size;
    let azimuth = from16(w2) * TAU;
    let polar = from16(w2 >> 16) * core::f32::consts::PI;
    let (sp, cp) = polar.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    TableEntry {
        position: (vertex.position.xyz() + turn.mul_vec3(a)).extend((w4 >> 16) as f32),
        direction: turn.mul_vec3(Vec3::new(sp * ca, cp, sp * sa)).extend(s),
        transmittance: Vec4::new(from16(w3), from16(w3 >> 16), from16(w4), 0.0),
    }
}

/// One entry of the light transport table: the exit ray's point nearest
/// the vertex (w: the path's status, `glass::PATH_*`), exit direction (w:
/// the distance from that point to the exit point along it, metres), and
/// the transmittance per channel after the entry interface (w unused). The
/// exit point is `position + direction * direction.w`.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct TableEntry {
    pub position: Vec4,
    pub direction: Vec4,
    pub transmittance: Vec4,
}

/// The exit ray of one vertex for one light: exit point (w: 1 if valid),
/// direction, transmittance per channel (entry included).
pub type ExitRay = TableEntry;

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)`, only `Vec4`s and 4-byte scalars, sizes multiples
    // of 16 with no padding; any bits are valid.
    unsafe impl bytemuck::Zeroable for super::CausticsParams {}
    unsafe impl bytemuck::Pod for super::CausticsParams {}
    unsafe impl bytemuck::Zeroable for super::TableEntry {}
    unsafe impl bytemuck::Pod for super::TableEntry {}
    const _: () = assert!(core::mem::size_of::<super::CausticsParams>() == 96 + 16 * super::MAX_SHAFT_PLANES as usize);
    const _: () = assert!(core::mem::size_of::<super::TableEntry>() == 48);
}

/// The tangent of a vertex's local frame (section 4, Fig. 3) from the unit
/// normal `n` as the object was defined (the host turns it with the object:
/// `GlassVertex::tangent`).
pub fn frame_tangent(n: Vec3) -> Vec3 {
    let a = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    a.cross(n).normalize()
}

/// The local frame of a vertex (section 4, Fig. 3): its unit normal `n`,
/// tangent `t` and binormal `b = n x t`, turned with its object.
pub fn vertex_frame(v: &GlassVertex) -> (Vec3, Vec3, Vec3) {
    let n = v.normal.xyz();
    let t = v.tangent.xyz();
    (n, t, n.cross(t))
}

/// The object's rotation of vertex `v` (see `GlassVertex::rotation`).
fn object_rotation(v: &GlassVertex) -> Quat {
    Quat::from_xyzw(v.rotation.x, v.rotation.y, v.rotation.z, v.rotation.w)
}

/// Eq. 3's angles of table direction `j`: (`phi` from the inward normal,
/// `theta` around it), radians. Direction 0 is the pole (`phi = 0`); then
/// rings `k = 1..=rings` at `phi = k pi / (2 rings)`, `azimuths` each.
pub fn direction_angles(params: &CausticsParams, j: u32) -> (f32, f32) {
    if j == 0 {
        return (0.0, 0.0);
    }
    let k = (j - 1) / params.azimuths + 1;
    let m = (j - 1) % params.azimuths;
    (k as f32 * FRAC_PI_2 / params.rings as f32, m as f32 * TAU / params.azimuths as f32)
}

/// Eq. 3: `w = -cos(phi) n - sin(phi) cos(theta) t - sin(phi) sin(theta) b`,
/// a direction of light arriving at the vertex.
pub fn sampling_direction(n: Vec3, t: Vec3, b: Vec3, phi: f32, theta: f32) -> Vec3 {
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    -(n * cp) - t * (sp * ct) - b * (sp * st)
}

/// Where table invocation `index` = `(vertex * directions + j) * channels +
/// channel` stores its entry: at `table_block * directions + j * channels_v +
/// channel` (`channels_v` its vertex's), or nowhere (`u32::MAX`) for a
/// channel its vertex does not trace (a glass that does not disperse traces
/// channel 0 for all three).
pub fn table_slot(index: u32, params: &CausticsParams, vertices: &[GlassVertex]) -> u32 {
    let c = index % params.channels;
    let j = (index / params.channels) % params.directions;
    let v = vertices[(index / (params.channels * params.directions)) as usize];
    if c >= v.channels {
        return u32::MAX;
    }
    v.table_block * params.directions + j * v.channels + c
}

/// The table entry of invocation `index` (see `table_slot`): the path of
/// table direction `j` in channel `channel` from the vertex.
pub fn table_entry(
    index: u32,
    params: &CausticsParams,
    geometry: &Geometry,
    glass: &Glass,
    materials: &[GpuMaterial],
) -> TableEntry {
    let c = index % params.channels;
    let j = (index / params.channels) % params.directions;
    let v = glass.vertices[(index / (params.channels * params.directions)) as usize];
    let p = v.position.xyz();
    let (n, t, b) = vertex_frame(&v);
    let (phi, theta) = direction_angles(params, j);
    let w = sampling_direction(n, t, b, phi, theta);
    // Self-occlusion (section 4): a ray from the vertex back toward the
    // light that meets the object itself.
    let eps = surface_epsilon(p);
    let back = trace_object(p + n * eps, -w, eps, NO_HIT, geometry, v.object);
    if back.distance != NO_HIT {
        return TableEntry {
            position: p.extend(PATH_OCCLUDED as f32),
            direction: w.extend(0.0),
            transmittance: Vec4::ZERO,
        };
    }
    // The last ring is traced just inside grazing, where the entry's
    // Fresnel transmittance is not yet 0 (see below).
    let w = if phi > MAX_TRACED_PHI { sampling_direction(n, t, b, MAX_TRACED_PHI, theta) } else { w };
    let path = trace_through(geometry, glass, materials, p, n, v.material, w, c, v.object, false);
    if path.status != PATH_OUT {
        return TableEntry {
            position: path.position.extend(path.status as f32),
            direction: path.direction.extend(0.0),
            transmittance: Vec4::ZERO,
        };
    }
    // The exit ray as a line: its point nearest the vertex and the distance
    // from there to the exit point. Interpolated between table directions,
    // these follow the line far more closely than the exit point does (for
    // glass of index 1 the point nearest the vertex is the vertex itself).
    let d = path.direction;
    let s_exit = (path.position - p).dot(d);
    let anchor = path.position - d * s_exit;
    // The entry's Fresnel transmittance is left out (the lookup applies it
    // for the light's exact angle): it falls to 0 at grazing faster than
    // the table's rings can follow.
    let entry = optics::transmittance(-w.dot(n), 1.0 / pick(materials[v.material as usize].ior, c));
    TableEntry {
        position: anchor.extend(PATH_OUT as f32),
        direction: d.extend(s_exit),
        transmittance: path.transmittance() / entry,
    }
}

/// Largest angle from the inward normal traced for the table, radians
/// (89.5 degrees; the entry's Fresnel transmittance there is at least 0.4 %
/// for indices up to 4).
pub const MAX_TRACED_PHI: f32 = 1.562_069;

/// `a` turned toward `b` by the fraction `w` of the angle between them:
/// the rotation about `a x b` as a quaternion (section 5.1's
/// quaternion-based vector interpolation).
pub fn rotate_toward(a: Vec3, b: Vec3, w: f32) -> Vec3 {
    let axis = a.cross(b);
    let sin = axis.length();
    let cos = a.dot(b);
    if sin < 1e-7 {
        return (a * (1.0 - w) + b * w).normalize();
    }
    let angle = atan2_accurate(sin, cos);
    Quat::from_axis_angle(axis / sin, angle * w).mul_vec3(a)
}

/// A table corner's exit ray in the frame turned about the vertex normal
/// by minus its own azimuth (`theta_j`; the pole, which has none, takes the
/// light's): the rotation (a quaternion) from its sampling direction to its
/// exit direction, and its point nearest the vertex, relative to the
/// vertex. Around a locally symmetric surface these hardly change between
/// the azimuths of a ring.
#[allow(clippy::too_many_arguments)]
fn corner_local(
    params: &CausticsParams,
    p: Vec3,
    n: Vec3,
    t: Vec3,
    k: u32,
    m: u32,
    theta_light: f32,
    e: &TableEntry,
) -> (Quat, Vec3) {
    let (phi, theta) = direction_angles(params, ring_index(params, k, m));
    let theta = if k == 0 { theta_light } else { theta };
    let r = Quat::from_axis_angle(n, -theta);
    let (sp, cp) = phi.min(MAX_TRACED_PHI).sin_cos();
    let sampled = -(n * cp) - t * sp;
    (rotation_arc(sampled, r.mul_vec3(e.direction.xyz())), r.mul_vec3(e.position.xyz() - p))
}

/// The shortest rotation taking unit `a` to unit `b` (glam's
/// `Quat::from_rotation_arc` without its `signum`, whose NaN case becomes
/// a NaN constant naga rejects): about `a x b`, or for opposite vectors by
/// pi about an axis normal to `a`.
pub fn rotation_arc(a: Vec3, b: Vec3) -> Quat {
    let dot = a.dot(b);
    if dot < -0.999_999 {
        let other = if a.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
        return Quat::from_axis_angle(a.cross(other).normalize(), core::f32::consts::PI);
    }
    let c = a.cross(b);
    Quat::from_xyzw(c.x, c.y, c.z, 1.0 + dot).normalize()
}

/// Two directions' interpolation by `rotate_toward` with weights `wa`,
/// `wb`; either may be missing (weight 0). Returns it and the weight sum.
fn blend(a: Vec3, wa: f32, b: Vec3, wb: f32) -> (Vec3, f32) {
    if wa > 0.0 && wb > 0.0 {
        (rotate_toward(a, b, wb / (wa + wb)), wa + wb)
    } else if wa > 0.0 {
        (a, wa)
    } else {
        (b, wb)
    }
}

/// Ring `k`'s sampling direction in the frame turned by its azimuth.
fn sampled_local(params: &CausticsParams, n: Vec3, t: Vec3, k: u32) -> Vec3 {
    let phi = (k as f32 * FRAC_PI_2 / params.rings as f32).min(MAX_TRACED_PHI);
    -(n * phi.cos()) - t * phi.sin()
}

/// The rotation of the heaviest of four corners.
#[allow(clippy::too_many_arguments)]
fn heaviest(q0: Quat, w0: f32, q1: Quat, w1: f32, q2: Quat, w2: f32, q3: Quat, w3: f32) -> Quat {
    let mut q = q0;
    let mut best = w0;
    if w1 > best {
        q = q1;
        best = w1;
    }
    if w2 > best {
        q = q2;
        best = w2;
    }
    if w3 > best {
        q = q3;
    }
    q
}

/// Table index of ring `k`, azimuth `m` (every azimuth of ring 0 is the pole).
fn ring_index(params: &CausticsParams, k: u32, m: u32) -> u32 {
    if k == 0 {
        0
    } else {
        1 + (k - 1) * params.azimuths + m
    }
}

/// Whether light from `light` reaches the glass vertex `v`, and its
/// direction of travel there.
pub fn light_at_vertex(light: &GpuLight, geometry: &Geometry, v: &GlassVertex) -> (bool, Vec3) {
    let (p, n) = (v.position.xyz(), v.normal.xyz());
    let (dir, distance) = if light.kind == LIGHT_DIRECTIONAL {
        (light.axis_z.xyz(), light_local(light, p).z)
    } else {
        let d = p - light.position.xyz();
        let s = d.length();
        (d / s.max(1e-30), s)
    };
    if !(dir.dot(n) < 0.0 && distance > 0.0) {
        return (false, dir);
    }
    (shadow_ray_visibility(geometry, p, n, -dir, distance) > 0.0, dir)
}

/// Lookup `index` = `(light * vertex_count + vertex) * channels + channel`
/// (section 5.1): the exit ray for the light's direction at the vertex, from
/// the four table directions around it. Corners whose paths do not leave the
/// glass add no transmittance, and the position and direction are taken
/// from the others.
pub fn lookup(
    index: u32,
    params: &CausticsParams,
    lights: &[GpuLight],
    geometry: &Geometry,
    vertices: &[GlassVertex],
    materials: &[GpuMaterial],
    table: &[u32],
) -> ExitRay {
    let invalid = ExitRay { position: Vec4::ZERO, direction: Vec4::ZERO, transmittance: Vec4::ZERO };
    let c = index % params.channels;
    let vi = (index / params.channels) % params.vertex_count;
    let li = index / (params.channels * params.vertex_count);
    let v = vertices[vi as usize];
    let (lit, l) = light_at_vertex(&lights[li as usize], geometry, &v);
    if !lit {
        return invalid;
    }
    exit_ray(params, &v, l, c, materials, table)
}

/// Section 5.1's lookup of vertex `v`'s table for light travelling along
/// `l` (unit) in channel `c`: the exit ray from the four table directions
/// around `l`. Invalid (`position.w` = 0) where none of them leaves the glass.
pub fn exit_ray(
    params: &CausticsParams,
    v: &GlassVertex,
    l: Vec3,
    c: u32,
    materials: &[GpuMaterial],
    table: &[u32],
) -> ExitRay {
    let invalid = ExitRay { position: Vec4::ZERO, direction: Vec4::ZERO, transmittance: Vec4::ZERO };
    let (n, t, b) = vertex_frame(v);
    // The angles by `atan2_accurate`: Vulkan's acos and atan2 may be off by
    // 2^-11, which moved the weights of the four table directions, and a
    // grazing exit ray with them, between the backends.
    let phi = atan2_accurate(l.cross(n).length(), (-l.dot(n)).max(0.0));
    let mut theta = atan2_accurate(-l.dot(b), -l.dot(t));
    if theta < 0.0 {
        theta += TAU;
    }
    let fk = phi / FRAC_PI_2 * params.rings as f32;
    let k0 = (fk.floor() as u32).min(params.rings - 1);
    // Between rings k0 and k0 + 1 by angle, the last ring where it was
    // traced (`MAX_TRACED_PHI`); beyond that, the last ring.
    let phi0 = k0 as f32 * FRAC_PI_2 / params.rings as f32;
    let phi1 = ((k0 + 1) as f32 * FRAC_PI_2 / params.rings as f32).min(MAX_TRACED_PHI);
    let wk = ((phi - phi0) / (phi1 - phi0)).clamp(0.0, 1.0);
    let fm = theta / TAU * params.azimuths as f32;
    let m0 = (fm.floor() as u32).min(params.azimuths - 1);
    let wm = (fm - m0 as f32).clamp(0.0, 1.0);
    let m1 = (m0 + 1) % params.azimuths;
    let base = v.table_block * params.directions;
    let (vc, c) = (v.channels, c.min(v.channels - 1));
    let e00 = load_entry(table, params, base + ring_index(params, k0, m0) * vc + c, v);
    let e01 = load_entry(table, params, base + ring_index(params, k0, m1) * vc + c, v);
    let e10 = load_entry(table, params, base + ring_index(params, k0 + 1, m0) * vc + c, v);
    let e11 = load_entry(table, params, base + ring_index(params, k0 + 1, m1) * vc + c, v);
    // Corners whose paths leave the glass give the exit ray. Those that
    // meet total internal reflection or the object itself transmit
    // nothing, so they count toward the transmittance as 0; a lost path (a
    // ray slipping between triangles at a shared vertex, an open mesh) says
    // nothing and counts toward neither.
    let valid = |e: &TableEntry| if e.position.w == PATH_OUT as f32 { 1.0 } else { 0.0 };
    let known = |e: &TableEntry| if e.position.w == PATH_LOST as f32 { 0.0 } else { 1.0 };
    let (b00, b01, b10, b11) = ((1.0 - wk) * (1.0 - wm), (1.0 - wk) * wm, wk * (1.0 - wm), wk * wm);
    let w00 = b00 * valid(&e00);
    let w01 = b01 * valid(&e01);
    let w10 = b10 * valid(&e10);
    let w11 = b11 * valid(&e11);
    let total = w00 + w01 + w10 + w11;
    let weighed = b00 * known(&e00) + b01 * known(&e01) + b10 * known(&e10) + b11 * known(&e11);
    if total <= 0.0 || total.is_nan() {
        return invalid;
    }
    // Interpolation in the frame that turns with the azimuth (section 5.1
    // interpolates the exit directions themselves; across a ring's azimuths
    // a great-circle arc cuts inside the ring, which bends the caustic):
    // each corner turned about the normal by minus its azimuth, where its
    // exit direction is its sampling direction turned by a rotation (a
    // quaternion); the corners' exit directions and their points nearest
    // the vertex blended with the bilinear weights; the result turned back
    // by the light's azimuth. Exact in azimuth around a surface of
    // revolution, and exact for glass that bends nothing.
    let pv = v.position.xyz();
    let (q00, a00) = corner_local(params, pv, n, t, k0, m0, theta, &e00);
    let (q01, a01) = corner_local(params, pv, n, t, k0, m1, theta, &e01);
    let (q10, a10) = corner_local(params, pv, n, t, k0 + 1, m0, theta, &e10);
    let (q11, a11) = corner_local(params, pv, n, t, k0 + 1, m1, theta, &e11);
    // A corner whose path was lost (a ray slipping between triangles, a
    // grazing ray that leaves the mesh at once) takes the rotation of the
    // heaviest corner whose path left the glass; a corner where the light
    // is totally reflected or blocked lends no direction at all.
    //
    // The exit ray's geometry weighs each corner also by the light it
    // carries: a path that leaves at the critical angle (the last ring of a
    // ball) grazes off along the surface with no light, and whether it
    // leaves at all there is a matter of rounding; it must not steer the
    // others' light.
    let carried = |e: &TableEntry| e.transmittance.x.max(e.transmittance.y).max(e.transmittance.z).clamp(1e-4, 1.0);
    let (t00, t01, t10, t11) = (w00 * carried(&e00), w01 * carried(&e01), w10 * carried(&e10), w11 * carried(&e11));
    let t_total = t00 + t01 + t10 + t11;
    let q = heaviest(q00, t00, q01, t01, q10, t10, q11, t11);
    let lost = |e: &TableEntry| if e.position.w == PATH_LOST as f32 { t_total / total } else { 0.0 };
    let (g00, g01, g10, g11) =
        (t00 + b00 * lost(&e00), t01 + b01 * lost(&e01), t10 + b10 * lost(&e10), t11 + b11 * lost(&e11));
    let pick_q = |qj: Quat, wj: f32| if wj > 0.0 { qj } else { q };
    let s0 = sampled_local(params, n, t, k0);
    let s1 = sampled_local(params, n, t, k0 + 1);
    let (ring0, h0) = blend(pick_q(q00, w00).mul_vec3(s0), g00, pick_q(q01, w01).mul_vec3(s0), g01);
    let (ring1, h1) = blend(pick_q(q10, w10).mul_vec3(s1), g10, pick_q(q11, w11).mul_vec3(s1), g11);
    let (local_exit, _) = blend(ring0, h0, ring1, h1);
    let local_anchor = (a00 * t00 + a01 * t01 + a10 * t10 + a11 * t11) / t_total;
    let back = Quat::from_axis_angle(n, theta);
    let direction = back.mul_vec3(local_exit).normalize();
    let anchor = pv + back.mul_vec3(local_anchor);
    let s_exit =
        (e00.direction.w * t00 + e01.direction.w * t01 + e10.direction.w * t10 + e11.direction.w * t11) / t_total;
    let inner = (e00.transmittance * w00 + e01.transmittance * w01 + e10.transmittance * w10 + e11.transmittance * w11)
        / weighed;
    // The entry's Fresnel transmittance at the light's own angle.
    let entry = optics::transmittance(-l.dot(n), 1.0 / pick(materials[v.material as usize].ior, c));
    ExitRay {
        position: (anchor + direction * s_exit).extend(1.0),
        direction: direction.extend(0.0),
        transmittance: inner * entry,
    }
}

/// Flux (W per channel, w = 0) entering the glass through triangle `tri`
/// from `light` and leaving it, before the flux ratio: `E_perp S cos(theta)`
/// times the mean transmittance of the vertices' exit rays.
pub fn triangle_flux(
    params: &CommonParams,
    light: &GpuLight,
    light_map: &[Vec4],
    a: Vec3,
    b: Vec3,
    c: Vec3,
    transmitted: Vec4,
) -> Vec4 {
    let g = (a + b + c) / 3.0;
    let local = light_local(light, g);
    let (dir, e_perp) = if light.kind == LIGHT_DIRECTIONAL {
        (light.axis_z.xyz(), emitted(light, light_map, local) * transmittance(params.sigma_t, local.z))
    } else {
        let d = g - light.position.xyz();
        let s2 = d.length_squared().max(1e-30);
        let s = s2.sqrt();
        (d / s, emitted(light, light_map, local) * transmittance(params.sigma_t, s) / s2)
    };
    let area_normal = (b - a).cross(c - a) * 0.5;
    let projected = area_normal.dot(dir).abs();
    let f = e_perp * transmitted * projected;
    Vec4::new(f.x, f.y, f.z, 0.0)
}

/// Bins per texel: `MAP_BINS` in the receivers' maps; the shaft maps
/// keep only the three densities (they are read straight up and down, and
/// the direction is already in them: `rasterize`).
pub fn texel_bins(params: &CausticsParams) -> u32 {
    if params.shaft_steps > 0 {
        3
    } else {
        MAP_BINS
    }
}

/// Texels of the caustics maps over all their planes.
pub fn map_texels(params: &CausticsParams) -> u32 {
    params.planes * params.map_width * params.map_height
}

/// Bins of the caustics maps: `texel_bins` per texel of every plane.
pub fn map_bins(params: &CausticsParams) -> u32 {
    map_texels(params) * texel_bins(params)
}

/// Invocations of the maps' rasteriser (`rasterize`): every light,
/// triangle, channel and plane.
pub fn map_invocations(params: &CausticsParams) -> u32 {
    params.light_count * params.triangle_count * params.channels * params.planes
}

/// Map invocation `index` = `((light * triangle_count + triangle) *
/// channels + channel) * planes + plane`: the cross-section of the triangle's
/// illumination volume with the plane, rasterised into its map.
#[allow(clippy::too_many_arguments)]
pub fn rasterize<A: AtomicWords + ?Sized>(
    index: u32,
    common: &CommonParams,
    params: &CausticsParams,
    lights: &[GpuLight],
    light_map: &[Vec4],
    glass: &Glass,
    rays: &[ExitRay],
    table: &[u32],
    materials: &[GpuMaterial],
    words: &mut A,
) {
    let k = index % params.planes;
    let c = (index / params.planes) % params.channels;
    let ti = (index / (params.planes * params.channels)) % params.triangle_count;
    let li = index / (params.planes * params.channels * params.triangle_count);
    let tri = glass.triangles[ti as usize];
    // Glass that does not disperse sends all three channels one way: its
    // channel-0 invocation draws them all, the others nothing.
    let own_channels = glass.vertices[tri.vertices[0] as usize].channels;
    if c >= own_channels {
        return;
    }
    let first = li * params.vertex_count;
    let r0 = rays[((first + tri.vertices[0]) * params.channels + c) as usize];
    let r1 = rays[((first + tri.vertices[1]) * params.channels + c) as usize];
    let r2 = rays[((first + tri.vertices[2]) * params.channels + c) as usize];
    if r0.position.w == 0.0 || r1.position.w == 0.0 || r2.position.w == 0.0 {
        return;
    }
    let (d0, d1, d2) = (r0.direction.xyz(), r1.direction.xyz(), r2.direction.xyz());
    // Only light going down, and not within 0.9 degrees of the horizontal
    // (`MAX_SLOPE`): such rays land over 64 heights away, where a
    // cross-section's corners lie so far out that f32 cannot tell which
    // samples it covers. In the receivers' maps a triangle whose corners
    // go both ways (the grazing light of a
    // ball's outer zone, part of which lands across its shadow) is cut
    // into its finest parts and only those that go down are drawn.
    let refine = params.shaft_steps == 0;
    let all_steep = steep(d0) && steep(d1) && steep(d2);
    if !all_steep && !refine {
        return;
    }
    let y = plane_height(params, k);
    let v0 = glass.vertices[tri.vertices[0] as usize];
    let v1 = glass.vertices[tri.vertices[1] as usize];
    let v2 = glass.vertices[tri.vertices[2] as usize];
    let light = lights[li as usize];
    // The flux through the triangle with no loss; each part takes its
    // share times its own rays' transmittance.
    let mut flux =
        triangle_flux(common, &light, light_map, v0.position.xyz(), v1.position.xyz(), v2.position.xyz(), Vec4::ONE);
    if own_channels == 3 {
        flux = channel_part(flux, c, 3);
    }
    let rect = plane_rect(params, k);
    let volume = Volume {
        field: RayField {
            r0,
            r1,
            r2,
            v0,
            v1,
            v2,
            light,
            channel: c,
            // The rays inside from the tables only where the corners go
            // both ways (never in the shaft maps, which drop such triangles:
            // their 32 planes would look the tables up 32 times over).
            // Elsewhere the straight blend, cut into parts where it fans
            // out: at the middles of the ball's lit triangles the turned
            // tables land 2.72 mm from an exact trace at the median, the
            // straight blend 2.84 mm (docs/caustics.md).
            refine: !all_steep,
            params,
            table,
            materials,
        },
        y,
        // Shaft planes: a ray that leaves the glass below the plane is drawn
        // where it leaves. Such a plane cuts the glass, which hides it, but
        // the light just under the glass is read between it and the plane
        // below: without its light there, the shaft would fade toward the glass.
        clamp: params.shaft_steps > 0,
        origin: Vec3::new(rect.x, 0.0, rect.y),
        texel: rect.z,
    };
    // The illumination volume holds the rays leaving the glass for every
    // point of the triangle, and its cross-section with the plane is the
    // image of the triangle under where they cross it. The flat triangle
    // of the three corners' crossings is that image only while the rays
    // vary little across the triangle. Where they fan out (light leaving
    // near the critical angle, rays near the horizontal: a ball's outer
    // zones, whose light spreads over its shadow) it misplaces the light,
    // and the ball's shadow showed spokes and wedges where a light tracer
    // shows a smooth halo. So the triangle is cut into `n x n` equal parts,
    // each its own cross-section with its share of the flux, `n` chosen so
    // an edge's middle ray lands within `SPLIT_TOLERANCE` texels of the
    // middle of its corners' crossings (`RayField::ray` for the rays inside).
    let n = if all_steep { splits(&volume) } else { MAX_SPLITS };
    let plane_base = k * params.map_width * params.map_height;
    if n == 1 {
        // Most volumes: the whole cross-section at once.
        let cut = volume.whole();
        if cut.drawn && cross_section_visits(&cut, params) > MAX_VOLUME_TEXELS {
            words.fetch_add(REJECTED_WORD, 1);
        } else {
            draw_cut(words, common, params, plane_base, &cut, flux, rect.z);
        }
        return;
    }
    let grid = Grid::new(&volume, n);
    // The parts' rows are walked three times over, so they are counted
    // first, from the parts' boxes: over `MAX_PART_ROWS`, the parts are
    // taken twice as large (every other vertex of the grid), and so on to
    // the whole cross-section.
    let mut stride = 1;
    let mut m = n;
    loop {
        let mut rows = 0.0;
        let mut part = 0;
        while part < m * m {
            let cut = grid.part(&volume, part, stride);
            if cut.drawn {
                let (j0, j1) = row_range(&cut.triangle, params);
                rows += (j1 - j0 + 1.0).max(0.0);
            }
            part += 1;
        }
        if rows <= MAX_PART_ROWS || m == 1 {
            break;
        }
        if m % 2 == 0 {
            stride *= 2;
            m /= 2;
        } else {
            // The whole cross-section, as a volume the rays cross straight.
            stride = n;
            m = 1;
        }
    }
    // First the texels to visit: a cross-section over `MAX_VOLUME_TEXELS`
    // in all (light spread over a tenth of a 512^2 map or more) is counted
    // as rejected and not drawn, on both backends alike: lavapipe ends
    // every loop of an invocation after 65 535 iterations in all, which
    // would cut it short on that device only.
    let mut visits = 0.0;
    let mut part = 0;
    while part < m * m {
        let cut = grid.part(&volume, part, stride);
        if cut.drawn {
            visits += cross_section_visits(&cut, params);
        }
        part += 1;
    }
    if visits > MAX_VOLUME_TEXELS {
        words.fetch_add(REJECTED_WORD, 1);
        return;
    }
    let parts = (m * m) as f32;
    let mut part = 0;
    while part < m * m {
        let cut = grid.part(&volume, part, stride);
        draw_cut(words, common, params, plane_base, &cut, flux / parts, rect.z);
        part += 1;
    }
}

/// Draws one part of a cross-section holding `flux` (W per channel, before
/// its rays' transmittance) into plane `plane_base`'s map (texel `texel` m).
fn draw_cut<A: AtomicWords + ?Sized>(
    words: &mut A,
    common: &CommonParams,
    params: &CausticsParams,
    plane_base: u32,
    cut: &Cut,
    flux: Vec4,
    texel: f32,
) {
    let w = cut.direction;
    let mut f = flux * cut.transmittance * transmittance(common.sigma_t, cut.distance);
    if params.shaft_steps > 0 {
        // Shaft maps: the light scattered toward the eye, `p(cos a) / |w_y|`
        // at the cross-section's centroid (Iwasaki 2002 weighs each
        // volume's cross-section by the phase function toward the eye). The
        // mean of the rays crossing a texel would not do: where they cross
        // from all sides (under a lens, around its focus) the phase of their
        // mean direction is not their mean phase.
        let to_eye = (common.camera_position.xyz() - cut.centroid).normalize();
        f *= phase::evaluate(common.phase_kind, w.dot(to_eye), common.phase_g) / -w.y;
    }
    if cut.drawn && (f.x > 0.0 || f.y > 0.0 || f.z > 0.0) {
        let slope_x = (w.x / -w.y).clamp(-MAX_SLOPE, MAX_SLOPE);
        let slope_z = (w.z / -w.y).clamp(-MAX_SLOPE, MAX_SLOPE);
        draw_cross_section(words, params, plane_base, &cut.triangle, f, texel, slope_x, slope_z);
    }
}

/// The rays leaving the glass for the light entering one lit triangle:
/// its corners' exit rays (the lookup's) and what the rays in between are
/// found from (`RayField::ray`).
struct RayField<'a> {
    r0: ExitRay,
    r1: ExitRay,
    r2: ExitRay,
    v0: GlassVertex,
    v1: GlassVertex,
    v2: GlassVertex,
    light: GpuLight,
    channel: u32,
    /// Rays inside from the corners' tables (else the corners' straight blend).
    refine: bool,
    params: &'a CausticsParams,
    table: &'a [u32],
    materials: &'a [GpuMaterial],
}

/// An illumination volume met by a plane: its rays, the plane's height,
/// whether a ray that leaves below the plane is drawn where it leaves
/// (shaft planes), and the map's corner and texel size (metres).
struct Volume<'a> {
    field: RayField<'a>,
    y: f32,
    clamp: bool,
    origin: Vec3,
    texel: f32,
}

/// One part of a volume's cross-section: the triangle in texel
/// coordinates, the part's mean direction (unit), its centroid on the
/// plane, the mean distance its rays travel to the plane (metres) and
/// their mean transmittance.
struct Cut {
    triangle: Triangle2,
    direction: Vec3,
    centroid: Vec3,
    distance: f32,
    transmittance: Vec4,
    /// Its rays all go down steeply and reach the plane.
    drawn: bool,
}

impl RayField<'_> {
    /// The straight blend of the corners' exit rays at barycentric
    /// `(u, v)` (the weights of corners 1 and 2): origin, unit direction,
    /// transmittance.
    fn blended(&self, u: f32, v: f32) -> (Vec3, Vec3, Vec4) {
        let (w0, w1, w2) = (1.0 - u - v, u, v);
        let o = self.r0.position.xyz() * w0 + self.r1.position.xyz() * w1 + self.r2.position.xyz() * w2;
        let d = self.r0.direction.xyz() * w0 + self.r1.direction.xyz() * w1 + self.r2.direction.xyz() * w2;
        let t = self.r0.transmittance * w0 + self.r1.transmittance * w1 + self.r2.transmittance * w2;
        (o, d.normalize(), t)
    }

    /// The exit ray of the light entering at barycentric `(u, v)` of the
    /// triangle. Each corner's table is looked up as if the surface around
    /// the corner were turned to the point (the rotation taking the
    /// corner's normal to the point's, applied to the light on the way in
    /// and to the exit ray on the way out: exact on a ball, whose tables
    /// are one table turned), and the three are blended by the barycentric
    /// weights. At a corner, the corner's own ray (the lookup's). Where no
    /// corner's table says the light leaves, the straight blend.
    fn ray(&self, u: f32, v: f32) -> (Vec3, Vec3, Vec4) {
        let (w0, w1, w2) = (1.0 - u - v, u, v);
        if !self.refine || w0 >= 1.0 || w1 >= 1.0 || w2 >= 1.0 {
            return self.blended(u, v);
        }
        let p = self.v0.position.xyz() * w0 + self.v1.position.xyz() * w1 + self.v2.position.xyz() * w2;
        let n = (self.v0.normal.xyz() * w0 + self.v1.normal.xyz() * w1 + self.v2.normal.xyz() * w2).normalize();
        let l = if self.light.kind == LIGHT_DIRECTIONAL {
            self.light.axis_z.xyz()
        } else {
            (p - self.light.position.xyz()).normalize()
        };
        let (o0, d0, t0, s0) = self.turned(&self.v0, w0, p, n, l);
        let (o1, d1, t1, s1) = self.turned(&self.v1, w1, p, n, l);
        let (o2, d2, t2, s2) = self.turned(&self.v2, w2, p, n, l);
        let sum = s0 + s1 + s2;
        if sum <= 0.0 || sum.is_nan() {
            return self.blended(u, v);
        }
        ((o0 + o1 + o2) / sum, (d0 + d1 + d2).normalize(), (t0 + t1 + t2) / sum)
    }

    /// Corner `x`'s lookup turned to the point `p` (normal `n`, light `l`),
    /// weighted by `w`: weighted exit point, direction, transmittance, and
    /// the weight (0 where the corner's table says nothing).
    fn turned(&self, x: &GlassVertex, w: f32, p: Vec3, n: Vec3, l: Vec3) -> (Vec3, Vec3, Vec4, f32) {
        let none = (Vec3::ZERO, Vec3::ZERO, Vec4::ZERO, 0.0);
        if w <= 0.0 {
            return none;
        }
        let q = rotation_arc(n, x.normal.xyz());
        let e = exit_ray(self.params, x, q.mul_vec3(l), self.channel, self.materials, self.table);
        if e.position.w == 0.0 {
            return none;
        }
        let back = q.conjugate();
        let exit = p + back.mul_vec3(e.position.xyz() - x.position.xyz());
        (exit * w, back.mul_vec3(e.direction.xyz()) * w, e.transmittance * w, w)
    }
}

impl Volume<'_> {
    /// The whole cross-section: where the corners' rays cross the plane.
    fn whole(&self) -> Cut {
        let (pa, ta, da, ra) = self.crossing(0.0, 0.0);
        let (pb, tb, db, rb) = self.crossing(1.0, 0.0);
        let (pc, tc, dc, rc) = self.crossing(0.0, 1.0);
        cut_of(self, [pa, pb, pc], [da, db, dc], [ta, tb, tc], [ra, rb, rc])
    }

    /// The ray at barycentric `(u, v)` meeting the plane: the point, the
    /// distance along the ray, its direction and transmittance.
    fn crossing(&self, u: f32, v: f32) -> (Vec3, f32, Vec3, Vec4) {
        let (o, d, tr) = self.field.ray(u, v);
        let t = (self.y - o.y) / d.y;
        let t = if self.clamp { t.max(0.0) } else { t };
        (o + d * t, t, d, tr)
    }
}

/// Vertices of the finest grid a triangle is cut into (`MAX_SPLITS`).
const GRID_VERTICES: usize = ((MAX_SPLITS + 1) * (MAX_SPLITS + 2) / 2) as usize;

/// Where a volume's rays from the vertices of its triangle's `n x n`
/// barycentric grid cross the plane, each ray found once (every part
/// shares its corners with its neighbours, and a ray is three lookups): the
/// crossing point, the ray's direction, its distance to the plane and its
/// transmittance.
struct Grid {
    n: u32,
    point: [Vec3; GRID_VERTICES],
    direction: [Vec3; GRID_VERTICES],
    distance: [f32; GRID_VERTICES],
    transmittance: [Vec4; GRID_VERTICES],
}

impl Grid {
    fn new(volume: &Volume, n: u32) -> Grid {
        let mut grid = Grid {
            n,
            point: [Vec3::ZERO; GRID_VERTICES],
            direction: [Vec3::ZERO; GRID_VERTICES],
            distance: [0.0; GRID_VERTICES],
            transmittance: [Vec4::ZERO; GRID_VERTICES],
        };
        let step = 1.0 / n as f32;
        let mut i = 0;
        while i <= n {
            let mut j = 0;
            while j <= n - i {
                let g = grid.index(i, j);
                let (p, t, d, tr) = volume.crossing(i as f32 * step, j as f32 * step);
                grid.point[g] = p;
                grid.distance[g] = t;
                grid.direction[g] = d;
                grid.transmittance[g] = tr;
                j += 1;
            }
            i += 1;
        }
        grid
    }

    /// Grid vertex `(i, j)` (`i` steps along corner 1, `j` along corner 2):
    /// row `i` holds `n + 1 - i` vertices.
    fn index(&self, i: u32, j: u32) -> usize {
        (i * (self.n + 1) - i * (i.max(1) - 1) / 2 + j) as usize
    }

    /// Part `index` of the `m x m` equal triangles whose corners are every
    /// `stride`-th vertex of the grid (`m = n / stride`): `m (m + 1) / 2`
    /// upright, then `m (m - 1) / 2` upside down.
    fn part(&self, volume: &Volume, index: u32, stride: u32) -> Cut {
        let n = self.n / stride;
        let upright = n * (n + 1) / 2;
        let (flip, r) = if index < upright { (false, index) } else { (true, index - upright) };
        let rows = if flip { n - 1 } else { n };
        // Row `i` of a triangular grid with `rows` rows, then `j` in it.
        let mut i = 0;
        let mut j = r;
        while j >= rows - i {
            j -= rows - i;
            i += 1;
        }
        let (i, j, s) = (i * stride, j * stride, stride);
        let (a, b, c) = if flip {
            (self.index(i + s, j), self.index(i, j + s), self.index(i + s, j + s))
        } else {
            (self.index(i, j), self.index(i + s, j), self.index(i, j + s))
        };
        cut_of(
            volume,
            [self.point[a], self.point[b], self.point[c]],
            [self.direction[a], self.direction[b], self.direction[c]],
            [self.distance[a], self.distance[b], self.distance[c]],
            [self.transmittance[a], self.transmittance[b], self.transmittance[c]],
        )
    }
}

/// The part of a volume's cross-section whose three rays cross the plane
/// at `point` (metres), going `direction`, after `distance` (metres), with
/// `transmittance`.
fn cut_of(
    volume: &Volume,
    point: [Vec3; 3],
    direction: [Vec3; 3],
    distance: [f32; 3],
    transmittance: [Vec4; 3],
) -> Cut {
    let (ax, az) = to_texel(point[0], volume.origin, volume.texel);
    let (bx, bz) = to_texel(point[1], volume.origin, volume.texel);
    let (cx, cz) = to_texel(point[2], volume.origin, volume.texel);
    let third = 1.0 / 3.0;
    let [da, db, dc] = direction;
    let [ta, tb, tc] = distance;
    let drawn = steep(da) && steep(db) && steep(dc) && ta >= 0.0 && tb >= 0.0 && tc >= 0.0;
    Cut {
        triangle: Triangle2::new(ax, az, bx, bz, cx, cz),
        direction: (da + db + dc).normalize(),
        centroid: (point[0] + point[1] + point[2]) * third,
        distance: (ta + tb + tc) * third,
        transmittance: (transmittance[0] + transmittance[1] + transmittance[2]) * third,
        drawn,
    }
}

/// Most parts along each edge a volume's cross-section is cut into
/// (`rasterize`): 64 parts at most.
pub const MAX_SPLITS: u32 = 8;
/// How far (texels) an edge's middle ray may land from the middle of its
/// corners' crossings before the cross-section is cut into parts.
pub const SPLIT_TOLERANCE: f32 = 0.5;

/// Parts along each edge (1..=`MAX_SPLITS`) for the volume's cross-section
/// to follow the rays within `SPLIT_TOLERANCE` texels: the middle ray's
/// miss falls with the square of the parts' size.
fn splits(v: &Volume) -> u32 {
    let (p0, ..) = v.crossing(0.0, 0.0);
    let (p1, ..) = v.crossing(1.0, 0.0);
    let (p2, ..) = v.crossing(0.0, 1.0);
    let (m01, ..) = v.crossing(0.5, 0.0);
    let (m02, ..) = v.crossing(0.0, 0.5);
    let (m12, ..) = v.crossing(0.5, 0.5);
    let miss =
        (m01 - (p0 + p1) * 0.5).length().max((m02 - (p0 + p2) * 0.5).length()).max((m12 - (p1 + p2) * 0.5).length())
            / v.texel;
    if miss.is_nan() || miss <= SPLIT_TOLERANCE {
        return 1;
    }
    let n = (miss / SPLIT_TOLERANCE).sqrt().ceil();
    if n >= MAX_SPLITS as f32 {
        MAX_SPLITS
    } else {
        n as u32
    }
}

/// Most rows of the map the parts of one cross-section may span in all
/// (`rasterize`; beyond it, larger parts). On lavapipe the turned torus's
/// maps differed from the CPU's in 5 622 texels with 2 048 rows, 468 with
/// 1 024; with 384, in 3 876 (0.54 %) again once the larger parts were
/// drawn instead of dropped: see `CausticsMaps::compare`.
pub const MAX_PART_ROWS: f32 = 384.0;

/// The rows `[j0, j1]` of the map whose squares a cross-section's box meets.
fn row_range(t: &Triangle2, params: &CausticsParams) -> (f32, f32) {
    let hmax = params.map_height as f32 - 1.0;
    let j0 = (t.az.min(t.bz).min(t.cz) - 0.5).ceil().max(0.0);
    let j1 = (t.az.max(t.bz).max(t.cz) + 0.5).floor().min(hmax);
    (j0, j1)
}

/// Texels a cross-section's rows span over the map (see `rasterize`).
fn cross_section_visits(cut: &Cut, params: &CausticsParams) -> f32 {
    let t = &cut.triangle;
    let wmax = params.map_width as f32 - 1.0;
    let (j0, j1) = row_range(t, params);
    let mut visits = 0.0;
    let mut j = j0;
    while j <= j1 {
        let (lo, hi) = row_span(t, j, wmax);
        visits += (hi - lo + 1.0).max(0.0);
        j += 1.0;
    }
    visits
}

/// A cross-section (texel coordinates, texel centres at integers) with
/// `flux` (W per channel) spread over the texels of plane `plane_base`'s
/// map it covers, by their 4 x 4 coverage samples.
#[allow(clippy::too_many_arguments)]
fn draw_cross_section<A: AtomicWords + ?Sized>(
    words: &mut A,
    params: &CausticsParams,
    plane_base: u32,
    tri: &Triangle2,
    flux: Vec4,
    texel: f32,
    slope_x: f32,
    slope_z: f32,
) {
    let (ax, az, bx, bz, cx, cz) = (tri.ax, tri.az, tri.bx, tri.bz, tri.cx, tri.cz);
    if !tri.is_finite() {
        return;
    }
    let (wmax, hmax) = (params.map_width as f32 - 1.0, params.map_height as f32 - 1.0);
    let area2 = (bx - ax) * (cz - az) - (bz - az) * (cx - ax);
    // Rows whose squares [j - 1/2, j + 1/2] the cross-section's box meets;
    // in each, only the texels its span over that row meets.
    let (j0, j1) = row_range(tri, params);
    // The sub-samples covered in all (4 x 4 per texel).
    let mut count = 0u32;
    if area2 != 0.0 {
        let mut j = j0;
        while j <= j1 {
            let (lo, hi) = row_span(tri, j, wmax);
            if lo <= hi {
                count += SubRows::new(tri, j).covered_span(lo, hi);
            }
            j += 1.0;
        }
    }
    // A cross-section partly off the map: its samples there are not all
    // it covers, so each sample carries the flux over the cross-section's
    // whole area (16 samples per texel), and what falls off the map is lost.
    let on_map = ax.min(bx).min(cx) >= -0.5
        && az.min(bz).min(cz) >= -0.5
        && ax.max(bx).max(cx) <= wmax + 0.5
        && az.max(bz).max(cz) <= hmax + 0.5;
    let samples = if on_map { count as f32 } else { (count as f32).max(area2.abs() * 0.5 * SUBSAMPLES as f32) };
    if count == 0 {
        // Smaller than a sub-sample's spacing, or a focal line: all of it
        // in the texel under the centroid.
        let gx = ((ax + bx + cx) / 3.0).round();
        let gz = ((az + bz + cz) / 3.0).round();
        if gx >= 0.0 && gx <= wmax && gz >= 0.0 && gz <= hmax {
            let density = flux / (texel * texel);
            deposit(words, params, plane_base + gz as u32 * params.map_width + gx as u32, density, slope_x, slope_z);
        }
        return;
    }
    // Last, each texel its share of the flux, by its sub-samples.
    let per_sample = flux * (SUBSAMPLES as f32 / (samples * texel * texel));
    let mut j = j0;
    while j <= j1 {
        let (lo, hi) = row_span(tri, j, wmax);
        let rows = SubRows::new(tri, j);
        let mut i = lo;
        while i <= hi {
            let covered = rows.covered(i);
            if covered > 0 {
                let density = per_sample * (covered as f32 / SUBSAMPLES as f32);
                deposit(words, params, plane_base + j as u32 * params.map_width + i as u32, density, slope_x, slope_z);
            }
            i += 1.0;
        }
        j += 1.0;
    }
}

/// Most texels one cross-section may visit (see `rasterize`): with three
/// walks over its rows (at most 4 096) and two over its texels, within
/// lavapipe's 65 535 loop iterations per invocation.
pub const MAX_VOLUME_TEXELS: f32 = 24_000.0;

/// The texels `[lo, hi]` of row `j` (within `[0, wmax]`) whose squares the
/// cross-section meets within the row's band `[j - 1/2, j + 1/2]`: the
/// x-extent of the triangle clipped to the band (empty: `lo > hi`).
fn row_span(t: &Triangle2, j: f32, wmax: f32) -> (f32, f32) {
    let (zlo, zhi) = (j - 0.5, j + 0.5);
    let (lo, hi) = clip_edge(t.ax, t.az, t.bx, t.bz, zlo, zhi, f32::MAX, -f32::MAX);
    let (lo, hi) = clip_edge(t.bx, t.bz, t.cx, t.cz, zlo, zhi, lo, hi);
    let (lo, hi) = clip_edge(t.cx, t.cz, t.ax, t.az, zlo, zhi, lo, hi);
    ((lo - 0.5).ceil().max(0.0), (hi + 0.5).floor().min(wmax))
}

/// `[lo, hi]` grown by the x-extent of the edge `(x0, z0)-(x1, z1)` where
/// it lies within `zlo <= z <= zhi`.
#[allow(clippy::too_many_arguments)]
fn clip_edge(x0: f32, z0: f32, x1: f32, z1: f32, zlo: f32, zhi: f32, lo: f32, hi: f32) -> (f32, f32) {
    let dz = z1 - z0;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    if dz == 0.0 {
        if z0 < zlo || z0 > zhi {
            return (lo, hi);
        }
    } else {
        let (ta, tb) = ((zlo - z0) / dz, (zhi - z0) / dz);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
        if t0 > t1 {
            return (lo, hi);
        }
    }
    let (xa, xb) = (x0 + (x1 - x0) * t0, x0 + (x1 - x0) * t1);
    (lo.min(xa).min(xb), hi.max(xa).max(xb))
}

/// Whether an exit ray goes down more steeply than `MAX_SLOPE`.
fn steep(d: Vec3) -> bool {
    d.y < 0.0 && d.x.abs().max(d.z.abs()) < -d.y * MAX_SLOPE
}

/// Coverage samples per texel (a 4 x 4 grid).
pub const SUBSAMPLES: u32 = 16;

/// A cross-section in texel coordinates: its corners, and its three edge
/// functions `e_k(x, z) = ex_k (x - ax) + ez_k (z - az) + c_k` (component
/// `k` of each), oriented to be non-negative inside (`Triangle2::new`).
pub struct Triangle2 {
    pub ax: f32,
    pub az: f32,
    pub bx: f32,
    pub bz: f32,
    pub cx: f32,
    pub cz: f32,
    ex: Vec3,
    ez: Vec3,
    c: Vec3,
}

impl Triangle2 {
    /// The cross-section with corners `a`, `b`, `c` (x, z).
    pub fn new(ax: f32, az: f32, bx: f32, bz: f32, cx: f32, cz: f32) -> Triangle2 {
        let (abx, abz, bcx, bcz, cax, caz) = (bx - ax, bz - az, cx - bx, cz - bz, ax - cx, az - cz);
        // Edge k from corner k to the next: cross(edge, q - corner), each
        // taken from `a` (e_2's constant is 0: its corner `c` is `a - ca`).
        let area2 = abx * (cz - az) - abz * (cx - ax);
        let sign = if area2 < 0.0 { -1.0 } else { 1.0 };
        Triangle2 {
            ax,
            az,
            bx,
            bz,
            cx,
            cz,
            ex: Vec3::new(-abz, -bcz, -caz) * sign,
            ez: Vec3::new(abx, bcx, cax) * sign,
            c: Vec3::new(0.0, bcz * abx - bcx * abz, 0.0) * sign,
        }
    }

    /// Whether every corner is finite (below 1e30 in size). A cross-section
    /// with a corner that is not draws nothing: its edge functions would
    /// bound no sub-sample row, and `SubRows` would count every sample.
    /// Each corner compared on its own (`max` passes a NaN over), and not
    /// by `is_finite`, whose infinite literal the SPIR-V front end rejects.
    pub fn is_finite(&self) -> bool {
        let small = |v: f32| v.abs() < 1e30;
        small(self.ax) && small(self.az) && small(self.bx) && small(self.bz) && small(self.cx) && small(self.cz)
    }
}

/// The four sub-sample rows of a texel row `j` (`z = j - 3/8, j - 1/8,
/// j + 1/8, j + 3/8`, one per component): on each, the samples inside the
/// cross-section, as the first and last sample index `s` (the row's
/// samples are at `x = s/4 - 3/8`, so texel column `i` holds `s = 4i` to
/// `4i + 3`; integers in f32, exact below 2^24) whose `x - ax` lies where
/// all three edge functions are non-negative (none: `first > last`). A
/// texel's coverage is then how many of its four sub-sample columns lie
/// between them (`covered`), not 16 tests of three edges; a run of texels'
/// coverage, their sum exactly (`covered_span`).
pub struct SubRows {
    first: Vec4,
    last: Vec4,
}

/// `[lo, hi]` (of `dx = x - ax`, per sub-sample row at `z - az`) narrowed
/// to where the edge function `ez z + c + ex dx` is non-negative; a row
/// that an edge parallel to the rows leaves wholly outside is made empty.
fn edge_bounds(lo: Vec4, hi: Vec4, z: Vec4, ex: f32, ez: f32, c: f32) -> (Vec4, Vec4) {
    let r = z * ez + Vec4::splat(c);
    if ex > 0.0 {
        (lo.max(-r / ex), hi)
    } else if ex < 0.0 {
        (lo, hi.min(-r / ex))
    } else {
        let none = Vec4::select(r.cmplt(Vec4::ZERO), Vec4::splat(-1e31), Vec4::splat(1e30));
        (lo, hi.min(none))
    }
}

impl SubRows {
    pub fn new(t: &Triangle2, j: f32) -> SubRows {
        let z = Vec4::new(j - 0.375, j - 0.125, j + 0.125, j + 0.375) - Vec4::splat(t.az);
        let (lo, hi) = (Vec4::splat(-1e30), Vec4::splat(1e30));
        let (lo, hi) = edge_bounds(lo, hi, z, t.ex.x, t.ez.x, t.c.x);
        let (lo, hi) = edge_bounds(lo, hi, z, t.ex.y, t.ez.y, t.c.y);
        let (lo, hi) = edge_bounds(lo, hi, z, t.ex.z, t.ez.z, t.c.z);
        // Sample s is at dx = s/4 - 3/8 - ax: in [lo, hi] for s from
        // ceil(4 (lo + ax) + 3/2) to floor(4 (hi + ax) + 3/2). Held within
        // +-2^30 (an unbounded side: 1e30), where an f32 integer plus or
        // minus a texel's few samples stays ordered.
        let ax = Vec4::splat(t.ax);
        let bound = Vec4::splat(1_073_741_824.0);
        let first = ((lo + ax) * 4.0 + Vec4::splat(1.5)).ceil().clamp(-bound, bound);
        let last = ((hi + ax) * 4.0 + Vec4::splat(1.5)).floor().clamp(-bound, bound);
        SubRows { first, last }
    }

    /// How many of texel column `i`'s 4 x 4 sub-samples (`x = i - 3/8, ...,
    /// i + 3/8` on each row) lie in the cross-section.
    pub fn covered(&self, i: f32) -> u32 {
        self.covered_span(i, i)
    }

    /// The sub-samples of texel columns `i0` to `i1` in the cross-section:
    /// the sum of their `covered`, exactly (the same integers).
    pub fn covered_span(&self, i0: f32, i1: f32) -> u32 {
        let first = self.first.max(Vec4::splat(4.0 * i0));
        let last = self.last.min(Vec4::splat(4.0 * i1 + 3.0));
        let n = (last - first + Vec4::ONE).max(Vec4::ZERO);
        (n.x + n.y + n.z + n.w) as u32
    }
}

/// Texel coordinates (centres at integers) of a point on a sample plane.
fn to_texel(q: Vec3, origin: Vec3, texel: f32) -> (f32, f32) {
    ((q.x - origin.x) / texel - 0.5, (q.z - origin.z) / texel - 0.5)
}

/// Adds a density (W/m^2 per channel) and its direction to a texel's bins.
fn deposit<A: AtomicWords + ?Sized>(
    words: &mut A,
    params: &CausticsParams,
    texel: u32,
    density: Vec4,
    slope_x: f32,
    slope_z: f32,
) {
    let bin = texel * texel_bins(params);
    let s = params.scale;
    if density.x > 0.0 {
        scatter_add(words, bin, density.x, s);
    }
    if density.y > 0.0 {
        scatter_add(words, bin + 1, density.y, s);
    }
    if density.z > 0.0 {
        scatter_add(words, bin + 2, density.z, s);
    }
    if texel_bins(params) < MAP_BINS {
        return;
    }
    let weight = density.x + density.y + density.z;
    if slope_x > 0.0 {
        scatter_add(words, bin + 3, weight * slope_x, s);
    } else if slope_x < 0.0 {
        scatter_add(words, bin + 4, -weight * slope_x, s);
    }
    if slope_z > 0.0 {
        scatter_add(words, bin + 5, weight * slope_z, s);
    } else if slope_z < 0.0 {
        scatter_add(words, bin + 6, -weight * slope_z, s);
    }
}

/// A bin's value from its words, in the map's units (f32).
pub fn read_bin(words: &[u32], params: &CausticsParams, bin: u32) -> f32 {
    let low = words[(1 + 2 * bin) as usize];
    let high = words[(2 + 2 * bin) as usize];
    (high as f32 * 4_294_967_296.0 + low as f32) / params.scale
}

/// Density (rgb) and slopes (w: unused) of one plane at texel coordinates
/// `(u, v)` (centres at integers), bilinear; zero outside the map.
fn sample_plane(words: &[u32], params: &CausticsParams, plane: u32, u: f32, v: f32) -> (Vec4, f32, f32) {
    let mut density = Vec4::ZERO;
    let mut sx = 0.0;
    let mut sz = 0.0;
    let i0 = u.floor();
    let j0 = v.floor();
    let fu = u - i0;
    let fv = v - j0;
    let mut corner = 0;
    while corner < 4 {
        let i = i0 + (corner % 2) as f32;
        let j = j0 + (corner / 2) as f32;
        let w = if corner % 2 == 1 { fu } else { 1.0 - fu } * if corner / 2 == 1 { fv } else { 1.0 - fv };
        if w > 0.0 && i >= 0.0 && j >= 0.0 && i < params.map_width as f32 && j < params.map_height as f32 {
            let bin = ((plane * params.map_height + j as u32) * params.map_width + i as u32) * MAP_BINS;
            let d = Vec4::new(
                read_bin(words, params, bin),
                read_bin(words, params, bin + 1),
                read_bin(words, params, bin + 2),
                0.0,
            );
            // Most texels of a map hold no light: no direction to read.
            if d.x > 0.0 || d.y > 0.0 || d.z > 0.0 {
                density += d * w;
                sx += (read_bin(words, params, bin + 3) - read_bin(words, params, bin + 4)) * w;
                sz += (read_bin(words, params, bin + 5) - read_bin(words, params, bin + 6)) * w;
            }
        }
        corner += 1;
    }
    (density, sx, sz)
}

/// The two sample planes around height `y` and the weight of the upper
/// one, for interpolating linearly in height (below the lowest plane and
/// above the highest, the nearest one; with one plane, that plane).
fn planes_around(params: &CausticsParams, y: f32) -> (u32, u32, f32) {
    if params.planes < 2 {
        return (0, 0, 0.0);
    }
    let s = ((y - params.map_origin.y) / params.plane_spacing).clamp(0.0, (params.planes - 1) as f32);
    let k0 = (s.floor() as u32).min(params.planes - 2);
    (k0, k0 + 1, s - k0 as f32)
}

/// Texel `index` (over all planes) of the shaft maps as f32: its three
/// densities (`p E_perp`, W/(m^2 sr); w = 0), resolved once from the
/// fixed-point words so that the march reads one `Vec4` per corner instead
/// of three 64-bit sums (`caustic_shaft_resolve_kernel`).
pub fn resolve_texel(index: u32, params: &CausticsParams, words: &[u32]) -> Vec4 {
    let b = index * texel_bins(params);
    Vec4::new(read_bin(words, params, b), read_bin(words, params, b + 1), read_bin(words, params, b + 2), 0.0)
}

/// Plane `k` of the resolved shaft maps at `(x, z)`, bilinear (texel
/// centres at integers); zero off its map.
fn resolved_at(texels: &[Vec4], params: &CausticsParams, k: u32, x: f32, z: f32) -> Vec4 {
    let rect = params.rects[k as usize];
    let u = (x - rect.x) / rect.z - 0.5;
    let v = (z - rect.y) / rect.z - 0.5;
    if !(u > -1.0 && v > -1.0 && u < params.map_width as f32 && v < params.map_height as f32) {
        return Vec4::ZERO;
    }
    let (i0, j0) = (u.floor(), v.floor());
    let (fu, fv) = (u - i0, v - j0);
    let (width, height) = (params.map_width as f32, params.map_height as f32);
    let (low, high) = if i0 >= 0.0 && j0 >= 0.0 && i0 + 1.0 < width && j0 + 1.0 < height {
        // All four texels on the map (most reads): one index, no tests.
        let at = ((k * params.map_height + j0 as u32) * params.map_width + i0 as u32) as usize;
        let row = params.map_width as usize;
        (texels[at] * (1.0 - fu) + texels[at + 1] * fu, texels[at + row] * (1.0 - fu) + texels[at + row + 1] * fu)
    } else {
        (
            texel_at(texels, params, k, i0, j0) * (1.0 - fu) + texel_at(texels, params, k, i0 + 1.0, j0) * fu,
            texel_at(texels, params, k, i0, j0 + 1.0) * (1.0 - fu)
                + texel_at(texels, params, k, i0 + 1.0, j0 + 1.0) * fu,
        )
    };
    low * (1.0 - fv) + high * fv
}

/// Texel `(i, j)` of plane `k` of the resolved shaft maps; zero off the map.
fn texel_at(texels: &[Vec4], params: &CausticsParams, k: u32, i: f32, j: f32) -> Vec4 {
    if i >= 0.0 && j >= 0.0 && i < params.map_width as f32 && j < params.map_height as f32 {
        texels[((k * params.map_height + j as u32) * params.map_width + i as u32) as usize]
    } else {
        Vec4::ZERO
    }
}

/// Caustic irradiance (W/m^2 per channel, w = 0) on a surface at `p` with
/// unit normal `n` facing the side the light arrives from: the two sample
/// planes around `p`'s height, interpolated linearly in height (below the
/// lowest plane and above the highest, the nearest one), each
/// `density |n . w| / |w_y|` (see the module docs).
pub fn caustic_irradiance(words: &[u32], params: &CausticsParams, p: Vec3, n: Vec3) -> Vec4 {
    let u = (p.x - params.map_origin.x) / params.map_origin.w - 0.5;
    let v = (p.z - params.map_origin.z) / params.map_origin.w - 0.5;
    // Off the maps (most of a large floor): no caustic.
    if !(u > -1.0 && v > -1.0 && u < params.map_width as f32 && v < params.map_height as f32) {
        return Vec4::ZERO;
    }
    let (k0, k1, w) = planes_around(params, p.y);
    let (d0, sx0, sz0) = sample_plane(words, params, k0, u, v);
    let (d1, sx1, sz1) = if w > 0.0 { sample_plane(words, params, k1, u, v) } else { (Vec4::ZERO, 0.0, 0.0) };
    let density = d0 * (1.0 - w) + d1 * w;
    let weight = density.x + density.y + density.z;
    if weight <= 0.0 || weight.is_nan() {
        return Vec4::ZERO;
    }
    let sx = (sx0 * (1.0 - w) + sx1 * w) / weight;
    let sz = (sz0 * (1.0 - w) + sz1 * w) / weight;
    // The mean ray direction (sx, -1, sz), normalised: |w_y| = 1 / len.
    let dir = Vec3::new(sx, -1.0, sz);
    let len = dir.length();
    let cos = (-n.dot(dir) / len).max(0.0);
    density * (cos * len)
}

/// The height (m) of sample plane `k` (`params.map_origin.y` the lowest).
fn plane_height(params: &CausticsParams, k: u32) -> f32 {
    params.map_origin.y + k as f32 * params.plane_spacing
}

/// The span `(t0, t1)` of the view ray `o + t d` (`0 <= t <= t_far`)
/// between shaft planes `k` and `k + 1`, within the x-z box both their
/// maps cover (empty: `t1 <= t0`).
fn slab_span(params: &CausticsParams, o: Vec3, d: Vec3, k: u32, t_far: f32) -> (f32, f32) {
    let (r0, r1) = (params.rects[k as usize], params.rects[k as usize + 1]);
    let (s0, s1) = (r0.z * params.map_width as f32, r1.z * params.map_width as f32);
    let (u0, u1) = (r0.z * params.map_height as f32, r1.z * params.map_height as f32);
    let y_k = plane_height(params, k);
    let span = clip_axis(o.y, d.y, y_k, y_k + params.plane_spacing, (0.0, t_far));
    let span = clip_axis(o.x, d.x, r0.x.min(r1.x), (r0.x + s0).max(r1.x + s1), span);
    clip_axis(o.z, d.z, r0.y.min(r1.y), (r0.y + u0).max(r1.y + u1), span)
}

/// `(a, b)` narrowed to where `o + t d` lies within `[lo, hi]` on one axis.
fn clip_axis(o: f32, d: f32, lo: f32, hi: f32, (a, b): (f32, f32)) -> (f32, f32) {
    if d.abs() < 1e-30 {
        if o < lo || o > hi {
            return (1.0, 0.0);
        }
        return (a, b);
    }
    let (ta, tb) = ((lo - o) / d, (hi - o) / d);
    (a.max(ta.min(tb)), b.min(ta.max(tb)))
}

/// Caustic light shafts (Iwasaki, Dobashi and Nishita 2002's virtual
/// planes, here the illumination volumes' cross-sections on horizontal
/// shaft planes, `params` the shaft maps'): the refracted light the medium
/// scatters toward the eye along the view ray of pixel `index` (band
/// relative), W/(m^2 sr) per channel (w = 0), up to the surface it sees
/// (`texel`'s distance) and within the maps' box:
///
/// `L = sigma_s int sum_i p(cos a_i) E_perp,i(t) e^(-sigma_t t) dt`
///
/// (the single-scattering integral of eq. 1 of the 2002 shafts paper with
/// the caustic light as the source), summed over the illumination volumes
/// `i` through each point: `E_perp,i = density_i / |w_y,i|` the flux per
/// unit area across volume `i`'s direction `w_i`, `cos a_i = w_i . (-d)`
/// toward the eye. The shaft maps hold the sum, `p E_perp` per channel
/// (W/(m^2 sr); `rasterize` weighs each cross-section by its phase toward
/// the eye and its `1 / |w_y|`). About `params.shaft_steps` intervals
/// over the view ray's spans between planes within their maps
/// (`slab_span`), the maps read at each one's middle straight up and down
/// (the slab's two planes; read along the mean ray, or following the planes'
/// squares, measured no nearer the reference), the eye's transmittance
/// integrated exactly over each (`phi`): energy-conserving per interval.
/// Light is read where the planes are (below the lowest and above the
/// highest, none).
pub fn caustic_shafts_pixel(
    index: u32,
    common: &CommonParams,
    params: &CausticsParams,
    texels: &[Vec4],
    texel: &GBufferTexel,
) -> Vec4 {
    if params.planes < 2 || params.shaft_steps == 0 {
        return Vec4::ZERO;
    }
    let pixel = index + common.band_start;
    let (o, d) = camera_ray(common, pixel % common.width, pixel / common.width);
    let t_far = texel.normal_distance.w;
    // Only the slabs the ray meets within the box all the maps cover (none: no light).
    let b = params.bounds;
    let y0 = params.map_origin.y;
    let top = y0 + (params.planes - 1) as f32 * params.plane_spacing;
    let (t0, t1) = clip_axis(o.y, d.y, y0, top, (0.0, t_far));
    let (t0, t1) = clip_axis(o.x, d.x, b.x, b.z, (t0, t1));
    let (t0, t1) = clip_axis(o.z, d.z, b.y, b.w, (t0, t1));
    if t0.is_nan() || t1.is_nan() || t1 <= t0 {
        return Vec4::ZERO;
    }
    let (ya, yb) = (o.y + d.y * t0, o.y + d.y * t1);
    let first = (((ya.min(yb) - y0) / params.plane_spacing).floor().max(0.0) as u32).min(params.planes - 2);
    let last = (((ya.max(yb) - y0) / params.plane_spacing).floor().max(0.0) as u32).min(params.planes - 2);
    // The view ray within each slab between two planes, clipped to where
    // the two planes' maps are: first their total length, shared out in
    // `shaft_steps` intervals, then each walked with its share (a ray
    // that crosses a narrow bundle in a short clipped span is sampled as
    // finely as one that runs along a wide one).
    let mut total = 0.0;
    let mut k = first;
    while k <= last {
        let (a, b) = slab_span(params, o, d, k, t_far);
        total += (b - a).max(0.0);
        k += 1;
    }
    if total.is_nan() || total <= 0.0 {
        return Vec4::ZERO;
    }
    let step = total / params.shaft_steps as f32;
    let sigma = common.sigma_t;
    let mut sum = Vec4::ZERO;
    let mut k = first;
    while k <= last {
        let (t0, t1) = slab_span(params, o, d, k, t_far);
        if t1 > t0 {
            // No finer than half the slab's texels or height: a read
            // between them adds nothing but time.
            let texel = params.rects[k as usize].z.min(params.rects[k as usize + 1].z);
            let finest = 0.5 * texel.min(params.plane_spacing / d.y.abs().max(1e-6));
            let n = ((t1 - t0) / step.max(finest)).ceil().max(1.0);
            let dt = (t1 - t0) / n;
            // Every point of the slab lies between planes k and k + 1, each
            // read bilinear in its own square (`plane_rect`) and the two
            // interpolated linearly in height, as `caustic_irradiance`
            // reads the receivers' maps.
            let y_k = plane_height(params, k);
            // int_a^(a + dt) e^(-sigma t) dt = e^(-sigma a) dt phi(sigma dt),
            // per channel: e^(-sigma a) carried from one interval to the
            // next by e^(-sigma dt), both taken at the slab's first lit
            // interval (none for a slab in the dark).
            let mut lit = false;
            let (mut e, mut r, mut w_phi) = (Vec4::ZERO, Vec4::ZERO, Vec4::ZERO);
            let mut i = 0.0;
            while i < n {
                let a = t0 + i * dt;
                let p = o + d * (a + 0.5 * dt);
                let w = ((p.y - y_k) / params.plane_spacing).clamp(0.0, 1.0);
                let below = resolved_at(texels, params, k, p.x, p.z);
                let above = if w > 0.0 { resolved_at(texels, params, k + 1, p.x, p.z) } else { Vec4::ZERO };
                let scattered = below * (1.0 - w) + above * w;
                if !lit && (scattered.x > 0.0 || scattered.y > 0.0 || scattered.z > 0.0) {
                    lit = true;
                    // One exp for the three channels of a grey medium.
                    e = transmittance(sigma, a);
                    r = transmittance(sigma, dt);
                    let x = sigma * dt;
                    w_phi = Vec4::new(phi_given(x.x, r.x), phi_given(x.y, r.y), phi_given(x.z, r.z), 0.0) * dt;
                }
                if lit {
                    sum += scattered * e * w_phi;
                    e *= r;
                }
                i += 1.0;
            }
        }
        k += 1;
    }
    let l = sum * common.sigma_s;
    Vec4::new(l.x, l.y, l.z, 0.0)
}

/// The caustic light a receiver (`surface::receiver`: the surface a view
/// ray meets, directly or through glass) reflects toward the eye,
/// W/(m^2 sr) per channel (w = 0): `albedo / pi * E_caustic` times the
/// receiver's weight (the transmittance along the view ray and through
/// glass). None without maps (`params.planes` = 0: no caustics this frame).
pub fn caustic_light(words: &[u32], params: &CausticsParams, materials: &[GpuMaterial], r: &Receiver) -> Vec4 {
    if params.planes == 0 || !r.found {
        return Vec4::ZERO;
    }
    let e = caustic_irradiance(words, params, r.point, r.normal);
    let l = materials[r.material as usize].albedo * e * r.weight * FRAC_1_PI;
    Vec4::new(l.x, l.y, l.z, 0.0)
}

/// Mantissa bits per channel of `pack_rgb`.
const PACKED_MANTISSA: u32 = 18;

/// Packs non-negative rgb into 64 bits: three 18-bit mantissas sharing the
/// 8-bit exponent of the largest channel (bits 0-17 r, 18-35 g, 36-53 b,
/// 54-61 the exponent), so each channel keeps 2^-18 of the largest, over
/// the whole f32 range (below 2^-109, with fewer bits). How the G-buffer carries
/// a pixel's caustic light from the surface pass to the caustics layer.
pub fn pack_rgb(v: Vec3) -> [u32; 2] {
    let m = v.x.max(v.y).max(v.z);
    // Not positive, or NaN: nothing.
    if m.is_nan() || m <= 0.0 {
        return [0, 0];
    }
    let e = ((m.to_bits() >> 23) & 0xff).clamp(18, 254);
    // v / 2^(e - 126 - 18): the largest channel lands in [2^17, 2^18).
    let scale = f32::from_bits((271 - e) << 23);
    let top = (1u32 << PACKED_MANTISSA) - 1;
    let q = |x: f32| ((x.max(0.0) * scale + 0.5) as u32).min(top);
    let (r, g, b) = (q(v.x), q(v.y), q(v.z));
    [r | (g << 18), (g >> 14) | (b << 4) | (e << 22)]
}

/// The rgb `pack_rgb` packed.
pub fn unpack_rgb(w: [u32; 2]) -> Vec3 {
    let e = (w[1] >> 22) & 0xff;
    if e == 0 {
        return Vec3::ZERO;
    }
    let mask = (1u32 << PACKED_MANTISSA) - 1;
    let r = w[0] & mask;
    let g = (w[0] >> 18) | ((w[1] & 0xf) << 14);
    let b = (w[1] >> 4) & mask;
    let unit = f32::from_bits((e - 17) << 23);
    Vec3::new(r as f32, g as f32, b as f32) * unit
}

/// Per-pixel kernel: the caustic light pixel `index` sees, W/(m^2 sr) per
/// channel (w = 0), from its G-buffer texel, where the surface pass left it
/// (`caustic_light` at the receivers it shaded, through glass included).
pub fn caustics_pixel(texel: &GBufferTexel) -> Vec4 {
    unpack_rgb(texel.caustic).extend(0.0)
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn caustics_table_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 31)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 32)] table: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.vertex_count * p.directions * p.channels {
        let geometry = crate::scene_geometry(&common[0], spheres, triangles, nodes);
        let slot = table_slot(index, p, glass_vertices);
        if slot != u32::MAX {
            let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
            let e = table_entry(index, p, &geometry, &glass, materials);
            let vertex = glass_vertices[(index / (p.channels * p.directions)) as usize];
            store_entry(table, p, slot, &e, &vertex);
        }
    }
}

#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn caustics_lookup_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] spheres: &[GpuSphere],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] triangles: &[GpuTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] nodes: &[GpuBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 31)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 32)] table: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 33)] rays: &mut [ExitRay],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < p.light_count * p.vertex_count * p.channels {
        let geometry = crate::scene_geometry(&common[0], spheres, triangles, nodes);

        rays[index as usize] = lookup(index, p, lights, &geometry, glass_vertices, materials, table);
    }
}

/// GPU only: on the host the words are `AtomicU32`s (`scatter::CpuAtomics`).
#[cfg(target_arch = "spirv")]
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn caustics_maps_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 31)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 32)] table: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 33)] rays: &[ExitRay],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 34)] words: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < map_invocations(p) {
        let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
        rasterize(index, &common[0], p, lights, light_map, &glass, rays, table, materials, words);
    }
}

/// The shaft maps (`caustic_shafts_pixel`): the same illumination volumes
/// as `caustics_maps_kernel`, cut by the shaft planes (`params`, binding 79)
/// into their own maps. GPU only, as that kernel.
#[cfg(target_arch = "spirv")]
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn caustic_shaft_maps_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] materials: &[GpuMaterial],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 29)] glass_vertices: &[GlassVertex],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 30)] glass_triangles: &[GlassTriangle],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 32)] table: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 33)] rays: &[ExitRay],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 79)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 80)] words: &mut [u32],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < map_invocations(p) {
        let glass = Glass { vertices: glass_vertices, triangles: glass_triangles };
        rasterize(index, &common[0], p, lights, light_map, &glass, rays, table, materials, words);
    }
}

#[spirv(compute(threads(64)))]
pub fn caustic_shafts_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 79)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 81)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 82)] texels: &[Vec4],
) {
    let index = crate::flat_index(id, groups);
    if index < common[0].band_pixels {
        radiance[index as usize] =
            caustic_shafts_pixel(index, &common[0], &params[0], texels, &gbuffer[index as usize]);
    }
}

/// The shaft maps resolved to f32 texels (`resolve_texel`).
#[spirv(compute(threads(64)))]
pub fn caustic_shaft_resolve_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 79)] params: &[CausticsParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 80)] words: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 82)] texels: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let p = &params[0];
    if index < map_texels(p) {
        texels[index as usize] = resolve_texel(index, p, words);
    }
}

#[spirv(compute(threads(64)))]
pub fn caustics_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 35)] radiance: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    if index < common[0].band_pixels {
        radiance[index as usize] = caustics_pixel(&gbuffer[index as usize]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [0, 1) from a 64-bit linear congruential
    /// generator seeded with `seed` (24 bits each).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f64) / (1u64 << 24) as f64
        }
    }

    #[test]
    fn packed_rgb_keeps_each_channel_to_2_pow_minus_17_of_the_largest() {
        let mut uniform = uniform(7);
        let mut next = move || uniform() as f32;
        for k in 0..20_000 {
            // Magnitudes from 1e-30 to 1e30, channels spread over 6 decades.
            let scale = 10f32.powf(next() * 60.0 - 30.0);
            let v = Vec3::new(next(), 10f32.powf(-6.0 * next()), next() * next()) * scale;
            let back = unpack_rgb(pack_rgb(v));
            let tol = v.max_element() * 2f32.powi(-17);
            assert!((back - v).abs().max_element() <= tol, "{k}: {v} -> {back}");
        }
        for v in [Vec3::ZERO, Vec3::splat(-1.0), Vec3::splat(f32::NAN)] {
            assert_eq!(unpack_rgb(pack_rgb(v)), Vec3::ZERO, "{v}");
        }
        // Negative channels beside a positive one read as 0; infinity as the largest finite step.
        assert_eq!(unpack_rgb(pack_rgb(Vec3::new(-1.0, 2.0, 0.0))), Vec3::new(0.0, 2.0, 0.0));
        assert!(unpack_rgb(pack_rgb(Vec3::new(f32::INFINITY, 0.0, 0.0))).x > 1e38);
    }

    /// `SubRows` counts a texel's covered sub-samples from each row's
    /// interval; here against the 16 samples tested one by one in f64, on
    /// triangles of every size and shape (slivers, texel-sized, rows
    /// parallel to an edge), near the map's corner and near the far side of
    /// a 512-texel map (where the sample indices are largest). A sample
    /// within 1e-4 texels of an edge may go either way (f32 rounding), so
    /// the f64 count is bracketed. A row's `covered_span` is the sum of its
    /// texels' `covered`.
    #[test]
    fn sub_rows_count_the_samples_inside() {
        let mut next = uniform(11);
        let mut texels = 0;
        for k in 0..4000 {
            let scale = [0.3, 2.0, 12.0][k % 3];
            let off = if k % 2 == 0 { 0 } else { 480 };
            let mut c: [f64; 6] = core::array::from_fn(|_| (20 + off) as f64 + (next() - 0.5) * scale);
            if k % 7 == 0 {
                c[3] = c[1]; // an edge parallel to the rows
            }
            if k % 11 == 0 {
                c[4] = c[0] + (c[2] - c[0]) * 0.5; // a sliver: c on the line through a and b
                c[5] = c[1] + (c[3] - c[1]) * 0.5 + 1e-3;
            }
            let t = Triangle2::new(c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32, c[4] as f32, c[5] as f32);
            let (a, b, cc) = ((t.ax as f64, t.az as f64), (t.bx as f64, t.bz as f64), (t.cx as f64, t.cz as f64));
            let area2 = (b.0 - a.0) * (cc.1 - a.1) - (b.1 - a.1) * (cc.0 - a.0);
            if area2 == 0.0 {
                continue;
            }
            let sign = area2.signum();
            // The signed distance (texels) of a point inside each edge; the least of the three.
            let depth = |x: f64, z: f64| {
                let e = |p: (f64, f64), q: (f64, f64)| {
                    sign * ((q.0 - p.0) * (z - p.1) - (q.1 - p.1) * (x - p.0)) / (q.0 - p.0).hypot(q.1 - p.1)
                };
                e(a, b).min(e(b, cc)).min(e(cc, a))
            };
            for j in 12 + off..29 + off {
                let rows = SubRows::new(&t, j as f32);
                let (i0, i1) = (12 + off, 28 + off);
                let sum: u32 = (i0..=i1).map(|i| rows.covered(i as f32)).sum();
                assert_eq!(rows.covered_span(i0 as f32, i1 as f32), sum, "triangle {k}, row {j}");
                for i in i0..=i1 {
                    let (mut surely, mut maybe) = (0, 0);
                    for sz in 0..4 {
                        for sx in 0..4 {
                            let d = depth(i as f64 - 0.375 + 0.25 * sx as f64, j as f64 - 0.375 + 0.25 * sz as f64);
                            surely += (d > 1e-4) as u32;
                            maybe += (d >= -1e-4) as u32;
                        }
                    }
                    let n = rows.covered(i as f32);
                    assert!(
                        surely <= n && n <= maybe,
                        "triangle {k} {c:?}, texel ({i}, {j}): {n} not in [{surely}, {maybe}]"
                    );
                    texels += (maybe > 0) as u32;
                }
            }
        }
        assert!(texels > 10_000, "{texels} texels covered");
    }

    /// A cross-section with a corner that is not finite draws nothing (its
    /// edge functions would bound no row, and every sample would count).
    #[test]
    fn a_cross_section_with_a_nan_corner_draws_nothing() {
        let params = CausticsParams { map_width: 16, map_height: 16, scale: 1024.0, ..Default::default() };
        let bins = 16 * 16 * MAP_BINS;
        let words: Vec<core::sync::atomic::AtomicU32> =
            (0..crate::scatter::words_for(bins)).map(|_| core::sync::atomic::AtomicU32::new(0)).collect();
        let mut atomics = crate::scatter::CpuAtomics(&words);
        let flux = Vec4::new(1.0, 1.0, 1.0, 0.0);
        for bad in [f32::NAN, f32::INFINITY, 1e31] {
            let t = Triangle2::new(2.0, 2.0, bad, 3.0, 4.0, 9.0);
            draw_cross_section(&mut atomics, &params, 0, &t, flux, 1.0, 0.0, 0.0);
        }
        assert!(words.iter().all(|w| w.load(core::sync::atomic::Ordering::Relaxed) == 0));
        // And a finite one does draw (the check above can fail).
        let t = Triangle2::new(2.0, 2.0, 8.0, 3.0, 4.0, 9.0);
        draw_cross_section(&mut atomics, &params, 0, &t, flux, 1.0, 0.0, 0.0);
        assert!(words.iter().any(|w| w.load(core::sync::atomic::Ordering::Relaxed) != 0));
    }
}
