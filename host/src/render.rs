//! The pass plan and the renderer: which passes a scene needs, run on the
//! chosen backend, with each pass's time.

use anyhow::Result;
use glam::Vec4;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::time::Instant;

use crate::cpu;
use crate::gpu::GpuContext;
use crate::scene::SceneData;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// The SPIR-V kernels on a Vulkan device through wgpu.
    Gpu,
    /// The same kernel functions on the CPU (rayon).
    Cpu,
    /// A Vulkan device if wgpu finds one, otherwise the CPU.
    Auto,
}

pub enum Backend {
    Cpu,
    Gpu(Box<GpuContext>),
}

impl Backend {
    /// Opens the chosen backend. `Gpu` fails if there is no device; `Auto`
    /// falls back to the CPU and says so on stderr.
    pub fn open(choice: BackendChoice) -> Result<Backend> {
        match choice {
            BackendChoice::Cpu => Ok(Backend::Cpu),
            BackendChoice::Gpu => Ok(Backend::Gpu(Box::new(GpuContext::new()?))),
            BackendChoice::Auto => match GpuContext::new() {
                Ok(ctx) => Ok(Backend::Gpu(Box::new(ctx))),
                Err(e) => {
                    eprintln!("slicelight: using the CPU backend: {e:#}");
                    Ok(Backend::Cpu)
                }
            },
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu(_) => "gpu",
        }
    }

    pub fn device(&self) -> String {
        match self {
            Backend::Cpu => format!("CPU ({} threads, rayon)", rayon::current_num_threads()),
            Backend::Gpu(ctx) => ctx.device_name(),
        }
    }
}

