//! The GPU backend: the SPIR-V kernels of every registered pass, run through
//! wgpu (Vulkan). Buffers are created per resource (by binding), bind groups
//! per pass from the pass's own resource lists; nothing here names a pass.

use anyhow::{anyhow, bail, Context, Result};
use slicelight_shaders::WORKGROUP_SIZE;
use std::collections::HashMap;
use std::time::Instant;

use crate::passes::{Buffer, Frame, Pass, Resource, ResourceKind, COMMON, PASSES};
use crate::scene::SceneData;

/// The kernels, compiled from `shader-crate` by `cargo xtask shaders` and kept
/// in `host/spirv/` (the build script warns when they are older than the sources).
pub const SPIRV: &[u8] = include_bytes!("../spirv/slicelight_shaders.spv");

/// What the error of a buffer too large for the device says (the benches
/// leave such a configuration out of that backend's sweep).
pub const TOO_LARGE: &str = "more than this device binds in one buffer";

/// wgpu cannot bind an empty buffer, nor one smaller than one element of the
/// array the kernel declares; a stand-in as large as the largest element type
/// (`GpuLight`) is never read because the matching count is 0.
const MIN_BUFFER_BYTES: u64 = std::mem::size_of::<slicelight_shaders::types::GpuLight>() as u64;

/// Runs `f` inside validation and out-of-memory error scopes, so that what
/// wgpu reports becomes an error naming `what` instead of a panic in wgpu's
/// default handler.
fn checked<T>(device: &wgpu::Device, what: &str, f: impl FnOnce() -> T) -> Result<T> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let value = f();
    if let Some(e) = pollster::block_on(validation.pop()) {
        bail!("{what}: {e}");
    }
    if let Some(e) = pollster::block_on(oom.pop()) {
        bail!("{what}: out of device memory: {e}");
    }
    Ok(value)
}

pub struct GpuContext {
    instance: wgpu::Instance,
    handle: wgpu::Adapter,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    /// Every registered pass's kernels, in one module.
    module: wgpu::ShaderModule,
    /// The pipelines built so far, by entry point: each is built the first
    /// time a frame runs it (`pipeline`), so that a scene pays only for the
    /// kernels it runs (on lavapipe, building all of them took 0.94 s; Fig. 6
    /// runs three, 0.12 s of it).
    pipelines: std::sync::Mutex<HashMap<&'static str, wgpu::ComputePipeline>>,
    max_binding_bytes: u64,
    /// Largest image band, bytes: `max_binding_bytes` unless lowered.
    band_limit_bytes: u64,
    /// Offsets of storage-buffer bindings are multiples of this (`Batch`'s parameter blocks).
    storage_alignment: u64,
    /// Workgroups per dispatch dimension.
    max_workgroups: u32,
    /// Whether per-pass times come from timestamp queries.
    timestamps: bool,
}

