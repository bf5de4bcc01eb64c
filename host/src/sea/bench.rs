//! `slicelight bench` on sea scenes: run time against error of the
//! second-order scattering over its settings (planes `n_z`, directions
//! `n_d`, the scattering maps' resolution) on each scene and backend, and
//! the paper's Fig. 7 and 8 (how the order-2 radiance changes from one
//! count to the next) beside the error those counts leave; CSVs and PNG plots.
//!
//! Error is the `sea.order2` layer's difference from the f64 quadrature
//! (`sea_reference`) at a lattice of pixel centres that see the sea,
//! relative to the reference value per pixel and channel: RMS and largest.
//! Times are medians over repeats: the whole render, the map passes, and the
//! per-pixel sea passes.

use anyhow::{Context, Result};
use glam::{DVec3, Vec3, Vec4};
use plotters::prelude::*;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

use crate::bench::{time_renders, BenchScene, Options};
use crate::passes::Dispatch;
use crate::reference::{SEA_HEIGHT_FIELD_TOLERANCE, SEA_TOLERANCE};
use crate::render::Backend;
use crate::scene::SceneData;
use crate::sea::reference::{grid_depth, HeightField, SeaReference};
use crate::sea::{order2_at, EPSILON};
use slicelight_shaders::sea::{sea_view, SeaParams};

/// One configuration of the sweep.
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// `planes`, `directions`, `map`, `paper` (12 planes, 32x32, the
    /// nearest direction counts to the paper's 128) or `auto` (the scene's
    /// 1/255 choice).
    pub series: &'static str,
    pub planes: u32,
    /// `k`: `n_d = 3 k^2`.
    pub polar: u32,
    pub map: u32,
    /// The depth table's samples across the image (0: none).
    pub table: u32,
}

impl Config {
    pub fn directions(&self) -> u32 {
        3 * self.polar * self.polar
    }
}

pub fn sweep(auto: &SeaParams, quick: bool) -> Vec<Config> {
    let base =
        Config { series: "auto", planes: auto.planes, polar: auto.polar, map: auto.map_width, table: auto.table_width };
    let planes: &[u32] = if quick { &[2, 4, 8, 16] } else { &[2, 3, 4, 6, 8, 12, 16, 24] };
    let polar: &[u32] = if quick { &[2, 6, 12] } else { &[2, 4, 6, 8, 10, 12, 16] };
    let maps: &[u32] = if quick { &[8, 32] } else { &[8, 16, 32, 64] };
    let mut v = vec![base];
    v.extend(planes.iter().map(|&n| Config { series: "planes", planes: n, ..base }));
    v.extend(polar.iter().map(|&k| Config { series: "directions", polar: k, ..base }));
    v.extend(maps.iter().map(|&m| Config { series: "map", map: m, ..base }));
    v.extend([6, 8].map(|k| Config { series: "paper", planes: 12, polar: k, map: 32, ..base }));
    if auto.layers > 1 {
        // A varying bottom: without the depth table (locally flat water) and
        // with tables of several sizes.
        let tables: &[u32] = if quick { &[0, 32] } else { &[0, 8, 16, 32, 64] };
        v.extend(tables.iter().map(|&t| Config { series: "depth-table", table: t, ..base }));
    }
    v
}

/// The scene with `c`'s settings in its `[sea]`, validated (and held to
/// the tables' memory limit) as a file's are.
fn configure(data: &SceneData, c: &Config) -> Result<SceneData> {
    let c = *c;
    data.reconfigure(move |f| {
        if let Some(s) = f.sea.as_mut() {
            s.planes = Some(c.planes);
            s.directions = Some(c.directions());
            s.scattering_map = [c.map, c.map];
            s.depth_table = c.table;
        }
    })
    .with_context(|| format!("sea bench configuration {c:?}"))
}

/// Pixels on a lattice of `stride` whose centre ray meets the sea, with the
/// direction the light leaves the water toward the eye, the surface's
/// `T_o / n^2` there, where it meets the surface, and the depth where it
/// meets the bottom.
pub fn sea_pixels(data: &SceneData, stride: u32) -> Vec<(u32, Vec3, f32, Vec3, f32)> {
    let common = slicelight_shaders::types::CommonParams { samples_per_pixel: 1, sample_index: 0, ..data.common };
    let blank = slicelight_shaders::common::surface::no_surface();
    let w = data.width();
    (0..data.height())
        .step_by(stride as usize)
        .flat_map(|y| (0..w).step_by(stride as usize).map(move |x| y * w + x))
        .filter_map(|i| {
            let v = sea_view(i, &common, &data.sea.params, &data.sea.waves, &blank);
            let p = &data.sea.params;
            let (depth, _) = slicelight_shaders::sea::bottom_hit(p, &data.sea.bottom, v.point.x, v.point.z, v.view);
            v.hit.then_some((i, v.view, v.transmission, v.point, depth))
        })
        .collect()
}

