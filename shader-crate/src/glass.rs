//! Smooth glass: rays refracted at every interface with the Fresnel
//! transmittance for unpolarised light, attenuated inside by Beer's law.
//!
//! Glass objects are triangle meshes whose vertices carry outward normals
//! (`GlassVertex`); a ray refracts about the normal interpolated over the
//! triangle it hits, so a tessellated ball refracts like a ball. Shared by
//! the surface pass (views through glass, section 5.3 of the caustics paper)
//! and the caustics passes (the light transport table, section 4).

use crate::geometry::{trace_object, Geometry, Hit, NO_HIT};
use crate::glam::{Vec3, Vec4, Vec4Swizzles};
use crate::optics::{refract, transmittance};
use crate::types::{GlassTriangle, GlassVertex, GpuMaterial, MATERIAL_GLASS, NO_OBJECT};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// Most interfaces one path crosses (or reflects at, inside) before it is
/// given up as lost.
pub const MAX_INTERFACES: u32 = 16;

/// The path left the glass.
pub const PATH_OUT: u32 = 0;
/// The path met total internal reflection (the table's flag, section 4).
pub const PATH_TOTAL_REFLECTION: u32 = 1;
/// Seen from the vertex, the light's side is blocked by the object itself
/// (the table's self-occlusion flag, section 4).
pub const PATH_OCCLUDED: u32 = 2;
/// The path did not leave: an open mesh, an opaque object inside the
/// glass, or more than `MAX_INTERFACES` interfaces.
pub const PATH_LOST: u32 = 3;

/// The glass meshes as the kernels see them.
#[derive(Copy, Clone)]
pub struct Glass<'a> {
    pub vertices: &'a [GlassVertex],
    pub triangles: &'a [GlassTriangle],
}

/// The smooth normal (unit, outward) at point `p` on the glass triangle
/// `hit` found: the vertex normals weighted by `p`'s barycentric
/// coordinates. A degenerate triangle gives its first vertex's normal.
pub fn shading_normal(geometry: &Geometry, glass: &Glass, hit: &Hit, p: Vec3) -> Vec3 {
    let tri = geometry.triangles[hit.primitive as usize];
    let g = glass.triangles[tri.glass as usize];
    let (a, b, c) = (tri.v0.xyz(), tri.v1.xyz(), tri.v2.xyz());
    let n0 = glass.vertices[g.vertices[0] as usize].normal.xyz();
    let n1 = glass.vertices[g.vertices[1] as usize].normal.xyz();
    let n2 = glass.vertices[g.vertices[2] as usize].normal.xyz();
    let cross = (b - a).cross(c - a);
    let area2 = cross.length_squared();
    if area2 <= 0.0 || area2.is_nan() {
        return n0;
    }
    let w1 = (p - a).cross(c - a).dot(cross) / area2;
    let w2 = (b - a).cross(p - a).dot(cross) / area2;
    let n = n0 * (1.0 - w1 - w2) + n1 * w1 + n2 * w2;
    let len = n.length();
    if len > 1e-6 {
        n / len
    } else {
        n0
    }
}

/// Whether a hit is on glass.
pub fn is_glass(materials: &[GpuMaterial], hit: &Hit) -> bool {
    hit.distance != NO_HIT && hit.primitive != NO_OBJECT && materials[hit.material as usize].kind == MATERIAL_GLASS
}

/// Where a ray ends up after glass.
#[derive(Copy, Clone, Debug)]
pub struct GlassPath {
    /// Where it left the last glass interface, metres.
    pub position: Vec3,
    /// Its unit direction from there.
    pub direction: Vec3,
    /// The product of the Fresnel transmittances along the way, for the
    /// channel traced.
    pub fresnel: f32,
    /// Absorption coefficient times length inside glass, summed along the
    /// way, per channel (w unused): Beer's law gives `exp(-optical_depth)`.
    pub optical_depth: Vec4,
    /// `PATH_OUT`, `PATH_TOTAL_REFLECTION` or `PATH_LOST`.
    pub status: u32,
    /// What the ray meets after leaving the glass (`NO_HIT` if nothing).
    pub next: Hit,
}

