//! `slicelight bench --caustics`: time against error of the caustics
//! passes over their settings: the table's directions, the glass mesh's
//! vertices (a glass sphere's tessellation), the table's compression, the
//! sample planes and the caustics maps' resolution; on each scene and
//! backend, a CSV and PNG plots.
//!
//! Times are medians over repeats at the scene's own resolution: the
//! precompute (the `caustics.table` pass, traced anew: no cache) and the
//! frame without it (the table cached). Error is the RMS difference of the
//! 8-bit images, % of 255, from the reference over the pixels that see no
//! glass, both at `width/stride x height/stride` with 16 samples per pixel
//! (the light tracer's pixels are box-filtered means): the reference's
//! direct light (`reference::render_surfaces`) plus the f64 light tracer's
//! caustics, transmission only (the paths the method models). For the
//! vertex sweep, the reference's sphere is the finest tessellation swept.
//!
//! In a scene whose medium scatters (`caustics_fog_ball`) the error is the
//! caustic light shafts' (the `caustics.shafts` layer) against the light
//! tracer's medium estimate (`Splat::Medium`), over the same pixels,
//! and the sweep adds the shaft planes, the shaft maps' resolution and the
//! steps along each view ray.

use anyhow::Result;
use glam::DVec3;
use std::path::{Path, PathBuf};

use crate::bench::{median, BenchScene};
use crate::metrics::{difference, to_f64};
use crate::render::{self, Backend};
use crate::scene::{self, SceneData};

/// One configuration of the sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// `directions`, `vertices`, `compression`, `planes`, `map`.
    pub series: &'static str,
    pub directions: [u32; 2],
    /// A glass sphere's `segments` (None: the scene's own mesh).
    pub segments: Option<[u32; 2]>,
    pub compression: bool,
    pub planes: u32,
    pub map_resolution: u32,
    pub shaft_planes: u32,
    pub shaft_resolution: u32,
    pub shaft_steps: u32,
}

const BASE: Config = Config {
    series: "",
    directions: [8, 16],
    segments: None,
    compression: true,
    planes: 6,
    map_resolution: 512,
    shaft_planes: 32,
    shaft_resolution: 128,
    shaft_steps: 32,
};

pub fn sweep(quick: bool, sphere: bool, shafts: bool) -> Vec<Config> {
    let dirs: &[[u32; 2]] =
        if quick { &[[2, 4], [8, 16], [16, 32]] } else { &[[2, 4], [4, 8], [6, 12], [8, 16], [12, 24], [16, 32]] };
    let segs: &[[u32; 2]] = if quick { &[[24, 16], [96, 64]] } else { &[[24, 16], [48, 32], [96, 64], [144, 96]] };
    let planes: &[u32] = if quick { &[1, 6] } else { &[1, 2, 4, 6, 12] };
    let maps: &[u32] = if quick { &[128, 512] } else { &[128, 256, 512, 1024] };
    let mut v = Vec::new();
    for &d in dirs {
        v.push(Config { series: "directions", directions: d, ..BASE });
    }
    if sphere {
        for &s in segs {
            v.push(Config { series: "vertices", segments: Some(s), ..BASE });
        }
    }
    for c in [true, false] {
        v.push(Config { series: "compression", compression: c, ..BASE });
    }
    for &p in planes {
        v.push(Config { series: "planes", planes: p, ..BASE });
    }
    for &m in maps {
        v.push(Config { series: "map", map_resolution: m, ..BASE });
    }
    if shafts {
        let planes: &[u32] = if quick { &[8, 32] } else { &[4, 8, 16, 32, 64] };
        let maps: &[u32] = if quick { &[64, 128] } else { &[32, 64, 128, 256] };
        let steps: &[u32] = if quick { &[16, 32] } else { &[8, 16, 32, 64, 128] };
        for &p in planes {
            v.push(Config { series: "shaft planes", shaft_planes: p, ..BASE });
        }
        for &m in maps {
            v.push(Config { series: "shaft map", shaft_resolution: m, ..BASE });
        }
        for &n in steps {
            v.push(Config { series: "shaft steps", shaft_steps: n, ..BASE });
        }
    }
    v
}

