//! `slicelight bench`: run time against error for the shafts pass over its
//! settings, on each scene and backend; a CSV and PNG plots.
//!
//! Error is measured against the f64 reference at a lattice of pixel
//! centres (every `stride`-th pixel in x and y), which the method's
//! full-resolution image is sampled at too: like is compared with like. Time
//! is the median over repeats of the whole render (all passes, uploads and
//! read-back included on the GPU), and of the shafts pass alone.

use anyhow::Result;
use glam::DVec3;
use plotters::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

use crate::bench::{
    draw_legend, log_ticks, pareto, register_font, save_plot, time_renders, BenchScene, Options, Series, COLORS,
};
use crate::metrics::{difference, Difference};
use crate::reference;
use crate::scene::{SceneData, ShaftMode, Shafts};

/// One configuration of the sweep.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Config {
    /// Which sweep it belongs to: `planes`, `planes-8bit`, `subplanes`, `tables`, `no-jitter`.
    pub series: &'static str,
    pub planes: u32,
    pub subplanes: u32,
    pub mode: ShaftMode,
    pub table_size: u32,
    pub analytic_inverse_square: bool,
    pub jitter: bool,
    pub quantize_8bit: bool,
}

/// One row of the CSV.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub backend: &'static str,
    #[serde(flatten)]
    pub config: Config,
    pub median_seconds: f64,
    /// Median time of the shafts family's passes (`shafts.tiles` and `shafts`).
    pub shafts_median_seconds: f64,
    pub rms_8bit_percent: f64,
    pub max_8bit_percent: f64,
    pub rms_relative: f64,
    pub max_relative: f64,
    pub shaft_samples: u64,
    pub shaft_samples_naive: u64,
}

/// The sweep: the paper's Fig. 4 (planes, 8-bit tables, no sub-planes) and
/// its float counterpart, Fig. 5 (sub-planes), table resolutions, jitter.
pub fn sweep(quick: bool) -> Vec<Config> {
    let base = Config {
        series: "",
        planes: 30,
        subplanes: 6,
        mode: ShaftMode::Exact,
        table_size: 256,
        analytic_inverse_square: true,
        jitter: true,
        quantize_8bit: false,
    };
    let planes: &[u32] = if quick { &[5, 30, 120] } else { &[5, 10, 20, 30, 60, 120, 240] };
    let subs: &[u32] = if quick { &[1, 6, 24] } else { &[1, 2, 4, 6, 12, 24] };
    let tables: &[u32] = if quick { &[16, 256] } else { &[16, 64, 256] };
    let mut v = Vec::new();
    for &n in planes {
        v.push(Config { series: "planes", planes: n, ..base });
        // The paper's hardware: 8-bit tables, 8-bit blending of each plane,
        // no sub-planes, no dither. The 1/s^2 stays analytic: an 8-bit h table
        // that includes it is all zeros but its first column (1/s^2 spans six
        // decades between LIGHT_RADIUS and the scene), which no plane count
        // recovers from.
        v.push(Config {
            series: "planes-8bit",
            planes: n,
            subplanes: 1,
            mode: ShaftMode::Tables,
            jitter: false,
            quantize_8bit: true,
            ..base
        });
    }
    for &m in subs {
        v.push(Config { series: "subplanes", subplanes: m, ..base });
    }
    for &t in tables {
        v.push(Config { series: "tables", mode: ShaftMode::Tables, table_size: t, ..base });
    }
    v.push(Config { series: "no-jitter", jitter: false, ..base });
    v
}

fn configure(data: &SceneData, c: &Config) -> Result<SceneData> {
    let s = Shafts {
        planes: c.planes,
        subplanes: c.subplanes,
        mode: c.mode,
        jitter: c.jitter,
        analytic_inverse_square: c.analytic_inverse_square,
        phase_table_size: c.table_size,
        h_table_size: [c.table_size, c.table_size],
        quantize_8bit: c.quantize_8bit,
    };
    data.reconfigure(move |f| f.shafts = s)
}