/// RMS and largest difference over the values, each relative to the reference's.
pub fn relative_error(values: &[DVec3], reference: &[DVec3]) -> (f64, f64) {
    let (mut sum2, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for (a, b) in values.iter().zip(reference) {
        for ch in 0..3 {
            if b[ch] > 0.0 {
                let e = (a[ch] - b[ch]).abs() / b[ch];
                sum2 += e * e;
                max = max.max(e);
                n += 1;
            }
        }
    }
    ((sum2 / n.max(1) as f64).sqrt(), max)
}

pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub config: Config,
    pub median_seconds: f64,
    pub maps_median_seconds: f64,
    pub pixels_median_seconds: f64,
    pub rms_relative: f64,
    pub max_relative: f64,
}

/// The paper's Fig. 7 or 8: the largest change of the order-2 radiance
/// from one count to the next (`n` to `n + 1` planes, `k` to `k + 2`), and the
/// error at that count against the reference, over the 1/255 rule's views.
pub struct Convergence {
    pub scene: String,
    pub what: &'static str,
    pub count: u32,
    pub step: f64,
    pub error: f64,
}

fn convergence(name: &str, p: &SeaParams, quick: bool) -> Vec<Convergence> {
    let views = crate::sea::rule_views(p);
    let reference = SeaReference::new(p, 1e-6);
    let exact: Vec<DVec3> = views.par_iter().map(|v| reference.order2(v.as_dvec3())).collect();
    let error = |values: &[Vec3]| {
        let v: Vec<DVec3> = values.iter().map(|x| x.as_dvec3()).collect();
        relative_error(&v, &exact).1
    };
    let step = |a: &[Vec3], b: &[Vec3]| crate::sea::max_difference(a, b) as f64;
    let mut out = Vec::new();
    let planes: Vec<u32> = if quick { (2..=12).collect() } else { (2..=24).collect() };
    for &n in &planes {
        let (a, b) =
            (order2_at(&SeaParams { planes: n, ..*p }, &views), order2_at(&SeaParams { planes: n + 1, ..*p }, &views));
        out.push(Convergence { scene: name.into(), what: "planes", count: n, step: step(&a, &b), error: error(&a) });
    }
    let ks: Vec<u32> = if quick { vec![2, 4, 6, 8, 10] } else { (1..=10).map(|k| 2 * k).collect() };
    for &k in &ks {
        let at = |k: u32| order2_at(&SeaParams { polar: k, azimuths: k, ..*p }, &views);
        let (a, b) = (at(k), at(k + 2));
        out.push(Convergence {
            scene: name.into(),
            what: "directions",
            count: 3 * k * k,
            step: step(&a, &b),
            error: error(&a),
        });
    }
    out
}

/// The sea family's sweep (`passes::FAMILIES` registers it): scenes with a
/// `[sea]` and no glass.
pub struct SeaSweep;

impl crate::bench::Sweep for SeaSweep {
    fn default_scenes(&self) -> &'static [&'static str] {
        &["sea_open", "sea_calm_noon", "sea_diver"]
    }
    fn takes(&self, s: &SceneData) -> bool {
        s.sea.enabled && s.glass_vertices.is_empty()
    }
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>> {
        // An eye under the water has its own sweep (`bench_under`).
        let (under, above): (Vec<&BenchScene>, Vec<&BenchScene>) =
            scenes.iter().partition(|s| s.data.sea.params.underwater != 0);
        let mut outputs = Vec::new();
        if !under.is_empty() {
            // Its reference costs ~0.25 s a pixel: at least every 40th.
            let (backends, stride) = (&opts.backends, opts.stride.max(40));
            outputs.extend(super::bench_under::run(&under, backends, opts.repeats, stride, opts.quick, &opts.out_dir)?);
        }
        if above.is_empty() {
            return Ok(outputs);
        }
        // The sea's reference costs ~0.2 s a pixel: at least every 40th.
        run(&above, &opts.backends, opts.repeats, opts.stride.max(40), opts.quick, &opts.out_dir)?;
        outputs.extend(
            [
                "sea_bench.csv",
                "sea_time_vs_error_*.png",
                "sea_convergence.csv",
                "sea_fig7_planes.png",
                "sea_fig8_directions.png",
            ]
            .map(|f| opts.out_dir.join(f)),
        );
        outputs.extend(super::bench_waves::run(&above, &opts.backends, opts.repeats, opts.quick, &opts.out_dir)?);
        Ok(outputs)
    }
}

