//! `slicelight bench` on sea scenes with waves: the wave filter's run time
//! against its error (`slicelight_shaders::sea::surface`).
//!
//! Each scene is rendered at a third of its resolution (each pixel three
//! times as wide, so the footprints cover three times the waves: a harder
//! case than the scene's own), at 1, 4, 16 and 64 samples per pixel, with
//! the slopes filtered by each sample's footprint and read at its point.
//! The reference is the point-sampled surface at `REFERENCE_SPP` samples
//! per pixel: the pixel mean both converge to. Error is the 8-bit RMS
//! (after the scene's tone mapping) over the rows below the horizon's own
//! row (that row is the sky's edge: antialiasing's error, not the waves'),
//! and over the band of them nearest the horizon (a tenth of the image's
//! height), where a pixel covers the most waves.

use anyhow::{Context, Result};
use glam::Vec4;
use std::path::{Path, PathBuf};

use crate::bench::{time_renders, BenchScene};
use crate::render::Backend;
use crate::scene::SceneData;
use crate::sea::Waves;

/// Samples per pixel of the point-sampled reference (quick: 64).
pub const REFERENCE_SPP: u32 = 1024;

/// One render of the sweep, and its CSV line (`write_csv`).
#[derive(serde::Serialize)]
pub struct Row {
    pub scene: String,
    pub backend: &'static str,
    pub filter: bool,
    pub spp: u32,
    pub median_seconds: f64,
    /// 8-bit RMS, % of the range, below the horizon and in the band nearest it.
    #[serde(rename = "rms_8bit_percent_below_horizon")]
    pub rms_8bit_percent: f64,
    #[serde(rename = "rms_8bit_percent_nearest")]
    pub band_rms_8bit_percent: f64,
}

/// The scene at a third of its resolution, `spp` samples per pixel and the
/// wave filter on or off, validated as a file's settings are.
fn configure(data: &SceneData, filter: bool, spp: u32) -> Result<SceneData> {
    data.reconfigure(move |f| {
        f.camera.resolution = f.camera.resolution.map(|n| (n / 3).max(8));
        f.camera.samples_per_pixel = spp;
        if let Some(Waves::Spectrum(s)) = f.sea.as_mut().map(|s| &mut s.waves) {
            s.filter = filter;
        }
    })
}

/// The first image row whose every pixel sees the sea (`seen`: a sea
/// layer, non-zero where the sea is seen): the rows below it are all sea,
/// the horizon's own row is the one above.
pub fn first_sea_row(seen: &[Vec4], width: u32, height: u32) -> Option<u32> {
    (0..height).find(|&y| (0..width).all(|x| seen[(y * width + x) as usize].max_element() > 0.0))
}

/// Runs the sweep over the scenes with waves; writes `sea_wave_filter.csv`
/// and `sea_wave_filter_<scene>_<backend>.png` into `out_dir`.
pub fn run(
    scenes: &[&BenchScene],
    backends: &[Backend],
    repeats: usize,
    quick: bool,
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    let mut rows = Vec::new();
    let reference_spp = if quick { 64 } else { REFERENCE_SPP };
    for BenchScene { name, data, .. } in scenes.iter().copied() {
        if data.sea.params.waves != slicelight_shaders::sea::WAVES_NORMAL_MAP {
            continue;
        }
        let t = std::time::Instant::now();
        let reference = crate::render::render_layers(&configure(data, false, reference_spp)?, &Backend::Cpu, false)?;
        let seen = reference
            .layers
            .iter()
            .find(|(n, _)| *n == "sea.order1")
            .map(|(_, b)| b.as_slice::<Vec4>().to_vec())
            .context("no sea.order1 layer")?;
        let small = configure(data, false, 1)?;
        let (w, h) = (small.width(), small.height());
        let first = first_sea_row(&seen, w, h).context("no row sees only sea")?;
        let below = ((first + 1) * w) as usize..(w * h) as usize;
        let band = below.start..(((first + 1 + h / 10) * w) as usize).min(below.end);
        eprintln!(
            "{name}: point-sampled reference at {reference_spp} spp, {w}x{h}, {:.1} s; rows {}..{h} below the horizon",
            t.elapsed().as_secs_f64(),
            first + 1
        );
        let exposure = data.exposure;
        let rms = |image: &[Vec4], range: &std::ops::Range<usize>| {
            let a = crate::metrics::to_f64(&image[range.clone()]);
            let b = crate::metrics::to_f64(&reference.image[range.clone()]);
            crate::metrics::difference(&a, &b, exposure).rms_8bit_percent
        };
        for backend in backends {
            for filter in [true, false] {
                for spp in [1, 4, 16, 64] {
                    let timed = time_renders(&configure(data, filter, spp)?, backend, repeats, &[])?;
                    let row = Row {
                        scene: name.clone(),
                        backend: backend.name(),
                        filter,
                        spp,
                        median_seconds: timed.total_seconds,
                        rms_8bit_percent: rms(&timed.last.image, &below),
                        band_rms_8bit_percent: rms(&timed.last.image, &band),
                    };
                    eprintln!(
                        "{name:>14} {:>4} {:<8} {spp:>3} spp {:>8.4} s  rms {:.2} % below the horizon, {:.2} % nearest it",
                        row.backend,
                        if filter { "filtered" } else { "point" },
                        row.median_seconds,
                        row.rms_8bit_percent,
                        row.band_rms_8bit_percent
                    );
                    rows.push(row);
                }
            }
        }
    }
    if rows.is_empty() {
        return Ok(Vec::new());
    }
    let csv = out_dir.join("sea_wave_filter.csv");
    write_csv(&csv, &rows)?;
    let mut outputs = vec![csv];
    let mut pairs: Vec<(String, &'static str)> = rows.iter().map(|r| (r.scene.clone(), r.backend)).collect();
    pairs.dedup();
    for (scene, backend) in &pairs {
        let path = out_dir.join(format!("sea_wave_filter_{scene}_{backend}.png"));
        plot(&path, &rows, scene, backend)?;
        outputs.push(path);
    }
    Ok(outputs)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    crate::bench::write_csv(path, rows)
}

/// Error nearest the horizon against the median frame time, one line per
/// filter setting, the points at 1, 4, 16 and 64 spp.
fn plot(path: &Path, rows: &[Row], scene: &str, backend: &str) -> Result<()> {
    let series: Vec<(String, Vec<(f64, f64)>)> = [(true, "filtered by the footprint"), (false, "point-sampled")]
        .iter()
        .map(|&(filter, label)| {
            let pts = rows
                .iter()
                .filter(|r| r.scene == scene && r.backend == backend && r.filter == filter)
                .map(|r| (r.median_seconds, r.band_rms_8bit_percent))
                .collect();
            (format!("{label}, 1/4/16/64 spp"), pts)
        })
        .collect();
    let caption = format!("{scene} ({backend}, a third of its resolution): waves near the horizon");
    let labels = crate::bench::LogLogPlot {
        caption: &caption,
        x_desc: "median frame time, s",
        y_desc: "RMS against the point-sampled mean, % of 8 bits",
    };
    crate::bench::plot_log_log(path, &labels, &series, 1e-3)
}
