//! Smoke (the survey's section 4, after Yoshida and Nishita, "Modeling of
//! smoke flow taking obstacles into account", Pacific Graphics 2000): a
//! fluid on a staggered voxel grid (Fig. 8: each velocity component on the
//! faces normal to it, temperature, pressure and smoke density at the cell
//! centres), stepped by operator splitting:
//!
//! 1. advection of every quantity through the velocity field, the
//!    convective terms of eq. 4 and 5 (semi-Lagrangian, Stam 1999, with an
//!    RK2 back-trace; optionally MacCormack's correction, Selle et al. 2008);
//! 2. forces: the buoyancy `F_bv` of eq. 4 (Boussinesq, `g (T - T_a) / T_a`,
//!    m/s^2) on the vertical faces and the random velocity components of
//!    the Reynolds equations as a random acceleration per face and step;
//! 3. diffusion, backward Euler by Jacobi iteration (unconditionally
//!    stable): eq. 4's viscosity `nu + nu_t` on the velocity, eq. 5's
//!    `alpha` on the temperature, plus eq. 5's eddy term `alpha_t lap T'`
//!    with the random temperature component `T'` drawn per cell and step;
//! 4. projection: the pressure term of eq. 4, `u -= grad(phi) / h` with
//!    `phi = p dt / rho` from the Poisson equation `A phi = -div(u) h^2`
//!    (`A` the 7-point negative Laplacian times `h^2` over the fluid cells,
//!    free-slip walls and obstacles as Neumann, open faces as `phi = 0`),
//!    solved by conjugate gradients preconditioned with a multigrid V-cycle
//!    (red-black Gauss-Seidel smoothing) until the measured residual is
//!    small (the host's `smoke` module runs the loop and its dot products).
//!
//! Every function here is one invocation's work: one face, one cell, one
//! coarse cell. Random numbers come from the counter-based hash of
//! (element, step, seed, stream) (`crate::random`), so both backends draw
//! the same ones. Units: metres, seconds, kelvin; positions inside the
//! grid in cells (`x / h` from the box's lower corner).

use crate::glam::{UVec3, Vec3};
use crate::random::random;

pub mod kernels;

/// Quantities, by what they are sampled as.
pub const KIND_U: u32 = 0;
pub const KIND_V: u32 = 1;
pub const KIND_W: u32 = 2;
pub const KIND_TEMPERATURE: u32 = 3;
pub const KIND_SMOKE: u32 = 4;

/// Bits of `FluidParams::walls`: which faces of the box are walls (closed,
/// free-slip); the others are open (the outside air: the wind's velocity,
/// the ambient temperature, no smoke, `phi = 0`).
pub const WALL_X_LO: u32 = 1;
pub const WALL_X_HI: u32 = 2;
pub const WALL_Y_LO: u32 = 4;
pub const WALL_Y_HI: u32 = 8;
pub const WALL_Z_LO: u32 = 16;
pub const WALL_Z_HI: u32 = 32;

/// Random streams (the hash's fourth argument).
const STREAM_TURBULENCE: u32 = 0x5e0;
const STREAM_TEMPERATURE: u32 = 0x5e3;

