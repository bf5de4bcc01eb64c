//! The pass registry (`FAMILIES`, `PASSES`), the resources passes share,
//! and the frame's buffers.
//!
//! A pass is one unit: its kernel in `shader-crate/src/<family>/` (the
//! pure per-invocation function and its thin entry point) and its host
//! side in `host/src/<family>/`, which says whether a scene needs it and why not, which
//! resources it reads and writes, how it is dispatched, how it runs the same
//! function on the CPU, and how its GPU and CPU results are compared. The
//! renderer, the pass plan, `--stats`, the progress bar, the GPU backend's
//! pipelines and bind groups, and the equivalence tests all walk `PASSES`.
//!
//! Resources are named by their binding number, which is written once, in
//! the `Resource` that declares it (shared ones below, a pass's own in its
//! module); the `bindings` test checks them against the compiled SPIR-V.

use bytemuck::Pod;
use glam::Vec4;
use indicatif::ProgressBar;
use slicelight_shaders::types::CommonParams;
use std::collections::HashMap;

use crate::scene::SceneData;

/// A `&'static [&'static Resource]` of the given resources (a pass's reads
/// or writes; a static, since a constant may not point at statics).
macro_rules! resources {
    ($($r:expr),* $(,)?) => {{
        static LIST: &[&Resource] = &[$(&$r),*];
        LIST
    }};
}

use crate::{caustics, common, desert, sea, shafts, sky, smoke, volumes};

/// A family: its passes (in the order they run), the kernels it
/// dispatches itself (a simulation's step), and its bench sweep.
pub struct Family {
    pub name: &'static str,
    pub passes: &'static [&'static dyn Pass],
    pub kernels: &'static [&'static crate::gpu::Kernel],
    pub bench: Option<&'static dyn crate::bench::Sweep>,
}

/// The families, registered here once. Within each dispatch kind the
/// renderer runs passes in this order, each family's in its own `passes`
/// order: every `Whole` pass first (the tables and maps), then the per-pixel
/// passes, whose radiance layers are summed into the image in the same
/// order. A pass reads only what earlier passes wrote (the
/// `passes_run_after_what_they_read` test checks it).
static FAMILIES: &[&Family] = &[
    &common::FAMILY,
    &caustics::FAMILY,
    &shafts::FAMILY,
    &sky::FAMILY,
    &sea::FAMILY,
    &volumes::FAMILY,
    &desert::FAMILY,
    &smoke::FAMILY,
];

/// The registered families (see `FAMILIES`).
pub fn families() -> &'static [&'static Family] {
    FAMILIES
}

/// Every pass, in the order the renderer runs them (see `FAMILIES`).
pub static PASSES: std::sync::LazyLock<Vec<&'static dyn Pass>> = std::sync::LazyLock::new(|| {
    let all = FAMILIES.iter().flat_map(|f| f.passes.iter().copied());
    let whole = all.clone().filter(|p| p.dispatch() == Dispatch::Whole);
    whole.chain(all.filter(|p| p.dispatch() == Dispatch::PerPixel)).collect()
});

/// Whether a pass that runs for `scene` reads `resource` (and looks at it
/// for this scene: `Pass::unused_reads`). A pass whose only work is an
/// input of others runs when this holds: what no running pass reads is
/// not computed.
pub fn read_by_a_running_pass(scene: &SceneData, resource: &Resource) -> bool {
    PASSES.iter().any(|p| {
        p.reads().iter().any(|r| r.binding == resource.binding)
            && !p.unused_reads(scene).iter().any(|r| r.binding == resource.binding)
            && p.plan(scene).runs
    })
}

/// The registered pass named `name`.
pub fn by_name(name: &str) -> Option<&'static dyn Pass> {
    PASSES.iter().copied().find(|p| p.name() == name)
}

/// A buffer the kernels bind, at `binding` of descriptor set 0.
pub struct Resource {
    pub binding: u32,
    pub name: &'static str,
    pub kind: ResourceKind,
}

