//! The atmosphere on the GPU: [`globus_geo::Atmosphere`]'s parameters as a uniform block and
//! its two tables as half-float textures, bound with the frame uniforms (group 0, bindings
//! 1-4) so that the sky and terrain shaders march the same air (`common.wgsl`).
//!
//! The tables take a few tens of milliseconds to build; they are built once per distinct
//! atmosphere in a process and shared.

use std::sync::{Arc, Mutex};

use bytemuck::{Pod, Zeroable};
use globus_geo::{Atmosphere, AtmosphereTables, SKY_IRRADIANCE_SIZE};

use crate::globe::{fragment_sampler, fragment_texture};

/// The Sun's illuminance in the shaders' units: pi lights a white Lambertian ground facing
/// it to 1, as the terrain's diffuse term does.
pub(crate) const SUN_ILLUMINANCE: f32 = std::f32::consts::PI;

/// Mirrors `Atmosphere` in `common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct AtmosphereUniforms {
    pub(crate) rayleigh: [f32; 4],
    pub(crate) mie: [f32; 4],
    pub(crate) ozone: [f32; 4],
    pub(crate) shell: [f32; 4],
    pub(crate) stretch: [f32; 4],
    /// The sky's light on level ground by the Sun's cosine from the zenith
    /// ([`AtmosphereTables::sky_irradiance`], rgb; zero without air).
    pub(crate) sky_irradiance: [[f32; 4]; SKY_IRRADIANCE_SIZE],
}

impl AtmosphereUniforms {
    pub(crate) fn new(a: &Atmosphere, tables: Option<&AtmosphereTables>) -> Self {
        let mut sky_irradiance = [[0.0; 4]; SKY_IRRADIANCE_SIZE];
        for (out, e) in sky_irradiance
            .iter_mut()
            .zip(tables.iter().flat_map(|t| t.sky_irradiance.iter()))
        {
            let e = e.as_vec3();
            *out = [e.x, e.y, e.z, 0.0];
        }
        let stretch = a.stretch().as_vec3();
        let (r, o) = (
            a.rayleigh_scattering.as_vec3(),
            a.ozone_absorption.as_vec3(),
        );
        let t = a.thickness_m;
        let thickness = if a.is_none() { 0.0 } else { t as f32 };
        Self {
            rayleigh: [r.x, r.y, r.z, a.rayleigh_scale_height_m as f32],
            mie: [
                a.mie_scattering as f32,
                a.mie_extinction as f32,
                a.mie_scale_height_m as f32,
                a.mie_g as f32,
            ],
            ozone: [o.x, o.y, o.z, a.ozone_peak_m as f32],
            shell: [
                a.bottom_radius_m as f32,
                thickness,
                a.ozone_half_width_m.max(1.0) as f32,
                (t.max(1.0) * (2.0 * a.bottom_radius_m + t.max(1.0))).sqrt() as f32,
            ],
            stretch: [stretch.x, stretch.y, stretch.z, SUN_ILLUMINANCE],
            sky_irradiance,
        }
    }
}

/// An atmosphere's uniforms and tables on the GPU.
pub(crate) struct AirResources {
    pub(crate) atmosphere: Atmosphere,
    pub(crate) uniforms: wgpu::Buffer,
    pub(crate) transmittance: wgpu::TextureView,
    pub(crate) multiple_scattering: wgpu::TextureView,
    pub(crate) sampler: wgpu::Sampler,
}

impl AirResources {
    pub(crate) fn new(device: &wgpu::Device, queue: &wgpu::Queue, atmosphere: Atmosphere) -> Self {
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("atmosphere"),
            size: std::mem::size_of::<AtmosphereUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let tables = (!atmosphere.is_none()).then(|| tables_for(&atmosphere));
        queue.write_buffer(
            &uniforms,
            0,
            bytemuck::bytes_of(&AtmosphereUniforms::new(&atmosphere, tables.as_deref())),
        );
        let (transmittance, multiple_scattering) = if let Some(tables) = &tables {
            let t = &tables.transmittance;
            let m = &tables.multiple_scattering;
            (
                table(device, queue, "transmittance", t.width, t.height, &t.data),
                table(
                    device,
                    queue,
                    "multiple scattering",
                    m.size,
                    m.size,
                    &m.data,
                ),
            )
        } else {
            (
                table(device, queue, "transmittance", 1, 1, &[[1.0; 4]]),
                table(device, queue, "multiple scattering", 1, 1, &[[0.0; 4]]),
            )
        };
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("atmosphere tables"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Self {
            atmosphere,
            uniforms,
            transmittance,
            multiple_scattering,
            sampler,
        }
    }

    /// Layout entries for bindings 1-4 of the frame group.
    pub(crate) fn layout_entries() -> [wgpu::BindGroupLayoutEntry; 4] {
        [
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(
                        std::mem::size_of::<AtmosphereUniforms>() as u64,
                    ),
                },
                count: None,
            },
            fragment_texture(2, true, wgpu::TextureViewDimension::D2),
            fragment_texture(3, true, wgpu::TextureViewDimension::D2),
            fragment_sampler(4),
        ]
    }

    /// Bind group entries for bindings 1-4 of the frame group.
    pub(crate) fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 4] {
        [
            wgpu::BindGroupEntry {
                binding: 1,
                resource: self.uniforms.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::TextureView(&self.transmittance),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&self.multiple_scattering),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            },
        ]
    }
}

/// The tables of `atmosphere`, built on first use in this process.
fn tables_for(atmosphere: &Atmosphere) -> Arc<AtmosphereTables> {
    static BUILT: Mutex<Vec<(Atmosphere, Arc<AtmosphereTables>)>> = Mutex::new(Vec::new());
    let mut built = BUILT
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((_, t)) = built.iter().find(|(a, _)| a == atmosphere) {
        return t.clone();
    }
    let started = std::time::Instant::now();
    let tables = Arc::new(AtmosphereTables::new(atmosphere));
    tracing::debug!(elapsed = ?started.elapsed(), "atmosphere tables built");
    built.push((*atmosphere, tables.clone()));
    tables
}

/// An RGBA half-float texture of `data` (rows first).
fn table(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    width: u32,
    height: u32,
    data: &[[f32; 4]],
) -> wgpu::TextureView {
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba16Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let halves: Vec<half::f16> = data
        .iter()
        .flatten()
        .map(|&v| half::f16::from_f32(v))
        .collect();
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(&halves),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * 8),
            rows_per_image: Some(height),
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}