/// The fluid's parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct FluidParams {
    /// Cells along x, y (up), z, and all of them.
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub cells: u32,
    /// Cell edge (m) and time step (s).
    pub h: f32,
    pub dt: f32,
    /// The step being taken (from 0) and the seed of its random numbers.
    pub step: u32,
    pub seed: u32,
    /// `WALL_*` bits.
    pub walls: u32,
    /// Gravity (m/s^2) and the ambient temperature (K).
    pub gravity: f32,
    pub ambient: f32,
    /// Amplitude of the random acceleration per face and step (m/s^2).
    pub turbulence: f32,
    /// The outside air's velocity (m/s), at open faces.
    pub wind_x: f32,
    pub wind_y: f32,
    pub wind_z: f32,
    /// Amplitude of the random temperature component `T'` (K) and eq. 5's
    /// eddy diffusivity `alpha_t` (m^2/s) that carries its Laplacian.
    pub temperature_noise: f32,
    pub eddy_diffusivity: f32,
    /// `(nu + nu_t) dt / h^2` and `alpha dt / h^2`: the implicit diffusion's
    /// weights, and the Jacobi iterations each gets (0: none).
    pub viscous_weight: f32,
    pub thermal_weight: f32,
    pub viscous_iterations: u32,
    pub thermal_iterations: u32,
    pub _pad: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)` of 4-byte scalars, no padding.
    unsafe impl bytemuck::Zeroable for super::FluidParams {}
    unsafe impl bytemuck::Pod for super::FluidParams {}
}

impl FluidParams {
    pub fn dims(&self) -> UVec3 {
        UVec3::new(self.nx, self.ny, self.nz)
    }

    /// The wind's component along `axis`.
    fn wind(&self, axis: u32) -> f32 {
        if axis == 0 {
            self.wind_x
        } else if axis == 1 {
            self.wind_y
        } else {
            self.wind_z
        }
    }
}

/// The extent of the array holding `kind` (faces: one more along its axis).
#[inline]
pub fn extent(p: &FluidParams, kind: u32) -> UVec3 {
    let n = p.dims();
    if kind == KIND_U {
        n + UVec3::X
    } else if kind == KIND_V {
        n + UVec3::Y
    } else if kind == KIND_W {
        n + UVec3::Z
    } else {
        n
    }
}

/// Element `(i, j, k)` of an array of extent `e`, x fastest.
#[inline]
pub fn index(e: UVec3, i: u32, j: u32, k: u32) -> usize {
    (i + e.x * (j + e.y * k)) as usize
}

/// The coordinates of element `flat` of an array of extent `e`.
pub fn coords(e: UVec3, flat: u32) -> UVec3 {
    UVec3::new(flat % e.x, (flat / e.x) % e.y, flat / (e.x * e.y))
}

/// Where element `(i, j, k)` of `kind` sits, in cells: a face's centre
/// (`(i, j + 1/2, k + 1/2)` for `u`) or a cell's.
#[inline]
pub fn position(kind: u32, c: UVec3) -> Vec3 {
    let x = c.as_vec3();
    if kind == KIND_U {
        x + Vec3::new(0.0, 0.5, 0.5)
    } else if kind == KIND_V {
        x + Vec3::new(0.5, 0.0, 0.5)
    } else if kind == KIND_W {
        x + Vec3::new(0.5, 0.5, 0.0)
    } else {
        x + Vec3::splat(0.5)
    }
}

/// What `kind` is outside an open face: the wind, the ambient
/// temperature, no smoke.
#[inline]
fn outside_value(p: &FluidParams, kind: u32) -> f32 {
    if kind <= KIND_W {
        p.wind(kind)
    } else if kind == KIND_TEMPERATURE {
        p.ambient
    } else {
        0.0
    }
}

/// Whether `x` (cells) lies beyond an open face of the box.
#[inline]
fn beyond_open_face(p: &FluidParams, x: Vec3) -> bool {
    let n = p.dims().as_vec3();
    (x.x < 0.0 && p.walls & WALL_X_LO == 0)
        || (x.x > n.x && p.walls & WALL_X_HI == 0)
        || (x.y < 0.0 && p.walls & WALL_Y_LO == 0)
        || (x.y > n.y && p.walls & WALL_Y_HI == 0)
        || (x.z < 0.0 && p.walls & WALL_Z_LO == 0)
        || (x.z > n.z && p.walls & WALL_Z_HI == 0)
}

/// The trilinear interpolation of `q` (an array of `kind`) at `x` (cells):
/// the outside air's value beyond an open face, else clamped to the box
/// (walls). Also the least and greatest of the eight values it blends
/// (MacCormack's limiter).
#[inline(always)]
pub fn sample_bounded(p: &FluidParams, kind: u32, q: &[f32], x: Vec3) -> (f32, f32, f32) {
    if beyond_open_face(p, x) {
        let o = outside_value(p, kind);
        return (o, o, o);
    }
    let e = extent(p, kind);
    let g = (x - position(kind, UVec3::ZERO)).clamp(Vec3::ZERO, (e - UVec3::ONE).as_vec3());
    let base = g.floor().as_uvec3().min(e - UVec3::ONE);
    blend(q, e, base, g - base.as_vec3())
}

/// The trilinear blend of `q` (extent `e`) from the lower corner `base` and
/// the fractions `f` (`sample_bounded`'s arithmetic); also the least and
/// greatest of the eight values.
#[inline(always)]
fn blend(q: &[f32], e: UVec3, base: UVec3, f: Vec3) -> (f32, f32, f32) {
    // The eight corners from one base index and three strides (zero
    // where the upper corner is clamped onto the lower): the same elements
    // as `index` of each corner, a third of the address arithmetic.
    let hi = (base + UVec3::ONE).min(e - UVec3::ONE);
    let at = index(e, base.x, base.y, base.z);
    let dx = (hi.x - base.x) as usize;
    let dy = ((hi.y - base.y) * e.x) as usize;
    let dz = ((hi.z - base.z) * e.x * e.y) as usize;
    let q000 = q[at];
    let q100 = q[at + dx];
    let q010 = q[at + dy];
    let q110 = q[at + dx + dy];
    let q001 = q[at + dz];
    let q101 = q[at + dx + dz];
    let q011 = q[at + dy + dz];
    let q111 = q[at + dx + dy + dz];
    let a = q000 + (q100 - q000) * f.x;
    let b = q010 + (q110 - q010) * f.x;
    let c = q001 + (q101 - q001) * f.x;
    let d = q011 + (q111 - q011) * f.x;
    let ab = a + (b - a) * f.y;
    let cd = c + (d - c) * f.y;
    let lo = q000.min(q100).min(q010).min(q110).min(q001).min(q101).min(q011).min(q111);
    let hi_v = q000.max(q100).max(q010).max(q110).max(q001).max(q101).max(q011).max(q111);
    (ab + (cd - ab) * f.z, lo, hi_v)
}

/// `sample_bounded`'s value alone.
#[inline(always)]
pub fn sample(p: &FluidParams, kind: u32, q: &[f32], x: Vec3) -> f32 {
    sample_bounded(p, kind, q, x).0
}

/// The velocity's three arrays (m/s on the faces).
#[derive(Copy, Clone)]
pub struct Velocity<'a> {
    pub u: &'a [f32],
    pub v: &'a [f32],
    pub w: &'a [f32],
}

/// The velocity (m/s) at `x` (cells).
#[inline]
pub fn velocity_at(p: &FluidParams, vel: Velocity, x: Vec3) -> Vec3 {
    Vec3::new(sample(p, KIND_U, vel.u, x), sample(p, KIND_V, vel.v, x), sample(p, KIND_W, vel.w, x))
}

/// Along one axis, the lower corner and the fraction at which
/// `sample_bounded` reads an array of extent `e` (its elements `array_half`
/// a half cell into their cells along the axis, else on the cell faces) at
/// the element `c` of another array (`element_half` likewise): its clamp
/// and floor for a point on the grid, in integers.
#[inline(always)]
fn grid_axis(c: u32, element_half: bool, array_half: bool, e: u32) -> (u32, f32) {
    if element_half == array_half {
        // The same offset: on an element of the array.
        (c.min(e - 1), 0.0)
    } else if element_half {
        // c + 1/2 on a face array (one longer): between c and c + 1.
        (c, 0.5)
    } else if c == 0 {
        // c - 1/2 on a centred array: clamped onto its first element,
        (0, 0.0)
    } else if c >= e {
        // or its last,
        (e - 1, 0.0)
    } else {
        // else between c - 1 and c.
        (c - 1, 0.5)
    }
}

/// Whether elements of `kind` sit a half cell into their cells along each axis.
#[inline(always)]
fn half_offsets(kind: u32) -> [bool; 3] {
    [kind != KIND_U, kind != KIND_V, kind != KIND_W]
}

/// `velocity_at` at element `c` of `kind` (m/s), the same values: the
/// lookups' corners and fractions worked out in integers (a back-trace's
/// first stage starts on the grid).
#[inline]
pub fn velocity_at_element(p: &FluidParams, vel: Velocity, kind: u32, c: UVec3) -> Vec3 {
    let at = half_offsets(kind);
    let component = |array: u32, q: &[f32]| {
        let e = extent(p, array);
        let half = half_offsets(array);
        let (bx, fx) = grid_axis(c.x, at[0], half[0], e.x);
        let (by, fy) = grid_axis(c.y, at[1], half[1], e.y);
        let (bz, fz) = grid_axis(c.z, at[2], half[2], e.z);
        blend(q, e, UVec3::new(bx, by, bz), Vec3::new(fx, fy, fz)).0
    };
    Vec3::new(component(KIND_U, vel.u), component(KIND_V, vel.v), component(KIND_W, vel.w))
}

/// `trace` from element `c` of `kind` (cells), the same point.
#[inline]
pub fn trace_element(p: &FluidParams, vel: Velocity, kind: u32, c: UVec3, direction: f32) -> Vec3 {
    let x = position(kind, c);
    let s = direction * p.dt / p.h;
    let v1 = velocity_at_element(p, vel, kind, c);
    let mid = x - 0.5 * s * v1;
    let v2 = velocity_at(p, vel, mid);
    x - s * v2
}

/// Where the fluid at `x` (cells) was `dt` ago (`direction` 1) or will be
/// `dt` on (`direction` -1): the explicit midpoint rule (RK2) through the
/// velocity field, in cells.
pub fn trace(p: &FluidParams, vel: Velocity, x: Vec3, direction: f32) -> Vec3 {
    let s = direction * p.dt / p.h;
    let v1 = velocity_at(p, vel, x);
    let mid = x - 0.5 * s * v1;
    let v2 = velocity_at(p, vel, mid);
    x - s * v2
}

/// Semi-Lagrangian advection (Stam 1999), the convective terms of eq. 4
/// and 5: element `flat` of `q` (an array of `kind`) after the step, the
/// value found where its fluid came from (`direction` 1; -1: the reverse
/// step, MacCormack's back-and-forth).
pub fn advect(p: &FluidParams, kind: u32, flat: u32, q: &[f32], vel: Velocity, direction: f32) -> f32 {
    sample(p, kind, q, trace_element(p, vel, kind, coords(extent(p, kind), flat), direction))
}

/// Where the fluid at element `flat` of `kind` was `dt` ago (cells): the
/// point `advect` samples (kept for MacCormack's limiter rather than
/// traced twice).
pub fn departure(p: &FluidParams, kind: u32, flat: u32, vel: Velocity) -> Vec3 {
    trace_element(p, vel, kind, coords(extent(p, kind), flat), 1.0)
}

/// MacCormack's correction (Selle, Fedkiw, Kim, Liu and Rossignac 2008) of
/// element `flat`: `forward` (one semi-Lagrangian step of `q`) plus half
/// the error `q - back` that the reverse step of `forward` (`back`) shows,
/// clamped to the values the forward step blended at its departure point
/// `from` (`departure`), so no new extrema appear.
pub fn maccormack_from(
    p: &FluidParams,
    kind: u32,
    flat: u32,
    q: &[f32],
    forward: &[f32],
    back: &[f32],
    from: Vec3,
) -> f32 {
    let i = flat as usize;
    limited(forward[i] + 0.5 * (q[i] - back[i]), forward[i], sample_bounded(p, kind, q, from))
}

/// `advect` of the two cell-centred quantities, temperature and smoke,
/// which share their back-trace: `(T, s)` after the step.
pub fn advect_centres(p: &FluidParams, flat: u32, t: &[f32], s: &[f32], vel: Velocity, direction: f32) -> (f32, f32) {
    let b = trace_element(p, vel, KIND_TEMPERATURE, coords(p.dims(), flat), direction);
    (sample(p, KIND_TEMPERATURE, t, b), sample(p, KIND_SMOKE, s, b))
}

/// A cell-centred quantity's three arrays in MacCormack's step: before,
/// after the forward step, and after the reverse of that.
#[derive(Copy, Clone)]
pub struct Stages<'a> {
    pub q: &'a [f32],
    pub forward: &'a [f32],
    pub back: &'a [f32],
}

/// `maccormack_from` of temperature and smoke at cell `flat`, which share
/// their departure point `b`.
pub fn maccormack_centres_from(p: &FluidParams, flat: u32, t: Stages, s: Stages, b: Vec3) -> (f32, f32) {
    (
        maccormack_from(p, KIND_TEMPERATURE, flat, t.q, t.forward, t.back, b),
        maccormack_from(p, KIND_SMOKE, flat, s.q, s.forward, s.back, b),
    )
}

/// MacCormack's limiter: the corrected value if it lies within the values
/// the forward step blended (`bounds`: value, least, greatest), else the
/// forward step's.
fn limited(corrected: f32, forward: f32, bounds: (f32, f32, f32)) -> f32 {
    if corrected < bounds.1 || corrected > bounds.2 {
        forward
    } else {
        corrected
    }
}

/// A uniform number in [-1, 1) from the hash of (element, step, seed, stream).
fn signed_uniform(element: u32, step: u32, seed: u32, stream: u32) -> f32 {
    (random(element, step, seed, stream) >> 8) as f32 * (2.0 / 16_777_216.0) - 1.0
}

/// A face's velocity after the step's forces (m/s): eq. 4's buoyancy
/// `F_bv = g (T - T_a) / T_a` on the vertical faces, `T` the mean of the
/// two cells either side (the one inside at the box's faces), and the
/// random acceleration `turbulence * U(-1, 1)` of the Reynolds equations'
/// random components, per face, component and step.
pub fn force_face(p: &FluidParams, kind: u32, flat: u32, q: f32, temperature: &[f32]) -> f32 {
    let mut a = p.turbulence * signed_uniform(flat, p.step, p.seed, STREAM_TURBULENCE + kind);
    if kind == KIND_V {
        let n = p.dims();
        let c = coords(extent(p, kind), flat);
        let below = if c.y > 0 { c.y - 1 } else { 0 };
        let above = if c.y < n.y { c.y } else { n.y - 1 };
        let t = 0.5 * (temperature[index(n, c.x, below, c.z)] + temperature[index(n, c.x, above, c.z)]);
        a += p.gravity * (t - p.ambient) / p.ambient;
    }
    q + p.dt * a
}

/// One Jacobi iteration of backward-Euler diffusion, `(1 - weight lap) x =
/// b` (`weight = kappa dt / h^2`): element `flat`'s new value from its
/// neighbours in `x` (insulating at the array's ends: free slip for the
/// tangential velocity). A closed face's velocity stays 0 (no flow through
/// a wall or a solid). Each iterate is a weighted mean of `b` and
/// neighbours, so no weight makes it grow.
pub fn diffuse(p: &FluidParams, kind: u32, flat: u32, b: &[f32], x: &[f32], weight: f32, fluid: &[u32]) -> f32 {
    if kind <= KIND_W && face_open(p, kind, flat, fluid) == 0 {
        return 0.0;
    }
    let e = extent(p, kind);
    let c = coords(e, flat);
    let mut sum = 0.0;
    let mut count = 0.0;
    if c.x > 0 {
        sum += x[index(e, c.x - 1, c.y, c.z)];
        count += 1.0;
    }
    if c.x + 1 < e.x {
        sum += x[index(e, c.x + 1, c.y, c.z)];
        count += 1.0;
    }
    if c.y > 0 {
        sum += x[index(e, c.x, c.y - 1, c.z)];
        count += 1.0;
    }
    if c.y + 1 < e.y {
        sum += x[index(e, c.x, c.y + 1, c.z)];
        count += 1.0;
    }
    if c.z > 0 {
        sum += x[index(e, c.x, c.y, c.z - 1)];
        count += 1.0;
    }
    if c.z + 1 < e.z {
        sum += x[index(e, c.x, c.y, c.z + 1)];
        count += 1.0;
    }
    (b[flat as usize] + weight * sum) / (1.0 + weight * count)
}

