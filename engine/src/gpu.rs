//! One wgpu instance, adapter, device and queue per process ([`GpuContext::global`]).
//!
//! Adapter choice: `FACTORY_ADAPTER=gpu` takes a hardware adapter, `cpu` a software one (Mesa's lavapipe),
//! any other value the first adapter whose name contains it (case-insensitive). Unset, a hardware adapter
//! is preferred and lavapipe is the fallback. The device is created with the adapter's full limits and
//! the features burn's cubecl-wgpu may use, so the learner shares it (docs/ARCHITECTURE.md section 2); the
//! engine's own needs ([`REQUIRED_LIMITS`]) are checked first and a shortfall names the limit.

use crate::error::{EngineError, Result};
use bytemuck::Pod;
use std::sync::OnceLock;

pub mod layout;

/// Environment variable that selects the adapter: `gpu`, `cpu`, or a substring of the adapter name.
pub const ADAPTER_ENV: &str = "FACTORY_ADAPTER";

/// Hint printed when no adapter exists at all.
pub const INSTALL_HINT: &str = "install a Vulkan driver: on Debian/Ubuntu `apt-get install mesa-vulkan-drivers` \
     (Mesa's software rasteriser lavapipe runs the engine on any CPU); on Fedora `dnf install mesa-vulkan-drivers`";

/// The limits the engine's kernels need: (name, minimum, getter). Checked against the adapter before the
/// device is requested, so a short adapter fails with the limit's name instead of a validation panic.
pub const REQUIRED_LIMITS: &[(&str, u64, fn(&wgpu::Limits) -> u64)] = &[
    ("max_storage_buffers_per_shader_stage", 8, |l| l.max_storage_buffers_per_shader_stage as u64),
    ("max_compute_invocations_per_workgroup", 256, |l| l.max_compute_invocations_per_workgroup as u64),
    ("max_compute_workgroup_size_x", 256, |l| l.max_compute_workgroup_size_x as u64),
    ("max_compute_workgroup_storage_size", 16384, |l| l.max_compute_workgroup_storage_size as u64),
    ("max_storage_buffer_binding_size", 128 << 20, |l| l.max_storage_buffer_binding_size),
    ("max_bind_groups", 3, |l| l.max_bind_groups as u64),
];

/// How the adapter is chosen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AdapterChoice {
    /// A hardware adapter if there is one, else a software one.
    Auto,
    /// Hardware only (discrete, integrated or virtual GPU).
    Gpu,
    /// Software only (lavapipe / llvmpipe / WARP).
    Cpu,
    /// The first adapter whose name contains this text (case-insensitive).
    Name(String),
}

impl AdapterChoice {
    /// Reads [`ADAPTER_ENV`]; unset or empty means [`AdapterChoice::Auto`].
    pub fn from_env() -> Self {
        match std::env::var(ADAPTER_ENV).ok().as_deref().map(str::trim) {
            None | Some("") | Some("auto") => AdapterChoice::Auto,
            Some(s) if s.eq_ignore_ascii_case("gpu") => AdapterChoice::Gpu,
            Some(s) if s.eq_ignore_ascii_case("cpu") => AdapterChoice::Cpu,
            Some(s) => AdapterChoice::Name(s.to_string()),
        }
    }
}

/// The process-wide GPU handles.
pub struct GpuContext {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Name, backend and type of the chosen adapter.
    pub info: wgpu::AdapterInfo,
}

static GLOBAL: OnceLock<std::result::Result<GpuContext, String>> = OnceLock::new();

fn is_hardware(t: wgpu::DeviceType) -> bool {
    matches!(t, wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu | wgpu::DeviceType::VirtualGpu)
}

/// Picks an adapter from `(name, type)` descriptions; pure so the rules are unit-tested without a GPU.
pub fn pick_adapter(adapters: &[(String, wgpu::DeviceType)], choice: &AdapterChoice) -> Option<usize> {
    let find = |f: &dyn Fn(&(String, wgpu::DeviceType)) -> bool| adapters.iter().position(f);
    // Rank discrete over integrated over virtual GPUs.
    let best_hw = || {
        [wgpu::DeviceType::DiscreteGpu, wgpu::DeviceType::IntegratedGpu, wgpu::DeviceType::VirtualGpu]
            .iter()
            .find_map(|t| find(&|a| a.1 == *t))
    };
    match choice {
        AdapterChoice::Gpu => best_hw(),
        AdapterChoice::Cpu => find(&|a| a.1 == wgpu::DeviceType::Cpu),
        AdapterChoice::Name(n) => {
            let n = n.to_lowercase();
            find(&|a| a.0.to_lowercase().contains(&n))
        }
        AdapterChoice::Auto => best_hw().or_else(|| find(&|a| a.1 == wgpu::DeviceType::Cpu)).or_else(|| {
            if adapters.is_empty() {
                None
            } else {
                Some(0)
            }
        }),
    }
}

