//! `slicelight`: render a scene, render its reference, compare two images.

use anyhow::{anyhow, Context, Result};
use clap::{Parser, Subcommand};
use glam::{DVec3, Vec4};
use slicelight::render::{Backend, BackendChoice};
use slicelight::{metrics, output, reference, render, scene};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Parser)]
#[command(name = "slicelight", version, about = "Light in participating media, as Rust-GPU compute kernels")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file to one or more images (.png tone-mapped sRGB, .exr linear).
    Render(RenderArgs),
    /// Render the f64 reference (shadow rays against the real geometry, no maps or tables).
    Reference(ReferenceArgs),
    /// Time against error over a family's settings, each configuration
    /// against the family's reference: CSVs and PNG plots. Each scene goes to
    /// the sweep of its family (glass: caustics; a [sea]: sea; [[volume]]:
    /// volumes; [[terrain]]: desert; sky alone: sky; the rest: shafts).
    Bench(BenchArgs),
    /// Print the RMS and max difference of IMAGE against REFERENCE.
    Compare(CompareArgs),
    /// Open a window on a scene: move the camera, the sun and the lights,
    /// change the medium and the planes, turn passes off, play an
    /// animation; the image refines while nothing changes. `--headless N`
    /// times the same frame loop without a window.
    View(ViewArgs),
    /// Write the scene's [[terrain]] height fields (dunes run here) to an
    /// image a scene can load back with `heights = { file = ... }`.
    Terrain(TerrainArgs),
}

#[derive(clap::Args)]
struct ViewArgs {
    /// The scene file (TOML; see scenes/README.md); edits to it show as they are saved.
    scene: PathBuf,
    /// gpu: a Vulkan device (an error without one); cpu: the same kernel
    /// functions on every core; auto: a device if there is one that is not
    /// itself the CPU (lavapipe: the CPU backend is faster).
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Sub-pixel samples per pixel a still view accumulates (the positions
    /// of `render --spp`; a moving view shows 1).
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Window size WxH [default: the scene's resolution].
    #[arg(long, value_parser = parse_size)]
    size: Option<[u32; 2]>,
    /// Folder where `S` writes its PNG and EXR.
    #[arg(long, default_value = ".")]
    output_dir: PathBuf,
    /// No window: time N views of the frame loop (each orbiting the last by
    /// a degree, at 1 sample per pixel) and print their times.
    #[arg(long)]
    headless: Option<usize>,
    /// With --headless: also write each view's times as CSV.
    #[arg(long, requires = "headless")]
    csv: Option<PathBuf>,
}

/// `WxH` in pixels.
fn parse_size(s: &str) -> std::result::Result<[u32; 2], String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT (640x360), got {s:?}"))?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|n| (1..=16384).contains(n));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok([w, h]),
        _ => Err(format!("expected WIDTHxHEIGHT with each in 1..=16384, got {s:?}")),
    }
}

#[derive(clap::Args)]
struct TerrainArgs {
    /// The scene file (TOML; see scenes/README.md).
    scene: PathBuf,
    /// Output: .exr (heights in metres, float) or .png (16-bit grey from 0
    /// to the highest point; the `scale` to load it back is printed). With
    /// several terrains, the second goes to NAME_1.EXT, and so on.
    #[arg(short, long = "output")]
    output: PathBuf,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// The scene file (TOML; see scenes/README.md).
    scene: PathBuf,
    /// Output image; give it more than once for several formats.
    #[arg(short, long = "output", required = true)]
    output: Vec<PathBuf>,
    /// gpu: a Vulkan device (an error without one); cpu: the same kernel
    /// functions on every core; auto: a device if there is one that is not
    /// itself the CPU (lavapipe: the CPU backend is faster).
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Write the device, the pass plan and each pass's time as JSON.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Print nothing but errors: no progress bar, no summary.
    #[arg(short, long, conflicts_with = "verbose")]
    quiet: bool,
    /// Also list the passes the scene skips, and why.
    #[arg(short, long)]
    verbose: bool,
    /// Exposure of the PNG's tone mapping (overrides `[camera] exposure`;
    /// the EXR is linear and unaffected).
    #[arg(long)]
    exposure: Option<f32>,
    #[command(flatten)]
    shafts: ShaftOverrides,
    /// Sub-pixel samples per pixel, stratified and box-filtered
    /// (overrides `[camera] samples_per_pixel`; 1 is the pixel centre).
    #[arg(long)]
    spp: Option<u32>,
    /// How directly seen surfaces find their shadows (overrides `[surface] shadows`).
    #[arg(long, value_enum)]
    surface_shadows: Option<slicelight::common::surface::SurfaceShadows>,
    /// Also run a pass no scene needs, by name (`scatter_check`: the
    /// scatter accumulation's self-check). Give it more than once for several.
    #[arg(long = "pass")]
    passes: Vec<String>,
    /// Render an animation: frames FIRST..END (END excluded), frame `f` at
    /// the scene's `[time] seconds + f / fps`; every output (and --stats)
    /// then holds a `%d`-style field for the frame number (`%04d`).
    #[arg(long, value_parser = parse_frames)]
    frames: Option<(u32, u32)>,
    /// Frames per second of `--frames`.
    #[arg(long, default_value_t = 24.0)]
    fps: f64,
    /// With `--frames`: skip frames whose outputs all exist (a render that
    /// stopped, or a range shared with another machine, goes on).
    #[arg(long, requires = "frames")]
    resume: bool,
    /// The most memory the render may hold (bytes, or with K, M, G): a
    /// scene that needs more is refused before anything is allocated.
    /// Default: the memory the system has available.
    #[arg(long, value_parser = parse_bytes)]
    max_memory: Option<u64>,
}