/// Eq. 5's eddy term at cell `flat`: `dt alpha_t lap T'` (K), `T'` the
/// random temperature component drawn per cell and step, its Laplacian
/// over the six neighbours inside the box.
pub fn temperature_eddy(p: &FluidParams, flat: u32) -> f32 {
    if p.temperature_noise == 0.0 || p.eddy_diffusivity == 0.0 {
        return 0.0;
    }
    let n = p.dims();
    let c = coords(n, flat);
    let centre = temperature_component(p, n, c.x, c.y, c.z);
    let mut lap = 0.0;
    if c.x > 0 {
        lap += temperature_component(p, n, c.x - 1, c.y, c.z) - centre;
    }
    if c.x + 1 < n.x {
        lap += temperature_component(p, n, c.x + 1, c.y, c.z) - centre;
    }
    if c.y > 0 {
        lap += temperature_component(p, n, c.x, c.y - 1, c.z) - centre;
    }
    if c.y + 1 < n.y {
        lap += temperature_component(p, n, c.x, c.y + 1, c.z) - centre;
    }
    if c.z > 0 {
        lap += temperature_component(p, n, c.x, c.y, c.z - 1) - centre;
    }
    if c.z + 1 < n.z {
        lap += temperature_component(p, n, c.x, c.y, c.z + 1) - centre;
    }
    p.dt * p.eddy_diffusivity * lap / (p.h * p.h)
}

