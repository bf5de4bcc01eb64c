//! GPU-vs-CPU equivalence: every registered pass's kernel, run as SPIR-V on a
//! Vulkan device and as the same Rust function on the CPU, on identical
//! inputs; then whole renders through the pass plan; then the fluid's
//! kernels (a family's own, outside the passes) step by step.
//!
//! These tests need a Vulkan device (lavapipe is enough: `scripts/setup.sh`
//! installs it). Without one they fail; they never skip.

mod common;

use indicatif::ProgressBar;
use slicelight::gpu::GpuContext;
use slicelight::passes::{Dispatch, Frame, PASSES};
use slicelight::render;
use slicelight::scene::SceneData;
use slicelight::smoke::gpu::GpuFluid;

fn device() -> GpuContext {
    let ctx = GpuContext::new().unwrap_or_else(|e| panic!("the equivalence tests need a Vulkan device: {e:#}"));
    println!("device: {}", ctx.device_name());
    ctx
}

fn fog_spot() -> SceneData {
    slicelight::scene::load(&common::root().join("scenes/fog_spot.toml")).unwrap()
}

/// A scene that reaches the code paths fog_spot does not: a directional light
/// through a window with a light map, a triangle mesh from OBJ, no light map
/// on a spotlight with a hard edge, a coloured medium.
/// The window scene with `edit` made to its settings (while its mesh and
/// light map exist: they are read again).
fn window_scene_with(edit: impl Fn(&mut slicelight::scene::SceneFile) + Send + Sync + 'static) -> SceneData {
    let dir = tempfile::tempdir().unwrap();
    let obj = "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0 1 0\nv 0 0 0.5\nf 1 2 3\nf 2 4 3\nf 4 1 3\n";
    std::fs::write(dir.path().join("tetra.obj"), obj).unwrap();
    let img = image::RgbImage::from_fn(4, 4, |x, y| image::Rgb([(x * 60) as u8, (y * 60) as u8, 200]));
    img.save(dir.path().join("glass.png")).unwrap();
    let toml = r#"
        [camera]
        position = [0.0, 2.0, 6.0]
        look_at = [0.0, 0.5, 0.0]
        vfov_deg = 50.0
        resolution = [320, 200]
        [medium]
        sigma_s = [0.02, 0.03, 0.05]
        sigma_t = [0.03, 0.04, 0.06]
        phase = { kind = "henyey-greenstein", g = 0.5 }
        [[directional_light]]
        direction = [0.3, -1.0, -0.2]
        irradiance = [2.0, 1.8, 1.5]
        origin = [0.0, 4.0, 0.0]
        size = [3.0, 2.0]
        light_map = "glass.png"
        shadow_map_resolution = 300
        [[spotlight]]
        position = [2.0, 3.0, 2.0]
        direction = [-1.0, -1.5, -1.0]
        cutoff_deg = 30.0
        intensity = [20.0, 20.0, 20.0]
        shadow_map_resolution = 256
        [[object]]
        type = "mesh"
        file = "tetra.obj"
        scale = 1.5
        [[object]]
        type = "quad"
        center = [0.0, 0.0, 0.0]
        u = [8.0, 0.0, 0.0]
        v = [0.0, 0.0, 8.0]
    "#;
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    slicelight::scene::load(&path).unwrap().reconfigure(edit).unwrap()
}

fn window_scene() -> SceneData {
    window_scene_with(|_| ())
}

/// The families of scenes the passes are checked on, a test each (one
/// test of them all took 65 s on lavapipe here; now at most about 25 s).
#[derive(Copy, Clone, PartialEq, Eq, Debug)]
enum Family {
    Lights,
    Sky,
    Sea,
    Glass,
    Caustics,
    Volumes,
    Desert,
}

