//! Render targets: the depth and id buffers a frame shares between its passes
//! ([`FrameTargets`]), their formats ([`FrameFormats`]), and an offscreen colour target read
//! back as RGBA ([`OffscreenTarget`]).
//!
//! The id buffer is Kaiser's item buffer (2018, 5.3): a second colour attachment of 32-bit
//! unsigned integers that pickable overlays write their object ids into while they draw
//! colour, sharing the depth buffer, so what is picked is what is seen. 0 means "no object"
//! (terrain and sky write nothing there).

use crate::RenderError;

/// Depth format: 32-bit float, used reversed (1 near, 0 at infinity).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Format of the id buffer.
pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// The colour format of offscreen frames.
pub const OFFSCREEN_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The attachments pipelines drawing into a Globus frame declare. Overlays: colour at
/// location 0, the id buffer at location 1, and (except in screen-space passes) depth. The
/// terrain pass has colour and depth only (the id buffer is cleared by the first overlay
/// pass, so a frame without overlays pays nothing for it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameFormats {
    /// The colour target's format (the window surface's, or [`OFFSCREEN_FORMAT`]).
    pub colour: wgpu::TextureFormat,
}

impl FrameFormats {
    /// Formats for frames drawn into `colour`.
    pub fn new(colour: wgpu::TextureFormat) -> Self {
        Self { colour }
    }

    /// The id buffer's format ([`ID_FORMAT`]).
    pub fn id(&self) -> wgpu::TextureFormat {
        ID_FORMAT
    }

    /// The depth format ([`DEPTH_FORMAT`]).
    pub fn depth(&self) -> wgpu::TextureFormat {
        DEPTH_FORMAT
    }

    /// The two colour targets of a pipeline: colour with `blend`, and the id buffer, written
    /// only if `writes_ids` (the fragment shader then outputs a `u32` at `@location(1)`;
    /// otherwise it need not output anything there).
    pub fn colour_targets(
        &self,
        blend: Option<wgpu::BlendState>,
        writes_ids: bool,
    ) -> [Option<wgpu::ColorTargetState>; 2] {
        [
            Some(wgpu::ColorTargetState {
                format: self.colour,
                blend,
                write_mask: wgpu::ColorWrites::ALL,
            }),
            Some(wgpu::ColorTargetState {
                format: ID_FORMAT,
                blend: None,
                write_mask: if writes_ids {
                    wgpu::ColorWrites::RED
                } else {
                    wgpu::ColorWrites::empty()
                },
            }),
        ]
    }

    /// The colour target of the terrain pass (sky and tiles, opaque, no ids).
    pub fn terrain_targets(&self) -> [Option<wgpu::ColorTargetState>; 1] {
        [Some(wgpu::ColorTargetState {
            format: self.colour,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })]
    }

    /// Depth testing against the shared reversed-Z buffer (nearer is greater), optionally
    /// writing depth: what world-space and screen-aligned pipelines use.
    pub fn depth_test(&self, write: bool) -> wgpu::DepthStencilState {
        wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(write),
            depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        }
    }
}

/// The depth and id buffers of frames of one size.
pub struct FrameTargets {
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    terrain_depth: wgpu::Texture,
    terrain_depth_view: wgpu::TextureView,
    ids: wgpu::Texture,
    id_view: wgpu::TextureView,
    width: u32,
    height: u32,
    depth_reader: DepthReader,
}

/// A compute pass that copies one pixel of the depth buffer into a buffer: depth textures
/// can only be copied whole.
struct DepthReader {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    pixel: wgpu::Buffer,
    picked: wgpu::Buffer,
}

