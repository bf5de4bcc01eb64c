//! `slicelight bench` on scenes with `[[volume]]`: run time against error
//! of the volumes' passes over their settings, on each scene and backend; a
//! CSV and a PNG plot.
//!
//! Four series:
//! - `planes`: the sample planes, single scattering, against the f64
//!   quadrature reference (`volumes::reference`);
//! - `light-grid`: the transmittance volume's nodes (`n` a side), single
//!   scattering, against the same reference;
//! - `columns`: multiple scattering by delta-Eddington columns (the
//!   default) at column widths 1, 1.75 (the default) and 3, against the
//!   Monte Carlo reference for all orders (`volumes::montecarlo`);
//! - `octaves`: multiple scattering by 1 (single scattering), 2, 4, 8 and
//!   12 of Wrenninge's octaves at the default factors, against the same;
//! - `splatting` (scenes whose volumes are all metaballs): Dobashi et al.
//!   2000's billboards (`volumes::splat`), single scattering against the
//!   quadrature and the default columns against Monte Carlo.
//!
//! Error is the RMS and largest difference of the 8-bit images (the
//! scene's exposure) at a lattice of pixel centres, % of 255, and the
//! image energy over the reference's at those pixels. Times are medians
//! over repeats: the whole render, the volumes' grids (automaton, density,
//! transmittance volumes) and the per-pixel `volumes` pass.

use anyhow::{Context, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

use super::Scattering;
use crate::bench::{time_renders, BenchScene, Options};
use crate::passes::Pass;
use crate::render::Backend;
use crate::scene::SceneData;

/// One configuration of the sweep.
#[derive(Debug, Clone, Copy)]
pub struct Config {
    pub series: &'static str,
    /// Sample planes (`None`: the scene's default).
    pub planes: Option<u32>,
    /// Transmittance-volume nodes a side (`None`: the default).
    pub light_grid: Option<u32>,
    /// Octaves (1: single scattering) where neither `column_width` nor
    /// `column_spread` is given.
    pub octaves: u32,
    /// Multiple scattering by columns of this width, no ring (`column_light`).
    pub column_width: Option<f32>,
    /// Multiple scattering by columns spread over rings this wide (`diffuse_node`).
    pub column_spread: Option<f32>,
    /// Splatting (`splat`) instead of slices.
    pub splatting: bool,
}

/// The sweep's configurations; `splattable`: the scene's volumes are all
/// metaballs, so the `splatting` series (single scattering, and the default
/// columns) runs too.
pub fn sweep(quick: bool, splattable: bool) -> Vec<Config> {
    let base = Config {
        series: "",
        planes: None,
        light_grid: None,
        octaves: 1,
        column_width: None,
        column_spread: None,
        splatting: false,
    };
    let planes: &[u32] = if quick { &[32, 128, 512] } else { &[16, 32, 64, 128, 256, 512, 1024] };
    let grids: &[u32] = if quick { &[16, 64, 128] } else { &[16, 32, 64, 128, 256] };
    let octaves: &[u32] = if quick { &[1, 8] } else { &[1, 2, 4, 8, 12] };
    let widths: &[f32] = if quick { &[super::COLUMN_WIDTH] } else { &[1.0, super::COLUMN_WIDTH, 3.0] };
    let spreads: &[f32] = if quick { &[super::COLUMN_SPREAD] } else { &[0.5, super::COLUMN_SPREAD, 1.5] };
    let mut v = Vec::new();
    v.extend(planes.iter().map(|&n| Config { series: "planes", planes: Some(n), ..base }));
    v.extend(grids.iter().map(|&n| Config { series: "light-grid", light_grid: Some(n), ..base }));
    v.extend(octaves.iter().map(|&n| Config { series: "octaves", octaves: n, ..base }));
    v.extend(widths.iter().map(|&w| Config { series: "columns", column_width: Some(w), ..base }));
    v.extend(spreads.iter().map(|&w| Config { series: "spread", column_spread: Some(w), ..base }));
    if splattable {
        let splats = Config { series: "splatting", splatting: true, ..base };
        v.push(splats);
        v.push(Config { column_width: Some(super::COLUMN_WIDTH), ..splats });
    }
    v
}

/// The scene with `c`'s settings in its `[volumes]`, validated as a file's are.
fn configure(data: &SceneData, c: &Config) -> Result<SceneData> {
    let c = *c;
    data.reconfigure(move |f| {
        let s = &mut f.volumes;
        s.planes = c.planes;
        s.light_grid = c.light_grid.map(|n| [n; 3]);
        let method = if c.splatting { super::Method::Splatting } else { super::Method::Slices };
        f.volume.iter_mut().for_each(|v| v.method = method);
        s.octaves = None;
        s.column_width = c.column_width;
        s.column_spread = c.column_spread;
        if c.column_width.is_some() || c.column_spread.is_some() {
            s.scattering = Scattering::Multiple;
        } else if c.octaves == 1 {
            s.scattering = Scattering::Single;
        } else {
            s.scattering = Scattering::Octaves;
            s.octaves = Some(c.octaves);
        }
    })
    .with_context(|| format!("volumes bench configuration {c:?}"))
}

pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub width: u32,
    pub height: u32,
    pub config: Config,
    pub median_seconds: f64,
    pub grids_median_seconds: f64,
    pub volumes_median_seconds: f64,
    pub rms_8bit_percent: f64,
    pub max_8bit_percent: f64,
    pub energy_ratio: f64,
}