/// The finest tessellation of the vertex sweep (the reference's sphere).
const FINEST: [u32; 2] = [144, 96];

#[derive(Debug, Clone)]
pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub config: Config,
    pub vertices: u32,
    pub table_median_seconds: f64,
    pub frame_median_seconds: f64,
    pub rms_8bit_percent: f64,
    pub max_8bit_percent: f64,
    /// The error is the caustic shafts' (the scene's medium scatters).
    pub shafts: bool,
}

/// Whether glass is the scene's sphere (whose tessellation the sweep varies).
fn glass_sphere(file: &scene::SceneFile) -> bool {
    file.object
        .iter()
        .any(|o| matches!(o, scene::Object::Sphere(s) if matches!(s.material, Some(scene::Material::Glass { .. }))))
}

/// The scene with `c`'s `[caustics]` settings and (with `segments`) its
/// glass spheres tessellated so, validated as a file's are (the table's
/// memory limit included). The table is traced afresh (no disk cache).
fn configure(data: &SceneData, c: &Config) -> Result<SceneData> {
    let c = *c;
    data.reconfigure(move |f| {
        f.caustics.directions = c.directions;
        f.caustics.compression = c.compression;
        f.caustics.planes = c.planes;
        f.caustics.map_resolution = c.map_resolution;
        f.caustics.shaft_planes = c.shaft_planes;
        f.caustics.shaft_resolution = c.shaft_resolution;
        f.caustics.shaft_steps = c.shaft_steps;
        f.caustics.cache = false;
        if let Some(segments) = c.segments {
            for o in &mut f.object {
                if let scene::Object::Sphere(s) = o {
                    if matches!(s.material, Some(scene::Material::Glass { .. })) {
                        s.segments = Some(segments);
                    }
                }
            }
        }
    })
}

/// The image at reduced size with 16 samples per pixel.
fn small(data: SceneData, stride: u32) -> Result<SceneData> {
    let (w, h) = ((data.width() / stride).max(8), (data.height() / stride).max(6));
    data.reconfigure(move |f| {
        f.camera.resolution = [w, h];
        f.camera.samples_per_pixel = 16;
    })
}

/// Pixels none of whose sub-pixel samples sees glass first (the pixels the
/// caustics error is measured over; also the tests').
pub fn not_glass(data: &SceneData) -> Vec<bool> {
    use slicelight_shaders::geometry::{trace_nearest, NO_HIT};

    let geometry = data.geometry();
    let mut keep = vec![true; data.pixel_count() as usize];
    for s in 0..data.samples_per_pixel() {
        let mut common = data.common;
        common.sample_index = s;
        for (i, k) in keep.iter_mut().enumerate() {
            let (x, y) = (i as u32 % data.width(), i as u32 / data.width());
            let (o, d) = slicelight_shaders::camera::camera_ray(&common, x, y);
            let hit = trace_nearest(o, d, 0.0, NO_HIT, &geometry);
            if slicelight_shaders::glass::is_glass(&data.materials, &hit) {
                *k = false;
            }
        }
    }
    keep
}

/// The values whose `keep` is true.
pub fn select(v: &[DVec3], keep: &[bool]) -> Vec<DVec3> {
    v.iter().zip(keep).filter(|(_, k)| **k).map(|(p, _)| *p).collect()
}

/// The caustics family's sweep (`passes::FAMILIES` registers it): scenes
/// with glass.
pub struct CausticsSweep;

