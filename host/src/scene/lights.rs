//! Scene lights to kernel lights: frames, light maps, shadow-map layout.

use anyhow::{anyhow, bail, Result};
use glam::{Vec3, Vec4};
use slicelight_shaders::types::{GpuLight, LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_SPOT};
use std::path::Path;

use super::schema::{DirectionalLight, LineLight, PointLight, Spotlight};
use super::validate::{finite3, invalid, non_negative3, shadow_resolution, unit3};

/// Every light of a scene, their light maps' texels, and each light's
/// shadow-map resolution as the file gives it (`None`: the default, which
/// depends on what the maps serve, `SceneData::lay_out_shadow_maps`; point
/// lights have no map and `None`).
#[derive(Default)]
pub struct Lights {
    pub lights: Vec<GpuLight>,
    pub light_map: Vec<Vec4>,
    pub shadow_resolutions: Vec<Option<u32>>,
    /// The line lights as defined (the kernels see their point lights).
    pub lines: Vec<LineSource>,
}

/// A line light as the scene defines it, for the references (which light
/// it continuously), and the point lights the kernels see in its place.
#[derive(Debug, Clone)]
pub struct LineSource {
    pub from: Vec3,
    pub to: Vec3,
    /// W/sr per metre per channel, emitted the same way in every direction.
    pub per_metre: Vec3,
    /// Its point lights among the scene's lights.
    pub lights: std::ops::Range<usize>,
}

impl Lights {
    /// Appends a light (with the shadow-map resolution its file gives) and
    /// lays out its light map's texels after the others'.
    fn push(&mut self, mut light: GpuLight, shadow_resolution: Option<u32>, map: LightMap) {
        if let Some((w, h, texels)) = map {
            light.light_map_offset = self.light_map.len() as u32;
            light.light_map_width = w;
            light.light_map_height = h;
            self.light_map.extend(texels);
        }
        self.lights.push(light);
        self.shadow_resolutions.push(shadow_resolution);
    }
}

/// Validates and converts the lights. `bounds` (of the geometry) places a
/// directional light's entry plane when the file gives none.
pub fn build(
    spots: &[Spotlight],
    directionals: &[DirectionalLight],
    points: &[PointLight],
    lines: &[LineLight],
    base: &Path,
    bounds: Option<(Vec3, Vec3)>,
) -> Result<Lights> {
    let mut out = Lights::default();
    for (i, p) in points.iter().enumerate() {
        let field = format!("point_light[{i}]");
        let position = finite3(&format!("{field}.position"), p.position)?;
        let power = non_negative3(&format!("{field}.intensity"), p.intensity)?;
        out.push(point_light(position, power), None, None);
    }
    for (i, l) in lines.iter().enumerate() {
        let field = format!("line_light[{i}]");
        let from = finite3(&format!("{field}.from"), l.from)?;
        let to = finite3(&format!("{field}.to"), l.to)?;
        let per_metre = non_negative3(&format!("{field}.intensity"), l.intensity)?;
        let length = (to - from).length();
        if length.is_nan() || length <= 1e-6 {
            bail!(invalid(&format!("{field}.to"), "a point different from from", l.to));
        }
        let n = match l.points {
            Some(n) if (1..=4096).contains(&n) => n,
            Some(n) => bail!(invalid(&format!("{field}.points"), "a count in 1..=4096", n)),
            None => line_light_points(length),
        };
        let first = out.lights.len();
        out.lines.push(LineSource { from, to, per_metre, lights: first..first + n as usize });
        // Point k at the middle of the k-th of n equal pieces, with that piece's intensity.
        for k in 0..n {
            let p = from + (to - from) * ((k as f32 + 0.5) / n as f32);
            out.push(point_light(p, per_metre * (length / n as f32)), None, None);
        }
    }
    for (i, s) in spots.iter().enumerate() {
        let field = format!("spotlight[{i}]");
        let (light, map) = spotlight(&field, s, base)?;
        out.push(light, shadow_resolution(&format!("{field}.shadow_map_resolution"), s.shadow_map_resolution)?, map);
    }
    for (i, d) in directionals.iter().enumerate() {
        let field = format!("directional_light[{i}]");
        let (light, map) = directional(&field, d, base, bounds)?;
        out.push(light, shadow_resolution(&format!("{field}.shadow_map_resolution"), d.shadow_map_resolution)?, map);
    }
    Ok(out)
}

type LightMap = Option<(u32, u32, Vec<Vec4>)>;

/// Point lights a line light of `length` metres becomes by default: one per
/// 5 cm, at least 4 and at most 64 (the caustics paper used 8).
pub fn line_light_points(length: f32) -> u32 {
    ((length / 0.05).ceil() as u32).clamp(4, 64)
}

fn point_light(position: Vec3, power: Vec3) -> GpuLight {
    GpuLight {
        position: position.extend(1.0),
        axis_x: Vec4::X,
        axis_y: Vec4::NEG_Y,
        axis_z: Vec4::NEG_Z,
        power: power.extend(0.0),
        kind: LIGHT_POINT,
        shadow_resolution: 0,
        ..Default::default()
    }
}