pub enum ResourceKind {
    /// Read-only data taken from the scene (geometry, lights, a pass's
    /// parameter block), uploaded once per frame.
    Scene(for<'a> fn(&'a SceneData) -> &'a [u8]),
    /// Written once per frame by a pass; `bytes(scene)` long. The GPU
    /// backend zero-fills it before the pass runs.
    Frame(fn(&SceneData) -> u64),
    /// Written for every pixel of a band by a per-pixel pass. `blank` is
    /// one pixel's value where no pass writes it (a G-buffer that sees no
    /// surface); its length is the bytes per pixel.
    PerPixel { blank: fn() -> Vec<u8> },
}

impl Resource {
    /// Bytes per pixel of a `PerPixel` resource.
    pub fn bytes_per_pixel(&self) -> Option<u64> {
        match self.kind {
            ResourceKind::PerPixel { blank } => Some(blank().len() as u64),
            _ => None,
        }
    }

    /// A `PerPixel` resource's contents for `pixels` pixels where no pass writes it.
    /// Filled in place and in parallel (a G-buffer's blank at 720x480 is
    /// 22 MB: built as one `Vec` and copied, it took 18 ms of `sea_open`'s
    /// frame); an all-zero blank is the allocator's zeroed pages.
    pub fn blank(&self, pixels: usize) -> Option<Buffer> {
        use rayon::prelude::*;
        let ResourceKind::PerPixel { blank } = self.kind else { return None };
        let pattern = blank();
        let bytes = pattern.len() * pixels;
        if pattern.iter().all(|&b| b == 0) {
            return Some(Buffer::zeroed::<u8>(bytes));
        }
        let mut buffer = Buffer::overwritten::<u8>(bytes);
        buffer.as_mut_slice::<u8>().par_chunks_mut(pattern.len() * 4096).for_each(|chunk| {
            for texel in chunk.chunks_exact_mut(pattern.len()) {
                texel.copy_from_slice(&pattern);
            }
        });
        Some(buffer)
    }
}

/// The blank of a per-pixel radiance layer: no light.
pub fn no_radiance() -> Vec<u8> {
    vec![0; 16]
}

// The resources several passes share. A pass's own live in its module.

pub static COMMON: Resource =
    Resource { binding: 0, name: "common parameters", kind: ResourceKind::Scene(|s| bytemuck::bytes_of(&s.common)) };
pub static LIGHTS: Resource =
    Resource { binding: 1, name: "lights", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.lights)) };
pub static SPHERES: Resource =
    Resource { binding: 2, name: "spheres", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.spheres)) };
pub static TRIANGLES: Resource =
    Resource { binding: 3, name: "triangles", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.triangles)) };
pub static BVH_NODES: Resource =
    Resource { binding: 4, name: "BVH nodes", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.bvh_nodes)) };
pub static MATERIALS: Resource =
    Resource { binding: 5, name: "materials", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.materials)) };
pub static LIGHT_MAPS: Resource =
    Resource { binding: 6, name: "light maps", kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.light_map)) };
pub static SHADOW_MAPS: Resource =
    Resource { binding: 7, name: "shadow maps", kind: ResourceKind::Frame(|s| s.common.shadow_texel_count as u64 * 4) };
pub static GBUFFER: Resource = Resource {
    binding: 8,
    name: "G-buffer",
    kind: ResourceKind::PerPixel {
        blank: || bytemuck::bytes_of(&slicelight_shaders::common::surface::no_surface()).to_vec(),
    },
};

pub static GLASS_VERTICES: Resource = Resource {
    binding: 29,
    name: "glass vertices",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.glass_vertices)),
};
pub static GLASS_TRIANGLES: Resource = Resource {
    binding: 30,
    name: "glass triangles",
    kind: ResourceKind::Scene(|s| bytemuck::cast_slice(&s.glass_triangles)),
};

/// How a pass's kernel is dispatched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dispatch {
    /// Once per frame, over `Plan::invocations` invocations.
    Whole,
    /// Once per band of pixels and per sub-pixel sample, one invocation per pixel.
    PerPixel,
}

/// Whether a pass runs for a scene, and why (or why not).
#[derive(Debug, Clone)]
pub struct Plan {
    pub runs: bool,
    pub reason: String,
    /// Invocations of a `Whole` pass (per-pixel passes: one per pixel).
    pub invocations: u64,
}

