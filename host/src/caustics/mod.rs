//! The caustics passes (kernels: `shader-crate/src/caustics/`): the light
//! transport table of every glass mesh (`caustics.table`), the exit rays for
//! the scene's lights (`caustics.lookup`), the illumination volumes
//! rasterised into caustics maps on horizontal sample planes
//! (`caustics.maps`), and the caustic light on the surfaces each pixel sees
//! (`caustics`, an EXR layer).

pub mod bench;
pub mod reference;

use anyhow::{bail, ensure, Result};
use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use slicelight_shaders::caustics::{
    caustic_shafts_pixel, caustics_pixel, light_at_vertex, load_entry, lookup, map_bins, map_invocations, map_texels,
    rasterize, resolve_texel, store_entry, table_entry, table_slot, triangle_flux, CausticsParams, ExitRay, TableEntry,
    ENTRY_WORDS, MAX_SHAFT_PLANES, MAX_SLOPE, PACKED_WORDS,
};
use slicelight_shaders::glass::{dispersive, trace_through, Glass, PATH_OUT};
use slicelight_shaders::scatter::words_for;
use slicelight_shaders::types::{CommonParams, GBufferTexel, MATERIAL_GLASS, NO_OBJECT};

use crate::passes::*;

/// The family's passes, in the order they run (see `passes::FAMILIES`).
pub static PASSES: &[&dyn Pass] = &[
    &CausticsTable,
    &CausticsLookup,
    &CausticsMaps,
    &Caustics,
    &CausticShaftMaps,
    &CausticShaftResolve,
    &CausticShafts,
];

/// The family, as `passes::FAMILIES` registers it.
pub static FAMILY: Family =
    Family { name: "caustics", passes: PASSES, kernels: &[], bench: Some(&bench::CausticsSweep) };
use crate::cpu::{for_each_invocation, scatter_each_index, ScatterKernel};
use crate::scene::{invalid, SceneData};
use rayon::prelude::*;
use slicelight_shaders::scatter::AtomicWords;

/// The scene's `[caustics]` table.
#[derive(Debug, Clone, Copy, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Settings {
    /// Draw caustics at all (true).
    pub enabled: bool,
    /// Table directions per vertex: `[rings, azimuths]`, `1 + rings x
    /// azimuths` in all (default `[8, 16]`: the paper's 129).
    pub directions: [u32; 2],
    /// Horizontal sample planes through the receivers (default 6, the paper's).
    pub planes: u32,
    /// Texels along the longer side of the caustics maps (default 512, the paper's).
    pub map_resolution: u32,
    /// Keep light transport tables on disk and reuse them (true).
    pub cache: bool,
    /// Pack table entries into 16-bit fields, 20 bytes instead of 48
    /// (section 6; true).
    pub compression: bool,
    /// Caustic light shafts in a scattering `[medium]` (true): the light the
    /// glass refracts, scattered toward the eye (`caustic_shafts_pixel`).
    pub shafts: bool,
    /// Horizontal shaft planes from the receivers up to the highest point
    /// the light leaves the glass from (default 32, 2..=64).
    pub shaft_planes: u32,
    /// Texels along each side of every shaft plane's square map, which
    /// covers where the light crosses that plane (default 128, 16..=1024).
    pub shaft_resolution: u32,
    /// Intervals along each view ray where it crosses the shaft maps (default 32, 2..=256).
    pub shaft_steps: u32,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            enabled: true,
            directions: [8, 16],
            planes: 6,
            map_resolution: 512,
            cache: true,
            compression: true,
            shafts: true,
            shaft_planes: 32,
            shaft_resolution: 128,
            shaft_steps: 32,
        }
    }
}

/// What the caustics passes run with.
#[derive(Debug, Clone, Default)]
pub struct Setup {
    pub enabled: bool,
    /// The whole light transport table, when every glass object's is in
    /// the cache (`has_cached_table`, `forget_cached_table`).
    cached_table: Option<Buffer>,
    /// Where each glass object's table is kept, and its entries in the table.
    pub cache_files: Vec<CacheFile>,
    /// Vertex-channels the table holds (`GlassVertex::table_block` of the end).
    pub table_blocks: u32,
    /// Why not, when not enabled.
    pub reason: String,
    pub params: CausticsParams,
    /// The shaft maps' parameters (`planes` 0: no caustic shafts).
    pub shafts: CausticsParams,
    /// Why no caustic shafts, when there are none.
    pub shafts_reason: String,
}

/// Largest light transport table, bytes (lavapipe binds at most 128 MiB).
const MAX_TABLE_BYTES: u64 = 120 << 20;

