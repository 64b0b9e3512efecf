// Shared by every Globus pipeline: the per-frame uniforms and small helpers.
// Mirrors `FrameUniforms` in `frame.rs` (std140-compatible: vec4 and mat4 only).

struct Frame {
    // Projection * camera rotation: maps eye-relative world offsets (ECEF axes) to clip space.
    clip_from_eye: mat4x4<f32>,
    // Inverse of clip_from_eye (rotation and projection only): clip -> eye-relative direction.
    eye_from_clip: mat4x4<f32>,
    // xyz: geodetic up at the eye; w: eye height above the ellipsoid, metres (from f64).
    eye_up_height: vec4<f32>,
    // xyz: unit direction towards the sun (ECEF axes); w: ambient light.
    sun: vec4<f32>,
    // x: planet mean radius (m); y: atmosphere thickness (m); z: inscatter gain; w: exposure.
    planet: vec4<f32>,
    // x, y: viewport size in pixels; z, w: 1 / size.
    viewport: vec4<f32>,
    // xyz: the eye, ECEF metres (f32: for directions and texture lookups only); w: the
    // planet's first eccentricity squared.
    eye_position: vec4<f32>,
    // x: night lights gain (0: none); y: their texture's width in texels; z: metres a pixel
    // spans 1 m in front of the eye (an orthographic camera: at any distance); w: procedural
    // towns' gain (0: none; only without an image).
    night: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;

// Oct-decodes a unit vector packed as two snorm16 (Cigolle et al. 2014).
fn decode_oct(packed: u32) -> vec3<f32> {
    let e = unpack2x16snorm(packed);
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x = n.x + select(t, -t, n.x >= 0.0);
    n.y = n.y + select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// Distance along a unit ray from a point `h` above the planet's sphere in the direction `up`
// from its centre to where the ray enters (x) and leaves (y) the sphere of radius planet
// radius + `shell_m`, computed from the height so that no large number is squared in f32.
// Returns y < x when the ray misses.
fn shell_span_from(up: vec3<f32>, h: f32, dir: vec3<f32>, shell_m: f32) -> vec2<f32> {
    let r0 = frame.planet.x;
    let r = r0 + h;
    let b = r * dot(dir, up);
    // r^2 - (r0 + shell)^2 = (h - shell) (2 r0 + h + shell)
    let c = (h - shell_m) * (2.0 * r0 + h + shell_m);
    let disc = b * b - c;
    if (disc < 0.0) {
        return vec2<f32>(1.0, -1.0);
    }
    let s = sqrt(disc);
    return vec2<f32>(-b - s, -b + s);
}

// Whether the frame's camera is orthographic (its clip w is 1, not the depth).
fn is_ortho() -> bool {
    return frame.clip_from_eye[3].w != 0.0;
}

// The unit view direction of an orthographic camera (all its rays are parallel to it).
fn ortho_forward() -> vec3<f32> {
    let near = frame.eye_from_clip * vec4<f32>(0.0, 0.0, 1.0, 1.0);
    let far = frame.eye_from_clip * vec4<f32>(0.0, 0.0, 0.0, 1.0);
    return normalize(far.xyz - near.xyz);
}

// Vertical optical depth of the whole atmosphere per colour channel (Rayleigh scattering is
// about 5 times stronger in blue than in red).
const VERTICAL_DEPTH: vec3<f32> = vec3<f32>(0.06, 0.13, 0.30);
struct Air {
    // Light scattered towards the eye.
    inscatter: vec3<f32>,
    // Fraction of the light from behind that gets through, per channel.
    transmittance: vec3<f32>,
}

// The air between a point `h` above the planet's sphere (direction `up` from its centre) and
// a point `dist` away along a unit ray (or the whole sky when `dist` is huge). The atmosphere
// is a uniform shell `planet.y` thick, lit by the sun at the middle of the path; `planet.z`
// scales the scattered light relative to the sunlit ground.
fn air_from(up: vec3<f32>, h: f32, dir: vec3<f32>, dist: f32) -> Air {
    let thickness = frame.planet.y;
    let span = shell_span_from(up, h, dir, thickness);
    if (span.y <= 0.0 || span.y < span.x) {
        return Air(vec3<f32>(0.0), vec3<f32>(1.0));
    }
    let ground = shell_span_from(up, h, dir, 0.0);
    var far = min(span.y, dist);
    if (ground.y >= ground.x && ground.x > 0.0) {
        far = min(far, ground.x);
    }
    let near = max(span.x, 0.0);
    let path = max(far - near, 0.0);
    let depth = VERTICAL_DEPTH * (path / thickness);
    let transmittance = exp(-depth);
    let mid = up * (frame.planet.x + h) + dir * (0.5 * (near + far));
    let sun_height = dot(normalize(mid), frame.sun.xyz);
    let day = smoothstep(-0.2, 0.25, sun_height);
    // Low sun: the light reaching the air has itself crossed much air and lost its blue.
    let sun_colour = mix(vec3<f32>(1.0, 0.55, 0.3), vec3<f32>(1.0), smoothstep(0.0, 0.35, sun_height));
    let inscatter = (vec3<f32>(1.0) - transmittance) * sun_colour * (frame.planet.z * (0.03 + 0.97 * day));
    return Air(inscatter, transmittance);
}

// The air between the eye and a point `dist` away along a unit ray.
fn air(dir: vec3<f32>, dist: f32) -> Air {
    return air_from(frame.eye_up_height.xyz, frame.eye_up_height.w, dir, dist);
}

// The air along an orthographic camera's ray to a point at `eye_offset` from the eye: from
// where the ray leaves the eye's plane, along the view.
fn air_ortho(eye_offset: vec3<f32>) -> Air {
    let f = ortho_forward();
    let along = dot(eye_offset, f);
    // The ray's start relative to the body's centre (the eye is planet radius + height
    // along its up; the rest is small next to that).
    let start = frame.eye_up_height.xyz * (frame.planet.x + frame.eye_up_height.w) + (eye_offset - f * along);
    let r = length(start);
    return air_from(start / r, r - frame.planet.x, f, along);
}

// Filmic-ish tone curve so bright sunlit snow does not clip hard.
fn tone(c: vec3<f32>) -> vec3<f32> {
    let x = c * frame.planet.w;
    return x / (1.0 + 0.15 * x);
}
