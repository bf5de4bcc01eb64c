//! `slicelight bench` on scenes with a smoke volume: the fluid's time per
//! step against its accuracy, and the smoke frame's render time against
//! the renderer's error; a CSV and a PNG plot.
//!
//! Three series:
//! - `taylor-green`: the Taylor-Green vortex (`reference::taylor_green`,
//!   viscosity 0.02 m^2/s, 1 s) on 32^2, 64^2 and 128^2 cells (128^2 left
//!   out with `--quick`) for each advection scheme; time per step against
//!   the effective viscosity's error, % of the given one;
//! - `step`: a hot plume in a box of 32^3, 64^3 (and 128^3 without
//!   `--quick`) cells, each scheme, on each backend (the fluid's kernels on
//!   the device, or their CPU twins): the median time of 5 steps after 5,
//!   the projection's iterations and the divergence it left (no error
//!   column: the plume has no closed form); `--fluid-sizes 64,128,256`
//!   runs this series alone at the sizes given;
//! - `frame`: the scene rendered on each backend (the fluid runs at load,
//!   on the CPU, and is not in the time): median render time and the RMS
//!   and largest 8-bit error against the f64 reference (`reference`), at a
//!   lattice of pixel centres (every second pixel each way at least).

use anyhow::Result;
use glam::{DVec3, Vec3};
use std::path::{Path, PathBuf};

use super::reference::taylor_green;
use super::{configure, Advection};
use crate::bench::{time_renders, BenchScene, Options};
use crate::scene::SceneData;

/// One row of the sweep, and its CSV line (`write_csv`: the fields in
/// order, `None` as an empty field).
#[derive(serde::Serialize)]
pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub series: &'static str,
    pub advection: &'static str,
    /// Cells a side.
    pub size: u32,
    pub seconds_per_step: Option<f64>,
    /// `frame`: the median render time.
    pub median_seconds: Option<f64>,
    /// `taylor-green`: |nu_eff - nu| / nu, %; `frame`: RMS % of 255.
    pub error_percent: Option<f64>,
    pub max_8bit_percent: Option<f64>,
    pub iterations: Option<u32>,
    pub divergence: Option<f64>,
}

/// The smoke family's sweep: scenes with a smoke volume.
pub struct SmokeSweep;

/// Whether a scene has a smoke volume.
pub fn has_smoke(s: &SceneData) -> bool {
    s.source.file.volume.iter().any(|v| v.smoke.is_some())
}

impl crate::bench::Sweep for SmokeSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["smoke_chimney"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        has_smoke(s) && !s.sea.enabled && s.glass_vertices.is_empty()
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        run(scenes, opts)?;
        Ok(vec![opts.out_dir.join("smoke_bench.csv"), opts.out_dir.join("smoke_time_vs_error.png")])
    }
}

const SCHEMES: [(Advection, &str); 2] =
    [(Advection::SemiLagrangian, "semi-lagrangian"), (Advection::Maccormack, "maccormack")];

fn fluid_row(series: &'static str, backend: &'static str, advection: &'static str, size: u32) -> Row {
    Row {
        scene: "-".into(),
        backend,
        series,
        advection,
        size,
        seconds_per_step: None,
        median_seconds: None,
        error_percent: None,
        max_8bit_percent: None,
        iterations: None,
        divergence: None,
    }
}

/// A plume's step times (medians, seconds) and solver figures.
struct Plume {
    seconds: f64,
    /// The step's stages: advection, forces and diffusion, projection.
    stages: [f64; 3],
    iterations: u32,
    divergence: f64,
}

/// The median step time (and of each stage), the most iterations and the
/// worst divergence of a hot plume on `n^3` cells (5 steps timed after 5)
/// on `backend`.
fn plume(n: u32, advection: &str, backend: &crate::render::Backend) -> Result<Plume> {
    let size = 0.1 * n as f32;
    let body = format!(
        "cells = [{n}, {n}, {n}]\nadvection = \"{advection}\"\nwind = [0.5, 0.0, 0.0]\n[[source]]\nposition = [{c}, {y}, {c}]\nradius = {r}\nrate = 10.0\ntemperature = 600.0\nvelocity = [0.0, 1.0, 0.0]",
        c = 0.5 * size,
        y = 0.1 * size,
        r = 0.08 * size
    );
    let s: super::Settings = toml::from_str(&body)?;
    let c = configure("bench", &s, Vec3::ZERO, Vec3::splat(size))?;
    let mut f = c.start(vec![1; c.params.cells as usize]);
    let device = match backend {
        crate::render::Backend::Gpu(ctx) => Some(&**ctx),
        crate::render::Backend::Cpu => None,
    };
    let mut stepper = super::gpu::Stepper::new(device, &f)?;
    for _ in 0..5 {
        stepper.step(&mut f)?;
    }
    let (mut times, mut stages, mut iterations, mut divergence) = (Vec::new(), [(); 3].map(|_| Vec::new()), 0, 0.0f64);
    for _ in 0..5 {
        let t = std::time::Instant::now();
        stepper.step(&mut f)?;
        times.push(t.elapsed().as_secs_f64());
        for (series, s) in stages.iter_mut().zip([f.last.advect_seconds, f.last.forces_seconds, f.last.project_seconds])
        {
            series.push(s);
        }
        iterations = iterations.max(f.last.solve.iterations);
        divergence = divergence.max(f.last.divergence);
    }
    Ok(Plume { seconds: crate::bench::median(times), stages: stages.map(crate::bench::median), iterations, divergence })
}