/// Validates the settings and places the sample planes and maps over the
/// area the scene's lights can send light through its glass to.
pub fn configure(s: &Settings, scene: &SceneData) -> Result<Setup> {
    let [rings, azimuths] = s.directions;
    if !(1..=64).contains(&rings) || !(3..=256).contains(&azimuths) {
        bail!(invalid("directions", "[rings, azimuths] with rings in 1..=64 and azimuths in 3..=256", s.directions));
    }
    if !(1..=64).contains(&s.planes) {
        bail!(invalid("planes", "a count in 1..=64", s.planes));
    }
    if !(16..=4096).contains(&s.map_resolution) {
        bail!(invalid("map_resolution", "a texel count in 16..=4096", s.map_resolution));
    }
    if !(2..=MAX_SHAFT_PLANES).contains(&s.shaft_planes) {
        bail!(invalid("shaft_planes", &format!("a count in 2..={MAX_SHAFT_PLANES}"), s.shaft_planes));
    }
    if !(16..=1024).contains(&s.shaft_resolution) {
        bail!(invalid("shaft_resolution", "a texel count in 16..=1024", s.shaft_resolution));
    }
    if !(2..=256).contains(&s.shaft_steps) {
        bail!(invalid("shaft_steps", "a count in 2..=256", s.shaft_steps));
    }
    let off = |reason: &str| Ok(Setup { enabled: false, reason: reason.into(), ..Default::default() });
    if scene.glass_vertices.is_empty() {
        return off("no glass");
    }
    if !s.enabled {
        return off("[caustics] enabled = false");
    }
    if scene.lights.is_empty() {
        return off("no lights");
    }
    let channels = if scene.materials.iter().any(|m| m.kind == MATERIAL_GLASS && dispersive(m)) { 3 } else { 1 };
    let directions = 1 + rings * azimuths;
    let vertex_count = scene.glass_vertices.len() as u32;
    let blocks = scene.glass_vertices.last().map_or(0, |v| v.table_block + v.channels) as u64;
    let entry_words = if s.compression { PACKED_WORDS } else { ENTRY_WORDS };
    let table_bytes = blocks * directions as u64 * entry_words as u64 * 4;
    if table_bytes > MAX_TABLE_BYTES {
        bail!(invalid(
            "directions",
            &format!(
                "a light transport table of at most {} MiB: {vertex_count} glass vertices ({blocks} vertex-channels) x {directions} directions x {} B is {} MiB",
                MAX_TABLE_BYTES >> 20,
                entry_words * 4,
                table_bytes >> 20
            ),
            s.directions
        ));
    }
    let Some((lo, hi)) = receiver_bounds(scene) else {
        return off("no opaque surface to receive caustics");
    };
    let glass_top = scene.glass_vertices.iter().map(|v| v.position.y).fold(f32::NEG_INFINITY, f32::max);
    let y_lo = lo.y;
    let y_hi = hi.y.min(glass_top).max(y_lo);
    let scale = lo.abs().max(hi.abs()).max_element().max(1.0);
    let (planes, spacing) = if s.planes == 1 || y_hi - y_lo < 1e-4 * scale {
        (1, 0.0)
    } else {
        (s.planes, (y_hi - y_lo) / (s.planes - 1) as f32)
    };

    let y_top = y_lo + spacing * (planes - 1) as f32;
    let exits = exit_rays(scene, channels);
    let Some(footprint) = footprint(&exits, [y_lo, y_top]) else {
        return off("no light leaves the glass downward toward the receivers");
    };
    let (xz_lo, map_width, map_height, texel) = map_rectangle(footprint, (lo, hi), scale, s.map_resolution);
    let Some(fixed_scale) = fixed_point_scale(scene, texel) else {
        return off("the lights send no light onto the glass");
    };

    let params = CausticsParams {
        map_origin: Vec4::new(xz_lo.x, y_lo, xz_lo.y, texel),
        rings,
        azimuths,
        directions,
        channels,
        vertex_count,
        triangle_count: scene.glass_triangles.len() as u32,
        light_count: scene.lights.len() as u32,
        planes,
        map_width,
        map_height,
        plane_spacing: spacing,
        scale: fixed_scale,
        compressed: s.compression as u32,
        entry_words,
        shaft_steps: 0,
        _pad: 0,
        ..Default::default()
    };
    let (shafts, shafts_reason) = match shaft_maps(s, scene, &params, &exits, (lo, hi), scale) {
        Ok(shafts) => (shafts, String::new()),
        Err(reason) => (CausticsParams::default(), reason.to_string()),
    };
    let mut setup =
        Setup { enabled: true, table_blocks: blocks as u32, params, shafts, shafts_reason, ..Default::default() };
    if s.cache {
        if let Some(dir) = cache::directory() {
            cache::load(&mut setup, scene, &dir);
        }
    }
    Ok(setup)
}

/// The bounds of the receivers: every surface that is not glass (none: `None`).
fn receiver_bounds(scene: &SceneData) -> Option<(Vec3, Vec3)> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for sph in &scene.spheres {
        let c = sph.center_radius.truncate();
        lo = lo.min(c - sph.center_radius.w);
        hi = hi.max(c + sph.center_radius.w);
    }
    for t in scene.triangles.iter().filter(|t| t.glass == NO_OBJECT) {
        for v in [t.v0, t.v1, t.v2] {
            lo = lo.min(v.truncate());
            hi = hi.max(v.truncate());
        }
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// The shaft maps' parameters (`caustic_shafts_pixel`): `shaft_planes`
/// planes from the receivers' lowest point up to the highest point the
/// light leaves the glass downward from, over where those rays go between
/// them; the reason why there are none otherwise.
fn shaft_maps(
    s: &Settings,
    scene: &SceneData,
    receivers: &CausticsParams,
    exits: &[(Vec3, Vec3)],
    bounds: (Vec3, Vec3),
    scale: f32,
) -> std::result::Result<CausticsParams, &'static str> {
    if !s.shafts {
        return Err("[caustics] shafts = false");
    }
    if scene.common.sigma_s.truncate().max_element() <= 0.0 {
        return Err("no scattering medium");
    }
    let y_lo = receivers.map_origin.y;
    let top = exits.iter().map(|(p, _)| p.y).fold(f32::NEG_INFINITY, f32::max);
    if top.is_nan() || top - y_lo <= 1e-4 * scale {
        return Err("no light leaves the glass above the receivers");
    }
    let planes = s.shaft_planes;
    let spacing = (top - y_lo) / (planes - 1) as f32;
    let res = s.shaft_resolution;
    let mut rects = [Vec4::ZERO; MAX_SHAFT_PLANES as usize];
    let mut union = (glam::Vec2::splat(f32::INFINITY), glam::Vec2::splat(f32::NEG_INFINITY));
    let mut finest = f32::INFINITY;
    for k in 0..planes {
        // Where the rays cross this plane, or leave the glass below it
        // (`rasterize` draws those where they leave).
        let y = y_lo + spacing * k as f32;
        let crossings = exits.iter().map(|&(p, d)| if p.y >= y { p + d * ((y - p.y) / d.y) } else { p });
        let (mut xs, mut zs): (Vec<f32>, Vec<f32>) = crossings.map(|q| (q.x, q.z)).unzip();
        let (Some(x), Some(z)) = (central(&mut xs), central(&mut zs)) else {
            return Err("no light leaves the glass above the receivers");
        };
        let lo = glam::Vec2::new(x.0, z.0);
        let hi = glam::Vec2::new(x.1, z.1);
        let (corner, _, _, texel) = map_rectangle((lo, hi), bounds, scale, res);
        rects[k as usize] = Vec4::new(corner.x, corner.y, texel, 0.0);
        union.0 = union.0.min(corner);
        union.1 = union.1.max(corner + glam::Vec2::splat(texel * res as f32));
        finest = finest.min(texel);
    }
    let fixed_scale = fixed_point_scale(scene, finest).ok_or("the lights send no light onto the glass")?;
    Ok(CausticsParams {
        map_origin: Vec4::new(union.0.x, y_lo, union.0.y, finest),
        planes,
        map_width: res,
        map_height: res,
        plane_spacing: spacing,
        scale: fixed_scale,
        shaft_steps: s.shaft_steps,
        bounds: Vec4::new(union.0.x, union.0.y, union.1.x, union.1.y),
        rects,
        ..*receivers
    })
}

