//! [`GlobeRenderer`]: sky and terrain in two draw calls.
//!
//! Per frame, in two phases:
//! 1. [`GlobeRenderer::prepare`] (CPU): writes the frame uniforms, each drawn tile's
//!    centre-to-eye offset (subtracted in f64, then rounded to f32) at its pool slot, and one
//!    indirect draw record per drawn tile (its index range and base vertex in the pools).
//! 2. [`GlobeRenderer::draw`] (GPU): records, into a render pass the caller began (colour and
//!    depth, see [`crate::FrameFormats::terrain_targets`]), the sky with a full-screen triangle,
//!    then every terrain tile, whatever its mesh, with one `multi_draw_indexed_indirect` over
//!    the shared vertex and index pools. Each vertex carries its slot, which picks its offset and its
//!    colour: a layer of the colour pool and the part of it over the tile (its own layer
//!    whole, or an ancestor's cropped while its own imagery loads).

use std::mem::size_of;
use std::ops::Range;
use std::time::{Duration, Instant};

use bytemuck::{Pod, Zeroable};
use globus_geo::{Atmosphere, DVec3, Ellipsoid};
use globus_terrain::TerrainVertex;
use globus_tiling::DrawTile;

use crate::aerial::AerialTable;
use crate::air::AirResources;
use crate::camera::FrameCamera;
use crate::fade::ColourFades;
use crate::night::NightLights;
use crate::pool::{ColourSource, TilePool, VertexExtra};
use crate::shaders;
use crate::target::{DEPTH_FORMAT, FrameFormats};

/// Uniforms shared by all pipelines (mirrors `Frame` in `common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct FrameUniforms {
    clip_from_eye: [[f32; 4]; 4],
    eye_from_clip: [[f32; 4]; 4],
    eye_up_height: [f32; 4],
    sun: [f32; 4],
    planet: [f32; 4],
    viewport: [f32; 4],
    eye_position: [f32; 4],
    night: [f32; 4],
    aerial: [f32; 4],
}

/// One indirect draw (the layout `multi_draw_indexed_indirect` reads).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct DrawIndexedArgs {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    base_vertex: i32,
    first_instance: u32,
}

/// The Sun and how the picture is exposed (the air itself is the body's:
/// [`GlobeRenderer::set_atmosphere`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Unit vector towards the sun, ECEF axes.
    pub sun_direction: DVec3,
    /// The least light on faces turned away from the sun, 0..1: a floor under the sky's own
    /// light (skylight from the air's tables, which is nothing without air or at night).
    pub ambient: f32,
    /// Brightness of light scattered by the air, 1 physical (0: the air only dims).
    pub inscatter_gain: f32,
    /// Brightness multiplier before tone mapping.
    pub exposure: f32,
}

impl Lighting {
    /// The real Sun at `unix_s` seconds since 1970-01-01 00:00 UTC
    /// ([`globus_geo::SunPosition`]), with no ambient floor: the ground is lit by the Sun
    /// and the sky, which fades through twilight, so the night side is dark but for its
    /// lights.
    pub fn at_time(unix_s: f64) -> Self {
        Self {
            sun_direction: globus_geo::SunPosition::at(unix_s).direction(),
            ambient: 0.0,
            ..Self::sun_over(0.0, 0.0)
        }
    }

    /// A sun standing over the given longitude and latitude (radians).
    pub fn sun_over(lon_rad: f64, lat_rad: f64) -> Self {
        let (sl, cl) = lat_rad.sin_cos();
        let (so, co) = lon_rad.sin_cos();
        Self {
            sun_direction: DVec3::new(cl * co, cl * so, sl),
            ambient: 0.1,
            inscatter_gain: 1.0,
            exposure: 1.25,
        }
    }
}

