//! Heterogeneous media: local volumes, each a medium inside its own box
//! whose density is a field (metaballs, after Dobashi et al. 2000, the
//! survey's section 3), rendered by slice accumulation over sample planes
//! parallel to the screen, with the lights' attenuation through the
//! volumes from a transmittance volume per light (the shadow test of eq. 2
//! of the 2002 shafts paper, generalised from a depth to an optical depth).
//!
//! Three kernels, each a pure per-invocation function and a thin entry point:
//! - `density_cell`: the density grid of every volume, the metaballs' field
//!   summed at each cell centre (eq. of Wyvill's field function, `field`);
//! - `optical_depth_column`: per light, a grid over the volumes in the
//!   light's space (the sun's orthographic, a spot's perspective), each
//!   column one light ray marched through the density grids, storing the
//!   optical depth from where the light enters the volumes at every node;
//! - `volumes_pixel`: per pixel, the planes' intervals front to back,
//!   carrying the view transmittance and adding each interval's
//!   in-scattered light in the energy-conserving form
//!   `S (1 - exp(-sigma_t dt)) / sigma_t` (exact for a constant `S` and
//!   `sigma_t` over the interval).
//!
//! Units: lengths in metres, `sigma_*` in 1/m per unit density, densities
//! dimensionless, radiance in W/(m^2 sr).

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::camera::camera_ray;
use crate::geometry::box_span;
use crate::glam::{UVec3, Vec3, Vec4, Vec4Swizzles};
use crate::light::{emitted_visible, light_local};
use crate::phase;
use crate::types::{CommonParams, GBufferTexel, GpuLight, LIGHT_DIRECTIONAL, LIGHT_SPOT};
use spirv_std::spirv;

pub mod automaton;
pub mod splat;
use automaton::{lattice_density, AutomatonParams};

/// `GpuVolume::phase_kind` for the two-lobe Henyey-Greenstein function
/// `w HG(g1) + (1 - w) HG(g2)` (the other kinds are `types::PHASE_*`).
pub const PHASE_DOUBLE_HENYEY_GREENSTEIN: u32 = 16;

/// One volume: its box, its coefficients per unit density, its phase
/// function, and where its density grid and metaball bins lie.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuVolume {
    /// The box's corners, metres (w unused).
    pub min: Vec4,
    pub max: Vec4,
    /// Scattering and extinction coefficients per unit density, 1/m (rgb).
    pub sigma_s: Vec4,
    pub sigma_t: Vec4,
    /// `types::PHASE_*` or `PHASE_DOUBLE_HENYEY_GREENSTEIN`.
    pub phase_kind: u32,
    /// Henyey-Greenstein asymmetry (the first lobe's), the second lobe's,
    /// and the first lobe's weight.
    pub g1: f32,
    pub g2: f32,
    pub weight: f32,
    /// Density grid cells along x, y, z (cell-centred samples).
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    /// Index of the volume's first cell in the density buffer.
    pub density_offset: u32,
    /// Metaball bins along x, y, z over the box, and the index in the bin
    /// buffer of the volume's `bx * by * bz + 1` bin starts.
    pub bins_x: u32,
    pub bins_y: u32,
    pub bins_z: u32,
    pub bin_offset: u32,
}

impl GpuVolume {
    /// Whether the volume's density is a grid from a file: such a volume
    /// has no metaball bins (`bins_x == 0`) and its values start at
    /// `bin_offset` in the grid buffer.
    pub fn is_file_grid(&self) -> bool {
        self.bins_x == 0
    }
}

/// A metaball: centre (m) and radius `R` (m) in `center_radius`, weight `q`
/// (density at the centre) in `q.x`.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuMetaball {
    pub center_radius: Vec4,
    pub q: Vec4,
}

/// A light's transmittance volume: `nu x nv x nz` nodes over `[lo, hi]` in
/// the light's space (directional: the light frame's x, y and the distance
/// z past its entry plane; spot: `x / z`, `y / z` and z along its axis),
/// holding the optical depth (rgb) from `lo.z` to the node along the
/// light's ray. `nu = 0`: the light has none (it never reaches a volume).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct LightGrid {
    pub lo: Vec4,
    pub hi: Vec4,
    pub nu: u32,
    pub nv: u32,
    pub nz: u32,
    /// Index of the first node in the optical-depth buffer (z fastest, then
    /// u, then v: a column's nodes are contiguous).
    pub offset: u32,
}

/// The volumes pass's parameter block.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct VolumesParams {
    pub volume_count: u32,
    /// Sample planes across `[depth_near, depth_far]`, the depth range
    /// (along the view direction, metres) of the volumes' boxes in view.
    pub plane_count: u32,
    pub depth_near: f32,
    pub depth_far: f32,
    /// Density cells in all volumes together (the density kernel's invocations).
    pub cell_count: u32,
    /// Light-grid columns in all lights together (the optical-depth kernel's).
    pub column_count: u32,
    /// Midpoint sub-steps per node interval of a light-grid column.
    pub column_substeps: u32,
    /// Scattering octaves (1: single scattering; more: Wrenninge's
    /// approximation of multiple scattering, `in_scattered`).
    pub octaves: u32,
    /// Per octave, the factors on the scattering coefficient (`a`), on the
    /// light's optical depth (`b`) and on the phase functions' asymmetry
    /// (`c`), each in (0, 1].
    pub octave_scattering: f32,
    pub octave_extinction: f32,
    pub octave_phase: f32,
    /// 1: multiple scattering by delta-Eddington columns (`column_light`,
    /// the default; `octaves` is then 1); 0: by the octaves where
    /// `octaves > 1`, else single scattering.
    pub columns: u32,
    /// `column_light`'s lateral extent of the medium around a light
    /// column, as a multiple of the column's scaled optical depth
    /// (dimensionless).
    pub column_width: f32,
    /// With the columns on the slices: the radius of the ring their diffuse
    /// light is averaged over across the light's travel, as a multiple of
    /// `sqrt(H d)`, `H` the light ray's length inside the volumes and `d`
    /// the node's depth along it (`diffuse_node`; 0: no ring, the lateral
    /// leakage by `column_width`'s buckling instead).
    pub column_spread: f32,
    /// The volume filled by the cloud automaton, plus one (0: none).
    pub automaton_volume: u32,
    /// `METHOD_SLICES` or `METHOD_SPLATTING` (`splat`): how every volume is drawn.
    pub method: u32,
    /// Metaballs in all volumes (the splatting kernels' balls).
    pub ball_count: u32,
    /// Splatting's screen tiles (`splat::TILE` pixels a side) across and
    /// down, and the most balls a tile lists (`splat::splat_tile`).
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub tile_capacity: u32,
}

impl VolumesParams {
    /// Whether the volumes scatter light more than once (the columns or
    /// the octaves): what the reference's Monte Carlo mode follows.
    pub fn all_orders(&self) -> bool {
        self.columns != 0 || self.octaves > 1
    }
}

/// `VolumesParams::method`: the slice renderer (`volumes_pixel`).
pub const METHOD_SLICES: u32 = 0;
/// `VolumesParams::method`: Dobashi et al. 2000's splatting (`splat`).
pub const METHOD_SPLATTING: u32 = 1;

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: `repr(C)` structs of 4-byte scalars and `Vec4`s whose sizes
    // are multiples of 16 (no padding); any bits are valid.
    unsafe impl bytemuck::Zeroable for super::GpuVolume {}
    unsafe impl bytemuck::Pod for super::GpuVolume {}
    unsafe impl bytemuck::Zeroable for super::GpuMetaball {}
    unsafe impl bytemuck::Pod for super::GpuMetaball {}
    unsafe impl bytemuck::Zeroable for super::LightGrid {}
    unsafe impl bytemuck::Pod for super::LightGrid {}
    unsafe impl bytemuck::Zeroable for super::VolumesParams {}
    unsafe impl bytemuck::Pod for super::VolumesParams {}
}