impl DepthReader {
    fn new(device: &wgpu::Device, depth: &wgpu::TextureView) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("pick depth"),
            source: wgpu::ShaderSource::Wgsl(crate::shaders::PICK.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pick depth"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        let pixel = buffer(
            "pick pixel",
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let picked = buffer(
            "picked depth",
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pick depth"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(depth),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: picked.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: pixel.as_entire_binding(),
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("pick depth"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("pick depth"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("read_depth"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self {
            pipeline,
            bind_group,
            pixel,
            picked,
        }
    }
}

/// What a frame left at one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelRead {
    /// The id an overlay wrote there (0: none).
    pub id: u32,
    /// Reversed-Z depth (0: nothing drawn, infinitely far).
    pub depth: f32,
}

impl FrameTargets {
    /// Depth and id buffers of `width` x `height` pixels.
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let texture =
            |label, format, usage| target_texture(device, label, (width, height), format, usage);
        let depth = texture(
            "frame depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        let terrain_depth = texture(
            "terrain depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let ids = texture("frame ids", ID_FORMAT, wgpu::TextureUsages::COPY_SRC);
        let depth_view = depth.create_view(&wgpu::TextureViewDescriptor::default());
        Self {
            depth_reader: DepthReader::new(device, &depth_view),
            depth_view,
            depth,
            terrain_depth_view: terrain_depth.create_view(&wgpu::TextureViewDescriptor::default()),
            terrain_depth,
            id_view: ids.create_view(&wgpu::TextureViewDescriptor::default()),
            ids,
            width,
            height,
        }
    }

    /// Width and height, pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The depth buffer.
    pub fn depth_view(&self) -> &wgpu::TextureView {
        &self.depth_view
    }

    /// A copy of the depth buffer as the terrain pass left it (see
    /// [`FrameTargets::copy_terrain_depth`]), for overlays that test against the terrain in
    /// their shaders.
    pub fn terrain_depth_view(&self) -> &wgpu::TextureView {
        &self.terrain_depth_view
    }

    /// Copies the depth buffer into the terrain depth texture.
    pub fn copy_terrain_depth(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_texture(
            self.depth.as_image_copy(),
            self.terrain_depth.as_image_copy(),
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// The id buffer.
    pub fn id_view(&self) -> &wgpu::TextureView {
        &self.id_view
    }

    /// GPU bytes of the depth, terrain depth and id buffers.
    pub fn gpu_bytes(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height) * 12
    }

    /// Reads the id and depth the last frame left at pixel (`x`, `y`), waiting for the GPU.
    /// `None` outside the targets.
    pub fn read_pixel(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        x: u32,
        y: u32,
    ) -> Result<Option<PixelRead>, RenderError> {
        if x >= self.width || y >= self.height {
            return Ok(None);
        }
        let row = u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pick readback"),
            size: 2 * row,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("pick readback"),
        });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.ids,
                mip_level: 0,
                origin: wgpu::Origin3d { x, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row as u32),
                    rows_per_image: Some(1),
                },
            },
            wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
        );
        let reader = &self.depth_reader;
        queue.write_buffer(&reader.pixel, 0, bytemuck::cast_slice(&[x, y, 0, 0]));
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("pick depth"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&reader.pipeline);
            pass.set_bind_group(0, &reader.bind_group, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        encoder.copy_buffer_to_buffer(&reader.picked, 0, &buffer, row, 4);
        queue.submit([encoder.finish()]);
        let data = map_and_read(device, &buffer)?;
        let word = |at: usize| [data[at], data[at + 1], data[at + 2], data[at + 3]];
        Ok(Some(PixelRead {
            id: u32::from_le_bytes(word(0)),
            depth: f32::from_le_bytes(word(row as usize)),
        }))
    }
}

/// A 2D texture to render into, of `size` pixels, with `usage` besides that.
fn target_texture(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | usage,
        view_formats: &[],
    })
}

/// Maps a readback buffer the GPU has been told to fill and copies its bytes out.
fn map_and_read(device: &wgpu::Device, buffer: &wgpu::Buffer) -> Result<Vec<u8>, RenderError> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| RenderError::Readback(format!("waiting for the GPU: {e}")))?;
    rx.recv()
        .map_err(|e| RenderError::Readback(format!("readback callback lost: {e}")))?
        .map_err(|e| RenderError::Readback(format!("mapping the readback buffer: {e}")))?;
    let bytes = slice
        .get_mapped_range()
        .map_err(|e| RenderError::Readback(format!("reading the readback buffer: {e}")))?
        .to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// An RGBA8 image, rows top to bottom. In rendered frames alpha is 255 where terrain was drawn
/// and 0 where the background (sky, space) shows.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbaImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub pixels: Vec<u8>,
}

impl RgbaImage {
    /// The pixel at (`x`, `y`).
    pub fn get(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        [
            self.pixels[i],
            self.pixels[i + 1],
            self.pixels[i + 2],
            self.pixels[i + 3],
        ]
    }
}

/// An offscreen colour target that can be read back.
pub struct OffscreenTarget {
    colour: wgpu::Texture,
    colour_view: wgpu::TextureView,
    width: u32,
    height: u32,
}

impl OffscreenTarget {
    /// The colour format.
    pub const FORMAT: wgpu::TextureFormat = OFFSCREEN_FORMAT;

    /// A target of `width` x `height` pixels.
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let colour = target_texture(
            device,
            "offscreen colour",
            (width, height),
            OFFSCREEN_FORMAT,
            wgpu::TextureUsages::COPY_SRC,
        );
        let colour_view = colour.create_view(&wgpu::TextureViewDescriptor::default());
        Self {
            colour,
            colour_view,
            width,
            height,
        }
    }

    /// The colour texture's view, to render into.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.colour_view
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Copies the colour texture into a buffer and waits for it: the finished frame.
    pub fn read_back(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<RgbaImage, RenderError> {
        let row = self.width * 4;
        let padded =
            row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded) * u64::from(self.height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.colour,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
        queue.submit([encoder.finish()]);
        let data = map_and_read(device, &buffer)?;
        let mut pixels = Vec::with_capacity((row * self.height) as usize);
        for y in 0..self.height {
            let start = (y * padded) as usize;
            pixels.extend_from_slice(&data[start..start + row as usize]);
        }
        Ok(RgbaImage {
            width: self.width,
            height: self.height,
            pixels,
        })
    }
}