/// What one frame draws.
pub struct FrameInputs<'a> {
    /// The camera (eye, matrices, near plane).
    pub camera: &'a FrameCamera,
    /// The body (for the atmosphere's space and geodetic latitudes on the GPU).
    pub ellipsoid: Ellipsoid,
    /// Sun and air.
    pub lighting: Lighting,
    /// Tiles to draw, with how far each has grown out of its parent
    /// ([`DrawTile::morph`]); each must be resident in the pool (others are skipped and
    /// counted).
    pub tiles: &'a [DrawTile],
}

/// What a frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DrawStats {
    /// Draw calls issued (sky and terrain).
    pub draw_calls: u32,
    /// Terrain tiles drawn.
    pub tiles: u32,
    /// Triangles submitted (skirts included).
    pub triangles: u64,
    /// Tiles asked for but not resident (drawn by nobody; should stay 0).
    pub missing: u32,
    /// Tiles drawn with an ancestor's colour, cropped and scaled (their own is loading).
    pub borrowed_colour: u32,
    /// Tiles drawn with no colour source at all (should stay 0: the engine uploads a tile
    /// without its colour only where an ancestor's can stand in).
    pub missing_colour: u32,
}

/// Per slot: where the tile's colour and its parent's are, and how far it has grown out of
/// its parent (`TileMap` in `terrain.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
struct TileMap {
    /// uv scale (u, v) and offset (u, v) of the tile in its colour layer.
    colour: [f32; 4],
    /// The same in the layer its parent shows.
    parent_colour: [f32; 4],
    /// How far the tile has grown out of its parent (0 to 1), the parent colour's layer, and
    /// how much of its own colour shows over the parent's (0 to 1).
    morph: [f32; 4],
}

