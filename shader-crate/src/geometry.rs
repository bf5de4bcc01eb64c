//! Ray casting against the scene's spheres and triangles.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::glam::{Vec3, Vec4Swizzles};
use crate::types::{GpuBvhNode, GpuSphere, GpuTriangle, NO_OBJECT};

/// Returned by the intersection functions when nothing is hit (the largest
/// finite f32: naga rejects infinite constants in shaders).
pub const NO_HIT: f32 = f32::MAX;

/// The nearest surface hit along a ray.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray direction, metres; `NO_HIT` if nothing.
    pub distance: f32,
    /// Unit geometric normal, not yet turned to face the ray.
    pub normal: Vec3,
    /// The scene object and the material hit (`NO_OBJECT` if nothing).
    pub object: u32,
    pub material: u32,
    /// The triangle hit (its index in BVH order), `NO_OBJECT` for a sphere or nothing.
    pub primitive: u32,
    /// BVH nodes whose boxes the walk tested: the cost of the trace (tests
    /// check that it grows about logarithmically with the triangle count).
    pub visits: u32,
}

impl Hit {
    /// No hit at all.
    pub fn none() -> Hit {
        Hit {
            distance: NO_HIT,
            normal: Vec3::ZERO,
            object: NO_OBJECT,
            material: NO_OBJECT,
            primitive: NO_OBJECT,
            visits: 0,
        }
    }
}

/// The scene's geometry as the kernels see it: spheres (tested one by one,
/// scenes hold few) and triangles under a BVH.
#[derive(Copy, Clone)]
pub struct Geometry<'a> {
    pub spheres: &'a [GpuSphere],
    pub sphere_count: u32,
    pub triangles: &'a [GpuTriangle],
    pub nodes: &'a [GpuBvhNode],
    pub node_count: u32,
}

impl Geometry<'_> {
    /// Whether the scene has no objects (no sphere, no triangle): every
    /// ray misses.
    pub fn is_empty(&self) -> bool {
        self.node_count == 0 && self.sphere_count == 0
    }
}

/// Distance to the first intersection of the ray `origin + t dir` (`dir` unit,
/// `t > t_min`) with a sphere, metres; `NO_HIT` if none.
///
/// Uses the numerically stable form (the half-chord is computed from the
/// distance of the centre to the ray, not from a difference of large squares),
/// so spheres far from the origin keep their shape in f32.
pub fn ray_sphere(origin: Vec3, dir: Vec3, center: Vec3, radius: f32, t_min: f32) -> f32 {
    let oc = center - origin;
    let t_closest = oc.dot(dir);
    let closest = oc - dir * t_closest;
    let d2 = closest.length_squared();
    let r2 = radius * radius;
    if d2 > r2 {
        return NO_HIT;
    }
    let half_chord = (r2 - d2).sqrt();
    let t_near = t_closest - half_chord;
    if t_near > t_min {
        return t_near;
    }
    let t_far = t_closest + half_chord;
    if t_far > t_min {
        return t_far;
    }
    NO_HIT
}

/// How far outside a triangle (in barycentric units) a hit still counts, at
/// least: a ray through a shared edge or vertex of a mesh meets at least
/// one of the triangles around it, instead of slipping between them when
/// the rounding of each triangle's test puts it just outside all of them (a
/// ray through a tessellated ball's centre hits the opposite vertex
/// exactly). `ray_triangle` widens it by `EDGE_SLACK` for small triangles
/// far from the ray's origin.
pub const EDGE_TOLERANCE: f32 = 1e-6;

/// Positions in f32 are off by about `f32::EPSILON` times their magnitude;
/// a triangle's test counts hits within 4 times that distance of its
/// edges (the ray's origin and the triangle's first vertex taken as the
/// magnitudes), converted to barycentric units.
pub const EDGE_SLACK: f32 = 4.0 * f32::EPSILON;

