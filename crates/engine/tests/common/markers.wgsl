// Test markers: discs of a Gaussian brightness, either a size in pixels facing the screen
// (screen-aligned) or a size in metres in the world, writing an id into the id buffer.

struct Camera {
    clip_from_eye: mat4x4<f32>,
    // x, y: viewport size in pixels.
    viewport: vec4<f32>,
    // Camera right and up, ECEF axes (for world-sized discs).
    right: vec4<f32>,
    up: vec4<f32>,
}

struct Marker {
    // xyz: centre minus the frame's origin (f64 on the CPU); w: radius (pixels or metres).
    centre: vec4<f32>,
    colour: vec4<f32>,
    // x: id; y: 1 if the radius is in metres.
    info: vec4<u32>,
}

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<storage, read> markers: array<Marker>;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) local: vec2<f32>,
    @location(1) @interpolate(flat) index: u32,
}

@vertex
fn vs_marker(@builtin(vertex_index) v: u32, @builtin(instance_index) i: u32) -> VsOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let m = markers[i];
    let c = corners[v];
    var out: VsOut;
    if (m.info.y == 1u) {
        let p = m.centre.xyz + (camera.right.xyz * c.x + camera.up.xyz * c.y) * m.centre.w;
        out.clip = camera.clip_from_eye * vec4<f32>(p, 1.0);
    } else {
        var clip = camera.clip_from_eye * vec4<f32>(m.centre.xyz, 1.0);
        clip = vec4<f32>(clip.xy + c * m.centre.w * 2.0 / camera.viewport.xy * clip.w, clip.zw);
        out.clip = clip;
    }
    out.local = c;
    out.index = i;
    return out;
}

struct FsOut {
    @location(0) colour: vec4<f32>,
    @location(1) id: u32,
}

@fragment
fn fs_marker(in: VsOut) -> FsOut {
    let r2 = dot(in.local, in.local);
    if (r2 > 1.0) {
        discard;
    }
    let m = markers[in.index];
    var out: FsOut;
    // The red channel carries the Gaussian weight (linear), for centroids.
    out.colour = vec4<f32>(exp(-4.5 * r2) * m.colour.x, m.colour.y, m.colour.z, 1.0);
    out.id = m.info.x;
    return out;
}