/// Wyvill's field function (Dobashi et al. 2000, eq. 1's `f`), the density
/// of a metaball of weight 1 at `a = r / R` (distance over radius,
/// dimensionless): `1 - 22/9 a^2 + 17/9 a^4 - 4/9 a^6` for `a < 1`, else 0.
/// It falls from 1 to 0 with zero slope at both ends; `a2` is `a^2`.
pub fn field(a2: f32) -> f32 {
    if a2 >= 1.0 {
        return 0.0;
    }
    1.0 + a2 * (-22.0 / 9.0 + a2 * (17.0 / 9.0 - a2 * (4.0 / 9.0)))
}

/// The volume's density at `p` from its metaballs: `sum_i q_i f(|p - c_i| / R_i)`
/// over the balls listed in the bin that holds `p` (every ball whose
/// sphere meets the bin is listed in it, so the sum is the whole field's).
pub fn metaball_density(v: &GpuVolume, balls: &[GpuMetaball], bins: &[u32], p: Vec3) -> f32 {
    let size = v.max.xyz() - v.min.xyz();
    let f = (p - v.min.xyz()) / size;
    let bx = ((f.x * v.bins_x as f32) as i32).clamp(0, v.bins_x as i32 - 1) as u32;
    let by = ((f.y * v.bins_y as f32) as i32).clamp(0, v.bins_y as i32 - 1) as u32;
    let bz = ((f.z * v.bins_z as f32) as i32).clamp(0, v.bins_z as i32 - 1) as u32;
    let bin = v.bin_offset + (bz * v.bins_y + by) * v.bins_x + bx;
    let (start, end) = (bins[bin as usize], bins[bin as usize + 1]);
    let mut sum = 0.0;
    let mut i = start;
    while i < end {
        let ball = &balls[bins[i as usize] as usize];
        let r = ball.center_radius.w;
        let a2 = (p - ball.center_radius.xyz()).length_squared() / (r * r);
        sum += ball.q.x * field(a2);
        i += 1;
    }
    sum
}

/// The volume among `volumes[..count]` whose cells hold cell `index` of the
/// density buffer, and the cell's index within it.
fn volume_of_cell(index: u32, volumes: &[GpuVolume], count: u32) -> (usize, u32) {
    let mut v = 0;
    while v + 1 < count as usize {
        let next = &volumes[v + 1];
        if index < next.density_offset {
            break;
        }
        v += 1;
    }
    (v, index - volumes[v].density_offset)
}

/// Density-grid kernel: the density at the centre of cell `index` (over all
/// volumes' grids in order; x fastest, then y, then z), the centre of cell
/// `(i, j, k)` being `min + (i + 0.5) / n * size` as Mitsuba places a
/// grid's samples.
///
/// The automaton's volume (`params.automaton_volume`) has the automaton's
/// lattice as its grid, and its density from `automaton::lattice_density`
/// (`smooth`: the automaton's weights per cell). A grid volume
/// (`GpuVolume::is_file_grid`) has its file's values, from `grid_values`
/// at `bin_offset`.
#[allow(clippy::too_many_arguments)]
pub fn density_cell(
    index: u32,
    params: &VolumesParams,
    volumes: &[GpuVolume],
    balls: &[GpuMetaball],
    bins: &[u32],
    automaton: &AutomatonParams,
    smooth: &[f32],
    grid_values: &[f32],
) -> f32 {
    let (v, cell) = volume_of_cell(index, volumes, params.volume_count);
    let vol = &volumes[v];
    if vol.is_file_grid() {
        // A grid from a file: its own values at its cell centres.
        return grid_values[(vol.bin_offset + cell) as usize];
    }
    let (i, j, k) = (cell % vol.nx, (cell / vol.nx) % vol.ny, cell / (vol.nx * vol.ny));
    let n = Vec3::new(vol.nx as f32, vol.ny as f32, vol.nz as f32);
    let f = (Vec3::new(i as f32, j as f32, k as f32) + Vec3::splat(0.5)) / n;
    let p = vol.min.xyz() + (vol.max.xyz() - vol.min.xyz()) * f;
    if params.automaton_volume == v as u32 + 1 {
        return lattice_density(vol, automaton, smooth, p, UVec3::new(i, j, k));
    }
    metaball_density(vol, balls, bins, p)
}

/// The density of volume `v` at `p` from its grid (`grid` is the whole
/// density buffer): 0 outside the box; inside, trilinear between cell
/// centres, each coordinate clamped to the outer centres (so the edge value
/// holds between the outer centres and the faces), as Mitsuba 3 samples a
/// grid volume.
pub fn grid_density(v: &GpuVolume, grid: &[f32], p: Vec3) -> f32 {
    let (lo, hi) = (v.min.xyz(), v.max.xyz());
    if p.x < lo.x || p.y < lo.y || p.z < lo.z || p.x > hi.x || p.y > hi.y || p.z > hi.z {
        return 0.0;
    }
    let n = Vec3::new(v.nx as f32, v.ny as f32, v.nz as f32);
    let g = ((p - lo) / (hi - lo) * n - Vec3::splat(0.5)).max(Vec3::ZERO).min(n - Vec3::ONE);
    let at = |i: u32, j: u32, k: u32| grid[(v.density_offset + (k * v.ny + j) * v.nx + i) as usize];
    trilinear(at, g, UVec3::new(v.nx, v.ny, v.nz))
}

/// Trilinear interpolation of `at(i, j, k)` at fractional node
/// coordinates `g` (each in `[0, n - 1]`) of an `n.x x n.y x n.z` lattice.
pub fn trilinear<T>(at: impl Fn(u32, u32, u32) -> T, g: Vec3, n: UVec3) -> T
where
    T: Copy + core::ops::Add<Output = T> + core::ops::Sub<Output = T> + core::ops::Mul<f32, Output = T>,
{
    let (i0, j0, k0) = (g.x as u32, g.y as u32, g.z as u32);
    let (i1, j1, k1) = ((i0 + 1).min(n.x - 1), (j0 + 1).min(n.y - 1), (k0 + 1).min(n.z - 1));
    let (fx, fy, fz) = (g.x - i0 as f32, g.y - j0 as f32, g.z - k0 as f32);
    let x00 = at(i0, j0, k0) + (at(i1, j0, k0) - at(i0, j0, k0)) * fx;
    let x10 = at(i0, j1, k0) + (at(i1, j1, k0) - at(i0, j1, k0)) * fx;
    let x01 = at(i0, j0, k1) + (at(i1, j0, k1) - at(i0, j0, k1)) * fx;
    let x11 = at(i0, j1, k1) + (at(i1, j1, k1) - at(i0, j1, k1)) * fx;
    let y0 = x00 + (x10 - x00) * fy;
    let y1 = x01 + (x11 - x01) * fy;
    y0 + (y1 - y0) * fz
}

/// Extinction coefficient (rgb, 1/m) of all volumes at `p`.
pub fn extinction_at(params: &VolumesParams, volumes: &[GpuVolume], grid: &[f32], p: Vec3) -> Vec4 {
    let mut sigma = Vec4::ZERO;
    let mut v = 0;
    while v < params.volume_count as usize {
        let rho = grid_density(&volumes[v], grid, p);
        if rho > 0.0 {
            sigma += volumes[v].sigma_t * rho;
        }
        v += 1;
    }
    sigma
}

/// The light whose grid holds item `index` of `count(grid)` a grid (its
/// columns or its nodes, over all lights' grids in order), and the item's
/// index within that grid; `(0, u32::MAX)` past the last.
fn light_holding(index: u32, grids: &[LightGrid], light_count: u32, count: impl Fn(&LightGrid) -> u32) -> (usize, u32) {
    let mut first = 0;
    let mut l = 0;
    while l < light_count as usize {
        let columns = count(&grids[l]);
        if index < first + columns {
            return (l, index - first);
        }
        first += columns;
        l += 1;
    }
    (0, u32::MAX)
}

/// The world point at light-space coordinates `(u, v, z)` of `light` (see
/// `LightGrid`), and the path length (m) per unit of z along the light's
/// ray through it.
fn light_space_point(light: &GpuLight, u: f32, v: f32, z: f32) -> (Vec3, f32) {
    let (x, y, stretch) =
        if light.kind == LIGHT_SPOT { (u * z, v * z, (1.0 + u * u + v * v).sqrt()) } else { (u, v, 1.0) };
    let p = light.position.xyz() + light.axis_x.xyz() * x + light.axis_y.xyz() * y + light.axis_z.xyz() * z;
    (p, stretch)
}

