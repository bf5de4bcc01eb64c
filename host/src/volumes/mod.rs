//! The volumes family (kernels: `shader-crate/src/volumes/`): local,
//! heterogeneous media in boxes (`[[volume]]`), their density from
//! metaballs, the lights' transmittance volumes, and the slice renderer
//! that integrates them along the view rays; the settings (`[volumes]`,
//! `[[volume]]`) and their validation.

pub mod automaton;
pub mod bench;
pub mod grid;
pub mod montecarlo;
pub mod reference;
pub mod splat;

use anyhow::{anyhow, bail, Context, Result};
use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::Deserialize;
use slicelight_shaders::light::light_local;
use slicelight_shaders::types::{
    CommonParams, GBufferTexel, GpuLight, LIGHT_POINT, LIGHT_SPOT, PHASE_DOBASHI, PHASE_HENYEY_GREENSTEIN,
    PHASE_ISOTROPIC, PHASE_RAYLEIGH,
};
use slicelight_shaders::volumes::{
    density_cell, diffuse_node, optical_depth_column, spread_columns, volumes_pixel, GpuMetaball, GpuVolume, LightGrid,
    VolumeInputs, VolumesParams, METHOD_SLICES, METHOD_SPLATTING, PHASE_DOUBLE_HENYEY_GREENSTEIN,
};
use std::path::Path;

use crate::cpu::{for_each_invocation, for_each_invocation2};
use crate::passes::*;
use crate::scene::{invalid, validate, SceneData};

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[
    &automaton::Steps,
    &automaton::Smooth,
    &Density,
    &OpticalDepth,
    &Diffuse,
    &splat::SplatSort,
    &splat::SplatTextures,
    &splat::SplatTiles,
    &Volumes,
    &splat::Splats,
];

/// The family, as `passes::FAMILIES` registers it.
pub static FAMILY: Family = Family { name: "volumes", passes: PASSES, kernels: &[], bench: Some(&bench::VolumesSweep) };

pub static VOLUMES_PARAMS: Resource = Resource {
    binding: 40,
    name: "volumes parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.volumes.params)),
};
pub static VOLUMES: Resource =
    Resource { binding: 41, name: "volumes", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.volumes)) };
pub static METABALLS: Resource =
    Resource { binding: 42, name: "metaballs", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.balls)) };
pub static METABALL_BINS: Resource = Resource {
    binding: 43,
    name: "metaball bins",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.bins)),
};
/// The grid volumes' values from their files.
pub static GRID_VALUES: Resource = Resource {
    binding: 56,
    name: "grid values",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.grid_values)),
};
/// Each volume's density at its cell centres.
pub static DENSITY: Resource = Resource {
    binding: 44,
    name: "density grids",
    kind: ResourceKind::Frame(|s| s.volumes.params.cell_count as u64 * 4),
};
pub static LIGHT_GRIDS: Resource = Resource {
    binding: 45,
    name: "light grids",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.grids)),
};
/// Per light, the optical depth through the volumes at its grid's nodes.
pub static OPTICAL_DEPTHS: Resource =
    Resource { binding: 46, name: "optical depths", kind: ResourceKind::Frame(|s| s.volumes.depth_nodes() * 16) };
/// The columns' smoothed diffuse light at the light grids' nodes
/// (`diffuse_node`: fluence and flux, a `Vec4` each per node); one
/// node's worth where no pass writes it.
pub static DIFFUSE: Resource =
    Resource { binding: 119, name: "diffuse light", kind: ResourceKind::Frame(|s| diffuse_nodes(s) * 32) };

/// The nodes `DIFFUSE` holds (1 where the slices do not spread the columns).
fn diffuse_nodes(s: &SceneData) -> u64 {
    let p = &s.volumes.params;
    if s.volumes.enabled && spread_columns(p) && p.method == METHOD_SLICES {
        s.volumes.depth_nodes().max(1)
    } else {
        1
    }
}

/// The volumes' radiance per pixel (rgb).
pub static VOLUME_RADIANCE: Resource =
    Resource { binding: 47, name: "volume radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The view transmittance through the volumes per pixel (rgb).
pub static VOLUME_TRANSMITTANCE: Resource =
    Resource { binding: 48, name: "volume transmittance", kind: ResourceKind::PerPixel { blank: clear } };

fn clear() -> Vec<u8> {
    bytemuck::bytes_of(&Vec4::new(1.0, 1.0, 1.0, 0.0)).to_vec()
}

/// A `[[volume]]`: a medium inside a box, added to `[medium]` where it is.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Volume {
    /// The box's corners, metres; the density is 0 outside it.
    pub min: [f32; 3],
    pub max: [f32; 3],
    /// Scattering and extinction per unit density, 1/m per channel.
    pub sigma_s: [f32; 3],
    pub sigma_t: [f32; 3],
    #[serde(default)]
    pub phase: VolumePhase,
    /// `[x, y, z, radius, q]` per metaball (metres; `q` the density at its centre).
    #[serde(default)]
    pub metaballs: Vec<[f32; 5]>,
    /// A text file of metaballs, five numbers a line (`#` starts a comment),
    /// relative to the scene file; added to `metaballs`.
    pub metaballs_file: Option<String>,
    /// Density grid cells along x, y, z (default: a quarter of the
    /// smallest metaball's radius, at most `MAX_DEFAULT_CELLS` in all).
    pub resolution: Option<[u32; 3]>,
    /// `"slices"` (the default): the slice renderer; `"splatting"`:
    /// Dobashi et al. 2000's billboards, one per metaball (`splat`). Every
    /// volume of a scene takes the same method.
    #[serde(default)]
    pub method: Method,
    /// The cloud automaton fills the box (instead of metaballs).
    pub automaton: Option<automaton::Settings>,
    /// A density grid from a file fills the box (instead of metaballs).
    pub grid: Option<GridFile>,
    /// Smoke simulated in the box (`crate::smoke`): its puffs are the
    /// metaballs (or its density field the grid).
    pub smoke: Option<crate::smoke::Settings>,
}