impl crate::bench::Sweep for CausticsSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["caustics_ball", "caustics_knot", "caustics_fog_ball"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        !s.glass_vertices.is_empty()
    }
    fn run(&self, scenes: &[BenchScene], opts: &crate::bench::Options) -> Result<Vec<PathBuf>> {
        run(scenes, &opts.backends, opts.repeats, opts.stride, opts.quick, &opts.out_dir)?;
        Ok(["caustics_bench.csv", "caustics_time_vs_error.png", "caustics_precompute.png"]
            .map(|f| opts.out_dir.join(f))
            .to_vec())
    }
}

/// Runs the sweep on every scene and backend; writes `caustics_bench.csv`
/// and the plots into `out_dir`.
pub fn run(
    scenes: &[BenchScene],
    backends: &[Backend],
    repeats: usize,
    stride: u32,
    quick: bool,
    out_dir: &Path,
) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    for BenchScene { name, data: scene, .. } in scenes {
        let sphere = glass_sphere(&scene.source.file);
        let shafts = scene.caustics.shafts_on();
        let configs = sweep(quick, sphere, shafts);
        // References: the scene as it is, and (sphere scenes) the finest sphere.
        let reference_of = |segments: Option<[u32; 2]>| -> Result<(Vec<DVec3>, Vec<bool>)> {
            let c = Config { segments, ..BASE };
            let data = small(configure(scene, &c)?, stride)?;
            if shafts {
                let (traced, paths) = crate::caustics::reference::light_trace_converged(
                    &data,
                    1 << 18,
                    1 << 23,
                    2e-3,
                    true,
                    crate::caustics::reference::Splat::Medium,
                );
                eprintln!("{name}: caustic shafts' reference with {paths} light paths per light and object");
                return Ok((traced, not_glass(&data)));
            }
            let direct = crate::reference::render_surfaces(&data);
            let (traced, paths) = crate::caustics::reference::light_trace_converged(
                &data,
                1 << 21,
                1 << 24,
                2e-3,
                true,
                crate::caustics::reference::Splat::Surfaces,
            );
            eprintln!("{name}: reference with {paths} light paths per light and object");
            let image = direct.iter().zip(&traced).map(|(a, b)| *a + *b).collect();
            Ok((image, not_glass(&data)))
        };
        let reference = reference_of(None)?;
        let finest = if sphere { Some(reference_of(Some(FINEST))?) } else { None };
        for backend in backends {
            for c in &configs {
                let data = match configure(scene, c) {
                    Ok(d) => d,
                    Err(e) => {
                        eprintln!("{name}: skipped {c:?}: {e:#}");
                        continue;
                    }
                };
                let (mut tables, mut frames) = (Vec::new(), Vec::new());
                for _ in 0..repeats.max(1) {
                    let mut fresh = data.clone();
                    fresh.caustics.forget_cached_table();
                    let (_, st) = render::render(&fresh, backend, false)?;
                    let table = st.seconds_of(&[&super::CausticsTable]);
                    tables.push(table);
                    frames.push(st.total_seconds - table);
                }
                let s = small(data.clone(), stride)?;
                let r = render::render_layers(&s, backend, false)?;
                let (image, keep) =
                    if c.segments.is_some() { finest.as_ref().unwrap_or(&reference) } else { &reference };
                let keep: Vec<bool> = keep.iter().zip(not_glass(&s)).map(|(a, b)| *a && b).collect();
                let measured = if shafts {
                    let layer = r.layers.iter().find(|(n, _)| *n == "caustics.shafts").map(|(_, b)| b.as_slice());
                    to_f64(layer.unwrap_or(&[]))
                } else {
                    to_f64(&r.image)
                };
                let d = difference(&select(&measured, &keep), &select(image, &keep), data.exposure);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    config: *c,
                    vertices: data.glass_vertices.len() as u32,
                    table_median_seconds: median(tables),
                    frame_median_seconds: median(frames),
                    rms_8bit_percent: d.rms_8bit_percent,
                    max_8bit_percent: d.max_8bit_percent,
                    shafts,
                };
                eprintln!(
                    "{name:>20} {:>4} {:<12} dirs={:?} verts={:<6} compress={:<5} planes={:<2} map={:<4} shaft planes={:<2} map={:<4} steps={:<3} table {:.3} s frame {:.4} s  rms {:.3}%  max {:.1}%",
                    row.backend,
                    c.series,
                    c.directions,
                    row.vertices,
                    c.compression,
                    c.planes,
                    c.map_resolution,
                    c.shaft_planes,
                    c.shaft_resolution,
                    c.shaft_steps,
                    row.table_median_seconds,
                    row.frame_median_seconds,
                    row.rms_8bit_percent,
                    row.max_8bit_percent
                );
                rows.push(row);
            }
        }
    }
    write_csv(&out_dir.join("caustics_bench.csv"), &rows)?;
    plot(&out_dir.join("caustics_time_vs_error.png"), &rows, false)?;
    plot(&out_dir.join("caustics_precompute.png"), &rows, true)?;
    Ok(rows)
}