impl GpuContext {
    /// The process-wide context, created on first use with [`AdapterChoice::from_env`].
    pub fn global() -> Result<&'static GpuContext> {
        GLOBAL
            .get_or_init(|| GpuContext::new(&AdapterChoice::from_env()).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|e| EngineError::Gpu(e.clone()))
    }

    /// Creates a new context. Prefer [`GpuContext::global`]: wgpu devices are heavy, and the trainer
    /// shares one with burn.
    pub fn new(choice: &AdapterChoice) -> Result<Self> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12,
            ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
        });
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let described: Vec<(String, wgpu::DeviceType)> =
            adapters.iter().map(|a| (a.get_info().name, a.get_info().device_type)).collect();
        if adapters.is_empty() {
            return Err(EngineError::Gpu(format!("no GPU or software adapter found; {INSTALL_HINT}")));
        }
        let Some(idx) = pick_adapter(&described, choice) else {
            let list: Vec<String> = described.iter().map(|(n, t)| format!("{n} ({t:?})")).collect();
            return Err(EngineError::Gpu(format!(
                "{ADAPTER_ENV}={choice:?} matches no adapter; available: {}; valid values: gpu, cpu, or a name substring",
                list.join(", ")
            )));
        };
        let adapter = adapters.into_iter().nth(idx).expect("index from pick_adapter");
        let info = adapter.get_info();
        let limits = adapter.limits();
        check_limits(&info.name, &limits)?;
        // Full adapter limits and every feature cubecl-wgpu 0.11 reads off the adapter to pick its kernels
        // (backend/wgsl.rs `register_wgsl_features`, runtime.rs), so burn can share this device: a kernel
        // it compiles for a feature the adapter has but the device lacks fails validation (lavapipe has
        // SHADER_FLOAT32_ATOMIC, and burn's sum reduction uses it).
        let wanted = wgpu::Features::SHADER_F16
            | wgpu::Features::SHADER_F64
            | wgpu::Features::SHADER_INT64
            | wgpu::Features::SHADER_FLOAT32_ATOMIC
            | wgpu::Features::SUBGROUP;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("factory-engine"),
            required_features: adapter.features() & wanted,
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| EngineError::Gpu(format!("adapter {:?} refused a device: {e}", info.name)))?;
        log::info!("factory-engine on {} ({:?}, {:?})", info.name, info.device_type, info.backend);
        Ok(GpuContext { instance, adapter, device, queue, info })
    }

    /// True when running on a software rasteriser (lavapipe): used by benchmarks to label results.
    pub fn is_software(&self) -> bool {
        !is_hardware(self.info.device_type)
    }

    /// Limits of the device (the adapter's full limits).
    pub fn limits(&self) -> wgpu::Limits {
        self.device.limits()
    }

    /// A storage buffer initialised with `data` (at least 4 bytes, so empty arrays still bind).
    pub fn storage_buffer<T: Pod>(&self, label: &str, data: &[T], extra_usage: wgpu::BufferUsages) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let padded;
        let contents = if bytes.len() < 4 {
            padded = vec![0u8; 4];
            &padded[..]
        } else {
            bytes
        };
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC
                | extra_usage,
        })
    }

    /// A uniform buffer holding `bytes`.
    pub fn uniform_buffer(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }

    /// An uninitialised (zeroed) storage buffer of `bytes` bytes.
    pub fn storage_buffer_zeroed(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4).next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    /// Bind group `index` of `pipeline` with `buffers` at bindings 0, 1, ... (whole buffers).
    pub fn bind_group(
        &self,
        pipeline: &wgpu::ComputePipeline,
        index: u32,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(index),
            entries: &buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                .collect::<Vec<_>>(),
        })
    }

    /// Bind groups 0, 1, ... of `pipeline`, group i with the buffers of `groups[i]` at bindings 0, 1, ...
    /// (see [`bind_group`](Self::bind_group)), created in that order.
    pub fn bind_groups<const N: usize>(
        &self,
        pipeline: &wgpu::ComputePipeline,
        groups: [&[&wgpu::Buffer]; N],
    ) -> [wgpu::BindGroup; N] {
        std::array::from_fn(|i| self.bind_group(pipeline, i as u32, groups[i]))
    }

    /// An explicit pipeline layout: one bind group layout per entry of `groups`, each a list of
    /// bindings 0, 1, ... (compute stage). Pipelines built on one explicit layout share bind groups, and a
    /// dynamic-offset uniform selects per-dispatch parameters (the automatic layouts of
    /// [`bind_group`](Self::bind_group) allow neither).
    pub fn explicit_layout(&self, label: &str, groups: &[&[Binding]]) -> ExplicitLayout {
        let groups: Vec<wgpu::BindGroupLayout> = groups
            .iter()
            .map(|bindings| {
                let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
                    .iter()
                    .enumerate()
                    .map(|(i, b)| wgpu::BindGroupLayoutEntry {
                        binding: i as u32,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::Buffer {
                            ty: match b {
                                Binding::Uniform | Binding::UniformDynamic => wgpu::BufferBindingType::Uniform,
                                Binding::Storage { read_only } => {
                                    wgpu::BufferBindingType::Storage { read_only: *read_only }
                                }
                            },
                            has_dynamic_offset: matches!(b, Binding::UniformDynamic),
                            min_binding_size: None,
                        },
                        count: None,
                    })
                    .collect();
                self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(label),
                    entries: &entries,
                })
            })
            .collect();
        let refs: Vec<Option<&wgpu::BindGroupLayout>> = groups.iter().map(Some).collect();
        let pipeline = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &refs,
            immediate_size: 0,
        });
        ExplicitLayout { groups, pipeline }
    }

    /// A compute pipeline for entry point `entry` of `source` on an explicit layout.
    pub fn pipeline_on(
        &self,
        layout: &ExplicitLayout,
        label: &str,
        source: &str,
        entry: &str,
    ) -> wgpu::ComputePipeline {
        self.pipeline_on_with(layout, label, source, entry, &[])
    }

    /// [`pipeline_on`](Self::pipeline_on) with values for the module's `override` constants.
    pub fn pipeline_on_with(
        &self,
        layout: &ExplicitLayout,
        label: &str,
        source: &str,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> wgpu::ComputePipeline {
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&layout.pipeline),
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        })
    }

    /// Bind group `index` of an explicit layout with `buffers` at bindings 0, 1, ...; a dynamic-offset
    /// uniform binds `dynamic_size` bytes of its buffer (the offset is given at dispatch).
    pub fn bind_explicit(
        &self,
        layout: &ExplicitLayout,
        index: usize,
        buffers: &[&wgpu::Buffer],
        dynamic_size: u64,
    ) -> wgpu::BindGroup {
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &layout.groups[index],
            entries: &buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: if dynamic_size > 0 {
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: b,
                            offset: 0,
                            size: std::num::NonZeroU64::new(dynamic_size),
                        })
                    } else {
                        b.as_entire_binding()
                    },
                })
                .collect::<Vec<_>>(),
        })
    }

    /// Copies `buffer` back to the host and waits. For tests, benchmarks and logging; never in a step loop.
    pub fn read_buffer<T: Pod>(&self, buffer: &wgpu::Buffer) -> Vec<T> {
        self.read_buffer_prefix(buffer, buffer.size())
    }

    /// Like [`read_buffer`](Self::read_buffer), but only the first `bytes` bytes (rounded up to 4).
    pub fn read_buffer_prefix<T: Pod>(&self, buffer: &wgpu::Buffer, bytes: u64) -> Vec<T> {
        self.read_buffer_range(buffer, 0, bytes)
    }

    /// Like [`read_buffer`](Self::read_buffer), but only `bytes` bytes (rounded up to 4) from byte `offset`
    /// (a multiple of 4).
    pub fn read_buffer_range<T: Pod>(&self, buffer: &wgpu::Buffer, offset: u64, bytes: u64) -> Vec<T> {
        HOST_SYNCS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let size = bytes.next_multiple_of(4).min(buffer.size().saturating_sub(offset));
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("device lost while reading back a buffer");
        rx.recv().expect("map callback").expect("buffer map failed");
        let view = staging.get_mapped_range(..).expect("mapped range");
        let n = view.len() / std::mem::size_of::<T>();
        let out = bytemuck::cast_slice::<u8, T>(&view[..n * std::mem::size_of::<T>()]).to_vec();
        drop(view);
        staging.unmap();
        out
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) {
        HOST_SYNCS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("device lost");
    }
}