/// `grid = { file = "..." }`: a Mitsuba `.vol` file (version 3, float32,
/// one channel) or an OpenVDB file (`.vdb`, a float grid: `name`, by
/// default `density` or the file's only grid), relative to the scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridFile {
    pub file: String,
    pub name: Option<String>,
}

#[derive(Debug, Default, Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    #[default]
    Slices,
    Splatting,
}

/// A volume's phase function: the medium's kinds and two-lobe Henyey-Greenstein.
#[derive(Debug, Default, Deserialize, Clone, Copy)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VolumePhase {
    #[default]
    Isotropic,
    HenyeyGreenstein {
        g: f32,
    },
    Rayleigh,
    Dobashi2002,
    /// `weight HG(g1) + (1 - weight) HG(g2)`.
    DoubleHenyeyGreenstein {
        g1: f32,
        g2: f32,
        weight: f32,
    },
}

/// The scene's `[volumes]` table: how all volumes are rendered.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Sample planes over the volumes' depth range (default: planes half a
    /// density cell apart, `16..=4096`).
    pub planes: Option<u32>,
    /// Transmittance-volume nodes per light: across x, across y, along the
    /// light (default: a density cell apart, at most `MAX_DEFAULT_NODES`).
    pub light_grid: Option<[u32; 3]>,
    /// `"multiple"` (the default): all orders by delta-Eddington columns;
    /// `"octaves"`: all orders by Wrenninge's octaves; `"single"`: single
    /// scattering.
    #[serde(default)]
    pub scattering: Scattering,
    /// With `"multiple"`: the medium's lateral extent around a light
    /// column as a multiple of the column's depth (`COLUMN_WIDTH` by
    /// default; `column_light`).
    pub column_width: Option<f32>,
    /// With `"multiple"` on the slices: the ring the columns' diffuse light
    /// is averaged over, its radius a multiple of `sqrt(H d)` (the light
    /// ray's length inside the volumes and a point's depth along it;
    /// `COLUMN_SPREAD` by default, 0 when `column_width` is given;
    /// `diffuse_node`). 0: no ring, the leakage by `column_width` instead.
    pub column_spread: Option<f32>,
    /// With `"octaves"`: the octaves' count and their factors on the
    /// scattering coefficient, the light's optical depth and the phase
    /// function's asymmetry (`OCTAVES`, `OCTAVE_*` by default).
    pub octaves: Option<u32>,
    pub octave_scattering: Option<f32>,
    pub octave_extinction: Option<f32>,
    pub octave_phase: Option<f32>,
}

#[derive(Debug, Default, Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub enum Scattering {
    Single,
    #[default]
    Multiple,
    Octaves,
}

/// The default `column_width`: chosen against the Monte Carlo reference
/// on thin, medium and dense clouds (`docs/volumes.md`, "Multiple
/// scattering"); 1 would be a ball's (as wide as deep).
pub const COLUMN_WIDTH: f32 = 1.75;

/// The default `column_spread`: chosen with `RING_CENTRE_WEIGHT` against
/// the Monte Carlo reference on thin, medium and dense clouds
/// (`docs/volumes.md`, "Multiple scattering").
pub const COLUMN_SPREAD: f32 = 1.0;

/// How a scene's volumes scatter: `(columns, width, spread)` for
/// `column_light` and `diffuse_node`, and `(count, a, b, c)` for the
/// octaves (count 1: none).
struct Orders {
    columns: bool,
    width: f32,
    spread: f32,
    octaves: (u32, f32, f32, f32),
}

fn orders(settings: &Settings) -> Result<Orders> {
    let octaves = octaves(settings)?;
    let columns = settings.scattering == Scattering::Multiple;
    if !columns && settings.column_width.is_some() {
        bail!(invalid("volumes.column_width", "none unless scattering = \"multiple\"", "a value"));
    }
    if !columns && settings.column_spread.is_some() {
        bail!(invalid("volumes.column_spread", "none unless scattering = \"multiple\"", "a value"));
    }
    let width = settings.column_width.unwrap_or(COLUMN_WIDTH);
    if !(width > 0.0 && width <= 1000.0) {
        bail!(invalid("volumes.column_width", "a positive multiple of a column's depth, at most 1000", width));
    }
    // A width asked for is the buckling's: no ring unless one is asked for too.
    let spread = settings.column_spread.unwrap_or(if settings.column_width.is_some() { 0.0 } else { COLUMN_SPREAD });
    if !(0.0..=10.0).contains(&spread) {
        bail!(invalid(
            "volumes.column_spread",
            "a multiple of sqrt(a light ray's length in the volumes times the depth) in [0, 10]",
            spread
        ));
    }
    if spread > 0.0 && settings.column_width.is_some() {
        bail!(invalid(
            "volumes.column_width",
            "none with column_spread > 0 (the ring carries the lateral leakage; column_spread = 0 for the width's)",
            width
        ));
    }
    Ok(Orders { columns, width, spread: if columns { spread } else { 0.0 }, octaves })
}

/// Default octaves of multiple scattering and their factors (`a`, `b`, `c`
/// of `in_scattered`), chosen against the Monte Carlo reference
/// (`docs/volumes.md`).
pub const OCTAVES: u32 = 8;
pub const OCTAVE_SCATTERING: f32 = 0.75;
pub const OCTAVE_EXTINCTION: f32 = 0.75;
pub const OCTAVE_PHASE: f32 = 0.75;