/// The volumes family's sweep (`passes::FAMILIES` registers it): every
/// scene with a `[[volume]]` (and no sea or glass, whose sweeps take those).
pub struct VolumesSweep;

impl crate::bench::Sweep for VolumesSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["cloud_cumulus", "cloud_automaton"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        s.volumes.enabled && !s.sea.enabled && s.glass_vertices.is_empty() && !crate::smoke::bench::has_smoke(s)
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        // The Monte Carlo reference costs ~0.1 s a pixel on a dense cloud:
        // at most every 8th pixel each way.
        run(scenes, &opts.backends, opts.repeats, opts.stride.max(8), opts.quick, &opts.out_dir)?;
        Ok(vec![opts.out_dir.join("volumes_bench.csv"), opts.out_dir.join("volumes_time_vs_error.png")])
    }
}

/// Runs the sweep over `scenes` and writes `volumes_bench.csv` and
/// `volumes_time_vs_error.png` into `out_dir`.
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
        anyhow::ensure!(data.volumes.enabled, "{}: no [[volume]] to benchmark", path.display());
        let pixels = crate::bench::pixel_lattice(data, stride);
        let mut references = Vec::new();
        for column_width in [None, Some(super::COLUMN_WIDTH)] {
            let single = column_width.is_none();
            let c = Config {
                series: "",
                planes: None,
                light_grid: None,
                octaves: 1,
                column_width,
                column_spread: None,
                splatting: false,
            };
            let d = configure(data, &c)?;
            let t = std::time::Instant::now();
            let (values, _) = crate::reference::render_converged_at(&d, &pixels, if single { 2e-4 } else { 3e-3 });
            eprintln!(
                "{name}: {} reference at {} pixels, {:.1} s",
                if single { "single-scattering" } else { "Monte Carlo" },
                pixels.len(),
                t.elapsed().as_secs_f64()
            );
            references.push(values);
        }
        for backend in backends {
            let splattable =
                data.volumes.params.automaton_volume == 0 && !data.volumes.volumes.iter().any(|v| v.is_file_grid());
            for c in sweep(quick, splattable) {
                let d = configure(data, &c)?;
                let grids: &[&dyn Pass] = &[
                    &super::automaton::Steps,
                    &super::automaton::Smooth,
                    &super::Density,
                    &super::OpticalDepth,
                    &super::Diffuse,
                    &super::splat::SplatSort,
                    &super::splat::SplatTextures,
                    &super::splat::SplatTiles,
                ];
                let timed =
                    match time_renders(&d, backend, repeats, &[grids, &[&super::Volumes, &super::splat::Splats]]) {
                        Ok(t) => t,
                        // A configuration the device cannot hold (lavapipe binds
                        // 128 MiB: a 256^3 transmittance volume) is left out of
                        // that backend's series, said, and the sweep goes on.
                        Err(e) if format!("{e:#}").contains(crate::gpu::TOO_LARGE) => {
                            eprintln!("{name:>16} {:>4} {:<10} {c:?}: left out: {e:#}", backend.name(), c.series);
                            continue;
                        }
                        Err(e) => return Err(e),
                    };
                let img = &timed.last.image;
                let at: Vec<DVec3> = pixels.iter().map(|&i| img[i as usize].truncate().as_dvec3()).collect();
                let all_orders = c.octaves > 1 || c.column_width.is_some() || c.column_spread.is_some();
                let reference = &references[if all_orders { 1 } else { 0 }];
                let diff = crate::metrics::difference(&at, reference, data.exposure);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    width: data.width(),
                    height: data.height(),
                    config: c,
                    median_seconds: timed.total_seconds,
                    grids_median_seconds: timed.group_seconds[0],
                    volumes_median_seconds: timed.group_seconds[1],
                    rms_8bit_percent: diff.rms_8bit_percent,
                    max_8bit_percent: diff.max_8bit_percent,
                    energy_ratio: diff.energy_ratio,
                };
                eprintln!(
                    "{name:>16} {:>4} {:<10} planes={:<5} light-grid={:<5} octaves={:<2} columns={:<5} spread={:<5} {:>8.4} s (grids {:.4} s, volumes {:.4} s)  rms {:.3}%  max {:.2}%  energy {:.3}",
                    row.backend,
                    c.series,
                    c.planes.map_or("auto".to_string(), |n| n.to_string()),
                    c.light_grid.map_or("auto".to_string(), |n| n.to_string()),
                    c.octaves,
                    c.column_width.map_or("-".to_string(), |w| w.to_string()),
                    c.column_spread.map_or("-".to_string(), |w| w.to_string()),
                    row.median_seconds,
                    row.grids_median_seconds,
                    row.volumes_median_seconds,
                    row.rms_8bit_percent,
                    row.max_8bit_percent,
                    row.energy_ratio
                );
                rows.push(row);
            }
        }
    }
    write_csv(&out_dir.join("volumes_bench.csv"), &rows)?;
    plot(&out_dir.join("volumes_time_vs_error.png"), &rows)?;
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
    planes: String,
    light_grid: String,
    octaves: u32,
    column_width: String,
    column_spread: String,
    median_seconds: f64,
    grids_median_seconds: f64,
    volumes_median_seconds: f64,
    rms_8bit_percent: f64,
    max_8bit_percent: f64,
    energy_ratio: f64,
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let auto = |v: Option<u32>| v.map_or("auto".to_string(), |n| n.to_string());
    crate::bench::write_csv(
        path,
        rows.iter().map(|r| Record {
            scene: &r.scene,
            width: r.width,
            height: r.height,
            backend: r.backend,
            series: r.config.series,
            planes: auto(r.config.planes),
            light_grid: auto(r.config.light_grid),
            octaves: r.config.octaves,
            column_width: r.config.column_width.map_or("none".to_string(), |w| w.to_string()),
            column_spread: r.config.column_spread.map_or("none".to_string(), |w| w.to_string()),
            median_seconds: r.median_seconds,
            grids_median_seconds: r.grids_median_seconds,
            volumes_median_seconds: r.volumes_median_seconds,
            rms_8bit_percent: r.rms_8bit_percent,
            max_8bit_percent: r.max_8bit_percent,
            energy_ratio: r.energy_ratio,
        }),
    )
}

/// Error against the median render time, one line per scene, backend and
/// series.
fn plot(path: &Path, rows: &[Row]) -> Result<()> {
    let series = crate::bench::series_of(
        rows,
        |r| format!("{} ({}, {})", r.scene, r.backend, r.config.series),
        |r| (r.median_seconds, r.rms_8bit_percent),
    );
    let labels = crate::bench::LogLogPlot {
        caption: "Volumes: run time against error (RMS % of the 8-bit range)",
        x_desc: "median render time, s",
        y_desc: "RMS error, % of 255",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-4)
}
