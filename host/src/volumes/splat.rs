//! Splatting (`method = "splatting"` on metaball volumes; kernels:
//! `shader-crate/src/volumes/splat.rs`): Dobashi et al. 2000's billboard
//! renderer as four passes: each metaball's light and rank
//! (`volume_splat_sort`, step 1 and the sort), its billboard's texture of
//! the light where the eye sees it (`volume_splat_textures`), the screen tiles' lists
//! (`volume_splat_tiles`), and the per-pixel blend (`volume_splats`,
//! step 2), which draws the layer the slice renderer's `volumes` pass
//! draws otherwise.

use anyhow::Result;
use glam::Vec2;
use glam::Vec4;
use indicatif::ProgressBar;
use rayon::prelude::*;
use slicelight_shaders::light::light_local;
use slicelight_shaders::types::CommonParams;
use slicelight_shaders::types::{GpuLight, LIGHT_DIRECTIONAL};
use slicelight_shaders::volumes::splat::BILLBOARD_TEXELS;
use slicelight_shaders::volumes::splat::{billboard_texel, splat_key, splat_light, splat_pixel, splat_tile};
use slicelight_shaders::volumes::splat::{LightBins, SplatBall, Step1};
use slicelight_shaders::volumes::GpuMetaball;
use slicelight_shaders::volumes::METHOD_SPLATTING;

use super::{
    clear, compare_layers, per_pixel_layers, scattering_label, skip_without_volumes, METABALLS, VOLUMES, VOLUMES_PARAMS,
};
use crate::passes::*;
use crate::scene::SceneData;

/// Per metaball, its billboard (`SplatBall`).
pub static SPLATS: Resource =
    Resource { binding: 69, name: "splats", kind: ResourceKind::Frame(|s| s.volumes.params.ball_count as u64 * 160) };
/// Per metaball, its billboard's texture: `BILLBOARD_TEXELS` colours (rgb).
pub static SPLAT_TEXTURES: Resource = Resource {
    binding: 84,
    name: "splat textures",
    kind: ResourceKind::Frame(|s| s.volumes.params.ball_count as u64 * BILLBOARD_TEXELS as u64 * 16),
};
/// The metaballs' indices front to back.
pub static SPLAT_ORDER: Resource = Resource {
    binding: 70,
    name: "splat order",
    kind: ResourceKind::Frame(|s| s.volumes.params.ball_count as u64 * 4),
};
/// Per screen tile, its count and list of metaballs.
pub static SPLAT_TILES: Resource =
    Resource { binding: 71, name: "splat tiles", kind: ResourceKind::Frame(|s| tile_words(s) * 4) };
/// Splatting's radiance per pixel (rgb).
pub static SPLAT_RADIANCE: Resource =
    Resource { binding: 72, name: "splat radiance", kind: ResourceKind::PerPixel { blank: no_radiance } };
/// The view transmittance through the billboards per pixel (rgb).
pub static SPLAT_TRANSMITTANCE: Resource =
    Resource { binding: 73, name: "splat transmittance", kind: ResourceKind::PerPixel { blank: clear } };

/// Per light, its bins of metaballs (`LightBins`; `nx = 0`: none).
pub static SPLAT_LIGHT_BINS: Resource = Resource {
    binding: 74,
    name: "splat light bins",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.light_bins)),
};
/// The light bins' cell starts and lists of balls.
pub static SPLAT_LIGHT_LISTS: Resource = Resource {
    binding: 75,
    name: "splat light lists",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.volumes.light_lists)),
};

/// Most metaballs a tile lists; a tile that meets more walks them all.
pub const TILE_CAPACITY: u32 = 1024;

/// Most cells of a light's bins, per metaball.
const CELLS_PER_BALL: f32 = 4.0;