impl Default for TileMap {
    fn default() -> Self {
        Self {
            colour: [1.0, 1.0, 0.0, 0.0],
            parent_colour: [1.0, 1.0, 0.0, 0.0],
            morph: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// A colour source as the shader reads it: uv scale and offset, and the layer.
fn map_of(c: ColourSource) -> ([f32; 4], u32) {
    (
        [
            c.scale[0] as f32,
            c.scale[1] as f32,
            c.offset[0] as f32,
            c.offset[1] as f32,
        ],
        c.layer,
    )
}

/// Pipelines and per-frame buffers for drawing the globe.
pub struct GlobeRenderer {
    frame_buffer: wgpu::Buffer,
    frame_layout: wgpu::BindGroupLayout,
    frame_bind_group: wgpu::BindGroup,
    air: AirResources,
    terrain_layout: wgpu::BindGroupLayout,
    terrain_bind_group: Option<wgpu::BindGroup>,
    terrain_pipeline: wgpu::RenderPipeline,
    sky_pipeline: wgpu::RenderPipeline,
    /// The sky seen from the eye, rebuilt each frame the eye is in the air (`sky.wgsl`).
    sky_view: SkyView,
    /// The air between the eye and the ground, rebuilt each frame (`aerial.rs`).
    aerial: AerialTable,
    /// Whether every ground fragment marches its own line of sight instead of reading
    /// `aerial` (the reference).
    marched_haze: bool,
    offset_buffer: wgpu::Buffer,
    offsets: Vec<[f32; 4]>,
    tile_map_buffer: wgpu::Buffer,
    /// Per slot, as `TileMap` in `terrain.wgsl`.
    tile_maps: Vec<TileMap>,
    /// Whether tiles grow out of their parents (else each shows its own surface at once).
    morph: bool,
    /// Own imagery fading in over its ancestor's.
    fades: ColourFades,
    indirect_buffer: wgpu::Buffer,
    indirect_capacity: u32,
    draws: Vec<DrawIndexedArgs>,
    sampler: wgpu::Sampler,
    pool: TilePool,
    stats: DrawStats,
    /// The night lights' texture (1 x 1 black without them), its sampler, and its width in
    /// texels (0 without).
    night_view: wgpu::TextureView,
    night_sampler: wgpu::Sampler,
    night_width: u32,
    /// Whether to draw procedural towns at night where there is no night lights image.
    procedural_lights: bool,
}

impl GlobeRenderer {
    /// Pipelines for rendering frames of `formats` with the given pool.
    ///
    /// The air is the Earth's over WGS84 until [`GlobeRenderer::set_atmosphere`] says
    /// otherwise.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        formats: FrameFormats,
        pool: TilePool,
    ) -> Self {
        // The aerial-perspective table's build (compute) reads the frame group too.
        let [a1, a2, a3, a4] = AirResources::layout_entries().map(|mut e| {
            e.visibility |= wgpu::ShaderStages::COMPUTE;
            e
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT | wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(size_of::<FrameUniforms>() as u64),
                    },
                    count: None,
                },
                a1,
                a2,
                a3,
                a4,
            ],
        });
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame uniforms"),
            size: size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let air = AirResources::new(device, queue, Atmosphere::earth(&Ellipsoid::WGS84));
        let frame_bind_group = frame_bind_group(device, &frame_layout, &frame_buffer, &air);
        let terrain_layout = terrain_bind_group_layout(device);
        let aerial = AerialTable::new(device, &frame_layout);
        let terrain_pipeline = terrain_pipeline(
            device,
            formats,
            [&frame_layout, &terrain_layout, &aerial.layout],
        );
        let sky_view = SkyView::new(device, &frame_layout);
        let sky_pipeline = sky_pipeline(device, formats, &frame_layout, &sky_view.layout);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("terrain colour"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            anisotropy_clamp: 8,
            ..Default::default()
        });
        let slots = pool.capacity();
        let offset_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tile offsets"),
            size: u64::from(slots) * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let tile_map_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tile colour maps and morphs"),
            size: u64::from(slots) * size_of::<TileMap>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let indirect_capacity = 256;
        let indirect_buffer = indirect_buffer(device, indirect_capacity);
        let night_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("night lights"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        Self {
            frame_buffer,
            frame_layout,
            frame_bind_group,
            air,
            terrain_layout,
            terrain_bind_group: None,
            terrain_pipeline,
            sky_pipeline,
            sky_view,
            aerial,
            marched_haze: false,
            offset_buffer,
            offsets: vec![[0.0; 4]; slots as usize],
            tile_map_buffer,
            tile_maps: vec![TileMap::default(); slots as usize],
            morph: true,
            fades: ColourFades::new(slots),
            indirect_buffer,
            indirect_capacity,
            draws: Vec::new(),
            sampler,
            pool,
            stats: DrawStats::default(),
            night_view: night_texture(device, None),
            night_sampler,
            night_width: 0,
            procedural_lights: false,
        }
    }

    /// Draws `atmosphere` (its sky, haze and the sunlight it lets through) from the next
    /// frame; [`Atmosphere::none`] draws none. Its tables are built on first use in the
    /// process (tens of milliseconds).
    pub fn set_atmosphere(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        atmosphere: Atmosphere,
    ) {
        if self.air.atmosphere == atmosphere {
            return;
        }
        self.air = AirResources::new(device, queue, atmosphere);
        self.frame_bind_group =
            frame_bind_group(device, &self.frame_layout, &self.frame_buffer, &self.air);
    }

    /// The air drawn.
    pub fn atmosphere(&self) -> &Atmosphere {
        &self.air.atmosphere
    }

    /// Whether tiles grow out of their parents' surfaces and colours as they come into their
    /// level of detail ([`DrawTile::morph`]; on by default), or show their own at once.
    pub fn set_morph(&mut self, on: bool) {
        self.morph = on;
    }

    /// How long a tile's own imagery takes to replace the ancestor's it showed while it
    /// loaded ([`crate::COLOUR_FADE`] by default); zero: at once (frames that must settle).
    pub fn set_colour_fade(&mut self, duration: Duration) {
        self.fades.set_duration(duration);
    }

    /// See [`GlobeRenderer::set_colour_fade`].
    pub fn colour_fade(&self) -> Duration {
        self.fades.duration()
    }

    /// Whether every ground fragment marches the air along its own line of sight (8 steps)
    /// instead of reading the frame's aerial-perspective table (`aerial.rs`; the default).
    /// The march is the reference the table is tested against, and slower.
    pub fn set_marched_haze(&mut self, on: bool) {
        self.marched_haze = on;
    }

    /// See [`GlobeRenderer::set_marched_haze`].
    pub fn marched_haze(&self) -> bool {
        self.marched_haze
    }

    /// Whether tiles grow out of their parents ([`GlobeRenderer::set_morph`]).
    pub fn morph(&self) -> bool {
        self.morph
    }

    /// Draws procedural towns on the night side's land (for a procedural planet), unless
    /// night lights are set ([`GlobeRenderer::set_night_lights`]).
    pub fn set_procedural_lights(&mut self, on: bool) {
        self.procedural_lights = on;
    }

    /// Draws `lights` on the night side from the next frame (`None`: none). The texture
    /// takes [`NightLights::gpu_bytes`] of GPU memory.
    pub fn set_night_lights(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        lights: Option<&NightLights>,
    ) {
        self.night_view = match lights {
            Some(l) => {
                let view = night_texture(device, Some((queue, l)));
                self.night_width = l.width();
                view
            }
            None => {
                self.night_width = 0;
                night_texture(device, None)
            }
        };
        self.terrain_bind_group = None;
    }

    /// CPU phase: uniforms and instances for this frame.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        inputs: &FrameInputs<'_>,
    ) -> DrawStats {
        let camera = inputs.camera;
        let view = camera.view();
        let (clip_from_eye, eye_from_clip) = (camera.clip_from_eye(), camera.eye_from_clip());
        let l = &inputs.lighting;
        let sun = l.sun_direction.normalize_or_zero().as_vec3();
        // The eye in the atmosphere's space: its direction from the centre and its height
        // over the sphere, from f64 (the one planet-sized subtraction).
        let radii = inputs.ellipsoid.radii();
        let stretched = view.position * (DVec3::splat(radii.x) / radii);
        let eye_r = stretched.length();
        let up = (stretched / eye_r.max(1.0)).as_vec3();
        let uniforms = FrameUniforms {
            clip_from_eye: clip_from_eye.to_cols_array_2d(),
            eye_from_clip: eye_from_clip.to_cols_array_2d(),
            eye_up_height: [up.x, up.y, up.z, (eye_r - radii.x) as f32],
            sun: [sun.x, sun.y, sun.z, l.ambient],
            planet: [
                radii.x as f32,
                if self.marched_haze { 1.0 } else { 0.0 },
                l.inscatter_gain,
                l.exposure,
            ],
            viewport: [
                view.width_px as f32,
                view.height_px as f32,
                1.0 / view.width_px.max(1) as f32,
                1.0 / view.height_px.max(1) as f32,
            ],
            eye_position: {
                let eye = view.position.as_vec3();
                let e2 = 1.0 - (radii.z * radii.z) / (radii.x * radii.x);
                [eye.x, eye.y, eye.z, e2 as f32]
            },
            night: [
                if self.night_width > 0 { 1.0 } else { 0.0 },
                self.night_width as f32,
                (1.0 / camera.pixels_per_metre(1.0)) as f32,
                if self.procedural_lights { 1.0 } else { 0.0 },
            ],
            aerial: crate::aerial::columns_rect(camera, radii.x + self.air.atmosphere.thickness_m),
        };
        queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&uniforms));
        let air = &self.air.atmosphere;
        if !air.is_none() && !camera.is_orthographic() {
            if eye_r - radii.x < air.thickness_m {
                self.sky_view.render(device, queue, &self.frame_bind_group);
            }
            if !self.marched_haze {
                self.aerial.build(device, queue, &self.frame_bind_group);
            }
        }

        self.draws.clear();
        let mut missing = 0;
        let mut borrowed_colour = 0;
        let mut missing_colour = 0;
        let mut triangles = 0u64;
        let mut tiles = 0u32;
        let now = Instant::now();
        for tile in inputs.tiles {
            let key = tile.key;
            let Some(r) = self.pool.resident(key) else {
                missing += 1;
                continue;
            };
            // The one place a planet-sized number becomes f32: after the f64 subtraction.
            let offset = (r.centre - view.position).as_vec3();
            let slot = r.slot;
            let own = self.pool.colour_source(key);
            match own {
                Some(c) => borrowed_colour += u32::from(c.from != key),
                None => missing_colour += 1,
            }
            let (map, layer) = own.map_or(([1.0, 1.0, 0.0, 0.0], slot), map_of);
            let morph = if self.morph { tile.morph as f32 } else { 1.0 };
            // The colour grows with the surface, and a tile's own imagery that has just
            // replaced its ancestor's fades in over it.
            let has_own = own.is_some_and(|c| c.from == key);
            let colour_share = morph * self.fades.own_share(slot, key, has_own, now);
            // Without a parent's colour to fade from, the tile's own stands in.
            let (parent_map, parent_layer) = self
                .pool
                .parent_colour_source(key)
                .filter(|_| colour_share < 1.0)
                .map_or((map, layer), map_of);
            self.offsets[slot as usize] = [offset.x, offset.y, offset.z, layer as f32];
            self.tile_maps[slot as usize] = TileMap {
                colour: map,
                parent_colour: parent_map,
                morph: [morph, parent_layer as f32, colour_share, 0.0],
            };
            // The whole tile, or the quadrants selection left it (its loaded children are
            // drawn over the rest).
            tiles += 1;
            let (first, base_vertex) = (r.indices.start, r.vertices.start as i32);
            let mut push = |range: Range<u32>| {
                triangles += u64::from(range.len() as u32 / 3);
                self.draws.push(DrawIndexedArgs {
                    index_count: range.len() as u32,
                    instance_count: 1,
                    first_index: first + range.start,
                    base_vertex,
                    first_instance: 0,
                });
            };
            match r.quadrants {
                Some(q) => q.ranges(tile.parts, &mut push),
                None => push(0..r.indices.len() as u32),
            }
        }
        let count = self.draws.len() as u32;
        if count > self.indirect_capacity {
            self.indirect_capacity = count.next_power_of_two();
            self.indirect_buffer = indirect_buffer(device, self.indirect_capacity);
        }
        if self.terrain_bind_group.is_none() {
            self.terrain_bind_group = Some(self.terrain_bind_group(device));
        }
        if !self.draws.is_empty() {
            queue.write_buffer(&self.offset_buffer, 0, bytemuck::cast_slice(&self.offsets));
            queue.write_buffer(
                &self.tile_map_buffer,
                0,
                bytemuck::cast_slice(&self.tile_maps),
            );
            queue.write_buffer(&self.indirect_buffer, 0, bytemuck::cast_slice(&self.draws));
        }
        self.stats = DrawStats {
            draw_calls: if count > 0 { 2 } else { 1 },
            tiles,
            triangles,
            missing,
            borrowed_colour,
            missing_colour,
        };
        self.stats
    }

    /// The GPU tile pools.
    pub fn pool(&self) -> &TilePool {
        &self.pool
    }

    /// The GPU tile pools, to upload into.
    pub fn pool_mut(&mut self) -> &mut TilePool {
        &mut self.pool
    }

    /// GPU phase: records the terrain prepared last and then the sky where no terrain is
    /// into `pass`, a pass over the frame's colour and depth targets that the caller began
    /// (clearing depth to 0, infinitely far, and colour as it likes; the sky covers every
    /// pixel still at 0) and may go on drawing into.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_bind_group(0, &self.frame_bind_group, &[]);
        if let Some(bind_group) = &self.terrain_bind_group
            && !self.draws.is_empty()
        {
            let (vertices, slots) = self.pool.vertex_buffers();
            pass.set_pipeline(&self.terrain_pipeline);
            pass.set_bind_group(1, bind_group, &[]);
            pass.set_bind_group(2, &self.aerial.bind_group, &[]);
            pass.set_vertex_buffer(0, vertices.slice(..));
            pass.set_vertex_buffer(1, slots.slice(..));
            pass.set_index_buffer(
                self.pool.index_buffer().slice(..),
                wgpu::IndexFormat::Uint32,
            );
            pass.multi_draw_indexed_indirect(&self.indirect_buffer, 0, self.draws.len() as u32);
        }
        // The sky last, only where the depth is still the cleared far plane: the ground
        // hides most of it from space, and its pixels there would march the air for nothing.
        pass.set_pipeline(&self.sky_pipeline);
        pass.set_bind_group(1, &self.sky_view.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }

    /// The stats of the last [`GlobeRenderer::prepare`].
    pub fn stats(&self) -> DrawStats {
        self.stats
    }

    fn terrain_bind_group(&self, device: &wgpu::Device) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("terrain"),
            layout: &self.terrain_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.offset_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(self.pool.colour_view()),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: self.tile_map_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(&self.night_view),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::Sampler(&self.night_sampler),
                },
            ],
        })
    }
}

