//! Desert scenes (the survey's section 5; kernels in
//! `shader-crate/src/desert/`): `[[terrain]]` height fields, from an image,
//! from procedural noise, or formed by the sand automaton (`dunes`), drawn
//! as the paper's mesh of quadrilaterals (two triangles each, through the
//! BVH, so that shadows, the sky's sun and every pass see them as any
//! object), and written out by `slicelight terrain`.

use anyhow::{anyhow, bail, Result};
use glam::Vec3;
use indicatif::ProgressBar;
use serde::Deserialize;
use std::path::{Path, PathBuf};

use crate::passes::{Family, Pass, Resource, ResourceKind};
use crate::scene::geometry::IndexedMesh;
use crate::scene::{invalid, validate};
use glam::Vec4;
use slicelight_shaders::desert::ripples::{RippleRecord, Ripples};

pub mod bench;
pub mod dunes;
pub(crate) mod reference;

static PASSES: &[&dyn Pass] = &[&dunes::Dunes];

pub static FAMILY: Family = Family { name: "desert", passes: PASSES, kernels: &[], bench: Some(&bench::DesertSweep) };

/// A `[[terrain]]`: a height field over the rectangle `min .. min + size`
/// (x, z; metres), its height 0 at `elevation` (y), from exactly one of
/// `heights`, `procedural` or `dunes`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Terrain {
    pub min: [f32; 2],
    pub size: [f32; 2],
    #[serde(default)]
    pub elevation: f32,
    pub heights: Option<HeightsFile>,
    pub procedural: Option<Procedural>,
    pub dunes: Option<dunes::Settings>,
    #[serde(default = "default_sand")]
    pub albedo: [f32; 3],
    /// Quadrilaterals along x and z; default one per cell of the field
    /// (at most 512 x 512).
    pub mesh: Option<[u32; 2]>,
    /// Wind ripples on the terrain as bump textures (the survey's 5.2).
    pub ripples: Option<RippleSettings>,
    /// Passes of a 3 x 3 binomial filter over the field before it is
    /// meshed (display only: the automaton's whole slabs become slopes);
    /// default 1 for dunes, 0 otherwise.
    pub smoothing: Option<u32>,
    /// The ground where the field has (next to) no sand: its own albedo,
    /// and no ripples.
    pub bare: Option<Bare>,
}

/// `bare = { albedo, depth = 0.05 }`: triangles whose three corners lie
/// less than `depth` m above the terrain's height 0 are bare ground.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bare {
    pub albedo: [f32; 3],
    pub depth: Option<f32>,
}

fn default_sand() -> [f32; 3] {
    [0.78, 0.62, 0.42]
}

/// `ripples = { ... }`: a ripple field formed by the sand automaton at
/// ripple scale (Nishimori and Ouchi: the saltation length grows with the
/// height, `jump_growth`), tiled over the terrain as a bump texture whose
/// resolution each triangle takes by its distance from the eye.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RippleSettings {
    /// The square tile's side, m; default 4.
    pub size: Option<f32>,
    /// Texels a side (a power of two, 32..=2048); default 256.
    pub cells: Option<u32>,
    /// Automaton steps; default 300.
    pub steps: Option<u32>,
    #[serde(default)]
    pub seed: u32,
    /// Growth of the saltation length per slab of height (a slab is a
    /// fiftieth of a texel), texels; default 1. The ripples' wavelength
    /// grows with it (tests/desert.rs).
    pub jump_growth: Option<f32>,
    /// Creep probability per round; default 0.3.
    pub creep: Option<f32>,
    /// How much the ripples tilt the surface: their heights times this; default 1.
    pub strength: Option<f32>,
    /// The level of detail: `true` (default), each triangle at the level
    /// its distance calls for (the paper's); `"blend"`, each point between
    /// the two levels around its own distance (no seams between
    /// triangles); `false`, always the full resolution (what the LOD is
    /// measured against).
    #[serde(default)]
    pub lod: RippleLod,
}

/// How the ripples' resolution follows the distance (`RipplesSettings::lod`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RippleLod {
    /// Always the full resolution (`lod = false`).
    Full,
    /// Each triangle at one level (`lod = true`), the paper's choice.
    #[default]
    Triangle,
    /// Each point between two levels (`lod = "blend"`).
    Blend,
}