/// One CSV line of the sweep (`write_csv`).
#[derive(serde::Serialize)]
struct Record<'a> {
    scene: &'a str,
    backend: &'a str,
    series: &'a str,
    rings: u32,
    azimuths: u32,
    directions: u32,
    vertices: u32,
    compression: bool,
    planes: u32,
    map_resolution: u32,
    shaft_planes: u32,
    shaft_resolution: u32,
    shaft_steps: u32,
    measured: &'a str,
    table_median_seconds: f64,
    frame_median_seconds: f64,
    rms_8bit_percent: f64,
    max_8bit_percent: f64,
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(
        path,
        rows.iter().map(|r| Record {
            scene: &r.scene,
            backend: r.backend,
            series: r.config.series,
            rings: r.config.directions[0],
            azimuths: r.config.directions[1],
            directions: 1 + r.config.directions[0] * r.config.directions[1],
            vertices: r.vertices,
            compression: r.config.compression,
            planes: r.config.planes,
            map_resolution: r.config.map_resolution,
            shaft_planes: r.config.shaft_planes,
            shaft_resolution: r.config.shaft_resolution,
            shaft_steps: r.config.shaft_steps,
            measured: if r.shafts { "caustic shafts" } else { "image" },
            table_median_seconds: r.table_median_seconds,
            frame_median_seconds: r.frame_median_seconds,
            rms_8bit_percent: r.rms_8bit_percent,
            max_8bit_percent: r.max_8bit_percent,
        }),
    )
}

/// `precompute`: the table's time against vertices x directions; else the
/// error against the frame time; one line per scene, backend and series.
fn plot(path: &Path, rows: &[Row], precompute: bool) -> Result<()> {
    let mut groups: Vec<(String, &'static str, &'static str)> = Vec::new();
    for r in rows {
        let g = (r.scene.clone(), r.backend, r.config.series);
        if !groups.contains(&g) && (!precompute || matches!(r.config.series, "directions" | "vertices")) {
            groups.push(g);
        }
    }
    let series: Vec<(String, Vec<(f64, f64)>)> = groups
        .iter()
        .map(|(scene, backend, name)| {
            let pts = rows
                .iter()
                .filter(|r| &r.scene == scene && r.backend == *backend && r.config.series == *name)
                .map(|r| {
                    if precompute {
                        let d = 1 + r.config.directions[0] * r.config.directions[1];
                        (r.vertices as f64 * d as f64, r.table_median_seconds)
                    } else {
                        (r.frame_median_seconds, r.rms_8bit_percent)
                    }
                })
                .collect();
            (format!("{scene} ({backend}, {name})"), pts)
        })
        .collect();
    let labels = if precompute {
        crate::bench::LogLogPlot {
            caption: "Caustics: light transport table time",
            x_desc: "vertices x directions",
            y_desc: "median table time, s",
        }
    } else {
        crate::bench::LogLogPlot {
            caption: "Caustics: frame time against error",
            x_desc: "median frame time without the table, s",
            y_desc: "RMS error, % of 8 bit (no glass; in fog, the caustic shafts)",
        }
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-4)
}
