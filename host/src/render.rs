//! The renderer: walks the registered passes (`passes::PASSES`), runs those
//! the scene needs on the chosen backend, and sums their radiance layers
//! into the image, over the sub-pixel samples.
//!
//! Order: every `Whole` pass runs once, first (shadow maps, and later maps
//! and tables that do not depend on the pixel); then, for each band of rows
//! and each sub-pixel sample, the `PerPixel` passes in registration order.
//! A `Whole` pass therefore never reads a per-pixel resource.

use anyhow::Result;
use glam::Vec4;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

use crate::gpu::GpuContext;
use crate::passes::{Buffer, Dispatch, Frame, Pass, Plan, Resource, ResourceKind, PASSES};
use crate::scene::SceneData;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// The SPIR-V kernels on a Vulkan device through wgpu.
    Gpu,
    /// The same kernel functions on the CPU (rayon).
    Cpu,
    /// A Vulkan device if wgpu finds one that is not itself the CPU
    /// (lavapipe), otherwise the CPU backend.
    Auto,
}

/// Where the simulations a scene runs at load step (a smoke volume's
/// fluid): the CPU unless the caller chose otherwise. The CLI passes its
/// `--backend` before it loads a scene (`simulate_on`).
static SIMULATION_BACKEND: std::sync::Mutex<BackendChoice> = std::sync::Mutex::new(BackendChoice::Cpu);

/// Chooses where simulations step: a device's kernels, their CPU twins,
/// or `auto` (the family decides which is faster for its device).
pub fn simulate_on(choice: BackendChoice) {
    if let Ok(mut s) = SIMULATION_BACKEND.lock() {
        *s = choice;
    }
}

/// See `simulate_on`.
pub fn simulation_backend() -> BackendChoice {
    SIMULATION_BACKEND.lock().map(|c| *c).unwrap_or(BackendChoice::Cpu)
}

pub enum Backend {
    Cpu,
    Gpu(Box<GpuContext>),
}

