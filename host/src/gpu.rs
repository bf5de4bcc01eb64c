//! The GPU backend: the SPIR-V kernels run through wgpu (Vulkan).

use anyhow::{anyhow, bail, Context, Result};
use glam::Vec4;
use slicelight_shaders::WORKGROUP_SIZE;
use std::collections::HashMap;

use crate::scene::SceneData;

/// The kernels compiled by `build.rs` from `shader-crate`.
const SPIRV: &[u8] = include_bytes!(env!("SLICELIGHT_SPV"));

/// Entry points of the shader module (`shader-crate/src/lib.rs`) and the
/// bindings each declares. Pipelines take their layouts from the SPIR-V, so a
/// binding listed here that a kernel does not declare (or the reverse) fails
/// at pipeline creation, in the equivalence tests.
pub const KERNELS: &[(&str, &[u32])] = &[
    ("shadow_map_kernel", &[0, 1, 2, 3, 5, 8]),
    ("surface_kernel", &[0, 1, 2, 3, 4, 5, 6, 8]),
    ("shafts_kernel", &[0, 1, 4, 5, 6, 7]),
];

const BINDING_SHADOW: usize = 5;
const MIN_BUFFER_BYTES: u64 = std::mem::size_of::<slicelight_shaders::types::GpuLight>() as u64;
const BINDING_OUTPUT: usize = 6;

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
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    pipelines: HashMap<&'static str, wgpu::ComputePipeline>,
    max_binding_bytes: u64,
    /// Largest image band, bytes: `max_binding_bytes` unless lowered.
    band_limit_bytes: u64,
}

impl GpuContext {
    /// Opens the first Vulkan device wgpu finds (a discrete GPU if there is
    /// one, else lavapipe) and builds every kernel's pipeline.
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
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("slicelight"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .with_context(|| format!("cannot open device {}", info.name))?;
        let pipelines = checked(&device, "building the kernels", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("slicelight kernels"),
                source: wgpu::util::make_spirv(SPIRV),
            });
            KERNELS
                .iter()
                .map(|&(name, _)| {
                    let p = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(name),
                        layout: None,
                        module: &module,
                        entry_point: Some(name),
                        compilation_options: Default::default(),
                        cache: None,
                    });
                    (name, p)
                })
                .collect::<HashMap<_, _>>()
        })?;
        Ok(GpuContext {
            device,
            queue,
            adapter: info,
            pipelines,
            max_binding_bytes: limits.max_storage_buffer_binding_size as u64,
            band_limit_bytes: limits.max_storage_buffer_binding_size as u64,
        })
    }

    pub fn device_name(&self) -> String {
        format!("{} ({:?}, {:?})", self.adapter.name, self.adapter.device_type, self.adapter.backend)
    }

    /// A storage buffer of `bytes` bytes; wgpu zero-fills it.
    fn allocate(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        // wgpu cannot bind an empty buffer, nor one smaller than one element
        // of the array the kernel declares; a stand-in as large as the largest
        // element type is never read because the matching count in
        // FrameParams is 0.
        let size = bytes.max(MIN_BUFFER_BYTES).next_multiple_of(4);
        if size > self.max_binding_bytes {
            bail!(
                "{label} needs {} MiB, more than this device binds in one buffer ({} MiB); lower the resolution",
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

    /// A storage buffer holding `bytes`.
    fn storage(&self, label: &str, bytes: &[u8]) -> Result<wgpu::Buffer> {
        let buffer = self.allocate(label, bytes.len() as u64)?;
        if !bytes.is_empty() {
            self.queue.write_buffer(&buffer, 0, bytes);
        }
        Ok(buffer)
    }

    /// Lowers the image band size (to test the banding on small images).
    pub fn limit_band_bytes(&mut self, bytes: u64) {
        self.band_limit_bytes = bytes.min(self.max_binding_bytes);
    }

    /// Pixels per band: the whole image if one buffer can hold it, else as
    /// many whole rows as fit.
    pub fn band_pixels(&self, data: &SceneData) -> u32 {
        let fit = (self.band_limit_bytes / std::mem::size_of::<Vec4>() as u64).min(u32::MAX as u64) as u32;
        let rows = (fit / data.width()).max(1);
        data.pixel_count().min(rows * data.width())
    }

    /// Uploads a scene's buffers. `shadow` gives the shadow maps' contents
    /// (from another backend, for equivalence tests); otherwise they are left
    /// for `shadow_map_kernel` to fill. The image kernels start on the first
    /// band (see `set_band`).
    pub fn upload(&self, data: &SceneData, shadow: Option<&[f32]>) -> Result<GpuFrame<'_>> {
        let shadow_bytes = data.params.shadow_texel_count as u64 * 4;
        let band_bytes = self.band_pixels(data) as u64 * std::mem::size_of::<Vec4>() as u64;
        let buffers = vec![
            self.storage("params", bytemuck::bytes_of(&data.params))?,
            self.storage("lights", bytemuck::cast_slice(&data.lights))?,
            self.storage("spheres", bytemuck::cast_slice(&data.spheres))?,
            self.storage("triangles", bytemuck::cast_slice(&data.triangles))?,
            self.storage("light maps", bytemuck::cast_slice(&data.light_map))?,
            // Filled by shadow_map_kernel unless given.
            match shadow {
                Some(s) => self.storage("shadow maps", bytemuck::cast_slice(s))?,
                None => self.allocate("shadow maps", shadow_bytes)?,
            },
            // Band parameters and contents are set by `set_band` below.
            self.allocate("image", band_bytes)?,
            self.storage("shaft tables", bytemuck::cast_slice(&data.tables))?,
            self.storage("triangle groups", bytemuck::cast_slice(&data.groups))?,
        ];
        let bind_groups = checked(&self.device, "binding the scene's buffers", || {
            KERNELS
                .iter()
                .map(|&(name, bindings)| {
                    let entries: Vec<_> = bindings
                        .iter()
                        .map(|&i| wgpu::BindGroupEntry {
                            binding: i,
                            resource: buffers[i as usize].as_entire_binding(),
                        })
                        .collect();
                    let layout = self.pipelines[name].get_bind_group_layout(0);
                    let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some(name),
                        layout: &layout,
                        entries: &entries,
                    });
                    (name, group)
                })
                .collect::<HashMap<_, _>>()
        })?;
        let frame = GpuFrame {
            ctx: self,
            buffers,
            bind_groups,
        };
        frame.set_band(data, 0, self.band_pixels(data));
        Ok(frame)
    }
}