impl<'de> serde::Deserialize<'de> for RippleLod {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Flag(bool),
            Name(String),
        }
        match Raw::deserialize(d)? {
            Raw::Flag(true) => Ok(RippleLod::Triangle),
            Raw::Flag(false) => Ok(RippleLod::Full),
            Raw::Name(name) => match name.as_str() {
                "triangle" => Ok(RippleLod::Triangle),
                "blend" => Ok(RippleLod::Blend),
                "full" => Ok(RippleLod::Full),
                _ => Err(serde::de::Error::custom(format!(
                    "expected true, false, \"triangle\", \"blend\" or \"full\", found \"{name}\""
                ))),
            },
        }
    }
}

impl RippleLod {
    /// Sets every terrain's ripples in `file` to this level of detail (a
    /// `SceneData::reconfigure` edit).
    pub fn apply(self, file: &mut crate::scene::SceneFile) {
        file.terrain.iter_mut().filter_map(|t| t.ripples.as_mut()).for_each(|r| r.lod = self);
    }

    /// `RippleRecord::lod`'s value.
    fn code(self) -> u32 {
        use slicelight_shaders::desert::ripples::{LOD_BLEND, LOD_FULL, LOD_TRIANGLE};
        match self {
            RippleLod::Full => LOD_FULL,
            RippleLod::Triangle => LOD_TRIANGLE,
            RippleLod::Blend => LOD_BLEND,
        }
    }
}

/// `heights = { file, scale }`: a grey image (8- or 16-bit PNG, or a float
/// EXR's red channel), its first row at `min`'s z, each pixel a node of the
/// field; height = value times `scale` metres (PNG values run 0 to 1).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeightsFile {
    pub file: PathBuf,
    #[serde(default = "one")]
    pub scale: f32,
    /// Whether the field wraps around (as a field `slicelight terrain`
    /// wrote from dunes does): its nodes then sit at the cells' corners and
    /// the last row and column meet the first.
    #[serde(default)]
    pub periodic: bool,
}

fn one() -> f32 {
    1.0
}

/// `procedural = { ... }`: value noise, `octaves` octaves from `wavelength`
/// metres down by halves, each half the last's amplitude; heights in
/// `[0, amplitude]` metres.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Procedural {
    pub cells: [u32; 2],
    pub amplitude: f32,
    pub wavelength: f32,
    #[serde(default = "four")]
    pub octaves: u32,
    #[serde(default)]
    pub seed: u32,
}

fn four() -> u32 {
    4
}

/// A height field: `heights` (m above the terrain's elevation) at
/// `nx x nz` nodes, x fastest. A periodic field (the automaton's, which
/// wraps around) has its nodes at the cells' corners `min + i size / n`,
/// node `n` being node 0; otherwise the nodes span the rectangle edge to
/// edge (`min + i size / (n - 1)`).
#[derive(Debug, Clone, Default)]
pub struct Field {
    pub nx: u32,
    pub nz: u32,
    pub heights: Vec<f32>,
    pub periodic: bool,
}

impl Field {
    fn at(&self, i: i64, k: i64) -> f32 {
        let (nx, nz) = (self.nx as i64, self.nz as i64);
        let (i, k) =
            if self.periodic { (i.rem_euclid(nx), k.rem_euclid(nz)) } else { (i.clamp(0, nx - 1), k.clamp(0, nz - 1)) };
        self.heights[(k * nx + i) as usize]
    }

    /// The height at `(u, v)` in `[0, 1]^2` of the rectangle, bilinear.
    pub fn sample(&self, u: f64, v: f64) -> f32 {
        let span = |n: u32| if self.periodic { n as f64 } else { (n.max(2) - 1) as f64 };
        let (x, z) = (u * span(self.nx), v * span(self.nz));
        let (i, k) = (x.floor(), z.floor());
        let (fx, fz) = ((x - i) as f32, (z - k) as f32);
        let (i, k) = (i as i64, k as i64);
        let a = self.at(i, k) * (1.0 - fx) + self.at(i + 1, k) * fx;
        let b = self.at(i, k + 1) * (1.0 - fx) + self.at(i + 1, k + 1) * fx;
        a * (1.0 - fz) + b * fz
    }