/// The random temperature component `T'` (K) of cell `(i, j, k)` at this step.
fn temperature_component(p: &FluidParams, n: UVec3, i: u32, j: u32, k: u32) -> f32 {
    p.temperature_noise * signed_uniform(index(n, i, j, k) as u32, p.step, p.seed, STREAM_TEMPERATURE)
}

/// Whether cell `(i, j, k)` (signed: -1 and `n` are outside) of a grid of
/// `n` cells with flags `fluid` (1 fluid, 0 solid) is fluid (1), solid or
/// beyond a wall (0), or beyond an open face (2).
fn neighbour(n: UVec3, walls: u32, fluid: &[u32], i: i32, j: i32, k: i32) -> u32 {
    let beyond = |c: i32, size: u32, lo_bit: u32, hi_bit: u32| -> u32 {
        if c < 0 {
            if walls & lo_bit != 0 {
                0
            } else {
                2
            }
        } else if c >= size as i32 {
            if walls & hi_bit != 0 {
                0
            } else {
                2
            }
        } else {
            1
        }
    };
    let bx = beyond(i, n.x, WALL_X_LO, WALL_X_HI);
    let by = beyond(j, n.y, WALL_Y_LO, WALL_Y_HI);
    let bz = beyond(k, n.z, WALL_Z_LO, WALL_Z_HI);
    if bx != 1 {
        return bx;
    }
    if by != 1 {
        return by;
    }
    if bz != 1 {
        return bz;
    }
    fluid[index(n, i as u32, j as u32, k as u32)]
}