impl GpuContext {
    /// Opens the first Vulkan device wgpu finds (a discrete GPU if there is
    /// one, else lavapipe) and loads the kernels; pipelines are built when
    /// a frame first needs them.
    pub fn new() -> Result<Self> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| {
            anyhow!(
                "no Vulkan device found ({e}); install a Vulkan driver (on Debian: apt-get install mesa-vulkan-drivers libvulkan1 for lavapipe) or use --backend cpu"
            )
        })?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let required_features = if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("slicelight"),
            required_limits: limits.clone(),
            required_features,
            ..Default::default()
        }))
        .with_context(|| format!("cannot open device {}", info.name))?;
        let module = checked(&device, "loading the kernels", || {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("slicelight kernels"),
                source: wgpu::util::make_spirv(SPIRV),
            })
        })?;
        Ok(GpuContext {
            instance,
            handle: adapter,
            device,
            queue,
            adapter: info,
            module,
            pipelines: Default::default(),
            max_binding_bytes: limits.max_storage_buffer_binding_size as u64,
            band_limit_bytes: limits.max_storage_buffer_binding_size as u64,
            storage_alignment: limits.min_storage_buffer_offset_alignment.max(4) as u64,
            max_workgroups: limits.max_compute_workgroups_per_dimension,
            timestamps,
        })
    }

    /// The instance, adapter, device and queue: for presenting in a window
    /// with the device that renders (the viewer's wgpu surface).
    pub fn handles(&self) -> (wgpu::Instance, wgpu::Adapter, wgpu::Device, wgpu::Queue) {
        (self.instance.clone(), self.handle.clone(), self.device.clone(), self.queue.clone())
    }

    pub fn device_name(&self) -> String {
        format!("{} ({:?}, {:?})", self.adapter.name, self.adapter.device_type, self.adapter.backend)
    }

    /// Whether per-pass times are the device's own (timestamp queries).
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    /// The pipeline of `pass`'s entry point `kernel` (its `kernel` or one of
    /// its `variants`), built on first use. The layout comes from the
    /// resources the pass declares, the same for all its entry points (a
    /// variant may leave some unused).
    fn pipeline(&self, pass: &dyn Pass, kernel: &'static str) -> Result<wgpu::ComputePipeline> {
        let bindings: Vec<_> = pass
            .reads()
            .iter()
            .map(|r| (r.binding, true))
            .chain(pass.writes().iter().map(|r| (r.binding, false)))
            .collect();
        self.built_pipeline(pass.name(), kernel, &bindings)
    }

    /// The pipeline of entry point `kernel` with storage buffers at
    /// `bindings` (binding, read-only), built on first use and kept.
    fn built_pipeline(
        &self,
        label: &str,
        kernel: &'static str,
        bindings: &[(u32, bool)],
    ) -> Result<wgpu::ComputePipeline> {
        let mut built = self.pipelines.lock().map_err(|_| anyhow!("a thread building a pipeline panicked"))?;
        if let Some(p) = built.get(kernel) {
            return Ok(p.clone());
        }
        let pipeline = checked(&self.device, &format!("building the kernel {kernel}"), || {
            let entries: Vec<_> = bindings
                .iter()
                .map(|&(binding, read_only)| wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                })
                .collect();
            let group = self
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
            let layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(&group)],
                immediate_size: 0,
            });
            self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(kernel),
                layout: Some(&layout),
                module: &self.module,
                entry_point: Some(kernel),
                compilation_options: Default::default(),
                cache: None,
            })
        })?;
        built.insert(kernel, pipeline.clone());
        Ok(pipeline)
    }

    /// Builds the pipelines `passes` run for `scene` that are not built yet
    /// (`frame` would build them on first use; a render builds them before
    /// it starts its clock, so that frame times leave out this one-time cost).
    pub fn prepare(&self, scene: &SceneData, passes: &[&'static dyn Pass]) -> Result<()> {
        for pass in passes {
            self.pipeline(*pass, pass.kernel_for(scene))?;
        }
        Ok(())
    }

    /// The entry points whose pipelines have been built so far.
    pub fn built_kernels(&self) -> Vec<&'static str> {
        self.pipelines.lock().map(|p| p.keys().copied().collect()).unwrap_or_default()
    }

    /// A storage buffer of `bytes` bytes; wgpu zero-fills it. Larger than
    /// the device binds: an error that says `TOO_LARGE`.
    fn allocate(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        let size = bytes.max(MIN_BUFFER_BYTES).next_multiple_of(4);
        if size > self.max_binding_bytes {
            bail!(
                "{label} needs {} MiB, {TOO_LARGE} ({} MiB); lower the resolution",
                size >> 20,
                self.max_binding_bytes >> 20
            );
        }
        checked(&self.device, label, || {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        })
    }

    /// Lowers the image band size (to test the banding on small images).
    pub fn limit_band_bytes(&mut self, bytes: u64) {
        self.band_limit_bytes = bytes.min(self.max_binding_bytes);
    }

    /// Whether the device is Vulkan on the CPU (lavapipe, SwiftShader).
    pub fn runs_on_the_cpu(&self) -> bool {
        self.adapter.device_type == wgpu::DeviceType::Cpu
    }

    /// Pixels per band: the whole image if every per-pixel buffer fits in
    /// one binding, else as many whole rows as fit.
    pub fn band_pixels(&self, data: &SceneData) -> u32 {
        let widest = PASSES
            .iter()
            .flat_map(|p| p.reads().iter().chain(p.writes()))
            .filter_map(|r| r.bytes_per_pixel())
            .max()
            .unwrap_or(16);
        let fit = (self.band_limit_bytes / widest).min(u32::MAX as u64) as u32;
        let rows = (fit / data.width()).max(1);
        data.pixel_count().min(rows * data.width())
    }

    /// Creates the buffers and bind groups of `passes` for a scene. Frame
    /// and per-pixel resources found in `inputs` (another backend's results,
    /// for equivalence tests) are uploaded; per-pixel resources none of the
    /// passes writes are filled with their blank. The per-pixel passes start
    /// on the first band, sample 0 (see `set_band`).
    pub fn frame<'a>(
        &'a self,
        scene: &SceneData,
        passes: &[&'static dyn Pass],
        inputs: Option<&Frame>,
    ) -> Result<GpuFrame<'a>> {
        let band = self.band_pixels(scene);
        let written: Vec<u32> = passes.iter().flat_map(|p| p.writes()).map(|r| r.binding).collect();
        let mut buffers: HashMap<u32, wgpu::Buffer> = HashMap::new();
        for r in passes.iter().flat_map(|p| p.reads().iter().chain(p.writes())) {
            if buffers.contains_key(&r.binding) {
                continue;
            }
            let given = inputs.and_then(|f| f.bytes(r));
            let buffer = match r.kind {
                ResourceKind::Scene(bytes) => self.storage(r.name, bytes(scene))?,
                ResourceKind::Frame(len) => match given {
                    Some(bytes) => self.storage(r.name, bytes)?,
                    None => self.allocate(r.name, len(scene))?,
                },
                ResourceKind::PerPixel { .. } => {
                    let bpp = r.bytes_per_pixel().unwrap_or(16);
                    let buffer = self.allocate(r.name, band as u64 * bpp)?;
                    match given {
                        Some(bytes) => {
                            ensure_one_band(scene, band, r)?;
                            self.queue.write_buffer(&buffer, 0, bytes);
                        }
                        None if !written.contains(&r.binding) => {
                            let blank = r.blank(band as usize).expect("per-pixel");
                            self.queue.write_buffer(&buffer, 0, blank.as_bytes());
                        }
                        None => {}
                    }
                    buffer
                }
            };
            buffers.insert(r.binding, buffer);
        }
        let pipelines = passes
            .iter()
            .map(|pass| Ok((pass.name(), self.pipeline(*pass, pass.kernel_for(scene))?)))
            .collect::<Result<HashMap<_, _>>>()?;
        let bind_groups = checked(&self.device, "binding the scene's buffers", || {
            passes
                .iter()
                .map(|pass| {
                    let entries: Vec<_> = pass
                        .reads()
                        .iter()
                        .chain(pass.writes())
                        .map(|r| wgpu::BindGroupEntry {
                            binding: r.binding,
                            resource: buffers[&r.binding].as_entire_binding(),
                        })
                        .collect();
                    let layout = pipelines[pass.name()].get_bind_group_layout(0);
                    let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(pass.name()),
                        layout: &layout,
                        entries: &entries,
                    });
                    (pass.name(), group)
                })
                .collect::<HashMap<_, _>>()
        })?;
        let repeats = passes.iter().map(|p| (p.name(), p.repeats(scene).max(1))).collect();
        let frame = GpuFrame { ctx: self, common: scene.common, buffers, bind_groups, pipelines, repeats };
        frame.set_band(0, band, 0);
        Ok(frame)
    }

    /// A storage buffer holding `bytes`.
    fn storage(&self, label: &str, bytes: &[u8]) -> Result<wgpu::Buffer> {
        let buffer = self.allocate(label, bytes.len() as u64)?;
        if !bytes.is_empty() {
            self.queue.write_buffer(&buffer, 0, bytes);
        }
        Ok(buffer)
    }

    fn wait(&self, what: &str) -> Result<()> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| anyhow!("device lost while {what}: {e}"))?;
        Ok(())
    }

    /// Copies the first `bytes` of `src` to a mappable buffer and returns them.
    fn read_buffer(&self, src: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        // Copies move whole 4-byte words; every element type is made of them.
        let size = bytes.next_multiple_of(4).min(src.size());
        if size == 0 {
            return Ok(Vec::new());
        }
        let staging = self.staging(size);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(src, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        self.map_staging(&staging, bytes)
    }

    /// A mappable buffer of `size` bytes to copy a result into.
    fn staging(&self, size: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// The workgroups `(x, y)` of a dispatch of `invocations`: rows of at
    /// most the per-dimension limit (the kernels' `flat_index` undoes it).
    fn workgroups(&self, invocations: u32) -> (u32, u32) {
        let groups = invocations.div_ceil(WORKGROUP_SIZE);
        let gx = groups.min(self.max_workgroups).max(1);
        (gx, groups.div_ceil(gx))
    }

    /// The first `bytes` of a mappable buffer whose copy has been submitted.
    fn map_staging(&self, staging: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait("reading a result")?;
        rx.recv()?.map_err(|e| anyhow!("cannot map the result buffer: {e}"))?;
        let view = slice.get_mapped_range().map_err(|e| anyhow!("cannot read the result buffer: {e}"))?;
        Ok(view[..bytes as usize].to_vec())
    }
}

fn ensure_one_band(scene: &SceneData, band: u32, r: &Resource) -> Result<()> {
    if band < scene.pixel_count() {
        bail!("{}: a given per-pixel input must fit in one band ({} of {} pixels)", r.name, band, scene.pixel_count());
    }
    Ok(())
}

/// A scene's buffers on the device, for a set of passes.
pub struct GpuFrame<'a> {
    ctx: &'a GpuContext,
    common: slicelight_shaders::types::CommonParams,
    buffers: HashMap<u32, wgpu::Buffer>,
    bind_groups: HashMap<&'static str, wgpu::BindGroup>,
    /// The pipeline each pass runs for this scene (its `Pass::kernel_for`).
    pipelines: HashMap<&'static str, wgpu::ComputePipeline>,
    /// Dispatches per run of each pass (`Pass::repeats`).
    repeats: HashMap<&'static str, u32>,
}

