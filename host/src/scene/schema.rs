//! The scene file's format (TOML), as serde reads it. Documented for users
//! in `scenes/README.md`.

use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub camera: Camera,
    #[serde(default)]
    pub medium: Medium,
    #[serde(default)]
    pub spotlight: Vec<Spotlight>,
    #[serde(default)]
    pub directional_light: Vec<DirectionalLight>,
    #[serde(default)]
    pub point_light: Vec<PointLight>,
    #[serde(default)]
    pub line_light: Vec<LineLight>,
    #[serde(default)]
    pub object: Vec<Object>,
    #[serde(default)]
    pub shafts: crate::shafts::Settings,
    #[serde(default)]
    pub surface: crate::common::surface::Settings,
    pub sky: Option<crate::sky::Settings>,
    pub sea: Option<crate::sea::Settings>,
    #[serde(default)]
    pub caustics: crate::caustics::Settings,
    /// Local media in boxes (`[[volume]]`), and how they are rendered (`[volumes]`).
    #[serde(default)]
    pub volume: Vec<crate::volumes::Volume>,
    #[serde(default)]
    pub volumes: crate::volumes::Settings,
    /// Height fields (`[[terrain]]`): dunes, ripples, images.
    #[serde(default)]
    pub terrain: Vec<crate::desert::Terrain>,
    /// The instant shown (`[time]`); an animation's frames count from it.
    #[serde(default)]
    pub time: Time,
    /// `[[keyframe]]`s are taken out before the file is read into this
    /// (`scene::keyframes`); the key is listed so its absence is no error.
    #[serde(default, skip_deserializing)]
    pub keyframe: (),
}

/// `[time]`: the scene's clock.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Time {
    /// Seconds at the instant a still shows (default 0); `render --frames`
    /// shows frame `f` at `seconds + f / fps`. Simulations (smoke) run to it.
    #[serde(default)]
    pub seconds: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view of a pinhole camera (a fisheye sees 180 degrees).
    pub vfov_deg: Option<f32>,
    #[serde(default)]
    pub projection: Projection,
    pub resolution: [u32; 2],
    #[serde(default = "one")]
    pub exposure: f32,
    /// Sub-pixel samples per pixel, box-filtered (1: the pixel centre).
    #[serde(default = "one_u32")]
    pub samples_per_pixel: u32,
}

#[derive(Debug, Default, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Projection {
    #[default]
    Pinhole,
    /// Equidistant over the hemisphere around the view direction.
    Fisheye,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Medium {
    /// 1/m per channel.
    pub sigma_s: [f32; 3],
    /// 1/m per channel.
    pub sigma_t: [f32; 3],
    #[serde(default)]
    pub phase: Phase,
}

impl Default for Medium {
    fn default() -> Self {
        Medium { sigma_s: [0.0; 3], sigma_t: [0.0; 3], phase: Phase::Isotropic }
    }
}

#[derive(Debug, Default, Deserialize, Clone, Copy)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Phase {
    #[default]
    Isotropic,
    HenyeyGreenstein {
        g: f32,
    },
    Rayleigh,
    /// `1 + 9 cos^16(a/2)` of the 2002 paper, normalised.
    Dobashi2002,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spotlight {
    pub position: [f32; 3],
    pub direction: [f32; 3],
    pub up: Option<[f32; 3]>,
    pub cutoff_deg: f32,
    pub beam_deg: Option<f32>,
    /// W/sr per channel.
    pub intensity: [f32; 3],
    pub light_map: Option<PathBuf>,
    pub shadow_map_resolution: Option<u32>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DirectionalLight {
    pub direction: [f32; 3],
    pub up: Option<[f32; 3]>,
    /// W/m^2 per channel, on a surface facing the light.
    pub irradiance: [f32; 3],
    pub origin: Option<[f32; 3]>,
    pub light_map: Option<PathBuf>,
    /// Width and height of the window the light map covers, metres.
    pub size: Option<[f32; 2]>,
    pub shadow_map_resolution: Option<u32>,
}

/// A light radiating the same intensity in every direction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointLight {
    pub position: [f32; 3],
    /// W/sr per channel.
    pub intensity: [f32; 3],
}