/// Whether face `flat` of `kind` (a velocity component) lets fluid through:
/// 0 on a wall or beside a solid cell, 1 between fluid cells or at an open
/// face of the box.
pub fn face_open(p: &FluidParams, kind: u32, flat: u32, fluid: &[u32]) -> u32 {
    let n = p.dims();
    let c = coords(extent(p, kind), flat);
    let (i, j, k) = (c.x as i32, c.y as i32, c.z as i32);
    let (a, b) = if kind == KIND_U {
        (neighbour(n, p.walls, fluid, i - 1, j, k), neighbour(n, p.walls, fluid, i, j, k))
    } else if kind == KIND_V {
        (neighbour(n, p.walls, fluid, i, j - 1, k), neighbour(n, p.walls, fluid, i, j, k))
    } else {
        (neighbour(n, p.walls, fluid, i, j, k - 1), neighbour(n, p.walls, fluid, i, j, k))
    };
    (a != 0 && b != 0) as u32
}

/// The divergence of the velocity at cell `flat`, times `h` (m/s): the net
/// outflow through its six faces. 0 in a solid cell.
pub fn divergence(p: &FluidParams, flat: u32, vel: Velocity, fluid: &[u32]) -> f32 {
    if fluid[flat as usize] == 0 {
        return 0.0;
    }
    let c = coords(p.dims(), flat);
    let eu = extent(p, KIND_U);
    let ev = extent(p, KIND_V);
    let ew = extent(p, KIND_W);
    (vel.u[index(eu, c.x + 1, c.y, c.z)] - vel.u[index(eu, c.x, c.y, c.z)])
        + (vel.v[index(ev, c.x, c.y + 1, c.z)] - vel.v[index(ev, c.x, c.y, c.z)])
        + (vel.w[index(ew, c.x, c.y, c.z + 1)] - vel.w[index(ew, c.x, c.y, c.z)])
}

/// Bits of a cell's `stencil`: which of its six neighbours (-x, +x, -y,
/// +y, -z, +z: bits 0 to 5) are fluid; the diagonal of `A` (its neighbours
/// that are fluid or beyond an open face, where `phi = 0`) in bits 8 to 11;
/// whether the cell is fluid; its red-black colour.
pub const STENCIL_FLUID: u32 = 1 << 12;
pub const STENCIL_COLOUR: u32 = 1 << 13;

/// Cell `flat`'s stencil (see `STENCIL_FLUID`) on a grid of `n` cells with
/// flags `fluid` and walls `walls`: computed once per grid, so the
/// solver's sweeps read one word instead of testing six neighbours.
pub fn stencil(n: UVec3, walls: u32, fluid: &[u32], flat: u32) -> u32 {
    let c = coords(n, flat);
    let (i, j, k) = (c.x as i32, c.y as i32, c.z as i32);
    let mut bits = ((c.x + c.y + c.z) & 1) * STENCIL_COLOUR;
    if fluid[flat as usize] == 0 {
        return bits;
    }
    bits |= STENCIL_FLUID;
    let mut diagonal = 0;
    let mut o = 0;
    while o < 6 {
        let sign = if o & 1 == 0 { -1 } else { 1 };
        let (di, dj, dk) = if o < 2 {
            (sign, 0, 0)
        } else if o < 4 {
            (0, sign, 0)
        } else {
            (0, 0, sign)
        };
        let kind = neighbour(n, walls, fluid, i + di, j + dj, k + dk);
        if kind == 1 {
            bits |= 1 << o;
        }
        if kind != 0 {
            diagonal += 1;
        }
        o += 1;
    }
    bits | (diagonal << 8)
}

/// A field of cell values read by index: a slice; on the CPU also cells
/// that other threads write at other indices (`gauss_seidel`'s in-place
/// sweep, where a colour's cells read only the other colour's).
pub trait Cells {
    fn cell(&self, i: usize) -> f32;
}

impl Cells for [f32] {
    #[inline(always)]
    fn cell(&self, i: usize) -> f32 {
        self[i]
    }
}

/// f32 bits in atomics (relaxed loads: plain loads on x86-64).
#[cfg(not(target_arch = "spirv"))]
impl Cells for [core::sync::atomic::AtomicU32] {
    #[inline(always)]
    fn cell(&self, i: usize) -> f32 {
        f32::from_bits(self[i].load(core::sync::atomic::Ordering::Relaxed))
    }
}