/// `4G`, `512M`, `64K` or a byte count.
fn parse_bytes(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim();
    let (digits, unit) = match t.char_indices().find(|(_, c)| !c.is_ascii_digit() && *c != '.') {
        Some((i, _)) => (&t[..i], t[i..].trim().to_ascii_uppercase()),
        None => (t, String::new()),
    };
    let n: f64 = digits.parse().map_err(|_| format!("expected a size such as 4G or 512M, got {s:?}"))?;
    let scale = match unit.trim_end_matches('B').trim_end_matches('I') {
        "" => 1u64,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => return Err(format!("expected a size such as 4G or 512M, got {s:?}")),
    };
    let bytes = n * scale as f64;
    if !(bytes >= 1.0 && bytes < u64::MAX as f64) {
        return Err(format!("expected a positive size, got {s:?}"));
    }
    Ok(bytes as u64)
}

/// `A..B`: frames A up to B, B excluded.
fn parse_frames(s: &str) -> std::result::Result<(u32, u32), String> {
    let (a, b) = s.split_once("..").ok_or_else(|| format!("expected FIRST..END (0..120), got {s:?}"))?;
    let a: u32 = a.trim().parse().map_err(|e| format!("{s:?}: first frame: {e}"))?;
    let b: u32 = b.trim().parse().map_err(|e| format!("{s:?}: end frame: {e}"))?;
    if b <= a {
        return Err(format!("expected END above FIRST (END is excluded), got {s:?}"));
    }
    Ok((a, b))
}

/// `path` with its `%d` / `%0Nd` field replaced by `frame`; `None` if it has none.
fn frame_path(path: &Path, frame: u32) -> Option<PathBuf> {
    let text = path.to_str()?;
    let start = text.find('%')?;
    let rest = &text[start + 1..];
    let end = rest.find('d')?;
    let spec = &rest[..end];
    if !spec.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let width: usize = if spec.is_empty() { 0 } else { spec.parse().ok()? };
    Some(PathBuf::from(format!("{}{frame:0width$}{}", &text[..start], &rest[end + 1..])))
}