/// The share of the exit rays a shaft map may leave off on each side, per
/// axis: the light that leaves a lens at grazing angles spreads over the
/// whole floor (a ball's rim sends rays out nearly level); bounding all of
/// it would spread a plane's texels over metres for a thousandth of the flux.
const SHAFT_TAIL: f64 = 0.01;

/// The range of `v` less its `SHAFT_TAIL` at each end (`None` if empty or not finite).
fn central(v: &mut [f32]) -> Option<(f32, f32)> {
    if v.is_empty() || v.iter().any(|x| !x.is_finite()) {
        return None;
    }
    v.sort_unstable_by(f32::total_cmp);
    let cut = (v.len() as f64 * SHAFT_TAIL) as usize;
    Some((v[cut], v[v.len() - 1 - cut]))
}

/// A map's corner (x, z), width and height in texels and texel size over
/// `footprint` with a margin for the rays between the sampled vertices,
/// within the receivers' `bounds`, `resolution` texels along its longer side.
fn map_rectangle(
    (xz_lo, xz_hi): (glam::Vec2, glam::Vec2),
    (lo, hi): (Vec3, Vec3),
    scale: f32,
    resolution: u32,
) -> (glam::Vec2, u32, u32, f32) {
    let margin = (xz_hi - xz_lo).max_element() * 0.1 + 1e-3 * scale;
    let xz_lo = (xz_lo - margin).max(glam::Vec2::new(lo.x, lo.z));
    let xz_hi = (xz_hi + margin).min(glam::Vec2::new(hi.x, hi.z));
    let size = (xz_hi - xz_lo).max(glam::Vec2::splat(1e-6 * scale));
    let texel = size.max_element() / resolution as f32;
    let width = ((size.x / texel).ceil() as u32).clamp(1, resolution);
    let height = ((size.y / texel).ceil() as u32).clamp(1, resolution);
    (xz_lo, width, height, texel)
}

/// The light leaving the glass downward: exactly traced exit rays (point,
/// direction) at up to 4096 vertices per light, in the order of the lights
/// and vertices. On every core: a scene of 11 lights (`caustics_lights`)
/// traces about 90 000 paths here at every build, cache or not.
fn exit_rays(scene: &SceneData, channels: u32) -> Vec<(Vec3, Vec3)> {
    use rayon::prelude::*;
    let geometry = scene.geometry();
    let glass = Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles };
    let stride = (scene.glass_vertices.len() / 4096).max(1);
    let vertices: Vec<_> = scene.glass_vertices.iter().step_by(stride).collect();
    // The channels traced: red and blue through dispersive glass, else one.
    let traced = if channels == 3 { [0, 2] } else { [0, 0] };
    let mut out = Vec::new();
    for light in &scene.lights {
        let rays: Vec<Vec<(Vec3, Vec3)>> = vertices
            .par_iter()
            .map(|v| {
                let (lit, dir) = light_at_vertex(light, &geometry, v);
                if !lit {
                    return Vec::new();
                }
                traced
                    .into_iter()
                    .filter_map(|c| {
                        let path = trace_through(
                            &geometry,
                            &glass,
                            &scene.materials,
                            v.position.truncate(),
                            v.normal.truncate(),
                            v.material,
                            dir,
                            c,
                            v.object,
                            false,
                        );
                        (path.status == PATH_OUT && path.direction.y < 0.0).then_some((path.position, path.direction))
                    })
                    .collect()
            })
            .collect();
        out.extend(rays.into_iter().flatten());
    }
    out
}

/// Where the exit rays cross the planes at `heights` (the lowest and the
/// highest), as x-z bounds; `None` if there is nowhere.
fn footprint(rays: &[(Vec3, Vec3)], heights: [f32; 2]) -> Option<(glam::Vec2, glam::Vec2)> {
    let mut xz_lo = glam::Vec2::splat(f32::INFINITY);
    let mut xz_hi = glam::Vec2::splat(f32::NEG_INFINITY);
    let mut add = |q: Vec3| {
        xz_lo = xz_lo.min(glam::Vec2::new(q.x, q.z));
        xz_hi = xz_hi.max(glam::Vec2::new(q.x, q.z));
    };
    for &(p, d) in rays {
        for y in heights {
            let t = (y - p.y) / d.y;
            if t >= 0.0 {
                add(p + d * t);
            }
        }
    }
    (xz_lo.x <= xz_hi.x).then_some((xz_lo, xz_hi))
}

/// The maps' fixed-point scale (units per W/m^2): no texel can hold more
/// than all the flux that falls on the glass, in one texel of `texel` m,
/// times the largest slope, in 2^60 units. `None` if no light reaches the glass.
fn fixed_point_scale(scene: &SceneData, texel: f32) -> Option<f32> {
    let mut flux_bound = 0.0f64;
    for light in &scene.lights {
        for t in &scene.glass_triangles {
            let [a, b, c] = t.vertices.map(|i| scene.glass_vertices[i as usize].position.truncate());
            let f = triangle_flux(&scene.common, light, &scene.light_map, a, b, c, Vec4::ONE);
            flux_bound += f.truncate().max_element() as f64;
        }
    }
    if flux_bound.is_nan() || flux_bound <= 0.0 {
        return None;
    }
    let peak = flux_bound / (texel as f64 * texel as f64) * 3.0 * MAX_SLOPE as f64;
    Some((2f64.powi(60) / peak).min(1e30) as f32)
}

/// One glass object's light transport table on disk.
#[derive(Debug, Clone)]
pub struct CacheFile {
    pub path: std::path::PathBuf,
    pub key: [u8; 16],
    /// Its entries in the scene's table.
    pub entries: std::ops::Range<usize>,
}