impl Backend {
    /// Opens the chosen backend. `Gpu` fails if there is no device; `Auto`
    /// falls back to the CPU and says so on stderr, also where the device
    /// is Vulkan on the CPU (lavapipe): the same kernels run faster on the
    /// CPU backend there (2026-12-07, 720x480 on two cores: `fig7_stage`
    /// 0.09 s against 0.49 s, `caustics_fog_ball` 0.56 against 1.84,
    /// `sea_diver` 0.43 against 2.35, `sky_sunset` 0.052 against 0.068).
    pub fn open(choice: BackendChoice) -> Result<Backend> {
        match choice {
            BackendChoice::Cpu => Ok(Backend::Cpu),
            BackendChoice::Gpu => Ok(Backend::Gpu(Box::new(GpuContext::new()?))),
            BackendChoice::Auto => match GpuContext::new() {
                Ok(ctx) if ctx.runs_on_the_cpu() => {
                    eprintln!(
                        "slicelight: using the CPU backend: the Vulkan device, {}, runs on the CPU, slower than the CPU backend (--backend gpu to use it)",
                        ctx.device_name()
                    );
                    Ok(Backend::Cpu)
                }
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
    /// Time in the pass's kernels (GPU: device timestamps where the device
    /// has them, see `RenderStats::pass_timing`).
    pub seconds: f64,
    /// What the pass reported (a self-check's verdict).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<String>,
    /// Its outputs were taken from an earlier render (`Memo`), not computed.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub kept: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct RenderStats {
    pub backend: &'static str,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub samples_per_pixel: u32,
    pub passes: Vec<PassStats>,
    /// How pass times were taken: `device timestamps`, `wall clock per
    /// submission` or `wall clock` (CPU).
    pub pass_timing: &'static str,
    /// Wall time of the whole render, including uploads and read-back on the GPU.
    pub total_seconds: f64,
    /// Wall time spent before the render building the GPU pipelines of the
    /// kernels it runs that were not built yet (a backend reused for later
    /// renders builds each once); 0 on the CPU.
    pub kernel_build_seconds: f64,
    /// The passes' named work counts (`shaft_samples`, ...).
    pub counters: BTreeMap<&'static str, u64>,
}

impl RenderStats {
    /// A named counter, 0 if no pass reported it.
    pub fn counter(&self, name: &str) -> u64 {
        self.counters.get(name).copied().unwrap_or(0)
    }

    /// The summed time of `passes` (a family's `PASSES`, or some of them):
    /// the benches time a family by its registered passes, so a pass added
    /// to it is counted without naming it.
    pub fn seconds_of(&self, passes: &[&dyn Pass]) -> f64 {
        let names: Vec<&str> = passes.iter().map(|p| p.name()).collect();
        self.passes.iter().filter(|p| names.contains(&p.name)).map(|p| p.seconds).sum()
    }
}

/// A rendered frame: the image (rgb radiance, W/(m^2 sr); w unused), and
/// each radiance layer that summed into it, by pass name.
pub struct Rendered {
    pub image: Vec<Vec4>,
    pub layers: Vec<(&'static str, Buffer)>,
    pub stats: RenderStats,
}

/// What every registered pass would do for the scene, decided before
/// anything runs.
pub fn plan(data: &SceneData) -> Vec<PassStats> {
    plans(data).into_iter().map(|(pass, plan)| stats_of(pass, &plan, data)).collect()
}

/// Pixels per rayon task in the frame's own per-pixel loops (summing layers).
const PIXEL_CHUNK: usize = 16384;

/// The plan's reason for a pass skipped because it was turned off
/// (`SceneData::disabled_passes`).
pub const TURNED_OFF: &str = "turned off";

fn plans(data: &SceneData) -> Vec<(&'static dyn Pass, Plan)> {
    let mut plans: Vec<(&'static dyn Pass, Plan)> = PASSES.iter().map(|&p| (p, p.plan(data))).collect();
    // Passes turned off (the viewer's toggles, `SceneData::disabled_passes`):
    // skipped unless another running pass reads what they write, in which
    // case they run and only their layer is left out of the image.
    for i in 0..plans.len() {
        let (pass, plan) = &plans[i];
        if !plan.runs || !data.disabled_passes.iter().any(|n| n == pass.name()) {
            continue;
        }
        let read_elsewhere = plans.iter().enumerate().any(|(j, (other, p))| {
            j != i && p.runs && other.reads().iter().any(|r| pass.writes().iter().any(|w| w.binding == r.binding))
        });
        if !read_elsewhere {
            plans[i].1 = Plan::skip(TURNED_OFF);
        }
    }
    plans
}

/// The memory budget of a render in bytes (`--max-memory`); 0: the
/// memory the system has available when the render starts.
pub static MEMORY_BUDGET: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The system's available memory (`MemAvailable` of /proc/meminfo), if known.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// What a render of `data` with the pass `plans` will hold at once, in
/// bytes, by what drives it: each resource the running passes bind
/// (per-pixel ones for the whole image on the CPU backend, a band on a
/// device), and the image and its layers kept for the outputs.
fn memory_needed(data: &SceneData, backend: &Backend, plans: &[(&'static dyn Pass, Plan)]) -> Vec<(String, u64)> {
    let running: Vec<&dyn Pass> = plans.iter().filter(|(_, p)| p.runs).map(|(p, _)| *p).collect();
    let pixels = match backend {
        Backend::Cpu => data.pixel_count() as u64,
        Backend::Gpu(ctx) => ctx.band_pixels(data) as u64,
    };
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for pass in &running {
        for r in pass.reads().iter().chain(pass.writes()) {
            if !seen.insert(r.binding) {
                continue;
            }
            let bytes = match r.kind {
                ResourceKind::Scene(f) => f(data).len() as u64,
                ResourceKind::Frame(f) => f(data),
                ResourceKind::PerPixel { blank } => blank().len() as u64 * pixels,
            };
            out.push((r.name.to_string(), bytes));
        }
    }
    let layers = running.iter().filter(|p| p.radiance_layer().is_some()).count() as u64;
    out.push(("the image and its layers".into(), 16 * data.pixel_count() as u64 * (layers + 1)));
    out
}

/// Refuses a render over the budget (`MEMORY_BUDGET`, else the available
/// memory) before anything is allocated, naming what needs the most.
fn check_memory(data: &SceneData, backend: &Backend, plans: &[(&'static dyn Pass, Plan)]) -> Result<()> {
    let set = MEMORY_BUDGET.load(std::sync::atomic::Ordering::Relaxed);
    let Some(budget) = (if set > 0 { Some(set) } else { available_memory() }) else { return Ok(()) };
    let mut needs = memory_needed(data, backend, plans);
    let total: u64 = needs.iter().map(|(_, b)| b).sum();
    if total <= budget {
        return Ok(());
    }
    needs.sort_by_key(|n| std::cmp::Reverse(n.1));
    let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
    let top: Vec<String> = needs.iter().take(3).map(|(n, b)| format!("{n} {:.2} GiB", gib(*b))).collect();
    anyhow::bail!(
        "the render needs {:.2} GiB ({}; camera.resolution {}x{} and samples_per_pixel {} drive the per-pixel ones), over the {} of {:.2} GiB",
        gib(total),
        top.join(", "),
        data.width(),
        data.height(),
        data.samples_per_pixel(),
        if set > 0 { "--max-memory budget" } else { "memory available" },
        gib(budget)
    )
}

fn invocations(pass: &dyn Pass, plan: &Plan, data: &SceneData) -> u64 {
    match (plan.runs, pass.dispatch()) {
        (false, _) => 0,
        (true, Dispatch::Whole) => plan.invocations,
        (true, Dispatch::PerPixel) => data.pixel_count() as u64 * data.samples_per_pixel() as u64,
    }
}

fn stats_of(pass: &'static dyn Pass, plan: &Plan, data: &SceneData) -> PassStats {
    PassStats {
        name: pass.name(),
        ran: plan.runs,
        reason: plan.reason.clone(),
        invocations: invocations(pass, plan, data),
        seconds: 0.0,
        report: None,
        kept: false,
    }
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

/// `sum += layer`, pixel by pixel.
pub fn add_into(sum: &mut [Vec4], layer: &[Vec4]) {
    sum.iter_mut().zip(layer).for_each(|(s, v)| *s += *v);
}

/// Multiplies the radiance layers in `frame` of the per-pixel passes that
/// run before each pass with a transmittance layer by it (rgb; `w`, which
/// some layers use for counts, is kept): what lies behind a medium is seen
/// through it (`Pass::transmittance_layer`).
fn attenuate(running: &[Running], frame: &mut Frame) {
    let per_pixel: Vec<&dyn Pass> = of_kind(running, Dispatch::PerPixel).map(|r| r.pass).collect();
    for (k, pass) in per_pixel.iter().enumerate() {
        let Some(t) = pass.transmittance_layer().and_then(|t| frame.remove(t).map(|b| (t, b))) else {
            continue;
        };
        for earlier in &per_pixel[..k] {
            let Some(behind) = earlier.radiance_layer() else {
                continue;
            };
            // Light gathered all along the ray passes the medium in front
            // of each of its points only: the share in `w`.
            let along = earlier.spans_the_view_ray();
            if let Some(mut layer) = frame.remove(behind) {
                layer
                    .as_mut_slice::<Vec4>()
                    .par_chunks_mut(PIXEL_CHUNK)
                    .zip(t.1.as_slice::<Vec4>().par_chunks(PIXEL_CHUNK))
                    .for_each(|(l, t)| {
                        for (l, t) in l.iter_mut().zip(t) {
                            let through = if along { glam::Vec3::splat(t.w) } else { t.truncate() };
                            *l = (l.truncate() * through).extend(l.w);
                        }
                    });
                frame.insert(behind, layer);
            }
        }
        frame.insert(t.0, t.1);
    }
}

/// A pass that runs this frame: where its stats are, and its invocations.
#[derive(Clone, Copy)]
struct Running {
    stat: usize,
    pass: &'static dyn Pass,
    invocations: u64,
}

/// A pass's outputs: each resource it writes with its contents.
type Outputs = Vec<(&'static Resource, Buffer)>;

/// The outputs of `Whole` passes (shadow maps, the sky's and the sea's
/// tables) kept from one render to the next: the viewer's renders, where a
/// moved camera leaves the sky's tables as they were and every sub-pixel
/// sample after the first would compute the same maps again. Each pass's
/// outputs are kept under a key that hashes everything its kernel is given
/// (its name and invocation count, the bytes of the scene resources it
/// reads, and the keys of the passes that wrote the frame resources it
/// reads), so a hit is the output the pass would write, bit for bit.
#[derive(Default)]
pub struct Memo {
    entries: std::collections::HashMap<&'static str, (u128, Outputs)>,
    /// Passes taken from the memo instead of run, over its life.
    pub hits: u64,
}

impl Memo {
    /// The keys of the `Whole` passes in `running`, in order; `None` for a
    /// pass that reads something no key covers (a per-pixel buffer). `known`
    /// holds the outputs cached before the frame (hashed by their bytes).
    fn keys(running: &[Running], data: &SceneData, known: &Frame) -> Vec<Option<u128>> {
        let mut written: std::collections::HashMap<u32, Option<u128>> = Default::default();
        let mut keys = Vec::new();
        for r in of_kind(running, Dispatch::Whole) {
            let mut h = twox_hash::XxHash3_128::new();
            h.write(r.pass.name().as_bytes());
            h.write(&r.invocations.to_le_bytes());
            let mut keyable = true;
            for input in r.pass.reads() {
                h.write(&input.binding.to_le_bytes());
                let bytes = match input.kind {
                    ResourceKind::Scene(f) => Some(f(data)),
                    _ => match written.get(&input.binding) {
                        Some(Some(k)) => {
                            h.write(&k.to_le_bytes());
                            continue;
                        }
                        Some(None) => None,
                        None => known.bytes(input).or(match input.kind {
                            ResourceKind::Frame(_) => Some(&[][..]),
                            _ => None,
                        }),
                    },
                };
                match bytes {
                    Some(b) => {
                        h.write(&(b.len() as u64).to_le_bytes());
                        h.write(b);
                    }
                    None => keyable = false,
                }
            }
            let key = keyable.then(|| h.finish_128());
            for w in r.pass.writes() {
                written.insert(w.binding, key);
            }
            keys.push(key);
        }
        keys
    }

    fn get(&mut self, pass: &dyn Pass, key: Option<u128>) -> Option<Outputs> {
        let (k, outputs) = self.entries.get(pass.name())?;
        (Some(*k) == key).then(|| {
            self.hits += 1;
            outputs.clone()
        })
    }

    fn put(&mut self, pass: &dyn Pass, key: Option<u128>, outputs: Outputs) {
        match key {
            Some(k) => self.entries.insert(pass.name(), (k, outputs)),
            None => self.entries.remove(pass.name()),
        };
    }
}

/// What the `Whole` passes write that no running pass reads (a self-check's
/// accumulators): the frame's results for `Pass::report` and `counters`.
/// Intermediates such as the shadow maps stay on the device, and so do
/// the kept outputs of passes that do not want them read back (`device`;
/// `Pass::keeps_on_device`).
fn final_outputs(running: &[Running], device: bool) -> Vec<&'static Resource> {
    let read = |r: &Resource| running.iter().any(|x| x.pass.reads().iter().any(|y| y.binding == r.binding));
    running
        .iter()
        .filter(|r| r.pass.dispatch() == Dispatch::Whole)
        .flat_map(|r| {
            let keeps = if device && !r.pass.keeps_on_device() { &[] } else { r.pass.keeps() };
            r.pass.writes().iter().copied().filter(move |w| !read(w) || keeps.iter().any(|k| k.binding == w.binding))
        })
        .collect()
}

/// The passes of one dispatch kind, in run order.
fn of_kind(running: &[Running], dispatch: Dispatch) -> impl Iterator<Item = &Running> {
    running.iter().filter(move |r| r.pass.dispatch() == dispatch)
}

/// A frame in progress: the passes that run, those that add a radiance
/// layer, and what they have produced.
struct Work<'a> {
    data: &'a SceneData,
    running: Vec<Running>,
    layers: Vec<&'static dyn Pass>,
    /// The results: `Whole` passes' final outputs (the layers join at the end).
    result: Frame,
    /// Each layer's sum over the sub-pixel samples (on the CPU the first
    /// sample's buffer itself, moved, not copied).
    sums: Vec<Option<Buffer>>,
    stats: Vec<PassStats>,
    progress: ProgressBar,
    /// The sub-pixel samples this render takes (of the scene's `samples_per_pixel` positions).
    samples: std::ops::Range<u32>,
    /// `Whole` passes' outputs from earlier renders (the viewer's).
    memo: Option<&'a mut Memo>,
}

impl Work<'_> {
    /// Runs every pass on the CPU; returns how the pass times were taken.
    fn run_cpu(&mut self, known: Frame) -> &'static str {
        let (data, pb) = (self.data, &self.progress);
        let pixels = data.pixel_count() as usize;
        let mut frame = known;
        // Per-pixel resources that running passes read but none writes
        // hold their blank (the rest are never touched).
        for r in self.running.iter().flat_map(|r| r.pass.reads().iter()) {
            let written = self.running.iter().any(|x| x.pass.writes().iter().any(|w| w.binding == r.binding));
            if !written && !frame.contains(r) {
                if let Some(blank) = r.blank(pixels) {
                    frame.insert(r, blank);
                }
            }
        }
        let keys = match self.memo {
            Some(_) => Memo::keys(&self.running, data, &frame),
            None => Vec::new(),
        };
        for (k, r) in of_kind(&self.running, Dispatch::Whole).enumerate() {
            if let Some(memo) = self.memo.as_deref_mut() {
                if let Some(outputs) = memo.get(r.pass, keys.get(k).copied().flatten()) {
                    outputs.into_iter().for_each(|(w, b)| frame.insert(w, b));
                    self.stats[r.stat].kept = true;
                    continue;
                }
            }
            pb.set_message(r.pass.name());
            let t = Instant::now();
            r.pass.run_cpu(data, &data.common, &mut frame, pb);
            self.stats[r.stat].seconds += t.elapsed().as_secs_f64();
            if let Some(memo) = self.memo.as_deref_mut() {
                let outputs = r.pass.writes().iter().filter_map(|w| Some((*w, frame.remove(w)?))).collect::<Vec<_>>();
                outputs.iter().for_each(|(w, b)| frame.insert(w, b.clone()));
                memo.put(r.pass, keys.get(k).copied().flatten(), outputs);
            }
        }
        for sample in self.samples.clone() {
            let mut common = data.common;
            common.sample_index = sample;
            for r in of_kind(&self.running, Dispatch::PerPixel) {
                pb.set_message(r.pass.name());
                let t = Instant::now();
                r.pass.run_cpu(data, &common, &mut frame, pb);
                self.stats[r.stat].seconds += t.elapsed().as_secs_f64();
            }
            attenuate(&self.running, &mut frame);
            for (sum, pass) in self.sums.iter_mut().zip(&self.layers) {
                let resource = pass.radiance_layer().expect("a layer");
                match sum {
                    None => *sum = frame.remove(resource),
                    Some(sum) => add_into(sum.as_mut_slice(), frame.get(resource)),
                }
            }
        }
        for w in final_outputs(&self.running, false) {
            if let Some(b) = frame.remove(w) {
                self.result.insert(w, b);
            }
        }
        "wall clock"
    }

    /// Runs every pass on the device, band by band of pixels; returns how
    /// the pass times were taken.
    fn run_gpu(&mut self, ctx: &GpuContext, mut known: Frame) -> Result<&'static str> {
        let (data, pb) = (self.data, &self.progress);
        let pixels = data.pixel_count() as usize;
        let passes: Vec<&'static dyn Pass> = self.running.iter().map(|r| r.pass).collect();
        // Passes the memo holds are not run: their outputs are uploaded.
        let keys = match self.memo {
            Some(_) => Memo::keys(&self.running, data, &known),
            None => Vec::new(),
        };
        let mut whole: Vec<(Running, Option<u128>)> = Vec::new();
        for (k, r) in of_kind(&self.running, Dispatch::Whole).enumerate() {
            let key = keys.get(k).copied().flatten();
            match self.memo.as_deref_mut().and_then(|m| m.get(r.pass, key)) {
                Some(outputs) => {
                    outputs.into_iter().for_each(|(w, b)| known.insert(w, b));
                    self.stats[r.stat].kept = true;
                }
                None => whole.push((*r, key)),
            }
        }
        let frame = ctx.frame(data, &passes, Some(&known))?;
        pb.set_message("maps");
        let times = frame.run(&whole.iter().map(|(r, _)| (r.pass, r.invocations as u32)).collect::<Vec<_>>())?;
        for ((r, _), t) in whole.iter().zip(times) {
            self.stats[r.stat].seconds += t;
            pb.inc(r.invocations);
        }
        if let Some(memo) = self.memo.as_deref_mut() {
            // Read back what ran, for the next render.
            for (r, key) in &whole {
                let mut outputs = Vec::new();
                for w in r.pass.writes() {
                    if let ResourceKind::Frame(len) = w.kind {
                        outputs.push((*w, frame.read(w, len(data))?));
                    }
                }
                memo.put(r.pass, *key, outputs);
            }
        }
        for w in final_outputs(&self.running, true) {
            if let ResourceKind::Frame(len) = w.kind {
                self.result.insert(w, frame.read(w, len(data))?);
            }
        }
        let per_pixel: Vec<Running> = of_kind(&self.running, Dispatch::PerPixel).copied().collect();
        let band = ctx.band_pixels(data);
        let mut first = 0;
        while first < data.pixel_count() {
            let count = band.min(data.pixel_count() - first);
            for sample in self.samples.clone() {
                frame.set_band(first, count, sample);
                pb.set_message("image");
                let times = frame.run(&per_pixel.iter().map(|r| (r.pass, count)).collect::<Vec<_>>())?;
                for (r, t) in per_pixel.iter().zip(times) {
                    self.stats[r.stat].seconds += t;
                    pb.inc(count as u64);
                }
                // The band's layers, and the transmittances that hide some of them.
                let mut band = Frame::default();
                for r in per_pixel
                    .iter()
                    .flat_map(|r| r.pass.radiance_layer().into_iter().chain(r.pass.transmittance_layer()))
                {
                    band.insert(r, frame.read(r, count as u64 * 16)?);
                }
                attenuate(&self.running, &mut band);
                for (sum, pass) in self.sums.iter_mut().zip(&self.layers) {
                    let layer = band.get::<Vec4>(pass.radiance_layer().expect("a layer"));
                    let sum = sum.get_or_insert_with(|| Buffer::zeroed::<Vec4>(pixels));
                    let range = &mut sum.as_mut_slice::<Vec4>()[first as usize..(first + count) as usize];
                    add_into(range, layer);
                }
            }
            first += count;
        }
        Ok(if ctx.has_timestamps() { "device timestamps" } else { "wall clock per submission" })
    }

    /// The passes' reports and counters, and the image: the mean over
    /// samples of the sum of the layers (box filter), with each layer.
    /// `timing` says how the pass times were taken, `start` is when the
    /// frame began.
    fn finish(mut self, backend: &Backend, timing: &'static str, start: Instant, build: f64) -> Result<Rendered> {
        let data = self.data;
        let pixels = data.pixel_count() as usize;
        self.progress.finish_and_clear();
        for (sum, pass) in std::mem::take(&mut self.sums).into_iter().zip(&self.layers) {
            let sum = sum.unwrap_or_else(|| Buffer::zeroed::<Vec4>(pixels));
            self.result.insert(pass.radiance_layer().expect("a layer"), sum);
        }
        let mut counters = BTreeMap::new();
        for r in &self.running {
            r.pass.persist(data, &self.result);
            self.stats[r.stat].report =
                r.pass.report(data, &self.result).map_err(|e| e.context(format!("pass {}", r.pass.name())))?;
            counters.extend(r.pass.counters(data, &self.result));
        }
        let mut named = Vec::new();
        for pass in &self.layers {
            let layer = self.result.remove(pass.radiance_layer().expect("a layer")).expect("inserted above");
            named.push((pass.name(), layer));
        }
        let image = mean_image(&mut named, self.samples.len() as u32, pixels);
        let stats = RenderStats {
            backend: backend.name(),
            device: backend.device(),
            width: data.width(),
            height: data.height(),
            samples_per_pixel: self.samples.len() as u32,
            passes: self.stats,
            pass_timing: timing,
            total_seconds: start.elapsed().as_secs_f64(),
            kernel_build_seconds: build,
            counters,
        };
        Ok(Rendered { image, layers: named, stats })
    }
}

/// Turns per-layer sums over `samples` sub-pixel samples into their means
/// (in place, alpha cleared) and returns the image of `pixels` pixels: the
/// sum of the layers (the box filter over the samples; black where no
/// pass draws, as in a scene whose every pass is skipped). A render's own
/// last step, and the viewer's, so that a view accumulated sample by
/// sample is the same image, bit for bit, as a render of all its samples
/// at once.
pub fn mean_image(layers: &mut [(&'static str, Buffer)], samples: u32, pixels: usize) -> Vec<Vec4> {
    let inv = 1.0 / samples.max(1) as f32;
    for (_, layer) in layers.iter_mut() {
        layer.as_mut_slice::<Vec4>().par_chunks_mut(PIXEL_CHUNK).for_each(|chunk| {
            for s in chunk {
                *s = (*s * inv).truncate().extend(0.0);
            }
        });
    }
    // Collected in parallel: the new image's first touch of its pages (a
    // page fault each) is shared among the threads.
    (0..pixels)
        .into_par_iter()
        .with_min_len(PIXEL_CHUNK)
        .map(|i| layers.iter().map(|(_, layer)| layer.as_slice::<Vec4>()[i]).sum())
        .collect()
}

/// Renders a scene: rgb radiance per pixel (W/(m^2 sr)).
pub fn render(data: &SceneData, backend: &Backend, show_progress: bool) -> Result<(Vec<Vec4>, RenderStats)> {
    let r = render_layers(data, backend, show_progress)?;
    Ok((r.image, r.stats))
}

/// Renders a scene, keeping each pass's radiance layer.
pub fn render_layers(data: &SceneData, backend: &Backend, show_progress: bool) -> Result<Rendered> {
    render_samples(data, backend, 0..data.samples_per_pixel(), show_progress, None)
}

/// Renders sub-pixel samples `samples` of the scene's `samples_per_pixel`
/// positions (the viewer's progressive refinement takes them one at a time):
/// the image and layers are their means. With a `memo`, `Whole` passes whose
/// inputs are those of an earlier render take that render's outputs.
pub fn render_samples(
    data: &SceneData,
    backend: &Backend,
    samples: std::ops::Range<u32>,
    show_progress: bool,
    memo: Option<&mut Memo>,
) -> Result<Rendered> {
    if samples.is_empty() || samples.end > data.samples_per_pixel() {
        anyhow::bail!("samples {samples:?}: expected a range inside 0..{}", data.samples_per_pixel());
    }
    let plans = plans(data);
    check_memory(data, backend, &plans)?;
    let stats: Vec<PassStats> = plans.iter().map(|(p, plan)| stats_of(*p, plan, data)).collect();
    let running: Vec<Running> = plans
        .iter()
        .enumerate()
        .filter(|(_, (_, plan))| plan.runs)
        .map(|(stat, (pass, plan))| Running { stat, pass: *pass, invocations: plan.invocations })
        .collect();
    let total: u64 = stats.iter().map(|p| p.invocations).sum();
    let progress = if show_progress { progress_bar(total) } else { ProgressBar::hidden() };
    let kernel_build_seconds = match backend {
        Backend::Gpu(ctx) => {
            let t = Instant::now();
            ctx.prepare(data, &running.iter().map(|r| r.pass).collect::<Vec<_>>())?;
            t.elapsed().as_secs_f64()
        }
        Backend::Cpu => 0.0,
    };
    let start = Instant::now();
    let layers: Vec<&'static dyn Pass> =
        running.iter().map(|r| r.pass).filter(|p| p.radiance_layer().is_some()).collect();
    // Outputs known before the frame (a cached table).
    let mut known = Frame::default();
    for pass in PASSES.iter() {
        if let Some((r, buffer)) = pass.cached(data) {
            known.insert(r, buffer);
        }
    }
    let sums = (0..layers.len()).map(|_| None).collect();
    let mut work = Work { data, running, layers, result: Frame::default(), sums, stats, progress, samples, memo };
    let pass_timing = match backend {
        Backend::Cpu => work.run_cpu(known),
        Backend::Gpu(ctx) => work.run_gpu(ctx, known)?,
    };
    work.finish(backend, pass_timing, start, kernel_build_seconds)
}

impl Rendered {
    /// The layers as slices of radiance, for `output::write_layered`.
    pub fn layer_slices(&self) -> Vec<(&'static str, &[Vec4])> {
        self.layers.iter().map(|(n, b)| (*n, b.as_slice::<Vec4>())).collect()
    }
}