impl GpuFrame<'_> {
    /// Points the per-pixel passes at pixels `start .. start + count` (a
    /// band of whole rows) and sub-pixel sample `sample`.
    pub fn set_band(&self, start: u32, count: u32, sample: u32) {
        // A frame of passes that do not read the common block has none.
        let Some(buffer) = self.buffers.get(&COMMON.binding) else {
            return;
        };
        let mut common = self.common;
        common.band_start = start;
        common.band_pixels = count;
        common.sample_index = sample;
        self.ctx.queue.write_buffer(buffer, 0, bytemuck::bytes_of(&common));
    }

    /// Runs `passes` (each with its invocation count) in order, in one
    /// submission, and waits. Returns each pass's seconds: the device's own
    /// timestamps where it has them, else the wall time of a submission per
    /// pass.
    pub fn run(&self, passes: &[(&'static dyn Pass, u32)]) -> Result<Vec<f64>> {
        let passes: Vec<_> = passes.iter().filter(|(_, n)| *n > 0).collect();
        if passes.is_empty() {
            return Ok(Vec::new());
        }
        if !self.ctx.timestamps {
            return passes
                .iter()
                .map(|&&(pass, n)| {
                    let t = Instant::now();
                    self.submit(&[(pass, n)], None)?;
                    Ok(t.elapsed().as_secs_f64())
                })
                .collect();
        }
        let count = 2 * passes.len() as u32;
        let query_set = self.ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass times"),
            ty: wgpu::QueryType::Timestamp,
            count,
        });
        let resolve = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pass times"),
            size: count as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let list: Vec<_> = passes.iter().map(|&&p| p).collect();
        self.submit(&list, Some((&query_set, &resolve)))?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&self.ctx.read_buffer(&resolve, count as u64 * 8)?);
        let period = self.ctx.queue.get_timestamp_period() as f64 * 1e-9;
        Ok(ticks.chunks(2).map(|t| t[1].saturating_sub(t[0]) as f64 * period).collect())
    }

    fn submit(
        &self,
        passes: &[(&'static dyn Pass, u32)],
        timing: Option<(&wgpu::QuerySet, &wgpu::Buffer)>,
    ) -> Result<()> {
        let names: Vec<_> = passes.iter().map(|(p, _)| p.name()).collect();
        checked(&self.ctx.device, &format!("running {}", names.join(", ")), || {
            let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
            for (k, &(pass, invocations)) in passes.iter().enumerate() {
                let (gx, gy) = self.ctx.workgroups(invocations);
                // A stepped pass dispatches once per step, copying what a
                // step wrote over what the next one reads (`Pass::carry`);
                // its time spans all steps.
                let steps = self.repeats.get(pass.name()).copied().unwrap_or(1);
                for step in 0..steps {
                    let (first, last) = (step == 0, step + 1 == steps);
                    let timestamp_writes =
                        timing.filter(|_| first || last).map(|(set, _)| wgpu::ComputePassTimestampWrites {
                            query_set: set,
                            beginning_of_pass_write_index: first.then_some(2 * k as u32),
                            end_of_pass_write_index: last.then_some(2 * k as u32 + 1),
                        });
                    {
                        let mut cpass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                            label: Some(pass.name()),
                            timestamp_writes,
                        });
                        cpass.set_pipeline(&self.pipelines[pass.name()]);
                        cpass.set_bind_group(0, &self.bind_groups[pass.name()], &[]);
                        cpass.dispatch_workgroups(gx, gy, 1);
                    }
                    for (from, to) in pass.carry() {
                        let (a, b) = (&self.buffers[&from.binding], &self.buffers[&to.binding]);
                        encoder.copy_buffer_to_buffer(a, 0, b, 0, a.size().min(b.size()));
                    }
                }
            }
            if let Some((set, resolve)) = timing {
                encoder.resolve_query_set(set, 0..2 * passes.len() as u32, resolve, 0);
            }
            self.ctx.queue.submit([encoder.finish()]);
        })?;
        self.ctx.wait(&format!("running {}", names.join(", ")))
    }

    /// Reads `r` back: `bytes` long (a per-pixel resource: the band's pixels).
    pub fn read(&self, r: &Resource, bytes: u64) -> Result<Buffer> {
        let buffer = self.buffers.get(&r.binding).ok_or_else(|| anyhow!("{} is not bound in this frame", r.name))?;
        Ok(Buffer::from_bytes(&self.ctx.read_buffer(buffer, bytes)?))
    }
}

