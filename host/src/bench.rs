//! The bench harness every family's sweep shares: the `Sweep` trait a
//! family registers (with its passes, in `passes::FAMILIES`), the routing of
//! scenes to sweeps, timed renders with medians, the Pareto front of time
//! against error, and the plots (PNG, written whole or not at all). Each
//! family's sweep lives in its folder (`shafts::bench`, `sky::bench`,
//! `sea::bench`, `caustics::bench`).

use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

use crate::passes::Pass;
use crate::render::{self, Backend, Rendered};
use crate::scene::SceneData;

/// What `slicelight bench` gives every sweep.
pub struct Options {
    pub backends: Vec<Backend>,
    /// Renders per configuration; times are their medians.
    pub repeats: usize,
    /// Error is measured at every `stride`-th pixel centre in x and y (a
    /// sweep may take a coarser lattice where its reference is costly).
    pub stride: u32,
    /// A shorter sweep.
    pub quick: bool,
    /// Smoke: when not empty, time only the fluid's step, at these cube
    /// sizes (cells a side), leaving out the Taylor-Green and frame series.
    pub fluid_sizes: Vec<u32>,
    /// Where the CSVs and plots go (created if missing).
    pub out_dir: PathBuf,
}

/// A scene a sweep runs: its file, its name (the file's stem, for the rows
/// and plots) and the scene as loaded, once, by `run`.
pub struct BenchScene {
    pub path: PathBuf,
    pub name: String,
    pub data: SceneData,
}

impl BenchScene {
    pub fn load(path: &Path) -> Result<BenchScene> {
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene").to_string();
        Ok(BenchScene { path: path.to_path_buf(), name, data: crate::scene::load(path)? })
    }
}

/// A family's bench sweep: run time against error over its settings, each
/// configuration measured against the family's reference.
pub trait Sweep: Sync {
    /// The scenes (`scenes/<name>.toml`) it runs when given none.
    fn default_scenes(&self) -> &'static [&'static str];
    /// Whether a scene is this sweep's to run. The sweeps' choices do not
    /// overlap: every scene belongs to exactly one.
    fn takes(&self, scene: &SceneData) -> bool;
    /// Runs the sweep over `scenes`; returns the files it wrote.
    fn run(&self, scenes: &[BenchScene], opts: &Options) -> Result<Vec<PathBuf>>;
}

/// The registered sweeps, by family name, in the families' order.
pub fn sweeps() -> Vec<(&'static str, &'static dyn Sweep)> {
    crate::passes::families().iter().filter_map(|f| f.bench.map(|s| (f.name, s))).collect()
}

/// Runs `family`'s sweep on its default scenes (under `scenes_dir`), or
/// each of `scenes` with the sweep that takes it; returns the files written.
pub fn run(family: Option<&str>, scenes: &[PathBuf], scenes_dir: &Path, opts: &Options) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(&opts.out_dir)
        .map_err(|e| anyhow!("{}: cannot create the folder: {e}", opts.out_dir.display()))?;
    let sweeps = sweeps();
    let mut written = Vec::new();
    if scenes.is_empty() {
        let name = family.unwrap_or("shafts");
        let Some((_, sweep)) = sweeps.iter().find(|(n, _)| *n == name) else {
            let names: Vec<_> = sweeps.iter().map(|(n, _)| *n).collect();
            bail!("command line: --family: expected one of {}, got {name:?}", names.join(", "));
        };
        // A step-time sweep (`fluid_sizes`) renders no scene: none is loaded
        // (loading a smoke scene runs its fluid).
        let defaults = if opts.fluid_sizes.is_empty() { sweep.default_scenes() } else { &[] };
        let loaded = defaults
            .iter()
            .map(|s| BenchScene::load(&scenes_dir.join(format!("{s}.toml"))))
            .collect::<Result<Vec<_>>>()?;
        written.extend(sweep.run(&loaded, opts)?);
        return Ok(written);
    }
    let mut by_sweep: Vec<Vec<BenchScene>> = (0..sweeps.len()).map(|_| Vec::new()).collect();
    for path in scenes {
        let scene = BenchScene::load(path)?;
        let takers: Vec<usize> = (0..sweeps.len()).filter(|&k| sweeps[k].1.takes(&scene.data)).collect();
        match takers[..] {
            [k] => {
                if let Some(name) = family.filter(|n| *n != sweeps[k].0) {
                    bail!("{}: a scene for the {} sweep, not {name}", path.display(), sweeps[k].0);
                }
                by_sweep[k].push(scene);
            }
            _ => bail!("{}: no single bench sweep takes this scene", path.display()),
        }
    }
    for ((_, sweep), loaded) in sweeps.iter().zip(&by_sweep) {
        if !loaded.is_empty() {
            written.extend(sweep.run(loaded, opts)?);
        }
    }
    Ok(written)
}