/// Optical-depth kernel: column `index` of the lights' transmittance
/// volumes, one light ray marched from `lo.z` to `hi.z`; writes the optical
/// depth (rgb, dimensionless) at each of its `nz` nodes into
/// `out[node - base]` (`node` its index in the whole optical-depth buffer:
/// the GPU passes the whole buffer and `base` 0, the CPU each column's own
/// slice), by the composite midpoint rule with `column_substeps` samples per
/// node interval (`tau_0 = 0`, `tau_{k+1} = tau_k + sum sigma_t(p) ds`);
/// in `w`, the ray's length (m) inside the volumes so far (the midpoint
/// samples where any volume's extinction is above 0: `diffuse_node`'s
/// ring radius).
#[allow(clippy::too_many_arguments)]
pub fn optical_depth_column(
    index: u32,
    common: &CommonParams,
    params: &VolumesParams,
    lights: &[GpuLight],
    grids: &[LightGrid],
    volumes: &[GpuVolume],
    density: &[f32],
    out: &mut [Vec4],
    base: u32,
) {
    let (l, column) = light_holding(index, grids, common.light_count, |g| g.nu * g.nv);
    if column == u32::MAX {
        return;
    }
    let g = &grids[l];
    let light = &lights[l];
    let (i, j) = (column % g.nu, column / g.nu);
    let u = g.lo.x + (g.hi.x - g.lo.x) * i as f32 / (g.nu - 1).max(1) as f32;
    let v = g.lo.y + (g.hi.y - g.lo.y) * j as f32 / (g.nv - 1).max(1) as f32;
    let dz = (g.hi.z - g.lo.z) / (g.nz - 1).max(1) as f32;
    let sub = params.column_substeps.max(1);
    let first = g.offset + column * g.nz;
    let mut tau = Vec4::ZERO;
    out[(first - base) as usize] = tau;
    let mut k = 1;
    while k < g.nz {
        let z0 = g.lo.z + (k - 1) as f32 * dz;
        let mut s = 0;
        while s < sub {
            let z = z0 + dz * (s as f32 + 0.5) / sub as f32;
            let (p, stretch) = light_space_point(light, u, v, z);
            let sigma = extinction_at(params, volumes, density, p);
            let ds = stretch * dz / sub as f32;
            tau += sigma * ds;
            if sigma.x > 0.0 || sigma.y > 0.0 || sigma.z > 0.0 {
                tau.w += ds;
            }
            s += 1;
        }
        out[(first + k - base) as usize] = tau;
        k += 1;
    }
}

/// The optical depth (rgb) through the volumes from `light` to `p`, from
/// the light's transmittance volume (trilinear between nodes): 0 outside
/// the grid's `(u, v)` range (no volume lies on those rays) and before
/// `lo.z`, the last node's value past `hi.z`.
pub fn light_optical_depth(light: &GpuLight, g: &LightGrid, depths: &[Vec4], p: Vec3) -> Vec4 {
    let (f, place) = grid_place(light, g, p);
    if place == PAST_ENTRY {
        grid_lookup(g, depths, f)
    } else {
        Vec4::ZERO
    }
}

/// Where a point lies in a light's transmittance volume (`grid_place`).
const OUTSIDE: u32 = 0;
const BEFORE_ENTRY: u32 = 1;
const PAST_ENTRY: u32 = 2;

/// Where `p` lies in light `g`'s transmittance volume: `OUTSIDE` its
/// `(u, v)` range (or behind a spot), `BEFORE_ENTRY` (`z <= lo.z`) or
/// `PAST_ENTRY`; and its fractional node coordinates `(z, u, v)`, each
/// clamped to the grid.
fn grid_place(light: &GpuLight, g: &LightGrid, p: Vec3) -> (Vec3, u32) {
    if g.nu == 0 {
        return (Vec3::ZERO, OUTSIDE);
    }
    let local = light_local(light, p);
    let (u, v, z) = if light.kind == LIGHT_SPOT {
        if local.z <= 0.0 {
            return (Vec3::ZERO, OUTSIDE);
        }
        (local.x / local.z, local.y / local.z, local.z)
    } else {
        (local.x, local.y, local.z)
    };
    if u < g.lo.x || u > g.hi.x || v < g.lo.y || v > g.hi.y {
        return (Vec3::ZERO, OUTSIDE);
    }
    let fu = ((u - g.lo.x) / (g.hi.x - g.lo.x).max(1e-30) * (g.nu - 1) as f32).clamp(0.0, (g.nu - 1) as f32);
    let fv = ((v - g.lo.y) / (g.hi.y - g.lo.y).max(1e-30) * (g.nv - 1) as f32).clamp(0.0, (g.nv - 1) as f32);
    let fz = ((z - g.lo.z) / (g.hi.z - g.lo.z).max(1e-30) * (g.nz - 1) as f32).clamp(0.0, (g.nz - 1) as f32);
    (Vec3::new(fz, fu, fv), if z <= g.lo.z { BEFORE_ENTRY } else { PAST_ENTRY })
}

/// The optical depth at fractional node coordinates `f = (z, u, v)` of
/// light grid `g`, trilinear between nodes (z fastest: a column is
/// contiguous).
fn grid_lookup(g: &LightGrid, depths: &[Vec4], f: Vec3) -> Vec4 {
    trilinear(|k, i, j| depths[grid_node(g, k, i, j) as usize], f, UVec3::new(g.nz, g.nu, g.nv))
}

/// The index of node `k` of column `(i, j)` of light grid `g` among all
/// grids' nodes (z fastest: a column is contiguous).
fn grid_node(g: &LightGrid, k: u32, i: u32, j: u32) -> u32 {
    g.offset + (j * g.nu + i) * g.nz + k
}

/// Light `l`'s transmittance (rgb) through the volumes to `p`, from its
/// transmittance volume (`grids[l]`): 1 where the scene has no volumes
/// (`grids` empty) or the light no transmittance volume.
pub fn light_transmittance(grids: &[LightGrid], depths: &[Vec4], light: &GpuLight, l: usize, p: Vec3) -> Vec4 {
    if l >= grids.len() || grids[l].nu == 0 {
        return Vec4::new(1.0, 1.0, 1.0, 0.0);
    }
    let tau = light_optical_depth(light, &grids[l], depths, p);
    Vec4::new((-tau.x).exp(), (-tau.y).exp(), (-tau.z).exp(), 0.0)
}

/// `light_optical_depth` at `p`, and the optical depth through all the
/// volumes along the light's ray through `p` (the column's last node).
pub fn light_optical_depths(light: &GpuLight, g: &LightGrid, depths: &[Vec4], p: Vec3) -> (Vec4, Vec4) {
    let (f, place) = grid_place(light, g, p);
    if place == OUTSIDE {
        return (Vec4::ZERO, Vec4::ZERO);
    }
    let through = grid_lookup(g, depths, Vec3::new((g.nz - 1) as f32, f.y, f.z));
    let tau = if place == PAST_ENTRY { grid_lookup(g, depths, f) } else { Vec4::ZERO };
    (tau, through)
}

/// A volume's phase function at `cos_theta` (incident and scattered travel
/// directions), 1/sr, with its Henyey-Greenstein asymmetries scaled by
/// `eccentricity` (1 for the volume's own; the octaves' `c^i` below).
pub fn volume_phase(v: &GpuVolume, cos_theta: f32, eccentricity: f32) -> f32 {
    if v.phase_kind == PHASE_DOUBLE_HENYEY_GREENSTEIN {
        v.weight * phase::henyey_greenstein(cos_theta, v.g1 * eccentricity)
            + (1.0 - v.weight) * phase::henyey_greenstein(cos_theta, v.g2 * eccentricity)
    } else {
        phase::evaluate(v.phase_kind, cos_theta, v.g1 * eccentricity)
    }
}

