//! The wgpu device every back end renders with.
//!
//! Which adapter (G10 runs one back end per GPU, two GPUs per node):
//!
//! 1. an adapter a projector file of this back end names (`adapter = "…"`),
//!    else `PARALLAX_ADAPTER=<name or #index>`: that one, or an error that
//!    lists the adapters;
//! 2. otherwise the best kind present (discrete, integrated, virtual, other,
//!    software: lavapipe is the fallback on a machine without a GPU), and
//!    among adapters of that kind the one at the back end's node-local rank
//!    (OpenMPI's `OMPI_COMM_WORLD_LOCAL_RANK`, MPICH's `MPI_LOCALRANKID`,
//!    Slurm's `SLURM_LOCALID`; the back-end index in the embedded mode),
//!    modulo their number, so the back ends of a node spread over its GPUs.
//!
//! The same GPU listed by several graphics APIs counts once (Vulkan, Metal
//! or DX12 before GL). The choice and its reason are logged (`RUST_LOG=info`).

use anyhow::{bail, Context, Result};

/// What the choice sees of an adapter.
#[derive(Clone, Debug, PartialEq)]
pub struct AdapterDesc {
    pub name: String,
    pub kind: wgpu::DeviceType,
    pub backend: wgpu::Backend,
}

impl AdapterDesc {
    fn of(info: &wgpu::AdapterInfo) -> Self {
        AdapterDesc {
            name: info.name.clone(),
            kind: info.device_type,
            backend: info.backend,
        }
    }
}

/// What a back end asks for.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdapterRequest {
    /// A name (substring, any case) or `#N` (the N-th adapter listed), and
    /// where it comes from (for messages).
    pub named: Option<(String, String)>,
    /// The back end's rank among those on its node.
    pub local_rank: Option<usize>,
}

impl AdapterRequest {
    /// `projector_adapter` (from this back end's projector files) before
    /// `PARALLAX_ADAPTER`, and the node-local rank from the MPI launcher's
    /// environment, else `fallback_rank`.
    pub fn from_env(projector_adapter: Option<(String, String)>, fallback_rank: usize) -> Self {
        let named = projector_adapter.or_else(|| {
            std::env::var("PARALLAX_ADAPTER")
                .ok()
                .filter(|v| !v.is_empty())
                .map(|v| (v, "PARALLAX_ADAPTER".to_string()))
        });
        let local_rank = [
            "OMPI_COMM_WORLD_LOCAL_RANK",
            "MPI_LOCALRANKID",
            "SLURM_LOCALID",
        ]
        .iter()
        .find_map(|k| std::env::var(k).ok()?.parse().ok())
        .or(Some(fallback_rank));
        AdapterRequest { named, local_rank }
    }
}