/// The shafts family's sweep (`passes::FAMILIES` registers it): scenes in
/// a scattering medium without glass, a sea or a sky alone.
pub struct ShaftsSweep;

impl crate::bench::Sweep for ShaftsSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["fig6_sphere", "fig7_stage", "stained_glass"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        s.glass_vertices.is_empty()
            && !s.sea.enabled
            && !(s.sky.enabled && !s.scatters())
            && !s.volumes.enabled
            && s.desert.fields.is_empty()
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        run(scenes, opts)?;
        Ok(["bench.csv", "error_vs_planes.png", "error_vs_subplanes.png", "time_vs_error.png"]
            .map(|f| opts.out_dir.join(f))
            .to_vec())
    }
}

/// Runs the sweep and writes `bench.csv` and the plots into `out_dir`.
pub fn run(scenes: &[BenchScene], opts: &Options) -> Result<Vec<Row>> {
    let backends = &opts.backends;
    let configs = sweep(opts.quick);
    let mut rows = Vec::new();
    for BenchScene { data, name, .. } in scenes {
        let stride = opts.stride.max(1);
        let pixels = crate::bench::pixel_lattice(data, stride);
        let t = std::time::Instant::now();
        let (refvals, samples) = reference::render_converged_at(data, &pixels, 2e-4);
        eprintln!(
            "{name}: reference at {} pixels, {samples} samples per ray, {:.1} s",
            pixels.len(),
            t.elapsed().as_secs_f64()
        );
        for backend in backends {
            for c in &configs {
                let d = configure(data, c)?;
                let timed = time_renders(&d, backend, opts.repeats, &[super::PASSES])?;
                let (img, st) = (&timed.last.image, &timed.last.stats);
                let at: Vec<DVec3> = pixels.iter().map(|&i| img[i as usize].truncate().as_dvec3()).collect();
                let e: Difference = difference(&at, &refvals, data.exposure);
                let row = Row {
                    scene: name.clone(),
                    width: data.width(),
                    height: data.height(),
                    backend: backend.name(),
                    config: *c,
                    median_seconds: timed.total_seconds,
                    shafts_median_seconds: timed.group_seconds[0],
                    rms_8bit_percent: e.rms_8bit_percent,
                    max_8bit_percent: e.max_8bit_percent,
                    rms_relative: e.rms_relative,
                    max_relative: e.max_relative,
                    shaft_samples: st.counter("shaft_samples"),
                    shaft_samples_naive: st.counter("shaft_samples_naive"),
                };
                eprintln!(
                    "{name:>14} {:>4} {:<12} n={:<4} m={:<3} {:?}{}{}{} {:>8.4} s  rms {:.3}%  max {:.2}%",
                    row.backend,
                    c.series,
                    c.planes,
                    c.subplanes,
                    c.mode,
                    if c.mode == ShaftMode::Tables { format!(" table={}", c.table_size) } else { String::new() },
                    if c.quantize_8bit { " 8-bit" } else { "" },
                    if c.jitter { "" } else { " no-jitter" },
                    row.median_seconds,
                    row.rms_8bit_percent,
                    row.max_8bit_percent
                );
                rows.push(row);
            }
        }
    }
    write_csv(&opts.out_dir.join("bench.csv"), &rows)?;
    plot(&opts.out_dir, &rows)?;
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
    planes: u32,
    subplanes: u32,
    mode: String,
    table_size: u32,
    analytic_inverse_square: bool,
    jitter: bool,
    quantize_8bit: bool,
    median_seconds: f64,
    shafts_median_seconds: f64,
    rms_8bit_percent: f64,
    max_8bit_percent: f64,
    rms_relative: f64,
    max_relative: f64,
    shaft_samples: u64,
    shaft_samples_naive: u64,
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
            planes: r.config.planes,
            subplanes: r.config.subplanes,
            mode: format!("{:?}", r.config.mode),
            table_size: r.config.table_size,
            analytic_inverse_square: r.config.analytic_inverse_square,
            jitter: r.config.jitter,
            quantize_8bit: r.config.quantize_8bit,
            median_seconds: r.median_seconds,
            shafts_median_seconds: r.shafts_median_seconds,
            rms_8bit_percent: r.rms_8bit_percent,
            max_8bit_percent: r.max_8bit_percent,
            rms_relative: r.rms_relative,
            max_relative: r.max_relative,
            shaft_samples: r.shaft_samples,
            shaft_samples_naive: r.shaft_samples_naive,
        }),
    )
}