/// What the volumes pass reads besides the common block and the pixel's
/// surface distance.
pub struct VolumeInputs<'a> {
    pub params: &'a VolumesParams,
    pub volumes: &'a [GpuVolume],
    pub density: &'a [f32],
    pub lights: &'a [GpuLight],
    pub light_map: &'a [Vec4],
    pub shadow: &'a [f32],
    pub grids: &'a [LightGrid],
    pub depths: &'a [Vec4],
    /// The columns' smoothed diffuse light at the light grids' nodes
    /// (`diffuse_node`: fluence, then flux, per node); empty unless
    /// `params.column_spread > 0` with the columns.
    pub diffuse: &'a [Vec4],
}

/// Radiance (W/(m^2 sr), rgb) arriving at `p` from light `l` before the
/// volumes' attenuation, with the light's own falloff, light map, shadow
/// test against the surfaces and the homogeneous medium's attenuation on
/// its way; and the unit direction the light travels at `p`.
fn light_at(common: &CommonParams, light: &GpuLight, light_map: &[Vec4], shadow: &[f32], p: Vec3) -> (Vec4, Vec3) {
    let local = light_local(light, p);
    let e = emitted_visible(light, light_map, shadow, local, 1.0);
    if light.kind == LIGHT_DIRECTIONAL {
        let fog = crate::light::transmittance(common.sigma_t, local.z.max(0.0));
        return (e * fog, light.axis_z.xyz());
    }
    let to_p = p - light.position.xyz();
    let s = to_p.length().max(crate::shafts::LIGHT_RADIUS);
    let fog = crate::light::transmittance(common.sigma_t, s);
    (e * fog / (s * s), to_p / s)
}

/// The volumes' radiance toward the camera along pixel `index`'s ray
/// (rgb, W/(m^2 sr)) and the view transmittance through them (rgb), up to
/// `surface_distance` (the G-buffer's).
///
/// The ray's span inside the volumes' boxes is cut by the sample planes
/// `z_k = depth_near + k dz` (depth along the view direction); on each
/// interval `[a, b]` the medium is sampled once, at the middle: the
/// extinction `sigma_t` of all volumes there and the in-scattered source
/// `S = sum_l sum_v rho_v sigma_s,v p_v(cos) E_l exp(-tau_l)`, where `E_l` is
/// what light `l` sends to the point and `tau_l` its optical depth through
/// the volumes (`light_optical_depth`). Eq. 2 of the 2002 paper for one
/// interval with constant `S` and `sigma_t`: the interval adds
/// `T S (1 - exp(-sigma_t (b - a))) / sigma_t` and multiplies `T` by
/// `exp(-sigma_t (b - a))`, so an interval never adds more than the light it
/// could scatter however thick it is. The homogeneous medium's attenuation
/// from the point to the camera, `exp(-sigma_t,medium t)`, multiplies the
/// added light. The march stops where `T` falls below `1e-6` in every channel.
pub fn volumes_pixel(index: u32, common: &CommonParams, inputs: &VolumeInputs, surface_distance: f32) -> (Vec4, Vec4) {
    let params = inputs.params;
    let x = index % common.width;
    let y = index / common.width;
    let (o, d) = camera_ray(common, x, y);
    let inv_dir = Vec3::ONE / d;
    let mut t_lo = f32::MAX;
    let mut t_hi = 0.0f32;
    let mut v = 0;
    while v < params.volume_count as usize {
        let vol = &inputs.volumes[v];
        let (near, far) = box_span(o, inv_dir, vol.min.xyz(), vol.max.xyz(), 0.0, f32::MAX);
        if near < far {
            t_lo = t_lo.min(near);
            t_hi = t_hi.max(far);
        }
        v += 1;
    }
    t_hi = t_hi.min(surface_distance);
    let mut radiance = Vec4::ZERO;
    let mut view = Vec4::ONE;
    if t_lo >= t_hi {
        return (radiance, view);
    }
    // The fog's light along the whole ray is seen through the volumes in
    // front of each point of it only: `FogShare` gathers its share (`w`).
    let fog_scatters = common.sigma_s.x > 0.0 || common.sigma_s.y > 0.0 || common.sigma_s.z > 0.0;
    let mut fog = FogShare::new(common, t_lo);
    let cos_view = d.dot(common.camera_forward.xyz());
    let dz = (params.depth_far - params.depth_near) / params.plane_count as f32;
    let k0 = ((t_lo * cos_view - params.depth_near) / dz).floor().max(0.0) as u32;
    let k1 = (((t_hi * cos_view - params.depth_near) / dz).ceil().max(0.0) as u32).min(params.plane_count);
    let mut end = t_lo;
    let mut k = k0;
    while k < k1 {
        let z0 = params.depth_near + k as f32 * dz;
        let a = (z0 / cos_view).max(t_lo);
        let b = ((z0 + dz) / cos_view).min(t_hi);
        k += 1;
        if b <= a {
            continue;
        }
        end = b;
        let t = 0.5 * (a + b);
        let p = o + d * t;
        let sigma = extinction_at(params, inputs.volumes, inputs.density, p);
        if fog_scatters {
            fog.interval(a, b - a, (view.x + view.y + view.z) / 3.0, (sigma.x + sigma.y + sigma.z) / 3.0);
        }
        if sigma.x <= 0.0 && sigma.y <= 0.0 && sigma.z <= 0.0 {
            continue;
        }
        let source = in_scattered(common, inputs, p, d);
        let step = Vec4::new((-sigma.x * (b - a)).exp(), (-sigma.y * (b - a)).exp(), (-sigma.z * (b - a)).exp(), 0.0);
        let weight = Vec4::new(
            interval_weight(sigma.x, step.x, b - a),
            interval_weight(sigma.y, step.y, b - a),
            interval_weight(sigma.z, step.z, b - a),
            0.0,
        );
        let fog_t = crate::light::transmittance(common.sigma_t, t);
        radiance += view * source * weight * fog_t;
        view = (view.xyz() * step.xyz()).extend(1.0);
        if view.x < 1e-6 && view.y < 1e-6 && view.z < 1e-6 {
            break;
        }
    }
    view.w = if fog_scatters { fog.share(end, (view.x + view.y + view.z) / 3.0, surface_distance) } else { 1.0 };
    (radiance, view)
}

/// The share of the homogeneous fog's light along a view ray that the
/// volumes let through (grey: the channels' means): `int w(t) T(t) dt /
/// int w(t) dt` over `[0, t_surface]`, `T(t)` the view transmittance
/// through the volumes up to `t` and `w(t) = exp(-sigma t)` (`sigma` the
/// fog's mean extinction) the weight of fog light scattered at `t` as if
/// its source were the same all along the ray (exact for a uniformly lit
/// fog). Before the volumes `T = 1`; in each interval `T` falls
/// exponentially; past them it holds.
struct FogShare {
    sigma: f32,
    seen: f32,
}

impl FogShare {
    /// Starts the sum with the fog in front of the volumes, `[0, t_lo]`.
    fn new(common: &CommonParams, t_lo: f32) -> FogShare {
        let sigma = (common.sigma_t.x + common.sigma_t.y + common.sigma_t.z) / 3.0;
        FogShare { sigma, seen: interval_weight(sigma, (-sigma * t_lo).exp(), t_lo) }
    }

    /// Adds the interval `[a, a + length]` entered with transmittance `t`
    /// through a volume of extinction `sigma_v`.
    fn interval(&mut self, a: f32, length: f32, t: f32, sigma_v: f32) {
        let s = self.sigma + sigma_v;
        self.seen += t * (-self.sigma * a).exp() * interval_weight(s, (-s * length).exp(), length);
    }

    /// The share, the volumes ending at `end` with transmittance `t`, the
    /// ray at `t_surface`.
    fn share(&self, end: f32, t: f32, t_surface: f32) -> f32 {
        let s = self.sigma;
        let span = (t_surface - end).max(0.0);
        let tail = t * (-s * end).exp() * interval_weight(s, (-s * span).exp(), span);
        let total = interval_weight(s, (-s * t_surface).exp(), t_surface);
        if total > 0.0 {
            ((self.seen + tail) / total).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }
}

/// `(1 - exp(-sigma L)) / sigma` given `step = exp(-sigma L)`: the
/// integral of the transmittance over an interval of length `L` (m); `L`
/// by its series where `x = sigma L` is below 0.05, where the difference
/// `1 - exp(-x)` loses `6e-8 / x` of its f32 precision (the series'
/// first omitted term, `x^4 / 120`, is below 5e-8 there).
pub fn interval_weight(sigma: f32, step: f32, length: f32) -> f32 {
    let x = sigma * length;
    if x < 0.05 {
        length * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0))))
    } else {
        (1.0 - step) / sigma
    }
}