/// Readbacks and waits for the device, every [`GpuContext`] together.
static HOST_SYNCS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many times the host has read a buffer back ([`GpuContext::read_buffer`] and its variants) or waited for
/// the device ([`GpuContext::wait`]) in this process: a test of a device-resident loop counts them before and
/// after (the count is process-wide, so such a test runs alone in its binary or tolerates others).
pub fn host_syncs() -> u64 {
    HOST_SYNCS.load(std::sync::atomic::Ordering::Relaxed)
}

/// Records `pipeline` with its three bind groups (model, state in, state out) over x by y workgroups.
pub fn dispatch_compute(
    pass: &mut wgpu::ComputePass,
    pipeline: &wgpu::ComputePipeline,
    groups: [&wgpu::BindGroup; 3],
    x: u32,
    y: u32,
) {
    bind_compute(pass, pipeline, groups);
    pass.dispatch_workgroups(x, y, 1);
}

/// Sets `pipeline` and its three bind groups for the dispatch that follows.
pub fn bind_compute(pass: &mut wgpu::ComputePass, pipeline: &wgpu::ComputePipeline, groups: [&wgpu::BindGroup; 3]) {
    pass.set_pipeline(pipeline);
    for (i, g) in groups.iter().enumerate() {
        pass.set_bind_group(i as u32, *g, &[]);
    }
}

