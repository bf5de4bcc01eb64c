//! `slicelight bench` on sky scenes: run time against error of the sky
//! passes over their settings (samples per view ray, the sky-view table's
//! size, the transmittance table's size), on each scene and backend; a CSV
//! and a PNG plot.
//!
//! Error is the RMS difference from the f64 reference (`sky_reference`) at
//! a lattice of pixel centres, relative to the sky's peak there, with the
//! sun's disk (and a degree around it) left out: the measure.
//! Times are medians over repeats: the whole render, the tables (the
//! transmittance and sky-view passes) and the per-pixel sky pass apart.

use anyhow::{Context, Result};
use glam::{DVec3, Vec4Swizzles};
use std::path::{Path, PathBuf};

use crate::bench::{time_renders, BenchScene, Options};
use crate::reference;
use crate::render::Backend;
use crate::scene::SceneData;

/// One configuration of the sweep.
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// `direct` (per-pixel integral over view samples), `sky-view` (table
    /// size), `transmittance` (table size).
    pub series: &'static str,
    pub sky_view: bool,
    pub view_samples: u32,
    pub sky_view_table: [u32; 2],
    pub transmittance_table: [u32; 2],
}

pub fn sweep(quick: bool) -> Vec<Config> {
    let base = Config {
        series: "",
        sky_view: true,
        view_samples: 32,
        sky_view_table: [192, 128],
        transmittance_table: [256, 64],
    };
    let samples: &[u32] = if quick { &[8, 32, 128] } else { &[8, 16, 32, 64, 128] };
    let views: &[[u32; 2]] =
        if quick { &[[48, 32], [192, 128]] } else { &[[48, 32], [96, 64], [192, 128], [384, 256]] };
    let trans: &[[u32; 2]] =
        if quick { &[[32, 8], [256, 64]] } else { &[[32, 8], [64, 16], [128, 32], [256, 64], [512, 128]] };
    let mut v = Vec::new();
    for &n in samples {
        v.push(Config { series: "direct", sky_view: false, view_samples: n, ..base });
    }
    for &n in samples {
        v.push(Config { series: "sky-view-samples", view_samples: n, ..base });
    }
    for &t in views {
        v.push(Config { series: "sky-view", sky_view_table: t, ..base });
    }
    for &t in trans {
        v.push(Config { series: "transmittance", transmittance_table: t, ..base });
    }
    v
}

/// The scene with `c`'s settings in its `[sky]`, validated as a file's are.
fn configure(data: &SceneData, c: &Config) -> Result<SceneData> {
    let c = *c;
    data.reconfigure(move |f| {
        if let Some(s) = f.sky.as_mut() {
            s.sky_view = c.sky_view;
            s.view_samples = c.view_samples;
            s.sky_view_table = c.sky_view_table;
            s.transmittance_table = c.transmittance_table;
        }
    })
    .with_context(|| format!("sky bench configuration {c:?}"))
}

/// Pixels whose centre ray is more than a degree outside the sun's disk
/// (and inside a fisheye's circle): where the sky is measured.
pub fn sky_pixels(data: &SceneData, stride: u32) -> Vec<u32> {
    let common = data.common;
    let sun = data.sky.params.sun_direction;
    let margin = (sun.w.clamp(-1.0, 1.0).acos() + 1f32.to_radians()).cos();
    let w = data.width();
    (0..data.height())
        .step_by(stride as usize)
        .flat_map(|y| (0..w).step_by(stride as usize).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let centre = slicelight_shaders::types::CommonParams { samples_per_pixel: 1, sample_index: 0, ..common };
            let (_, d) = slicelight_shaders::camera::camera_ray(&centre, x, y);
            slicelight_shaders::camera::in_image(&centre, x, y) && d.dot(sun.xyz()) < margin
        })
        .map(|(x, y)| y * w + x)
        .collect()
}

pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub width: u32,
    pub height: u32,
    pub config: Config,
    pub median_seconds: f64,
    pub tables_median_seconds: f64,
    pub sky_median_seconds: f64,
    pub rms_relative: f64,
    pub max_relative: f64,
}

/// The sky family's sweep (`passes::FAMILIES` registers it): scenes of sky
/// alone (no scattering medium, sea or glass).
pub struct SkySweep;

impl crate::bench::Sweep for SkySweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["sky_noon", "sky_sunset", "sky_twilight"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        s.sky.enabled
            && !s.scatters()
            && !s.sea.enabled
            && s.glass_vertices.is_empty()
            && !s.volumes.enabled
            && s.desert.fields.is_empty()
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        run(scenes, &opts.backends, opts.repeats, opts.stride, opts.quick, &opts.out_dir)?;
        Ok(vec![opts.out_dir.join("sky_bench.csv"), opts.out_dir.join("sky_time_vs_error.png")])
    }
}

