//! `slicelight bench` on scenes with `[[terrain]]`: run time against error
//! of the terrain's mesh resolution, and the sand automaton's time per step
//! by lattice size, on each scene and backend; a CSV and a PNG plot.
//!
//! Two series:
//! - `mesh`: the terrain meshed with `n x n` quadrilaterals, from an eighth
//!   of the field's resolution up to all of it; error against the f64
//!   reference (`reference`, shadow rays against the real triangles) of the
//!   scene meshed at the field's full resolution: what coarser meshes cost
//!   in accuracy, and what the renderer's own error is at full resolution;
//!   with ripples, the full mesh again with the ripples at full
//!   resolution everywhere (no LOD), as the reference takes them;
//! - `skylight-spacing` (under a `[sky]` that lights the scene): the full
//!   mesh and ripples with the skylight's visibility rays traced at every pixel
//!   (`size` 1), one in 2x2 (2, the default) and one in 4x4 (4);
//! - `automaton`: the scene's dunes (first terrain with `dunes`) on
//!   lattices of 64^2 up to 512^2 cells of its cell width (256^2 with
//!   `--quick`), 20 steps
//!   each through the `desert.dunes` pass; time per step. The automaton is
//!   exact (integers; the equivalence test holds both backends bit for
//!   bit): its error column is empty.
//!
//! Error is the RMS and largest difference of the 8-bit images (the
//! scene's exposure) at a lattice of pixel centres, % of 255.

use anyhow::{Context, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

use crate::bench::{time_renders, BenchScene, Options};
use crate::passes::Pass;
use crate::scene::SceneData;

/// One row of the sweep, and its CSV line (`write_csv`: the fields in
/// order, `None` as an empty field).
#[derive(serde::Serialize)]
pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub series: &'static str,
    /// Quadrilaterals a side (`mesh`), pixels between the pixels that
    /// trace the skylight's rays (`skylight-spacing`) or cells a side
    /// (`automaton`).
    pub size: u32,
    pub median_seconds: f64,
    /// `automaton`: the median over repeats of the pass's time over its steps.
    pub seconds_per_step: Option<f64>,
    pub rms_8bit_percent: Option<f64>,
    pub max_8bit_percent: Option<f64>,
}

/// The desert family's sweep: scenes with a `[[terrain]]` (and no glass,
/// sea or volume, whose sweeps take those).
pub struct DesertSweep;

impl crate::bench::Sweep for DesertSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["desert_dunes"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        !s.desert.fields.is_empty() && s.glass_vertices.is_empty() && !s.sea.enabled && !s.volumes.enabled
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        run(scenes, opts)?;
        Ok(vec![opts.out_dir.join("desert_bench.csv"), opts.out_dir.join("desert_time_vs_error.png")])
    }
}

/// The scene with every terrain meshed by `n x n` quadrilaterals.
fn meshed(data: &SceneData, n: u32) -> Result<SceneData> {
    data.reconfigure(move |f| f.terrain.iter_mut().for_each(|t| t.mesh = Some([n, n])))
        .with_context(|| format!("desert bench: mesh {n} x {n}"))
}

/// The scene's first dunes on `n x n` cells of the scene's cell width and
/// slab (the terrain grows or shrinks; its piles wrapped into it), for
/// `steps` steps, their self-check pass requested.
fn dunes_on(data: &SceneData, n: u32, steps: u32) -> Result<Option<SceneData>> {
    if !data.source.file.terrain.iter().any(|t| t.dunes.is_some()) {
        return Ok(None);
    }
    let mut d = data
        .reconfigure(move |f| {
            if let Some(t) = f.terrain.iter_mut().find(|t| t.dunes.is_some()) {
                let dunes = t.dunes.as_mut().expect("found");
                let cell = t.size[0] / dunes.cells[0] as f32;
                dunes.slab = Some(dunes.slab.unwrap_or(cell / 10.0));
                dunes.cells = [n, n];
                dunes.steps = steps;
                let side = cell * n as f32;
                t.size = [side; 2];
                // Piles keep their place in the field, wrapped into the
                // new one (and no wider than half of it).
                let min = t.min;
                for pile in dunes.piles.iter_mut().flatten() {
                    pile[0] = min[0] + (pile[0] - min[0]).rem_euclid(side);
                    pile[1] = min[1] + (pile[1] - min[1]).rem_euclid(side);
                    pile[2] = pile[2].min(0.5 * side);
                }
            }
            // The automaton alone: a frame of one pixel.
            f.camera.resolution = [1, 1];
        })
        .with_context(|| format!("desert bench: dunes on {n} x {n} cells"))?;
    d.requested_passes.push("desert.dunes".into());
    Ok(Some(d))
}