impl Plan {
    pub fn skip(reason: impl Into<String>) -> Plan {
        Plan { runs: false, reason: reason.into(), invocations: 0 }
    }
    pub fn run(reason: impl Into<String>, invocations: u64) -> Plan {
        Plan { runs: true, reason: reason.into(), invocations }
    }
}

/// One pass: see the module docs.
pub trait Pass: Sync {
    /// Its name in the plan, `--stats` and the EXR's layers.
    fn name(&self) -> &'static str;
    /// Its SPIR-V entry point (rust-gpu names it by its module path:
    /// `surface::surface_kernel`).
    fn kernel(&self) -> &'static str;
    /// Other entry points of the same kernel function, compiled with what
    /// some scenes do not need left out (a const generic); each computes
    /// what `kernel` computes for the scenes `kernel_for` gives it to.
    fn variants(&self) -> &'static [&'static str] {
        &[]
    }
    /// The entry point a scene runs: `kernel` or one of the `variants`.
    fn kernel_for(&self, _scene: &SceneData) -> &'static str {
        self.kernel()
    }
    /// Resources its kernel only reads.
    fn reads(&self) -> &'static [&'static Resource];
    /// Of `reads`, those its kernel binds but does not look at for this
    /// scene (the shadow maps where surfaces take shadow rays): a pass
    /// that writes them need not run for it (`read_by_a_running_pass`).
    fn unused_reads(&self, _scene: &SceneData) -> &'static [&'static Resource] {
        &[]
    }
    /// Resources its kernel writes.
    fn writes(&self) -> &'static [&'static Resource];
    fn dispatch(&self) -> Dispatch;
    /// Whether the scene needs it, and why (or why not).
    fn plan(&self, scene: &SceneData) -> Plan;
    /// Runs its kernel function on the CPU for every invocation, reading
    /// and writing `frame`. `common` is the scene's common block with the
    /// band (the whole image on the CPU) and sub-pixel sample set.
    fn run_cpu(&self, scene: &SceneData, common: &CommonParams, frame: &mut Frame, progress: &ProgressBar);
    /// The per-pixel radiance (rgb, W/(m^2 sr)) it adds to the image, if
    /// any: a layer of the EXR, summed into the beauty image.
    fn radiance_layer(&self) -> Option<&'static Resource> {
        None
    }
    /// Whether its radiance layer is light gathered all along the view ray
    /// (a homogeneous medium's in-scattering) rather than light from where
    /// the ray ends: a later pass's transmittance layer then attenuates it
    /// by its `w`, the share of such light the medium in front lets through,
    /// instead of by the transmittance to the ray's end (rgb).
    fn spans_the_view_ray(&self) -> bool {
        false
    }
    /// Dispatches of a `Whole` pass per frame: a simulation's steps. After
    /// each, the GPU copies every `carry` pair (what the step wrote, over
    /// what the next step reads); the CPU path runs all the steps itself.
    fn repeats(&self, _scene: &SceneData) -> u32 {
        1
    }
    /// See `repeats`: `(written, read)` resource pairs, both the pass's own.
    fn carry(&self) -> &'static [(&'static Resource, &'static Resource)] {
        &[]
    }
    /// The per-pixel transmittance (rgb; `w`: the share of light gathered
    /// along the whole ray that passes, see `spans_the_view_ray`) of what
    /// the pass renders, if it hides what lies behind it (a participating medium in front of the
    /// surfaces and the sky): the renderer multiplies the radiance layers
    /// of every per-pixel pass that runs before it by it, sample by sample,
    /// before they are summed (so each layer holds the light that reaches
    /// the eye).
    fn transmittance_layer(&self) -> Option<&'static Resource> {
        None
    }
    /// What the pass found, for the stats (a self-check's verdict), or an
    /// error if what it found is wrong (a failed self-check fails the
    /// render). `frame` holds the frame's results: what `Whole` passes wrote
    /// that no pass reads, and each radiance layer summed over the sub-pixel
    /// samples.
    fn report(&self, _scene: &SceneData, _frame: &Frame) -> anyhow::Result<Option<String>> {
        Ok(None)
    }
    /// Named counts of the work it did, for the stats (from the same frame).
    fn counters(&self, _scene: &SceneData, _frame: &Frame) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
    /// An output the pass need not compute because it is already known (a
    /// light transport table from the disk cache): the renderer puts these
    /// bytes in the frame (uploads them on the GPU) and the pass's plan
    /// skips it.
    fn cached(&self, _scene: &SceneData) -> Option<(&'static Resource, Buffer)> {
        None
    }
    /// Outputs that later passes consume but that stay in the frame's
    /// results for `report`, `counters` and `persist` (read back from the GPU).
    fn keeps(&self) -> &'static [&'static Resource] {
        &[]
    }
    /// Whether a device reads `keeps` back after every frame. A pass whose
    /// kept outputs are large and serve only a diagnostic `report` says
    /// false: on a device its report is then absent (the CPU backend's
    /// results are in memory and cost nothing to keep).
    fn keeps_on_device(&self) -> bool {
        true
    }
    /// Keeps outputs beyond the frame (writes the cache), from the results.
    fn persist(&self, _scene: &SceneData, _results: &Frame) {}
    /// Compares what the GPU wrote with what the CPU wrote, from the same
    /// inputs, within tolerances the pass states and justifies; returns a
    /// line describing the agreement, or an error.
    fn compare(&self, scene: &SceneData, gpu: &Frame, cpu: &Frame) -> anyhow::Result<String>;
}