/// The frame group: the uniforms and the air.
fn frame_bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    buffer: &wgpu::Buffer,
    air: &AirResources,
) -> wgpu::BindGroup {
    let [a1, a2, a3, a4] = air.entries();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("frame"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: buffer.as_entire_binding(),
            },
            a1,
            a2,
            a3,
            a4,
        ],
    })
}

/// The night lights' texture with its mips (R8), or a 1 x 1 black one.
fn night_texture(
    device: &wgpu::Device,
    lights: Option<(&wgpu::Queue, &NightLights)>,
) -> wgpu::TextureView {
    let (width, height, mips) = match lights {
        Some((_, l)) => (l.width(), l.height(), l.levels().len() as u32),
        None => (1, 1, 1),
    };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("night lights"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: mips,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::R8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    if let Some((queue, l)) = lights {
        for (level, (w, h, data)) in l.levels().iter().enumerate() {
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &texture,
                    mip_level: level as u32,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                data,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(*w),
                    rows_per_image: Some(*h),
                },
                wgpu::Extent3d {
                    width: *w,
                    height: *h,
                    depth_or_array_layers: 1,
                },
            );
        }
    }
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

fn indirect_buffer(device: &wgpu::Device, capacity: u32) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("terrain draws"),
        size: u64::from(capacity) * size_of::<DrawIndexedArgs>() as u64,
        usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A read-only storage buffer of per-slot records, read by the vertex shader.
