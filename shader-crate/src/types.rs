//! Buffer layouts shared by the host and the kernels. They are written once, here.
//!
//! Every struct is built from `Vec4`s and groups of four 32-bit scalars, so that its
//! layout is the same on the host (Rust `repr(C)`) and in SPIR-V (rust-gpu emits the
//! offsets of the Rust layout), with no `vec3` padding surprises.

use crate::glam::Vec4;

/// What the kernels know about one frame: camera, medium and object counts.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct FrameParams {
    /// Camera position, metres (w unused).
    pub camera_position: Vec4,
    /// Unit view direction (w unused).
    pub camera_forward: Vec4,
    /// Camera right axis scaled by `tan(vfov / 2) * aspect` (w unused).
    pub camera_right: Vec4,
    /// Camera up axis scaled by `tan(vfov / 2)` (w unused).
    pub camera_up: Vec4,
    /// Extinction coefficient per channel, 1/m (w unused).
    pub sigma_t: Vec4,
    /// Scattering coefficient per channel, 1/m (w unused).
    pub sigma_s: Vec4,
    pub width: u32,
    pub height: u32,
    pub light_count: u32,
    pub sphere_count: u32,
    pub triangle_count: u32,
    /// Total number of shadow-map texels over all lights.
    pub shadow_texel_count: u32,
    /// One of the `PHASE_*` constants.
    pub phase_kind: u32,
    /// Henyey-Greenstein asymmetry `g` (only for `PHASE_HENYEY_GREENSTEIN`).
    pub phase_g: f32,
    /// Shafts: number of sample planes `n` (eq. 5).
    pub plane_count: u32,
    /// Shafts: sub-sample planes per plane interval `m` (eq. 9).
    pub subplane_count: u32,
    /// Shafts: `shafts::MODE_EXACT` or `shafts::MODE_TABLES`.
    pub shaft_mode: u32,
    /// Shafts: 1 to offset the plane lattice per pixel by an ordered dither.
    pub jitter: u32,
    /// Shafts: depth range (along the view direction, metres) the planes span.
    pub depth_near: f32,
    pub depth_far: f32,
    /// Shafts: nodes of the phase table `F(alpha)` over [0, pi].
    pub phase_table_size: u32,
    /// Shafts: nodes of the attenuation table `h(s, t)` along `s` and `t`.
    pub h_table_s: u32,
    pub h_table_t: u32,
    /// Shafts: the `h` table covers `[0, h_s_max] x [0, h_t_max]` metres.
    pub h_s_max: f32,
    pub h_t_max: f32,
    /// Shafts: 1 to integrate the `1/s^2` of eq. 3 exactly over each interval.
    pub analytic_inverse_square: u32,
    /// Shafts: 1 to round each interval's contribution to 8 bits of the
    /// frame buffer, as the 2002 paper's blending hardware did.
    pub quantize_8bit: u32,
    /// Radiance that maps to 1.0 in the frame buffer is `1 / quantize_scale`
    /// (the PNG exposure).
    pub quantize_scale: f32,
    /// The image kernels write pixels `band_start .. band_start + band_pixels`
    /// (row-major) into an output buffer of `band_pixels` elements; the host
    /// splits images larger than one device buffer into such bands.
    pub band_start: u32,
    pub band_pixels: u32,
    /// Number of triangle groups (one per scene object made of triangles).
    pub group_count: u32,
    pub _pad: [u32; 3],
}

pub const PHASE_ISOTROPIC: u32 = 0;
pub const PHASE_HENYEY_GREENSTEIN: u32 = 1;
pub const PHASE_RAYLEIGH: u32 = 2;
/// `1 + 9 cos^16(a/2)` of the 2002 shafts-of-light paper, normalised.
pub const PHASE_DOBASHI: u32 = 3;

pub const LIGHT_SPOT: u32 = 0;
pub const LIGHT_DIRECTIONAL: u32 = 1;