/// The in-scattered source at `p` toward the camera (the ray's direction
/// `d`), summed over lights and volumes, W/(m^3 sr).
///
/// Multiple scattering (the default) by delta-Eddington columns
/// (`column_light`): each light's ray through the volumes is a
/// plane-parallel slab whose diffuse light has a closed form. Or, with
/// `scattering = "octaves"` and `octaves = N > 1`, multiple scattering by Wrenninge's octaves
/// (Wrenninge, Kulla and Lundqvist, "Oz: the great and volumetric",
/// SIGGRAPH 2013 talk; as in Frostbite and Unreal): the source is the sum
/// over `i < N` of single scattering with the scattering coefficient times
/// `(a (1 - exp(-tau_through)))^i`, the light's optical depth times `b^i`
/// and the asymmetry times `c^i`. Light scattered many times reaches deeper
/// (less extinction on its way), is dimmer (`a^i`) and less forward-peaked
/// (`c^i`); octave 0 is single scattering. `tau_through` is the optical
/// depth of the whole light ray through the volumes at `p` (the light
/// grid's last node), so `1 - exp(-tau_through)` is the share of that light
/// scattered at all: a thin cloud scatters little of it again, a dense one
/// nearly all. Without that factor the octaves over-brighten thin clouds
/// two to three times (`docs/volumes.md`). The view's extinction is not
/// scaled.
fn in_scattered(common: &CommonParams, inputs: &VolumeInputs, p: Vec3, d: Vec3) -> Vec4 {
    let params = inputs.params;
    let mut source = Vec4::ZERO;
    let mut l = 0;
    while l < common.light_count as usize {
        light_ref!(light = inputs.lights, l);
        let (e, travel) = light_at(common, light, inputs.light_map, inputs.shadow, p);
        if e.x > 0.0 || e.y > 0.0 || e.z > 0.0 {
            let (tau, through) = light_optical_depths(light, &inputs.grids[l], inputs.depths, p);
            // The scattered light travels toward the camera, along -d.
            let cos_theta = -travel.dot(d);
            let mut v = 0;
            while v < params.volume_count as usize {
                let vol = &inputs.volumes[v];
                let rho = grid_density(vol, inputs.density, p);
                if rho > 0.0 {
                    let light_here = if spread_columns(params) {
                        spread_column_light(vol, &inputs.grids[l], inputs.diffuse, light, p, e, tau, cos_theta)
                    } else {
                        scattered_light(params, vol, e, tau, through, cos_theta)
                    };
                    source += light_here * vol.sigma_s * rho;
                }
                v += 1;
            }
        }
        l += 1;
    }
    source
}

/// What light `e` (W/m^2 before the volumes, rgb) scatters toward the
/// camera per unit scattering coefficient at a point of volume `vol` at
/// optical depth `tau` along its ray, the ray `through` deep in all
/// (W/(m^2 sr); times `sigma_s rho` it is `in_scattered`'s source): by the
/// columns (`column_light`), the octaves (`octave_light`) or single
/// scattering, as `params` says.
pub fn scattered_light(
    params: &VolumesParams,
    vol: &GpuVolume,
    e: Vec4,
    tau: Vec4,
    through: Vec4,
    cos_theta: f32,
) -> Vec4 {
    if params.columns != 0 {
        return column_light(params, vol, e, tau, through, cos_theta);
    }
    // The octaves' weight: the share of the light that scatters at all on
    // its way through the volumes along its ray.
    let thick = Vec4::ONE - Vec4::new((-through.x).exp(), (-through.y).exp(), (-through.z).exp(), 0.0);
    octave_light(params, vol, e, tau, thick, cos_theta)
}

/// The light of the octaves that reaches a point of volume `vol` and is
/// scattered toward the camera per unit scattering coefficient (W/(m^2 sr),
/// rgb; times `sigma_s rho` it is `in_scattered`'s source): the sum over
/// octaves `i` of `e exp(-b^i tau) a_i p(cos_theta, c^i)`, `a_0 = 1`,
/// `a_(i+1) = a_i thick octave_scattering`. `e` is what the light sends
/// before the volumes, `tau` its optical depth to the point, `thick` the
/// share of its ray's light the volumes scatter at all (`in_scattered`).
pub fn octave_light(params: &VolumesParams, vol: &GpuVolume, e: Vec4, tau: Vec4, thick: Vec4, cos_theta: f32) -> Vec4 {
    let mut sum = Vec4::ZERO;
    let (mut a, mut b, mut c) = (Vec4::ONE, 1.0f32, 1.0f32);
    let mut octave = 0;
    while octave < params.octaves.max(1) {
        let arriving = e * Vec4::new((-b * tau.x).exp(), (-b * tau.y).exp(), (-b * tau.z).exp(), 0.0);
        sum += arriving * a * volume_phase(vol, cos_theta, c);
        a *= thick * params.octave_scattering;
        b *= params.octave_extinction;
        c *= params.octave_phase;
        octave += 1;
    }
    sum
}

/// The density kernel's entry point (`density_cell`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn density_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 42)] balls: &[GpuMetaball],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 43)] bins: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 44)] density: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 49)] automaton: &[AutomatonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 55)] smooth: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 56)] grid_values: &[f32],
) {
    let index = crate::flat_index(id, groups);
    let params = &params[0];
    if index < params.cell_count {
        density[index as usize] = density_cell(index, params, volumes, balls, bins, &automaton[0], smooth, grid_values);
    }
}

/// The optical-depth kernel's entry point (`optical_depth_column`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn optical_depth_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 44)] density: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let params = &params[0];
    if index < params.column_count {
        optical_depth_column(index, &common[0], params, lights, grids, volumes, density, depths, 0);
    }
}

/// The diffuse-light kernel's entry point (`diffuse_node`): two `Vec4`s a
/// node, fluence then flux.
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn diffuse_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 44)] density: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 119)] diffuse: &mut [Vec4],
) {
    let index = crate::flat_index(id, groups);
    let nodes = (diffuse.len() / 2) as u32;
    if index < nodes {
        let (fluence, flux) =
            diffuse_node(index, &params[0], lights, grids, volumes, density, depths, common[0].light_count);
        diffuse[2 * index as usize] = fluence;
        diffuse[2 * index as usize + 1] = flux;
    }
}

/// The volumes pass's entry point (`volumes_pixel`).
#[allow(clippy::too_many_arguments)]
#[spirv(compute(threads(64)))]
pub fn volumes_kernel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] common: &[CommonParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] lights: &[GpuLight],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] light_map: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] shadow: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] gbuffer: &[GBufferTexel],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 40)] params: &[VolumesParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 41)] volumes: &[GpuVolume],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 44)] density: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 45)] grids: &[LightGrid],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 46)] depths: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 47)] radiance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 48)] transmittance: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 119)] diffuse: &[Vec4],
) {
    let index = crate::flat_index(id, groups);
    let common = &common[0];
    if index < common.band_pixels {
        let inputs =
            VolumeInputs { params: &params[0], volumes, density, lights, light_map, shadow, grids, depths, diffuse };
        let distance = gbuffer[index as usize].normal_distance.w;
        let (l, t) = volumes_pixel(common.band_start + index, common, &inputs, distance);
        radiance[index as usize] = l;
        transmittance[index as usize] = t;
    }
}

/// The phase function's first two Legendre moments `(g, f)` (eq. C1 of
/// `docs/volumes.md`): its mean cosine `g` and `f = <P2(cos)>`, the share
/// of the light the delta-M scaling moves into the forward peak
/// (Wiscombe 1977). Henyey-Greenstein: `(g, g^2)`, a double one the
/// weighted sums; Rayleigh `(0, 0.1)`; the 2002 paper's `1 + 9
/// cos^16(a/2)`: `(0.4, 0.2545)` (integrated in closed form over
/// `x = (1 + cos) / 2`); isotropic `(0, 0)`.
pub fn phase_moments(v: &GpuVolume) -> (f32, f32) {
    if v.phase_kind == PHASE_DOUBLE_HENYEY_GREENSTEIN {
        let w = v.weight;
        (w * v.g1 + (1.0 - w) * v.g2, w * v.g1 * v.g1 + (1.0 - w) * v.g2 * v.g2)
    } else if v.phase_kind == crate::types::PHASE_HENYEY_GREENSTEIN {
        (v.g1, v.g1 * v.g1)
    } else if v.phase_kind == crate::types::PHASE_RAYLEIGH {
        (0.0, 0.1)
    } else if v.phase_kind == crate::types::PHASE_DOBASHI {
        (0.4, 0.2545)
    } else {
        (0.0, 0.0)
    }
}

