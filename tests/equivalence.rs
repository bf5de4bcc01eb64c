//! GPU-vs-CPU equivalence: every kernel, run as SPIR-V on a Vulkan device and
//! as the same Rust function on the CPU, on identical inputs.
//!
//! These tests need a Vulkan device (lavapipe is enough: `scripts/setup.sh`
//! installs it). Without one they fail; they never skip.

mod common;

use glam::Vec4;
use indicatif::ProgressBar;
use slicelight::gpu::GpuContext;
use slicelight::scene::SceneData;
use slicelight::{cpu, render};

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
fn window_scene() -> SceneData {
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
    slicelight::scene::load(&path).unwrap()
}

/// Counts values whose difference exceeds `tol(cpu)`, and returns the largest
/// difference among the rest.
fn compare(gpu: &[f32], cpu: &[f32], tol: impl Fn(f32) -> f32) -> (usize, f32) {
    assert_eq!(gpu.len(), cpu.len());
    let mut outliers = 0;
    let mut worst = 0.0f32;
    for (&g, &c) in gpu.iter().zip(cpu) {
        let d = (g - c).abs();
        if d.is_nan() || d > tol(c) {
            outliers += 1;
        } else {
            worst = worst.max(d);
        }
    }
    (outliers, worst)
}

fn check_shadow_maps(ctx: &GpuContext, data: &SceneData) {
    let cpu_maps = cpu::shadow_maps(data, &ProgressBar::hidden());
    let frame = ctx.upload(data, None).unwrap();
    frame.run("shadow_map_kernel", data.params.shadow_texel_count).unwrap();
    let gpu_maps = frame.read_shadow(cpu_maps.len()).unwrap();
    // A depth is one ray-surface intersection in f32. The GPU may fuse
    // multiply-adds and round sqrt differently, so depths agree to a few ulps
    // of the operands (1e-5 relative leaves a 10x margin over the worst seen).
    // A texel whose ray grazes a silhouette can hit on one backend and miss on
    // the other: such flips are allowed on at most 1e-4 of the texels.
    let (outliers, worst) = compare(&gpu_maps, &cpu_maps, |c| 1e-5 * c.abs().max(1.0));
    let allowed = cpu_maps.len() / 10_000 + 1;
    println!("shadow maps: {} texels, {outliers} silhouette flips, worst other difference {worst:e} m", cpu_maps.len());
    assert!(outliers <= allowed, "{outliers} of {} shadow texels differ (allowed {allowed})", cpu_maps.len());
}

fn check_surface(ctx: &GpuContext, data: &SceneData) {
    // Both backends shade from the same (CPU-built) shadow maps, so this
    // compares the surface kernel alone.
    let shadow = cpu::shadow_maps(data, &ProgressBar::hidden());
    let cpu_img = cpu::surface(data, &shadow, &ProgressBar::hidden());
    let frame = ctx.upload(data, Some(&shadow)).unwrap();
    frame.run("surface_kernel", data.pixel_count()).unwrap();
    let gpu_img = frame.read_image(cpu_img.len()).unwrap();
    let flat = |img: &[Vec4]| img.iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>();
    let peak = cpu_img.iter().map(|p| p.truncate().max_element()).fold(0.0, f32::max);
    // Radiance is a product of about 20 f32 factors (exp, sqrt, dot products):
    // 1e-5 of the image's peak is ~100 ulps of the largest value. Hit
    // distances (w) agree like the shadow depths. A pixel can flip where its
    // ray grazes a silhouette or its shadow test sits on the bias threshold:
    // at most 1e-3 of the values may.
    let (outliers, worst) = compare(&flat(&gpu_img), &flat(&cpu_img), |c| {
        if c > 1e30 {
            0.0
        } else {
            1e-5 * peak.max(c.abs())
        }
    });
    let allowed = cpu_img.len() * 4 / 1000 + 1;
    println!("surface: {} pixels, {outliers} flipped values, worst other difference {worst:e} (peak {peak:e})", cpu_img.len());
    assert!(outliers <= allowed, "{outliers} of {} pixel values differ (allowed {allowed})", cpu_img.len() * 4);
}