/// A 16-byte, 16-aligned block: the storage of `Frame`, so that any buffer
/// can be viewed as a slice of `Vec4` or of the kernels' structs.
#[repr(C, align(16))]
#[derive(Copy, Clone, Default)]
struct Block([u32; 4]);
// SAFETY: 16 bytes of u32s, align 16, no padding; any bits are valid.
unsafe impl bytemuck::Zeroable for Block {}
unsafe impl bytemuck::Pod for Block {}

/// A buffer's contents on the CPU, 16-aligned so that it can be viewed as
/// a slice of `Vec4` or of the kernels' structs. Clones share the bytes
/// until one is written (a cached table goes into each frame uncopied).
#[derive(Clone, Default)]
pub struct Buffer {
    /// Shared between clones; copied on the first write to a shared one.
    blocks: std::sync::Arc<Vec<Block>>,
    bytes: usize,
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Buffer({} bytes)", self.bytes)
    }
}

impl Buffer {
    /// `len` zeroed `T`s: the storage of a dropped buffer of the same size
    /// if one is kept (`recycled`), else fresh from the allocator, whose
    /// new pages are zero and cost nothing until touched (a sparse caustics
    /// map, a layer most pixels of which a pass leaves at 0).
    pub fn zeroed<T: Pod>(len: usize) -> Buffer {
        Buffer::of::<T>(len, recycled)
    }

    /// `len` `T`s of unspecified value (kept storage reused as it is, else
    /// zeroed), for a pass that assigns every element before anything reads
    /// the buffer: `cpu::for_each_invocation` over all of it.
    pub fn overwritten<T: Pod>(len: usize) -> Buffer {
        Buffer::of::<T>(len, take_kept)
    }

    /// `len` `T`s in storage from `kept` (by its number of blocks), or else
    /// fresh and zeroed.
    fn of<T: Pod>(len: usize, kept: fn(usize) -> Option<Vec<Block>>) -> Buffer {
        let bytes = len * std::mem::size_of::<T>();
        let blocks = kept(bytes.div_ceil(16)).unwrap_or_else(|| bytemuck::zeroed_vec::<Block>(bytes.div_ceil(16)));
        Buffer { blocks: std::sync::Arc::new(blocks), bytes }
    }

    pub fn from_bytes(bytes: &[u8]) -> Buffer {
        // Every byte is assigned; the padding to the last block is never
        // seen (`as_slice` and `as_bytes` end at `bytes`).
        let mut b = Buffer::overwritten::<u8>(bytes.len());
        b.as_mut_slice::<u8>().copy_from_slice(bytes);
        b
    }

    pub fn as_slice<T: Pod>(&self) -> &[T] {
        &bytemuck::cast_slice(self.blocks.as_slice())[..self.bytes / std::mem::size_of::<T>()]
    }

