//! The aerial-perspective table (Hillaire 2020, section 5.5's froxels): the air between the
//! eye and the ground, built once a frame instead of marched for every ground fragment.
//!
//! A compute pass (`aerial.wgsl`) casts 32 x 32 rays through a grid of screen points and
//! marches each once through the air (64 steps), storing what has built up (the light
//! scattered towards the eye and the transmittance, half floats) at the ends of 32 slices,
//! and the ray's range: from where it enters the air (the eye, when the eye is in it) to where
//! it leaves it or meets the body's sphere (from the air, a sphere 12 km lower, so that a ray
//! that meets the ground sooner than its neighbour goes on as the neighbour does). From the
//! air the grid spans the viewport and the slices crowd towards the eye with the square of
//! the depth (a kilometre-wide first slice along the horizon, metres looking down); from
//! space it spans the air's disc on the screen ([`columns_rect`], so a planet small on the
//! screen still gets every ray) and the slices crowd towards the ground, where the air is
//! dense.
//!
//! A ground fragment (`aerial_perspective` in `terrain.wgsl`) reads the four columns round
//! its pixel and weights them by nearness, reading each where it best stands for the
//! fragment's own ray: from the air at the fragment's distance (near the horizon, where it
//! matters, the rays are almost parallel); from space at the same share of the way from the
//! air's edge to the ground (rays that enter the air kilometres apart reach the same height
//! there, where the same distance would put one deep in the haze and the other above it).
//! The hardware's trilinear filter cannot do that: neighbouring columns' ranges differ, most
//! of all either side of the body's silhouette, so the same depth in the texture stands for
//! different distances. Each column's two slices either side are read as texels and blended
//! in the shader (on lavapipe a filtered 3D read costs eight texel fetches). From space, where the light changes faster than the grid follows
//! (rays that graze the ground, columns either side of the silhouette, columns whose light
//! differs by more than 30 %: the limb and the terminator, 1-10 % of the ground in the views
//! tested), the fragment marches its own line of sight. An orthographic camera's rays start
//! from points of its plane, not from the eye, and are always marched; so are all when asked
//! for the reference ([`crate::GlobeRenderer::set_marched_haze`]).
//!
//! The march it replaces takes 8 steps a fragment, each with two table lookups and three
//! exponentials; the table costs a fragment two ray-sphere intersections, four small
//! records and sixteen texel reads, and the pass 65,536 steps a frame. How far the table's pictures are from the
//! march's is tested in `crates/engine/tests/atmosphere.rs`.

use globus_geo::DVec2;

use crate::camera::FrameCamera;
use crate::globe::fragment_texture;
use crate::shaders;

/// Columns across and down, and slices along each (mirrors `AP_COLUMNS` and `AP_SLICES` in
/// `common.wgsl`).
const COLUMNS: (u32, u32) = (32, 32);
const SLICES: u32 = 32;
/// Invocations per workgroup along x and y (mirrors `cs_aerial`'s).
const WORKGROUP: u32 = 8;
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The framebuffer rectangle the table's columns spread over (pixels: left, top, right,
/// bottom), for a body whose air lies within `air_radius_m` of its centre: the whole
/// viewport while the eye is within that radius; from further out, the air's disc on the
/// screen (the projection of its silhouette circle, 72 points) grown by a column each side
/// and cut to the viewport, so that a planet small on the screen still gets every column.
pub(crate) fn columns_rect(camera: &FrameCamera, air_radius_m: f64) -> [f32; 4] {
    let (w, h) = camera.viewport_px();
    let (w, h) = (f64::from(w), f64::from(h));
    let whole = [0.0, 0.0, w as f32, h as f32];
    let eye = camera.view().position;
    let d = eye.length();
    if camera.is_orthographic() || d <= air_radius_m * 1.000_001 {
        return whole;
    }
    let towards = eye / d;
    let centre = towards * (air_radius_m * air_radius_m / d);
    let radius = air_radius_m * (1.0 - (air_radius_m / d).powi(2)).sqrt();
    let u = towards.any_orthonormal_vector();
    let v = towards.cross(u);
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for k in 0..72 {
        let a = f64::from(k) * std::f64::consts::TAU / 72.0;
        // The chord between two points strays inside the circle by 1 - cos(pi / 72) of its
        // radius: push the points out by that so the polygon contains the circle.
        let p =
            centre + (u * a.cos() + v * a.sin()) * (radius / (std::f64::consts::PI / 72.0).cos());
        let Some(px) = camera.project(p) else {
            return whole;
        };
        lo = lo.min(px);
        hi = hi.max(px);
    }
    let margin = (hi - lo) / f64::from(COLUMNS.0);
    let (lo, hi) = (
        (lo - margin).max(DVec2::ZERO),
        (hi + margin).min(DVec2::new(w, h)),
    );
    if hi.x - lo.x < 1.0 || hi.y - lo.y < 1.0 {
        return whole;
    }
    [lo.x as f32, lo.y as f32, hi.x as f32, hi.y as f32]
}