/// Each directional light's bins of metaballs (`LightBins`), and their
/// cell starts and lists one after another: a grid across the light's rays
/// over the balls' shadows, cells the balls' mean radius wide (coarsened to
/// at most `CELLS_PER_BALL` cells a ball), each ball listed, in order, in
/// every cell its shadow's square meets (its radius widened by 1e-3 for
/// rounding: the field is 0 with zero slope at its edge). Step 1 then walks
/// the few balls in its centre's cell instead of every ball: the sea of
/// clouds' 10^4 balls took 0.82 s a frame walking them all. Spot lights
/// get none (their rays are not parallel).
pub fn light_bins(lights: &[GpuLight], balls: &[GpuMetaball]) -> (Vec<LightBins>, Vec<u32>) {
    let mut bins = Vec::with_capacity(lights.len());
    let mut lists = Vec::new();
    for light in lights {
        if light.kind != LIGHT_DIRECTIONAL || balls.is_empty() {
            bins.push(LightBins::default());
            continue;
        }
        let shadows: Vec<(Vec2, f32)> = balls
            .iter()
            .map(|b| (light_local(light, b.center_radius.truncate()).truncate(), b.center_radius.w * 1.001))
            .collect();
        let lo = shadows.iter().fold(Vec2::MAX, |m, (c, r)| m.min(*c - *r));
        let hi = shadows.iter().fold(Vec2::MIN, |m, (c, r)| m.max(*c + *r));
        let size = (hi - lo).max(Vec2::splat(1e-6));
        let mean_radius = shadows.iter().map(|(_, r)| *r as f64).sum::<f64>() / shadows.len() as f64;
        let most = CELLS_PER_BALL * balls.len() as f32;
        let cell = (mean_radius as f32).max((size.x * size.y / most).sqrt());
        let nx = ((size.x / cell).ceil() as u32).max(1);
        let ny = ((size.y / cell).ceil() as u32).max(1);
        let mut cells: Vec<Vec<u32>> = vec![Vec::new(); (nx * ny) as usize];
        let index = |v: f32, n: u32| (((v / cell).floor()) as i64).clamp(0, n as i64 - 1) as u32;
        for (i, (c, r)) in shadows.iter().enumerate() {
            let (a, b) = ((*c - *r - lo), (*c + *r - lo));
            for y in index(a.y, ny)..=index(b.y, ny) {
                for x in index(a.x, nx)..=index(b.x, nx) {
                    cells[(y * nx + x) as usize].push(i as u32);
                }
            }
        }
        let offset = lists.len() as u32;
        let mut start = offset + nx * ny + 1;
        for c in &cells {
            lists.push(start);
            start += c.len() as u32;
        }
        lists.push(start);
        for c in &cells {
            lists.extend_from_slice(c);
        }
        bins.push(LightBins { lo: lo.extend(0.0).extend(0.0), cell, nx, ny, offset });
    }
    (bins, lists)
}

fn tile_words(s: &SceneData) -> u64 {
    let p = &s.volumes.params;
    p.tiles_x as u64 * p.tiles_y as u64 * (p.tile_capacity as u64 + 1)
}

/// Why a splatting pass does not run, if it does not.
fn skip(scene: &SceneData) -> Option<Plan> {
    skip_without_volumes(scene).or_else(|| {
        (scene.volumes.params.method != METHOD_SPLATTING).then(|| Plan::skip("the volumes are drawn by slices"))
    })
}

pub struct SplatSort;

