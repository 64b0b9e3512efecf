//! [`GpuContext`]: one wgpu device, with or without a window.

/// Why the renderer could not start.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No usable GPU or software adapter.
    #[error(
        "no graphics adapter found ({0}); on Linux without a GPU install Mesa's software Vulkan driver (Debian: mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("cannot create a device on {adapter}: {message}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's message.
        message: String,
    },
    /// The window surface could not be created or configured.
    #[error("cannot draw into the window: {0}")]
    Surface(String),
    /// Reading a frame or a pixel back from the GPU failed.
    #[error("cannot read the frame back: {0}")]
    Readback(String),
}

/// A wgpu instance, adapter, device and queue.
pub struct GpuContext {
    /// The instance.
    pub instance: wgpu::Instance,
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
}

impl GpuContext {
    /// A context for offscreen rendering on the best available adapter (a real GPU if there is
    /// one, else a software one such as lavapipe).
    pub fn headless() -> Result<Self, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        Self::with_adapter(instance, adapter)
    }

    /// A context for an adapter chosen by the caller (for example compatible with a window).
    pub fn with_adapter(
        instance: wgpu::Instance,
        adapter: wgpu::Adapter,
    ) -> Result<Self, RenderError> {
        let supported = adapter.limits();
        let limits = wgpu::Limits {
            max_texture_array_layers: supported.max_texture_array_layers,
            max_storage_buffer_binding_size: supported.max_storage_buffer_binding_size,
            max_buffer_size: supported.max_buffer_size,
            ..wgpu::Limits::default()
        };
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("globus device"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| RenderError::Device {
            adapter: info.name.clone(),
            message: e.to_string(),
        })?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
        })
    }

    /// A one-line description of the adapter ("llvmpipe (LLVM 15.0.6, 256 bits), Vulkan, Cpu").
    pub fn adapter_description(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }
}
