//! Buffer layouts shared by the host and the kernels of more than one pass.
//! They are written once, here; a pass's own parameter block lives in the
//! pass's module (`shafts::ShaftsParams`, ...).
//!
//! Every struct is built from `Vec4`s and groups of four 32-bit scalars, so that its
//! layout is the same on the host (Rust `repr(C)`) and in SPIR-V (rust-gpu emits the
//! offsets of the Rust layout), with no `vec3` padding surprises.

use crate::glam::Vec4;

/// The block every kernel may read: camera, medium, image, band and sample,
/// and the scene's counts.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct CommonParams {
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
    /// The per-pixel kernels write pixels `band_start .. band_start + band_pixels`
    /// (row-major) into buffers of `band_pixels` elements; the host splits
    /// images larger than one device buffer into such bands of whole rows.
    pub band_start: u32,
    pub band_pixels: u32,
    pub light_count: u32,
    pub sphere_count: u32,
    pub triangle_count: u32,
    /// Nodes of the triangle BVH (0 without triangles).
    pub bvh_node_count: u32,
    /// Total number of shadow-map texels over all lights.
    pub shadow_texel_count: u32,
    /// One of the `PHASE_*` constants.
    pub phase_kind: u32,
    /// Henyey-Greenstein asymmetry `g` (only for `PHASE_HENYEY_GREENSTEIN`).
    pub phase_g: f32,
    /// Sub-pixel samples per pixel (1: the pixel centre); see `camera::sample_offset`.
    pub samples_per_pixel: u32,
    /// Which of the `samples_per_pixel` positions this dispatch renders.
    pub sample_index: u32,
    /// `SHADOWS_RAYS` or `SHADOWS_MAP`: how directly seen surfaces test
    /// their visibility of each light.
    pub surface_shadows: u32,
    /// `PROJECTION_PINHOLE` or `PROJECTION_FISHEYE` (see `camera::camera_ray`).
    pub projection: u32,
    pub _pad: u32,
}

/// A pinhole camera: `camera_right` and `camera_up` are scaled by the
/// half-extents of the image plane at distance 1.
pub const PROJECTION_PINHOLE: u32 = 0;
/// An equidistant fisheye over the hemisphere around `camera_forward`:
/// the distance from the image centre is proportional to the angle from the
/// view direction, 90 degrees at the inscribed circle (`camera_right`,
/// `camera_up` unit axes).
pub const PROJECTION_FISHEYE: u32 = 1;

pub const PHASE_ISOTROPIC: u32 = 0;
pub const PHASE_HENYEY_GREENSTEIN: u32 = 1;
pub const PHASE_RAYLEIGH: u32 = 2;
/// `1 + 9 cos^16(a/2)` of the 2002 shafts-of-light paper, normalised.
pub const PHASE_DOBASHI: u32 = 3;

/// Surfaces seen directly cast a shadow ray to each light through the BVH.
pub const SHADOWS_RAYS: u32 = 0;
/// Surfaces seen directly look their shadows up in the lights' shadow maps.
pub const SHADOWS_MAP: u32 = 1;

pub const LIGHT_SPOT: u32 = 0;
pub const LIGHT_DIRECTIONAL: u32 = 1;
/// A point light: `power` is its radiant intensity, W/sr, the same in every
/// direction (no cone, no light map, no shadow map: surfaces test it with
/// shadow rays). A line light becomes a row of them.
pub const LIGHT_POINT: u32 = 2;

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
    /// `LIGHT_SPOT`, `LIGHT_DIRECTIONAL` or `LIGHT_POINT`.
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
    /// Spot: `cos^2(cutoff)` and `sin^2(cutoff)`, the cone's quadric
    /// coefficients (`shafts::clip_to_cone`), computed once on the host.
    pub cos2_cutoff: f32,
    pub sin2_cutoff: f32,
    pub _pad: u32,
}

/// A sphere. `object` is the index of the scene's `[[object]]` it came
/// from; `material` indexes the material buffer.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuSphere {
    /// Centre xyz in metres, radius in w.
    pub center_radius: Vec4,
    pub object: u32,
    pub material: u32,
    pub _pad: [u32; 2],
}

/// A triangle (vertices in metres, w unused). Surfaces are two-sided.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuTriangle {
    pub v0: Vec4,
    pub v1: Vec4,
    pub v2: Vec4,
    pub object: u32,
    pub material: u32,
    /// Index of this triangle in the glass triangle list (`GlassTriangle`,
    /// whose vertices carry the smooth normals refraction uses), or
    /// `NO_OBJECT` for a triangle of an opaque object.
    pub glass: u32,
    pub _pad: u32,
}