/// The highest scaled albedo `column_channel` uses: at 1 the slab's two
/// homogeneous solutions coincide (`k = 0`); 0.9999 keeps `k >= 0.017`,
/// conserving energy to 1e-4.
pub const MAX_COLUMN_ALBEDO: f32 = 0.9999;

/// One channel of the delta-Eddington column (eqs. C1-C6 of
/// `docs/volumes.md`): light of irradiance 1 (W/m^2, normal to its travel)
/// enters a plane-parallel slab `through` optical depths thick (its travel
/// the slab's normal); at optical depth `tau` from the lit face, with
/// albedo `omega` and phase moments `(g, f)`, returns `(direct, fluence,
/// flux)`: the scaled direct beam's irradiance `exp(-t)` (W/m^2), and the
/// diffuse light's fluence (W/m^2) and net flux along the travel (W/m^2)
/// in the Eddington (P1) approximation with Marshak's boundary conditions.
/// `width` is the medium's lateral extent as a multiple of the scaled
/// depth: its leakage sideways enters as diffusion theory's geometric
/// buckling (eq. C4); 0: none (a slab without sides).
pub fn column_channel(omega: f32, g: f32, f: f32, tau: f32, through: f32, width: f32) -> (f32, f32, f32) {
    // (C2) delta-M scaling: the forward peak `f` travels on with the beam.
    let scale = (1.0 - omega * f).max(1e-6);
    let w = ((1.0 - f) * omega / scale).clamp(0.0, MAX_COLUMN_ALBEDO);
    let gs = (g - f) / (1.0 - f).max(1e-6);
    let t = scale * tau;
    let depth = scale * through.max(tau);
    let transport = 1.0 - w * gs;
    // (C4) the slab's decay constant, and the lateral leakage of a medium
    // `width depth` wide (plus the extrapolation length `2/(3 transport)`
    // on each side), in both lateral directions.
    let lateral = if width > 0.0 {
        let extent = width * depth + 4.0 / (3.0 * transport);
        2.0 * core::f32::consts::PI * core::f32::consts::PI / (extent * extent)
    } else {
        0.0
    };
    let mut k2 = 3.0 * (1.0 - w) * transport + lateral;
    // The particular solution is singular at k = 1: step off it (the
    // cancellation that remains costs below 1e-3 of the fluence).
    if (k2 - 1.0).abs() < 1e-3 {
        k2 = if k2 < 1.0 { 1.0 - 1e-3 } else { 1.0 + 1e-3 };
    }
    let k = k2.sqrt();
    // (C3) phi'' - k^2 phi = -3 w (1 + gs (1 - w)) exp(-t): the particular
    // solution alpha exp(-t).
    let alpha = 3.0 * w * (1.0 + gs * (1.0 - w)) / (k2 - 1.0);
    // (C5) Marshak: phi + 2F = 0 at the lit face, phi - 2F = 0 at the far
    // one, with F = (3 w gs exp(-t) - phi') / (3 transport); the
    // homogeneous parts written `A exp(-k t) + B exp(-k (T - t))` so no
    // exponential exceeds 1.
    let h = 2.0 / (3.0 * transport);
    let s = 3.0 * w * gs + alpha;
    let far = (-depth).exp();
    let top = -(alpha + h * s);
    let bottom = far * (h * s - alpha);
    let (p, q) = (1.0 + h * k, (-k * depth).exp() * (1.0 - h * k));
    let det = p * p - q * q;
    let a = (top * p - q * bottom) / det;
    let b = (p * bottom - q * top) / det;
    let down = (-k * t).exp();
    let up = (-k * (depth - t)).exp();
    let direct = (-t).exp();
    let fluence = a * down + b * up + alpha * direct;
    let slope = -k * a * down + k * b * up - alpha * direct;
    let flux = (3.0 * w * gs * direct - slope) / (3.0 * transport);
    (direct, fluence, flux)
}

/// Whether the slices take the columns' diffuse light from the light
/// grids' smoothed nodes (`diffuse_node`).
pub fn spread_columns(params: &VolumesParams) -> bool {
    params.columns != 0 && params.column_spread > 0.0
}

/// Points of `diffuse_node`'s ring, evenly around it.
pub const RING_POINTS: u32 = 6;

/// The weight of a node's own column in `diffuse_node` (the ring shares
/// the rest): fitted with `column_spread` against the Monte Carlo
/// reference (`docs/volumes.md`, "Multiple scattering").
pub const RING_CENTRE_WEIGHT: f32 = 0.3;

/// The delta-Eddington column's fields at optical depth `tau` of a ray
/// `through` deep, per unit irradiance, its lateral leakage by `width`
/// (eq. C4; 0: none, where the ring carries it): `(direct, fluence,
/// flux)` per channel (rgb; `column_channel`). One channel at a time,
/// unrolled: a Vec4 indexed by a loop variable becomes a pointer select
/// that Vulkan's SPIR-V does not allow.
fn column_fields(vol: &GpuVolume, tau: Vec4, through: Vec4, width: f32) -> (Vec4, Vec4, Vec4) {
    let (g, f) = phase_moments(vol);
    let channel = |sigma_s: f32, sigma_t: f32, tau: f32, through: f32| -> (f32, f32, f32) {
        let omega = if sigma_t > 0.0 { sigma_s / sigma_t } else { 0.0 };
        column_channel(omega, g, f, tau, through, width)
    };
    let (s, t) = (vol.sigma_s, vol.sigma_t);
    let x = channel(s.x, t.x, tau.x, through.x);
    let (y, z) = if grey_column(vol, tau, through) {
        (x, x)
    } else {
        (channel(s.y, t.y, tau.y, through.y), channel(s.z, t.z, tau.z, through.z))
    };
    (Vec4::new(x.0, y.0, z.0, 0.0), Vec4::new(x.1, y.1, z.1, 0.0), Vec4::new(x.2, y.2, z.2, 0.0))
}

/// The volume whose extinction at `p` is largest (0 where none is there):
/// whose albedo and phase function `diffuse_node` solves a column with.
fn dominant_volume(params: &VolumesParams, volumes: &[GpuVolume], density: &[f32], p: Vec3) -> usize {
    let mut best = 0;
    let mut most = 0.0;
    let mut v = 0;
    while v < params.volume_count as usize {
        let sigma = volumes[v].sigma_t.x * grid_density(&volumes[v], density, p);
        if sigma > most {
            most = sigma;
            best = v;
        }
        v += 1;
    }
    best
}