#[derive(clap::Args)]
struct ReferenceArgs {
    /// The scene file (TOML; see scenes/README.md).
    scene: PathBuf,
    /// Output image (.png or .exr); give it more than once for several formats.
    #[arg(short, long = "output", required = true)]
    output: Vec<PathBuf>,
    /// Stop doubling the ray-march samples when the image changes by less
    /// than this RMS, relative to its peak.
    #[arg(long, default_value_t = 2e-4)]
    tolerance: f64,
    /// Sub-pixel samples per pixel, at the same positions as `render --spp`.
    #[arg(long)]
    spp: Option<u32>,
    /// Glass: light paths (per light, glass object and traced channel)
    /// the caustics light tracer starts with; it doubles them until the
    /// caustic image changes by less than 10x `tolerance`.
    #[arg(long, default_value_t = 1 << 20)]
    paths: u64,
    /// Glass: keep only the paths the caustics method models (refraction
    /// at every interface; no reflection, no total internal reflection).
    #[arg(long)]
    transmission_only: bool,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Scene files [default: the --family's own scenes].
    scenes: Vec<PathBuf>,
    /// The family whose sweep runs when no scene is given: shafts (Fig. 6,
    /// Fig. 7, the stained glass), sky, sea, caustics, volumes or desert
    /// [default: shafts].
    #[arg(long, conflicts_with_all = ["sky", "sea", "caustics"])]
    family: Option<String>,
    /// Short for --family sky (scenes/sky_noon, sky_sunset, sky_twilight).
    #[arg(long)]
    sky: bool,
    /// Short for --family sea (scenes/sea_open, sea_calm_noon).
    #[arg(long, conflicts_with = "sky")]
    sea: bool,
    /// Short for --family caustics (scenes/caustics_ball, caustics_knot, caustics_fog_ball).
    #[arg(long, conflicts_with_all = ["sky", "sea"])]
    caustics: bool,
    /// Backends to time (give it more than once).
    #[arg(long, value_enum, default_values = ["cpu"])]
    backend: Vec<BackendChoice>,
    /// Renders per configuration; the median time is reported.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Error is measured at every STRIDE-th pixel centre in x and y.
    #[arg(long, default_value_t = 4)]
    stride: u32,
    /// A shorter sweep (3 plane counts, 3 sub-plane counts, 2 table sizes).
    #[arg(long)]
    quick: bool,
    /// Smoke: time only the fluid's step (a hot plume, each advection
    /// scheme, each --backend) at these cube sizes, cells a side, 2 to
    /// 512; the Taylor-Green and frame series are left out.
    #[arg(long, value_delimiter = ',')]
    fluid_sizes: Vec<u32>,
    /// Folder for the CSVs and plots (created if missing).
    #[arg(long, default_value = "bench")]
    out_dir: PathBuf,
}

#[derive(clap::Args)]
struct CompareArgs {
    /// The image to judge (.png or .exr).
    image: PathBuf,
    /// The image it is judged against (.png or .exr, the same size).
    reference: PathBuf,
    /// Exposure of the 8-bit tone mapping the % figures are taken after
    /// [default: the --scene's exposure, else 1].
    #[arg(long)]
    exposure: Option<f32>,
    /// The scene the images were rendered from: its exposure is used
    /// unless --exposure is given.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Write |image - reference| as a linear greyscale-per-channel PNG,
    /// scaled so that the largest difference (printed) is white.
    #[arg(long)]
    diff: Option<PathBuf>,
}

/// Command-line overrides of the scene's `[shafts]` settings.
#[derive(clap::Args, Default, Clone)]
struct ShaftOverrides {
    /// Sample planes (eq. 5) [default: the scene's `[shafts] planes`, else 30].
    #[arg(long)]
    planes: Option<u32>,
    /// Sub-sample planes per plane interval (eq. 9) [default: the scene's
    /// `[shafts] subplanes`, else 6].
    #[arg(long)]
    subplanes: Option<u32>,
    /// exact: evaluate the phase and attenuation functions; tables: the
    /// paper's lookup tables [default: the scene's `[shafts] mode`, else exact].
    #[arg(long, value_enum)]
    mode: Option<scene::ShaftMode>,
    /// Do not offset the planes per pixel (the scene's `[shafts] jitter`
    /// otherwise decides; on by default).
    #[arg(long)]
    no_jitter: bool,
}

/// A command's overrides of the scene file's settings. They are an edit of
/// the file (`scene::load_edited`), built and validated with it once, and
/// kept by an animated scene for every frame.
#[derive(Default, Clone)]
struct Overrides {
    shafts: ShaftOverrides,
    spp: Option<u32>,
    exposure: Option<f32>,
    surface_shadows: Option<slicelight::common::surface::SurfaceShadows>,
}

impl Overrides {
    /// The flags given and the file's fields they set.
    fn given(&self) -> Vec<(&'static str, &'static str)> {
        let s = &self.shafts;
        [
            (s.planes.is_some(), "--planes", "shafts.planes"),
            (s.subplanes.is_some(), "--subplanes", "shafts.subplanes"),
            (s.mode.is_some(), "--mode", "shafts.mode"),
            (s.no_jitter, "--no-jitter", "shafts.jitter"),
            (self.spp.is_some(), "--spp", "camera.samples_per_pixel"),
            (self.exposure.is_some(), "--exposure", "camera.exposure"),
            (self.surface_shadows.is_some(), "--surface-shadows", "surface.shadows"),
        ]
        .into_iter()
        .filter_map(|(given, flag, field)| given.then_some((flag, field)))
        .collect()
    }