/// A kernel a family dispatches itself, outside a frame's passes (a
/// simulation's step: the fluid solver): its entry point, the bindings it
/// reads and those it writes. Families list theirs in `Family::kernels`; a
/// test checks them against the SPIR-V as it checks the passes.
pub struct Kernel {
    pub name: &'static str,
    pub reads: &'static [u32],
    pub writes: &'static [u32],
}

/// Dispatches of `Kernel`s, copies and clears, recorded in order and run
/// as one submission (`GpuContext::batch`). Each dispatch binds its own
/// buffers (the same binding may be `u` in one and the temperature in the
/// next) and its own parameter block, which the batch packs into one
/// buffer at the device's offset alignment.
pub struct Batch<'a> {
    ctx: &'a GpuContext,
    params: Vec<u8>,
    commands: Vec<Command>,
}

enum Command {
    Dispatch {
        kernel: &'static Kernel,
        params_binding: u32,
        params: std::ops::Range<u64>,
        buffers: Vec<(u32, wgpu::Buffer)>,
        invocations: u32,
    },
    Copy {
        from: wgpu::Buffer,
        to: wgpu::Buffer,
        bytes: u64,
    },
    Clear(wgpu::Buffer),
}

impl GpuContext {
    /// A storage buffer holding `contents` (at least one element long).
    pub fn array(&self, label: &str, contents: &[u8]) -> Result<wgpu::Buffer> {
        self.storage(label, contents)
    }