impl Pass for SplatSort {
    fn name(&self) -> &'static str {
        "volume_splat_sort"
    }
    fn kernel(&self) -> &'static str {
        "volumes::splat::splat_ball_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            LIGHTS,
            LIGHT_MAPS,
            SHADOW_MAPS,
            VOLUMES_PARAMS,
            VOLUMES,
            METABALLS,
            SPLAT_LIGHT_BINS,
            SPLAT_LIGHT_LISTS
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SPLATS, SPLAT_ORDER]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip(scene) {
            return skip;
        }
        let v = &scene.volumes;
        let n = v.params.ball_count as u64;
        let binned = v.light_bins.iter().filter(|b| b.nx > 0).count();
        Plan::run(
            format!(
                "{n} metaballs: the light at each centre and half a radius either side along its key light, through the billboards toward {} light(s) ({binned} binned, {} entries), and the order from the eye",
                scene.lights.len(),
                v.light_lists.len()
            ),
            n,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        let n = v.params.ball_count as usize;
        let shadow = frame.get::<f32>(&SHADOW_MAPS);
        let inp = Step1 {
            common,
            params: &v.params,
            volumes: &v.volumes,
            balls: &v.balls,
            lights: &scene.lights,
            light_map: &scene.light_map,
            shadow,
            bins: &v.light_bins,
            lists: &v.light_lists,
        };
        let mut splats: Vec<SplatBall> = (0..n as u32)
            .into_par_iter()
            .map(|j| {
                let s = splat_light(j, &inp);
                progress.inc(1);
                s
            })
            .collect();
        // The ranks `splat_rank` counts, by a sort of the same keys: the
        // order by key, equal keys by index (keys are finite and not
        // negative, so `total_cmp` orders them as `<` does).
        let keys: Vec<f32> = (0..n as u32).map(|j| splat_key(common, &v.balls, j)).collect();
        let mut sorted: Vec<u32> = (0..n as u32).collect();
        sorted.par_sort_unstable_by(|&a, &b| keys[a as usize].total_cmp(&keys[b as usize]).then(a.cmp(&b)));
        for (rank, &j) in sorted.iter().enumerate() {
            splats[j as usize].rank = rank as u32;
        }
        frame.write::<u32>(&SPLAT_ORDER, n, |_, order| order.copy_from_slice(&sorted));
        frame.insert(&SPLATS, Buffer::from_bytes(bytemuck::cast_slice(&splats)));
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Colours: per light, exps of sums of polynomial chords over all
        // metaballs: 1e-4 of the peak. The order: two centres whose
        // squared distances differ in the last bit may swap (a GPU's
        // fused multiply-add): 1 % of the places.
        let g = gpu.get::<SplatBall>(&SPLATS);
        let c = cpu.get::<SplatBall>(&SPLATS);
        // Every ball's colours (centre, toward and away from the key light,
        // all light and its direct part) in one list, and the key light's
        // axis (a unit vector: 1e-4).
        let colors = |s: &[SplatBall]| {
            s.iter()
                .flat_map(|b| [b.color, b.toward, b.away, b.direct, b.direct_toward, b.direct_away])
                .collect::<Vec<Vec4>>()
        };
        let a = compare_rgb("splat colours", &colors(g), &colors(c), 1e-4, 0)?;
        let axes = |s: &[SplatBall]| s.iter().flat_map(|b| b.axis.truncate().to_array()).collect::<Vec<f32>>();
        let b = compare_values("splat axes", &axes(g), &axes(c), 1e-4, 0)?;
        let (moved, places) =
            differing_records("splat order", gpu.get::<u32>(&SPLAT_ORDER), cpu.get::<u32>(&SPLAT_ORDER), 1)?;
        anyhow::ensure!(moved <= places / 100, "splat order: {moved} of {places} places differ");
        Ok(format!("{a}; {b}; order: {moved} of {places} places differ"))
    }
}

/// Each billboard's texture (`billboard_texel`): the light where the eye
/// sees the ball, per texel, from step 1's samples.
pub struct SplatTextures;

impl Pass for SplatTextures {
    fn name(&self) -> &'static str {
        "volume_splat_textures"
    }
    fn kernel(&self) -> &'static str {
        "volumes::splat::splat_texture_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, VOLUMES_PARAMS, VOLUMES, METABALLS, SPLATS]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SPLAT_TEXTURES]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip(scene) {
            return skip;
        }
        let n = scene.volumes.params.ball_count as u64;
        let side = slicelight_shaders::volumes::splat::BILLBOARD_SIDE;
        Plan::run(
            format!(
                "{n} billboard textures of {side}x{side}: the light where the eye sees each ball ({:.1} MiB)",
                (n * BILLBOARD_TEXELS as u64 * 16) as f64 / (1u64 << 20) as f64
            ),
            n * BILLBOARD_TEXELS as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        let n = (v.params.ball_count * BILLBOARD_TEXELS) as usize;
        let splats = frame.get::<SplatBall>(&SPLATS);
        let texels: Vec<Vec4> = (0..n as u32)
            .into_par_iter()
            .map(|k| {
                let w = billboard_texel(k, common, &v.volumes, &v.balls, splats);
                if k % BILLBOARD_TEXELS == 0 {
                    progress.inc(BILLBOARD_TEXELS as u64);
                }
                w
            })
            .collect();
        frame.insert(&SPLAT_TEXTURES, Buffer::from_bytes(bytemuck::cast_slice(&texels)));
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // Colours from step 1's (1e-4 of the peak, `SplatSort::compare`)
        // read at points found by Newton's method in f32: 1e-3 of the
        // peak, and a texel in a thousand further (a step that lands on
        // the other side of a bisection).
        let c = cpu.get::<Vec4>(&SPLAT_TEXTURES);
        compare_rgb("splat textures", gpu.get::<Vec4>(&SPLAT_TEXTURES), c, 1e-3, c.len() * 3 / 1000 + 1)
    }
}

pub struct SplatTiles;