    /// The edit of the file's settings, if any flag is given.
    fn edit(&self) -> Option<scene::Edit> {
        if self.given().is_empty() {
            return None;
        }
        let o = self.clone();
        Some(std::sync::Arc::new(move |f: &mut scene::SceneFile| {
            let s = &mut f.shafts;
            s.planes = o.shafts.planes.unwrap_or(s.planes);
            s.subplanes = o.shafts.subplanes.unwrap_or(s.subplanes);
            s.mode = o.shafts.mode.unwrap_or(s.mode);
            s.jitter &= !o.shafts.no_jitter;
            f.camera.samples_per_pixel = o.spp.unwrap_or(f.camera.samples_per_pixel);
            f.camera.exposure = o.exposure.unwrap_or(f.camera.exposure);
            f.surface.shadows = o.surface_shadows.unwrap_or(f.surface.shadows);
        }))
    }

    /// The scene at `path` with the overrides applied; an error about a
    /// field a flag set names the flag.
    fn load(&self, path: &Path) -> Result<scene::SceneData> {
        scene::load_edited(path, self.edit()).map_err(|e| {
            let text = format!("{e:#}");
            match self.given().into_iter().find(|(_, field)| text.contains(&format!("{field}:"))) {
                Some((flag, _)) => anyhow!("command line: {flag}: {text}"),
                None => e,
            }
        })
    }
}

/// The Vulkan loader and Mesa's drivers print "XDG_RUNTIME_DIR is invalid or
/// not set" on a headless machine without one. Give them a private folder
/// (mode 0700, as the XDG spec asks) before any thread starts.
fn ensure_runtime_dir() {
    let usable = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
    if usable {
        return;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt};
        let uid = std::fs::metadata("/proc/self").map(|m| m.uid()).unwrap_or(0);
        let dir = std::env::temp_dir().join(format!("slicelight-runtime-{uid}"));
        let made = std::fs::DirBuilder::new().mode(0o700).create(&dir);
        if made.is_ok() || dir.is_dir() {
            // Single-threaded here: nothing else reads the environment yet.
            std::env::set_var("XDG_RUNTIME_DIR", &dir);
        }
    }
}

use output::say;

fn main() {
    ensure_runtime_dir();
    output::remove_temporaries_on_signal();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("slicelight: error: {e:#}");
        std::process::exit(1);
    }
}

/// Checks every output path before any work: a known format, and a folder
/// that exists.
fn check_outputs(outputs: &[PathBuf]) -> Result<()> {
    for o in outputs {
        output::format_of(o)?;
        check_outputs_dir(o)?;
    }
    Ok(())
}

/// Writes the image to every output and `extra` files (the stats), all or
/// none (`output::write_all`).
fn write_outputs(
    outputs: &[PathBuf],
    pixels: &[Vec4],
    layers: &[(&str, &[Vec4])],
    data: &scene::SceneData,
    quiet: bool,
    extra: &[(&Path, Vec<u8>)],
) -> Result<()> {
    let extra: Vec<(&Path, &[u8])> = extra.iter().map(|(p, b)| (*p, b.as_slice())).collect();
    output::write_images(outputs, pixels, layers, (data.width(), data.height(), data.exposure), &extra)?;
    if !quiet {
        for o in outputs.iter().map(|p| p.as_path()).chain(extra.iter().map(|(p, _)| *p)) {
            eprintln!("wrote {}", o.display());
        }
    }
    Ok(())
}

