//! The headless wgpu context: adapter choice (hardware, then Vulkan, then GL), the features and
//! limits asked for, and a report of what was chosen.

use crate::error::GpuError;
use std::sync::{Arc, Mutex};

/// What adapter the context runs on and why.
#[derive(Debug, Clone, PartialEq)]
pub struct AdapterReport {
    /// The adapter's name (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
    pub name: String,
    /// The backend: "vulkan", "gl", ...
    pub backend: String,
    /// "DiscreteGpu", "Cpu", ...
    pub device_type: String,
    /// Driver name and version.
    pub driver: String,
    /// Whether GPU timestamp queries are available (benches use them, else wall time).
    pub timestamps: bool,
    /// Choices made for this adapter, in words.
    pub notes: Vec<String>,
}

/// A device and queue made for headless work, with the adapter it came from.
///
/// Library passes never create a device themselves: they take `&wgpu::Device` and
/// `&wgpu::Queue`, so an engine passes its own. This context is for tests, the demo and
/// users without a device of their own.
#[derive(Debug)]
pub struct GpuContext {
    /// The wgpu instance.
    pub instance: wgpu::Instance,
    /// The chosen adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    report: AdapterReport,
    /// Errors wgpu reported outside any error scope (from recorded commands, at submit).
    errors: Arc<Mutex<Vec<wgpu::Error>>>,
    /// Set by the device-lost callback: the reason and message.
    lost: Arc<Mutex<Option<(String, String)>>>,
}

/// Preference of an adapter: lower is better. Hardware first, then software Vulkan
/// (lavapipe), then software GL (llvmpipe), then anything else.
fn rank(info: &wgpu::AdapterInfo) -> u32 {
    use wgpu::{Backend, DeviceType};
    let hardware = matches!(
        info.device_type,
        DeviceType::DiscreteGpu | DeviceType::IntegratedGpu | DeviceType::VirtualGpu
    );
    match (hardware, info.backend) {
        (true, Backend::Vulkan) => 0,
        (true, _) => 1,
        (false, Backend::Vulkan) => 2,
        (false, Backend::Gl) => 3,
        _ => 4,
    }
}

/// Errors of submitted work kept until [`GpuContext::check`] collects them.
const MAX_KEPT_ERRORS: usize = 64;

impl GpuContext {
    /// Creates a headless context. Honours `WGPU_BACKEND` (e.g. `vulkan`, `gl`) and
    /// `WGPU_ADAPTER_NAME` (a case-insensitive part of the adapter's name).
    #[cfg(feature = "blocking")]
    pub fn new_headless() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_headless_async())
    }

    /// The async form of [`GpuContext::new_headless`].
    pub async fn new_headless_async() -> Result<Self, GpuError> {
        let name_filter = std::env::var("WGPU_ADAPTER_NAME")
            .ok()
            .filter(|s| !s.is_empty());
        // Vulkan first, GL only when Vulkan has no adapter: probing GL's EGL platforms prints
        // driver noise (`XDG_RUNTIME_DIR is invalid`) on every run of a headless machine.
        let tries = match wgpu::Backends::from_env() {
            Some(forced) => vec![forced],
            None => vec![wgpu::Backends::VULKAN, wgpu::Backends::GL],
        };
        let mut asked = wgpu::Backends::empty();
        for backends in tries {
            asked |= backends;
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends,
                flags: wgpu::InstanceFlags::from_build_config().with_env(),
                ..wgpu::InstanceDescriptor::new_without_display_handle()
            });
            let mut adapters = instance.enumerate_adapters(backends).await;
            if let Some(filter) = &name_filter {
                let f = filter.to_lowercase();
                adapters.retain(|a| a.get_info().name.to_lowercase().contains(&f));
            }
            adapters.sort_by_key(|a| rank(&a.get_info()));
            for a in &adapters {
                let info = a.get_info();
                tracing::debug!(name = %info.name, backend = ?info.backend, kind = ?info.device_type, "adapter found");
            }
            if let Some(adapter) = adapters.into_iter().next() {
                let info = adapter.get_info();
                tracing::info!(name = %info.name, backend = ?info.backend, kind = ?info.device_type, "GPU adapter chosen");
                return Self::from_adapter(instance, adapter).await;
            }
        }
        Err(GpuError::NoAdapter {
            backends: asked,
            name_filter,
        })
    }

    /// Creates the device on a chosen adapter: the adapter's own limits (so large maps fit)
    /// and the optional features it has (timestamps, adapter-specific format features).
    pub async fn from_adapter(
        instance: wgpu::Instance,
        adapter: wgpu::Adapter,
    ) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let wanted = wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
            | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES;
        let features = adapter.features() & wanted;
        let mut notes = Vec::new();
        if !features.contains(wgpu::Features::TIMESTAMP_QUERY) {
            notes.push(
                "no timestamp queries: GPU timings use wall time with a blocking poll".into(),
            );
        }
        notes.push(
            "heights live in u32 storage buffers (one texel per element): exact integer stamps \
             in place on every backend, where R16 storage textures are not writable on GL"
                .into(),
        );
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("terrain-gpu device"),
                required_features: features,
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await?;
        let report = AdapterReport {
            name: info.name.clone(),
            backend: info.backend.to_str().to_string(),
            device_type: format!("{:?}", info.device_type),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            notes,
        };
        // Errors in recorded commands surface at submit, outside the scopes resource creation
        // uses; collect them instead of wgpu's default panic, and hand them over in `check`.
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut list) = sink.lock() {
                // Bounded: a device that fails every frame must not grow this without end.
                if list.len() < MAX_KEPT_ERRORS {
                    list.push(e);
                }
            }
        }));
        // A lost device reports nothing for the work sent to it afterwards (WebGPU), so the
        // loss itself is recorded here and `check` turns it into an error.
        let lost = Arc::new(Mutex::new(None));
        let flag = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut l) = flag.lock() {
                l.get_or_insert((format!("{reason:?}"), message));
            }
        });
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            report,
            errors,
            lost,
        })
    }

    /// Whether the device has been lost (destroyed, reset by the driver, dropped).
    pub fn is_lost(&self) -> bool {
        match self.lost.lock() {
            Ok(l) => l.is_some(),
            Err(poisoned) => poisoned.into_inner().is_some(),
        }
    }

    /// Returns [`GpuError::DeviceLost`] once the device is lost, else the errors wgpu reported
    /// since the last call outside an error scope (validation or out-of-memory errors of
    /// submitted work), as one [`GpuError::Submitted`].
    pub fn check(&self) -> Result<(), GpuError> {
        let lost = match self.lost.lock() {
            Ok(l) => l.clone(),
            Err(poisoned) => poisoned.into_inner().clone(),
        };
        if let Some((reason, message)) = lost {
            return Err(GpuError::DeviceLost { reason, message });
        }
        let errors: Vec<wgpu::Error> = match self.errors.lock() {
            Ok(mut list) => list.drain(..).collect(),
            Err(poisoned) => poisoned.into_inner().drain(..).collect(),
        };
        if errors.is_empty() {
            Ok(())
        } else {
            Err(GpuError::Submitted { errors })
        }
    }

    /// The adapter and the choices made for it.
    pub fn report(&self) -> &AdapterReport {
        &self.report
    }
}