fn kind_order(k: wgpu::DeviceType) -> u8 {
    match k {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

fn backend_order(b: wgpu::Backend) -> u8 {
    match b {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    }
}

/// The adapter to use: its index in `adapters`, and why (for the log).
pub fn choose_adapter(adapters: &[AdapterDesc], req: &AdapterRequest) -> Result<(usize, String)> {
    if adapters.is_empty() {
        bail!("no GPU adapter found (on a machine without a GPU, install Mesa's lavapipe: apt install mesa-vulkan-drivers)");
    }
    // One entry per device: the best graphics API of each (name, kind).
    let mut devices: Vec<usize> = Vec::new();
    for (i, a) in adapters.iter().enumerate() {
        match devices
            .iter_mut()
            .find(|&&mut j| adapters[j].name == a.name && adapters[j].kind == a.kind)
        {
            Some(j) if backend_order(a.backend) < backend_order(adapters[*j].backend) => *j = i,
            Some(_) => {}
            None => devices.push(i),
        }
    }
    let listing = || {
        devices
            .iter()
            .enumerate()
            .map(|(n, &i)| {
                format!(
                    "#{n} {} ({:?}, {:?})",
                    adapters[i].name, adapters[i].kind, adapters[i].backend
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some((want, source)) = &req.named {
        if let Some(n) = want.strip_prefix('#') {
            let n: usize = n.parse().with_context(|| {
                format!(
                    "{source} = \"{want}\": expected #N; adapters: {}",
                    listing()
                )
            })?;
            let &i = devices.get(n).with_context(|| {
                format!(
                    "{source} = \"{want}\": there are {} adapters: {}",
                    devices.len(),
                    listing()
                )
            })?;
            return Ok((i, format!("{source} = \"{want}\"")));
        }
        let w = want.to_lowercase();
        return devices
            .iter()
            .copied()
            .filter(|&i| adapters[i].name.to_lowercase().contains(&w))
            .min_by_key(|&i| kind_order(adapters[i].kind))
            .map(|i| (i, format!("{source} = \"{want}\"")))
            .with_context(|| {
                format!(
                    "{source} = \"{want}\": no such adapter; adapters: {}",
                    listing()
                )
            });
    }
    let best = devices
        .iter()
        .map(|&i| kind_order(adapters[i].kind))
        .min()
        .expect("at least one device");
    let group: Vec<usize> = devices
        .iter()
        .copied()
        .filter(|&i| kind_order(adapters[i].kind) == best)
        .collect();
    let rank = req.local_rank.unwrap_or(0);
    let i = group[rank % group.len()];
    Ok((
        i,
        format!(
            "the best kind present ({:?}): {} of them, node-local rank {rank}",
            adapters[i].kind,
            group.len()
        ),
    ))
}

/// Lavapipe, Mesa's CPU Vulkan driver, runs a compute dispatch on a pool of
/// `LP_NUM_THREADS` threads (one per core by default) and hands each thread
/// one contiguous block of the workgroups: with one block per core, the
/// core whose part of the image holds the denser rays finishes last and the
/// other waits (the translucent Colin27 brain at 512² rendered 15 % slower
/// than with four blocks per core, `parallax render` on 2 cores). Unless
/// the user set it, this asks for four threads per core, at most 32 (the
/// driver's limit): still all cores busy, in blocks small enough to even
/// out.
///
/// It also asks lavapipe to filter 8-bit textures (the pool of 8-bit
/// bricks) on its float path instead of its 8-bit integer one
/// (`GALLIVM_PERF=no_aos_sampling`), unless the user set `GALLIVM_PERF`:
/// the integer path rounds the interpolation weights to 8 bits, an error
/// the float pool does not have, and was not faster (the brain's 4 mm
/// partner on 8-bit bricks took 0.93 of its time with the float path;
/// docs/performance.md, "lavapipe's float path for 8-bit bricks").
///
/// It only sets environment variables the driver reads when it starts;
/// other adapters ignore them. Call it first thing in `main`, before any
/// other thread exists.
pub fn spread_cpu_device_work() {
    if std::env::var_os("LP_NUM_THREADS").is_none() {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        std::env::set_var("LP_NUM_THREADS", (4 * cores).min(32).to_string());
    }
    if std::env::var_os("GALLIVM_PERF").is_none() {
        std::env::set_var("GALLIVM_PERF", "no_aos_sampling");
    }
}

pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// The instance and adapter the device came from: a window's surface
    /// must be made by the same instance and presented by that adapter
    /// (`crate::present`).
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
}

impl Gpu {
    /// The first adapter of the best kind (or `PARALLAX_ADAPTER`'s).
    pub fn new() -> Result<Self> {
        Self::with_request(&AdapterRequest::from_env(None, 0))
    }

    pub fn with_request(req: &AdapterRequest) -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        for a in &adapters {
            let i = a.get_info();
            tracing::debug!(name = %i.name, kind = ?i.device_type, backend = ?i.backend, "GPU adapter found");
        }
        let descs: Vec<AdapterDesc> = adapters
            .iter()
            .map(|a| AdapterDesc::of(&a.get_info()))
            .collect();
        let (index, why) = choose_adapter(&descs, req)?;
        let adapter = adapters
            .into_iter()
            .nth(index)
            .expect("chosen from the list");
        let info = adapter.get_info();
        tracing::info!(
            name = %info.name,
            kind = ?info.device_type,
            backend = ?info.backend,
            driver = %info.driver,
            reason = %why,
            "GPU adapter chosen"
        );
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("parallax"),
            // Hardware trilinear filtering of full-precision bricks, where
            // the adapter has it.
            required_features: adapter.features() & wgpu::Features::FLOAT32_FILTERABLE,
            // Everything the adapter offers: the brick pool and the images
            // want the largest textures and storage bindings available.
            required_limits: limits,
            ..Default::default()
        }))
        .with_context(|| format!("cannot open GPU device on adapter '{}'", info.name))?;
        Ok(Gpu {
            device,
            queue,
            info,
            instance,
            adapter,
        })
    }

    /// Waits for all submitted work.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| anyhow::anyhow!("GPU wait failed: {e}"))
    }

    /// Maps `slice` of a MAP_READ buffer for reading once the submitted
    /// work is done; `what` names it in errors. Unmap the buffer after.
    pub fn map_read(&self, slice: wgpu::BufferSlice, what: &str) -> Result<wgpu::BufferView> {
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()??;
        slice
            .get_mapped_range()
            .map_err(|e| anyhow::anyhow!("reading back {what}: {e:?}"))
    }

    /// Runs `f` inside a validation error scope and fails with the first
    /// validation error instead of letting it be logged and lost.
    pub fn validated<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        if let Some(e) = pollster::block_on(scope.pop()) {
            bail!("{what}: {e}");
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::{Backend, DeviceType};

    fn a(name: &str, kind: DeviceType, backend: Backend) -> AdapterDesc {
        AdapterDesc {
            name: name.into(),
            kind,
            backend,
        }
    }

    fn pick(list: &[AdapterDesc], named: Option<&str>, rank: usize) -> Result<String> {
        let req = AdapterRequest {
            named: named.map(|n| (n.to_string(), "PARALLAX_ADAPTER".to_string())),
            local_rank: Some(rank),
        };
        choose_adapter(list, &req).map(|(i, _)| format!("{} {:?}", list[i].name, list[i].backend))
    }

    #[test]
    fn back_ends_spread_over_a_nodes_gpus() {
        // Two discrete GPUs, each also listed by GL, and lavapipe.
        let node = [
            a("llvmpipe", DeviceType::Cpu, Backend::Vulkan),
            a("NVIDIA H100 (0)", DeviceType::DiscreteGpu, Backend::Gl),
            a("NVIDIA H100 (0)", DeviceType::DiscreteGpu, Backend::Vulkan),
            a("NVIDIA H100 (1)", DeviceType::DiscreteGpu, Backend::Vulkan),
            a("NVIDIA H100 (1)", DeviceType::DiscreteGpu, Backend::Gl),
        ];
        let got: Vec<String> = (0..4).map(|r| pick(&node, None, r).unwrap()).collect();
        assert_eq!(
            got,
            [
                "NVIDIA H100 (0) Vulkan",
                "NVIDIA H100 (1) Vulkan",
                "NVIDIA H100 (0) Vulkan",
                "NVIDIA H100 (1) Vulkan"
            ]
        );
        // The front end as local rank 0, two back ends at 1 and 2: two GPUs.
        assert_ne!(pick(&node, None, 1).unwrap(), pick(&node, None, 2).unwrap());
        // Named: by name (any case) or by index, whatever the rank.
        assert_eq!(
            pick(&node, Some("h100 (1)"), 0).unwrap(),
            "NVIDIA H100 (1) Vulkan"
        );
        assert_eq!(pick(&node, Some("#0"), 3).unwrap(), "llvmpipe Vulkan");
        assert_eq!(pick(&node, Some("llvm"), 1).unwrap(), "llvmpipe Vulkan");
        let e = pick(&node, Some("radeon"), 0).unwrap_err().to_string();
        assert!(
            e.contains("PARALLAX_ADAPTER = \"radeon\": no such adapter")
                && e.contains("#2 NVIDIA H100 (1)"),
            "{e}"
        );
        let e = pick(&node, Some("#7"), 0).unwrap_err().to_string();
        assert!(e.contains("there are 3 adapters"), "{e}");
    }

    #[test]
    fn a_node_with_one_gpu_and_a_machine_without() {
        let one = [
            a("llvmpipe", DeviceType::Cpu, Backend::Vulkan),
            a("AMD Radeon", DeviceType::DiscreteGpu, Backend::Vulkan),
            a("Intel UHD", DeviceType::IntegratedGpu, Backend::Vulkan),
        ];
        for r in 0..3 {
            assert_eq!(pick(&one, None, r).unwrap(), "AMD Radeon Vulkan");
        }
        let software = [a(
            "llvmpipe (LLVM 15.0.6, 256 bits)",
            DeviceType::Cpu,
            Backend::Vulkan,
        )];
        for r in 0..3 {
            assert_eq!(
                pick(&software, None, r).unwrap(),
                "llvmpipe (LLVM 15.0.6, 256 bits) Vulkan"
            );
        }
        assert!(choose_adapter(&[], &AdapterRequest::default())
            .unwrap_err()
            .to_string()
            .contains("mesa-vulkan-drivers"));
    }
}