fn check_shafts(ctx: &GpuContext, data: &SceneData) {
    // Same shadow maps and same surface image (with its hit distances) on
    // both backends: this compares the shafts kernel alone.
    let pb = ProgressBar::hidden();
    let shadow = cpu::shadow_maps(data, &pb);
    let surface = cpu::surface(data, &shadow, &pb);
    let mut cpu_img = surface.clone();
    cpu::shafts(data, &shadow, &mut cpu_img, &pb);
    let frame = ctx.upload(data, Some(&shadow)).unwrap();
    frame.write_image(&surface);
    frame.run("shafts_kernel", data.pixel_count()).unwrap();
    let gpu_img = frame.read_image(cpu_img.len()).unwrap();
    let rgb = |img: &[Vec4]| img.iter().flat_map(|p| p.truncate().to_array()).collect::<Vec<f32>>();
    let peak = cpu_img.iter().map(|p| p.truncate().max_element()).fold(0.0, f32::max);
    // In-scattered radiance is a sum over up to planes x sub-planes x lights
    // terms, each a product like the surface's, plus (tables mode) an acos,
    // which Vulkan lets a device compute to 4096 ulps, ahead of a table
    // interpolation. Measured on lavapipe: worst 1.1e-5 of the peak in exact
    // mode, 1.6e-5 with tables; the bound is 3e-5. A sub-plane sample can
    // flip where its shadow test or cone test sits on a threshold (a plane
    // boundary rounded differently moves it): at most 1e-3 of the values may.
    let (outliers, worst) = compare(&rgb(&gpu_img), &rgb(&cpu_img), |c| 3e-5 * peak.max(c.abs()));
    let allowed = cpu_img.len() * 3 / 1000 + 1;
    println!(
        "shafts ({:?}): {} pixels, {outliers} flipped values, worst other difference {worst:e} (peak {peak:e})",
        data.shafts.mode,
        cpu_img.len()
    );
    let worst_rel = rgb(&gpu_img).iter().zip(rgb(&cpu_img)).map(|(g, c)| (g - c).abs() / peak).fold(0.0, f32::max);
    println!("worst difference / peak: {worst_rel:e}");
    assert!(outliers <= allowed, "{outliers} of {} pixel values differ (allowed {allowed})", cpu_img.len() * 3);
    // The sample counts (w) are integers; a flipped clip bound may move one
    // interval's sub-planes in or out of a pixel's count.
    let counts_differ = gpu_img.iter().zip(&cpu_img).filter(|(g, c)| g.w != c.w).count();
    assert!(counts_differ <= allowed, "{counts_differ} sample counts differ");
}

#[test]
fn shafts_kernel_matches_cpu() {
    let ctx = device();
    let mut data = fog_spot();
    check_shafts(&ctx, &data);
    let mut s = data.shafts;
    s.mode = slicelight::scene::ShaftMode::Tables;
    s.jitter = false;
    data.configure_shafts(s).unwrap();
    check_shafts(&ctx, &data);
    check_shafts(&ctx, &window_scene());
}

#[test]
fn shadow_map_kernel_matches_cpu() {
    let ctx = device();
    check_shadow_maps(&ctx, &fog_spot());
    check_shadow_maps(&ctx, &window_scene());
}

#[test]
fn surface_kernel_matches_cpu() {
    let ctx = device();
    check_surface(&ctx, &fog_spot());
    check_surface(&ctx, &window_scene());
}

#[test]
fn whole_render_matches_cpu() {
    // End to end through the pass plan on both backends, as the CLI runs it.
    let ctx = device();
    let data = fog_spot();
    let (cpu_img, _) = render::render(&data, &render::Backend::Cpu, false).unwrap();
    let gpu = render::Backend::Gpu(Box::new(ctx));
    let (gpu_img, stats) = render::render(&data, &gpu, false).unwrap();
    assert_eq!(stats.backend, "gpu");
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
    ctx.limit_band_bytes(37 * data.width() as u64 * 16);
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