/// The octaves' parameters from the settings: `(count, a, b, c)`.
fn octaves(settings: &Settings) -> Result<(u32, f32, f32, f32)> {
    let given = [
        ("octaves", settings.octaves.is_some()),
        ("octave_scattering", settings.octave_scattering.is_some()),
        ("octave_extinction", settings.octave_extinction.is_some()),
        ("octave_phase", settings.octave_phase.is_some()),
    ];
    if settings.scattering != Scattering::Octaves {
        if let Some((name, _)) = given.iter().find(|(_, g)| *g) {
            bail!(invalid(&format!("volumes.{name}"), "none unless scattering = \"octaves\"", "a value"));
        }
        return Ok((1, 1.0, 1.0, 1.0));
    }
    let count = settings.octaves.unwrap_or(OCTAVES);
    if !(1..=16).contains(&count) {
        bail!(invalid("volumes.octaves", "an octave count in 1..=16", count));
    }
    let factor = |name: &str, value: Option<f32>, default: f32| -> Result<f32> {
        let f = value.unwrap_or(default);
        if !(f > 0.0 && f <= 1.0) {
            bail!(invalid(&format!("volumes.{name}"), "a factor in (0, 1]", f));
        }
        Ok(f)
    };
    let a = factor("octave_scattering", settings.octave_scattering, OCTAVE_SCATTERING)?;
    let b = factor("octave_extinction", settings.octave_extinction, OCTAVE_EXTINCTION)?;
    let c = factor("octave_phase", settings.octave_phase, OCTAVE_PHASE)?;
    if a > b {
        // Wrenninge's condition: with a <= b, no octave adds more light
        // than the extinction it removes would have let through.
        bail!(invalid(
            "volumes.octave_scattering",
            &format!("at most octave_extinction ({b}), or energy is created"),
            a
        ));
    }
    Ok((count, a, b, c))
}

/// Most density cells a volume gets by default (32 MiB of f32).
pub const MAX_DEFAULT_CELLS: u64 = 1 << 23;
/// Most density cells a `resolution` may ask for, all volumes together.
pub const MAX_CELLS: u64 = 1 << 28;
/// Most transmittance-volume nodes a light gets by default (64 MiB of rgb).
pub const MAX_DEFAULT_NODES: u64 = 1 << 22;
/// Most nodes a `light_grid` may ask for, all lights together.
pub const MAX_NODES: u64 = 1 << 26;
/// Midpoint samples per node interval of a transmittance-volume column.
pub const COLUMN_SUBSTEPS: u32 = 2;

/// The volumes' state for one scene.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    /// Whether the scene has any `[[volume]]`.
    pub enabled: bool,
    pub params: VolumesParams,
    pub volumes: Vec<GpuVolume>,
    pub balls: Vec<GpuMetaball>,
    /// Per volume, its bins' starts (absolute indices into this buffer),
    /// then the balls listed in each bin.
    pub bins: Vec<u32>,
    /// One per light (`nu = 0`: the light has none).
    pub grids: Vec<LightGrid>,
    /// The cloud automaton, if a volume has one.
    pub automaton: automaton::Setup,
    /// The grid volumes' values from their files, one after another.
    pub grid_values: Vec<f32>,
    /// Splatting: each light's bins of metaballs and their lists (`splat::light_bins`).
    pub light_bins: Vec<slicelight_shaders::volumes::splat::LightBins>,
    pub light_lists: Vec<u32>,
}

impl Setup {
    /// A grid volume's values from its file (`None` for other volumes).
    pub fn file_grid(&self, v: &GpuVolume) -> Option<&[f32]> {
        let count = (v.nx * v.ny * v.nz) as usize;
        v.is_file_grid().then(|| &self.grid_values[v.bin_offset as usize..v.bin_offset as usize + count])
    }

    /// Nodes in all lights' transmittance volumes.
    pub fn depth_nodes(&self) -> u64 {
        self.grids.iter().map(|g| g.nu as u64 * g.nv as u64 * g.nz as u64).sum()
    }
}

/// Reads a metaball file: five numbers a line.
fn read_metaballs(field: &str, base: &Path, file: &str) -> Result<Vec<[f32; 5]>> {
    let path = base.join(file);
    crate::output::regular_file(field, &path, crate::output::MAX_DATA_BYTES)?;
    let text = std::fs::read_to_string(&path).with_context(|| format!("{field}: cannot read {}", path.display()))?;
    let mut balls = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let values: Vec<f32> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|w| !w.is_empty())
            .map(|w| w.parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| anyhow!("{field}: {} line {}: {e}", path.display(), n + 1))?;
        let ball: [f32; 5] = values.try_into().map_err(|v: Vec<f32>| {
            anyhow!(
                "{field}: {} line {}: expected five numbers (x y z radius q), got {}",
                path.display(),
                n + 1,
                v.len()
            )
        })?;
        balls.push(ball);
    }
    Ok(balls)
}

fn phase(field: &str, p: VolumePhase) -> Result<(u32, f32, f32, f32)> {
    let g_in_range = |name: &str, g: f32| -> Result<f32> {
        if !(g > -1.0 && g < 1.0) {
            bail!(invalid(&format!("{field}.{name}"), "a number in (-1, 1)", g));
        }
        Ok(g)
    };
    Ok(match p {
        VolumePhase::Isotropic => (PHASE_ISOTROPIC, 0.0, 0.0, 1.0),
        VolumePhase::Rayleigh => (PHASE_RAYLEIGH, 0.0, 0.0, 1.0),
        VolumePhase::Dobashi2002 => (PHASE_DOBASHI, 0.0, 0.0, 1.0),
        VolumePhase::HenyeyGreenstein { g } => (PHASE_HENYEY_GREENSTEIN, g_in_range("g", g)?, 0.0, 1.0),
        VolumePhase::DoubleHenyeyGreenstein { g1, g2, weight } => {
            if !(0.0..=1.0).contains(&weight) {
                bail!(invalid(&format!("{field}.weight"), "a weight in [0, 1]", weight));
            }
            (PHASE_DOUBLE_HENYEY_GREENSTEIN, g_in_range("g1", g1)?, g_in_range("g2", g2)?, weight)
        }
    })
}