    /// The field filtered once by the 3 x 3 binomial kernel (1 2 1 along
    /// each axis, over 16), wrapping around a periodic field and holding the
    /// edge values of another.
    pub fn smoothed(&self) -> Field {
        let mut heights = Vec::with_capacity(self.heights.len());
        for k in 0..self.nz as i64 {
            for i in 0..self.nx as i64 {
                let mut sum = 0.0;
                for (dk, wk) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                    for (di, wi) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                        sum += wk * wi * self.at(i + di, k + dk);
                    }
                }
                heights.push(sum / 16.0);
            }
        }
        Field { heights, ..*self }
    }

    /// Quadrilaterals per axis the field has.
    fn quads(&self) -> [u32; 2] {
        let q = |n: u32| if self.periodic { n } else { n.saturating_sub(1).max(1) };
        [q(self.nx), q(self.nz)]
    }
}

/// The family's share of a scene: each terrain's field, and the first
/// dunes' automaton (what the `desert.dunes` self-check runs) with the
/// slabs it ended with at load, before settling.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub fields: Vec<Field>,
    pub dunes: Option<dunes::Setup>,
    pub dune_slabs: Option<Vec<u32>>,
    /// The ripple textures (`shaders::desert::ripples`) and, per terrain,
    /// its record's index + 1 (0: no ripples).
    pub ripple_records: Vec<RippleRecord>,
    pub ripple_normals: Vec<Vec4>,
    pub ripple_of_terrain: Vec<u32>,
}

impl Setup {
    pub fn ripples(&self) -> Ripples<'_> {
        Ripples { records: &self.ripple_records, normals: &self.ripple_normals }
    }
}

pub static RIPPLE_RECORDS: Resource = Resource {
    binding: 66,
    name: "ripple records",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.desert.ripple_records)),
};
pub static RIPPLE_NORMALS: Resource = Resource {
    binding: 67,
    name: "ripple normals",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.desert.ripple_normals)),
};

/// Most quadrilaterals a terrain's mesh may have (8 million triangles).
const MAX_QUADS: u64 = 1 << 22;
/// Most nodes a height field may have.
const MAX_NODES: u64 = 1 << 26;

/// Validates the terrains and builds their fields (running the dunes'
/// automaton, with a progress bar when `progress` is shown).
pub fn configure(terrains: &[Terrain], base: &Path, time: f64, progress: &ProgressBar) -> Result<Setup> {
    let mut setup = Setup::default();
    for (t, terrain) in terrains.iter().enumerate() {
        let field = format!("terrain[{t}]");
        validate::finite3(&format!("{field}.min"), [terrain.min[0], 0.0, terrain.min[1]])?;
        if !terrain.size.iter().all(|s| s.is_finite() && *s > 0.0) {
            bail!(invalid(&format!("{field}.size"), "two positive lengths (m) along x and z", terrain.size));
        }
        if !terrain.elevation.is_finite() {
            bail!(invalid(&format!("{field}.elevation"), "a finite height (m)", terrain.elevation));
        }
        validate::albedo(&format!("{field}.albedo"), terrain.albedo)?;
        if let Some(b) = &terrain.bare {
            validate::albedo(&format!("{field}.bare.albedo"), b.albedo)?;
            let depth = b.depth.unwrap_or(DEFAULT_BARE_DEPTH);
            if !(depth.is_finite() && depth > 0.0 && depth <= 1e7) {
                bail!(invalid(&format!("{field}.bare.depth"), "a positive depth of sand, m", depth));
            }
        }
        let sources =
            terrain.heights.is_some() as u32 + terrain.procedural.is_some() as u32 + terrain.dunes.is_some() as u32;
        if sources != 1 {
            bail!(invalid(&field, "exactly one of heights, procedural or dunes", format!("{sources} of them")));
        }
        let f = if let Some(h) = &terrain.heights {
            read_heights(&format!("{field}.heights"), base, h)?
        } else if let Some(p) = &terrain.procedural {
            procedural(&format!("{field}.procedural"), p)?
        } else {
            let d = terrain.dunes.as_ref().expect("one source");
            let s = dunes::configure(&field, d, terrain.min, terrain.size, time)?;
            let (slabs, heights) = dunes::formed(&s, progress)?;
            let field = Field { nx: s.cells[0], nz: s.cells[1], heights, periodic: true };
            if setup.dunes.is_none() {
                setup.dunes = Some(s);
                setup.dune_slabs = Some(slabs);
            }
            field
        };
        let passes = terrain.smoothing.unwrap_or(if terrain.dunes.is_some() { 1 } else { 0 });
        if passes > 16 {
            bail!(invalid(&format!("{field}.smoothing"), "0 to 16 filter passes", passes));
        }
        let f = (0..passes).fold(f, |f, _| f.smoothed());
        if let Some(m) = terrain.mesh {
            if m[0] == 0 || m[1] == 0 || m[0] as u64 * m[1] as u64 > MAX_QUADS {
                bail!(invalid(
                    &format!("{field}.mesh"),
                    &format!("two positive counts, at most {MAX_QUADS} quadrilaterals"),
                    m
                ));
            }
        }
        setup.fields.push(f);
        let record = match &terrain.ripples {
            Some(r) => {
                ripple_texture(&format!("{field}.ripples"), r, terrain, &mut setup, progress)?;
                setup.ripple_records.len() as u32
            }
            None => 0,
        };
        setup.ripple_of_terrain.push(record);
    }
    Ok(setup)
}