/// The render's summary on stderr: each pass that ran with its time and why
/// it ran (with `all`, also those skipped and why), in aligned columns, then
/// the total.
fn print_summary(st: &render::RenderStats, all: bool) {
    let shown: Vec<_> = st.passes.iter().filter(|p| p.ran || all).collect();
    let width = shown.iter().map(|p| p.name.len()).max().unwrap_or(0).max("total".len());
    for p in &shown {
        if p.ran {
            eprintln!("  {:<width$} {:>9.3} s  {}", p.name, p.seconds, p.reason);
        } else {
            eprintln!("  {:<width$}   skipped  {}", p.name, p.reason);
        }
        if let Some(report) = &p.report {
            eprintln!("  {:<width$}            {report}", "");
        }
    }
    let skipped = st.passes.len() - st.passes.iter().filter(|p| p.ran).count();
    eprintln!(
        "  {:<width$} {:>9.3} s  ({} sample(s) per pixel; pass times: {}{})",
        "total",
        st.total_seconds,
        st.samples_per_pixel,
        st.pass_timing,
        if all || skipped == 0 { String::new() } else { format!("; {skipped} passes skipped, -v lists them") }
    );
    if st.kernel_build_seconds > 0.0 {
        eprintln!("  (before it: {:.3} s building the GPU kernels it runs)", st.kernel_build_seconds);
    }
    if st.counter("shaft_samples_naive") > 0 {
        eprintln!(
            "  shaft samples {} of a naive {} ({:.1}%)",
            st.counter("shaft_samples"),
            st.counter("shaft_samples_naive"),
            100.0 * st.counter("shaft_samples") as f64 / st.counter("shaft_samples_naive") as f64
        );
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(args) => render_command(args),
        Command::Reference(args) => reference_command(args),
        Command::Bench(args) => bench_command(args),
        Command::Compare(args) => compare_command(args),
        Command::Terrain(args) => terrain_command(args),
        Command::View(args) => view_command(args),
    }
}

fn render_command(args: RenderArgs) -> Result<()> {
    let RenderArgs {
        scene,
        output,
        backend,
        stats,
        quiet,
        verbose,
        exposure,
        shafts,
        spp,
        surface_shadows,
        passes,
        frames,
        fps,
        resume,
        max_memory,
    } = args;
    if let Some(bytes) = max_memory {
        slicelight::render::MEMORY_BUDGET.store(bytes, std::sync::atomic::Ordering::Relaxed);
    }
    slicelight::output::QUIET.store(quiet, std::sync::atomic::Ordering::Relaxed);
    for name in &passes {
        if slicelight::passes::by_name(name).is_none() {
            let known: Vec<_> = slicelight::passes::PASSES.iter().map(|p| p.name()).collect();
            return Err(anyhow!("command line: --pass: expected one of {}, got {name:?}", known.join(", ")));
        }
    }
    // The frames to render, each with its outputs and stats path.
    let jobs: Vec<(Option<u32>, Vec<PathBuf>, Option<PathBuf>)> = match frames {
        None => vec![(None, output.clone(), stats.clone())],
        Some((first, end)) => {
            if !(fps.is_finite() && fps > 0.0) {
                return Err(anyhow!("command line: --fps: expected a positive number of frames per second, got {fps}"));
            }
            for p in output.iter().chain(&stats) {
                if frame_path(p, 0).is_none() {
                    return Err(anyhow!(
                        "{}: expected a frame-number field (%d or %04d) in every output with --frames",
                        p.display()
                    ));
                }
            }
            (first..end)
                .map(|f| {
                    let at = |p: &PathBuf| frame_path(p, f).expect("checked above");
                    (Some(f), output.iter().map(at).collect(), stats.as_ref().map(at))
                })
                .collect()
        }
    };
    // Simulations step where the frame renders (their kernels, or their CPU twins).
    render::simulate_on(backend);
    let overrides = Overrides { shafts, spp, exposure, surface_shadows };
    let base = overrides.load(&scene)?;
    for (_, outs, st) in &jobs {
        check_outputs(outs)?;
        if let Some(path) = st {
            check_outputs_dir(path)?;
        }
        let written: Vec<&Path> = outs.iter().map(|p| p.as_path()).chain(st.as_deref()).collect();
        check_distinct(&written, &[(&scene, "the scene")])?;
    }
    let backend = Backend::open(backend)?;
    if !quiet {
        eprintln!("backend: {} on {}", backend.name(), backend.device());
    }
    for light in base.lights_inside_glass() {
        output::note(&format!(
            "warning: {}: {light}, which is glass: light from inside glass is not carried out of it (the caustics start outside the object), so it adds no light",
            scene.display()
        ));
    }
    for light in base.spotlights_reaching_nothing() {
        output::note(&format!(
            "warning: {}: {light} reaches nothing (no surface or volume in its cone, no scattering medium): it adds no light",
            scene.display()
        ));
    }
    let show = !quiet && std::io::stderr().is_terminal();
    let total = jobs.len();
    let clock = Instant::now();
    let mut done = 0usize;
    for (k, (frame, outs, st)) in jobs.iter().enumerate() {
        if resume && outs.iter().chain(st).all(|p| p.exists()) {
            if !quiet {
                eprintln!("frame {}: its outputs exist, skipped (--resume)", frame.unwrap_or(0));
            }
            continue;
        }
        let frame_clock = Instant::now();
        let mut data = match frame {
            None => base.clone(),
            Some(f) => {
                let t = base.time + *f as f64 / fps;
                base.at_time(t).map_err(|e| anyhow!("{}: {e}", scene.display()))?
            }
        };
        data.requested_passes = passes.clone();
        let rendered = render::render_layers(&data, &backend, show && frame.is_none())?;
        let stats_of = &rendered.stats;
        if !quiet && frame.is_none() {
            print_summary(stats_of, verbose || st.is_some());
        }
        let json = match st {
            Some(path) => vec![(path.as_path(), serde_json::to_vec_pretty(stats_of)?)],
            None => Vec::new(),
        };
        write_outputs(outs, &rendered.image, &rendered.layer_slices(), &data, quiet || frame.is_some(), &json)?;
        done += 1;
        if let (Some(f), false) = (frame, quiet) {
            let per_frame = clock.elapsed().as_secs_f64() / done as f64;
            let left = total - k - 1;
            eprintln!(
                "frame {f} ({} of {total}, t = {:.3} s): {:.2} s, wrote {}; about {:.0} s to go",
                k + 1,
                data.time,
                frame_clock.elapsed().as_secs_f64(),
                outs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
                per_frame * left as f64
            );
        }
    }
    Ok(())
}