/// Parses and validates WGSL `source` with naga, no GPU needed (every crate's shader tests), allowing
/// subgroup operations or not (the portable kernels must not use them). The error is naga's report.
pub fn validate_wgsl(source: &str, subgroups: bool) -> std::result::Result<(), String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let caps = if subgroups { naga::valid::Capabilities::SUBGROUP } else { naga::valid::Capabilities::empty() };
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
        .validate(&module)
        .map(|_| ())
        .map_err(|e| format!("{e:?}"))
}

/// Checks [`REQUIRED_LIMITS`] against `limits`, naming the first shortfall.
pub fn check_limits(adapter: &str, limits: &wgpu::Limits) -> Result<()> {
    for (name, min, get) in REQUIRED_LIMITS {
        let have = get(limits);
        if have < *min {
            return Err(EngineError::Gpu(format!(
                "adapter {adapter:?} is short of a needed limit: {name} = {have}, the engine needs at least {min}"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::DeviceType as T;

    #[test]
    fn adapter_rules() {
        let a = vec![("llvmpipe (LLVM 15)".to_string(), T::Cpu), ("NVIDIA H100".to_string(), T::DiscreteGpu)];
        assert_eq!(pick_adapter(&a, &AdapterChoice::Auto), Some(1));
        assert_eq!(pick_adapter(&a, &AdapterChoice::Cpu), Some(0));
        assert_eq!(pick_adapter(&a, &AdapterChoice::Gpu), Some(1));
        assert_eq!(pick_adapter(&a, &AdapterChoice::Name("LLVM".into())), Some(0));
        assert_eq!(pick_adapter(&a, &AdapterChoice::Name("radeon".into())), None);
        let cpu_only = vec![("llvmpipe".to_string(), T::Cpu)];
        assert_eq!(pick_adapter(&cpu_only, &AdapterChoice::Auto), Some(0));
        assert_eq!(pick_adapter(&cpu_only, &AdapterChoice::Gpu), None);
    }

    #[test]
    fn short_limit_is_named() {
        let mut l = wgpu::Limits::default();
        l.max_storage_buffers_per_shader_stage = 4;
        let e = check_limits("toy", &l).unwrap_err().to_string();
        assert!(e.contains("max_storage_buffers_per_shader_stage = 4") && e.contains("at least 8"), "{e}");
    }
}

/// A binding of an [`GpuContext::explicit_layout`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    Uniform,
    /// A uniform whose offset is set per dispatch (`set_bind_group(.., &[offset])`).
    UniformDynamic,
    Storage {
        read_only: bool,
    },
}

/// Bind group layouts and the pipeline layout made of them.
pub struct ExplicitLayout {
    pub groups: Vec<wgpu::BindGroupLayout>,
    pub pipeline: wgpu::PipelineLayout,
}

/// Pairs of 3-vectors (a body's linear and angular velocity, a force and a torque) as the kernels store
/// them: two vec4 each, w unused.
pub fn pack_vec3_pairs(v: &[[glam::Vec3; 2]]) -> Vec<[f32; 4]> {
    v.iter().flat_map(|v| [v[0].extend(0.0).to_array(), v[1].extend(0.0).to_array()]).collect()
}

/// The inverse of [`pack_vec3_pairs`].
pub fn unpack_vec3_pairs(v: &[[f32; 4]]) -> Vec<[glam::Vec3; 2]> {
    v.chunks_exact(2)
        .map(|p| [glam::Vec4::from_array(p[0]).truncate(), glam::Vec4::from_array(p[1]).truncate()])
        .collect()
}