fn per_slot_storage(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The layer count to give a 2D texture array that should hold `wanted` layers, within the
/// adapter's `max`: at least 2, and never a multiple of 6. wgpu's OpenGL backend decides a
/// texture's GL target from its description alone: a square 2D texture with a multiple of 6
/// layers becomes a cube map array and one with a single layer a plain 2D texture, and an
/// array view of either samples as zeros (gfx-rs/wgpu#7428). A pool of 1,200 tile slots drew
/// the whole landscape black on Mesa's llvmpipe that way. The extra layer goes unused.
pub fn array_layers(wanted: u32, max: u32) -> u32 {
    let max = max.max(2);
    let n = wanted.clamp(2, max);
    match (n.is_multiple_of(6), n < max) {
        (false, _) => n,
        (true, true) => n + 1,
        (true, false) => n - 1,
    }
}

/// The layout entry of a float texture read by fragment shaders (`filterable`: sampled
/// with a filtering sampler; else read with `textureLoad` or a non-filtering one). Shared
/// with the engine's overlay pipelines.
pub fn fragment_texture(
    binding: u32,
    filterable: bool,
    view_dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension,
            multisampled: false,
        },
        count: None,
    }
}

/// A filtering sampler used by fragment shaders.
pub(crate) fn fragment_sampler(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        count: None,
    }
}