pub const MATERIAL_DIFFUSE: u32 = 0;
/// Smooth glass: Fresnel refraction at its surface, Beer's law inside.
pub const MATERIAL_GLASS: u32 = 1;

/// How a surface reflects light.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuMaterial {
    /// Diffuse albedo per channel in [0, 1] (w unused).
    pub albedo: Vec4,
    /// One of the `MATERIAL_*` constants.
    pub kind: u32,
    /// A terrain's ripple texture: its record's index + 1 (0: none;
    /// `desert::ripples`).
    pub ripples: u32,
    pub _pad: [u32; 2],
    /// Glass: index of refraction per channel (w unused; 1 for diffuse).
    pub ior: Vec4,
    /// Glass: absorption coefficient inside per channel, 1/m (w unused).
    pub absorption: Vec4,
}

/// A vertex of a glass mesh: position (metres; w = 1) and the unit
/// outward normal refraction uses there (w: the object's diagonal, metres,
/// the range of a compressed light transport table), shared by the triangles
/// around it so that a tessellated curved surface refracts like the curve.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GlassVertex {
    pub position: Vec4,
    pub normal: Vec4,
    /// The tangent of the vertex's local frame (section 4; w unused):
    /// `caustics::frame_tangent` of the normal as the object was defined,
    /// turned with the object, so the frame turns with it.
    pub tangent: Vec4,
    /// The object's rotation from its definition to the scene (a unit
    /// quaternion, x y z w): its table holds the exit rays as defined, and
    /// stays valid however the object is turned or moved.
    pub rotation: Vec4,
    /// The object and material of the mesh it belongs to.
    pub object: u32,
    pub material: u32,
    /// Channels its material traces separately: 3 for dispersive glass, else 1.
    pub channels: u32,
    /// Sum of `channels` over the vertices before it: its light transport
    /// table starts at entry `table_block * directions`.
    pub table_block: u32,
}

/// A triangle of a glass mesh: indices of its three `GlassVertex`es and
/// the object it belongs to.
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GlassTriangle {
    pub vertices: [u32; 3],
    pub object: u32,
}

/// A node of the triangle BVH, flattened in depth-first order: the first
/// child of an inner node is the next node, `right` the second (the
/// kernels' nearest-first walk, `geometry::trace_nearest`), and `skip` the
/// node after its subtree (the f64 reference's walk).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GpuBvhNode {
    /// Box corners, metres (w unused), padded so that f32 rounding of the
    /// slab test cannot let a ray slip past a triangle inside.
    pub bounds_min: Vec4,
    pub bounds_max: Vec4,
    /// Leaf: its triangles are `first .. first + count`; inner: `count` = 0.
    pub first: u32,
    pub count: u32,
    /// Index of the node after this node's subtree (`bvh_node_count` at the end).
    pub skip: u32,
    /// Inner node: its second child (the first is the next node); leaf: 0.
    pub right: u32,
}

/// What the surface pass leaves for later passes at every pixel (G-buffer).
#[repr(C)]
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct GBufferTexel {
    /// Unit normal turned toward the viewer (xyz) and distance along the
    /// view ray to the surface, metres (w; `surface::MISS_DISTANCE` if none).
    pub normal_distance: Vec4,
    /// Index of the scene object seen (`NO_OBJECT` if none).
    pub object: u32,
    /// Its material (`NO_OBJECT` if none).
    pub material: u32,
    /// The caustic light this pixel sees (on the surface itself, or behind
    /// glass), rgb W/(m^2 sr), packed by `caustics::pack_rgb`; 0 without
    /// caustics maps. The caustics pass turns it into its layer.
    pub caustic: [u32; 2],
}

/// `GBufferTexel::object` and `material` of a pixel that sees no surface.
pub const NO_OBJECT: u32 = u32::MAX;

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
    pod!(
        super::CommonParams,
        super::GpuLight,
        super::GpuSphere,
        super::GpuTriangle,
        super::GpuMaterial,
        super::GpuBvhNode,
        super::GBufferTexel,
        super::GlassVertex,
        super::GlassTriangle
    );

    const _: () = {
        assert!(core::mem::size_of::<super::CommonParams>() == 6 * 16 + 64);
        assert!(core::mem::size_of::<super::GpuLight>() == 5 * 16 + 64);
        assert!(core::mem::size_of::<super::GpuSphere>() == 32);
        assert!(core::mem::size_of::<super::GpuTriangle>() == 64);
        assert!(core::mem::size_of::<super::GpuMaterial>() == 64);
        assert!(core::mem::size_of::<super::GpuBvhNode>() == 48);
        assert!(core::mem::size_of::<super::GBufferTexel>() == 32);
        assert!(core::mem::size_of::<super::GlassVertex>() == 80);
        assert!(core::mem::size_of::<super::GlassTriangle>() == 16);
    };
}