fn reference_command(args: ReferenceArgs) -> Result<()> {
    let ReferenceArgs { scene, output, tolerance, spp, paths, transmission_only } = args;
    check_outputs(&output)?;
    check_distinct(&output.iter().map(|p| p.as_path()).collect::<Vec<_>>(), &[(&scene, "the scene")])?;
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance < 1.0) {
        return Err(anyhow!("command line: --tolerance: expected a relative change in (0, 1), got {tolerance}"));
    }
    if paths == 0 {
        return Err(anyhow!("command line: --paths: expected at least 1 light path, got 0"));
    }
    let data = Overrides { spp, ..Default::default() }.load(&scene)?;
    reference::supports(&data).map_err(|e| anyhow!("{}: {e}", scene.display()))?;
    let t = Instant::now();
    let (mut image, samples) = reference::render_converged(&data, tolerance);
    if data.scatters() || data.volumes.enabled {
        eprintln!("reference: {samples} samples per ray, {:.3} s", t.elapsed().as_secs_f64());
    } else {
        eprintln!("reference: {:.3} s (the medium does not scatter: no ray march)", t.elapsed().as_secs_f64());
    }
    if !data.glass_vertices.is_empty() && !data.lights.is_empty() {
        use slicelight::caustics::reference::{light_trace_converged, Splat};
        // The caustics on surfaces, and in a scattering medium the caustic
        // light it scatters toward the eye (the caustic shafts).
        let splats = [(Splat::Surfaces, "caustics"), (Splat::Medium, "caustic shafts")];
        for (splat, what) in splats.into_iter().filter(|(s, _)| *s == Splat::Surfaces || data.scatters()) {
            let t = Instant::now();
            let (light, n) =
                light_trace_converged(&data, paths, paths << 6, 10.0 * tolerance, transmission_only, splat);
            for (p, c) in image.iter_mut().zip(light) {
                *p += c;
            }
            eprintln!(
                "reference {what}: {n} light paths per light, glass object and channel{}, {:.3} s",
                if transmission_only { " (transmission only)" } else { "" },
                t.elapsed().as_secs_f64()
            );
        }
    }
    let pixels: Vec<Vec4> = image.iter().map(|p| p.as_vec3().extend(0.0)).collect();
    write_outputs(&output, &pixels, &[], &data, false, &[])
}