    /// A zero-filled storage buffer of `bytes`.
    pub fn zeroed(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        self.allocate(label, bytes)
    }

    /// Overwrites the start of `buffer` with `contents` (before the next submission's work).
    pub fn upload(&self, buffer: &wgpu::Buffer, contents: &[u8]) {
        if !contents.is_empty() {
            self.queue.write_buffer(buffer, 0, contents);
        }
    }

    /// The first `bytes` of `buffer`.
    pub fn download(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        self.read_buffer(buffer, bytes)
    }

    /// An empty batch of kernel dispatches.
    pub fn batch(&self) -> Batch<'_> {
        Batch { ctx: self, params: Vec::new(), commands: Vec::new() }
    }

    /// The pipeline of a family's own kernel, built on first use; its
    /// layout from the kernel's reads and writes.
    fn kernel_pipeline(&self, kernel: &Kernel) -> Result<wgpu::ComputePipeline> {
        let bindings: Vec<_> =
            kernel.reads.iter().map(|b| (*b, true)).chain(kernel.writes.iter().map(|b| (*b, false))).collect();
        self.built_pipeline(kernel.name, kernel.name, &bindings)
    }
}

impl Batch<'_> {
    /// Dispatches `kernel` over `invocations` with `params` at
    /// `params_binding` and `buffers` at the other bindings it declares.
    pub fn dispatch<P: bytemuck::Pod>(
        &mut self,
        kernel: &'static Kernel,
        params_binding: u32,
        params: &P,
        buffers: &[(u32, &wgpu::Buffer)],
        invocations: u32,
    ) {
        let align = self.ctx.storage_alignment as usize;
        let start = self.params.len().next_multiple_of(align);
        self.params.resize(start, 0);
        self.params.extend_from_slice(bytemuck::bytes_of(params));
        self.commands.push(Command::Dispatch {
            kernel,
            params_binding,
            params: start as u64..self.params.len() as u64,
            buffers: buffers.iter().map(|(b, buf)| (*b, (*buf).clone())).collect(),
            invocations,
        });
    }

    /// Copies the first `bytes` of `from` over `to`.
    pub fn copy(&mut self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64) {
        self.commands.push(Command::Copy { from: from.clone(), to: to.clone(), bytes: bytes.next_multiple_of(4) });
    }

    /// Fills `buffer` with zeros.
    pub fn clear(&mut self, buffer: &wgpu::Buffer) {
        self.commands.push(Command::Clear(buffer.clone()));
    }

    /// Runs what was recorded, in order, and waits.
    pub fn submit(self) -> Result<()> {
        self.run(None).map(|_| ())
    }

    /// Runs what was recorded, then reads the first `bytes` of `buffer`,
    /// in the same submission (a reduction's partial sums).
    pub fn submit_reading(self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        self.run(Some((buffer, bytes)))
    }

    fn run(self, read: Option<(&wgpu::Buffer, u64)>) -> Result<Vec<u8>> {
        let ctx = self.ctx;
        if self.commands.is_empty() {
            return match read {
                Some((buffer, bytes)) => ctx.read_buffer(buffer, bytes),
                None => Ok(Vec::new()),
            };
        }
        let staging = read.map(|(_, bytes)| ctx.staging(bytes.next_multiple_of(4).max(4)));
        let arena = ctx.storage("kernel parameters", &self.params)?;
        // Every binding given before anything is created.
        for c in &self.commands {
            if let Command::Dispatch { kernel, params_binding, buffers, .. } = c {
                for b in kernel.reads.iter().chain(kernel.writes).filter(|b| **b != *params_binding) {
                    if !buffers.iter().any(|(k, _)| k == b) {
                        bail!("{}: nothing bound at binding {b}", kernel.name);
                    }
                }
                for (b, _) in buffers {
                    if !kernel.reads.contains(b) && !kernel.writes.contains(b) {
                        bail!("{}: binding {b} given, but the kernel declares no such binding", kernel.name);
                    }
                }
            }
        }
        let pipelines = self
            .commands
            .iter()
            .map(|c| match c {
                Command::Dispatch { kernel, .. } => ctx.kernel_pipeline(kernel).map(Some),
                _ => Ok(None),
            })
            .collect::<Result<Vec<_>>>()?;
        let groups = checked(&ctx.device, "binding a batch of kernels", || {
            self.commands
                .iter()
                .zip(pipelines)
                .map(|(c, pipeline)| {
                    let (Command::Dispatch { kernel, params_binding, params, buffers, .. }, Some(pipeline)) =
                        (c, pipeline)
                    else {
                        return None;
                    };
                    let mut entries = vec![wgpu::BindGroupEntry {
                        binding: *params_binding,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &arena,
                            offset: params.start,
                            size: std::num::NonZeroU64::new(params.end - params.start),
                        }),
                    }];
                    for b in kernel.reads.iter().chain(kernel.writes).filter(|b| **b != *params_binding) {
                        let (_, buffer) = buffers.iter().find(|(k, _)| k == b).expect("checked above");
                        entries.push(wgpu::BindGroupEntry { binding: *b, resource: buffer.as_entire_binding() });
                    }
                    let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(kernel.name),
                        layout: &pipeline.get_bind_group_layout(0),
                        entries: &entries,
                    });
                    Some((pipeline, group))
                })
                .collect::<Vec<_>>()
        })?;
        checked(&ctx.device, "running a batch of kernels", || {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            for (c, bound) in self.commands.iter().zip(&groups) {
                match (c, bound) {
                    (Command::Dispatch { kernel, invocations, .. }, Some((pipeline, group))) => {
                        if *invocations == 0 {
                            continue;
                        }
                        let (gx, gy) = ctx.workgroups(*invocations);
                        let mut cpass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                            label: Some(kernel.name),
                            timestamp_writes: None,
                        });
                        cpass.set_pipeline(pipeline);
                        cpass.set_bind_group(0, group, &[]);
                        cpass.dispatch_workgroups(gx, gy, 1);
                    }
                    (Command::Copy { from, to, bytes }, _) => {
                        let size = (*bytes).min(from.size()).min(to.size());
                        encoder.copy_buffer_to_buffer(from, 0, to, 0, size);
                    }
                    (Command::Clear(buffer), _) => encoder.clear_buffer(buffer, 0, None),
                    _ => {}
                }
            }
            if let (Some((buffer, _)), Some(staging)) = (read, &staging) {
                encoder.copy_buffer_to_buffer(buffer, 0, staging, 0, staging.size().min(buffer.size()));
            }
            ctx.queue.submit([encoder.finish()]);
        })?;
        ctx.wait("running a batch of kernels")?;
        match (read, staging) {
            (Some((_, bytes)), Some(staging)) => ctx.map_staging(&staging, bytes),
            _ => Ok(Vec::new()),
        }
    }
}