    pub fn as_mut_slice<T: Pod>(&mut self) -> &mut [T] {
        let len = self.bytes / std::mem::size_of::<T>();
        &mut bytemuck::cast_slice_mut(std::sync::Arc::make_mut(&mut self.blocks).as_mut_slice())[..len]
    }

    pub fn as_bytes(&self) -> &[u8] {
        &bytemuck::cast_slice(self.blocks.as_slice())[..self.bytes]
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // The last owner of the bytes gives them back for a later frame.
        if let Some(blocks) = std::sync::Arc::get_mut(&mut self.blocks) {
            keep(std::mem::take(blocks));
        }
    }
}

/// Storage of dropped buffers, kept for the next buffer of the same size:
/// a renderer that draws frame after frame (the bench, an animation) then
/// writes into memory it already has. Fresh memory costs a page fault per
/// 4 KiB on first touch (about 0.44 ms per MiB on the development machine:
/// 7 ms of CPU time for Fig. 6's 16.5 MiB surface layer and G-buffer), and
/// freed memory that the allocator hands out again is zeroed by one thread
/// inside `calloc` (the surface pass's 13 ms became 18 ms from the second
/// frame in a process on). Only buffers of at least `KEEP_MIN_BLOCKS` are
/// kept, at most `KEEP_MAX_BLOCKS` in all.
static KEPT: std::sync::Mutex<Vec<Vec<Block>>> = std::sync::Mutex::new(Vec::new());
const KEEP_MIN_BLOCKS: usize = 1 << 16;
const KEEP_MAX_BLOCKS: usize = 1 << 26;

fn keep(blocks: Vec<Block>) {
    if blocks.len() < KEEP_MIN_BLOCKS {
        return;
    }
    let Ok(mut kept) = KEPT.lock() else { return };
    let held: usize = kept.iter().map(Vec::len).sum();
    if held + blocks.len() <= KEEP_MAX_BLOCKS {
        kept.push(blocks);
    }
}

/// A kept storage of exactly `blocks` blocks, as it was left, if any.
fn take_kept(blocks: usize) -> Option<Vec<Block>> {
    if blocks < KEEP_MIN_BLOCKS {
        return None;
    }
    let mut kept = KEPT.lock().ok()?;
    let k = kept.iter().position(|b| b.len() == blocks)?;
    Some(kept.swap_remove(k))
}

/// A kept storage of exactly `blocks` blocks, zeroed (in parallel), if any.
/// Only the 4 KiB pages that hold something are written: a sparse buffer's
/// untouched pages (a caustics map's) are still the kernel's shared zero
/// page after a pass read them, and writing zeros there cost a
/// copy-on-write fault and a TLB shootdown per page (5 % of
/// `caustics_fog_ball`'s frames from the second on, in `perf`); reading
/// them is a read of one page that stays in the cache.
fn recycled(blocks: usize) -> Option<Vec<Block>> {
    let mut storage = take_kept(blocks)?;
    use rayon::prelude::*;
    storage.par_chunks_mut(256).for_each(|page| {
        if page.iter().any(|b| b.0 != [0; 4]) {
            page.fill(Block::default());
        }
    });
    Some(storage)
}

/// The buffers passes write (shadow maps, G-buffer, radiance layers,
/// accumulators), by binding, on the CPU: what the CPU backend computes, and
/// what the GPU backend reads back.
#[derive(Default, Clone)]
pub struct Frame {
    buffers: HashMap<u32, Buffer>,
}

impl Frame {
    /// The contents of `r` as `T`s (empty if nothing wrote it).
    pub fn get<T: Pod>(&self, r: &Resource) -> &[T] {
        self.buffers.get(&r.binding).map_or(&[], |b| b.as_slice())
    }

    pub fn bytes(&self, r: &Resource) -> Option<&[u8]> {
        self.buffers.get(&r.binding).map(|b| b.as_bytes())
    }

    pub fn contains(&self, r: &Resource) -> bool {
        self.buffers.contains_key(&r.binding)
    }

    pub fn insert(&mut self, r: &Resource, buffer: Buffer) {
        self.buffers.insert(r.binding, buffer);
    }

    pub fn remove(&mut self, r: &Resource) -> Option<Buffer> {
        self.buffers.remove(&r.binding)
    }