/// A scene the passes are checked on: its name, its family, how it is made.
type CheckedScene = (&'static str, Family, fn() -> SceneData);

/// The scenes every pass is checked on, each with its family and how it
/// is made (built only by the test that checks it): between them they
/// reach every kernel path (spot and directional lights, light maps, a
/// mesh, exact and table shafts, the self-check).
fn scenes() -> Vec<CheckedScene> {
    use Family::*;
    vec![
        ("fog_spot", Lights, || {
            let mut fog = fog_spot();
            fog.requested_passes.push("scatter_check".into());
            fog
        }),
        ("fog_spot, tables", Lights, || {
            fog_spot()
                .reconfigure(|f| {
                    f.shafts.mode = slicelight::scene::ShaftMode::Tables;
                    f.shafts.jitter = false;
                })
                .unwrap()
        }),
        ("window", Lights, window_scene),
        ("window, sample 3 of 4", Lights, || {
            window_scene_with(|f| f.camera.samples_per_pixel = 4).at_sample(3).unwrap()
        }),
        ("window, shadow-mapped surfaces", Lights, || {
            window_scene_with(|f| f.surface.shadows = slicelight::common::surface::SurfaceShadows::ShadowMap)
        }),
        ("sky_noon", Sky, || sky("sky_noon", 128, 128)),
        ("sky_twilight", Sky, || sky("sky_twilight", 128, 128)),
        ("sky_sunset, per-pixel sky", Sky, || {
            sky("sky_sunset", 180, 120).reconfigure(move |f| f.sky.as_mut().expect("a [sky]").sky_view = false).unwrap()
        }),
        ("sun_garden", Sky, || sky("sun_garden", 180, 120)),
        ("glass_garden", Glass, || traced("glass_garden", 180, 120)),
        ("sea_glass", Caustics, || traced("sea_glass", 180, 120)),
        ("sea_open", Sea, || sky("sea_open", 180, 120)),
        ("sea_calm_noon", Sea, || sky("sea_calm_noon", 180, 120)),
        ("sea_shore", Sea, || sky("sea_shore", 180, 120)),
        ("sea_pier", Sea, || sky("sea_pier", 180, 120)),
        ("sea_diver", Sea, || sky("sea_diver", 180, 120)),
        ("sea_under_pier", Sea, || sky("sea_under_pier", 180, 120)),
        ("under a shore, a sphere in the water", Sea, under_a_shore),
        ("under the pier, a glass ball above the water", Sea, glass_over_the_diver),
        ("caustics_ball", Caustics, || traced("caustics_ball", 160, 120)),
        ("caustics_fog_ball", Caustics, || traced("caustics_fog_ball", 160, 120)),
        ("caustics_torus, turned", Glass, turned_torus),
        ("cloud_cumulus", Volumes, || sky("cloud_cumulus", 160, 120)),
        ("cloud_cumulus_splat", Volumes, || sky("cloud_cumulus_splat", 160, 120)),
        ("cloud_automaton", Volumes, || sky("cloud_automaton", 160, 120)),
        ("cloud_grid", Volumes, || sky("cloud_grid", 160, 120)),
        ("cloud_sea", Volumes, || sky("cloud_sea", 160, 120)),
        ("dunes, 32x32 cells, 60 steps", Desert, small_dunes),
        ("dunes, ripples blended between levels", Desert, || {
            small_dunes().reconfigure(|f| slicelight::desert::RippleLod::Blend.apply(f)).unwrap()
        }),
        ("barchans, piles on bare ground, 32x32 cells, 60 steps", Desert, small_barchans),
    ]
}

/// `sea_diver` 1 m down over `sea_shore`'s rising bottom, looking down
/// the slope at a sphere in the water (the water's pass on its light).
fn under_a_shore() -> SceneData {
    let text = std::fs::read_to_string(common::root().join("scenes/sea_diver.toml")).unwrap();
    let text = text
        .replace("resolution = [720, 480]", "resolution = [120, 80]")
        .replace("position = [0.0, -5.0, 0.0]", "position = [0.0, -1.0, 0.0]")
        .replace("look_at = [5.0, 0.8, -8.66]", "look_at = [-4.0, -3.0, -8.0]")
        .replace(
            "depth_m = 12.0",
            "bottom = { kind = \"shore\", slope = 0.12, shallow_m = 0.3, deep_m = 40.0, direction_deg = 270.0, offset_m = -8.0 }",
        )
        + "\n[[object]]\ntype = \"sphere\"\ncenter = [-2.0, -3.0, -6.0]\nradius = 1.0\nalbedo = [0.7, 0.6, 0.5]\n";
    let data = common::scene_from_str(&text);
    assert!(data.sea.params.underwater != 0 && data.sea.params.bottom_nx >= 2 && data.has_geometry());
    data
}

/// `sea_under_pier` at 180x120 with a glass ball (radius 0.4 m) hung
/// under the deck where the eye sees it through Snell's window
/// (`sea.glass_air` under the water).
fn glass_over_the_diver() -> SceneData {
    let text = std::fs::read_to_string(common::root().join("scenes/sea_under_pier.toml")).unwrap();
    let text = text.replace("resolution = [720, 480]", "resolution = [180, 120]")
        + "\n[[object]]\ntype = \"sphere\"\ncenter = [1.5, 1.0, -7.66]\nradius = 0.4\nmaterial = { kind = \"glass\", ior = 1.5 }\n";
    let mut data = common::scene_from_str(&text);
    data.caustics.forget_cached_table();
    assert!(data.sea.params.underwater != 0 && data.has_glass());
    data
}

/// A shipped desert scene at 96x64 with its dune field's `field` (the
/// text of its cells and steps) made `small` (32x32 cells), its
/// automaton's self-check requested.
fn small_desert(scene: &str, field: &str, small: &str) -> SceneData {
    let text = std::fs::read_to_string(common::root().join(format!("scenes/{scene}.toml"))).unwrap();
    let text = text.replace("resolution = [720, 480]", "resolution = [96, 64]").replace(field, small);
    let mut data = common::scene_from_str(&text);
    assert!(data.desert.dunes.as_ref().is_some_and(|d| d.params.cells == 1024), "{scene}");
    data.requested_passes.push("desert.dunes".into());
    data
}

/// `desert_dunes` with a small field and few steps (each step is eight
/// dispatches).
fn small_dunes() -> SceneData {
    small_desert("desert_dunes", "cells = [128, 128], steps = 1500", "cells = [32, 32], steps = 60, creep = 0.3")
}

/// `desert_barchans` (piles of sand laid by the host, read by the
/// automaton's start; bare ground of its own albedo) with a small field.
fn small_barchans() -> SceneData {
    let data = small_desert("desert_barchans", "cells = [256, 256], steps = 800", "cells = [32, 32], steps = 60");
    assert_eq!(data.desert.dunes.as_ref().map(|d| d.params.given_start), Some(1));
    data
}

/// Fig. 8(b)'s torus, coarser, turned by a `rotation` (its table held in
/// its own frame: both backends turn exit rays back and forth), its table
/// traced here.
fn turned_torus() -> SceneData {
    let text = std::fs::read_to_string(common::root().join("scenes/caustics_torus.toml")).unwrap();
    let text = text
        .replace("resolution = [640, 480]", "resolution = [160, 120]")
        .replace("segments = [128, 48]", "segments = [64, 24]")
        .replace(
            "material = { kind = \"glass\", ior = 1.5 }",
            "material = { kind = \"glass\", ior = 1.5 }\nrotation = { axis = [1.0, 0.2, 0.0], deg = 35.0 }",
        );
    let mut data = common::scene_from_str(&text);
    data.caustics.forget_cached_table();
    data
}

/// A shipped scene at a smaller resolution, its light transport tables
/// traced here even when the disk cache holds them (so that the table
/// kernel itself is compared).
fn traced(name: &str, width: u32, height: u32) -> SceneData {
    let mut data = sky(name, width, height);
    data.caustics.forget_cached_table();
    data
}

/// A shipped scene at a smaller resolution of the same aspect.
fn sky(name: &str, width: u32, height: u32) -> SceneData {
    let data = slicelight::scene::load(&common::root().join(format!("scenes/{name}.toml"))).unwrap();
    data.reconfigure(move |f| f.camera.resolution = [width, height]).unwrap()
}

/// Every registered pass, on every scene of `family` that runs it: the CPU
/// runs all passes up to and including it; the GPU runs it alone on the
/// CPU's inputs (so this compares the one kernel), and the pass compares
/// the two with the tolerances it states.
fn passes_match_cpu(family: Family) {
    let ctx = device();
    let pb = ProgressBar::hidden();
    let mut scenes_checked = 0;
    for (name, _, make) in scenes().into_iter().filter(|s| s.1 == family) {
        let clock = std::time::Instant::now();
        let data = make();
        let mut cpu_frame = Frame::default();
        for r in PASSES.iter().flat_map(|p| p.reads().iter().chain(p.writes())) {
            if let Some(blank) = r.blank(data.pixel_count() as usize) {
                cpu_frame.insert(r, blank);
            }
        }
        for &pass in PASSES.iter() {
            if !pass.plan(&data).runs {
                continue;
            }
            let inputs = cpu_frame.clone();
            pass.run_cpu(&data, &data.common, &mut cpu_frame, &pb);
            let invocations = match pass.dispatch() {
                Dispatch::Whole => pass.plan(&data).invocations as u32,
                Dispatch::PerPixel => data.pixel_count(),
            };
            let frame = ctx.frame(&data, &[pass], Some(&inputs)).unwrap();
            frame.set_band(0, data.pixel_count(), data.common.sample_index);
            frame.run(&[(pass, invocations)]).unwrap();
            let mut gpu_frame = Frame::default();
            for w in pass.writes() {
                let bytes = cpu_frame.bytes(w).expect("the CPU wrote it").len() as u64;
                gpu_frame.insert(w, frame.read(w, bytes).unwrap());
            }
            match pass.compare(&data, &gpu_frame, &cpu_frame) {
                Ok(line) => println!("{name}: {}: {line}", pass.name()),
                Err(e) => panic!("{name}: {}: GPU and CPU differ: {e:#}", pass.name()),
            }
        }
        println!("{name}: every pass checked in {:.1} s", clock.elapsed().as_secs_f64());
        scenes_checked += 1;
    }
    assert!(scenes_checked > 0, "no scene of {family:?}");
}

#[test]
fn light_and_surface_passes_match_cpu() {
    passes_match_cpu(Family::Lights);
}

#[test]
fn sky_passes_match_cpu() {
    passes_match_cpu(Family::Sky);
}

#[test]
fn sea_passes_match_cpu() {
    passes_match_cpu(Family::Sea);
}

// The glass scenes in two tests (all five took 48 s alone here, most of it
// tracing their light transport tables): the garden's glass under the sky
// and the turned torus; the glass in the sea and the balls under lights.
#[test]
fn glass_passes_match_cpu() {
    passes_match_cpu(Family::Glass);
}

#[test]
fn caustics_passes_match_cpu() {
    passes_match_cpu(Family::Caustics);
}

#[test]
fn volume_passes_match_cpu() {
    passes_match_cpu(Family::Volumes);
}

#[test]
fn desert_passes_match_cpu() {
    passes_match_cpu(Family::Desert);
}

/// Every pass is checked at least once by the tests above, in each of its
/// variants (`Pass::variants`): some scene of theirs plans it.
#[test]
fn every_pass_is_checked_on_some_scene() {
    let mut checked = std::collections::HashSet::new();
    for (_, _, make) in scenes() {
        let data = make();
        checked.extend(PASSES.iter().filter(|p| p.plan(&data).runs).map(|p| p.kernel_for(&data)));
    }
    for p in PASSES.iter() {
        for kernel in std::iter::once(p.kernel()).chain(p.variants().iter().copied()) {
            assert!(checked.contains(kernel), "pass {}: entry point {kernel} was not checked on any scene", p.name());
        }
    }
}

/// A scene pays only for the kernels it runs: the GPU backend builds a
/// pipeline the first time a frame needs it (all of them took 0.94 s on
/// lavapipe; Fig. 6 needs three).
#[test]
fn a_render_builds_only_the_kernels_its_scene_runs() {
    let gpu = render::Backend::Gpu(Box::new(device()));
    let data = fog_spot();
    render::render(&data, &gpu, false).unwrap();
    let render::Backend::Gpu(ctx) = &gpu else { unreachable!() };
    let mut built = ctx.built_kernels();
    built.sort();
    let mut runs: Vec<_> = PASSES.iter().filter(|p| p.plan(&data).runs).map(|p| p.kernel_for(&data)).collect();
    runs.sort();
    assert_eq!(built, runs);
    // Not every kernel: the scene has no glass, sky or sea.
    assert!(built.len() < PASSES.len());
}

#[test]
fn whole_render_matches_cpu() {
    // End to end through the pass plan on both backends, as the CLI runs it,
    // with 4 sub-pixel samples (the sample loop and the box filter).
    let ctx = device();
    let data = fog_spot().reconfigure(|f| f.camera.samples_per_pixel = 4).unwrap();
    let (cpu_img, _) = render::render(&data, &render::Backend::Cpu, false).unwrap();
    let gpu = render::Backend::Gpu(Box::new(ctx));
    let (gpu_img, stats) = render::render(&data, &gpu, false).unwrap();
    assert_eq!(stats.backend, "gpu");
    println!(
        "pass timing: {}; {:?}",
        stats.pass_timing,
        stats.passes.iter().map(|p| (p.name, p.seconds)).collect::<Vec<_>>()
    );
    let d = slicelight::metrics::difference(
        &slicelight::metrics::to_f64(&gpu_img),
        &slicelight::metrics::to_f64(&cpu_img),
        data.exposure,
    );
    println!("whole render, gpu vs cpu: {d:?}");
    // Shadow-map flips move single pixels; over the image they stay far below
    // one 8-bit step (0.39 %) in RMS.
    assert!(d.rms_8bit_percent < 0.05, "{d:?}");
    assert!(d.rms_relative < 1e-4, "{d:?}");
}

#[test]
fn banded_render_matches_cpu() {
    // Images larger than one device buffer are rendered in bands of whole
    // rows. Force bands of 37 rows (an uneven split of 480) and compare with
    // the CPU, which renders the image whole.
    let mut ctx = device();
    let data = fog_spot();
    ctx.limit_band_bytes(37 * data.width() as u64 * 32);
    assert_eq!(ctx.band_pixels(&data), 37 * data.width());
    let (cpu_img, _) = render::render(&data, &render::Backend::Cpu, false).unwrap();
    let (gpu_img, _) = render::render(&data, &render::Backend::Gpu(Box::new(ctx)), false).unwrap();
    let d = slicelight::metrics::difference(
        &slicelight::metrics::to_f64(&gpu_img),
        &slicelight::metrics::to_f64(&cpu_img),
        data.exposure,
    );
    println!("banded render, gpu vs cpu: {d:?}");
    // As for the whole render: a band in the wrong place would be off by
    // whole rows of radiance, orders of magnitude above this.
    assert!(d.rms_relative < 1e-4, "{d:?}");
}

#[test]
fn scatter_self_check_passes_on_the_device() {
    // Through the renderer, as `render --pass scatter_check` runs it.
    let ctx = device();
    let mut data = fog_spot();
    data.requested_passes.push("scatter_check".into());
    // A failed check is the render's error.
    let (_, stats) = render::render(&data, &render::Backend::Gpu(Box::new(ctx)), false).expect("the check passes");
    let check = stats.passes.iter().find(|p| p.name == "scatter_check").unwrap();
    println!("{:?}", check.report);
    assert!(check.ran && check.report.is_some());
}

/// The dunes' automaton run by the renderer on the device (`render --pass
/// desert.dunes`) ends with the heights the CPU built at load, bit for bit.
#[test]
fn dunes_self_check_passes_on_the_device() {
    let ctx = device();
    let data = small_dunes();
    let (_, stats) = render::render(&data, &render::Backend::Gpu(Box::new(ctx)), false).expect("the check passes");
    let check = stats.passes.iter().find(|p| p.name == "desert.dunes").unwrap();
    println!("{:?}", check.report);
    assert!(check.ran && check.report.as_deref().is_some_and(|r| r.contains("equal the load's")));
}

/// The largest difference between two fields, relative to the larger
/// field's largest magnitude (0 when both are 0).
fn relative_difference(a: &[f32], b: &[f32]) -> f64 {
    let scale = a.iter().chain(b).fold(0.0f64, |m, x| m.max(x.abs() as f64));
    let diff = a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs() as f64));
    if scale == 0.0 {
        diff
    } else {
        diff / scale
    }
}

