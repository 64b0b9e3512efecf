// Sky and space: one full-screen triangle behind everything (drawn first, no depth).
// Alpha 0 marks background coverage.

struct SkyOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
}

@vertex
fn vs_sky(@builtin(vertex_index) index: u32) -> SkyOut {
    let xy = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u)) * 2.0 - 1.0;
    var out: SkyOut;
    out.clip = vec4<f32>(xy, 0.0, 1.0);
    out.ndc = xy;
    return out;
}

@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let space = vec3<f32>(0.0004, 0.0005, 0.0012);
    // An orthographic view's rays are parallel, each from its own point on the eye's plane:
    // space, and the atmosphere's rim round the planet.
    if (is_ortho()) {
        let p = frame.eye_from_clip * vec4<f32>(in.ndc, 1.0, 1.0);
        let start = frame.eye_up_height.xyz * (frame.planet.x + frame.eye_up_height.w) + p.xyz / p.w;
        let r = length(start);
        let rim = air_from(start / r, r - frame.planet.x, ortho_forward(), 3.0e38).inscatter;
        return vec4<f32>(tone(space + rim), 0.0);
    }
    // Reversed-Z: depth 1 is the near plane; the point there gives the view ray.
    let near = frame.eye_from_clip * vec4<f32>(in.ndc, 1.0, 1.0);
    let dir = normalize(near.xyz / near.w);
    let sky = air(dir, 3.0e38).inscatter;
    // The sun disc.
    let sun = smoothstep(0.9995, 0.9998, dot(dir, frame.sun.xyz));
    return vec4<f32>(tone(space + sky + vec3<f32>(sun * 3.0)), 0.0);
}