/// One volume, validated: its kernel record (offsets not yet set), balls,
/// and the grid's resolution.
fn volume(field: &str, v: &Volume, base: &Path) -> Result<(GpuVolume, Vec<GpuMetaball>, Option<grid::Grid>)> {
    let (lo, hi) = box_of(field, v)?;
    let sigma_s = validate::non_negative3(&format!("{field}.sigma_s"), v.sigma_s)?;
    let sigma_t = validate::non_negative3(&format!("{field}.sigma_t"), v.sigma_t)?;
    if sigma_s.cmpgt(sigma_t).any() {
        bail!(invalid(
            &format!("{field}.sigma_s"),
            "no channel above sigma_t (scattering is part of extinction)",
            v.sigma_s
        ));
    }
    let (phase_kind, g1, g2, weight) = phase(&format!("{field}.phase"), v.phase)?;
    let mut given = v.metaballs.clone();
    if let Some(file) = &v.metaballs_file {
        given.extend(read_metaballs(&format!("{field}.metaballs_file"), base, file)?);
    }
    let mut balls = Vec::with_capacity(given.len());
    for (i, b) in given.iter().enumerate() {
        let name = format!("{field}.metaballs[{i}]");
        let c = validate::finite3(&name, [b[0], b[1], b[2]])?;
        if c.cmplt(lo).any() || c.cmpgt(hi).any() {
            bail!(invalid(&name, "a centre inside the volume's box", b));
        }
        validate::positive(&format!("{name} radius"), b[3])?;
        // Density multiplies the coefficients (up to 1e12 /m): 1e6 keeps
        // their products and the optical depths finite in f32.
        if !(b[4].is_finite() && (0.0..=1e6).contains(&b[4])) {
            bail!(invalid(&format!("{name} q"), "a density in [0, 1e6]", b[4]));
        }
        balls.push(GpuMetaball { center_radius: c.extend(b[3]), q: Vec4::new(b[4], 0.0, 0.0, 0.0) });
    }
    let size = hi - lo;
    if let Some(a) = &v.automaton {
        if !balls.is_empty() {
            bail!(invalid(&format!("{field}.automaton"), "no metaballs besides an automaton", "metaballs"));
        }
        if v.resolution.is_some() {
            bail!(invalid(
                &format!("{field}.resolution"),
                "none with an automaton (its cells are the grid)",
                "a value"
            ));
        }
        if !a.cells.iter().all(|n| (1..=4096).contains(n)) {
            bail!(invalid(&format!("{field}.automaton.cells"), "three cell counts in 1..=4096", a.cells));
        }
    }
    let file = match &v.grid {
        Some(g) => {
            let sources = [!balls.is_empty(), v.automaton.is_some()];
            if sources.iter().any(|s| *s) {
                bail!(invalid(&format!("{field}.grid"), "a grid alone (no metaballs or automaton besides it)", "both"));
            }
            if v.resolution.is_some() {
                bail!(invalid(
                    &format!("{field}.resolution"),
                    "none with a grid (its cells are the grid's)",
                    "a value"
                ));
            }
            let path = base.join(&g.file);
            if grid::is_vdb(&g.file) {
                Some(grid::read_vdb(&format!("{field}.grid"), &path, g.name.as_deref(), MAX_DEFAULT_CELLS)?)
            } else if g.name.is_some() {
                bail!(invalid(&format!("{field}.grid.name"), "none for a .vol file (it holds one grid)", "a name"));
            } else {
                Some(grid::read_vol(&format!("{field}.grid.file"), &path)?)
            }
        }
        None => None,
    };
    let [nx, ny, nz] = match (v.resolution, &v.automaton) {
        _ if file.is_some() => file.as_ref().expect("a grid").cells,
        (_, Some(a)) => a.cells,
        (Some(r), None) => {
            if !r.iter().all(|n| (1..=4096).contains(n)) {
                bail!(invalid(&format!("{field}.resolution"), "three cell counts in 1..=4096", r));
            }
            r
        }
        (None, None) => default_resolution(size, &balls),
    };
    let record = GpuVolume {
        min: lo.extend(0.0),
        max: hi.extend(0.0),
        sigma_s: sigma_s.extend(0.0),
        sigma_t: sigma_t.extend(0.0),
        phase_kind,
        g1,
        g2,
        weight,
        nx,
        ny,
        nz,
        ..Default::default()
    };
    Ok((record, balls, file))
}

/// A volume's box, checked: its corners `min` and `max` (m).
fn box_of(field: &str, v: &Volume) -> Result<(Vec3, Vec3)> {
    let lo = validate::finite3(&format!("{field}.min"), v.min)?;
    let hi = validate::finite3(&format!("{field}.max"), v.max)?;
    if !hi.cmpgt(lo).all() {
        bail!(invalid(&format!("{field}.max"), "a corner above min in every axis (a box with volume)", v.max));
    }
    Ok((lo, hi))
}

/// A smoke volume: the fluid simulated to the scene's time, its puffs
/// the volume's metaballs (`render = "puffs"`) or its density field the
/// grid (`"density"`).
fn smoke_volume(
    field: &str,
    v: &Volume,
    s: &crate::smoke::Settings,
    data: &SceneData,
    base: &Path,
) -> Result<(GpuVolume, Vec<GpuMetaball>, Option<grid::Grid>)> {
    let others = [!v.metaballs.is_empty() || v.metaballs_file.is_some(), v.automaton.is_some(), v.grid.is_some()];
    if others.iter().any(|o| *o) {
        bail!(invalid(&format!("{field}.smoke"), "smoke alone (no metaballs, automaton or grid besides it)", "both"));
    }
    let (lo, hi) = box_of(field, v)?;
    let config = crate::smoke::configure(field, s, lo, hi)?;
    let cells = if config.obstacles {
        crate::smoke::voxelise(data, &config.params, lo)
    } else {
        vec![1; config.params.cells as usize]
    };
    let progress = crate::smoke::progress_bar(field);
    let fluid = crate::smoke::simulate(&config, cells, config.seconds as f64 + data.time, &progress)?;
    let mut plain = v.clone();
    plain.smoke = None;
    match config.render {
        crate::smoke::Render::Puffs => {
            plain.metaballs = crate::smoke::metaballs(&fluid, lo, hi);
            if plain.metaballs.is_empty() && plain.resolution.is_none() {
                plain.resolution = Some([1, 1, 1]);
            }
            volume(field, &plain, base)
        }
        crate::smoke::Render::Density => {
            if v.resolution.is_some() {
                bail!(invalid(
                    &format!("{field}.resolution"),
                    "none with render = \"density\" (the fluid's cells are the grid)",
                    "a value"
                ));
            }
            plain.resolution = Some(s.cells);
            let (mut record, balls, _) = volume(field, &plain, base)?;
            record.nx = s.cells[0];
            record.ny = s.cells[1];
            record.nz = s.cells[2];
            Ok((record, balls, Some(grid::Grid { cells: s.cells, values: fluid.smoke.clone() })))
        }
    }
}

