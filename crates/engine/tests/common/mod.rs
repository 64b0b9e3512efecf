//! What the engine's tests share: a marker overlay drawn through the public [`Overlay`]
//! trait, image measurements, and scratch folders.

#![allow(dead_code)] // each test file uses its own subset

use bytemuck::{Pod, Zeroable};
use globus_engine::{CameraSpec, DVec3, FrameContext, Overlay, OverlayPass, RgbaImage};

/// A camera in degrees and metres (`alt` above the ground if `above_ground`).
pub fn camera(
    lon: f64,
    lat: f64,
    alt: f64,
    heading: f64,
    pitch: f64,
    above_ground: bool,
) -> CameraSpec {
    CameraSpec {
        lon_deg: lon,
        lat_deg: lat,
        alt_m: alt,
        heading_deg: heading,
        pitch_deg: pitch,
        above_ground,
    }
}

/// A disc drawn at a world point.
#[derive(Clone, Copy, Debug)]
pub struct Marker {
    /// ECEF metres.
    pub at: DVec3,
    /// Radius: pixels (screen-aligned) or metres (`in_metres`).
    pub radius: f32,
    pub in_metres: bool,
    /// Written into the id buffer (0: not pickable).
    pub id: u32,
    pub pass: OverlayPass,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuCamera {
    clip_from_eye: [[f32; 4]; 4],
    viewport: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuMarker {
    centre: [f32; 4],
    colour: [f32; 4],
    info: [u32; 4],
}

struct Gpu {
    pipeline: wgpu::RenderPipeline,
    camera: wgpu::Buffer,
    markers: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

/// Discs in magenta whose red channel is a Gaussian of the distance from their centre
/// (`exp(-4.5 r^2)`, `r` 1 at the rim), so their drawn centre can be measured to a fraction of
/// a pixel ([`marker_centroid`]).
pub struct Markers {
    pub markers: Vec<Marker>,
    passes: Vec<OverlayPass>,
    /// Instances of each pass, in `markers` order after sorting.
    ranges: Vec<(OverlayPass, std::ops::Range<u32>)>,
    gpu: Option<Gpu>,
}

const MAX_MARKERS: u64 = 64;

impl Markers {
    pub fn new(mut markers: Vec<Marker>) -> Self {
        markers.sort_by_key(|m| m.pass as u8);
        let mut passes: Vec<OverlayPass> = markers.iter().map(|m| m.pass).collect();
        passes.dedup();
        let ranges = passes
            .iter()
            .map(|&p| {
                let first = markers.iter().position(|m| m.pass == p).unwrap_or(0) as u32;
                let n = markers.iter().filter(|m| m.pass == p).count() as u32;
                (p, first..first + n)
            })
            .collect();
        Self {
            markers,
            passes,
            ranges,
            gpu: None,
        }
    }

    fn create(frame: &FrameContext<'_>) -> Gpu {
        let device = frame.device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("test markers"),
            source: wgpu::ShaderSource::Wgsl(include_str!("markers.wgsl").into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("test markers"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
            ],
        });
        let buffer = |label, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let camera = buffer(
            "marker camera",
            std::mem::size_of::<GpuCamera>() as u64,
            wgpu::BufferUsages::UNIFORM,
        );
        let markers = buffer(
            "markers",
            MAX_MARKERS * std::mem::size_of::<GpuMarker>() as u64,
            wgpu::BufferUsages::STORAGE,
        );
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("test markers"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: camera.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: markers.as_entire_binding(),
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("test markers"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let formats = frame.formats();
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("test markers"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_marker"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(formats.depth_test(true)),
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_marker"),
                compilation_options: Default::default(),
                targets: &formats.colour_targets(None, true),
            }),
            multiview_mask: None,
            cache: None,
        });
        Gpu {
            pipeline,
            camera,
            markers,
            bind_group,
        }
    }
}

impl Overlay for Markers {
    fn passes(&self) -> &[OverlayPass] {
        &self.passes
    }

    fn prepare(&mut self, frame: &FrameContext<'_>) {
        let gpu = self.gpu.get_or_insert_with(|| Self::create(frame));
        let camera = frame.camera();
        let (w, h) = camera.viewport_px();
        let view = camera.view();
        let v3 = |v: DVec3| {
            let v = v.as_vec3();
            [v.x, v.y, v.z, 0.0]
        };
        let uniforms = GpuCamera {
            clip_from_eye: camera.clip_from_eye().to_cols_array_2d(),
            viewport: [w as f32, h as f32, 0.0, 0.0],
            right: v3(view.right()),
            up: v3(view.up()),
        };
        frame
            .queue()
            .write_buffer(&gpu.camera, 0, bytemuck::bytes_of(&uniforms));
        let instances: Vec<GpuMarker> = self
            .markers
            .iter()
            .map(|m| {
                let c = camera.relative(m.at);
                GpuMarker {
                    centre: [c.x, c.y, c.z, m.radius],
                    colour: [1.0, 0.0, 1.0, 1.0],
                    info: [m.id, u32::from(m.in_metres), 0, 0],
                }
            })
            .collect();
        if !instances.is_empty() {
            frame
                .queue()
                .write_buffer(&gpu.markers, 0, bytemuck::cast_slice(&instances));
        }
    }

