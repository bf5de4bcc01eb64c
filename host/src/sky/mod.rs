//! The sky passes (kernels: `shader-crate/src/sky/`): the transmittance
//! table, the optional sky-view table, and the per-pixel sky; their settings
//! (the scene's `[sky]` table) and the sun as a light on the scene.

pub mod bench;
pub mod glass;
pub mod reference;

use anyhow::{bail, Result};
use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use serde::Deserialize;
use slicelight_shaders::sky::light::{
    irradiance_texel, sky_light_pixel, sphere_texel, visibility_pixel, SkyTables, IRRADIANCE_HEIGHT, IRRADIANCE_WIDTH,
    SPHERE_DIRECTIONS,
};
use slicelight_shaders::sky::{
    hits_ground, optical_depth_to_top, sky_pixel, sky_view_texel, transmittance_texel, SkyParams, MIE_CORNETTE_SHANKS,
    MIE_HENYEY_GREENSTEIN,
};
use slicelight_shaders::types::{CommonParams, GBufferTexel};

use crate::passes::*;

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[
    &SkyTransmittance,
    &SkyView,
    &SkySphere,
    &SkyIrradiance,
    &Sky,
    &glass::SkyGlass,
    &SkyVisibility,
    &SkyLight,
    &Aerial,
];

/// The family, as `passes::FAMILIES` registers it.
pub static FAMILY: Family = Family { name: "sky", passes: PASSES, kernels: &[], bench: Some(&bench::SkySweep) };
use crate::cpu::for_each_invocation;
use crate::scene::validate::positive;
use crate::scene::{invalid, validate, SceneData};

pub static SKY_PARAMS: Resource =
    Resource { binding: 15, name: "sky parameters", kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.sky.params)) };
/// Optical depth (rgb) to the top of the atmosphere over heights and directions.
pub static SKY_TRANSMITTANCE: Resource = Resource {
    binding: 16,
    name: "sky transmittance table",
    kind: ResourceKind::Frame(|s| s.sky.transmittance_texels() * 16),
};
/// Sky radiance (rgb) over view directions.
pub static SKY_VIEW: Resource =
    Resource { binding: 17, name: "sky-view table", kind: ResourceKind::Frame(|s| s.sky.sky_view_texels() * 16) };