/// Runs the ripple automaton for `r`, and appends its record and its
/// normals at every level (full resolution, then each halving to 32).
fn ripple_texture(
    field: &str,
    r: &RippleSettings,
    t: &Terrain,
    setup: &mut Setup,
    progress: &ProgressBar,
) -> Result<()> {
    let size = r.size.unwrap_or(4.0);
    if !(size.is_finite() && size > 0.0) {
        bail!(invalid(&format!("{field}.size"), "a positive tile side, m", size));
    }
    let n = r.cells.unwrap_or(256);
    if !(n.is_power_of_two() && (32..=2048).contains(&n)) {
        bail!(invalid(&format!("{field}.cells"), "a power of two in 32..=2048", n));
    }
    let strength = r.strength.unwrap_or(1.0);
    if !(strength.is_finite() && (0.0..=100.0).contains(&strength)) {
        bail!(invalid(&format!("{field}.strength"), "a factor in [0, 100]", strength));
    }
    let growth = r.jump_growth.unwrap_or(1.0);
    if !(growth.is_finite() && (0.0..=256.0).contains(&growth)) {
        bail!(invalid(&format!("{field}.jump_growth"), "texels per slab in [0, 256]", growth));
    }
    let dx = size / n as f32;
    let settings = dunes::Settings {
        cells: [n, n],
        steps: r.steps.unwrap_or(300),
        steps_per_second: None,
        seed: r.seed,
        sand: Some(dx * 0.2),
        slab: Some(dx * 0.02),
        wind_speed: None,
        wind_direction: None,
        threshold_speed: None,
        erosion: None,
        jump: Some(1.0),
        jump_growth: Some(growth / (dx * 0.02)),
        hops: Some(1),
        deposit: None,
        repose_deg: None,
        shadow_deg: None,
        creep: Some(r.creep.unwrap_or(0.3)),
        piles: None,
        avalanche_rounds: None,
        creep_rounds: None,
    };
    let s = dunes::configure(field, &settings, [0.0, 0.0], [size, size], 0.0)?;
    let mut heights: Vec<f32> = dunes::formed(&s, progress)?.1.iter().map(|h| h * strength).collect();
    let offset = setup.ripple_normals.len() as u32;
    let mut side = n;
    let mut levels = 0;
    loop {
        // Normals by central differences over the periodic field.
        let at =
            |i: i64, k: i64| heights[(k.rem_euclid(side as i64) * side as i64 + i.rem_euclid(side as i64)) as usize];
        let texel = size / side as f32;
        for k in 0..side as i64 {
            for i in 0..side as i64 {
                let dhdx = (at(i + 1, k) - at(i - 1, k)) / (2.0 * texel);
                let dhdz = (at(i, k + 1) - at(i, k - 1)) / (2.0 * texel);
                setup.ripple_normals.push(Vec3::new(-dhdx, 1.0, -dhdz).normalize().extend(0.0));
            }
        }
        levels += 1;
        if side <= 32 {
            break;
        }
        // The next level: each 2 x 2 block's mean height.
        let half = side / 2;
        let mut coarse = Vec::with_capacity((half * half) as usize);
        for k in 0..half {
            for i in 0..half {
                let (a, b) = ((2 * k * side + 2 * i) as usize, ((2 * k + 1) * side + 2 * i) as usize);
                coarse.push(0.25 * (heights[a] + heights[a + 1] + heights[b] + heights[b + 1]));
            }
        }
        heights = coarse;
        side = half;
    }
    setup.ripple_records.push(RippleRecord {
        origin_x: t.min[0],
        origin_z: t.min[1],
        inverse_size: 1.0 / size,
        texel: dx,
        resolution: n,
        levels,
        offset,
        lod: r.lod.code(),
    });
    Ok(())
}