/// Diffuse-light kernel: node `index` of the lights' grids (over all
/// lights' grids in order, as `depths`), the columns' diffuse light there
/// per unit irradiance (W/m^2 per W/m^2): `(fluence, flux)`, rgb each.
///
/// A column alone (eqs. C1-C5) is a slab as wide as the sky; a cloud's
/// light also diffuses sideways, out of its domes and into its flanks
/// (the radiative smoothing of the independent-column approximation's
/// field, Marshak et al. 1995, over about the cloud's depth). So the node
/// takes `RING_CENTRE_WEIGHT` of its own column's fields and shares the
/// rest among `RING_POINTS` points on a ring across the light's travel,
/// of radius `column_spread sqrt(H d)` (m), `H` the length of the node's
/// light ray inside the volumes and `d` that length up to the node
/// (`depths`' `w`): nothing at the lit face, the ray's whole length at
/// its far end. Each ring point has its own column's fields, none where
/// the ring point lies outside every volume (the light that diffuses there
/// has left the cloud) unless the node does too (its value is then only
/// what the samples inside near it interpolate toward). The columns solve
/// without eq. C4's buckling: the ring is the lateral leakage. The albedo
/// and phase function are those of the volume with the most extinction at
/// the node.
#[allow(clippy::too_many_arguments)]
pub fn diffuse_node(
    index: u32,
    params: &VolumesParams,
    lights: &[GpuLight],
    grids: &[LightGrid],
    volumes: &[GpuVolume],
    density: &[f32],
    depths: &[Vec4],
    light_count: u32,
) -> (Vec4, Vec4) {
    // The light and column holding the node, and its place on the column.
    let (l, local) = light_holding(index, grids, light_count, |g| g.nu * g.nv * g.nz);
    if local == u32::MAX {
        return (Vec4::ZERO, Vec4::ZERO);
    }
    let g = &grids[l];
    let light = &lights[l];
    let (column, k) = (local / g.nz, local % g.nz);
    let (i, j) = (column % g.nu, column / g.nu);
    let u = g.lo.x + (g.hi.x - g.lo.x) * i as f32 / (g.nu - 1).max(1) as f32;
    let v = g.lo.y + (g.hi.y - g.lo.y) * j as f32 / (g.nv - 1).max(1) as f32;
    let z = g.lo.z + (g.hi.z - g.lo.z) * k as f32 / (g.nz - 1).max(1) as f32;
    let (p, _) = light_space_point(light, u, v, z);
    let tau = depths[(g.offset + local) as usize];
    let through = depths[(g.offset + column * g.nz + g.nz - 1) as usize];
    let vol = &volumes[dominant_volume(params, volumes, density, p)];
    let (_, mut fluence, mut flux) = column_fields(vol, tau, through, 0.0);
    // From 0 at the lit face to the ray's whole length at the far one,
    // as the square root of the depth (m).
    let radius = params.column_spread * (through.w * tau.w).max(0.0).sqrt();
    if radius > 0.0 {
        // A node outside every volume holds what the samples inside near
        // it interpolate toward: its ring is not cut by the vacuum around it.
        let sigma = extinction_at(params, volumes, density, p);
        let inside = sigma.x > 0.0 || sigma.y > 0.0 || sigma.z > 0.0;
        // Across the travel at p: the light's own axes (a spot's, at its axis).
        let (a, b) = (light.axis_x.xyz(), light.axis_y.xyz());
        let share = (1.0 - RING_CENTRE_WEIGHT) / RING_POINTS as f32;
        fluence *= RING_CENTRE_WEIGHT;
        flux *= RING_CENTRE_WEIGHT;
        let mut n = 0;
        while n < RING_POINTS {
            let angle = n as f32 * (2.0 * core::f32::consts::PI / RING_POINTS as f32);
            let q = p + (a * angle.cos() + b * angle.sin()) * radius;
            let sigma = extinction_at(params, volumes, density, q);
            if !inside || sigma.x > 0.0 || sigma.y > 0.0 || sigma.z > 0.0 {
                let (tq, thq) = light_optical_depths(light, g, depths, q);
                let (_, fq, hq) = column_fields(vol, tq, thq, 0.0);
                fluence += fq * share;
                flux += hq * share;
            }
            n += 1;
        }
    }
    (fluence, flux)
}

/// Multiple scattering by columns spread across the light's travel (the
/// slices' default): what light `e` scatters toward the camera at `p` per
/// unit scattering coefficient (as `column_light`), the scaled direct
/// beam at `p`'s own optical depth `tau` with the phase function, and the
/// diffuse light's P1 radiance from `diffuse_node`'s fields, trilinear
/// between the light grid `g`'s nodes.
#[allow(clippy::too_many_arguments)]
pub fn spread_column_light(
    vol: &GpuVolume,
    g: &LightGrid,
    diffuse: &[Vec4],
    light: &GpuLight,
    p: Vec3,
    e: Vec4,
    tau: Vec4,
    cos_theta: f32,
) -> Vec4 {
    let (gm, f) = phase_moments(vol);
    let phase = volume_phase(vol, cos_theta, 1.0);
    let (s, t) = (vol.sigma_s, vol.sigma_t);
    // (C2): the direct beam's scaled optical depth, per channel.
    let scaled = |sigma_s: f32, sigma_t: f32, tau: f32| -> f32 {
        let omega = if sigma_t > 0.0 { sigma_s / sigma_t } else { 0.0 };
        (-(1.0 - omega * f).max(1e-6) * tau).exp()
    };
    let direct = Vec4::new(scaled(s.x, t.x, tau.x), scaled(s.y, t.y, tau.y), scaled(s.z, t.z, tau.z), 0.0);
    let (fc, place) = grid_place(light, g, p);
    let mut radiance = Vec4::ZERO;
    if place != OUTSIDE {
        let n = UVec3::new(g.nz, g.nu, g.nv);
        let fluence = trilinear(|k, i, j| diffuse[(2 * grid_node(g, k, i, j)) as usize], fc, n);
        let flux = trilinear(|k, i, j| diffuse[(2 * grid_node(g, k, i, j) + 1) as usize], fc, n);
        radiance = p1_radiance(fluence, flux, gm, cos_theta);
    }
    e * (direct * phase + radiance)
}

/// Multiple scattering by delta-Eddington columns (the default; eqs. C1-C6
/// of `docs/volumes.md`): the light's ray through the volumes taken as a
/// plane-parallel slab `through` optical depths deep (the tilted
/// independent-column approximation of cloud radiation), solved per
/// channel in closed form by `column_channel`; W/(m^2 sr) per unit
/// scattering coefficient, rgb, as `scattered_light`. (C6): the scaled
/// direct beam scatters with the phase function `p`, the diffuse light's
/// P1 radiance `(phi + 3 F mu) / 4 pi` with it (`g` its mean cosine, `mu =
/// cos_theta` between the light's travel and the scattered light's).
pub fn column_light(
    params: &VolumesParams,
    vol: &GpuVolume,
    e: Vec4,
    tau: Vec4,
    through: Vec4,
    cos_theta: f32,
) -> Vec4 {
    let (g, _) = phase_moments(vol);
    let (direct, fluence, flux) = column_fields(vol, tau, through, params.column_width);
    e * (direct * volume_phase(vol, cos_theta, 1.0) + p1_radiance(fluence, flux, g, cos_theta))
}

/// (C6) The diffuse light's P1 radiance toward the camera per unit
/// irradiance, `(phi + 3 g F cos theta) / 4 pi` per channel, none below 0
/// (W/(m^2 sr)): `fluence` and `flux` the column's (`column_fields`), `g`
/// the phase function's mean cosine.
fn p1_radiance(fluence: Vec4, flux: Vec4, g: f32, cos_theta: f32) -> Vec4 {
    ((fluence + flux * (3.0 * g) * cos_theta) / (4.0 * core::f32::consts::PI)).max(Vec4::ZERO)
}