fn terrain_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("terrain"),
        entries: &[
            per_slot_storage(0),
            fragment_texture(1, true, wgpu::TextureViewDimension::D2Array),
            fragment_sampler(2),
            per_slot_storage(3),
            fragment_texture(4, true, wgpu::TextureViewDimension::D2),
            fragment_sampler(5),
        ],
    })
}

/// Vertex streams: [`TerrainVertex`] from the pool, and the slot of each vertex.
const TERRAIN_VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32, 2 => Unorm16x2];
/// [`VertexExtra`]: slot, morph height and the parent's normal.
const EXTRA_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![3 => Uint32, 4 => Float32, 5 => Uint32];

/// `layouts`: the frame group's, the terrain group's and the aerial-perspective table's.
fn terrain_pipeline(
    device: &wgpu::Device,
    formats: FrameFormats,
    layouts: [&wgpu::BindGroupLayout; 3],
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("terrain"),
        source: wgpu::ShaderSource::Wgsl(shaders::TERRAIN.into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("terrain"),
        bind_group_layouts: &layouts.map(Some),
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("terrain"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[
                Some(wgpu::VertexBufferLayout {
                    array_stride: size_of::<TerrainVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &TERRAIN_VERTEX_ATTRIBUTES,
                }),
                Some(wgpu::VertexBufferLayout {
                    array_stride: size_of::<VertexExtra>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &EXTRA_ATTRIBUTES,
                }),
            ],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: Some(wgpu::Face::Back),
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &formats.terrain_targets(),
        }),
        multiview_mask: None,
        cache: None,
    })
}