fn bench_command(args: BenchArgs) -> Result<()> {
    let BenchArgs { scenes, family, sky, sea, caustics, backend, repeats, stride, quick, fluid_sizes, out_dir } = args;
    if repeats == 0 {
        return Err(anyhow!("command line: --repeats: expected at least 1 render per configuration, got 0"));
    }
    if stride == 0 {
        return Err(anyhow!("command line: --stride: expected at least 1 (every pixel), got 0"));
    }
    let family = family.or_else(|| {
        [(sky, "sky"), (sea, "sea"), (caustics, "caustics")].iter().find(|(on, _)| *on).map(|(_, n)| n.to_string())
    });
    if let Some(n) = fluid_sizes.iter().find(|n| !(2..=512).contains(*n)) {
        return Err(anyhow!("command line: --fluid-sizes: expected 2 to 512 cells a side, got {n}"));
    }
    if !fluid_sizes.is_empty() && !scenes.is_empty() {
        // The step sweep runs a plume of its own: a scene given with it
        // would be loaded (a smoke scene runs its fluid at load) and ignored.
        return Err(anyhow!(
            "command line: --fluid-sizes times the fluid's step on a plume of its own and takes no scene file, got {}",
            scenes[0].display()
        ));
    }
    let family = match family {
        None if !fluid_sizes.is_empty() => Some("smoke".to_string()),
        Some(f) if !fluid_sizes.is_empty() && f != "smoke" => {
            return Err(anyhow!("command line: --fluid-sizes: only the smoke family has a fluid, not {f}"));
        }
        other => other,
    };
    let backends: Vec<render::Backend> = backend.iter().map(|b| render::Backend::open(*b)).collect::<Result<_>>()?;
    let opts = slicelight::bench::Options { backends, repeats, stride, quick, fluid_sizes, out_dir };
    let written = slicelight::bench::run(family.as_deref(), &scenes, Path::new("scenes"), &opts)?;
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    eprintln!("wrote {}", names.join(", "));
    Ok(())
}