/// A configuration's timed renders: medians over the repeats of the whole
/// render and of each group of passes (timed by identity), and the last
/// render.
pub struct Timed {
    pub total_seconds: f64,
    pub group_seconds: Vec<f64>,
    pub last: Rendered,
}

/// Renders `data` `repeats` times (at least once) on `backend` and takes
/// the medians (see `Timed`).
pub fn time_renders(data: &SceneData, backend: &Backend, repeats: usize, groups: &[&[&dyn Pass]]) -> Result<Timed> {
    let mut totals = Vec::new();
    let mut per_group = vec![Vec::new(); groups.len()];
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let r = render::render_layers(data, backend, false)?;
        totals.push(r.stats.total_seconds);
        for (times, group) in per_group.iter_mut().zip(groups) {
            times.push(r.stats.seconds_of(group));
        }
        last = Some(r);
    }
    Ok(Timed {
        total_seconds: median(totals),
        group_seconds: per_group.into_iter().map(median).collect(),
        last: last.expect("at least one render"),
    })
}

/// Every `stride`-th pixel in x and y (row-major indices): where a sweep
/// measures its error against a costly reference.
pub fn pixel_lattice(data: &SceneData, stride: u32) -> Vec<u32> {
    let (w, stride) = (data.width(), stride.max(1) as usize);
    (0..data.height()).step_by(stride).flat_map(|y| (0..w).step_by(stride).map(move |x| y * w + x)).collect()
}

/// Rows grouped into plot series by `label` (in the order labels first
/// appear), each row one point.
pub fn series_of<R>(
    rows: &[R],
    label: impl Fn(&R) -> String,
    point: impl Fn(&R) -> (f64, f64),
) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in rows {
        let name = label(r);
        match series.iter_mut().find(|(n, _)| *n == name) {
            Some((_, points)) => points.push(point(r)),
            None => series.push((name, vec![point(r)])),
        }
    }
    series
}

/// The median of `v` (the mean of the middle two for an even count).
/// Writes `rows` to `path` as CSV through serde (the `csv` crate): a
/// header of the record's field names, then a line per row, fields quoted
/// where they hold commas; written whole or not at all.
pub fn write_csv<R: serde::Serialize>(path: &Path, rows: impl IntoIterator<Item = R>) -> Result<()> {
    let mut out = csv::Writer::from_writer(Vec::new());
    for row in rows {
        out.serialize(row)?;
    }
    let bytes = out.into_inner().map_err(|e| anyhow!("{}: {e}", path.display()))?;
    crate::output::write_atomically(path, &bytes)
}

pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The points not dominated in (time, error): the Pareto front, by time.
pub fn pareto(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<_> = points.to_vec();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for q in p {
        if front.last().is_none_or(|f| q.1 < f.1) {
            front.push(q);
        }
    }
    front
}

/// Fonts for the plots: DejaVu Sans from the system (Debian's
/// fonts-dejavu-core, which scripts/setup.sh installs).
pub fn register_font() -> Result<()> {
    const CANDIDATES: &[&str] = &[
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    ];
    let path = CANDIDATES.iter().find(|p| Path::new(p).exists()).ok_or_else(|| {
        anyhow!("no DejaVuSans.ttf for the plots' labels; install fonts-dejavu-core (scripts/setup.sh does)")
    })?;
    let bytes: &'static [u8] = Box::leak(std::fs::read(path)?.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| anyhow!("{path}: not a usable font"))?;
    Ok(())
}

pub const COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

pub(crate) type Series = (String, Vec<(f64, f64)>);

/// The legend box, the same on every plot.
pub fn draw_legend<'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()?;
    Ok(())
}

/// Tick positions for a logarithmic axis over `[lo, hi]`: 1, 2 and 5 times
/// each power of ten in range (plotters' own choice can leave a narrow log
/// axis, such as render times from 0.04 to 0.3 s, without a single label).
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut ticks = Vec::new();
    if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
        return ticks;
    }
    let mut decade = 10f64.powi(lo.log10().floor() as i32);
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let t = m * decade;
            if t >= lo && t <= hi {
                ticks.push(t);
            }
        }
        decade *= 10.0;
    }
    ticks
}

/// The size of every plot, pixels.
const PLOT_SIZE: (u32, u32) = (900, 600);