/// Whether every channel of a column has the same inputs (a grey medium,
/// as clouds and smoke are): then they have the same bits, and the slab is
/// solved once.
fn grey_column(vol: &GpuVolume, tau: Vec4, through: Vec4) -> bool {
    let (s, t) = (vol.sigma_s, vol.sigma_t);
    s.y == s.x
        && s.z == s.x
        && t.y == t.x
        && t.z == t.x
        && tau.y == tau.x
        && tau.z == tau.x
        && through.y == through.x
        && through.z == through.x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_falls_from_one_to_zero_smoothly() {
        assert_eq!(field(0.0), 1.0);
        assert!(field(1.0 - 1e-7).abs() < 1e-6);
        assert_eq!(field(1.5), 0.0);
        // Monotone on [0, 1].
        let mut last = 1.0;
        for i in 1..=100 {
            let f = field((i as f32 / 100.0).powi(2));
            assert!(f <= last && f >= 0.0, "f({}) = {f}", i as f32 / 100.0);
            last = f;
        }
        // Its volume integral: int_0^1 f(a) 4 pi a^2 da = 4 pi * 61/945
        // (by the polynomial, term by term: 1/3 - 22/45 + 17/63 - 4/81).
        let n = 100_000;
        let sum: f64 = (0..n)
            .map(|i| {
                let a = (i as f64 + 0.5) / n as f64;
                field((a * a) as f32) as f64 * 4.0 * std::f64::consts::PI * a * a / n as f64
            })
            .sum();
        let exact = 4.0 * std::f64::consts::PI * (1.0 / 3.0 - 22.0 / 45.0 + 17.0 / 63.0 - 4.0 / 81.0);
        assert!((sum - exact).abs() < 1e-5 * exact, "{sum} against {exact}");
    }

    /// A slab 10 m thick and 100 m wide (density 1 in a 2x2x2 grid,
    /// `sigma_t` 1/m, albedo 0.99, Henyey-Greenstein 0.85) under a light
    /// travelling straight down; its light grid 21x21 columns 5 m apart
    /// across it, 21 nodes 1 m apart from 5 m above the slab's top; the
    /// optical depths by `optical_depth_column`.
    fn slab(spread: f32) -> Slab {
        let volume = GpuVolume {
            min: Vec4::new(-50.0, 0.0, -50.0, 0.0),
            max: Vec4::new(50.0, 10.0, 50.0, 0.0),
            sigma_s: Vec4::new(0.99, 0.99, 0.99, 0.0),
            sigma_t: Vec4::new(1.0, 1.0, 1.0, 0.0),
            phase_kind: crate::types::PHASE_HENYEY_GREENSTEIN,
            g1: 0.85,
            nx: 2,
            ny: 2,
            nz: 2,
            ..Default::default()
        };
        let light = GpuLight {
            position: Vec4::new(0.0, 15.0, 0.0, 0.0),
            axis_x: Vec4::new(1.0, 0.0, 0.0, 0.0),
            axis_y: Vec4::new(0.0, 0.0, 1.0, 0.0),
            axis_z: Vec4::new(0.0, -1.0, 0.0, 0.0),
            kind: LIGHT_DIRECTIONAL,
            ..Default::default()
        };
        let grid = LightGrid {
            lo: Vec4::new(-50.0, -50.0, 0.0, 0.0),
            hi: Vec4::new(50.0, 50.0, 20.0, 0.0),
            nu: 21,
            nv: 21,
            nz: 21,
            offset: 0,
        };
        let params = VolumesParams {
            volume_count: 1,
            column_count: 441,
            column_substeps: 8,
            columns: 1,
            column_spread: spread,
            ..Default::default()
        };
        let common = CommonParams { light_count: 1, ..Default::default() };
        let density = [1.0f32; 8];
        let mut depths = vec![Vec4::ZERO; 441 * 21];
        for column in 0..441u32 {
            let nodes = &mut depths[(column * 21) as usize..((column + 1) * 21) as usize];
            optical_depth_column(column, &common, &params, &[light], &[grid], &[volume], &density, nodes, column * 21);
        }
        Slab { params, lights: [light], grids: [grid], volumes: [volume], density, depths }
    }

    /// `slab`'s scene: what `diffuse_node` reads.
    struct Slab {
        params: VolumesParams,
        lights: [GpuLight; 1],
        grids: [LightGrid; 1],
        volumes: [GpuVolume; 1],
        density: [f32; 8],
        depths: Vec<Vec4>,
    }

    /// The ring leaves a medium that is the same all across alone (every
    /// ring point's column is the node's own), takes light away where part
    /// of the ring lies outside the volume (the light that diffuses out of
    /// a cloud's side), and without a spread is the column alone (eq. C4's
    /// buckling off).
    #[test]
    fn the_ring_spreads_a_column_only_where_the_medium_changes_across() {
        let node = |i: u32, j: u32, k: u32| (j * 21 + i) * 21 + k;
        for spread in [0.0f32, 1.0] {
            let Slab { params, lights, grids, volumes, density, depths } = slab(spread);
            let at = |n: u32| diffuse_node(n, &params, &lights, &grids, &volumes, &density, &depths, 1);
            for k in [5u32, 10, 15, 20] {
                // The column alone, from the node's own depths.
                let tau = depths[node(10, 10, k) as usize];
                let through = depths[node(10, 10, 20) as usize];
                assert!((through.x - 10.0).abs() < 1e-3 && (through.w - 10.0).abs() < 1e-3, "{through:?}");
                let (g, f) = phase_moments(&volumes[0]);
                let (_, fluence, flux) = column_channel(0.99, g, f, tau.x, through.x, 0.0);
                // The middle column (u = v = 0) and ones 10 m in from a
                // side: the ring (radius sqrt(10 m * depth) <= 10 m) stays
                // in the slab.
                for (i, j) in [(10u32, 10u32), (2, 10), (10, 18)] {
                    let (a, b) = at(node(i, j, k));
                    assert!(
                        (a.x - fluence).abs() <= 1e-4 * fluence.abs().max(1e-3),
                        "{spread} {k}: {a:?} against {fluence}"
                    );
                    assert!((b.x - flux).abs() <= 1e-4 * fluence.abs().max(1e-3), "{spread} {k}: {b:?} against {flux}");
                    assert_eq!((a.y, a.z), (a.x, a.x), "a grey slab's channels are one");
                }
            }
        }
    }

    /// A step: a second box 10 m tall on the slab's left half (x <= 0),
    /// the light 5 m above it. A node 5 m deep in the step and 5 m from its
    /// side has a ring of radius sqrt(20 m * 5 m) = 10 m: the ring point
    /// toward +x lies over the slab's right half, in the air above it,
    /// where the light that diffuses out of the step's side is lost; the
    /// node keeps its column's share and the five other points' (each the
    /// same column as the step's middle, 25 m from any side).
    #[test]
    fn the_ring_loses_what_diffuses_out_of_a_side() {
        let Slab { mut params, mut lights, mut grids, volumes, .. } = slab(1.0);
        let step = GpuVolume {
            min: Vec4::new(-50.0, 10.0, -50.0, 0.0),
            max: Vec4::new(0.0, 20.0, 50.0, 0.0),
            density_offset: 8,
            ..volumes[0]
        };
        let volumes = [volumes[0], step];
        let density = [1.0f32; 16];
        lights[0].position.y = 25.0;
        grids[0].hi.z = 30.0;
        grids[0].nz = 31;
        params.volume_count = 2;
        let common = CommonParams { light_count: 1, ..Default::default() };
        let mut depths = vec![Vec4::ZERO; 441 * 31];
        for column in 0..441u32 {
            let nodes = &mut depths[(column * 31) as usize..((column + 1) * 31) as usize];
            optical_depth_column(column, &common, &params, &lights, &grids, &volumes, &density, nodes, column * 31);
        }
        let node = |i: u32, j: u32, k: u32| (j * 21 + i) * 31 + k;
        let at = |n: u32| diffuse_node(n, &params, &lights, &grids, &volumes, &density, &depths, 1).0.x;
        // z = 10: 5 m into the step (y = 15). x = -25 (i = 5) and x = -5 (i = 9).
        let (middle, side) = (at(node(5, 10, 10)), at(node(9, 10, 10)));
        let through = depths[node(9, 10, 30) as usize];
        assert!((through.w - 20.0).abs() < 1e-3 && (depths[node(9, 10, 10) as usize].w - 5.0).abs() < 1e-3);
        let share = (1.0 - RING_CENTRE_WEIGHT) / RING_POINTS as f32;
        assert!(middle > 0.0);
        assert!((side - middle * (1.0 - share)).abs() < 0.02 * middle, "{side} against {middle} less a share");
    }

    #[test]
    fn interval_weight_is_continuous_at_its_switch() {
        // Against f64 on both sides of the switch and far from it: the f32
        // forms hold 2e-6 relative (the direct form's cancellation at x = 0.05).
        for &l in &[0.5f32, 1.0, 3.0] {
            for &x in &[1e-8f64, 1e-3, 0.0499, 0.0501, 0.5, 5.0] {
                let s = (x / l as f64) as f32;
                let got = interval_weight(s, (-s * l).exp(), l) as f64;
                let exact = (1.0 - (-x).exp()) / (x / l as f64);
                assert!((got - exact).abs() < 2e-6 * exact, "x {x}: {got} against {exact}");
            }
        }
        // Thick: the weight tends to 1 / sigma, never more.
        assert!((interval_weight(1e4, 0.0, 1.0) - 1e-4).abs() < 1e-9);
    }
}
