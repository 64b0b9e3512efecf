// Shared by the engine's overlay shaders, which are compiled with this file in front of
// them: sRGB colours, and tests against the depth the terrain pass left. A shader using
// `terrain_*` declares `terrain_depth: texture_2d<f32>` (the terrain's depth copy, read
// with textureLoad).

// Styles are sRGB; the colour targets are sRGB formats, which expect linear values.
fn srgb_to_linear(c: u32) -> vec4<f32> {
    let s = unpack4x8unorm(c);
    let lo = s.rgb / 12.92;
    let hi = pow((s.rgb + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return vec4<f32>(select(hi, lo, s.rgb <= vec3<f32>(0.04045)), s.a);
}

// The terrain's depth at a texel, 0 (infinitely far) outside the frame.
fn terrain_at(t: vec2<i32>) -> f32 {
    let size = vec2<i32>(textureDimensions(terrain_depth));
    if (any(t < vec2<i32>(0)) || any(t >= size)) {
        return 0.0;
    }
    return textureLoad(terrain_depth, t, 0).r;
}

// The farthest of the terrain's depths at the four texels round a pixel position (reversed
// Z: the least). Something there at depth `z` is hidden when even that is nearer than it:
// on the surface it lies on, some of the four are at or behind it.
fn terrain_farthest_around(p: vec2<f32>) -> f32 {
    let q = vec2<i32>(floor(p - vec2<f32>(0.5)));
    return min(
        min(terrain_at(q), terrain_at(q + vec2<i32>(1, 0))),
        min(terrain_at(q + vec2<i32>(0, 1)), terrain_at(q + vec2<i32>(1, 1))),
    );
}

// Whether a camera's clip_from_eye is orthographic: its clip w is 1, not the depth.
fn is_orthographic(clip_from_eye: mat4x4<f32>) -> bool {
    return clip_from_eye[3].w != 0.0;
}