/// The disk cache of light transport tables: one file per glass object,
/// named by a 128-bit hash (XXH3) of everything its table depends on (the
/// object's shape as defined, less its position and rotation: a sphere's
/// radius and tessellation, a mesh file's bytes and scale; its material;
/// the table's directions and format). Entries hold the exit rays relative
/// to their vertex, in the object's frame as defined (`store_entry`), so a
/// table stays valid when its object is moved or turned. A file holds a
/// magic string, the format version, the key, the entry count, the entries
/// and a 64-bit checksum of them; a file that fails any check is rebuilt,
/// never trusted.
pub mod cache {
    use super::*;
    use std::path::{Path, PathBuf};
    use twox_hash::{XxHash3_128, XxHash3_64};

    const MAGIC: &[u8; 8] = b"SLCTABLE";
    /// Bump when the table's contents change for the same inputs.
    const VERSION: u32 = 8;
    const HEADER: usize = 8 + 4 + 16 + 8;

    /// The cache folder (`output::cache_directory`).
    pub fn directory() -> Option<PathBuf> {
        crate::output::cache_directory()
    }

    /// The key of the table of the glass object whose vertices are `verts`
    /// (contiguous from index `first`).
    fn key(
        scene: &SceneData,
        params: &CausticsParams,
        first: usize,
        verts: &[slicelight_shaders::types::GlassVertex],
    ) -> [u8; 16] {
        let object = verts[0].object;
        let mut bytes: Vec<u8> = Vec::new();
        bytes.extend(VERSION.to_le_bytes());
        bytes.extend(env!("CARGO_PKG_VERSION").as_bytes());
        bytes.extend(params.rings.to_le_bytes());
        bytes.extend(params.azimuths.to_le_bytes());
        bytes.extend(params.compressed.to_le_bytes());
        // The object's shape, not its place (its definition, less its
        // position: `SceneData::shape_keys`), and its vertex count.
        bytes.extend(scene.shape_keys[object as usize].to_le_bytes());
        bytes.extend((verts.len() as u64).to_le_bytes());
        bytes.extend(verts[0].channels.to_le_bytes());
        for t in scene.glass_triangles.iter().filter(|t| t.object == object) {
            for i in t.vertices {
                bytes.extend((i as u64 - first as u64).to_le_bytes());
            }
        }
        let m = &scene.materials[verts[0].material as usize];
        bytes.extend(bytemuck::bytes_of(&m.ior));
        bytes.extend(bytemuck::bytes_of(&m.absorption));
        XxHash3_128::oneshot(&bytes).to_le_bytes()
    }

    /// Finds each glass object's file; when all are there and sound, the
    /// whole table is `setup.cached_table`.
    pub fn load(setup: &mut Setup, scene: &SceneData, dir: &Path) {
        let d = setup.params.directions as usize;
        let verts = &scene.glass_vertices;
        let mut tables = Vec::new();
        let mut first = 0;
        while first < verts.len() {
            let object = verts[first].object;
            let end = first + verts[first..].iter().take_while(|v| v.object == object).count();
            let block =
                |i: usize| if i < verts.len() { verts[i].table_block as usize } else { setup.table_blocks as usize };
            let entries = block(first) * d..block(end) * d;
            let key = key(scene, &setup.params, first, &verts[first..end]);
            let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
            let path = dir.join(format!("{hex}.table"));
            tables.push(read(&path, &key, entries.len() * setup.params.entry_words as usize * 4));
            setup.cache_files.push(CacheFile { path, key, entries });
            first = end;
        }
        if tables.iter().all(Option::is_some) {
            // One buffer, filled from each file's payload in place.
            let size = setup.params.entry_words as usize * 4;
            let mut table = Buffer::zeroed::<u8>(setup.table_blocks as usize * d * size);
            let out = table.as_mut_slice::<u8>();
            for (bytes, f) in tables.into_iter().flatten().zip(&setup.cache_files) {
                let payload = &bytes[HEADER..HEADER + f.entries.len() * size];
                out[f.entries.start * size..f.entries.end * size].copy_from_slice(payload);
            }
            setup.cached_table = Some(table);
        }
    }

    /// A cache file's bytes, if it is sound and has `key` and a payload of `len` bytes.
    fn read(path: &Path, key: &[u8; 16], len: usize) -> Option<Vec<u8>> {
        crate::output::regular_file("cache", path, (HEADER + len + 8) as u64).ok()?;
        let bytes = std::fs::read(path).ok()?;
        if !sound(&bytes, key, len) {
            eprintln!("{}: a stale or corrupt light transport table; tracing it again", path.display());
            return None;
        }
        Some(bytes)
    }

    /// Whether a cache file's bytes are whole: the magic, this version, the
    /// table's `key`, a payload of `len` bytes and its checksum.
    pub fn sound(bytes: &[u8], key: &[u8; 16], len: usize) -> bool {
        bytes.len() == HEADER.saturating_add(len).saturating_add(8)
            && &bytes[..8] == MAGIC
            && bytes[8..12] == VERSION.to_le_bytes()
            && &bytes[12..28] == key
            && bytes[28..36] == (len as u64).to_le_bytes()
            && bytes[HEADER + len..] == XxHash3_64::oneshot(&bytes[HEADER..HEADER + len]).to_le_bytes()
    }

    /// Writes each object's part of `table` (words) to its file (whole or not at all).
    pub fn save(setup: &Setup, table: &[u32]) {
        let words = setup.params.entry_words as usize;
        for f in &setup.cache_files {
            let Some(part) = table.get(f.entries.start * words..f.entries.end * words) else {
                return;
            };
            let payload: &[u8] = bytemuck::cast_slice(part);
            let mut bytes = Vec::with_capacity(HEADER + payload.len() + 8);
            bytes.extend(MAGIC);
            bytes.extend(VERSION.to_le_bytes());
            bytes.extend(f.key);
            bytes.extend((payload.len() as u64).to_le_bytes());
            bytes.extend(payload);
            bytes.extend(XxHash3_64::oneshot(payload).to_le_bytes());
            let written = f
                .path
                .parent()
                .map_or(Ok(()), std::fs::create_dir_all)
                .map_err(anyhow::Error::from)
                .and_then(|_| crate::output::write_atomically(&f.path, &bytes));
            if let Err(e) = written {
                eprintln!("{}: cannot keep the light transport table: {e:#}", f.path.display());
            }
        }
    }
}