/// The sum of `x` over the fluid neighbours a stencil lists.
#[inline(always)]
fn stencil_sum<X: Cells + ?Sized>(n: UVec3, bits: u32, x: &X, flat: u32) -> f32 {
    let i = flat as usize;
    let (sy, sz) = (n.x as usize, (n.x * n.y) as usize);
    let mut sum = 0.0;
    if bits & 1 != 0 {
        sum += x.cell(i - 1);
    }
    if bits & 2 != 0 {
        sum += x.cell(i + 1);
    }
    if bits & 4 != 0 {
        sum += x.cell(i - sy);
    }
    if bits & 8 != 0 {
        sum += x.cell(i + sy);
    }
    if bits & 16 != 0 {
        sum += x.cell(i - sz);
    }
    if bits & 32 != 0 {
        sum += x.cell(i + sz);
    }
    sum
}

/// `(A x)` at cell `flat` of a grid of `n` cells with `stencils`: `A` is
/// `-h^2` times the 7-point Laplacian over the fluid cells (Neumann at
/// walls and solids, `phi = 0` beyond open faces); 0 in solid cells.
pub fn apply_poisson(n: UVec3, stencils: &[u32], x: &[f32], flat: u32) -> f32 {
    let bits = stencils[flat as usize];
    if bits & STENCIL_FLUID == 0 {
        return 0.0;
    }
    ((bits >> 8) & 15) as f32 * x[flat as usize] - stencil_sum(n, bits, x, flat)
}

/// One Gauss-Seidel update of cell `flat` for `A x = b` if its colour
/// (`(i + j + k) mod 2`) is `colour`; its value unchanged otherwise. Cells
/// of one colour have neighbours of the other only, so a colour's cells
/// may be updated in any order (in parallel).
pub fn gauss_seidel<X: Cells + ?Sized>(n: UVec3, stencils: &[u32], b: &[f32], x: &X, flat: u32, colour: u32) -> f32 {
    let i = flat as usize;
    let bits = stencils[i];
    if ((bits & STENCIL_COLOUR) != 0) as u32 != colour {
        return x.cell(i);
    }
    let diagonal = ((bits >> 8) & 15) as f32;
    if bits & STENCIL_FLUID == 0 || diagonal == 0.0 {
        return 0.0;
    }
    (b[i] + stencil_sum(n, bits, x, flat)) / diagonal
}

/// Red-black Gauss-Seidel, one colour in place: each cell `lane, lane +
/// lanes, ...` of colour `colour` takes its `gauss_seidel` update in `x`
/// itself; the other colour's cells are not written. A colour's cells read
/// only the other colour's, so every split of them among lanes, in any
/// order, gives exactly the values the sweep into a second array gives.
pub fn gauss_seidel_in_place(n: UVec3, stencils: &[u32], b: &[f32], x: &mut [f32], lane: u32, lanes: u32, colour: u32) {
    let cells = n.x * n.y * n.z;
    let mut i = lane;
    while i < cells {
        if ((stencils[i as usize] & STENCIL_COLOUR) != 0) as u32 == colour {
            let v = gauss_seidel(n, stencils, b, x, i, colour);
            x[i as usize] = v;
        }
        i += lanes;
    }
}

/// The multigrid's coarsest level (at most 4 cells a side: 64) is solved
/// by this many symmetric pairs of half-sweeps, colours 0 then 1, then as
/// many pairs in the reverse order (the V-cycle stays symmetric, as
/// conjugate gradients need).
pub const COARSE_SWEEPS: u32 = 16;
/// The coarse solve's half-sweeps in all.
pub const COARSE_HALF_SWEEPS: u32 = 4 * COARSE_SWEEPS;
/// Invocations of the coarse solve's one workgroup.
pub const COARSE_LANES: u32 = 64;

/// The colour of half-sweep `k` of the coarse solve.
pub fn coarse_colour(k: u32) -> u32 {
    if k < 2 * COARSE_SWEEPS {
        k % 2
    } else {
        1 - k % 2
    }
}

/// The coarse solve, `x` from 0 (the caller clears it): every half-sweep
/// in order on one lane, as the CPU runs it (the GPU's workgroup splits
/// each half-sweep among `COARSE_LANES` with a barrier between them, and
/// gets the same values).
pub fn coarse_solve(n: UVec3, stencils: &[u32], b: &[f32], x: &mut [f32]) {
    let mut k = 0;
    while k < COARSE_HALF_SWEEPS {
        gauss_seidel_in_place(n, stencils, b, x, 0, 1, coarse_colour(k));
        k += 1;
    }
}

/// The cells of the next coarser multigrid level: `ceil(n / 2)` per axis.
pub fn coarser(n: UVec3) -> UVec3 {
    (n + UVec3::ONE) / 2
}

/// The index of child `n` (0..8: x, then y, then z offsets of 0 or 1) of
/// coarse cell `flat` on the fine grid of `fine` cells, or `NO_CHILD` where
/// an odd fine size leaves the coarse cell without it.
pub fn child(fine: UVec3, flat: u32, n: u32) -> u32 {
    let c = coords(coarser(fine), flat) * 2 + UVec3::new(n & 1, (n >> 1) & 1, n >> 2);
    if c.x < fine.x && c.y < fine.y && c.z < fine.z {
        index(fine, c.x, c.y, c.z) as u32
    } else {
        NO_CHILD
    }
}

/// See `child`.
pub const NO_CHILD: u32 = u32::MAX;

