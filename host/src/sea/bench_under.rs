//! `slicelight bench` on an eye under water (issue 26): run time against
//! error over the second-order settings (planes `n_z`, directions `n_d`)
//! and the caustic shafts' planes (none: the flat beam) on each scene and
//! backend; `sea_under_bench.csv` and a PNG plot per
//! scene and backend.
//!
//! Error is the whole image's difference from the f64 reference
//! (`reference::sea_radiance_under`: quadrature along the view ray and
//! toward the surface, no planes, maps or closed forms) at a lattice of
//! pixel centres, the same centres the render samples: the 8-bit RMS and
//! largest difference after the scene's tone mapping, and the RMS relative
//! to the reference's peak. Waves are read at each sample's point on both
//! sides (the footprint filter off), so that the two see the same normal.
//! Times are medians over repeats: the whole render, `sea.order2`, and the
//! shafts' passes (`sea.caustics`, `sea.shafts`, `sea.shaft_samples`,
//! `sea.order1`). The shafts' sample stride is swept too.

use anyhow::{Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

use crate::bench::{time_renders, BenchScene};
use crate::render::Backend;
use crate::scene::SceneData;

/// One configuration: `auto` (the scene's 1/255 choice), or a count of
/// planes or directions (`n_d = 3 k^2`) or shaft planes (0: no shafts)
/// with the rest the scene's.
#[derive(Debug, Clone, Copy)]
struct Config {
    series: &'static str,
    planes: u32,
    polar: u32,
    shaft_planes: u32,
    shaft_steps: u32,
    shaft_stride: u32,
}

struct Row {
    scene: String,
    backend: &'static str,
    config: Config,
    seconds: f64,
    order2_seconds: f64,
    shafts_seconds: f64,
    rms_8bit: f64,
    max_8bit: f64,
    rms_relative: f64,
}

fn sweep(data: &SceneData, quick: bool) -> Vec<Config> {
    let p = &data.sea.params;
    let base = Config {
        series: "auto",
        planes: p.planes,
        polar: p.polar,
        shaft_planes: p.shaft_planes,
        shaft_steps: p.shaft_steps,
        shaft_stride: p.shaft_stride,
    };
    let planes: &[u32] = if quick { &[2, 4, 8, 16] } else { &[2, 3, 4, 6, 8, 12, 16, 24] };
    let polar: &[u32] = if quick { &[2, 6, 12] } else { &[2, 4, 6, 8, 12, 16] };
    let shafts: &[u32] = if quick { &[0, 4, 12, 24] } else { &[0, 2, 4, 8, 12, 24, 48] };
    let steps: &[u32] = if quick { &[4, 8, 16, 32] } else { &[2, 4, 6, 8, 12, 16, 24, 32, 64] };
    let strides: &[u32] = if quick { &[1, 2, 4] } else { &[1, 2, 3, 4, 6, 8] };
    let mut v = vec![base];
    v.extend(planes.iter().map(|&n| Config { series: "planes", planes: n, ..base }));
    v.extend(polar.iter().map(|&k| Config { series: "directions", polar: k, ..base }));
    if p.shaft_planes > 0 {
        v.extend(shafts.iter().map(|&k| Config { series: "shafts", shaft_planes: k, ..base }));
        v.extend(steps.iter().map(|&k| Config { series: "shaft steps", shaft_steps: k, ..base }));
    }
    if p.shaft_planes > 0 || !data.geometry().is_empty() {
        v.extend(strides.iter().map(|&k| Config { series: "shaft stride", shaft_stride: k, ..base }));
    }
    v
}

/// The scene with `c`'s counts and the wave filter off, validated as a file's are.
fn configure(data: &SceneData, c: Option<&Config>) -> Result<SceneData> {
    let c = c.copied();
    data.reconfigure(move |f| {
        if let Some(s) = f.sea.as_mut() {
            if let Some(c) = c {
                s.planes = Some(c.planes);
                s.directions = Some(3 * c.polar * c.polar);
                s.shafts = c.shaft_planes > 0;
                if c.shaft_planes > 0 {
                    s.shaft_planes = c.shaft_planes;
                    s.shaft_steps = c.shaft_steps;
                }
                s.shaft_stride = c.shaft_stride;
            }
            if let super::Waves::Spectrum(w) = &mut s.waves {
                w.filter = false;
            }
        }
    })
    .with_context(|| format!("sea under-water bench configuration {c:?}"))
}

/// Benchmarks the underwater `scenes` (each must have its eye under the
/// water) and writes `sea_under_bench.csv` and
/// `sea_under_time_vs_error_<scene>_<backend>.png` into `out_dir`.
pub fn run(
    scenes: &[&BenchScene],
    backends: &[Backend],
    repeats: usize,
    stride: u32,
    quick: bool,
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    let mut rows = Vec::new();
    for BenchScene { path, name, data } in scenes.iter().copied() {
        crate::reference::supports(data).with_context(|| format!("{}", path.display()))?;
        let unfiltered = configure(data, None)?;
        let (w, h) = (data.width(), data.height());
        // Every `stride`-th pixel each way, the k-th one moved on by k mod 4
        // pixels: the lattice meets every offset from the shafts' samples
        // (`shaft_stride` 2 or 4), not only the samples themselves.
        let along =
            |n: u32| (0..n).step_by(stride as usize).enumerate().map(|(k, v)| v + k as u32 % 4).filter(move |&v| v < n);
        let pixels: Vec<u32> = along(h).flat_map(|y| along(w).map(move |x| y * w + x)).collect();
        let t = std::time::Instant::now();
        let reference: Vec<DVec3> =
            pixels.par_iter().map(|&i| crate::reference::surface_pixel(&unfiltered, i % w, i / w)).collect();
        eprintln!("{name}: reference at {} pixel centres, {:.1} s", pixels.len(), t.elapsed().as_secs_f64());
        for backend in backends {
            for c in sweep(&unfiltered, quick) {
                let d = configure(data, Some(&c))?;
                let order2: Vec<&'static dyn crate::passes::Pass> = vec![&super::SeaOrder2];
                let shafts: Vec<&'static dyn crate::passes::Pass> = vec![
                    &super::SeaCausticRays,
                    &super::SeaCaustics,
                    &super::SeaShafts,
                    &super::SeaShaftSamples,
                    &super::SeaOrder1,
                ];
                let timed = time_renders(&d, backend, repeats, &[&order2, &shafts])?;
                let at: Vec<DVec3> =
                    pixels.iter().map(|&i| timed.last.image[i as usize].truncate().as_dvec3()).collect();
                let diff = crate::metrics::difference(&at, &reference, data.exposure);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    config: c,
                    seconds: timed.total_seconds,
                    order2_seconds: timed.group_seconds[0],
                    shafts_seconds: timed.group_seconds[1],
                    rms_8bit: diff.rms_8bit_percent,
                    max_8bit: diff.max_8bit_percent,
                    rms_relative: diff.rms_relative,
                };
                eprintln!(
                    "{name:>14} {:>4} {:<12} n_z={:<3} n_d={:<5} shaft planes={:<3} steps={:<3} stride={} {:>8.4} s (order 2 {:.4} s, shafts {:.4} s)  8-bit rms {:.3}%  max {:.3}%",
                    row.backend,
                    c.series,
                    c.planes,
                    3 * c.polar * c.polar,
                    c.shaft_planes,
                    c.shaft_steps,
                    c.shaft_stride,
                    row.seconds,
                    row.order2_seconds,
                    row.shafts_seconds,
                    row.rms_8bit,
                    row.max_8bit
                );
                rows.push(row);
            }
        }
    }
    let mut outputs = vec![out_dir.join("sea_under_bench.csv")];
    write_csv(&outputs[0], &rows)?;
    let mut pairs: Vec<(String, &'static str)> = rows.iter().map(|r| (r.scene.clone(), r.backend)).collect();
    pairs.dedup();
    for (scene, backend) in &pairs {
        let path = out_dir.join(format!("sea_under_time_vs_error_{scene}_{backend}.png"));
        let series: Vec<(String, Vec<(f64, f64)>)> =
            ["planes", "directions", "shafts", "shaft steps", "shaft stride", "auto"]
                .iter()
                .map(|s| {
                    let points = rows
                        .iter()
                        .filter(|r| &r.scene == scene && r.backend == *backend && r.config.series == *s)
                        .map(|r| (r.seconds, r.rms_8bit))
                        .collect();
                    (s.to_string(), points)
                })
                .collect();
        let caption = format!("{scene} ({backend}): under water, time against error");
        let labels = crate::bench::LogLogPlot {
            caption: &caption,
            x_desc: "median render time, s",
            y_desc: "RMS difference from the reference, % of the 8-bit range",
        };
        crate::bench::plot_log_log(&path, &labels, &series, 1e-3)?;
        outputs.push(path);
    }
    Ok(outputs)
}

/// One CSV line of the sweep (`write_csv`).
#[derive(serde::Serialize)]
struct Record<'a> {
    scene: &'a str,
    backend: &'a str,
    series: &'a str,
    planes: u32,
    directions: u32,
    shaft_planes: u32,
    shaft_steps: u32,
    shaft_stride: u32,
    median_seconds: f64,
    order2_median_seconds: f64,
    shafts_median_seconds: f64,
    rms_8bit_percent: f64,
    max_8bit_percent: f64,
    rms_relative: f64,
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(
        path,
        rows.iter().map(|r| Record {
            scene: &r.scene,
            backend: r.backend,
            series: r.config.series,
            planes: r.config.planes,
            directions: 3 * r.config.polar * r.config.polar,
            shaft_planes: r.config.shaft_planes,
            shaft_steps: r.config.shaft_steps,
            shaft_stride: r.config.shaft_stride,
            median_seconds: r.seconds,
            order2_median_seconds: r.order2_seconds,
            shafts_median_seconds: r.shafts_seconds,
            rms_8bit_percent: r.rms_8bit,
            max_8bit_percent: r.max_8bit,
            rms_relative: r.rms_relative,
        }),
    )
}