impl Setup {
    /// Whether every glass object's table came from the disk cache.
    pub fn has_cached_table(&self) -> bool {
        self.cached_table.is_some()
    }

    /// Forgets the table the disk cache gave, so the table kernel traces it
    /// again (benches and the equivalence tests time and compare the
    /// kernel itself).
    pub fn forget_cached_table(&mut self) {
        self.cached_table = None;
    }

    /// Entries of the table: `directions` per vertex and channel it traces.
    pub fn table_len(&self) -> u64 {
        self.table_blocks as u64 * self.params.directions as u64
    }
    /// 32-bit words of the table.
    pub fn table_words(&self) -> u64 {
        self.table_len() * self.params.entry_words as u64
    }
    /// Every entry of a table, decoded, in slot order.
    pub fn decode_table(&self, scene: &SceneData, words: &[u32]) -> Vec<TableEntry> {
        let d = self.params.directions;
        let mut out = Vec::with_capacity(self.table_len() as usize);
        if words.len() as u64 != self.table_words() {
            return out;
        }
        for v in &scene.glass_vertices {
            for slot in v.table_block * d..(v.table_block + v.channels) * d {
                out.push(load_entry(words, &self.params, slot, v));
            }
        }
        out
    }
    /// Invocations of the table kernel: every vertex, direction and channel.
    pub fn table_invocations(&self) -> u64 {
        let p = &self.params;
        p.vertex_count as u64 * p.directions as u64 * p.channels as u64
    }
    pub fn rays_len(&self) -> u64 {
        let p = &self.params;
        p.light_count as u64 * p.vertex_count as u64 * p.channels as u64
    }
    pub fn map_invocations(&self) -> u64 {
        map_invocations(&self.params) as u64
    }
    pub fn map_words(&self) -> u64 {
        if self.enabled {
            words_for(map_bins(&self.params)) as u64
        } else {
            1
        }
    }
    /// Whether the caustic shafts run (glass, light on it, a scattering medium).
    pub fn shafts_on(&self) -> bool {
        self.enabled && self.shafts.planes > 0
    }
    pub fn shaft_map_invocations(&self) -> u64 {
        map_invocations(&self.shafts) as u64
    }
    /// Texels of the shaft maps over all planes (1 without them: a buffer is never empty).
    pub fn shaft_texels(&self) -> u64 {
        if self.shafts_on() {
            map_texels(&self.shafts) as u64
        } else {
            1
        }
    }
    pub fn shaft_map_words(&self) -> u64 {
        if self.shafts_on() {
            words_for(map_bins(&self.shafts)) as u64
        } else {
            1
        }
    }
}

pub static CAUSTICS_PARAMS: Resource = Resource {
    binding: 31,
    name: "caustics parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.caustics.params)),
};
/// The light transport table (section 4): an entry (`store_entry`) per vertex, direction and channel.
pub static CAUSTICS_TABLE: Resource = Resource {
    binding: 32,
    name: "light transport table",
    kind: ResourceKind::Frame(|s| s.caustics.table_words() * 4),
};
/// Exit rays per light, vertex and channel.
pub static CAUSTICS_RAYS: Resource = Resource {
    binding: 33,
    name: "caustics exit rays",
    kind: ResourceKind::Frame(|s| s.caustics.rays_len() * std::mem::size_of::<ExitRay>() as u64),
};
/// The caustics maps' fixed-point words (`scatter.rs`), `MAP_BINS` bins per texel.
pub static CAUSTICS_MAPS: Resource =
    Resource { binding: 34, name: "caustics maps", kind: ResourceKind::Frame(|s| s.caustics.map_words() * 4) };
/// Caustic radiance per pixel (rgb; w = 0).
pub static CAUSTICS_RADIANCE: Resource =
    Resource { binding: 35, name: "caustics radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

/// The shaft maps' parameters (`Setup::shafts`).
pub static CAUSTIC_SHAFT_PARAMS: Resource = Resource {
    binding: 79,
    name: "caustic shaft parameters",
    kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.caustics.shafts)),
};
/// The shaft maps' fixed-point words, as `CAUSTICS_MAPS`.
pub static CAUSTIC_SHAFT_MAPS: Resource = Resource {
    binding: 80,
    name: "caustic shaft maps",
    kind: ResourceKind::Frame(|s| s.caustics.shaft_map_words() * 4),
};
/// The shaft maps' texels as f32 (`resolve_texel`), every plane's in turn.
pub static CAUSTIC_SHAFT_TEXELS: Resource = Resource {
    binding: 82,
    name: "caustic shaft texels",
    kind: ResourceKind::Frame(|s| s.caustics.shaft_texels() * 16),
};
/// Caustic light scattered toward the eye per pixel (rgb; w = 0).
pub static CAUSTIC_SHAFTS_RADIANCE: Resource =
    Resource { binding: 81, name: "caustic shafts radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };

fn skip(scene: &SceneData) -> Option<Plan> {
    (!scene.caustics.enabled).then(|| Plan::skip(scene.caustics.reason.clone()))
}

fn glass(scene: &SceneData) -> Glass<'_> {
    Glass { vertices: &scene.glass_vertices, triangles: &scene.glass_triangles }
}