    /// Runs `fill` on a zeroed buffer of `len` `T`s that becomes the
    /// contents of `r`, while the rest of the frame stays readable.
    pub fn write<T: Pod>(&mut self, r: &Resource, len: usize, fill: impl FnOnce(&Frame, &mut [T])) {
        self.fill_into(r, Buffer::zeroed::<T>(len), fill);
    }

    /// As `write`, for a `fill` that assigns every element (a kernel run
    /// over the whole buffer by `cpu::for_each_invocation`): the buffer
    /// starts with unspecified values (`Buffer::overwritten`), not zeroed.
    pub fn write_all<T: Pod>(&mut self, r: &Resource, len: usize, fill: impl FnOnce(&Frame, &mut [T])) {
        self.fill_into(r, Buffer::overwritten::<T>(len), fill);
    }

    fn fill_into<T: Pod>(&mut self, r: &Resource, mut buffer: Buffer, fill: impl FnOnce(&Frame, &mut [T])) {
        self.buffers.remove(&r.binding);
        fill(self, buffer.as_mut_slice());
        self.buffers.insert(r.binding, buffer);
    }
}

/// Counts values whose difference exceeds `tol(cpu)` (or is NaN), and
/// returns the largest difference among the rest: the equivalence tests'
/// measure.
pub fn count_differences(gpu: &[f32], cpu: &[f32], tol: impl Fn(f32) -> f32) -> (usize, f32) {
    assert_eq!(gpu.len(), cpu.len(), "buffers of different lengths");
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

/// Compares two tables or layers of `Vec4`s (rgb) within `rel` of the
/// CPU's peak per value, `allowed` values free to differ (pixels that
/// flip across an edge); the callers say why their `rel` is what it is.
/// For comparisons of exact records (indices, lists, automaton cells):
/// how many of the records of `stride` elements differ between the two
/// backends, and how many records there are; unequal lengths are an error
/// naming `what`.
pub fn differing_records<T: PartialEq>(
    what: &str,
    gpu: &[T],
    cpu: &[T],
    stride: usize,
) -> anyhow::Result<(usize, usize)> {
    anyhow::ensure!(gpu.len() == cpu.len(), "{what}: {} and {} elements", gpu.len(), cpu.len());
    let stride = stride.max(1);
    let differ = gpu.chunks(stride).zip(cpu.chunks(stride)).filter(|(a, b)| a != b).count();
    Ok((differ, cpu.len().div_ceil(stride)))
}

pub fn compare_rgb(what: &str, gpu: &[Vec4], cpu: &[Vec4], rel: f32, allowed: usize) -> anyhow::Result<String> {
    anyhow::ensure!(gpu.len() == cpu.len(), "{what}: {} and {} values", gpu.len(), cpu.len());
    let flat = |v: &[Vec4]| v.iter().flat_map(|p| p.truncate().to_array()).collect::<Vec<f32>>();
    let (g, c) = (flat(gpu), flat(cpu));
    let peak = c.iter().fold(0.0f32, |m, v| m.max(*v));
    compare_within(what, &g, &c, peak, rel, allowed)
}

/// `compare_rgb` for plain values (positions, distances), the peak taken
/// over their magnitudes.
pub fn compare_values(what: &str, gpu: &[f32], cpu: &[f32], rel: f32, allowed: usize) -> anyhow::Result<String> {
    anyhow::ensure!(gpu.len() == cpu.len(), "{what}: {} and {} values", gpu.len(), cpu.len());
    let peak = cpu.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    compare_within(what, gpu, cpu, peak, rel, allowed)
}

/// Values differing by more than `rel` of `peak` (or of the value) are
/// outliers; at most `allowed` of them.
fn compare_within(what: &str, g: &[f32], c: &[f32], peak: f32, rel: f32, allowed: usize) -> anyhow::Result<String> {
    let (outliers, worst) = count_differences(g, c, |v| rel * peak.max(v.abs()));
    anyhow::ensure!(
        outliers <= allowed,
        "{what}: {outliers} of {} values differ by more than {rel:e} of the peak",
        c.len()
    );
    Ok(format!("{what}: {} values, {outliers} outliers, worst difference {worst:e} (peak {peak:e})", c.len()))
}