/// The terrain's mesh: `mesh` quadrilaterals (default the field's, at most
/// 512 a side), two triangles each facing up, vertices on the field.
/// The depth of sand (m) under which the ground shows (`bare`).
const DEFAULT_BARE_DEPTH: f32 = 0.05;

/// `mesh` split into the sand's triangles and, with `bare`, the bare
/// ground's (every corner less than `bare.depth` above height 0) with its
/// albedo (`None` without `bare` or where no triangle is bare). Both keep
/// every vertex.
pub fn sand_and_bare(terrain: &Terrain, mesh: IndexedMesh) -> (IndexedMesh, Option<(IndexedMesh, [f32; 3])>) {
    let Some(b) = &terrain.bare else { return (mesh, None) };
    let below = terrain.elevation + b.depth.unwrap_or(DEFAULT_BARE_DEPTH);
    let (bare, sand): (Vec<[u32; 3]>, Vec<[u32; 3]>) =
        mesh.indices.iter().partition(|f| f.iter().all(|&i| mesh.positions[i as usize].y < below));
    if bare.is_empty() {
        return (mesh, None);
    }
    let ground = IndexedMesh { positions: mesh.positions.clone(), normals: mesh.normals.clone(), indices: bare };
    (IndexedMesh { indices: sand, ..mesh }, Some((ground, b.albedo)))
}

pub fn mesh(terrain: &Terrain, field: &Field) -> IndexedMesh {
    let [mx, mz] = mesh_quads(terrain, field);
    let mut mesh = IndexedMesh::default();
    for k in 0..=mz {
        for i in 0..=mx {
            mesh.positions.push(mesh_node(terrain, field, [mx, mz], i, k));
        }
    }
    let row = mx + 1;
    for k in 0..mz {
        for i in 0..mx {
            let a = k * row + i;
            let (b, c, d) = (a + 1, a + row + 1, a + row);
            mesh.indices.push([a, c, b]);
            mesh.indices.push([a, d, c]);
        }
    }
    // Smooth normals (area-weighted), though diffuse triangles shade flat.
    mesh.normals = vec![Vec3::ZERO; mesh.positions.len()];
    for f in &mesh.indices {
        let [a, b, c] = f.map(|i| mesh.positions[i as usize]);
        let n = (b - a).cross(c - a);
        for i in f {
            mesh.normals[*i as usize] += n;
        }
    }
    for n in &mut mesh.normals {
        *n = n.normalize_or(Vec3::Y);
    }
    mesh
}

/// The terrain's mesh of quadrilaterals: `mesh`, or the field's own
/// resolution up to 512 each way.
fn mesh_quads(terrain: &Terrain, field: &Field) -> [u32; 2] {
    terrain.mesh.unwrap_or_else(|| field.quads().map(|q| q.min(512)))
}

/// Node `(i, k)` of the terrain's mesh of `quads` quadrilaterals (m).
fn mesh_node(terrain: &Terrain, field: &Field, quads: [u32; 2], i: u32, k: u32) -> Vec3 {
    let (u, v) = (i as f64 / quads[0] as f64, k as f64 / quads[1] as f64);
    let y = terrain.elevation + field.sample(u, v);
    let (x, z) =
        (terrain.min[0] as f64 + u * terrain.size[0] as f64, terrain.min[1] as f64 + v * terrain.size[1] as f64);
    Vec3::new(x as f32, y, z as f32)
}

/// How far below the terrain's base its skirt reaches (m): past a ground
/// laid a few centimetres under the base, as the desert scenes lay theirs.
pub const SKIRT_DEPTH: f32 = 0.1;