fn line_plot(path: &Path, title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<()> {
    save_plot(path, |root| {
        let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
        let (x0, x1) = xs.clone().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        let y1 = series.iter().flat_map(|s| s.1.iter().map(|p| p.1)).fold(0.0, f64::max) * 1.1 + 1e-9;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0 * 0.8..x1 * 1.25)
                    .log_scale()
                    .with_key_points(vec![1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]),
                0.0..y1,
            )?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_desc(y_label)
            .label_style(("sans-serif", 15))
            .draw()?;
        for (i, (name, pts)) in series.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                .label(name.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, color.filled())))?;
        }
        draw_legend(&mut chart)
    })
}

fn plot(dir: &Path, rows: &[Row]) -> Result<()> {
    register_font()?;
    let groups: Vec<(String, &'static str)> = {
        let mut g: Vec<(String, &'static str)> = rows.iter().map(|r| (r.scene.clone(), r.backend)).collect();
        g.dedup();
        g
    };
    let series_of = |series: &str, x: fn(&Row) -> f64| -> Vec<Series> {
        groups
            .iter()
            .map(|(scene, backend)| {
                let pts = rows
                    .iter()
                    .filter(|r| &r.scene == scene && r.backend == *backend && r.config.series == series)
                    .map(|r| (x(r), r.rms_8bit_percent))
                    .collect();
                (format!("{scene} ({backend}, {series})"), pts)
            })
            .collect()
    };
    let mut planes = series_of("planes", |r| r.config.planes as f64);
    planes.extend(series_of("planes-8bit", |r| r.config.planes as f64));
    line_plot(
        &dir.join("error_vs_planes.png"),
        "Error against sample planes (the 2002 paper's Fig. 4)",
        "sample planes n",
        "RMS error, % of 8-bit range",
        &planes,
    )?;
    line_plot(
        &dir.join("error_vs_subplanes.png"),
        "Error against sub-planes at 30 planes (Fig. 5)",
        "sub-sample planes m",
        "RMS error, % of 8-bit range",
        &series_of("subplanes", |r| r.config.subplanes as f64),
    )?;

    // Time against error, every configuration, Pareto front per group.
    save_plot(&dir.join("time_vs_error.png"), |root| {
        let (t0, t1) =
            rows.iter().fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(r.median_seconds), b.max(r.median_seconds)));
        let e1 = rows.iter().map(|r| r.rms_8bit_percent).fold(0.0, f64::max) * 1.1 + 1e-9;
        let mut chart = ChartBuilder::on(&root)
            .caption("Run time against error (lines: Pareto fronts)", ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (t0 * 0.8..t1 * 1.25).log_scale().with_key_points(log_ticks(t0 * 0.8, t1 * 1.25)),
                0.0..e1,
            )?;
        chart
            .configure_mesh()
            .x_desc("median render time, s")
            // Log-scale key points such as 0.1 * 3 print as 0.30000000000000004.
            .x_label_formatter(&|x| format!("{}", (x * 1e4).round() / 1e4))
            .y_desc("RMS error, % of 8-bit range")
            .label_style(("sans-serif", 15))
            .draw()?;
        for (i, (scene, backend)) in groups.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| &r.scene == scene && r.backend == *backend)
                .map(|r| (r.median_seconds, r.rms_8bit_percent))
                .collect();
            chart
                .draw_series(pts.iter().map(|p| Circle::new(*p, 4, color.filled())))?
                .label(format!("{scene} ({backend})"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
            chart.draw_series(LineSeries::new(pareto(&pts), color.stroke_width(2)))?;
        }
        draw_legend(&mut chart)
    })
}