/// A coarse cell is fluid if any of its (up to eight) children is.
pub fn coarse_fluid(fine: UVec3, fluid: &[u32], flat: u32) -> u32 {
    let mut any = 0;
    let mut n = 0;
    while n < 8 {
        let c = child(fine, flat, n);
        if c != NO_CHILD {
            any |= fluid[c as usize];
        }
        n += 1;
    }
    any
}

/// The restriction of a fine residual `r` to coarse cell `flat`: half the
/// sum over its children (the average, times `(2h)^2 / h^2 = 4`, since `A`
/// carries `h^2`).
pub fn restrict(fine: UVec3, r: &[f32], flat: u32) -> f32 {
    let mut sum = 0.0;
    let mut n = 0;
    while n < 8 {
        let c = child(fine, flat, n);
        if c != NO_CHILD {
            sum += r[c as usize];
        }
        n += 1;
    }
    0.5 * sum
}

/// Fine cell `flat`'s value after adding the coarse correction `e` of its
/// parent (piecewise-constant prolongation, the transpose of `restrict` up
/// to a constant, so the V-cycle is symmetric); solid cells stay 0.
pub fn prolong(fine: UVec3, fluid: &[u32], x: &[f32], e: &[f32], flat: u32) -> f32 {
    let i = flat as usize;
    if fluid[i] == 0 {
        return 0.0;
    }
    let c = coords(fine, flat) / 2;
    x[i] + e[index(coarser(fine), c.x, c.y, c.z)]
}

/// A face's velocity after the projection: `u - (phi_b - phi_a) / h`, the
/// pressure term of eq. 4 (`phi = p dt / rho`, m^2/s, from `A phi = -h D`,
/// `D` the cell's `divergence`), `phi = 0` beyond an open face; closed
/// faces (walls, solids) 0.
pub fn project_face(p: &FluidParams, kind: u32, flat: u32, q: f32, phi: &[f32], fluid: &[u32]) -> f32 {
    if face_open(p, kind, flat, fluid) == 0 {
        return 0.0;
    }
    let n = p.dims();
    let c = coords(extent(p, kind), flat);
    let axis_size = if kind == KIND_U {
        n.x
    } else if kind == KIND_V {
        n.y
    } else {
        n.z
    };
    let along = if kind == KIND_U {
        c.x
    } else if kind == KIND_V {
        c.y
    } else {
        c.z
    };
    let step = if kind == KIND_U {
        UVec3::X
    } else if kind == KIND_V {
        UVec3::Y
    } else {
        UVec3::Z
    };
    let before = if along > 0 {
        let b = c - step;
        phi[index(n, b.x, b.y, b.z)]
    } else {
        0.0
    };
    let after = if along < axis_size { phi[index(n, c.x, c.y, c.z)] } else { 0.0 };
    q - (after - before) / p.h
}

/// Elements of a vector per partial sum (`partial`): one invocation sums
/// them in order, so both backends add in the same order and the host adds
/// the partials in f64.
pub const PARTIAL_SPAN: u32 = 256;

/// The partial reductions of elements `group * PARTIAL_SPAN ..` (up to
/// `count`) of `a` and `b`: `(sum a b, max |a|, sum a, count)`, the last two
/// over the cells `fluid` marks (when `fluid` is given: the mean the
/// singular case removes) or over all elements. The conjugate gradients'
/// dot products, its stopping test's `max |r|` and the measured speed and
/// divergence are these summed over groups.
pub fn partial(a: &[f32], b: &[f32], fluid: &[u32], use_fluid: bool, count: u32, group: u32) -> crate::glam::Vec4 {
    let start = group * PARTIAL_SPAN;
    let end = if start + PARTIAL_SPAN < count { start + PARTIAL_SPAN } else { count };
    let (mut dot, mut max, mut sum, mut n) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut i = start;
    while i < end {
        let x = a[i as usize];
        dot += x * b[i as usize];
        let m = x.abs();
        if m > max {
            max = m;
        }
        if !use_fluid || fluid[i as usize] != 0 {
            sum += x;
            n += 1.0;
        }
        i += 1;
    }
    crate::glam::Vec4::new(dot, max, sum, n)
}

/// The partial groups of a vector of `count` elements.
pub fn partial_groups(count: u32) -> u32 {
    count.div_ceil(PARTIAL_SPAN)
}

/// One conjugate-gradient update of element `i`: `phi + alpha p` and
/// `r - alpha A p`.
pub fn cg_update(phi: f32, r: f32, p: f32, ap: f32, alpha: f32) -> (f32, f32) {
    (phi + alpha * p, r - alpha * ap)
}

/// The next search direction's element: `z + beta p`.
pub fn cg_direction(z: f32, p: f32, beta: f32) -> f32 {
    z + beta * p
}

/// A fluid cell's value less the mean over the fluid cells (the singular
/// case's null space); solid cells keep theirs.
pub fn less_mean(x: f32, fluid: u32, mean: f32) -> f32 {
    if fluid != 0 {
        x - mean
    } else {
        x
    }
}

/// What a fluid kernel's dispatch needs besides the fluid's parameters:
/// which quantity (`KIND_*`), the red-black colour, the advection's
/// direction, a scalar (a diffusion weight, a conjugate-gradient `alpha` or
/// `beta`, a mean), a multigrid level's cells, and the invocations.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct FluidDispatch {
    pub fluid: FluidParams,
    pub kind: u32,
    pub colour: u32,
    pub direction: f32,
    pub scalar: f32,
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub count: u32,
}

#[cfg(not(target_arch = "spirv"))]
mod dispatch_pod {
    // SAFETY: `repr(C)` of 4-byte scalars and `FluidParams` (the same), no padding.
    unsafe impl bytemuck::Zeroable for super::FluidDispatch {}
    unsafe impl bytemuck::Pod for super::FluidDispatch {}
}