/// Runs the sea sweep over `scenes` and writes `sea_bench.csv`,
/// `sea_time_vs_error_<scene>_<backend>.png`, `sea_convergence.csv`,
/// `sea_fig7_planes.png` and `sea_fig8_directions.png` into `out_dir`.
pub fn run(
    scenes: &[&BenchScene],
    backends: &[Backend],
    repeats: usize,
    stride: u32,
    quick: bool,
    out_dir: &Path,
) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    let mut curves = Vec::new();
    for BenchScene { path, name, data } in scenes.iter().copied() {
        anyhow::ensure!(
            data.sea.enabled && data.sea.second_order,
            "{}: no [sea] with second-order scattering to benchmark",
            path.display()
        );
        let pixels = sea_pixels(data, stride.max(1));
        let t = std::time::Instant::now();
        // Over a varying bottom the reference integrates over the real height
        // field (as `slicelight reference` does).
        let p = &data.sea.params;
        let height = grid_depth(p, &data.sea.bottom);
        let field = HeightField::of_sea(p, &height);
        let exact: Vec<DVec3> = pixels
            .par_iter()
            .map(|&(_, v, tr, point, depth)| {
                let o2 = if p.layers > 1 {
                    SeaReference::new(p, SEA_HEIGHT_FIELD_TOLERANCE).order2_over(
                        &field,
                        (point.x as f64, point.z as f64),
                        v.as_dvec3(),
                    )
                } else {
                    SeaReference::new(&SeaParams { depth, ..*p }, SEA_TOLERANCE).order2(v.as_dvec3())
                };
                o2 * tr as f64
            })
            .collect();
        eprintln!("{name}: reference order 2 at {} pixels, {:.1} s", pixels.len(), t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        curves.extend(convergence(name, &data.sea.params, quick));
        eprintln!("{name}: Fig. 7 and 8 curves, {:.1} s", t.elapsed().as_secs_f64());
        for backend in backends {
            for c in sweep(&data.sea.params, quick) {
                let d = configure(data, &c)?;
                // The sea family's passes, once per frame (maps, tables) or per pixel.
                let sea = |dispatch: Dispatch| -> Vec<&'static dyn crate::passes::Pass> {
                    super::PASSES.iter().copied().filter(|p| p.dispatch() == dispatch).collect()
                };
                let (maps, per_pixel) = (sea(Dispatch::Whole), sea(Dispatch::PerPixel));
                let timed = time_renders(&d, backend, repeats, &[&maps, &per_pixel])?;
                let r = &timed.last;
                let layer = r
                    .layers
                    .iter()
                    .find(|(n, _)| *n == "sea.order2")
                    .map(|(_, b)| b.as_slice::<Vec4>().to_vec())
                    .context("no sea.order2 layer")?;
                let at: Vec<DVec3> = pixels.iter().map(|&(i, ..)| layer[i as usize].truncate().as_dvec3()).collect();
                let (rms, max) = relative_error(&at, &exact);
                let row = Row {
                    scene: name.clone(),
                    backend: backend.name(),
                    config: c,
                    median_seconds: timed.total_seconds,
                    maps_median_seconds: timed.group_seconds[0],
                    pixels_median_seconds: timed.group_seconds[1],
                    rms_relative: rms,
                    max_relative: max,
                };
                eprintln!(
                    "{name:>14} {:>4} {:<11} n_z={:<3} n_d={:<5} map={:<3} table={:<3} {:>8.4} s (maps {:.4} s, per-pixel {:.4} s)  rms {:.3}%  max {:.3}%",
                    row.backend,
                    c.series,
                    c.planes,
                    c.directions(),
                    c.map,
                    c.table,
                    row.median_seconds,
                    row.maps_median_seconds,
                    row.pixels_median_seconds,
                    100.0 * rms,
                    100.0 * max
                );
                rows.push(row);
            }
        }
    }
    write_csv(&out_dir.join("sea_bench.csv"), &rows)?;
    write_convergence(&out_dir.join("sea_convergence.csv"), &curves)?;
    let mut pairs: Vec<(String, &'static str)> = rows.iter().map(|r| (r.scene.clone(), r.backend)).collect();
    pairs.dedup();
    for (scene, backend) in &pairs {
        plot(&out_dir.join(format!("sea_time_vs_error_{scene}_{backend}.png")), &rows, scene, backend)?;
    }
    plot_convergence(&out_dir.join("sea_fig7_planes.png"), &curves, "planes", "sampling planes n_z")?;
    plot_convergence(&out_dir.join("sea_fig8_directions.png"), &curves, "directions", "sampling directions n_d")?;
    Ok(rows)
}

