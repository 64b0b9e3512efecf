// Reads the depth buffer at one pixel into a storage buffer (depth textures cannot be
// copied in part). The depth texture is bound as an unfilterable float texture, which every
// backend can load from (the GL backend cannot `textureLoad` a `texture_depth_2d`).

@group(0) @binding(0) var depth: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> picked: array<f32, 4>;
@group(0) @binding(2) var<uniform> pixel: vec4<u32>;

@compute @workgroup_size(1)
fn read_depth() {
    picked[0] = textureLoad(depth, vec2<i32>(pixel.xy), 0).x;
}