fn view_command(args: ViewArgs) -> Result<()> {
    let ViewArgs { scene, backend, spp, size, output_dir, headless, csv } = args;
    if !(1..=scene::MAX_SAMPLES_PER_PIXEL).contains(&spp) {
        return Err(anyhow!("command line: --spp: expected 1 to {}, got {spp}", scene::MAX_SAMPLES_PER_PIXEL));
    }
    render::simulate_on(backend);
    let Some(frames) = headless else {
        return slicelight::view::run(slicelight::view::Options { scene, backend, samples: spp, size, output_dir });
    };
    if frames == 0 {
        return Err(anyhow!("command line: --headless: expected at least 1 view, got 0"));
    }
    if let Some(path) = &csv {
        check_outputs_dir(path)?;
        check_distinct(&[path.as_path()], &[(&scene, "the scene")])?;
    }
    let base = scene::load(&scene)?;
    let size = size.unwrap_or([base.width(), base.height()]);
    let views = slicelight::view::headless(&scene, base, backend, size, frames)?;
    let median = slicelight::bench::median;
    let last = &views[views.len() - 1].1;
    say(&format!(
        "{}: {} views at {}x{}, 1 sample per pixel, {} on {}: median {:.1} ms per view (render {:.1} ms), first {:.1} ms",
        scene.display(),
        views.len(),
        size[0],
        size[1],
        last.backend,
        last.device,
        1e3 * median(views.iter().map(|v| v.0).collect()),
        1e3 * median(views.iter().map(|v| v.1.total_seconds).collect()),
        1e3 * views[0].0
    ));
    for p in last.passes.iter().filter(|p| p.ran) {
        let name = p.name;
        let of_pass: Vec<&render::PassStats> =
            views.iter().filter_map(|v| v.1.passes.iter().find(|q| q.name == name)).collect();
        let kept = of_pass.iter().filter(|q| q.kept).count();
        let ran: Vec<f64> = of_pass.iter().filter(|q| !q.kept).map(|q| q.seconds).collect();
        let time = if ran.is_empty() { "        -".to_string() } else { format!("{:>8.2} ms", 1e3 * median(ran)) };
        let note = if kept > 0 {
            format!("  (kept from an earlier view in {kept} of {})", of_pass.len())
        } else {
            String::new()
        };
        say(&format!("  {name:<24} {time}{note}"));
    }
    if let Some(path) = csv {
        /// One CSV line per view: its whole time and the render's.
        #[derive(serde::Serialize)]
        struct Record {
            view: usize,
            seconds: f64,
            render_seconds: f64,
        }
        let rows = views.iter().enumerate().map(|(view, (s, st))| Record {
            view,
            seconds: *s,
            render_seconds: st.total_seconds,
        });
        slicelight::bench::write_csv(&path, rows)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn terrain_command(args: TerrainArgs) -> Result<()> {
    check_outputs(std::slice::from_ref(&args.output))?;
    check_distinct(&[args.output.as_path()], &[(&args.scene, "the scene")])?;
    let data = scene::load(&args.scene)?;
    for (path, note) in slicelight::desert::write_fields(&data.desert, &args.output)? {
        say(&format!("wrote {}{note}", path.display()));
    }
    Ok(())
}

fn compare_command(args: CompareArgs) -> Result<()> {
    let CompareArgs { image, reference, exposure, scene, diff } = args;
    if let Some(path) = &diff {
        let mut inputs = vec![(image.as_path(), "an input image"), (reference.as_path(), "an input image")];
        if let Some(s) = &scene {
            inputs.push((s.as_path(), "the scene"));
        }
        check_distinct(&[path.as_path()], &inputs)?;
        check_outputs_dir(path)?;
    }
    let exposure = match (exposure, &scene) {
        (Some(e), _) => e,
        (None, Some(path)) => scene::load(path)?.exposure,
        (None, None) => 1.0,
    };
    if !(exposure.is_finite() && exposure > 0.0) {
        return Err(anyhow!("command line: --exposure: expected a positive number, got {exposure}"));
    }
    let (w, h, a) = read_linear(&image)?;
    let (rw, rh, b) = read_linear(&reference)?;
    if (w, h) != (rw, rh) {
        return Err(anyhow!("{} is {w}x{h} but {} is {rw}x{rh}", image.display(), reference.display()));
    }
    let d = metrics::difference(&a, &b, exposure);
    say(&format!(
        "rms_relative     {:.4e}\nmax_relative     {:.4e}\nrms_8bit_percent {:.4}\nmax_8bit_percent {:.4}\nenergy_ratio     {:.4}",
        d.rms_relative, d.max_relative, d.rms_8bit_percent, d.max_8bit_percent, d.energy_ratio
    ));
    if let Some(path) = diff {
        let largest = a.iter().zip(&b).map(|(x, y)| (*x - *y).abs().max_element()).fold(0.0, f64::max).max(1e-300);
        let pixels: Vec<Vec4> =
            a.iter().zip(&b).map(|(x, y)| ((*x - *y).abs() / largest).as_vec3().extend(0.0)).collect();
        output::write_image(&path, &pixels, w, h, 1.0)?;
        eprintln!(
                    "wrote {}: per channel |image - reference| / {largest:.4e} (white: that difference; linear, no tone mapping)",
                    path.display()
                );
    }
    Ok(())
}

/// Refuses, before any work, outputs that would destroy an input or each
/// other: an output that is one of `inputs` (the scene, an image being
/// compared), the same file given twice, or a folder. Files are compared by
/// what they resolve to, so `o.png` and `./o.png` are one.
fn check_distinct(outputs: &[&Path], inputs: &[(&Path, &str)]) -> Result<()> {
    let resolve = |p: &Path| -> PathBuf {
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let dir = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        dir.join(p.file_name().unwrap_or_default())
    };
    for (k, out) in outputs.iter().enumerate() {
        if out.is_dir() {
            return Err(anyhow!("{}: expected a file to write, but it is a folder", out.display()));
        }
        let r = resolve(out);
        for (input, what) in inputs {
            if resolve(input) == r {
                return Err(anyhow!(
                    "{}: is {what} this command reads; an output may not overwrite its input",
                    out.display()
                ));
            }
        }
        if outputs[..k].iter().any(|o| resolve(o) == r) {
            return Err(anyhow!("{}: given as an output more than once", out.display()));
        }
    }
    Ok(())
}

fn check_outputs_dir(path: &Path) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        return Err(anyhow!("{}: the folder {} does not exist", path.display(), dir.display()));
    }
    if path.is_dir() {
        return Err(anyhow!("{}: expected a file to write, got a folder", path.display()));
    }
    // Writable: create and remove a probe file (permissions alone do not
    // tell: root, read-only mounts, /proc).
    let probe = dir.join(format!(".slicelight-probe-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(anyhow!("{}: cannot write in the folder {}: {e}", path.display(), dir.display())),
    }
}

/// Reads an image as linear rgb: EXR as stored, PNG with its sRGB transfer undone.
fn read_linear(path: &Path) -> Result<(u32, u32, Vec<DVec3>)> {
    let format = output::format_of(path)?;
    output::regular_file("the image", path, output::MAX_IMAGE_BYTES)?;
    let img = image::open(path).with_context(|| format!("{}: cannot read the image", path.display()))?.to_rgb32f();
    let decode = |v: f32| {
        if format == output::Format::Png {
            scene::srgb_to_linear(v)
        } else {
            v
        }
    };
    let pixels =
        img.pixels().map(|p| DVec3::new(decode(p[0]) as f64, decode(p[1]) as f64, decode(p[2]) as f64)).collect();
    Ok((img.width(), img.height(), pixels))
}