/// Runs the sky sweep over `scenes` and writes `sky_bench.csv` and
/// `sky_time_vs_error.png` into `out_dir`.
pub fn run(
    scenes: &[BenchScene],
    backends: &[Backend],
    repeats: usize,
    stride: u32,
    quick: bool,
    out_dir: &Path,
) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    for BenchScene { path, name, data } in scenes {
        anyhow::ensure!(data.sky.enabled, "{}: no [sky] to benchmark", path.display());
        let pixels = sky_pixels(data, stride.max(1));
        let t = std::time::Instant::now();
        let (refvals, _) = reference::render_converged_at(data, &pixels, 2e-4);
        eprintln!("{name}: reference at {} pixels, {:.1} s", pixels.len(), t.elapsed().as_secs_f64());
        for backend in backends {
            for c in sweep(quick) {
                let d = configure(data, &c)?;
                let tables: &[&dyn crate::passes::Pass] = &[&super::SkyTransmittance, &super::SkyView];
                let timed = time_renders(&d, backend, repeats, &[tables, &[&super::Sky]])?;
                let img = &timed.last.image;
                let at: Vec<DVec3> = pixels.iter().map(|&i| img[i as usize].truncate().as_dvec3()).collect();
                let (rms, max) = crate::metrics::relative_error(&at, &refvals);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    width: data.width(),
                    height: data.height(),
                    config: c,
                    median_seconds: timed.total_seconds,
                    tables_median_seconds: timed.group_seconds[0],
                    sky_median_seconds: timed.group_seconds[1],
                    rms_relative: rms,
                    max_relative: max,
                };
                eprintln!(
                    "{name:>14} {:>4} {:<17} samples={:<4} sky-view={:?} transmittance={:?} {:>8.4} s (tables {:.4} s, sky {:.4} s)  rms {:.3}%  max {:.2}%",
                    row.backend,
                    c.series,
                    c.view_samples,
                    if c.sky_view { Some(c.sky_view_table) } else { None },
                    c.transmittance_table,
                    row.median_seconds,
                    row.tables_median_seconds,
                    row.sky_median_seconds,
                    100.0 * rms,
                    100.0 * max
                );
                rows.push(row);
            }
        }
    }
    write_csv(&out_dir.join("sky_bench.csv"), &rows)?;
    plot(&out_dir.join("sky_time_vs_error.png"), &rows)?;
    Ok(rows)
}

/// One CSV line of the sweep (`write_csv`).
#[derive(serde::Serialize)]
struct Record<'a> {
    scene: &'a str,
    width: u32,
    height: u32,
    backend: &'a str,
    series: &'a str,
    sky_view: bool,
    view_samples: u32,
    sky_view_width: u32,
    sky_view_height: u32,
    transmittance_width: u32,
    transmittance_height: u32,
    median_seconds: f64,
    tables_median_seconds: f64,
    sky_median_seconds: f64,
    rms_relative_percent: f64,
    max_relative_percent: f64,
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(
        path,
        rows.iter().map(|r| Record {
            scene: &r.scene,
            width: r.width,
            height: r.height,
            backend: r.backend,
            series: r.config.series,
            sky_view: r.config.sky_view,
            view_samples: r.config.view_samples,
            sky_view_width: r.config.sky_view_table[0],
            sky_view_height: r.config.sky_view_table[1],
            transmittance_width: r.config.transmittance_table[0],
            transmittance_height: r.config.transmittance_table[1],
            median_seconds: r.median_seconds,
            tables_median_seconds: r.tables_median_seconds,
            sky_median_seconds: r.sky_median_seconds,
            rms_relative_percent: 100.0 * r.rms_relative,
            max_relative_percent: 100.0 * r.max_relative,
        }),
    )
}

/// Error against the median render time, one colour per series, one
/// marker shape per scene and backend.
fn plot(path: &Path, rows: &[Row]) -> Result<()> {
    let series = crate::bench::series_of(
        rows,
        |r| format!("{} ({}, {})", r.scene, r.backend, r.config.series),
        |r| (r.median_seconds, 100.0 * r.rms_relative),
    );
    let labels = crate::bench::LogLogPlot {
        caption: "Sky: run time against error (RMS % of the sky's peak)",
        x_desc: "median render time, s",
        y_desc: "RMS error, % of the sky's peak",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-6)
}