/// Runs the sweep over `scenes` and writes `desert_bench.csv` and
/// `desert_time_vs_error.png` into the options' folder. Error is measured
/// at every `stride | 1`-th pixel each way (odd, at least 3).
pub fn run(scenes: &[BenchScene], opts: &Options) -> Result<Vec<Row>> {
    let Options { backends, repeats, quick, out_dir, .. } = opts;
    // An odd stride (5 with the default 4): the lattice meets the pixels
    // that trace the skylight's visibility (even coordinates at spacing 2)
    // and those that take theirs alike.
    let (repeats, quick, stride) = (*repeats, *quick, opts.stride.max(2) | 1);
    let mut rows = Vec::new();
    for BenchScene { path, name, data } in scenes {
        anyhow::ensure!(!data.desert.fields.is_empty(), "{}: no [[terrain]] to benchmark", path.display());
        let full = data.desert.fields.iter().map(|f| f.nx.max(f.nz)).max().unwrap_or(1).clamp(8, 1024);
        let pixels = crate::bench::pixel_lattice(data, stride);
        let finest = meshed(data, full)?;
        let t = std::time::Instant::now();
        let (reference, _) = crate::reference::render_converged_at(&finest, &pixels, 2e-4);
        eprintln!(
            "{name}: reference at {} pixels on the {full}^2 mesh, {:.1} s",
            pixels.len(),
            t.elapsed().as_secs_f64()
        );
        let sizes: Vec<u32> = if quick { vec![full / 8, full] } else { vec![full / 8, full / 4, full / 2, full] };
        for backend in backends {
            // The mesh series, then (with ripples) the full mesh with the
            // ripples at full resolution everywhere: what the LOD costs
            // against the reference's full-resolution ripples.
            let rippled = data.source.file.terrain.iter().any(|t| t.ripples.is_some());
            // Under a sky, the full mesh with the skylight's visibility rays
            // traced at every pixel, one in 2x2 and one in 4x4.
            let lit = data.sky.light && data.sky.params.light_rays > 0;
            let spacings: &[u32] = if lit { &[1, 2, 4] } else { &[] };
            let configs = sizes
                .iter()
                .map(|&n| ("mesh", n))
                .chain(rippled.then_some(("mesh-ripples-full", full)))
                .chain(rippled.then_some(("mesh-ripples-blend", full)))
                .chain(spacings.iter().map(|&s| ("skylight-spacing", s)));
            for (series, n) in configs {
                let d = match series {
                    "mesh" => meshed(data, n)?,
                    // The ripples at full resolution, as the reference
                    // takes them: what is left is the skylight's.
                    "skylight-spacing" => finest
                        .reconfigure(move |f| {
                            f.sky.iter_mut().for_each(|s| s.sky_light_spacing = n);
                            super::RippleLod::Full.apply(f)
                        })
                        .with_context(|| format!("desert bench: sky_light_spacing {n}"))?,
                    "mesh-ripples-blend" => finest.reconfigure(move |f| super::RippleLod::Blend.apply(f))?,
                    _ => finest.reconfigure(move |f| super::RippleLod::Full.apply(f))?,
                };
                let timed = time_renders(&d, backend, repeats, &[])?;
                let img = &timed.last.image;
                let at: Vec<DVec3> = pixels.iter().map(|&i| img[i as usize].truncate().as_dvec3()).collect();
                let diff = crate::metrics::difference(&at, &reference, data.exposure);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    series,
                    size: n,
                    median_seconds: timed.total_seconds,
                    seconds_per_step: None,
                    rms_8bit_percent: Some(diff.rms_8bit_percent),
                    max_8bit_percent: Some(diff.max_8bit_percent),
                };
                eprintln!(
                    "{name:>14} {:>4} {series} {n:>4}^2 {:>8.4} s  rms {:.3}%  max {:.2}%",
                    row.backend, row.median_seconds, diff.rms_8bit_percent, diff.max_8bit_percent
                );
                rows.push(row);
            }
            let lattices: &[u32] = if quick { &[64, 256] } else { &[64, 128, 256, 512] };
            for &n in lattices {
                let steps = 20;
                let Some(d) = dunes_on(data, n, steps)? else { break };
                let dunes: &[&dyn Pass] = &[&super::dunes::Dunes];
                let timed = time_renders(&d, backend, repeats, &[dunes])?;
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    series: "automaton",
                    size: n,
                    median_seconds: timed.total_seconds,
                    seconds_per_step: Some(timed.group_seconds[0] / steps as f64),
                    rms_8bit_percent: None,
                    max_8bit_percent: None,
                };
                eprintln!(
                    "{name:>14} {:>4} dunes {n:>4}^2 {:>8.5} s per step ({steps} steps)",
                    row.backend,
                    row.seconds_per_step.unwrap_or(0.0)
                );
                rows.push(row);
            }
        }
    }
    write_csv(&out_dir.join("desert_bench.csv"), &rows)?;
    plot(&out_dir.join("desert_time_vs_error.png"), &rows)?;
    Ok(rows)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(path, rows)
}

/// The mesh and skylight series' error against the median render time,
/// one line per scene, backend and series.
fn plot(path: &Path, rows: &[Row]) -> Result<()> {
    let mesh: Vec<&Row> = rows.iter().filter(|r| r.rms_8bit_percent.is_some()).collect();
    let series = crate::bench::series_of(
        &mesh,
        |r| format!("{} ({}, {})", r.scene, r.backend, r.series),
        |r| (r.median_seconds, r.rms_8bit_percent.unwrap_or(0.0)),
    );
    let labels = crate::bench::LogLogPlot {
        caption: "Desert: run time against error, the mesh and the skylight's spacing (RMS % of 255)",
        x_desc: "median render time, s",
        y_desc: "RMS error, % of 255",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-4)
}