/// Sky radiance per pixel (rgb) where no surface is seen.
pub static SKY_RADIANCE: Resource =
    Resource { binding: 18, name: "sky radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The sky's radiance (rgb) toward the irradiance quadrature's directions.
pub static SKY_SPHERE: Resource = Resource {
    binding: 87,
    name: "sky radiance over the sphere",
    kind: ResourceKind::Frame(|_| SPHERE_DIRECTIONS as u64 * 16),
};
/// The skylight's irradiance over normals (`sky::light`).
pub static SKY_IRRADIANCE: Resource = Resource {
    binding: 62,
    name: "sky irradiance table",
    kind: ResourceKind::Frame(|_| (IRRADIANCE_WIDTH * IRRADIANCE_HEIGHT) as u64 * 16),
};
pub static SKY_LIGHT_RADIANCE: Resource =
    Resource { binding: 63, name: "skylight radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The skylight's visibility `V` (rgb; w 1) at the pixels that trace it.
pub static SKY_VISIBILITY: Resource =
    Resource { binding: 86, name: "skylight visibility", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The air's light in front of the surfaces (aerial perspective).
pub static AERIAL_RADIANCE: Resource =
    Resource { binding: 64, name: "aerial radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The air's transmittance to the surfaces (rgb; w 1).
pub static AERIAL_TRANSMITTANCE: Resource = Resource {
    binding: 65,
    name: "aerial transmittance",
    kind: ResourceKind::PerPixel { blank: || bytemuck::bytes_of(&Vec4::ONE).to_vec() },
};

/// The scene's `[sky]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Angle of the sun from the zenith, degrees (above 90: below the horizon).
    pub sun_zenith_deg: f32,
    /// Azimuth of the sun, degrees from +z toward +x (y is up).
    #[serde(default)]
    pub sun_azimuth_deg: f32,
    /// Solar irradiance normal to the sun's rays at the top of the
    /// atmosphere, W/m^2 per channel.
    #[serde(default = "unit3")]
    pub sun_irradiance: [f32; 3],
    /// Angular radius of the sun's disk, degrees.
    #[serde(default = "sun_radius")]
    pub sun_angular_radius_deg: f32,
    /// Altitude of the observer (the camera) above the ground, m.
    #[serde(default)]
    pub observer_altitude_m: f32,
    /// Lambertian albedo of the ground below the horizon.
    #[serde(default = "ground_albedo")]
    pub ground_albedo: [f32; 3],
    /// Whether the sun lights the scene's surfaces (a directional light of
    /// the sun's colour after the air it crosses to the observer).
    #[serde(default = "yes")]
    pub light_scene: bool,
    /// Whether the sky's own light (not the sun's) falls on the scene's
    /// diffuse surfaces (with `light_scene`).
    #[serde(default = "yes")]
    pub sky_light: bool,
    /// Rays per pixel finding how much of the sky a surface sees (0:
    /// unshadowed skylight).
    #[serde(default = "sky_light_rays")]
    pub sky_light_rays: u32,
    /// Pixels between the pixels that trace those rays, across and down
    /// (1: every pixel traces its own; 2: one in each 2x2 block, the others
    /// take theirs where they see the same surface).
    #[serde(default = "sky_light_spacing")]
    pub sky_light_spacing: u32,
    /// Whether the air between the eye and the surfaces scatters the sun's
    /// light toward the eye and dims what lies behind it.
    #[serde(default = "yes")]
    pub aerial_perspective: bool,
    /// Quadrature samples per view ray.
    #[serde(default = "view_samples")]
    pub view_samples: u32,
    /// Quadrature samples per ray of the transmittance table.
    #[serde(default = "table_samples")]
    pub table_samples: u32,
    /// Transmittance table size: directions x heights.
    #[serde(default = "transmittance_table")]
    pub transmittance_table: [u32; 2],
    /// Look the sky up in a table over view directions (else integrate it per pixel).
    #[serde(default = "yes")]
    pub sky_view: bool,
    /// Sky-view table size: azimuths x elevations (even; half below the horizon).
    #[serde(default = "sky_view_table")]
    pub sky_view_table: [u32; 2],
    #[serde(default)]
    pub atmosphere: Atmosphere,
}

fn unit3() -> [f32; 3] {
    [1.0; 3]
}
fn sun_radius() -> f32 {
    0.2666
}
fn ground_albedo() -> [f32; 3] {
    [0.1; 3]
}
fn yes() -> bool {
    true
}
fn sky_light_rays() -> u32 {
    8
}
fn sky_light_spacing() -> u32 {
    2
}
fn view_samples() -> u32 {
    32
}
fn table_samples() -> u32 {
    // 64 until 2026-12-06: against 256 samples, 32 is within 1.2e-3 of the
    // image (relative, at worst; sky_sunset, sea_sunset) and 0.04 % of the
    // 8-bit range RMS, for half the table's time (docs/sky.md).
    32
}
fn transmittance_table() -> [u32; 2] {
    [256, 64]
}
fn sky_view_table() -> [u32; 2] {
    [192, 128]
}

/// `[sky.atmosphere]`: Earth's by default.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Atmosphere {
    pub ground_radius_m: f32,
    pub top_radius_m: f32,
    /// Rayleigh scattering at the ground, 1/m per channel.
    pub rayleigh_scattering: [f32; 3],
    pub rayleigh_scale_height_m: f32,
    /// Aerosols; none unless given.
    pub mie: Option<Mie>,
    /// Ozone; none unless given.
    pub ozone: Option<Ozone>,
}

impl Default for Atmosphere {
    fn default() -> Self {
        Atmosphere {
            ground_radius_m: 6_360_000.0,
            top_radius_m: 6_420_000.0,
            rayleigh_scattering: [5.802e-6, 13.558e-6, 33.1e-6],
            rayleigh_scale_height_m: 8000.0,
            mie: None,
            ozone: None,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Mie {
    /// At the ground, 1/m.
    pub scattering: f32,
    /// At the ground, 1/m (scattering plus absorption).
    pub extinction: f32,
    pub scale_height_m: f32,
    pub phase: MiePhase,
    pub g: f32,
}

impl Default for Mie {
    fn default() -> Self {
        Mie {
            scattering: 3.996e-6,
            extinction: 1.11 * 3.996e-6,
            scale_height_m: 1200.0,
            phase: MiePhase::CornetteShanks,
            g: 0.8,
        }
    }
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MiePhase {
    HenyeyGreenstein,
    #[default]
    CornetteShanks,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ozone {
    /// Absorption at the layer's peak, 1/m per channel.
    pub absorption: [f32; 3],
    pub center_m: f32,
    pub half_width_m: f32,
}

impl Default for Ozone {
    fn default() -> Self {
        Ozone { absorption: [0.650e-6, 1.881e-6, 0.085e-6], center_m: 25_000.0, half_width_m: 15_000.0 }
    }
}

/// The sky's state for one scene.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    /// Whether the scene has a `[sky]`.
    pub enabled: bool,
    pub params: SkyParams,
    /// Whether the sky lights the scene's surfaces (`sky_light` and `light_scene`).
    pub light: bool,
    /// Whether the air in front of the surfaces is drawn (`aerial_perspective`).
    pub aerial: bool,
    /// The references' skylight grid (`reference::sky_light_grid`), made
    /// the first time a reference needs it.
    pub reference_grid: std::sync::OnceLock<Vec<(glam::DVec3, glam::DVec3)>>,
}

impl Setup {
    pub fn transmittance_texels(&self) -> u64 {
        if self.enabled {
            self.params.transmittance_width as u64 * self.params.transmittance_height as u64
        } else {
            0
        }
    }
    pub fn sky_view_texels(&self) -> u64 {
        if self.enabled && self.params.use_sky_view != 0 {
            self.params.sky_view_width as u64 * self.params.sky_view_height as u64
        } else {
            0
        }
    }

    /// The sun's irradiance (W/m^2 per channel, normal to its rays) at the
    /// observer, after the air it crosses, and the unit direction toward
    /// it; `None` when the sun is below the horizon or dimmed to nothing.
    /// The optical depth is the transmittance table kernel's quadrature.
    pub fn sun_at_observer(&self) -> Option<(Vec3, Vec3)> {
        let p = &self.params;
        let sun = p.sun_direction.truncate();
        let h = p.observer_altitude.min(p.atmosphere_height);
        if hits_ground(p, h, sun.y).0 {
            return None;
        }
        let tau = optical_depth_to_top(p, h, sun.y, p.table_samples.max(256));
        let e = p.sun_irradiance.truncate() * (-tau).exp();
        (e.max_element() > 0.0).then_some((e, sun))
    }
}

/// The largest coefficient of the atmosphere, 1/m: fog with a visibility
/// of 3 m (clear air's are about 1e-5); the tables' optical depths then
/// stay finite over the atmosphere's depth.
const MAX_COEFFICIENT: f32 = 1.0;

/// An atmosphere's coefficient (1/m): non-negative, up to `MAX_COEFFICIENT`.
fn non_negative(field: &str, v: f32) -> Result<f32> {
    if !(v.is_finite() && (0.0..=MAX_COEFFICIENT).contains(&v)) {
        bail!(invalid(field, "a coefficient in [0, 1] per metre", v));
    }
    Ok(v)
}

/// Three atmosphere coefficients (1/m), each as `non_negative`.
fn coefficients(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if !v.iter().all(|x| x.is_finite() && (0.0..=MAX_COEFFICIENT).contains(x)) {
        bail!(invalid(field, "three coefficients in [0, 1] per metre", v));
    }
    Ok(Vec3::from(v))
}

fn table_size(field: &str, size: [u32; 2], even_rows: bool) -> Result<()> {
    if !size.iter().all(|n| (2..=8192).contains(n)) || (even_rows && (size[1] < 4 || !size[1].is_multiple_of(2))) {
        let what =
            if even_rows { "two sizes in 2..=8192, the second even and at least 4" } else { "two sizes in 2..=8192" };
        bail!(invalid(field, what, size));
    }
    Ok(())
}

/// Validates `[sky]` and returns the sky's setup; the error names the
/// field under `sky.`.
pub fn configure(s: &Settings) -> Result<Setup> {
    if !(s.sun_zenith_deg.is_finite() && (0.0..=180.0).contains(&s.sun_zenith_deg)) {
        bail!(invalid("sky.sun_zenith_deg", "an angle in [0, 180] degrees", s.sun_zenith_deg));
    }
    if !s.sun_azimuth_deg.is_finite() {
        bail!(invalid("sky.sun_azimuth_deg", "a finite angle in degrees", s.sun_azimuth_deg));
    }
    let irradiance = validate::non_negative3("sky.sun_irradiance", s.sun_irradiance)?;
    if !(s.sun_angular_radius_deg > 0.0 && s.sun_angular_radius_deg <= 10.0) {
        bail!(invalid("sky.sun_angular_radius_deg", "an angle in (0, 10] degrees", s.sun_angular_radius_deg));
    }
    if !(s.observer_altitude_m.is_finite() && s.observer_altitude_m >= 0.0 && s.observer_altitude_m <= 1e7) {
        bail!(invalid("sky.observer_altitude_m", "an altitude in [0, 1e7] m", s.observer_altitude_m));
    }
    let albedo = validate::albedo("sky.ground_albedo", s.ground_albedo)?;
    if !(1..=65536).contains(&s.view_samples) {
        bail!(invalid("sky.view_samples", "a sample count in 1..=65536", s.view_samples));
    }
    if !(1..=65536).contains(&s.table_samples) {
        bail!(invalid("sky.table_samples", "a sample count in 1..=65536", s.table_samples));
    }
    if s.sky_light_rays > 1024 {
        bail!(invalid("sky.sky_light_rays", "0 to 1024 rays per pixel", s.sky_light_rays));
    }
    if !(1..=8).contains(&s.sky_light_spacing) {
        bail!(invalid("sky.sky_light_spacing", "1 to 8 pixels", s.sky_light_spacing));
    }
    table_size("sky.transmittance_table", s.transmittance_table, false)?;
    table_size("sky.sky_view_table", s.sky_view_table, true)?;
    let a = &s.atmosphere;
    // Planets from a small moon's 1e5 m to a gas giant's 1e8 m; an
    // atmosphere 1 km to 1e7 m deep: f32 then resolves metres of altitude
    // and r^2 stays far from overflow.
    let ground = a.ground_radius_m;
    if !(ground.is_finite() && (1e5..=1e8).contains(&ground)) {
        bail!(invalid("sky.atmosphere.ground_radius_m", "a planet's radius in [1e5, 1e8] m", ground));
    }
    let top = a.top_radius_m;
    if !(top.is_finite() && top - ground >= 1e3 && top - ground <= 1e7) {
        bail!(invalid(
            "sky.atmosphere.top_radius_m",
            "a radius 1e3 to 1e7 m above ground_radius_m (the atmosphere's depth)",
            top
        ));
    }
    let rayleigh = coefficients("sky.atmosphere.rayleigh_scattering", a.rayleigh_scattering)?;
    let rayleigh_h = positive("sky.atmosphere.rayleigh_scale_height_m", a.rayleigh_scale_height_m)?;
    let (mie, mie_phase) = match &a.mie {
        None => (Vec4::new(0.0, 0.0, 1200.0, 0.0), MIE_HENYEY_GREENSTEIN),
        Some(m) => {
            let sc = non_negative("sky.atmosphere.mie.scattering", m.scattering)?;
            let ext = non_negative("sky.atmosphere.mie.extinction", m.extinction)?;
            if ext < sc {
                bail!(invalid("sky.atmosphere.mie.extinction", "at least mie.scattering", m.extinction));
            }
            let height = positive("sky.atmosphere.mie.scale_height_m", m.scale_height_m)?;
            if !(m.g > -1.0 && m.g < 1.0) {
                bail!(invalid("sky.atmosphere.mie.g", "a number in (-1, 1)", m.g));
            }
            let kind = match m.phase {
                MiePhase::HenyeyGreenstein => MIE_HENYEY_GREENSTEIN,
                MiePhase::CornetteShanks => MIE_CORNETTE_SHANKS,
            };
            (Vec4::new(sc, ext, height, m.g), kind)
        }
    };
    let (ozone, ozone_center, ozone_half) = match &a.ozone {
        None => (Vec3::ZERO, 0.0, 0.0),
        Some(o) => {
            let abs = coefficients("sky.atmosphere.ozone.absorption", o.absorption)?;
            if !o.center_m.is_finite() {
                bail!(invalid("sky.atmosphere.ozone.center_m", "a finite height in m", o.center_m));
            }
            (abs, o.center_m, positive("sky.atmosphere.ozone.half_width_m", o.half_width_m)?)
        }
    };
    let (zenith, azimuth) = (s.sun_zenith_deg.to_radians(), s.sun_azimuth_deg.to_radians());
    let sun = Vec3::new(zenith.sin() * azimuth.sin(), zenith.cos(), zenith.sin() * azimuth.cos());
    let radius = s.sun_angular_radius_deg.to_radians();
    // 2 pi (1 - cos r), written without the cancellation that costs f32 0.5 % at the sun's size.
    let solid_angle = (4.0 * std::f64::consts::PI * (0.5 * radius as f64).sin().powi(2)) as f32;
    let params = SkyParams {
        sun_direction: sun.extend(radius.cos()),
        sun_irradiance: irradiance.extend(solid_angle),
        rayleigh: rayleigh.extend(rayleigh_h),
        mie,
        ozone: ozone.extend(0.0),
        ground_albedo: albedo,
        ground_radius: ground,
        atmosphere_height: top - ground,
        observer_altitude: s.observer_altitude_m,
        ozone_center,
        ozone_half_width: ozone_half,
        mie_phase,
        view_samples: s.view_samples,
        table_samples: s.table_samples,
        transmittance_width: s.transmittance_table[0],
        transmittance_height: s.transmittance_table[1],
        sky_view_width: s.sky_view_table[0],
        sky_view_height: s.sky_view_table[1],
        use_sky_view: s.sky_view as u32,
        horizon: 0.0,
        sea: 0,
        light_rays: s.sky_light_rays,
        lights_surfaces: (s.sky_light && s.light_scene) as u32,
        light_spacing: s.sky_light_spacing,
        pad: [0; 2],
    };
    let params = SkyParams { horizon: slicelight_shaders::sky::horizon_elevation(&params), ..params };
    Ok(Setup {
        enabled: true,
        params,
        light: s.sky_light && s.light_scene,
        aerial: s.aerial_perspective,
        reference_grid: Default::default(),
    })
}

fn skip_without_sky(scene: &SceneData) -> Option<Plan> {
    (!scene.sky.enabled).then(|| Plan::skip("no [sky]"))
}

pub struct SkyTransmittance;

impl Pass for SkyTransmittance {
    fn name(&self) -> &'static str {
        "sky_transmittance"
    }
    fn kernel(&self) -> &'static str {
        "sky::transmittance_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SKY_PARAMS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_TRANSMITTANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky(scene) {
            return skip;
        }
        let p = &scene.sky.params;
        Plan::run(
            format!(
                "optical depth to the top of the atmosphere (eq. 2), {}x{} table, {} samples per ray",
                p.transmittance_width, p.transmittance_height, p.table_samples
            ),
            scene.sky.transmittance_texels(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sky.params;
        frame.write::<Vec4>(&SKY_TRANSMITTANCE, scene.sky.transmittance_texels() as usize, |_, out| {
            for_each_invocation(out, 0, progress, |i, v| *v = transmittance_texel(i, p));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A sum of 128 products of f32 exps: 1e-5 of the largest depth
        // (about 40 ulps of a value near it).
        compare_rgb("optical depths", gpu.get(&SKY_TRANSMITTANCE), cpu.get(&SKY_TRANSMITTANCE), 1e-5, 0)
    }
}

pub struct SkyView;

impl Pass for SkyView {
    fn name(&self) -> &'static str {
        "sky_view"
    }
    fn kernel(&self) -> &'static str {
        "sky::sky_view_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SKY_PARAMS, SKY_TRANSMITTANCE]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_VIEW]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky(scene) {
            return skip;
        }
        let p = &scene.sky.params;
        if p.use_sky_view == 0 {
            return Plan::skip("the sky is integrated per pixel (sky_view = false)");
        }
        Plan::run(
            format!(
                "sky radiance over {}x{} view directions, {} samples per ray",
                p.sky_view_width, p.sky_view_height, p.view_samples
            ),
            scene.sky.sky_view_texels(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sky.params;
        frame.write::<Vec4>(&SKY_VIEW, scene.sky.sky_view_texels() as usize, |frame, out| {
            let table = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
            for_each_invocation(out, 0, progress, |i, v| *v = sky_view_texel(i, p, table));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The radiance sums ~32 samples of products of about ten f32 factors
        // and exps, each ~1e-6 relative: 1e-4 of the peak is a wide margin.
        compare_rgb("sky-view radiance", gpu.get(&SKY_VIEW), cpu.get(&SKY_VIEW), 1e-4, 0)
    }
}

pub struct Sky;

impl Pass for Sky {
    fn name(&self) -> &'static str {
        "sky"
    }
    fn kernel(&self) -> &'static str {
        "sky::sky_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER, SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SKY_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky(scene) {
            return skip;
        }
        let how = if scene.sky.params.use_sky_view != 0 {
            "looked up in the sky-view table".to_string()
        } else {
            format!("integrated per pixel, {} samples per ray", scene.sky.params.view_samples)
        };
        Plan::run(format!("sky where no surface is seen, {how}, and the sun's disk"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let p = &scene.sky.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        frame.write_all::<Vec4>(&SKY_RADIANCE, n, |frame, out| {
            let transmittance = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
            let sky_view = frame.get::<Vec4>(&SKY_VIEW);
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
                *v = sky_pixel(i, common, p, transmittance, sky_view, texel);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The pixel's direction and its table coordinates go through sin,
        // cos, asin and acos, which Vulkan lets a device compute to an
        // absolute 2^-11 (sin, cos) or 4096 ulps (the inverses): directions
        // may differ by ~5e-4 rad between the backends, and the sky's
        // steepest slopes (the sun's aureole, the horizon) are a few times
        // its peak per radian, so 2e-3 of the peak (lavapipe: 5e-4 seen). A
        // pixel on the disk's rim or on the horizon may flip between sky
        // and sun or ground: at most 1e-3 of the values.
        let cpu_values = cpu.get::<Vec4>(&SKY_RADIANCE);
        compare_rgb("sky radiance", gpu.get(&SKY_RADIANCE), cpu_values, 2e-3, cpu_values.len() * 3 / 1000 + 1)
    }
}

/// Why the skylight does not run, if it does not.
fn skip_without_sky_light(scene: &SceneData) -> Option<Plan> {
    if let Some(skip) = skip_without_sky(scene) {
        return Some(skip);
    }
    if !scene.sky.light {
        return Some(Plan::skip("the sky does not light the scene (sky_light or light_scene false)"));
    }
    if !scene.has_geometry() {
        return Some(Plan::skip("no surfaces to light"));
    }
    None
}

/// The skylight's first table: the sky's radiance toward the directions
/// the irradiance quadrature sums, looked up once for all its normals.
pub struct SkySphere;

impl Pass for SkySphere {
    fn name(&self) -> &'static str {
        "sky_sphere"
    }
    fn kernel(&self) -> &'static str {
        "sky::sphere_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_SPHERE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky_light(scene) {
            return skip;
        }
        Plan::run(format!("the sky's radiance toward {SPHERE_DIRECTIONS} directions"), SPHERE_DIRECTIONS as u64)
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sky.params;
        frame.write::<Vec4>(&SKY_SPHERE, SPHERE_DIRECTIONS as usize, |frame, out| {
            let transmittance = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
            let sky_view = frame.get::<Vec4>(&SKY_VIEW);
            for_each_invocation(out, 0, progress, |i, v| *v = sphere_texel(i, p, transmittance, sky_view));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Sky-view lookups, each through asin and acos (4096 ulps on
        // Vulkan) and the direction through sin and cos: as `Sky::compare`,
        // 2e-3 of the peak; a direction on the horizon may flip between
        // sky and ground: at most 1e-3 of the values.
        let cpu_values = cpu.get::<Vec4>(&SKY_SPHERE);
        compare_rgb("sky sphere", gpu.get(&SKY_SPHERE), cpu_values, 2e-3, cpu_values.len() * 3 / 1000 + 1)
    }
}

pub struct SkyIrradiance;

impl Pass for SkyIrradiance {
    fn name(&self) -> &'static str {
        "sky_irradiance"
    }
    fn kernel(&self) -> &'static str {
        "sky::irradiance_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![SKY_PARAMS, SKY_SPHERE]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_IRRADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky_light(scene) {
            return skip;
        }
        Plan::run(
            format!(
                "the sky's irradiance over {IRRADIANCE_WIDTH}x{IRRADIANCE_HEIGHT} normals, {SPHERE_DIRECTIONS} sky directions each"
            ),
            (IRRADIANCE_WIDTH * IRRADIANCE_HEIGHT) as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.sky.params;
        frame.write::<Vec4>(&SKY_IRRADIANCE, (IRRADIANCE_WIDTH * IRRADIANCE_HEIGHT) as usize, |frame, out| {
            let sphere = frame.get::<Vec4>(&SKY_SPHERE);
            for_each_invocation(out, 0, progress, |i, v| *v = irradiance_texel(i, p, sphere));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A cosine-weighted sum of 3072 radiances: the GPU sums its own
        // sphere table (within 2e-3 of the peak, see `SkySphere::compare`),
        // so 1e-3 of the peak here (the errors average over the sum).
        compare_rgb("sky irradiance", gpu.get(&SKY_IRRADIANCE), cpu.get(&SKY_IRRADIANCE), 1e-3, 0)
    }
}

/// The skylight's first pass: `V` at the pixels that trace the visibility
/// rays (one in `light_spacing`^2), which `sky_light` spreads to the pixels
/// around them that see the same surface.
pub struct SkyVisibility;

impl Pass for SkyVisibility {
    fn name(&self) -> &'static str {
        "sky_visibility"
    }
    fn kernel(&self) -> &'static str {
        "sky::sky_visibility_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, SPHERES, TRIANGLES, BVH_NODES, MATERIALS, GBUFFER, SKY_PARAMS, SKY_TRANSMITTANCE, SKY_VIEW]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_VISIBILITY]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky_light(scene) {
            return skip;
        }
        let (rays, spacing) = (scene.sky.params.light_rays, scene.sky.params.light_spacing);
        if rays == 0 {
            return Plan::skip("no visibility rays (sky_light_rays = 0): the skylight is unshadowed");
        }
        let which = if spacing == 1 { "every pixel".to_string() } else { format!("one pixel in {spacing}x{spacing}") };
        Plan::run(format!("the sky a surface sees: {rays} rays at {which}"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let p = &scene.sky.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        let geometry = scene.geometry();
        frame.write_all::<Vec4>(&SKY_VISIBILITY, n, |frame, out| {
            let transmittance = frame.get::<Vec4>(&SKY_TRANSMITTANCE);
            let sky_view = frame.get::<Vec4>(&SKY_VIEW);
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
                *v = visibility_pixel(i, common, p, transmittance, sky_view, &geometry, &scene.materials, texel);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Shares of 8 rays weighted by the sky's radiance (sky-view lookups
        // through asin and acos, 4096 ulps on Vulkan): 1e-3; a ray that
        // grazes an edge may go either way on the two backends (1/8 of a
        // pixel's share), at most 1 % of the values.
        let cpu_values = cpu.get::<Vec4>(&SKY_VISIBILITY);
        compare_rgb("skylight visibility", gpu.get(&SKY_VISIBILITY), cpu_values, 1e-3, cpu_values.len() * 3 / 100 + 1)
    }
}

pub struct SkyLight;

impl Pass for SkyLight {
    fn name(&self) -> &'static str {
        "sky_light"
    }
    fn kernel(&self) -> &'static str {
        "sky::sky_light_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            GBUFFER,
            SKY_PARAMS,
            SKY_TRANSMITTANCE,
            SKY_VIEW,
            SKY_IRRADIANCE,
            SKY_VISIBILITY
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SKY_LIGHT_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SKY_LIGHT_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky_light(scene) {
            return skip;
        }
        let rays = scene.sky.params.light_rays;
        let shadow = if rays == 0 { "unshadowed".to_string() } else { "visibility from sky_visibility".to_string() };
        Plan::run(format!("the sky's light on diffuse surfaces (irradiance table), {shadow}"), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let p = &scene.sky.params;
        let geometry = scene.geometry();
        frame.write_all::<Vec4>(&SKY_LIGHT_RADIANCE, n, |frame, out| {
            let sky = SkyTables {
                p,
                transmittance: frame.get::<Vec4>(&SKY_TRANSMITTANCE),
                sky_view: frame.get::<Vec4>(&SKY_VIEW),
                irradiance: frame.get::<Vec4>(&SKY_IRRADIANCE),
            };
            let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
            let visibility = frame.get::<Vec4>(&SKY_VISIBILITY);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                *v = sky_light_pixel(i, common, &sky, &geometry, &scene.materials, gbuffer, visibility);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The irradiance table's bilinear lookup through acos and atan2 (4096
        // ulps on Vulkan) on a smooth table, and visibility rays that may
        // graze an edge differently on the two backends (a ray flips a
        // pixel's share by 1/8): 2e-3 of the peak, and at most 1 % of the
        // values beyond it.
        let cpu_values = cpu.get::<Vec4>(&SKY_LIGHT_RADIANCE);
        compare_rgb("skylight", gpu.get(&SKY_LIGHT_RADIANCE), cpu_values, 2e-3, cpu_values.len() * 3 / 100 + 1)
    }
}

pub struct Aerial;

impl Pass for Aerial {
    fn name(&self) -> &'static str {
        "sky_aerial"
    }
    fn kernel(&self) -> &'static str {
        "sky::aerial_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER, SKY_PARAMS, SKY_TRANSMITTANCE]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![AERIAL_RADIANCE, AERIAL_TRANSMITTANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&AERIAL_RADIANCE)
    }
    fn transmittance_layer(&self) -> Option<&'static Resource> {
        Some(&AERIAL_TRANSMITTANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_sky(scene) {
            return skip;
        }
        if !scene.sky.aerial {
            return Plan::skip("aerial_perspective = false");
        }
        if scene.sky.params.sea == slicelight_shaders::sky::SEA_AROUND {
            return Plan::skip("the eye is under the water");
        }
        if !scene.has_geometry() {
            return Plan::skip("no surfaces in front of the sky");
        }
        Plan::run(
            format!(
                "the air between the eye and the surfaces: its light and transmittance, a sample per {} m",
                slicelight_shaders::sky::aerial::AERIAL_STEP
            ),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let n = common.band_pixels as usize;
        let p = &scene.sky.params;
        let blank = slicelight_shaders::common::surface::no_surface();
        let mut light = vec![Vec4::ZERO; n];
        let mut through = vec![Vec4::ONE; n];
        let (gbuffer, table) = (frame.get::<GBufferTexel>(&GBUFFER), frame.get::<Vec4>(&SKY_TRANSMITTANCE));
        crate::cpu::for_each_invocation2(&mut light, &mut through, common.band_start, progress, |i, l, t| {
            let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
            (*l, *t) = slicelight_shaders::sky::aerial::aerial_pixel(i, common, p, table, texel);
        });
        frame.insert(&AERIAL_RADIANCE, Buffer::from_bytes(bytemuck::cast_slice(&light)));
        frame.insert(&AERIAL_TRANSMITTANCE, Buffer::from_bytes(bytemuck::cast_slice(&through)));
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Sums of up to 4 `view_samples` products of f32 exps and the
        // transmittance table's bilinear lookups, through the pixel's
        // direction (sin, cos to 2^-11 on Vulkan): 1e-3 of the peak.
        let radiance = compare_rgb("aerial radiance", gpu.get(&AERIAL_RADIANCE), cpu.get(&AERIAL_RADIANCE), 1e-3, 0)?;
        let t = compare_rgb(
            "aerial transmittance",
            gpu.get(&AERIAL_TRANSMITTANCE),
            cpu.get(&AERIAL_TRANSMITTANCE),
            1e-4,
            0,
        )?;
        Ok(format!("{radiance}; {t}"))
    }
}