/// Compares two buffers of table entries or exit rays: each position and
/// direction within `tol` (metres, or of a unit vector), transmittances
/// within `tol`, statuses equal, except `allowed` entries (paths that pass
/// an edge of the mesh at a hair's breadth and take another triangle on
/// one backend: f32 intersection tests differ by ulps between them).
fn compare_entries(what: &str, gpu: &[TableEntry], cpu: &[TableEntry], tol: f32) -> Result<String> {
    ensure!(gpu.len() == cpu.len(), "{what}: {} and {} entries", gpu.len(), cpu.len());
    let mut differ = 0;
    let mut worst = 0.0f32;
    for (g, c) in gpu.iter().zip(cpu) {
        let d = (g.position - c.position)
            .abs()
            .max((g.direction - c.direction).abs())
            .max((g.transmittance - c.transmittance).abs())
            .max_element();
        let within = d <= tol * c.position.truncate().abs().max_element().max(1.0);
        if g.position.w != c.position.w || !within {
            differ += 1;
        } else {
            worst = worst.max(d);
        }
    }
    let allowed = cpu.len() / 100 + 1;
    ensure!(differ <= allowed, "{what}: {differ} of {} entries differ (allowed {allowed})", cpu.len());
    Ok(format!("{what}: {} entries, {differ} differ, worst other difference {worst:e}", cpu.len()))
}

pub struct CausticsTable;