/// Cells a quarter of the smallest ball's radius wide (the trilinear
/// interpolation of the field function then errs by under 1 % of a ball's
/// peak), coarsened evenly to at most `MAX_DEFAULT_CELLS`.
fn default_resolution(size: Vec3, balls: &[GpuMetaball]) -> [u32; 3] {
    let smallest = balls.iter().map(|b| b.center_radius.w).fold(f32::INFINITY, f32::min);
    if !smallest.is_finite() {
        return [1, 1, 1];
    }
    let mut cell = smallest * 0.25;
    let count = |cell: f32| (size / cell).ceil().max(Vec3::ONE).min(Vec3::splat(4096.0));
    let cells = |n: Vec3| n.x as u64 * n.y as u64 * n.z as u64;
    while cells(count(cell)) > MAX_DEFAULT_CELLS {
        cell *= 1.1;
    }
    let n = count(cell);
    [n.x as u32, n.y as u32, n.z as u32]
}

/// Sorts the balls into bins over the box (each bin lists every ball whose
/// bounding box meets it): bins about a mean ball diameter wide, at most
/// 64 a side. Appends the volume's bin starts and lists to `bins`.
fn bin_balls(v: &mut GpuVolume, balls: &[GpuMetaball], first_ball: u32, bins: &mut Vec<u32>) {
    let (lo, hi) = (v.min.truncate(), v.max.truncate());
    let size = hi - lo;
    let mean = if balls.is_empty() {
        size.max_element()
    } else {
        balls.iter().map(|b| b.center_radius.w).sum::<f32>() / balls.len() as f32
    };
    let n = (size / (2.0 * mean)).ceil().clamp(Vec3::ONE, Vec3::splat(64.0));
    let (bx, by, bz) = (n.x as u32, n.y as u32, n.z as u32);
    let count = (bx * by * bz) as usize;
    let mut lists: Vec<Vec<u32>> = vec![Vec::new(); count];
    let cell = size / n;
    for (i, b) in balls.iter().enumerate() {
        let (c, r) = (b.center_radius.truncate(), b.center_radius.w);
        let from = ((c - Vec3::splat(r) - lo) / cell).floor().max(Vec3::ZERO).min(n - Vec3::ONE);
        let to = ((c + Vec3::splat(r) - lo) / cell).floor().max(Vec3::ZERO).min(n - Vec3::ONE);
        for z in from.z as u32..=to.z as u32 {
            for y in from.y as u32..=to.y as u32 {
                for x in from.x as u32..=to.x as u32 {
                    lists[((z * by + y) * bx + x) as usize].push(first_ball + i as u32);
                }
            }
        }
    }
    v.bins_x = bx;
    v.bins_y = by;
    v.bins_z = bz;
    v.bin_offset = bins.len() as u32;
    let mut start = bins.len() as u32 + count as u32 + 1;
    for list in &lists {
        bins.push(start);
        start += list.len() as u32;
    }
    bins.push(start);
    for list in lists {
        bins.extend(list);
    }
}