/// One pass of the plan: whether it runs, why, and how long it took.
#[derive(Debug, Clone, Serialize)]
pub struct PassStats {
    pub name: &'static str,
    pub ran: bool,
    /// Why it runs or why it was skipped.
    pub reason: String,
    /// Kernel invocations (0 when skipped).
    pub invocations: u64,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct RenderStats {
    pub backend: &'static str,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub passes: Vec<PassStats>,
    /// Wall time of all passes, including uploads and read-back on the GPU.
    pub total_seconds: f64,
    /// `H I_l` samples the shafts pass evaluated, and the naive count
    /// `pixels x planes x sub-planes x lights` without clipping or culling.
    pub shaft_samples: u64,
    pub shaft_samples_naive: u64,
}

/// What the scene needs, decided before anything runs.
pub fn plan(data: &SceneData) -> Vec<PassStats> {
    let pass = |name, ran: bool, reason: String, invocations: u32| PassStats {
        name,
        ran,
        reason,
        invocations: if ran { invocations as u64 } else { 0 },
        seconds: 0.0,
    };
    let shadow_texels = data.params.shadow_texel_count;
    let lights = data.lights.len();
    let shadow_reason = if lights == 0 {
        "no lights".to_string()
    } else if !data.has_geometry() {
        "no geometry to cast shadows".to_string()
    } else {
        format!("{lights} light(s), {} shadow-map texels", shadow_texels)
    };
    let visible = data.lights.iter().filter(|l| l.in_view != 0).count();
    let (shafts_run, shafts_reason) = if !data.scatters() {
        (false, "the medium does not scatter (sigma_s = 0)".to_string())
    } else if visible == 0 {
        (false, format!("no light's volume is in view ({lights} light(s))"))
    } else {
        let s = &data.shafts;
        (
            true,
            format!(
                "{visible} of {lights} light(s) in view, {} planes x {} sub-planes, {:?} mode",
                s.planes, s.subplanes, s.mode
            ),
        )
    };
    vec![
        pass("shadow_maps", shadow_texels > 0, shadow_reason, shadow_texels),
        pass(
            "surface",
            data.has_geometry(),
            if data.has_geometry() { "surfaces seen through the medium (eq. 1, first term)".into() } else { "no geometry".into() },
            data.pixel_count(),
        ),
        pass("shafts", shafts_run, shafts_reason, data.pixel_count()),
    ]
}

/// A pixel whose view ray meets no surface.
pub fn no_surface() -> Vec4 {
    Vec4::new(0.0, 0.0, 0.0, slicelight_shaders::surface::MISS_DISTANCE)
}

fn progress_bar(total: u64) -> ProgressBar {
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template("{msg:>12} [{elapsed_precise}] {wide_bar} {percent}%")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb
}

/// Renders a scene: rgb radiance per pixel (W/(m^2 sr)), w = hit distance.
pub fn render(data: &SceneData, backend: &Backend, show_progress: bool) -> Result<(Vec<Vec4>, RenderStats)> {
    let mut passes = plan(data);
    let total: u64 = passes.iter().map(|p| p.invocations).sum();
    let pb = if show_progress { progress_bar(total) } else { ProgressBar::hidden() };
    let start = Instant::now();
    let pixels = data.pixel_count() as usize;
    let image = match backend {
        Backend::Cpu => {
            let mut shadow = Vec::new();
            let mut image = vec![no_surface(); pixels];
            for pass in passes.iter_mut().filter(|p| p.ran) {
                pb.set_message(pass.name);
                let t = Instant::now();
                match pass.name {
                    "shadow_maps" => shadow = cpu::shadow_maps(data, &pb),
                    "surface" => image = cpu::surface(data, &shadow, &pb),
                    "shafts" => cpu::shafts(data, &shadow, &mut image, &pb),
                    other => unreachable!("pass {other} has no CPU path"),
                }
                pass.seconds = t.elapsed().as_secs_f64();
            }
            image
        }
        Backend::Gpu(ctx) => {
            let frame = ctx.upload(data, None)?;
            let entry = |name: &str| match name {
                "shadow_maps" => "shadow_map_kernel",
                "surface" => "surface_kernel",
                "shafts" => "shafts_kernel",
                other => unreachable!("pass {other} has no GPU kernel"),
            };
            // Shadow maps once; the image passes band by band when the image
            // is larger than one device buffer.
            for pass in passes.iter_mut().filter(|p| p.ran && p.name == "shadow_maps") {
                pb.set_message(pass.name);
                let t = Instant::now();
                frame.run(entry(pass.name), pass.invocations as u32)?;
                pass.seconds = t.elapsed().as_secs_f64();
                pb.inc(pass.invocations);
            }
            let band = ctx.band_pixels(data);
            let mut image = Vec::with_capacity(pixels);
            let mut start = 0;
            while start < data.pixel_count() {
                let count = band.min(data.pixel_count() - start);
                // `upload` set up the first band. Uploads and read-back count
                // in the total time, not in a pass's.
                if start > 0 {
                    frame.set_band(data, start, count);
                }
                for pass in passes.iter_mut().filter(|p| p.ran && p.name != "shadow_maps") {
                    pb.set_message(pass.name);
                    let t = Instant::now();
                    frame.run(entry(pass.name), count)?;
                    pass.seconds += t.elapsed().as_secs_f64();
                    pb.inc(count as u64);
                }
                image.extend(frame.read_image(count as usize)?);
                start += count;
            }
            image
        }
    };
    pb.finish_and_clear();
    let shafts_ran = passes.iter().any(|p| p.name == "shafts" && p.ran);
    let shaft_samples = if shafts_ran { image.iter().map(|p| p.w as u64).sum() } else { 0 };
    let s = &data.shafts;
    let shaft_samples_naive = if shafts_ran {
        data.pixel_count() as u64 * s.planes as u64 * s.subplanes as u64 * data.lights.len() as u64
    } else {
        0
    };
    let stats = RenderStats {
        shaft_samples,
        shaft_samples_naive,
        backend: backend.name(),
        device: backend.device(),
        width: data.width(),
        height: data.height(),
        passes,
        total_seconds: start.elapsed().as_secs_f64(),
    };
    Ok((image, stats))
}
