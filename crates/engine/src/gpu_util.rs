//! Small wgpu helpers the engine's built-in overlays share: buffers that grow by doubling,
//! bind-group layout entries, and render pipelines of one shader module.

/// A buffer that grows by doubling, keeping its contents (copied on the GPU).
pub(crate) struct Growing {
    pub buffer: wgpu::Buffer,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl Growing {
    pub(crate) fn new(
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
        size: u64,
    ) -> Self {
        let usage = usage | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC;
        Self {
            buffer: buffer(device, label, size, usage),
            label,
            usage,
        }
    }

    /// Makes room for `bytes`, keeping what is there.
    pub(crate) fn reserve(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        bytes: u64,
    ) -> bool {
        if bytes <= self.buffer.size() {
            return false;
        }
        let bigger = buffer(device, self.label, bytes.next_power_of_two(), self.usage);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("overlay buffer growth"),
        });
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &bigger, 0, self.buffer.size());
        queue.submit([encoder.finish()]);
        self.buffer = bigger;
        true
    }

    /// Writes `bytes` at the start, growing (without keeping) if needed.
    pub(crate) fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        let need = (bytes.len() as u64).max(16);
        if need > self.buffer.size() {
            self.buffer = buffer(device, self.label, need.next_power_of_two(), self.usage);
        }
        if !bytes.is_empty() {
            queue.write_buffer(&self.buffer, 0, bytes);
        }
    }
}

/// A buffer of `size` bytes (at least 16, rounded up to a multiple of 16).
pub(crate) fn buffer(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16).div_ceil(16) * 16,
        usage,
        mapped_at_creation: false,
    })
}

/// A buffer binding.
pub(crate) fn buffer_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BufferBindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A float texture read by fragment shaders.
pub(crate) use globus_render::fragment_texture as texture_entry;

/// Makes the render pipelines of one shader module and pipeline layout.
pub(crate) struct Pipelines<'a> {
    pub device: &'a wgpu::Device,
    pub layout: &'a wgpu::PipelineLayout,
    pub module: &'a wgpu::ShaderModule,
}

impl Pipelines<'_> {
    /// A pipeline of entry points `vs` and `fs`, triangle lists, no multisampling.
    pub(crate) fn make(
        &self,
        label: &str,
        vs: &str,
        fs: &str,
        buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
        depth: wgpu::DepthStencilState,
        targets: &[Option<wgpu::ColorTargetState>],
    ) -> wgpu::RenderPipeline {
        self.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(self.layout),
                vertex: wgpu::VertexState {
                    module: self.module,
                    entry_point: Some(vs),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: Some(depth),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: self.module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets,
                }),
                multiview_mask: None,
                cache: None,
            })
    }
}