/// The corners of the volumes' boxes.
fn corners(volumes: &[GpuVolume]) -> Vec<Vec3> {
    volumes
        .iter()
        .flat_map(|v| {
            let (lo, hi) = (v.min.truncate(), v.max.truncate());
            (0..8).map(move |i| {
                Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
        })
        .collect()
}

/// A light's transmittance volume over the boxes' corners (see
/// `LightGrid`); nodes `cell` metres apart across and along the light (a
/// spot's across at its far end), at most `MAX_DEFAULT_NODES`, unless
/// `given`.
fn light_grid(light: &GpuLight, corners: &[Vec3], cell: f32, given: Option<[u32; 3]>) -> LightGrid {
    let local: Vec<Vec3> = corners.iter().map(|&c| light_local(light, c)).collect();
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    if light.kind == LIGHT_SPOT {
        let far = local.iter().map(|p| p.z).fold(f32::MIN, f32::max);
        if far <= 0.0 {
            return LightGrid::default();
        }
        let near = local.iter().map(|p| p.z).fold(f32::MAX, f32::min).max(far * 1e-3);
        let t = light.tan_cutoff;
        let (mut ulo, mut uhi) = (Vec3::new(-t, -t, 0.0), Vec3::new(t, t, 0.0));
        // Corners behind the light: the box may span the whole cone.
        if local.iter().all(|p| p.z > 0.0) {
            let (a, b) = local.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), p| {
                let q = Vec3::new(p.x / p.z, p.y / p.z, 0.0);
                (a.min(q), b.max(q))
            });
            ulo = a.max(ulo);
            uhi = b.min(uhi);
        }
        lo = Vec3::new(ulo.x, ulo.y, near);
        hi = Vec3::new(uhi.x, uhi.y, far);
    } else {
        for p in &local {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let across = if light.kind == LIGHT_SPOT { (hi - lo) * Vec3::new(hi.z, hi.z, 1.0) } else { hi - lo };
    let [nu, nv, nz] = given.unwrap_or_else(|| {
        let mut step = cell;
        let count = |step: f32| (across / step).ceil() + Vec3::ONE;
        let nodes = |n: Vec3| n.x.min(4096.0) as u64 * n.y.min(4096.0) as u64 * n.z.min(4096.0) as u64;
        while nodes(count(step)) > MAX_DEFAULT_NODES {
            step *= 1.1;
        }
        let n = count(step).clamp(Vec3::splat(2.0), Vec3::splat(4096.0));
        [n.x as u32, n.y as u32, n.z as u32]
    });
    LightGrid { lo: lo.extend(0.0), hi: hi.extend(0.0), nu, nv, nz, offset: 0 }
}

/// Validates `[[volume]]` and `[volumes]` for a scene whose camera and
/// lights are set, and returns the volumes' setup; errors name the field.
pub fn configure(list: &[Volume], settings: &Settings, data: &SceneData, base: &Path) -> Result<Setup> {
    if list.is_empty() {
        return Ok(Setup::default());
    }
    let mut volumes = Vec::with_capacity(list.len());
    let mut balls = Vec::new();
    let mut bins = Vec::new();
    let mut cells = 0u64;
    let mut cloud_automaton = automaton::Setup::default();
    let mut grid_values = Vec::new();
    let mut automaton_volume = 0;
    for (i, v) in list.iter().enumerate() {
        let field = format!("volume[{i}]");
        let (mut record, mut own, file) = match &v.smoke {
            Some(s) => smoke_volume(&field, v, s, data, base)?,
            None => volume(&field, v, base)?,
        };
        if v.method != list[0].method {
            bail!(invalid(
                &format!("{field}.method"),
                &format!("volume[0]'s method, {:?} (one renderer draws all volumes)", list[0].method),
                format!("{:?}", v.method)
            ));
        }
        if v.method == Method::Splatting && (file.is_some() || v.automaton.is_some()) {
            bail!(invalid(
                &format!("{field}.method"),
                "\"slices\" for a grid or automaton volume (splatting draws metaballs)",
                "\"splatting\""
            ));
        }
        for ball in &mut own {
            // The ball's volume, for the splatting kernels (`splat::volume_of`).
            ball.q.y = i as f32;
        }
        if let Some(a) = &v.automaton {
            if automaton_volume != 0 {
                bail!(invalid(&format!("{field}.automaton"), "one automaton per scene", "a second"));
            }
            cloud_automaton =
                automaton::configure_at(&field, i, a, record.min.truncate(), record.max.truncate(), data.time)?;
            automaton_volume = i as u32 + 1;
        }
        record.density_offset =
            u32::try_from(cells).map_err(|_| invalid(&format!("{field}.resolution"), "fewer cells", cells))?;
        cells += record.nx as u64 * record.ny as u64 * record.nz as u64;
        if cells > MAX_CELLS {
            bail!(invalid(
                &format!("{field}.resolution"),
                &format!("at most {MAX_CELLS} density cells in all volumes together"),
                [record.nx, record.ny, record.nz]
            ));
        }
        match file {
            // A grid volume: no bins (`GpuVolume::is_file_grid`); `bin_offset` is where
            // its values start in the grid buffer.
            Some(g) => {
                record.bin_offset = grid_values.len() as u32;
                grid_values.extend(g.values);
            }
            None => bin_balls(&mut record, &own, balls.len() as u32, &mut bins),
        }
        balls.extend(own);
        volumes.push(record);
    }
    let smallest_cell = volumes
        .iter()
        .map(|v| ((v.max - v.min).truncate() / Vec3::new(v.nx as f32, v.ny as f32, v.nz as f32)).min_element())
        .fold(f32::INFINITY, f32::min);
    // The depth range of the boxes along the view direction.
    let common = &data.common;
    let eye = common.camera_position.truncate();
    let forward = common.camera_forward.truncate();
    let all = corners(&volumes);
    let depths = all.iter().map(|c| (*c - eye).dot(forward));
    let near = depths.clone().fold(f32::MAX, f32::min).max(0.0);
    let far = depths.fold(f32::MIN, f32::max).max(near);
    let planes = match settings.planes {
        Some(n) if (1..=65536).contains(&n) => n,
        Some(n) => bail!(invalid("volumes.planes", "a plane count in 1..=65536", n)),
        None => (((far - near) / (0.5 * smallest_cell)).ceil() as u32).clamp(16, 4096),
    };
    if let Some(g) = settings.light_grid {
        if !g.iter().all(|n| (2..=4096).contains(n)) {
            bail!(invalid("volumes.light_grid", "three node counts in 2..=4096", g));
        }
    }
    let mut grids = Vec::with_capacity(data.lights.len());
    let mut nodes = 0u64;
    let mut columns = 0u64;
    for (l, light) in data.lights.iter().enumerate() {
        if light.kind == LIGHT_POINT {
            bail!(invalid(
                if data.is_line_point(l) { "line_light" } else { "point_light" },
                "spot and directional lights only in a scene with [[volume]] (their transmittance volumes)",
                "a point light"
            ));
        }
        let mut g = light_grid(light, &all, smallest_cell, settings.light_grid);
        g.offset = u32::try_from(nodes).map_err(|_| invalid("volumes.light_grid", "fewer nodes", nodes))?;
        nodes += g.nu as u64 * g.nv as u64 * g.nz as u64;
        columns += g.nu as u64 * g.nv as u64;
        grids.push(g);
    }
    if nodes > MAX_NODES {
        bail!(invalid(
            "volumes.light_grid",
            &format!("at most {MAX_NODES} transmittance-volume nodes in all lights together"),
            nodes
        ));
    }
    let orders = orders(settings)?;
    let (octave_count, a, b, c) = orders.octaves;
    let params = VolumesParams {
        volume_count: volumes.len() as u32,
        plane_count: planes,
        depth_near: near,
        depth_far: far,
        cell_count: cells as u32,
        column_count: columns as u32,
        column_substeps: COLUMN_SUBSTEPS,
        octaves: octave_count,
        octave_scattering: a,
        octave_extinction: b,
        octave_phase: c,
        columns: orders.columns as u32,
        column_width: orders.width,
        column_spread: orders.spread,
        automaton_volume,
        method: if list[0].method == Method::Splatting { METHOD_SPLATTING } else { METHOD_SLICES },
        ball_count: balls.len() as u32,
        tiles_x: common.width.div_ceil(slicelight_shaders::volumes::splat::TILE),
        tiles_y: common.height.div_ceil(slicelight_shaders::volumes::splat::TILE),
        tile_capacity: splat::TILE_CAPACITY.min(balls.len() as u32),
    };
    let (light_bins, light_lists) = if params.method == METHOD_SPLATTING {
        splat::light_bins(&data.lights, &balls)
    } else {
        (Vec::new(), Vec::new())
    };
    Ok(Setup {
        enabled: true,
        params,
        volumes,
        balls,
        bins,
        grids,
        automaton: cloud_automaton,
        grid_values,
        light_bins,
        light_lists,
    })
}

/// The scattering a volume renderer's plan names: single, the columns
/// and their width, or the octaves and their factors.
fn scattering_label(p: &VolumesParams) -> String {
    if spread_columns(p) && p.method == METHOD_SLICES {
        format!("multiple scattering (delta-Eddington columns spread over rings, column_spread {})", p.column_spread)
    } else if p.columns != 0 {
        format!("multiple scattering (delta-Eddington columns, width {})", p.column_width)
    } else if p.octaves > 1 {
        format!(
            "multiple scattering ({} octaves, a {} b {} c {})",
            p.octaves, p.octave_scattering, p.octave_extinction, p.octave_phase
        )
    } else {
        "single scattering".to_string()
    }
}

fn skip_without_volumes(scene: &SceneData) -> Option<Plan> {
    (!scene.volumes.enabled).then(|| Plan::skip("no [[volume]]"))
}

pub struct Density;

impl Pass for Density {
    fn name(&self) -> &'static str {
        "volume_density"
    }
    fn kernel(&self) -> &'static str {
        "volumes::density_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            VOLUMES_PARAMS,
            VOLUMES,
            METABALLS,
            METABALL_BINS,
            automaton::AUTOMATON_PARAMS,
            automaton::AUTOMATON_WEIGHTS,
            GRID_VALUES
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![DENSITY]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_volumes(scene) {
            return skip;
        }
        if !read_by_a_running_pass(scene, &DENSITY) {
            return Plan::skip("no running pass reads the density grids (the volumes are splatted)");
        }
        let v = &scene.volumes;
        Plan::run(
            format!(
                "{} metaballs'{} field{} at {} cell centres ({:.1} MiB)",
                v.balls.len() as u64 + v.automaton.params.cells as u64,
                if v.params.automaton_volume > 0 { " (the automaton's)" } else { "" },
                match v.volumes.iter().filter(|x| x.is_file_grid()).count() {
                    0 => String::new(),
                    n => format!(" and {n} grid(s) from files"),
                },
                v.params.cell_count,
                v.params.cell_count as f64 * 4.0 / (1u64 << 20) as f64
            ),
            v.params.cell_count as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        frame.write_all::<f32>(&DENSITY, v.params.cell_count as usize, |f, out| {
            let weights: &[f32] =
                if f.contains(&automaton::AUTOMATON_WEIGHTS) { f.get(&automaton::AUTOMATON_WEIGHTS) } else { &[] };
            let a = &v.automaton.params;
            for_each_invocation(out, 0, progress, |i, d| {
                *d = density_cell(i, &v.params, &v.volumes, &v.balls, &v.bins, a, weights, &v.grid_values)
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A sum of a few polynomials of f32 distances per cell: 1e-5 of the
        // peak density is tens of ulps.
        compare_values("densities", gpu.get(&DENSITY), cpu.get(&DENSITY), 1e-5, 0)
    }
}

pub struct OpticalDepth;

impl Pass for OpticalDepth {
    fn name(&self) -> &'static str {
        "volume_light"
    }
    fn kernel(&self) -> &'static str {
        "volumes::optical_depth_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, LIGHTS, VOLUMES_PARAMS, VOLUMES, DENSITY, LIGHT_GRIDS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![OPTICAL_DEPTHS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_volumes(scene) {
            return skip;
        }
        if !read_by_a_running_pass(scene, &OPTICAL_DEPTHS) {
            return Plan::skip("no running pass reads the transmittance volumes (the volumes are splatted)");
        }
        let v = &scene.volumes;
        let sizes: Vec<String> =
            v.grids.iter().filter(|g| g.nu > 0).map(|g| format!("{}x{}x{}", g.nu, g.nv, g.nz)).collect();
        Plan::run(
            format!(
                "optical depth toward each light, transmittance volumes {} ({:.1} MiB)",
                sizes.join(", "),
                v.depth_nodes() as f64 * 16.0 / (1u64 << 20) as f64
            ),
            v.params.column_count as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        frame.write::<Vec4>(&OPTICAL_DEPTHS, v.depth_nodes() as usize, |frame, out| {
            let density = frame.get::<f32>(&DENSITY);
            let mut first_column = 0u32;
            let mut rest = out;
            for g in &v.grids {
                let len = (g.nu * g.nv * g.nz) as usize;
                let (mine, after) = rest.split_at_mut(len);
                rest = after;
                if len == 0 {
                    continue;
                }
                mine.par_chunks_mut(g.nz as usize).enumerate().for_each(|(c, column)| {
                    let base = g.offset + c as u32 * g.nz;
                    let index = first_column + c as u32;
                    optical_depth_column(
                        index,
                        common,
                        &v.params,
                        &scene.lights,
                        &v.grids,
                        &v.volumes,
                        density,
                        column,
                        base,
                    );
                });
                progress.inc((g.nu * g.nv) as u64);
                first_column += g.nu * g.nv;
            }
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Sums of up to a few thousand f32 products along a column: 1e-4
        // of the largest depth.
        compare_rgb("optical depths", gpu.get(&OPTICAL_DEPTHS), cpu.get(&OPTICAL_DEPTHS), 1e-4, 0)
    }
}

pub struct Diffuse;

impl Pass for Diffuse {
    fn name(&self) -> &'static str {
        "volume_diffuse"
    }
    fn kernel(&self) -> &'static str {
        "volumes::diffuse_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, LIGHTS, VOLUMES_PARAMS, VOLUMES, DENSITY, LIGHT_GRIDS, OPTICAL_DEPTHS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![DIFFUSE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_volumes(scene) {
            return skip;
        }
        let p = &scene.volumes.params;
        if p.method == METHOD_SPLATTING {
            return Plan::skip("the volumes are splatted (their columns keep column_width's leakage)");
        }
        if p.columns == 0 {
            return Plan::skip("no multiple scattering by columns (scattering = \"single\" or \"octaves\")");
        }
        if p.column_spread <= 0.0 {
            return Plan::skip("column_spread = 0 (the columns leak by column_width)");
        }
        let nodes = scene.volumes.depth_nodes();
        Plan::run(
            format!(
                "the columns' diffuse light at {nodes} transmittance-volume nodes, each spread over a ring \
                 (column_spread {}; {:.1} MiB)",
                p.column_spread,
                nodes as f64 * 32.0 / (1u64 << 20) as f64
            ),
            nodes,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        let nodes = v.depth_nodes() as usize;
        frame.write_all::<Vec4>(&DIFFUSE, 2 * nodes, |frame, out| {
            let density = frame.get::<f32>(&DENSITY);
            let depths = frame.get::<Vec4>(&OPTICAL_DEPTHS);
            let pairs: &mut [[Vec4; 2]] = bytemuck::cast_slice_mut(out);
            for_each_invocation(pairs, 0, progress, |i, o| {
                let (fluence, flux) = diffuse_node(
                    i,
                    &v.params,
                    &scene.lights,
                    &v.grids,
                    &v.volumes,
                    density,
                    depths,
                    common.light_count,
                );
                *o = [fluence, flux];
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Seven columns' closed forms (a dozen f32 exps each) from
        // trilinear lookups of depths that agree to 1e-4: 1e-3 of the
        // largest value. A ring point on a volume's edge may fall inside
        // on one backend and outside on the other: 1e-3 of the values may
        // differ more.
        let c = cpu.get::<Vec4>(&DIFFUSE);
        compare_rgb("diffuse light", gpu.get(&DIFFUSE), c, 1e-3, c.len() * 3 / 1000 + 1)
    }
}

pub struct Volumes;

impl Pass for Volumes {
    fn name(&self) -> &'static str {
        "volumes"
    }
    fn kernel(&self) -> &'static str {
        "volumes::volumes_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            LIGHT_MAPS,
            SHADOW_MAPS,
            GBUFFER,
            VOLUMES_PARAMS,
            VOLUMES,
            DENSITY,
            LIGHT_GRIDS,
            OPTICAL_DEPTHS,
            DIFFUSE
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![VOLUME_RADIANCE, VOLUME_TRANSMITTANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&VOLUME_RADIANCE)
    }
    fn transmittance_layer(&self) -> Option<&'static Resource> {
        Some(&VOLUME_TRANSMITTANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip_without_volumes(scene) {
            return skip;
        }
        let p = &scene.volumes.params;
        if p.method == METHOD_SPLATTING {
            return Plan::skip("the volumes are splatted (volume_splats)");
        }
        Plan::run(
            format!(
                "{} volume(s), {} on {} planes over depths {:.3}..{:.3} m",
                p.volume_count,
                scattering_label(p),
                p.plane_count,
                p.depth_near,
                p.depth_far
            ),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        let inputs = VolumeInputs {
            params: &v.params,
            volumes: &v.volumes,
            density: frame.get(&DENSITY),
            lights: &scene.lights,
            light_map: &scene.light_map,
            shadow: frame.get(&SHADOW_MAPS),
            grids: &v.grids,
            depths: frame.get(&OPTICAL_DEPTHS),
            diffuse: frame.get(&DIFFUSE),
        };
        let layers = per_pixel_layers(common, frame, progress, |i, d| volumes_pixel(i, common, &inputs, d));
        frame.insert(&VOLUME_RADIANCE, layers.0);
        frame.insert(&VOLUME_TRANSMITTANCE, layers.1);
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layers(gpu, cpu, &VOLUME_RADIANCE, &VOLUME_TRANSMITTANCE)
    }
}

/// Runs a volume renderer's per-pixel function (pixel index and the
/// G-buffer's surface distance to radiance and transmittance) over the
/// band: its radiance and transmittance layers.
fn per_pixel_layers(
    common: &CommonParams,
    frame: &Frame,
    progress: &ProgressBar,
    pixel: impl Fn(u32, f32) -> (Vec4, Vec4) + Sync,
) -> (Buffer, Buffer) {
    let n = common.band_pixels as usize;
    let blank = slicelight_shaders::common::surface::no_surface();
    let gbuffer = frame.get::<GBufferTexel>(&GBUFFER);
    let mut radiance = Buffer::overwritten::<Vec4>(n);
    let mut transmittance = Buffer::overwritten::<Vec4>(n);
    for_each_invocation2(
        radiance.as_mut_slice::<Vec4>(),
        transmittance.as_mut_slice::<Vec4>(),
        common.band_start,
        progress,
        |i, l, t| {
            let texel = gbuffer.get((i - common.band_start) as usize).unwrap_or(&blank);
            (*l, *t) = pixel(i, texel.normal_distance.w);
        },
    );
    (radiance, transmittance)
}

/// Compares a volume renderer's two layers between the backends.
fn compare_layers(gpu: &Frame, cpu: &Frame, radiance: &Resource, transmittance: &Resource) -> Result<String> {
    // Hundreds of intervals or billboards per ray, each a product of f32
    // exps (and trilinear lookups): 1e-3 of the peak. A ray that grazes a
    // box's edge or a plane may take or miss one interval between the
    // backends, and a tile or order that differs (splatting) changes a few
    // pixels: 1e-3 of the values may differ more.
    let l = cpu.get::<Vec4>(radiance);
    let a = compare_rgb(radiance.name, gpu.get(radiance), l, 1e-3, l.len() * 3 / 1000 + 1)?;
    let t = cpu.get::<Vec4>(transmittance);
    let b = compare_rgb(transmittance.name, gpu.get(transmittance), t, 1e-3, t.len() * 3 / 1000 + 1)?;
    Ok(format!("{a}; {b}"))
}