/// Möller-Trumbore ray/triangle intersection: distance along `dir` (unit) to
/// the triangle, metres, if it is beyond `t_min`; `NO_HIT` otherwise.
pub fn ray_triangle(origin: Vec3, dir: Vec3, v0: Vec3, v1: Vec3, v2: Vec3, t_min: f32) -> f32 {
    let e1 = v1 - v0;
    let e2 = v2 - v0;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-20 {
        return NO_HIT;
    }
    let inv_det = 1.0 / det;
    let s = origin - v0;
    // A move of the ray by `delta` metres moves `u` by up to `delta |p| /
    // |det|` and `v` by `delta |e1| / |det|` (max norms: a bound within 3x).
    let reach = (origin.abs().max_element() + v0.abs().max_element()) * EDGE_SLACK;
    let tolerance = EDGE_TOLERANCE + reach * p.abs().max(e1.abs()).max_element() * inv_det.abs();
    let u = s.dot(p) * inv_det;
    if u < -tolerance || u > 1.0 + tolerance {
        return NO_HIT;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv_det;
    if v < -tolerance || u + v > 1.0 + tolerance {
        return NO_HIT;
    }
    let t = e2.dot(q) * inv_det;
    if t > t_min {
        t
    } else {
        NO_HIT
    }
}

/// Entries of the BVH traversal stack: at least the deepest tree's depth
/// (`bvh::SAH_DEPTH + 32` on the host).
pub const BVH_STACK: usize = 64;

/// Where the ray `origin + t dir` enters the box `[lo, hi]` within
/// `[t_min, t_max]` (`t_min` if it starts inside), or `NO_HIT` if it does
/// not meet it there; the slab test of `ray_hits_box`.
pub fn box_entry(origin: Vec3, inv_dir: Vec3, lo: Vec3, hi: Vec3, t_min: f32, t_max: f32) -> f32 {
    let (near, far) = box_span(origin, inv_dir, lo, hi, t_min, t_max);
    if near <= far {
        near
    } else {
        NO_HIT
    }
}

/// Where the ray `origin + t dir` (`inv_dir = 1 / dir`) enters and leaves
/// the box `[lo, hi]`, clipped to `[t_min, t_max]`: the slab test; it meets
/// the box there only if `near <= far`.
#[inline]
pub fn box_span(origin: Vec3, inv_dir: Vec3, lo: Vec3, hi: Vec3, t_min: f32, t_max: f32) -> (f32, f32) {
    let a = (lo - origin) * inv_dir;
    let b = (hi - origin) * inv_dir;
    let near = a.x.min(b.x).max(a.y.min(b.y)).max(a.z.min(b.z)).max(t_min);
    let far = a.x.max(b.x).min(a.y.max(b.y)).min(a.z.max(b.z)).min(t_max);
    (near, far)
}

/// Whether the ray `origin + t dir` meets the box `[lo, hi]` for some `t` in
/// `[t_min, t_max]` (slab test). Axes along which `dir` is 0 give infinite
/// slab distances, which `min`/`max` order correctly. The one case that
/// yields a NaN (`0 * inf`: the origin exactly on a face, the ray parallel to
/// it) may report a miss; the host pads every box beyond its triangles, so
/// such a ray cannot meet any of them.
pub fn ray_hits_box(origin: Vec3, inv_dir: Vec3, lo: Vec3, hi: Vec3, t_min: f32, t_max: f32) -> bool {
    box_entry(origin, inv_dir, lo, hi, t_min, t_max) < NO_HIT
}

/// The nearest hit of a ray with the scene, closer than `t_max`.
///
/// Triangles are found through the BVH, walked nearest child first: at an
/// inner node both children's boxes are tested, the nearer one is entered
/// and the farther one put on a small stack with its entry distance; a box
/// the ray misses, or enters only beyond the nearest hit so far, is never
/// opened. Nearest-first, the first hits found are close, which prunes the
/// rest early.
pub fn trace_nearest(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, geometry: &Geometry) -> Hit {
    trace(origin, dir, t_min, t_max, geometry, false, NO_OBJECT)
}

/// The nearest hit of a ray with one object of the scene (`object`), as if
/// the rest were not there: the same walk, skipping other objects' triangles.
pub fn trace_object(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, geometry: &Geometry, object: u32) -> Hit {
    trace(origin, dir, t_min, t_max, geometry, false, object)
}

/// Whether anything lies on the ray between `t_min` and `t_max` (a shadow
/// ray): the same walk, stopping at the first hit.
pub fn occluded(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, geometry: &Geometry) -> bool {
    trace(origin, dir, t_min, t_max, geometry, true, NO_OBJECT).distance < t_max
}

/// The walk behind `trace_nearest` and `occluded`: with `any_hit`, it
/// returns the first hit found rather than the nearest; with `only` other
/// than `NO_OBJECT`, only that object's spheres and triangles count.
fn trace(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32, geometry: &Geometry, any_hit: bool, only: u32) -> Hit {
    let mut hit = Hit::none();
    let mut best = t_max;
    let mut i = 0;
    while i < geometry.sphere_count as usize {
        let s = geometry.spheres[i];
        let center = s.center_radius.xyz();
        let t = ray_sphere(origin, dir, center, s.center_radius.w, t_min);
        if t < best && (only == NO_OBJECT || s.object == only) {
            best = t;
            hit.distance = t;
            hit.normal = (origin + dir * t - center).normalize();
            hit.object = s.object;
            hit.material = s.material;
            hit.primitive = NO_OBJECT;
            if any_hit {
                return hit;
            }
        }
        i += 1;
    }
    if geometry.node_count == 0 {
        return hit;
    }
    let inv_dir = Vec3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z);
    // Nodes still to visit (the farther child wherever both were met) and
    // where the ray enters their boxes.
    let mut stack = [0u32; BVH_STACK];
    let mut entry = [0.0f32; BVH_STACK];
    let mut depth = 0usize;
    let root = geometry.nodes[0];
    hit.visits += 1;
    let mut n = 0u32;
    let mut walking = box_entry(origin, inv_dir, root.bounds_min.xyz(), root.bounds_max.xyz(), t_min, best) < NO_HIT;
    while walking {
        let node = geometry.nodes[n as usize];
        let mut next = NO_OBJECT;
        if node.count > 0 {
            let mut j = node.first as usize;
            let end = j + node.count as usize;
            while j < end {
                let tri = geometry.triangles[j];
                let (v0, v1, v2) = (tri.v0.xyz(), tri.v1.xyz(), tri.v2.xyz());
                let t = ray_triangle(origin, dir, v0, v1, v2, t_min);
                if t < best && (only == NO_OBJECT || tri.object == only) {
                    best = t;
                    hit.distance = t;
                    hit.normal = (v1 - v0).cross(v2 - v0).normalize();
                    hit.object = tri.object;
                    hit.material = tri.material;
                    hit.primitive = j as u32;
                    if any_hit {
                        return hit;
                    }
                }
                j += 1;
            }
        } else {
            let (l, r) = (n + 1, node.right);
            let (ln, rn) = (geometry.nodes[l as usize], geometry.nodes[r as usize]);
            hit.visits += 2;
            let tl = box_entry(origin, inv_dir, ln.bounds_min.xyz(), ln.bounds_max.xyz(), t_min, best);
            let tr = box_entry(origin, inv_dir, rn.bounds_min.xyz(), rn.bounds_max.xyz(), t_min, best);
            if tl < NO_HIT && tr < NO_HIT {
                // Both: the nearer now, the farther later (`depth` stays
                // below the tree's depth, which the host keeps within the stack).
                let (near, far, t_far) = if tl <= tr { (l, r, tr) } else { (r, l, tl) };
                stack[depth % BVH_STACK] = far;
                entry[depth % BVH_STACK] = t_far;
                depth += 1;
                next = near;
            } else if tl < NO_HIT {
                next = l;
            } else if tr < NO_HIT {
                next = r;
            }
        }
        // Otherwise the nearest node put aside that the ray enters before
        // the nearest hit so far.
        while next == NO_OBJECT && depth > 0 {
            depth -= 1;
            if entry[depth % BVH_STACK] < best {
                next = stack[depth % BVH_STACK];
            }
        }
        walking = next != NO_OBJECT;
        n = next;
    }
    hit
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_hit_from_outside_and_inside() {
        let t = ray_sphere(Vec3::ZERO, Vec3::Z, Vec3::new(0.0, 0.0, 5.0), 1.0, 0.0);
        assert!((t - 4.0).abs() < 1e-6);
        let t = ray_sphere(Vec3::ZERO, Vec3::Z, Vec3::ZERO, 2.0, 0.0);
        assert!((t - 2.0).abs() < 1e-6);
        let t = ray_sphere(Vec3::ZERO, Vec3::X, Vec3::new(0.0, 0.0, 5.0), 1.0, 0.0);
        assert_eq!(t, NO_HIT);
    }

    #[test]
    fn far_sphere_keeps_its_shape_in_f32() {
        // A 1 m sphere 1e5 m away: the naive quadratic loses every digit of the
        // half-chord; the stable form must still find the near surface within
        // f32's spacing at 1e5 (about 8 mm).
        let c = Vec3::new(0.0, 0.0, 1.0e5);
        let t = ray_sphere(Vec3::ZERO, Vec3::Z, c, 1.0, 0.0);
        assert!((t - (1.0e5 - 1.0)).abs() < 0.016, "t = {t}");
    }

    #[test]
    fn box_test_is_conservative_for_flat_boxes_and_axis_rays() {
        // A flat box (a quad's bounds, padded as the host pads them) met
        // head-on, and a ray along an axis that runs inside a slab.
        let (lo, hi) = (Vec3::new(-1.0, -1.0, 2.99999), Vec3::new(1.0, 1.0, 3.00001));
        let inv = |d: Vec3| Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        assert!(ray_hits_box(Vec3::ZERO, inv(Vec3::Z), lo, hi, 0.0, NO_HIT));
        assert!(!ray_hits_box(Vec3::new(2.0, 0.0, 0.0), inv(Vec3::Z), lo, hi, 0.0, NO_HIT));
        // Hit only beyond t_max: skipped.
        assert!(!ray_hits_box(Vec3::ZERO, inv(Vec3::Z), lo, hi, 0.0, 2.0));
        // A zero direction component (inverse infinite) with the origin
        // inside that slab, and outside it.
        assert!(ray_hits_box(Vec3::new(0.5, 0.0, 0.0), inv(Vec3::Z), lo, hi, 0.0, NO_HIT));
        assert!(!ray_hits_box(Vec3::new(1.5, 0.0, 0.0), inv(Vec3::Z), lo, hi, 0.0, NO_HIT));
    }

    #[test]
    fn triangle_hit_edges_and_miss() {
        let (a, b, c) = (Vec3::new(-1.0, -1.0, 3.0), Vec3::new(1.0, -1.0, 3.0), Vec3::new(0.0, 1.0, 3.0));
        assert!((ray_triangle(Vec3::ZERO, Vec3::Z, a, b, c, 0.0) - 3.0).abs() < 1e-6);
        assert_eq!(ray_triangle(Vec3::new(5.0, 0.0, 0.0), Vec3::Z, a, b, c, 0.0), NO_HIT);
        // Behind the origin: not hit.
        assert_eq!(ray_triangle(Vec3::ZERO, -Vec3::Z, a, b, c, 0.0), NO_HIT);
        // Ray parallel to the triangle's plane.
        assert_eq!(ray_triangle(Vec3::new(0.0, 0.0, 3.0), Vec3::X, a, b, c, 0.0), NO_HIT);
    }
}