/// A scene's buffers on the device.
pub struct GpuFrame<'a> {
    ctx: &'a GpuContext,
    buffers: Vec<wgpu::Buffer>,
    bind_groups: HashMap<&'static str, wgpu::BindGroup>,
}

impl GpuFrame<'_> {
    /// Runs `entry` for `invocations` invocations and waits for it to finish.
    /// Workgroups beyond the per-dimension limit wrap into rows (see
    /// `flat_index` in the shader crate).
    pub fn run(&self, entry: &str, invocations: u32) -> Result<()> {
        if invocations == 0 {
            return Ok(());
        }
        let pipeline = self.ctx.pipelines.get(entry).ok_or_else(|| anyhow!("no kernel named {entry}"))?;
        let groups = invocations.div_ceil(WORKGROUP_SIZE);
        let max = self.ctx.device.limits().max_compute_workgroups_per_dimension;
        let gx = groups.min(max);
        let gy = groups.div_ceil(gx);
        checked(&self.ctx.device, entry, || {
            let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.bind_groups[entry], &[]);
                pass.dispatch_workgroups(gx, gy, 1);
            }
            self.ctx.queue.submit([encoder.finish()]);
        })?;
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| anyhow!("device lost while running {entry}: {e}"))?;
        Ok(())
    }

    fn read(&self, index: usize) -> Result<Vec<u8>> {
        let src = &self.buffers[index];
        let staging = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: src.size(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(src, 0, &staging, 0, src.size());
        self.ctx.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| anyhow!("device lost: {e}"))?;
        rx.recv()?.map_err(|e| anyhow!("cannot map the result buffer: {e}"))?;
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| anyhow!("cannot read the result buffer: {e}"))?
            .to_vec();
        Ok(bytes)
    }

    pub fn read_shadow(&self, texels: usize) -> Result<Vec<f32>> {
        let bytes = self.read(BINDING_SHADOW)?;
        Ok(bytemuck::cast_slice(&bytes[..texels * 4]).to_vec())
    }

    /// Points the image kernels at pixels `start .. start + count` (a band of
    /// whole rows) and clears the image buffer to "no surface".
    pub fn set_band(&self, data: &SceneData, start: u32, count: u32) {
        let mut params = data.params;
        params.band_start = start;
        params.band_pixels = count;
        self.ctx.queue.write_buffer(&self.buffers[0], 0, bytemuck::bytes_of(&params));
        self.write_image(&vec![crate::render::no_surface(); count as usize]);
    }

    /// Replaces the image buffer's contents (for testing a kernel that reads it).
    pub fn write_image(&self, pixels: &[Vec4]) {
        self.ctx
            .queue
            .write_buffer(&self.buffers[BINDING_OUTPUT], 0, bytemuck::cast_slice(pixels));
    }

    pub fn read_image(&self, pixels: usize) -> Result<Vec<Vec4>> {
        let bytes = self.read(BINDING_OUTPUT)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..pixels * 16]))
    }
}