/// Runs the sweep and writes `smoke_bench.csv` and `smoke_time_vs_error.png`.
pub fn run(scenes: &[BenchScene], opts: &Options) -> Result<Vec<Row>> {
    let Options { backends, repeats, quick, out_dir, .. } = opts;
    let (repeats, quick, stride) = (*repeats, *quick, opts.stride.max(2));
    let mut rows = Vec::new();
    let nu = 0.02;
    let steps_only = !opts.fluid_sizes.is_empty();
    let defaults: &[u32] = if quick { &[32, 64] } else { &[32, 64, 128] };
    // Taylor-Green sizes, plume sizes.
    let (sizes, step_sizes): (&[u32], &[u32]) =
        if steps_only { (&[], &opts.fluid_sizes) } else { (defaults, defaults) };
    for &(scheme, name) in &SCHEMES {
        for &n in sizes {
            let tg = taylor_green(n, nu, scheme, 1.0);
            let mut row = fluid_row("taylor-green", "cpu", name, n);
            row.seconds_per_step = Some(tg.seconds_per_step);
            row.error_percent = Some(100.0 * (tg.viscosity - nu as f64).abs() / nu as f64);
            row.divergence = Some(tg.divergence);
            eprintln!(
                "taylor-green {name:>15} {n:>4}^2 {:>9.5} s/step  nu_eff {:.5} ({:.2} % off)",
                tg.seconds_per_step,
                tg.viscosity,
                row.error_percent.unwrap_or(0.0)
            );
            rows.push(row);
        }
        for &n in step_sizes {
            for backend in backends {
                let Plume { seconds, stages: [advect, forces, project], iterations, divergence } =
                    plume(n, name, backend)?;
                let mut row = fluid_row("step", backend.name(), name, n);
                row.seconds_per_step = Some(seconds);
                row.iterations = Some(iterations);
                row.divergence = Some(divergence);
                eprintln!(
                    "plume {:>4} {name:>15} {n:>4}^3 {seconds:>9.5} s/step (advect {advect:.4}, forces {forces:.4}, project {project:.4})  {iterations} iterations, divergence {divergence:.1e}",
                    backend.name()
                );
                rows.push(row);
            }
        }
    }
    for BenchScene { path, name, data } in scenes.iter().filter(|_| !steps_only) {
        anyhow::ensure!(has_smoke(data), "{}: no smoke volume to benchmark", path.display());
        let pixels = crate::bench::pixel_lattice(data, stride);
        let t = std::time::Instant::now();
        let (reference, _) = crate::reference::render_converged_at(data, &pixels, 2e-4);
        eprintln!("{name}: reference at {} pixels, {:.1} s", pixels.len(), t.elapsed().as_secs_f64());
        for backend in backends {
            let timed = time_renders(data, backend, repeats, &[])?;
            let img = &timed.last.image;
            let at: Vec<DVec3> = pixels.iter().map(|&i| img[i as usize].truncate().as_dvec3()).collect();
            let diff = crate::metrics::difference(&at, &reference, data.exposure);
            eprintln!(
                "{name:>14} {:>4} frame {:>8.4} s  rms {:.3}%  max {:.2}%",
                backend.name(),
                timed.total_seconds,
                diff.rms_8bit_percent,
                diff.max_8bit_percent
            );
            rows.push(Row {
                scene: name.clone(),
                backend: backend.name(),
                series: "frame",
                advection: "-",
                size: data.width(),
                seconds_per_step: None,
                median_seconds: Some(timed.total_seconds),
                error_percent: Some(diff.rms_8bit_percent),
                max_8bit_percent: Some(diff.max_8bit_percent),
                iterations: None,
                divergence: None,
            });
        }
    }
    write_csv(&out_dir.join("smoke_bench.csv"), &rows)?;
    plot(&out_dir.join("smoke_time_vs_error.png"), &rows)?;
    Ok(rows)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(path, rows)
}

/// The Taylor-Green series: time per step against the viscosity's error,
/// one line per advection scheme.
fn plot(path: &Path, rows: &[Row]) -> Result<()> {
    let tg: Vec<&Row> = rows.iter().filter(|r| r.series == "taylor-green").collect();
    let series = crate::bench::series_of(
        &tg,
        |r| format!("Taylor-Green, {}", r.advection),
        |r| (r.seconds_per_step.unwrap_or(0.0), r.error_percent.unwrap_or(0.0)),
    );
    let labels = crate::bench::LogLogPlot {
        caption: "Smoke: fluid step time against the effective viscosity's error (32^2 to 128^2 cells)",
        x_desc: "median time per step, s",
        y_desc: "|nu_eff - nu| / nu, %",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-3)
}