impl FluidDispatch {
    /// The multigrid level's cells.
    pub fn level(&self) -> UVec3 {
        UVec3::new(self.nx, self.ny, self.nz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(n: [u32; 3]) -> FluidParams {
        FluidParams {
            nx: n[0],
            ny: n[1],
            nz: n[2],
            cells: n[0] * n[1] * n[2],
            h: 0.5,
            dt: 0.1,
            walls: 63,
            gravity: 9.81,
            ambient: 300.0,
            ..Default::default()
        }
    }

    #[test]
    fn the_velocity_at_an_element_is_the_lookup_there_bit_for_bit() {
        // Every element of every kind on boxes with one-cell axes, open
        // faces and walls, a velocity with no pattern: the integer corners
        // and fractions give the lookup's values to the bit.
        for (n, walls) in [([4, 5, 3], 63), ([3, 1, 2], 0), ([1, 1, 1], 21), ([6, 2, 1], 42)] {
            let p = FluidParams { walls, ..params(n) };
            let field = |kind: u32, salt: u32| -> Vec<f32> {
                let e = extent(&p, kind);
                (0..e.x * e.y * e.z).map(|i| signed_uniform(i, salt, 7, kind) * 3.0).collect()
            };
            let (u, v, w) = (field(KIND_U, 1), field(KIND_V, 2), field(KIND_W, 3));
            let vel = Velocity { u: &u, v: &v, w: &w };
            for kind in [KIND_U, KIND_V, KIND_W, KIND_TEMPERATURE] {
                let e = extent(&p, kind);
                for flat in 0..e.x * e.y * e.z {
                    let c = coords(e, flat);
                    let fast = velocity_at_element(&p, vel, kind, c);
                    let slow = velocity_at(&p, vel, position(kind, c));
                    assert_eq!(
                        fast.to_array().map(f32::to_bits),
                        slow.to_array().map(f32::to_bits),
                        "{n:?} kind {kind} {c}"
                    );
                    let (a, b) = (trace_element(&p, vel, kind, c, -1.0), trace(&p, vel, position(kind, c), -1.0));
                    assert_eq!(a.to_array().map(f32::to_bits), b.to_array().map(f32::to_bits));
                }
            }
        }
    }

    #[test]
    fn sampling_a_linear_field_is_exact_inside_and_clamped_at_walls() {
        let p = params([4, 3, 5]);
        let e = extent(&p, KIND_U);
        let q: Vec<f32> = (0..e.x * e.y * e.z)
            .map(|f| {
                let x = position(KIND_U, coords(e, f));
                1.0 + 2.0 * x.x - x.y + 0.5 * x.z
            })
            .collect();
        let at = Vec3::new(1.3, 1.7, 2.2);
        let got = sample(&p, KIND_U, &q, at);
        assert!((got - (1.0 + 2.6 - 1.7 + 1.1)).abs() < 1e-5, "{got}");
        // Outside a wall: the value at the nearest point inside.
        let clamped = sample(&p, KIND_U, &q, Vec3::new(-3.0, 1.7, 2.2));
        assert!((clamped - (1.0 - 1.7 + 1.1)).abs() < 1e-5, "{clamped}");
    }

    #[test]
    fn open_faces_give_the_outside_air() {
        let mut p = params([4, 4, 4]);
        p.walls = WALL_Y_LO;
        p.wind_x = 3.0;
        let q = vec![0.0; 5 * 4 * 4];
        assert_eq!(sample(&p, KIND_U, &q, Vec3::new(-0.5, 2.0, 2.0)), 3.0);
        assert_eq!(sample(&p, KIND_TEMPERATURE, &[1.0; 64], Vec3::new(2.0, 5.0, 2.0)), 300.0);
        // Below the floor (a wall): clamped, not the outside.
        assert_eq!(sample(&p, KIND_SMOKE, &[1.0; 64], Vec3::new(2.0, -1.0, 2.0)), 1.0);
    }

    #[test]
    fn poisson_operator_is_symmetric_with_solids_and_open_faces() {
        let mut p = params([3, 4, 2]);
        p.walls = WALL_Y_LO | WALL_X_HI;
        let n = p.dims();
        let cells = p.cells as usize;
        let mut fluid = vec![1u32; cells];
        fluid[5] = 0;
        fluid[13] = 0;
        let unit = |i: usize| {
            let mut x = vec![0.0; cells];
            x[i] = 1.0;
            x
        };
        let st: Vec<u32> = (0..cells as u32).map(|i| stencil(n, p.walls, &fluid, i)).collect();
        for a in 0..cells {
            for b in 0..cells {
                let ab = apply_poisson(n, &st, &unit(b), a as u32);
                let ba = apply_poisson(n, &st, &unit(a), b as u32);
                assert_eq!(ab, ba, "A[{a}][{b}]");
            }
        }
    }

    #[test]
    fn buoyancy_lifts_hot_air_and_sinks_cold() {
        let p = params([1, 2, 1]);
        let hot = [600.0, 600.0];
        let cold = [150.0, 150.0];
        // The face between the two cells.
        let up = force_face(&p, KIND_V, 1, 0.0, &hot);
        let down = force_face(&p, KIND_V, 1, 0.0, &cold);
        assert!((up - 0.1 * 9.81).abs() < 1e-6, "{up}");
        assert!((down + 0.1 * 9.81 * 0.5).abs() < 1e-6, "{down}");
    }
}