/// One CSV line of the sweep (`write_csv`).
#[derive(serde::Serialize)]
struct Record<'a> {
    scene: &'a str,
    backend: &'a str,
    series: &'a str,
    planes: u32,
    directions: u32,
    map: u32,
    depth_table: u32,
    median_seconds: f64,
    maps_median_seconds: f64,
    per_pixel_median_seconds: f64,
    rms_relative_percent: f64,
    max_relative_percent: f64,
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(
        path,
        rows.iter().map(|r| Record {
            scene: &r.scene,
            backend: r.backend,
            series: r.config.series,
            planes: r.config.planes,
            directions: r.config.directions(),
            map: r.config.map,
            depth_table: r.config.table,
            median_seconds: r.median_seconds,
            maps_median_seconds: r.maps_median_seconds,
            per_pixel_median_seconds: r.pixels_median_seconds,
            rms_relative_percent: 100.0 * r.rms_relative,
            max_relative_percent: 100.0 * r.max_relative,
        }),
    )
}

/// One CSV line of a convergence curve (`write_convergence`).
#[derive(serde::Serialize)]
struct ConvergenceRecord<'a> {
    scene: &'a str,
    sweep: &'a str,
    count: u32,
    max_step_relative: f64,
    max_error_relative: f64,
}

fn write_convergence(path: &Path, curves: &[Convergence]) -> Result<()> {
    crate::bench::write_csv(
        path,
        curves.iter().map(|c| ConvergenceRecord {
            scene: &c.scene,
            sweep: c.what,
            count: c.count,
            max_step_relative: c.step,
            max_error_relative: c.error,
        }),
    )
}

/// Largest error (% of the reference) against the median map-pass time on
/// `backend`, one line per sweep, for one scene.
fn plot(path: &Path, rows: &[Row], scene: &str, backend: &str) -> Result<()> {
    let mut names: Vec<&'static str> =
        rows.iter().filter(|r| r.scene == scene && r.backend == backend).map(|r| r.config.series).collect();
    names.dedup();
    let series: Vec<(String, Vec<(f64, f64)>)> = names
        .iter()
        .map(|name| {
            let pts = rows
                .iter()
                .filter(|r| r.scene == scene && r.backend == backend && r.config.series == *name)
                .map(|r| (r.maps_median_seconds, 100.0 * r.max_relative))
                .collect();
            let label = match *name {
                "auto" => "the 1/255 rule's choice".to_string(),
                "paper" => "the paper's 12 planes, 108 and 192 directions".to_string(),
                other => format!("{other} swept"),
            };
            (label, pts)
        })
        .collect();
    let caption = format!("{scene} ({backend}), order 2: map time against largest error");
    let labels = crate::bench::LogLogPlot {
        caption: &caption,
        x_desc: "median time of the map passes, s",
        y_desc: "largest error of sea.order2, % of the reference",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-5)
}

/// The paper's Fig. 7 or 8: the step from one count to the next, and the
/// error, against the count, with the 1/255 threshold.
fn plot_convergence(path: &Path, curves: &[Convergence], what: &'static str, x_desc: &str) -> Result<()> {
    crate::bench::register_font()?;
    let mine: Vec<&Convergence> = curves.iter().filter(|c| c.what == what).collect();
    crate::bench::save_plot(path, |root| {
        let x1 = mine.iter().map(|c| c.count).max().unwrap_or(2) as f64;
        let ys = mine.iter().flat_map(|c| [c.step, c.error]).map(|v| 100.0 * v.max(1e-5));
        let (y0, y1) = ys.fold((100.0 * EPSILON as f64, 100.0 * EPSILON as f64), |(a, b), y| (a.min(y), b.max(y)));
        let caption = if what == "planes" { "Fig. 7: order 2 against n_z" } else { "Fig. 8: order 2 against n_d" };
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x1 * 1.05, (y0 * 0.8..y1 * 1.25).log_scale())?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc("% of the order-2 radiance")
            .y_label_formatter(&|y| format!("{}", (y * 1e4).round() / 1e4))
            .label_style(("sans-serif", 15))
            .draw()?;
        let threshold = 100.0 * EPSILON as f64;
        chart
            .draw_series(LineSeries::new([(0.0, threshold), (x1 * 1.05, threshold)], BLACK.stroke_width(1)))?
            .label("1/255")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(1)));
        let mut scenes: Vec<&str> = mine.iter().map(|c| c.scene.as_str()).collect();
        scenes.dedup();
        for (i, scene) in scenes.iter().enumerate() {
            for (j, (label, pick)) in
                [("largest step to the next count", 0), ("largest error", 1)].into_iter().enumerate()
            {
                let color = crate::bench::COLORS[(2 * i + j) % crate::bench::COLORS.len()];
                let pts: Vec<(f64, f64)> = mine
                    .iter()
                    .filter(|c| c.scene == *scene)
                    .map(|c| (c.count as f64, 100.0 * if pick == 0 { c.step } else { c.error }.max(1e-5)))
                    .collect();
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                    .label(format!("{scene}: {label}"))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
                chart.draw_series(pts.iter().map(|p| Circle::new(*p, 3, color.filled())))?;
            }
        }
        crate::bench::draw_legend(&mut chart)
    })
}