/// The terrain's skirt: walls from the mesh's edge straight down to
/// `SKIRT_DEPTH` under its base (`elevation`), wherever the edge stands
/// more than a millimetre above the base. A field's edge is wherever its rectangle ends (a
/// periodic dune field's edge cuts through dunes): without the walls a low
/// view past the edge meets the ground under the mesh, in the mesh's
/// shadow, a dark band along the field's foot. (Terrain renderers hang
/// such skirts on their tiles for the same reason.)
pub fn skirt(terrain: &Terrain, field: &Field) -> IndexedMesh {
    let [mx, mz] = mesh_quads(terrain, field);
    let node = |i: u32, k: u32| mesh_node(terrain, field, [mx, mz], i, k);
    // The edge once around, corner to corner.
    let edge: Vec<Vec3> = (0..mx)
        .map(|i| node(i, 0))
        .chain((0..mz).map(|k| node(mx, k)))
        .chain((1..=mx).rev().map(|i| node(i, mz)))
        .chain((1..=mz).rev().map(|k| node(0, k)))
        .collect();
    let foot = terrain.elevation - SKIRT_DEPTH;
    let mut wall = IndexedMesh::default();
    for (j, &a) in edge.iter().enumerate() {
        let b = edge[(j + 1) % edge.len()];
        // (A millimetre is no wall: a field's bare edge may round above 0.)
        if a.y <= terrain.elevation + 1e-3 && b.y <= terrain.elevation + 1e-3 {
            continue;
        }
        let first = wall.positions.len() as u32;
        wall.positions.extend([a, b, Vec3::new(b.x, foot, b.z), Vec3::new(a.x, foot, a.z)]);
        let out = (b - a).cross(Vec3::Y).normalize_or(Vec3::X);
        wall.normals.extend([out; 4]);
        wall.indices.push([first, first + 1, first + 2]);
        wall.indices.push([first, first + 2, first + 3]);
    }
    wall
}

fn read_heights(field: &str, base: &Path, h: &HeightsFile) -> Result<Field> {
    if !(h.scale.is_finite() && h.scale > 0.0) {
        bail!(invalid(&format!("{field}.scale"), "a positive number of metres per unit", h.scale));
    }
    let path = base.join(&h.file);
    crate::output::regular_file(&format!("{field}.file"), &path, crate::output::MAX_IMAGE_BYTES)?;
    let img = image::open(&path)
        .map_err(|e| anyhow!("{field}.file: cannot read the height image '{}': {e}", path.display()))?;
    heights_from_image(field, &path, &img, h.scale, h.periodic)
}

/// A height field from a decoded grey image (the first channel, times
/// `scale` metres); `path` names it in errors.
pub fn heights_from_image(
    field: &str,
    path: &Path,
    img: &image::DynamicImage,
    scale: f32,
    periodic: bool,
) -> Result<Field> {
    let (w, hgt) = (img.width(), img.height());
    if w as u64 * hgt as u64 > MAX_NODES {
        bail!(invalid(
            &format!("{field}.file"),
            &format!("an image of at most {MAX_NODES} pixels"),
            format!("{w}x{hgt} ({})", path.display())
        ));
    }
    let rgb = img.to_rgb32f();
    let mut heights = Vec::with_capacity((w * hgt) as usize);
    for (i, p) in rgb.pixels().enumerate() {
        let v = p.0[0];
        if !v.is_finite() {
            bail!(invalid(
                &format!("{field}.file"),
                "finite heights in every pixel",
                format!("{v} at pixel ({}, {}) of '{}'", i as u32 % w, i as u32 / w, path.display())
            ));
        }
        heights.push(v * scale);
    }
    Ok(Field { nx: w, nz: hgt, heights, periodic })
}