fn spotlight(field: &str, s: &Spotlight, base: &Path) -> Result<(GpuLight, LightMap)> {
    let pos = finite3(&format!("{field}.position"), s.position)?;
    let z = unit3(&format!("{field}.direction"), s.direction)?;
    let (x, y) = light_frame(field, z, s.up)?;
    if !(s.cutoff_deg > 0.0 && s.cutoff_deg < 90.0) {
        bail!(invalid(&format!("{field}.cutoff_deg"), "an angle in (0, 90) degrees", s.cutoff_deg));
    }
    let beam = s.beam_deg.unwrap_or(s.cutoff_deg);
    if !(beam > 0.0 && beam <= s.cutoff_deg) {
        bail!(invalid(&format!("{field}.beam_deg"), "an angle in (0, cutoff_deg] degrees", beam));
    }
    let (tan_cutoff, cos2_cutoff, sin2_cutoff) = slicelight_shaders::light::cone_terms(s.cutoff_deg.to_radians());
    let light = GpuLight {
        position: pos.extend(1.0),
        axis_x: x.extend(0.0),
        axis_y: y.extend(0.0),
        axis_z: z.extend(0.0),
        power: non_negative3(&format!("{field}.intensity"), s.intensity)?.extend(0.0),
        kind: LIGHT_SPOT,
        cutoff: s.cutoff_deg.to_radians(),
        beam: beam.to_radians(),
        tan_cutoff,
        cos2_cutoff,
        sin2_cutoff,
        ..Default::default()
    };
    let map = match &s.light_map {
        Some(file) => Some(load_light_map(&format!("{field}.light_map"), base, file)?),
        None => None,
    };
    Ok((light, map))
}

fn directional(
    field: &str,
    d: &DirectionalLight,
    base: &Path,
    bounds: Option<(Vec3, Vec3)>,
) -> Result<(GpuLight, LightMap)> {
    let z = unit3(&format!("{field}.direction"), d.direction)?;
    let (x, y) = light_frame(field, z, d.up)?;
    // Without an explicit entry plane, the light enters the medium where
    // it first meets the scene's bounding sphere.
    let (center, radius) = match bounds {
        Some((lo, hi)) => ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-3)),
        None => (Vec3::ZERO, 1.0),
    };
    let origin = match d.origin {
        Some(o) => finite3(&format!("{field}.origin"), o)?,
        None => center - z * radius,
    };
    let mut light = GpuLight {
        position: origin.extend(1.0),
        axis_x: x.extend(0.0),
        axis_y: y.extend(0.0),
        axis_z: z.extend(0.0),
        power: non_negative3(&format!("{field}.irradiance"), d.irradiance)?.extend(0.0),
        kind: LIGHT_DIRECTIONAL,
        half_extent_x: radius,
        half_extent_y: radius,
        ..Default::default()
    };
    if let Some(size) = d.size {
        if !(size.iter().all(|s| s.is_finite() && *s > 0.0)) {
            bail!(invalid(&format!("{field}.size"), "two positive sizes in metres", size));
        }
        light.half_extent_x = size[0] * 0.5;
        light.half_extent_y = size[1] * 0.5;
        light.bounded = 1;
    }
    let map = match &d.light_map {
        Some(_) if d.size.is_none() => {
            bail!(invalid(
                &format!("{field}.size"),
                "the window's [width, height] in metres when a light_map is given",
                "nothing"
            ))
        }
        Some(file) => Some(load_light_map(&format!("{field}.light_map"), base, file)?),
        None => None,
    };
    Ok((light, map))
}

/// An orthonormal light frame: `z` along the light, `x` to its right, `y`
/// down, seen from behind the light with `up` up (so a light map's first row
/// lands at the top, like a slide projector's). Without an `up`, it is +y, or
/// -z for a light that points straight up or down.
fn light_frame(field: &str, z: Vec3, up: Option<[f32; 3]>) -> Result<(Vec3, Vec3)> {
    let up = match up {
        Some(up) => unit3(&format!("{field}.up"), up)?,
        None if z.y.abs() > 0.999 => Vec3::NEG_Z,
        None => Vec3::Y,
    };
    let x = z.cross(up);
    if x.length() < 1e-4 {
        return Err(invalid(&format!("{field}.up"), "an up vector not parallel to the direction", up));
    }
    let x = x.normalize();
    Ok((x, z.cross(x)))
}

/// Decodes an image into linear-light texels (sRGB transfer undone).
fn load_light_map(field: &str, base: &Path, file: &Path) -> Result<(u32, u32, Vec<Vec4>)> {
    let path = base.join(file);
    crate::output::regular_file(field, &path, crate::output::MAX_IMAGE_BYTES)?;
    let img = image::open(&path).map_err(|e| anyhow!("{field}: cannot read light map '{}': {e}", path.display()))?;
    Ok(light_map_from_image(&img))
}

/// A decoded image's texels in linear light (sRGB transfer undone).
pub fn light_map_from_image(img: &image::DynamicImage) -> (u32, u32, Vec<Vec4>) {
    let img = img.to_rgb32f();
    let texels = img
        .pixels()
        .map(|p| Vec4::new(srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2]), 1.0))
        .collect();
    (img.width(), img.height(), texels)
}

pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