/// A fluid configured from a `smoke = { ... }` body over a box of 10 cm cells.
fn fluid_config(name: &str, body: &str) -> slicelight::smoke::Config {
    let s: slicelight::smoke::Settings = toml::from_str(body).unwrap_or_else(|e| panic!("{name}: {e}"));
    let hi = glam::UVec3::from(s.cells).as_vec3() * 0.1;
    slicelight::smoke::configure("volume[0]", &s, glam::Vec3::ZERO, hi).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The largest difference between two fluid states over their fields, each
/// relative to its largest magnitude (the temperature's above the
/// ambient, not above 0 K), with the field's name.
fn state_difference(a: &slicelight::smoke::Fluid, b: &slicelight::smoke::Fluid) -> (f64, &'static str) {
    let ambient = a.params.ambient;
    let above = |v: &[f32]| v.iter().map(|t| t - ambient).collect::<Vec<_>>();
    [
        ("u", relative_difference(&a.u, &b.u)),
        ("v", relative_difference(&a.v, &b.v)),
        ("w", relative_difference(&a.w, &b.w)),
        ("temperature", relative_difference(&above(&a.temperature), &above(&b.temperature))),
        ("smoke", relative_difference(&a.smoke, &b.smoke)),
    ]
    .into_iter()
    .fold((0.0, "none"), |m, (name, d)| if d > m.0 { (d, name) } else { m })
}

/// The puffs' largest distance between two states, in cells.
fn puff_distance(a: &slicelight::smoke::Fluid, b: &slicelight::smoke::Fluid) -> f32 {
    assert_eq!(a.puffs.len(), b.puffs.len(), "puff counts");
    a.puffs.iter().zip(&b.puffs).fold(0.0f32, |m, (p, q)| m.max((p.position - q.position).length() / a.params.h))
}

/// How the two backends' fluids compare over a run (`compare_fluid`).
struct Agreement {
    /// Lockstep: each step taken by the device from the CPU's state before
    /// it; the worst difference from the CPU's own step over the run.
    one_step: f64,
    one_step_field: &'static str,
    /// The puffs' worst lockstep distance, cells.
    one_step_puffs: f32,
    /// Free-running: the device's own state stepped from the start, and
    /// the CPU's, compared at the end (reported, not bounded: see
    /// `assert_agreement`).
    free: f64,
    free_field: &'static str,
    /// The flow's own amplification of rounding: the CPU against itself
    /// with one ulp of noise added to every value after each step, compared
    /// at the end.
    noise_drift: f64,
    /// Restarts: values (fields, `phi`, puffs) of the device's free-running
    /// steps that differ in their bits from the same step taken by a fresh
    /// device fluid uploaded from the state read back before it.
    restart_differences: usize,
}

/// Steps `c` (solid cells `cells`) `steps` times on the CPU and on `ctx`,
/// both lockstep and free-running; `check(step, cpu, device)` sees each
/// lockstep pair.
fn compare_fluid(
    ctx: &GpuContext,
    name: &str,
    c: &slicelight::smoke::Config,
    cells: Vec<u32>,
    steps: u32,
    mut check: impl FnMut(u32, &slicelight::smoke::Fluid, &slicelight::smoke::Fluid),
) -> Agreement {
    let fail = |step: u32| move |e: anyhow::Error| -> ! { panic!("{name}: step {step}: {e:#}") };
    let start = c.start(cells);
    let mut noisy = start.clone();
    let mut cpu = start.clone();
    let mut free = start.clone();
    let mut on_device = GpuFluid::new(ctx, &free).unwrap_or_else(|e| fail(0)(e));
    let mut agreement = Agreement {
        one_step: 0.0,
        one_step_field: "none",
        one_step_puffs: 0.0,
        free: 0.0,
        free_field: "none",
        noise_drift: 0.0,
        restart_differences: 0,
    };
    for step in 0..steps {
        let mut lock = cpu.clone();
        let mut device = GpuFluid::new(ctx, &lock).unwrap_or_else(|e| fail(step)(e));
        device.step(&mut lock).unwrap_or_else(|e| fail(step)(e));
        device.download(&mut lock).unwrap_or_else(|e| fail(step)(e));
        cpu.step();
        noisy.step();
        add_an_ulp(&mut noisy, step);
        // The device's own step, and the same step from its state read
        // back and uploaded again.
        on_device.download(&mut free).unwrap_or_else(|e| fail(step)(e));
        let mut restarted = free.clone();
        let mut fresh = GpuFluid::new(ctx, &restarted).unwrap_or_else(|e| fail(step)(e));
        fresh.step(&mut restarted).unwrap_or_else(|e| fail(step)(e));
        fresh.download(&mut restarted).unwrap_or_else(|e| fail(step)(e));
        on_device.step(&mut free).unwrap_or_else(|e| fail(step)(e));
        on_device.download(&mut free).unwrap_or_else(|e| fail(step)(e));
        agreement.restart_differences += bit_differences(&free, &restarted);
        check(step, &cpu, &lock);
        let (d, field) = state_difference(&cpu, &lock);
        if d > agreement.one_step {
            (agreement.one_step, agreement.one_step_field) = (d, field);
        }
        agreement.one_step_puffs = agreement.one_step_puffs.max(puff_distance(&cpu, &lock));
    }
    (agreement.free, agreement.free_field) = state_difference(&cpu, &free);
    agreement.noise_drift = state_difference(&cpu, &noisy).0;
    println!(
        "{name}: {steps} steps: lockstep worst {:.2e} ({}), puffs {:.1e} cells; restarts: {} values differ; free-running {:.2e} ({}), the CPU against itself with an ulp of noise per step {:.2e}",
        agreement.one_step,
        agreement.one_step_field,
        agreement.one_step_puffs,
        agreement.restart_differences,
        agreement.free,
        agreement.free_field,
        agreement.noise_drift
    );
    agreement
}

/// The values (fields, `phi`, puffs' positions) whose bits differ.
fn bit_differences(a: &slicelight::smoke::Fluid, b: &slicelight::smoke::Fluid) -> usize {
    let fields = [
        (&a.u, &b.u),
        (&a.v, &b.v),
        (&a.w, &b.w),
        (&a.temperature, &b.temperature),
        (&a.smoke, &b.smoke),
        (&a.phi, &b.phi),
    ];
    let values = fields
        .iter()
        .map(|(x, y)| x.iter().zip(y.iter()).filter(|(p, q)| p.to_bits() != q.to_bits()).count())
        .sum::<usize>();
    let puffs = a
        .puffs
        .iter()
        .zip(&b.puffs)
        .filter(|(p, q)| p.position.to_array().map(f32::to_bits) != q.position.to_array().map(f32::to_bits))
        .count();
    values + puffs + a.puffs.len().abs_diff(b.puffs.len())
}

/// One ulp up or down (a counter hash of value, field and step) on every
/// nonzero value of the state's fields: rounding-sized noise.
fn add_an_ulp(f: &mut slicelight::smoke::Fluid, step: u32) {
    for (k, field) in [&mut f.u, &mut f.v, &mut f.w, &mut f.temperature, &mut f.smoke].into_iter().enumerate() {
        for (i, x) in field.iter_mut().enumerate() {
            if *x != 0.0 && x.is_finite() {
                let up = slicelight::shaders::random::random(i as u32, step, k as u32, 3) & 1 == 0;
                *x = f32::from_bits(if up { x.to_bits() + 1 } else { x.to_bits() - 1 });
            }
        }
    }
}

/// What `compare_fluid` must find, and why.
///
/// Bit identity is not expected: both backends run the same f32 functions
/// in the same order, and the conjugate gradients take their scalars from
/// the same partial sums, but a device may contract `a * b + c` into one
/// fused multiply-add (rounded once, not twice) and use its own `exp` and
/// division (Vulkan allows a few ulp), and the solver's stop on the
/// measured residual (divergence 1e-6 of the speed per cell) turns such
/// last-bit differences into an iteration more or less now and then.
/// - **Lockstep**, each step from the same state: within 1e-4 of each
///   field's largest magnitude, puffs within 1e-3 cells. A wrong stage (a
///   missing source, a swapped binding) differs at order 1 in one step.
///   Measured: lavapipe 0 to 2e-7; an NVIDIA H200 (driver 580.159)
///   2.5e-7 to 2.4e-6.
/// - **Restarts**, bit for bit: each of the device's free-running steps
///   equals the same step taken by a fresh device fluid uploaded from the
///   state read back before it. The device is deterministic
///   (`fluid_steps_repeat_bit_for_bit_on_the_device`), so any difference
///   is state the device carries between steps that the host's `Fluid`
///   does not hold (a field left stale, a solver guess not read back): what
///   a restart from a cached state would lose.
/// - **Free-running**, each backend from the start on its own, is
///   reported, not bounded: the differences each step leaves are carried
///   on and amplified by the flow itself. The CPU shows as much against
///   itself: with one ulp of noise added to every value after each step,
///   the MacCormack plume (turbulence, the limiter's switches) drifts
///   1.6e-2 in 40 steps, the closed box 1e-5, the one-cell-thick grid
///   1.4e-3 in 20. A device's differences are not white noise but smooth
///   and systematic (fused multiply-adds, its own `exp`), and they sit
///   in the flow's growing modes: on the H200 the MacCormack plume drifts
///   1.6e-2, the closed box 3.8e-4, the thin grid 2.2e-4; lavapipe, whose
///   arithmetic matches the CPU's, 2.3e-6 at most. Lockstep and restarts
///   together cover what a bound on the drift would: every step's
///   arithmetic, and every step's dependence on the state alone.
fn assert_agreement(name: &str, a: &Agreement) {
    assert!(a.one_step <= 1e-4, "{name}: lockstep: {} differs by {:.3e}", a.one_step_field, a.one_step);
    assert!(a.one_step_puffs <= 1e-3, "{name}: lockstep: puffs {} cells apart", a.one_step_puffs);
    assert_eq!(a.restart_differences, 0, "{name}: restarts: values whose bits differ from a restarted device's step");
}

#[test]
fn fluid_steps_match_cpu() {
    let ctx = device();
    let plume = "cells = [20, 16, 12]\ndt = 0.05\nturbulence = 2.0\ntemperature_noise = 20.0\neddy_diffusivity = 0.01\neddy_viscosity = 0.005\nwind = [0.5, 0.0, 0.0]\n[[source]]\nposition = [0.5, 0.2, 0.6]\nradius = 0.15\nrate = 8.0\ntemperature = 600.0\nvelocity = [0.0, 1.0, 0.0]";
    let cases = [
        ("plume, MacCormack", format!("advection = \"maccormack\"\n{plume}"), true),
        ("plume, semi-Lagrangian", format!("advection = \"semi-lagrangian\"\n{plume}"), true),
        ("closed box", "cells = [12, 12, 12]\ndt = 0.05\nwalls = \"closed\"\n[[source]]\nposition = [0.6, 0.2, 0.6]\nradius = 0.2\nrate = 4.0\ntemperature = 500.0".to_string(), false),
    ];
    for (name, body, obstacle) in cases {
        let c = fluid_config(name, &body);
        let n = c.params.dims();
        let mut cells = vec![1u32; c.params.cells as usize];
        if obstacle {
            // A block downwind of the source.
            for (i, f) in cells.iter_mut().enumerate() {
                let x = slicelight::shaders::smoke::coords(n, i as u32);
                if (10..14).contains(&x.x) && x.y < 8 && (3..9).contains(&x.z) {
                    *f = 0;
                }
            }
        }
        let agreement = compare_fluid(&ctx, name, &c, cells, 40, |step, cpu, gpu| {
            assert!(
                cpu.last.divergence <= 1e-5 && gpu.last.divergence <= 1e-5,
                "{name}: step {step}: {:?} {:?}",
                cpu.last,
                gpu.last
            );
        });
        assert_agreement(name, &agreement);
    }
}

/// The device runs its fluid deterministically: the same step from the
/// same state twice gives the same bits (a race between invocations, or
/// an unordered float atomic, would not).
#[test]
fn fluid_steps_repeat_bit_for_bit_on_the_device() {
    let ctx = device();
    let body = "advection = \"maccormack\"\ncells = [20, 16, 12]\ndt = 0.05\nturbulence = 2.0\ntemperature_noise = 20.0\neddy_diffusivity = 0.01\neddy_viscosity = 0.005\nwind = [0.5, 0.0, 0.0]\n[[source]]\nposition = [0.5, 0.2, 0.6]\nradius = 0.15\nrate = 8.0\ntemperature = 600.0\nvelocity = [0.0, 1.0, 0.0]";
    let c = fluid_config("plume", body);
    let mut state = c.start(vec![1; c.params.cells as usize]);
    for _ in 0..10 {
        state.step();
    }
    let run = |steps: u32| {
        let mut f = state.clone();
        let mut d = GpuFluid::new(&ctx, &f).unwrap_or_else(|e| panic!("{e:#}"));
        for _ in 0..steps {
            d.step(&mut f).unwrap_or_else(|e| panic!("{e:#}"));
        }
        d.download(&mut f).unwrap_or_else(|e| panic!("{e:#}"));
        f
    };
    let (a, b) = (run(5), run(5));
    assert_eq!(bit_differences(&a, &b), 0, "values (fields, phi, puffs) whose bits differ between two runs");
    println!("5 steps twice from the same state: every field and puff the same bits");
}

/// The fluid's kernels at the edges of their parameters, on the device:
/// `dt` 100 times the CFL limit with a 10^4 K source, and a grid one cell
/// thick. Every value stays finite, every projection converges to the 1e-5
/// divergence target, and the fields agree as `assert_agreement` asks.
#[test]
fn fluid_kernels_hold_at_large_steps_and_thin_grids() {
    let ctx = device();
    let cases = [
        "cells = [16, 16, 16]\ndt = 2.0\n[[source]]\nposition = [0.8, 0.3, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 10000.0\nvelocity = [0.0, 3.0, 0.0]",
        "cells = [16, 1, 16]\ndt = 0.05\n[[source]]\nposition = [0.8, 0.05, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 600.0",
    ];
    for body in cases {
        let c = fluid_config(body, body);
        let cells = vec![1; c.params.cells as usize];
        let name = body.lines().take(2).collect::<Vec<_>>().join(", ");
        let agreement = compare_fluid(&ctx, &name, &c, cells, 20, |step, _, gpu| {
            assert!(gpu.last.solve.converged && gpu.last.divergence <= 1e-5, "{name}: step {step}: {:?}", gpu.last);
            for field in [&gpu.u, &gpu.v, &gpu.w, &gpu.temperature, &gpu.smoke] {
                assert!(field.iter().all(|x| x.is_finite()), "{name}: step {step}: a value not finite");
            }
        });
        assert_agreement(&name, &agreement);
    }
}