/// The table's GPU side: the build pass and what the terrain pipeline binds (group 2).
pub(crate) struct AerialTable {
    pipeline: wgpu::ComputePipeline,
    build_group: wgpu::BindGroup,
    /// The terrain pipeline's group 2: the two volumes and the ranges.
    pub(crate) layout: wgpu::BindGroupLayout,
    pub(crate) bind_group: wgpu::BindGroup,
}

impl AerialTable {
    /// The table and its build pass, which reads the frame group of `frame_layout`.
    pub(crate) fn new(device: &wgpu::Device, frame_layout: &wgpu::BindGroupLayout) -> Self {
        let volume = |label| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: COLUMNS.0,
                    height: COLUMNS.1,
                    depth_or_array_layers: SLICES,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: FORMAT,
                usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        };
        let views = [volume("aerial inscatter"), volume("aerial transmittance")]
            .map(|t| t.create_view(&wgpu::TextureViewDescriptor::default()));
        let ranges = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("aerial ranges"),
            size: u64::from(COLUMNS.0 * COLUMNS.1) * 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let storage_volume = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: FORMAT,
                view_dimension: wgpu::TextureViewDimension::D3,
            },
            count: None,
        };
        let ranges_entry = |binding, visibility, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: wgpu::BufferSize::new(16),
            },
            count: None,
        };
        let build_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("aerial build"),
            entries: &[
                storage_volume(0),
                storage_volume(1),
                ranges_entry(2, wgpu::ShaderStages::COMPUTE, false),
            ],
        });
        // Both groups bind the same three resources, in the same order.
        let bind = |label, layout| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&views[0]),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&views[1]),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: ranges.as_entire_binding(),
                    },
                ],
            })
        };
        let build_group = bind("aerial build", &build_layout);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("aerial"),
            entries: &[
                fragment_texture(0, false, wgpu::TextureViewDimension::D3),
                fragment_texture(1, false, wgpu::TextureViewDimension::D3),
                ranges_entry(2, wgpu::ShaderStages::FRAGMENT, true),
            ],
        });
        let bind_group = bind("aerial", &layout);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("aerial"),
            source: wgpu::ShaderSource::Wgsl(shaders::AERIAL.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("aerial"),
            bind_group_layouts: &[Some(frame_layout), Some(&build_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("aerial"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("cs_aerial"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self {
            pipeline,
            build_group,
            layout,
            bind_group,
        }
    }

    /// Builds the table from this frame's uniforms (written to the queue before).
    pub(crate) fn build(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        frame: &wgpu::BindGroup,
    ) {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("aerial"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("aerial"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, frame, &[]);
            pass.set_bind_group(1, &self.build_group, &[]);
            pass.dispatch_workgroups(
                COLUMNS.0.div_ceil(WORKGROUP),
                COLUMNS.1.div_ceil(WORKGROUP),
                1,
            );
        }
        queue.submit([encoder.finish()]);
    }
}

#[cfg(test)]
mod tests {
    use super::{COLUMNS, SLICES, WORKGROUP};

    #[test]
    fn the_tables_size_is_the_shaders() {
        let common = include_str!("shaders/common.wgsl");
        let columns = format!(
            "const AP_COLUMNS: vec2<u32> = vec2<u32>({}u, {}u);",
            COLUMNS.0, COLUMNS.1
        );
        assert!(common.contains(&columns), "{columns}");
        let slices = format!("const AP_SLICES: u32 = {SLICES}u;");
        assert!(common.contains(&slices), "{slices}");
        let workgroup = format!("@workgroup_size({WORKGROUP}, {WORKGROUP}, 1)");
        assert!(crate::shaders::AERIAL.contains(&workgroup), "{workgroup}");
    }
}