fn sky_pipeline(
    device: &wgpu::Device,
    formats: FrameFormats,
    frame_layout: &wgpu::BindGroupLayout,
    sky_layout: &wgpu::BindGroupLayout,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("sky"),
        source: wgpu::ShaderSource::Wgsl(shaders::SKY.into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("sky"),
        bind_group_layouts: &[Some(frame_layout), Some(sky_layout)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("sky"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_sky"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        // At depth 0, drawn after the terrain: it covers what is still cleared to 0.
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(false),
            depth_compare: Some(wgpu::CompareFunction::Equal),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_sky"),
            compilation_options: Default::default(),
            targets: &formats.terrain_targets(),
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Hillaire's sky-view table: the sky seen from the eye, 192 x 108 half floats rendered by
/// `fs_sky_view` before the frame (while the eye is in the air) and read by `fs_sky`.
struct SkyView {
    pipeline: wgpu::RenderPipeline,
    target: wgpu::TextureView,
    layout: wgpu::BindGroupLayout,
    bind_group: wgpu::BindGroup,
}

impl SkyView {
    const SIZE: (u32, u32) = (192, 108);
    const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

    fn new(device: &wgpu::Device, frame_layout: &wgpu::BindGroupLayout) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("sky view"),
            size: wgpu::Extent3d {
                width: Self::SIZE.0,
                height: Self::SIZE.1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: Self::FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let target = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("sky view"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sky view"),
            entries: &[
                fragment_texture(0, true, wgpu::TextureViewDimension::D2),
                fragment_sampler(1),
            ],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sky view"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&target),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&sampler),
                },
            ],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sky view"),
            source: wgpu::ShaderSource::Wgsl(shaders::SKY.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sky view"),
            bind_group_layouts: &[Some(frame_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("sky view"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_sky"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_sky_view"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: Self::FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        Self {
            pipeline,
            target,
            layout,
            bind_group,
        }
    }

    /// Renders the table from this frame's uniforms (written to the queue before).
    fn render(&self, device: &wgpu::Device, queue: &wgpu::Queue, frame: &wgpu::BindGroup) {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("sky view"),
        });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("sky view"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, frame, &[]);
            pass.draw(0..3, 0..1);
        }
        queue.submit([encoder.finish()]);
    }
}

#[cfg(test)]
mod tests {
    use std::mem::{offset_of, size_of};

    use super::{FrameUniforms, TileMap, array_layers};
    use crate::air::AtmosphereUniforms;

    /// The size and member offsets of the WGSL struct `name` as naga lays it out.
    fn wgsl_layout(source: &str, name: &str) -> (u32, Vec<(String, u32)>) {
        let module = naga::front::wgsl::parse_str(source).expect("the shader parses");
        let (_, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name}"));
        match &ty.inner {
            naga::TypeInner::Struct { members, span } => (
                *span,
                members
                    .iter()
                    .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                    .collect(),
            ),
            other => panic!("{name} is {other:?}"),
        }
    }

    /// Checks a struct both shaders declare.
    fn check(name: &str, size: usize, offsets: &[(&str, usize)]) {
        check_in(
            &[
                ("terrain", crate::shaders::TERRAIN),
                ("sky", crate::shaders::SKY),
            ],
            name,
            size,
            offsets,
        );
    }

    fn check_in(shaders: &[(&str, &str)], name: &str, size: usize, offsets: &[(&str, usize)]) {
        for &(shader, source) in shaders {
            let (span, members) = wgsl_layout(source, name);
            assert_eq!(span as usize, size, "{shader}: {name}'s size");
            let got: Vec<(&str, usize)> = members
                .iter()
                .map(|(n, o)| (n.as_str(), *o as usize))
                .collect();
            assert_eq!(got, offsets, "{shader}: {name}'s members");
        }
    }

    #[test]
    fn texture_arrays_never_look_like_cube_maps_or_single_textures() {
        for wanted in 0..=4000 {
            for max in [256, 2048, 2046] {
                let n = array_layers(wanted, max);
                assert!(
                    !n.is_multiple_of(6) && n >= 2 && n <= max,
                    "{wanted} of {max}: {n}"
                );
                assert!(n + 1 >= wanted.min(max), "{wanted} of {max}: {n}");
            }
        }
        assert_eq!(array_layers(1200, 2048), 1201);
        assert_eq!(array_layers(2046, 2046), 2045);
        assert_eq!(array_layers(1, 2048), 2);
    }

    #[test]
    fn uniform_structs_match_their_wgsl_layouts() {
        check(
            "Frame",
            size_of::<FrameUniforms>(),
            &[
                ("clip_from_eye", offset_of!(FrameUniforms, clip_from_eye)),
                ("eye_from_clip", offset_of!(FrameUniforms, eye_from_clip)),
                ("eye_up_height", offset_of!(FrameUniforms, eye_up_height)),
                ("sun", offset_of!(FrameUniforms, sun)),
                ("planet", offset_of!(FrameUniforms, planet)),
                ("viewport", offset_of!(FrameUniforms, viewport)),
                ("eye_position", offset_of!(FrameUniforms, eye_position)),
                ("night", offset_of!(FrameUniforms, night)),
                ("aerial", offset_of!(FrameUniforms, aerial)),
            ],
        );
        check(
            "Atmosphere",
            size_of::<AtmosphereUniforms>(),
            &[
                ("rayleigh", offset_of!(AtmosphereUniforms, rayleigh)),
                ("mie", offset_of!(AtmosphereUniforms, mie)),
                ("ozone", offset_of!(AtmosphereUniforms, ozone)),
                ("shell", offset_of!(AtmosphereUniforms, shell)),
                ("stretch", offset_of!(AtmosphereUniforms, stretch)),
                (
                    "sky_irradiance",
                    offset_of!(AtmosphereUniforms, sky_irradiance),
                ),
            ],
        );
        check_in(
            &[("terrain", crate::shaders::TERRAIN)],
            "TileMap",
            size_of::<TileMap>(),
            &[
                ("colour", offset_of!(TileMap, colour)),
                ("parent_colour", offset_of!(TileMap, parent_colour)),
                ("morph", offset_of!(TileMap, morph)),
            ],
        );
    }
}