/// A segment radiating like a row of point lights: `intensity` W/sr per
/// metre of its length, per channel.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineLight {
    pub from: [f32; 3],
    pub to: [f32; 3],
    pub intensity: [f32; 3],
    /// Point lights it becomes (default: one per 5 cm, 4 to 64).
    pub points: Option<u32>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Object {
    Sphere(SphereObject),
    Box(BoxObject),
    Quad(QuadObject),
    Mesh(MeshObject),
    Torus(TorusObject),
    TrefoilKnot(TrefoilKnotObject),
    Lathe(LatheObject),
}

/// What an object is made of; without one, a diffuse surface of the
/// object's `albedo`.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Material {
    Diffuse,
    Glass {
        ior: Ior,
        /// 1/m per channel (Beer's law inside).
        #[serde(default)]
        absorption: [f32; 3],
    },
}

/// A turn of an object about its own centre (a sphere's, box's, quad's,
/// torus's or knot's `center`; a mesh's origin, after `scale`, before
/// `translate`): `deg` degrees about `axis`, counter-clockwise seen from
/// the axis's tip. A glass object keeps its light transport table when
/// turned or moved.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rotation {
    pub axis: [f32; 3],
    pub deg: f32,
}

/// One index of refraction, or one per channel (dispersion).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
pub enum Ior {
    One(f32),
    Rgb([f32; 3]),
}

impl Ior {
    pub fn rgb(self) -> [f32; 3] {
        match self {
            Ior::One(n) => [n; 3],
            Ior::Rgb(v) => v,
        }
    }
}

/// A trefoil knot: the curve `(sin t + 2 sin 2t, cos t - 2 cos 2t, -sin 3t)`
/// scaled by `scale` around `center` (x, z horizontal, y up from the third
/// coordinate), swept by a tube of radius `tube_radius`, tessellated into
/// `segments[0] x segments[1] x 2` triangles (along the curve, around the tube).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrefoilKnotObject {
    pub center: [f32; 3],
    pub scale: f32,
    pub tube_radius: f32,
    #[serde(default = "default_knot_segments")]
    pub segments: [u32; 2],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

fn default_knot_segments() -> [u32; 2] {
    [256, 24]
}

/// A solid of revolution: the outline `profile` (pairs `[r, h]`, metres:
/// distance from the axis and height along it from `center`) turned about
/// `axis` through `center`, tessellated into `segments` slices. The outline
/// runs from the axis back to the axis (first and last `r` = 0, every other
/// `r` > 0): bottom, sides, top, so that it bounds a closed solid. Vertex
/// normals follow the outline smoothly, except at corners sharper than
/// `sharp_deg`, where each side keeps its own.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatheObject {
    pub center: [f32; 3],
    #[serde(default = "default_up")]
    pub axis: [f32; 3],
    pub profile: Vec<[f32; 2]>,
    #[serde(default = "default_lathe_segments")]
    pub segments: u32,
    #[serde(default = "default_sharp_deg")]
    pub sharp_deg: f32,
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

fn default_lathe_segments() -> u32 {
    96
}

fn default_sharp_deg() -> f32 {
    40.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereObject {
    pub center: [f32; 3],
    pub radius: f32,
    /// A glass sphere is tessellated (the caustics method works on a mesh's
    /// vertices): `[around, pole to pole]`, default `[96, 64]` (6 050 vertices).
    pub segments: Option<[u32; 2]>,
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxObject {
    pub min: [f32; 3],
    pub max: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

/// The rectangle `center +- u/2 +- v/2`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadObject {
    pub center: [f32; 3],
    pub u: [f32; 3],
    pub v: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshObject {
    pub file: PathBuf,
    #[serde(default = "one")]
    pub scale: f32,
    #[serde(default)]
    pub translate: [f32; 3],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

/// A torus around `axis` through `center`: tube radius `minor_radius` swept
/// around a circle of radius `major_radius`, tessellated into
/// `segments[0] x segments[1] x 2` triangles (around the axis, around the tube).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TorusObject {
    pub center: [f32; 3],
    #[serde(default = "default_up")]
    pub axis: [f32; 3],
    pub major_radius: f32,
    pub minor_radius: f32,
    #[serde(default = "default_torus_segments")]
    pub segments: [u32; 2],
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    pub material: Option<Material>,
    pub rotation: Option<Rotation>,
}

fn default_torus_segments() -> [u32; 2] {
    [96, 48]
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn one() -> f32 {
    1.0
}
fn one_u32() -> u32 {
    1
}
fn default_albedo() -> [f32; 3] {
    [0.8; 3]
}