    fn draw(
        &self,
        pass: OverlayPass,
        _frame: &FrameContext<'_>,
        render_pass: &mut wgpu::RenderPass<'_>,
    ) {
        let Some(gpu) = &self.gpu else {
            return;
        };
        for (p, range) in &self.ranges {
            if *p == pass {
                render_pass.set_pipeline(&gpu.pipeline);
                render_pass.set_bind_group(0, &gpu.bind_group, &[]);
                render_pass.draw(0..6, range.clone());
            }
        }
    }
}

/// sRGB-encoded 8-bit value to linear.
fn linear(v: u8) -> f64 {
    let c = f64::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Whether a pixel is a marker's (magenta key: no green, full blue).
pub fn is_marker(p: [u8; 4]) -> bool {
    p[1] == 0 && p[2] == 255
}

/// Marker pixels in the image.
pub fn marker_pixels(img: &RgbaImage) -> usize {
    (0..img.height)
        .flat_map(|y| (0..img.width).map(move |x| (x, y)))
        .filter(|&(x, y)| is_marker(img.get(x, y)))
        .count()
}

/// The Gaussian-weighted centre of the marker pixels within `radius` pixels of `near`, in
/// pixel coordinates (pixel centres at `i + 0.5`), and how many there were.
pub fn marker_centroid(
    img: &RgbaImage,
    near: (f64, f64),
    radius: f64,
) -> Option<((f64, f64), usize)> {
    let (mut sx, mut sy, mut sw, mut n) = (0.0, 0.0, 0.0, 0);
    let x0 = (near.0 - radius).floor().max(0.0) as u32;
    let y0 = (near.1 - radius).floor().max(0.0) as u32;
    let x1 = ((near.0 + radius).ceil() as u32).min(img.width - 1);
    let y1 = ((near.1 + radius).ceil() as u32).min(img.height - 1);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = img.get(x, y);
            if !is_marker(p) {
                continue;
            }
            let w = linear(p[0]);
            sx += w * (f64::from(x) + 0.5);
            sy += w * (f64::from(y) + 0.5);
            sw += w;
            n += 1;
        }
    }
    (sw > 0.0).then(|| ((sx / sw, sy / sw), n))
}

/// An empty scratch folder for one test under the test output folder of `group`.
pub fn scratch(group: &str, name: &str) -> std::path::PathBuf {
    let dir = globus_test_support::output_dir(group).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// A globe over a pyramid `globus tile` makes of the SRTM tile N57E011 (Terrarium PNG,
/// geographic, to the source's own resolution) in the scratch folder `group/srtm`, with no
/// procedural refinement below it. The pyramid is made once per test binary and group: tests
/// run in parallel, and two tilers writing one folder at once fail or leave each other torn
/// tiles.
pub fn srtm_builder(group: &str) -> globus_engine::GlobeBuilder {
    use globus_tiler::{ElevationEncoding, JobKind, TileJob};
    use std::collections::HashMap;
    use std::sync::{Mutex, PoisonError};
    static MADE: Mutex<Option<HashMap<String, std::path::PathBuf>>> = Mutex::new(None);
    let mut made = MADE.lock().unwrap_or_else(PoisonError::into_inner);
    let pyramid = match made.get_or_insert_with(HashMap::new).get(group) {
        Some(pyramid) => pyramid.clone(),
        None => {
            let pyramid = scratch(group, "srtm").join("srtm");
            let job = TileJob {
                threads: Some(2),
                ..TileJob::new(
                    JobKind::Dem {
                        encoding: ElevationEncoding::Terrarium,
                        height_scale: None,
                    },
                    vec![globus_test_support::shared_data("N57E011.hgt")],
                    pyramid.clone(),
                )
            };
            globus_tiler::run(&job).expect("tiling N57E011");
            made.get_or_insert_with(HashMap::new)
                .insert(group.to_owned(), pyramid.clone());
            pyramid
        }
    };
    drop(made);
    let spec = globus_engine::SourceSpec::parse(pyramid.to_str().expect("utf-8")).expect("spec");
    let mut builder = globus_engine::GlobeBuilder::new();
    builder.terrain(spec).max_level(0);
    builder
}