/// A light, in the frame the kernels use.
///
/// Spotlight frame: `axis_z` is the beam direction, `axis_x` the light map's `u`
/// direction and `axis_y` its `v` direction (image rows go down `axis_y`).
/// Directional light: `position` is the centre of the entry plane (where the
/// light enters the medium), `axis_z` the direction the light travels.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuLight {
    /// Spotlight position, or the directional light's entry-plane centre, metres.
    pub position: Vec4,
    pub axis_x: Vec4,
    pub axis_y: Vec4,
    pub axis_z: Vec4,
    /// Radiant intensity W/sr per channel (spot) or irradiance W/m^2 on a
    /// surface facing the light (directional).
    pub power: Vec4,
    /// `LIGHT_SPOT` or `LIGHT_DIRECTIONAL`.
    pub kind: u32,
    /// Offset of the first light-map texel in the texel buffer.
    pub light_map_offset: u32,
    /// Light map size in texels; 0 means no light map (a uniform beam).
    pub light_map_width: u32,
    pub light_map_height: u32,
    /// Spot: half-angle of the cone, radians.
    pub cutoff: f32,
    /// Spot: half-angle inside which the beam is at full strength, radians
    /// (equal to `cutoff` for a hard edge).
    pub beam: f32,
    /// Spot: `tan(cutoff)`.
    pub tan_cutoff: f32,
    /// Directional: half-size of the lit (and shadow-mapped) rectangle, metres.
    pub half_extent_x: f32,
    pub half_extent_y: f32,
    /// Offset of the first shadow-map texel in the shadow buffer.
    pub shadow_offset: u32,
    /// Shadow map is `shadow_resolution` x `shadow_resolution`.
    pub shadow_resolution: u32,
    /// 1 when light-map and shadow-map coverage outside the rectangle is dark
    /// (directional light through a window); 0 for an unbounded beam.
    pub bounded: u32,
    /// 1 if the light's volume may be seen by the camera (the shafts pass
    /// skips the others).
    pub in_view: u32,
    pub _pad: [u32; 3],
}

/// A sphere with a diffuse albedo.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuSphere {
    /// Centre xyz in metres, radius in w.
    pub center_radius: Vec4,
    /// Diffuse albedo per channel in [0, 1].
    pub albedo: Vec4,
}

/// A triangle with a diffuse albedo. Surfaces are two-sided.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuTriangle {
    pub v0: Vec4,
    pub v1: Vec4,
    pub v2: Vec4,
    pub albedo: Vec4,
}

/// A run of consecutive triangles (one scene object) and its bounding box:
/// a ray that misses the box skips all of them.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuTriangleGroup {
    /// Box corners, metres (w unused).
    pub bounds_min: Vec4,
    pub bounds_max: Vec4,
    pub first_triangle: u32,
    pub triangle_count: u32,
    pub _pad: [u32; 2],
}

#[cfg(not(target_arch = "spirv"))]
mod pod {
    // SAFETY: every type here is `repr(C)`, `Copy`, made only of `f32`/`u32`/`Vec4`
    // fields whose sizes add up to a multiple of 16 bytes, so there is no padding
    // and every bit pattern is a valid value.
    macro_rules! pod {
        ($($t:ty),*) => {$(
            unsafe impl bytemuck::Zeroable for $t {}
            unsafe impl bytemuck::Pod for $t {}
        )*};
    }
    pod!(super::FrameParams, super::GpuLight, super::GpuSphere, super::GpuTriangle, super::GpuTriangleGroup);

    const _: () = {
        assert!(core::mem::size_of::<super::FrameParams>() == 6 * 16 + 112);
        assert!(core::mem::size_of::<super::GpuTriangleGroup>() == 48);
        assert!(core::mem::size_of::<super::GpuLight>() == 5 * 16 + 64);
        assert!(core::mem::size_of::<super::GpuSphere>() == 32);
        assert!(core::mem::size_of::<super::GpuTriangle>() == 64);
    };
}