/// A distance that keeps a ray from meeting the surface it leaves, in f32,
/// at point `p`: relative to the scene's scale there.
pub fn surface_epsilon(p: Vec3) -> f32 {
    1e-5 * p.abs().max_element().max(1.0)
}

/// Follows a ray that arrives in direction `d` at point `p` of a glass
/// surface (unit outward normal `n`, material `material`), in channel
/// `channel` (0, 1, 2: its index and absorption): refracted in, through the
/// glass, refracted out, and into any further glass it meets, until it
/// leaves glass for good. With `object` other than `NO_OBJECT`, that object
/// is traced alone, as if the rest of the scene were not there (the light
/// transport table of one object, which depends on nothing else).
///
/// Total internal reflection ends the path (`PATH_TOTAL_REFLECTION`) unless
/// `follow_reflection`, in which case the ray reflects and goes on (views
/// through glass). The transmittance is the product of the Fresnel
/// transmittances at the interfaces crossed and of `exp(-absorption * length)`
/// inside; reflected light at the interfaces crossed is not followed.
#[allow(clippy::too_many_arguments)]
pub fn trace_through(
    geometry: &Geometry,
    glass: &Glass,
    materials: &[GpuMaterial],
    p: Vec3,
    n: Vec3,
    material: u32,
    d: Vec3,
    channel: u32,
    object: u32,
    follow_reflection: bool,
) -> GlassPath {
    let mut path = GlassPath {
        position: p,
        direction: d,
        fresnel: 1.0,
        optical_depth: Vec4::ZERO,
        status: PATH_LOST,
        next: Hit::none(),
    };
    let mut point = p;
    let mut normal = n;
    let mut mat = material;
    let mut dir = d;
    let mut inside = false;
    let mut count = 0;
    while count < MAX_INTERFACES {
        count += 1;
        let m = materials[mat as usize];
        let ior = pick(m.ior, channel);
        // The normal on the incident side, and the relative index.
        let facing = if normal.dot(dir) > 0.0 { -normal } else { normal };
        let eta = if inside { ior } else { 1.0 / ior };
        let cos_i = (-facing.dot(dir)).clamp(0.0, 1.0);
        let (refracted, ok) = refract(dir, facing, eta);
        if ok {
            path.fresnel *= transmittance(cos_i, eta);
            inside = !inside;
        } else if !follow_reflection {
            path.position = point;
            path.direction = dir;
            path.status = PATH_TOTAL_REFLECTION;
            return path;
        }
        dir = refracted;
        let eps = surface_epsilon(point);
        let hit = trace_object(point, dir, eps, NO_HIT, geometry, object);
        if inside {
            // Inside: the next interface must be this glass.
            if hit.distance == NO_HIT || !is_glass(materials, &hit) || (object != NO_OBJECT && hit.object != object) {
                path.position = point;
                path.direction = dir;
                path.status = PATH_LOST;
                return path;
            }
            path.optical_depth += m.absorption * hit.distance;
        } else {
            // Outside: done unless the ray meets glass again.
            let again = is_glass(materials, &hit) && (object == NO_OBJECT || hit.object == object);
            if !again {
                path.position = point;
                path.direction = dir;
                path.status = PATH_OUT;
                path.next = hit;
                return path;
            }
        }
        point += dir * hit.distance;
        normal = shading_normal(geometry, glass, &hit, point);
        mat = hit.material;
    }
    path.position = point;
    path.direction = dir;
    path.status = PATH_LOST;
    path
}

impl GlassPath {
    /// Transmittance per channel (w = 0): the Fresnel product times Beer's law.
    pub fn transmittance(&self) -> Vec4 {
        let t =
            Vec4::new((-self.optical_depth.x).exp(), (-self.optical_depth.y).exp(), (-self.optical_depth.z).exp(), 0.0);
        t * self.fresnel
    }
}

/// Whether a glass material's index differs between channels (dispersion:
/// each channel then takes its own path).
pub fn dispersive(m: &GpuMaterial) -> bool {
    m.ior.x != m.ior.y || m.ior.y != m.ior.z
}

/// Component `channel` (0, 1, 2) of `v`.
pub fn pick(v: Vec4, channel: u32) -> f32 {
    if channel == 0 {
        v.x
    } else if channel == 1 {
        v.y
    } else {
        v.z
    }
}