/// Draws into an RGB buffer with `draw` and writes it as a PNG, whole or not at all.
pub fn save_plot(
    path: &Path,
    draw: impl FnOnce(DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    let (w, h) = PLOT_SIZE;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, PLOT_SIZE).into_drawing_area();
        root.fill(&WHITE)?;
        draw(root.clone())?;
        root.present()?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).expect("buffer sized for the plot");
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)?;
    crate::output::write_atomically(path, png.get_ref())
}

/// Marker `shape` (0 circle, 1 triangle, else square) centred `at` pixels
/// from its anchor.
fn marker<DB: DrawingBackend>(shape: usize, at: (i32, i32), color: RGBColor) -> DynElement<'static, DB, (i32, i32)> {
    let (x, y) = at;
    match shape {
        0 => Circle::new((x, y), 4, color.filled()).into_dyn(),
        1 => Polygon::new(vec![(x, y - 5), (x - 5, y + 4), (x + 5, y + 4)], color.filled()).into_dyn(),
        _ => Rectangle::new([(x - 4, y - 4), (x + 4, y + 4)], color.filled()).into_dyn(),
    }
}

/// Labels of a log-log plot of lines with markers.
pub struct LogLogPlot<'a> {
    pub caption: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
}

/// A log-log plot of labelled lines with markers (the time-against-error
/// plots); values at or below 0 are drawn at `floor`.
pub fn plot_log_log(path: &Path, labels: &LogLogPlot, series: &[(String, Vec<(f64, f64)>)], floor: f64) -> Result<()> {
    register_font()?;
    save_plot(path, |root| {
        let points = series.iter().flat_map(|s| s.1.iter().map(|&(x, y)| (x.max(floor), y.max(floor))));
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
        for (x, y) in points {
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
        let mut chart = ChartBuilder::on(&root)
            .caption(labels.caption, ("sans-serif", 24))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0 * 0.8..x1 * 1.25).log_scale().with_key_points(log_ticks(x0 * 0.8, x1 * 1.25)),
                (y0 * 0.8..y1 * 1.25).log_scale().with_key_points(log_ticks(y0 * 0.8, y1 * 1.25)),
            )?;
        chart
            .configure_mesh()
            .x_desc(labels.x_desc)
            .x_label_formatter(&|x| format!("{}", (x * 1e4).round() / 1e4))
            .y_label_formatter(&|y| format!("{}", (y * 1e4).round() / 1e4))
            .y_desc(labels.y_desc)
            .label_style(("sans-serif", 15))
            .draw()?;
        for (i, (label, pts)) in series.iter().enumerate() {
            // Past the palette, the colours come round again with another
            // marker: circles, then triangles, then squares.
            let color = COLORS[i % COLORS.len()];
            let shape = (i / COLORS.len()) % 3;
            let pts: Vec<(f64, f64)> = pts.iter().map(|&(x, y)| (x.max(floor), y.max(floor))).collect();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (20, 0)], color.stroke_width(2))
                        + marker(shape, (10, 0), color)
                });
            chart.draw_series(pts.iter().map(|&p| EmptyElement::at(p) + marker(shape, (0, 0), color)))?;
        }
        draw_legend(&mut chart)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_keeps_only_undominated_points() {
        let pts = [(1.0, 5.0), (2.0, 3.0), (3.0, 4.0), (4.0, 1.0), (0.5, 9.0)];
        assert_eq!(pareto(&pts), vec![(0.5, 9.0), (1.0, 5.0), (2.0, 3.0), (4.0, 1.0)]);
    }

    #[test]
    fn log_ticks_cover_a_narrow_range() {
        assert_eq!(log_ticks(0.04, 0.3), vec![0.05, 0.1, 0.2]);
        assert_eq!(log_ticks(0.9, 12.0), vec![1.0, 2.0, 5.0, 10.0]);
        assert!(log_ticks(0.0, 1.0).is_empty());
    }

    /// A header from the field names, a line per row, a field holding a
    /// comma quoted, `None` empty, numbers as serde writes them.
    #[test]
    fn csv_rows_go_through_serde() {
        #[derive(serde::Serialize)]
        struct Record<'a> {
            scene: &'a str,
            planes: u32,
            seconds: Option<f64>,
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rows.csv");
        let rows = [
            Record { scene: "fog, thin", planes: 32, seconds: Some(0.25) },
            Record { scene: "sea", planes: 8, seconds: None },
        ];
        write_csv(&path, rows).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "scene,planes,seconds\n\"fog, thin\",32,0.25\nsea,8,\n");
    }

    #[test]
    fn median_of_even_and_odd() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
    }
}