impl Pass for CausticsTable {
    fn name(&self) -> &'static str {
        "caustics.table"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustics_table_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, SPHERES, TRIANGLES, BVH_NODES, MATERIALS, GLASS_VERTICES, GLASS_TRIANGLES, CAUSTICS_PARAMS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_TABLE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip(scene) {
            return s;
        }
        let p = &scene.caustics.params;
        if scene.caustics.cached_table.is_some() {
            return Plan::skip(format!(
                "light transport table of {} glass vertices x {} directions from the cache ({} file(s))",
                p.vertex_count,
                p.directions,
                scene.caustics.cache_files.len()
            ));
        }
        Plan::run(
            format!(
                "light transport table (section 4): {} glass vertices x {} directions{}",
                p.vertex_count,
                p.directions,
                if p.channels == 3 { ", 3 channels where the glass disperses" } else { "" }
            ),
            scene.caustics.table_invocations(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (geometry, glass, p) = (scene.geometry(), glass(scene), &scene.caustics.params);
        let verts = &scene.glass_vertices;
        // The entries in invocation order, each with its slot (see `table_slot`).
        let invocations = scene.caustics.table_invocations() as u32;
        let entries: Vec<(u32, TableEntry)> = (0..invocations)
            .into_par_iter()
            .with_min_len(4096)
            .filter_map(|i| {
                if i % 4096 == 0 {
                    progress.inc(4096.min(invocations - i) as u64);
                }
                let slot = table_slot(i, p, verts);
                (slot != u32::MAX).then(|| (i, table_entry(i, p, &geometry, &glass, &scene.materials)))
            })
            .collect();
        frame.write::<u32>(&CAUSTICS_TABLE, scene.caustics.table_words() as usize, |_, out| {
            for (i, e) in entries {
                let vertex = &verts[(i / (p.channels * p.directions)) as usize];
                store_entry(out, p, table_slot(i, p, verts), &e, vertex);
            }
        });
    }
    fn cached(&self, scene: &SceneData) -> Option<(&'static Resource, Buffer)> {
        Some((&CAUSTICS_TABLE, scene.caustics.cached_table.clone()?))
    }
    fn keeps(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_TABLE]
    }
    fn persist(&self, scene: &SceneData, results: &Frame) {
        cache::save(&scene.caustics, results.get::<u32>(&CAUSTICS_TABLE));
    }
    fn counters(&self, scene: &SceneData, frame: &Frame) -> Vec<(&'static str, u64)> {
        let table = scene.caustics.decode_table(scene, frame.get::<u32>(&CAUSTICS_TABLE));
        let count = |s: u32| table.iter().filter(|e| e.position.w == s as f32).count() as u64;
        vec![
            ("table entries leaving the glass", count(PATH_OUT)),
            ("table entries totally reflected", count(slicelight_shaders::glass::PATH_TOTAL_REFLECTION)),
            ("table entries self-occluded", count(slicelight_shaders::glass::PATH_OCCLUDED)),
            ("table entries lost", count(slicelight_shaders::glass::PATH_LOST)),
        ]
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Positions and directions come from a chain of refractions (sqrt,
        // divisions) over up to 16 interfaces: 1e-3 relative (far above
        // the 16-bit fields' steps of 1.5e-5).
        let c = &scene.caustics;
        compare_entries(
            "light transport table",
            &c.decode_table(scene, gpu.get::<u32>(&CAUSTICS_TABLE)),
            &c.decode_table(scene, cpu.get::<u32>(&CAUSTICS_TABLE)),
            1e-3,
        )
    }
}

pub struct CausticsLookup;

impl Pass for CausticsLookup {
    fn name(&self) -> &'static str {
        "caustics.lookup"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustics_lookup_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            SPHERES,
            TRIANGLES,
            BVH_NODES,
            MATERIALS,
            GLASS_VERTICES,
            CAUSTICS_PARAMS,
            CAUSTICS_TABLE
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_RAYS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip(scene) {
            return s;
        }
        Plan::run(
            format!(
                "exit rays of the lit vertices for {} light(s): four table directions, bilinear and quaternion interpolation (5.1)",
                scene.caustics.params.light_count
            ),
            scene.caustics.rays_len(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let (geometry, p) = (scene.geometry(), &scene.caustics.params);
        frame.write::<ExitRay>(&CAUSTICS_RAYS, scene.caustics.rays_len() as usize, |f, out| {
            let table = f.get::<u32>(&CAUSTICS_TABLE);
            for_each_invocation(out, 0, progress, |i, r| {
                *r = lookup(i, p, &scene.lights, &geometry, &scene.glass_vertices, &scene.materials, table)
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // As the table, plus acos/atan2 for the angles (Vulkan: 2^-11
        // absolute), which move the interpolation weights: 2e-3.
        compare_entries("exit rays", gpu.get::<ExitRay>(&CAUSTICS_RAYS), cpu.get::<ExitRay>(&CAUSTICS_RAYS), 2e-3)
    }
}

pub struct CausticsMaps;

/// The maps' densities (rgb, W/m^2 of the plane) per texel, decoded.
pub fn decode_maps(scene: &SceneData, words: &[u32]) -> Vec<Vec4> {
    decode(&scene.caustics.params, words)
}

/// The densities (rgb) per texel of maps of `p`, decoded (`resolve_texel`).
fn decode(p: &CausticsParams, words: &[u32]) -> Vec<Vec4> {
    (0..map_texels(p)).map(|t| resolve_texel(t, p, words)).collect()
}

/// Each plane's sum of the maps' densities (rgb, W/m^2 summed over its
/// texels), from the fixed-point words: the integer sums exactly, then
/// scaled (what summing `read_bin` of every texel in f64 gives, to f32's
/// rounding of each), without decoding the maps: the colour bins of every
/// texel (the slope bins not read), rows in parallel; a frame's report
/// costs about 1 ms instead of the 34 ms decoding took (`caustics_fog_ball`:
/// 6 planes of 512^2 texels with 7 bins each, 88 MB of words).
fn plane_sums(p: &CausticsParams, words: &[u32]) -> Vec<glam::DVec3> {
    let bins = slicelight_shaders::caustics::texel_bins(p) as usize;
    let (width, rows) = (p.map_width as usize, (p.planes * p.map_height) as usize);
    let row_sums: Vec<[u128; 3]> = (0..rows)
        .into_par_iter()
        .map(|row| {
            let mut sum = [0u128; 3];
            for t in row * width..(row + 1) * width {
                for (c, s) in sum.iter_mut().enumerate() {
                    let w = 1 + 2 * (t * bins + c);
                    *s += ((words[w + 1] as u128) << 32) | words[w] as u128;
                }
            }
            sum
        })
        .collect();
    row_sums
        .chunks(p.map_height as usize)
        .map(|plane| {
            let total = plane.iter().fold([0u128; 3], |a, r| [a[0] + r[0], a[1] + r[1], a[2] + r[2]]);
            glam::DVec3::new(total[0] as f64, total[1] as f64, total[2] as f64) / p.scale as f64
        })
        .collect()
}

/// Every lit triangle's illumination volume rasterised into maps of `p`
/// (`words` words) on the CPU (`rasterize`).
fn draw_maps(
    scene: &SceneData,
    common: &CommonParams,
    p: &CausticsParams,
    words: u64,
    frame: &Frame,
    progress: &ProgressBar,
) -> Buffer {
    let glass = glass(scene);
    // Zeroed pages the rasteriser never reaches are never touched: most
    // of a map holds no light.
    let mut maps = Buffer::zeroed::<u32>(words as usize);
    let rays = frame.get::<ExitRay>(&CAUSTICS_RAYS);
    let table = frame.get::<u32>(&CAUSTICS_TABLE);
    let kernel = Rasterize { scene, common, p, glass, rays, table };
    scatter_each_index(maps.as_mut_slice::<u32>(), map_invocations(p), progress, &kernel);
    maps
}

/// `rasterize` over the maps of `p`, as the CPU's scatter driver calls it.
struct Rasterize<'a> {
    scene: &'a SceneData,
    common: &'a CommonParams,
    p: &'a CausticsParams,
    glass: Glass<'a>,
    rays: &'a [ExitRay],
    table: &'a [u32],
}

impl ScatterKernel for Rasterize<'_> {
    fn run<A: AtomicWords + ?Sized>(&self, i: u32, words: &mut A) {
        let s = self.scene;
        let (m, t) = (&s.materials, self.table);
        rasterize(i, self.common, self.p, &s.lights, &s.light_map, &self.glass, self.rays, t, m, words);
    }
}

impl Pass for CausticsMaps {
    fn name(&self) -> &'static str {
        "caustics.maps"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustics_maps_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            MATERIALS,
            LIGHT_MAPS,
            GLASS_VERTICES,
            GLASS_TRIANGLES,
            CAUSTICS_PARAMS,
            CAUSTICS_TABLE,
            CAUSTICS_RAYS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_MAPS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip(scene) {
            return s;
        }
        let p = &scene.caustics.params;
        Plan::run(
            format!(
                "illumination volumes of {} triangles cut by {} sample plane(s) into {}x{} caustics maps (eq. 2)",
                p.triangle_count, p.planes, p.map_width, p.map_height
            ),
            scene.caustics.map_invocations(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let c = &scene.caustics;
        let maps = draw_maps(scene, common, &c.params, c.map_words(), frame, progress);
        frame.insert(&CAUSTICS_MAPS, maps);
    }
    fn keeps(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_MAPS]
    }
    /// The flux report is the CPU backend's: on a device the maps would be
    /// read back after every frame for it (84 MiB for `caustics_fog_ball`'s
    /// six 512x512 planes, most of a frame's time on a fast GPU).
    fn keeps_on_device(&self) -> bool {
        false
    }
    fn report(&self, scene: &SceneData, frame: &Frame) -> Result<Option<String>> {
        let words = frame.get::<u32>(&CAUSTICS_MAPS);
        if words.is_empty() {
            return Ok(None);
        }
        let p = &scene.caustics.params;
        let area = p.map_origin.w as f64 * p.map_origin.w as f64;
        let flux: Vec<String> = plane_sums(p, words)
            .iter()
            .map(|sum| {
                let sum = *sum * area;
                format!("[{:.4e}, {:.4e}, {:.4e}]", sum.x, sum.y, sum.z)
            })
            .collect();
        Ok(Some(format!(
            "flux on each plane (W, from the lowest): {}; {} rejected contributions (not finite, or a cross-section over {} texels)",
            flux.join(", "),
            words[0],
            slicelight_shaders::caustics::MAX_VOLUME_TEXELS
        )))
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Each texel sums the same flux on both backends, except where a
        // backend's rounding moves a cross-section's edge across a coverage
        // sample: 1e-3 of the peak density, 1 % of the texels free to
        // differ. Measured on lavapipe: none on the balls; 0.54 % on the
        // turned torus, all from the light of triangles whose exit rays go
        // both up and down (cut into parts; with those dropped, none
        // differ), which lands far out from rays within a few degrees of
        // the horizontal, where rounding moves it most.
        let (g, c) =
            (decode_maps(scene, gpu.get::<u32>(&CAUSTICS_MAPS)), decode_maps(scene, cpu.get::<u32>(&CAUSTICS_MAPS)));
        compare_rgb("caustics maps", &g, &c, 1e-3, c.len() * 3 / 100 + 1)
    }
}

pub struct Caustics;

impl Pass for Caustics {
    fn name(&self) -> &'static str {
        "caustics"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustics_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTICS_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&CAUSTICS_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip(scene) {
            return s;
        }
        Plan::run(
            "caustic light on the surfaces seen, directly or through glass (5.2, 5.3), as the surface pass found it",
            0,
        )
    }
    fn run_cpu(&self, _scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        frame.write_all::<Vec4>(&CAUSTICS_RADIANCE, common.band_pixels as usize, |f, out| {
            let gbuffer = f.get::<GBufferTexel>(&GBUFFER);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                *v = caustics_pixel(&gbuffer[(i - common.band_start) as usize]);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Bilinear reads of maps that agree to 1e-3 of their peak (above),
        // along view rays that may refract differently at a silhouette:
        // 2e-3 of the peak, 1 % of the values free to differ.
        let (g, c) = (gpu.get::<Vec4>(&CAUSTICS_RADIANCE), cpu.get::<Vec4>(&CAUSTICS_RADIANCE));
        compare_rgb("caustics radiance", g, c, 2e-3, c.len() * 3 / 100 + 1)
    }
}

/// Skips the caustic shafts where they do not run.
fn skip_shafts(scene: &SceneData) -> Option<Plan> {
    skip(scene).or_else(|| (!scene.caustics.shafts_on()).then(|| Plan::skip(scene.caustics.shafts_reason.clone())))
}

/// The shaft maps' densities (rgb, W/m^2 of the plane) per texel, decoded.
pub fn decode_shaft_maps(scene: &SceneData, words: &[u32]) -> Vec<Vec4> {
    decode(&scene.caustics.shafts, words)
}

pub struct CausticShaftMaps;

impl Pass for CausticShaftMaps {
    fn name(&self) -> &'static str {
        "caustics.shaft_maps"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustic_shaft_maps_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            MATERIALS,
            LIGHT_MAPS,
            GLASS_VERTICES,
            GLASS_TRIANGLES,
            CAUSTICS_TABLE,
            CAUSTICS_RAYS,
            CAUSTIC_SHAFT_PARAMS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTIC_SHAFT_MAPS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip_shafts(scene) {
            return s;
        }
        let p = &scene.caustics.shafts;
        Plan::run(
            format!(
                "illumination volumes cut by {} shaft plane(s) {:.3} m apart into {}x{} maps (Iwasaki 2002)",
                p.planes, p.plane_spacing, p.map_width, p.map_height
            ),
            scene.caustics.shaft_map_invocations(),
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let c = &scene.caustics;
        let maps = draw_maps(scene, common, &c.shafts, c.shaft_map_words(), frame, progress);
        frame.insert(&CAUSTIC_SHAFT_MAPS, maps);
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // As the caustics maps (the same rasteriser).
        let g = decode_shaft_maps(scene, gpu.get::<u32>(&CAUSTIC_SHAFT_MAPS));
        let c = decode_shaft_maps(scene, cpu.get::<u32>(&CAUSTIC_SHAFT_MAPS));
        compare_rgb("caustic shaft maps", &g, &c, 1e-3, c.len() * 3 / 100 + 1)
    }
}

pub struct CausticShaftResolve;

impl Pass for CausticShaftResolve {
    fn name(&self) -> &'static str {
        "caustics.shaft_resolve"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustic_shaft_resolve_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![CAUSTIC_SHAFT_PARAMS, CAUSTIC_SHAFT_MAPS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTIC_SHAFT_TEXELS]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip_shafts(scene) {
            return s;
        }
        Plan::run("the shaft maps' fixed-point sums as f32 texels", scene.caustics.shaft_texels())
    }
    fn run_cpu(&self, scene: &SceneData, _common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.caustics.shafts;
        frame.write_all::<Vec4>(&CAUSTIC_SHAFT_TEXELS, scene.caustics.shaft_texels() as usize, |f, out| {
            let words = f.get::<u32>(&CAUSTIC_SHAFT_MAPS);
            for_each_invocation(out, 0, progress, |i, v| *v = resolve_texel(i, p, words));
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // The same words converted the same way: to within f32 rounding of
        // the conversion (2^-24 of each value, far under 1e-6 of the peak).
        let (g, c) = (gpu.get::<Vec4>(&CAUSTIC_SHAFT_TEXELS), cpu.get::<Vec4>(&CAUSTIC_SHAFT_TEXELS));
        compare_rgb("caustic shaft texels", g, c, 1e-6, 0)
    }
}

pub struct CausticShafts;

impl Pass for CausticShafts {
    fn name(&self) -> &'static str {
        "caustics.shafts"
    }
    fn kernel(&self) -> &'static str {
        "caustics::caustic_shafts_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, GBUFFER, CAUSTIC_SHAFT_PARAMS, CAUSTIC_SHAFT_TEXELS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![CAUSTIC_SHAFTS_RADIANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&CAUSTIC_SHAFTS_RADIANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(s) = skip_shafts(scene) {
            return s;
        }
        Plan::run(
            format!(
                "caustic light shafts: the shaft maps read at {} intervals along each view ray",
                scene.caustics.shafts.shaft_steps
            ),
            0,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.caustics.shafts;
        frame.write_all::<Vec4>(&CAUSTIC_SHAFTS_RADIANCE, common.band_pixels as usize, |f, out| {
            let gbuffer = f.get::<GBufferTexel>(&GBUFFER);
            let texels = f.get::<Vec4>(&CAUSTIC_SHAFT_TEXELS);
            for_each_invocation(out, common.band_start, progress, |i, v| {
                let local = i - common.band_start;
                *v = caustic_shafts_pixel(local, common, p, texels, &gbuffer[local as usize]);
            });
        });
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Reads of maps that agree to 1e-3 of their peak, summed over the
        // intervals, along view rays whose ends (the G-buffer's distance,
        // the box's faces) differ by rounding: 2e-3 of the peak, 1 % of the
        // values free to differ.
        let (g, c) = (gpu.get::<Vec4>(&CAUSTIC_SHAFTS_RADIANCE), cpu.get::<Vec4>(&CAUSTIC_SHAFTS_RADIANCE));
        compare_rgb("caustic shafts radiance", g, c, 2e-3, c.len() * 3 / 100 + 1)
    }
}