/// Value noise on integer lattice points (the counter-based hash), smoothed.
fn procedural(field: &str, p: &Procedural) -> Result<Field> {
    let [nx, nz] = p.cells;
    if nx < 2 || nz < 2 || nx as u64 * nz as u64 > MAX_NODES {
        bail!(invalid(
            &format!("{field}.cells"),
            &format!("two node counts of at least 2, at most {MAX_NODES} in all"),
            p.cells
        ));
    }
    if !(p.amplitude.is_finite() && p.amplitude >= 0.0) {
        bail!(invalid(&format!("{field}.amplitude"), "a height of at least 0 m", p.amplitude));
    }
    if !(p.wavelength.is_finite() && p.wavelength > 0.0) {
        bail!(invalid(&format!("{field}.wavelength"), "a positive number of metres", p.wavelength));
    }
    if !(1..=12).contains(&p.octaves) {
        bail!(invalid(&format!("{field}.octaves"), "1 to 12 octaves", p.octaves));
    }
    use slicelight_shaders::random::random;
    let lattice = |o: u32, i: i64, k: i64| {
        let cell = (i as u32).wrapping_mul(0x9e37_79b9) ^ (k as u32);
        random(cell, o, p.seed, 300) as f32 / u32::MAX as f32
    };
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let mut heights = Vec::with_capacity((nx * nz) as usize);
    let norm: f32 = (0..p.octaves).map(|o| 0.5f32.powi(o as i32)).sum();
    for k in 0..nz {
        for i in 0..nx {
            let mut h = 0.0;
            for o in 0..p.octaves {
                // Node (i, k) in units of this octave's wavelength (nodes a node apart, 1 m each).
                let cells_per_wave = p.wavelength / 2f32.powi(o as i32);
                let (x, z) = (i as f32 / cells_per_wave, k as f32 / cells_per_wave);
                let (xi, zi) = (x.floor() as i64, z.floor() as i64);
                let (fx, fz) = (smooth(x - x.floor()), smooth(z - z.floor()));
                let a = lattice(o, xi, zi) * (1.0 - fx) + lattice(o, xi + 1, zi) * fx;
                let b = lattice(o, xi, zi + 1) * (1.0 - fx) + lattice(o, xi + 1, zi + 1) * fx;
                h += (a * (1.0 - fz) + b * fz) * 0.5f32.powi(o as i32);
            }
            heights.push(h / norm * p.amplitude);
        }
    }
    Ok(Field { nx, nz, heights, periodic: false })
}

/// Writes each terrain's heights (m above its elevation): a float EXR
/// (grey in r, g and b), or a 16-bit grey PNG from 0 to the field's highest
/// point; `path` for the first, `stem_1.ext` ... for the others. Returns the
/// files written, each with a note (a PNG's `scale`).
pub fn write_fields(setup: &Setup, path: &Path) -> Result<Vec<(PathBuf, String)>> {
    if setup.fields.is_empty() {
        bail!("the scene has no [[terrain]] to write");
    }
    let png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !png && !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
        bail!("{}: expected a .exr or .png file name", path.display());
    }
    let mut written = Vec::new();
    for (t, f) in setup.fields.iter().enumerate() {
        let out = if t == 0 {
            path.to_path_buf()
        } else {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let ext = path.extension().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            path.with_file_name(format!("{stem}_{t}.{ext}"))
        };
        let periodic = if f.periodic { ", periodic = true" } else { "" };
        let encoded = if png {
            let top = f.heights.iter().fold(0.0f32, |m, &h| m.max(h));
            let scale = if top > 0.0 { top } else { 1.0 };
            let grey: Vec<u16> =
                f.heights.iter().map(|&h| (h.max(0.0) / scale * 65535.0).round().min(65535.0) as u16).collect();
            let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(f.nx, f.nz, grey).expect("nx * nz values");
            let mut bytes = std::io::Cursor::new(Vec::new());
            image::DynamicImage::ImageLuma16(img)
                .write_to(&mut bytes, image::ImageFormat::Png)
                .map(|()| (bytes.into_inner(), format!(" (heights = {{ file, scale = {scale}{periodic} }})")))
                .map_err(|e| anyhow!("{e}"))
        } else {
            let rgb = ["R", "G", "B"].map(|c| (c.to_string(), f.heights.clone())).to_vec();
            crate::output::exr_bytes(f.nx, f.nz, rgb).map(|b| (b, format!(" (heights = {{ file{periodic} }})")))
        };
        let (bytes, note) = encoded.map_err(|e| anyhow!("{}: cannot encode the heights: {e}", out.display()))?;
        crate::output::write_atomically(&out, &bytes)?;
        written.push((out, note));
    }
    Ok(written)
}
