// Terrain: one instanced draw over the shared tile grid. Vertex data is pulled from the
// vertex pool by slot; positions are f32 offsets from the tile's centre, and each instance
// carries the centre-to-eye offset computed in f64 on the CPU, so nothing large reaches f32.

struct TerrainVertex {
    position: vec3<f32>,
    normal_oct: u32,
}

struct TileInstance {
    // Tile centre minus eye position, metres (f64 on the CPU, rounded once).
    offset: vec3<f32>,
    // Slot in the vertex pool and colour texture array.
    slot: u32,
}

const MESH_SIDE: u32 = 33u;
const GRID_VERTICES: u32 = 1089u;
const VERTICES_PER_TILE: u32 = 1221u;
const SEGMENTS: f32 = 32.0;

@group(1) @binding(0) var<storage, read> vertices: array<TerrainVertex>;
@group(1) @binding(1) var<storage, read> instances: array<TileInstance>;
@group(1) @binding(2) var colours: texture_2d_array<f32>;
@group(1) @binding(3) var colour_sampler: sampler;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) eye_offset: vec3<f32>,
    @location(3) @interpolate(flat) slot: u32,
}

// Grid column and row of a vertex (skirt vertices share their edge vertex's position in uv).
fn grid_uv(index: u32) -> vec2<f32> {
    if (index < GRID_VERTICES) {
        return vec2<f32>(f32(index % MESH_SIDE), f32(index / MESH_SIDE)) / SEGMENTS;
    }
    let s = index - GRID_VERTICES;
    let edge = s / MESH_SIDE;
    let k = f32(s % MESH_SIDE);
    switch edge {
        case 0u: { return vec2<f32>(k, 0.0) / SEGMENTS; }
        case 1u: { return vec2<f32>(k, SEGMENTS) / SEGMENTS; }
        case 2u: { return vec2<f32>(0.0, k) / SEGMENTS; }
        default: { return vec2<f32>(SEGMENTS, k) / SEGMENTS; }
    }
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32, @builtin(instance_index) instance: u32) -> VsOut {
    let tile = instances[instance];
    let v = vertices[tile.slot * VERTICES_PER_TILE + index];
    let eye_offset = tile.offset + v.position;
    var out: VsOut;
    out.clip = frame.clip_from_eye * vec4<f32>(eye_offset, 1.0);
    out.uv = grid_uv(index);
    out.normal = decode_oct(v.normal_oct);
    out.eye_offset = eye_offset;
    out.slot = tile.slot;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let texel = textureSample(colours, colour_sampler, in.uv, in.slot);
    let albedo = texel.rgb;
    let water = 1.0 - texel.a;
    let n = normalize(in.normal);
    let sun = frame.sun.xyz;
    let ambient = frame.sun.w;
    let diffuse = max(dot(n, sun), 0.0);
    let dist = length(in.eye_offset);
    let view = -in.eye_offset / max(dist, 1e-6);
    // Sun glint on water (Blinn-Phong).
    let h = normalize(sun + view);
    let glint = water * pow(max(dot(n, h), 0.0), 200.0) * 0.35 * step(0.0, dot(n, sun));
    var colour = albedo * (ambient + (1.0 - ambient) * diffuse) + vec3<f32>(glint);
    // Aerial perspective: the air between the eye and the ground dims and tints it.
    let haze = air(-view, dist);
    colour = colour * haze.transmittance + haze.inscatter;
    // Alpha 1 marks terrain coverage (read back by tests; forced opaque in saved images).
    return vec4<f32>(tone(colour), 1.0);
}
