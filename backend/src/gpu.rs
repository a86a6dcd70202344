//! The wgpu device every back end renders with. A real GPU is preferred; a
//! software adapter (lavapipe, `DeviceType::Cpu`) is used when there is none.
//! `PARALLAX_ADAPTER=<substring>` picks an adapter by name.

use anyhow::{bail, Context, Result};

pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl Gpu {
    pub fn new() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        if adapters.is_empty() {
            bail!("no GPU adapter found (on a machine without a GPU, install Mesa's lavapipe: apt install mesa-vulkan-drivers)");
        }
        let wanted = std::env::var("PARALLAX_ADAPTER").ok();
        let rank = |a: &wgpu::Adapter| {
            let i = a.get_info();
            let named = wanted
                .as_ref()
                .is_some_and(|w| i.name.to_lowercase().contains(&w.to_lowercase()));
            let kind = match i.device_type {
                wgpu::DeviceType::DiscreteGpu => 0,
                wgpu::DeviceType::IntegratedGpu => 1,
                wgpu::DeviceType::VirtualGpu => 2,
                wgpu::DeviceType::Other => 3,
                wgpu::DeviceType::Cpu => 4,
            };
            (!named, kind)
        };
        for a in &adapters {
            let i = a.get_info();
            tracing::debug!(name = %i.name, kind = ?i.device_type, backend = ?i.backend, "GPU adapter found");
        }
        let adapter = adapters
            .into_iter()
            .min_by_key(rank)
            .expect("adapters is not empty");
        let info = adapter.get_info();
        tracing::info!(
            name = %info.name,
            kind = ?info.device_type,
            backend = ?info.backend,
            driver = %info.driver,
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
        })
    }

    /// Waits for all submitted work.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| anyhow::anyhow!("GPU wait failed: {e}"))
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