impl Pass for SplatTiles {
    fn name(&self) -> &'static str {
        "volume_splat_tiles"
    }
    fn kernel(&self) -> &'static str {
        "volumes::splat::splat_tile_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![COMMON, VOLUMES_PARAMS, METABALLS, SPLAT_ORDER]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SPLAT_TILES]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::Whole
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip(scene) {
            return skip;
        }
        let p = &scene.volumes.params;
        Plan::run(
            format!(
                "{}x{} tiles of {} pixels, up to {} metaballs each ({:.1} MiB)",
                p.tiles_x,
                p.tiles_y,
                slicelight_shaders::volumes::splat::TILE,
                p.tile_capacity,
                tile_words(scene) as f64 * 4.0 / (1u64 << 20) as f64
            ),
            p.tiles_x as u64 * p.tiles_y as u64,
        )
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let p = &scene.volumes.params;
        let stride = p.tile_capacity as usize + 1;
        frame.write::<u32>(&SPLAT_TILES, tile_words(scene) as usize, |f, out| {
            let order = f.get::<u32>(&SPLAT_ORDER);
            out.par_chunks_mut(stride).enumerate().for_each(|(t, list)| {
                splat_tile(t as u32, common, p, &scene.volumes.balls, order, list, 0);
                progress.inc(1);
            });
        });
    }
    fn counters(&self, scene: &SceneData, frame: &Frame) -> Vec<(&'static str, u64)> {
        let p = &scene.volumes.params;
        let tiles = frame.get::<u32>(&SPLAT_TILES);
        let counts = tiles.chunks(p.tile_capacity as usize + 1).map(|t| t.first().copied().unwrap_or(0));
        let full = counts.clone().filter(|&n| n > p.tile_capacity).count() as u64;
        let listed = counts.map(|n| n.min(p.tile_capacity) as u64).sum();
        vec![("splat tile entries", listed), ("splat tiles over capacity", full)]
    }
    fn keeps(&self) -> &'static [&'static Resource] {
        resources![SPLAT_TILES]
    }
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        // A ball whose angular distance from a tile's cone is within the
        // last bit of `acos` may be listed on one backend only, and a
        // swapped pair in the order (`SplatSort::compare`) swaps entries:
        // 1 % of the tiles may differ.
        let stride = scene.volumes.params.tile_capacity as usize + 1;
        let (g, c) = (gpu.get::<u32>(&SPLAT_TILES), cpu.get::<u32>(&SPLAT_TILES));
        let (differ, tiles) = differing_records("splat tiles", g, c, stride)?;
        anyhow::ensure!(differ <= tiles / 100, "splat tiles: {differ} of {tiles} tiles differ");
        Ok(format!("splat tiles: {differ} of {tiles} tiles differ"))
    }
}

pub struct Splats;

impl Pass for Splats {
    fn name(&self) -> &'static str {
        "volume_splats"
    }
    fn kernel(&self) -> &'static str {
        "volumes::splat::splat_pixel_kernel"
    }
    fn reads(&self) -> &'static [&'static Resource] {
        resources![
            COMMON,
            GBUFFER,
            VOLUMES_PARAMS,
            VOLUMES,
            METABALLS,
            SPLATS,
            SPLAT_TEXTURES,
            SPLAT_ORDER,
            SPLAT_TILES
        ]
    }
    fn writes(&self) -> &'static [&'static Resource] {
        resources![SPLAT_RADIANCE, SPLAT_TRANSMITTANCE]
    }
    fn dispatch(&self) -> Dispatch {
        Dispatch::PerPixel
    }
    fn radiance_layer(&self) -> Option<&'static Resource> {
        Some(&SPLAT_RADIANCE)
    }
    fn transmittance_layer(&self) -> Option<&'static Resource> {
        Some(&SPLAT_TRANSMITTANCE)
    }
    fn plan(&self, scene: &SceneData) -> Plan {
        if let Some(skip) = skip(scene) {
            return skip;
        }
        let p = &scene.volumes.params;
        Plan::run(format!("{} billboards blended front to back, {}", p.ball_count, scattering_label(p)), 0)
    }
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar) {
        let v = &scene.volumes;
        let splats = frame.get::<SplatBall>(&SPLATS);
        let textures = frame.get::<Vec4>(&SPLAT_TEXTURES);
        let order = frame.get::<u32>(&SPLAT_ORDER);
        let tiles = frame.get::<u32>(&SPLAT_TILES);
        let layers = per_pixel_layers(common, frame, progress, |i, d| {
            splat_pixel(i, common, &v.params, &v.volumes, &v.balls, splats, textures, order, tiles, d)
        });
        frame.insert(&SPLAT_RADIANCE, layers.0);
        frame.insert(&SPLAT_TRANSMITTANCE, layers.1);
    }
    fn compare(&self, _scene: &SceneData, gpu: &Frame, cpu: &Frame) -> Result<String> {
        compare_layers(gpu, cpu, &SPLAT_RADIANCE, &SPLAT_TRANSMITTANCE)
    }
}
