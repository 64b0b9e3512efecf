// Shared by every Globus pipeline: the per-frame uniforms and small helpers.
// Mirrors `FrameUniforms` in `frame.rs` (std140-compatible: vec4 and mat4 only).

struct Frame {
    // Projection * camera rotation: maps eye-relative world offsets (ECEF axes) to clip space.
    clip_from_eye: mat4x4<f32>,
    // Inverse of clip_from_eye (rotation and projection only): clip -> eye-relative direction.
    eye_from_clip: mat4x4<f32>,
    // The eye in the atmosphere's space (the body stretched into a sphere, see `Atmosphere`):
    // xyz: unit direction from the centre; w: height above the sphere, metres (from f64).
    eye_up_height: vec4<f32>,
    // xyz: unit direction towards the sun (ECEF axes); w: ambient light.
    sun: vec4<f32>,
    // x: planet equatorial radius (m); y: 1 to march the air to each ground fragment instead of
    // reading the aerial-perspective table (0); z: inscatter gain; w: exposure.
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
    // The framebuffer rectangle the aerial-perspective table's columns spread over (pixels:
    // left, top, right, bottom): the viewport from the air, the air's disc from space.
    aerial: vec4<f32>,
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

const PI: f32 = 3.14159265;

// The body's air (mirrors `AtmosphereUniforms` in `globe.rs`; the model and its tables are
// `globus_geo::Atmosphere`'s, marched here with the same formulas in f32). Everything about
// the air is in the atmosphere's space: ECEF stretched per axis so that the body is the sphere
// of its equatorial radius.
struct Atmosphere {
    // xyz: Rayleigh scattering at the ground, per metre; w: its scale height, metres.
    rayleigh: vec4<f32>,
    // x: Mie scattering and y: extinction at the ground, per metre; z: scale height, metres;
    // w: asymmetry g.
    mie: vec4<f32>,
    // xyz: ozone absorption at the layer's peak, per metre; w: the peak's height, metres.
    ozone: vec4<f32>,
    // x: the sphere's radius; y: the air's thickness (0: no air); z: half the ozone layer's
    // width; w: the distance from the ground to the top along the horizon. Metres.
    shell: vec4<f32>,
    // xyz: the per-axis stretch from ECEF; w: the Sun's illuminance (pi lights a white
    // Lambertian ground facing it to 1).
    stretch: vec4<f32>,
    // The sky's light on level ground (rgb, for a Sun of illuminance 1) by the Sun's cosine
    // from the zenith, from SKY_MIN_MU to 1 in even steps (`AtmosphereTables::sky_irradiance`).
    sky_irradiance: array<vec4<f32>, 32>,
}

const SKY_MIN_MU: f32 = -0.3;

// The sky's light on level ground with the Sun at cosine `mu_s` from the zenith, in the
// shading's units (as the Sun's own term: the table's value times the Sun's illuminance
// over pi).
fn sky_irradiance(mu_s: f32) -> vec3<f32> {
    if (mu_s < SKY_MIN_MU) {
        return vec3<f32>(0.0);
    }
    let x = (min(mu_s, 1.0) - SKY_MIN_MU) / (1.0 - SKY_MIN_MU) * 31.0;
    let i = min(u32(x), 30u);
    let f = clamp(x - f32(i), 0.0, 1.0);
    let e = mix(atmosphere.sky_irradiance[i].rgb, atmosphere.sky_irradiance[i + 1u].rgb, f);
    return e * (atmosphere.stretch.w / PI);
}

@group(0) @binding(1) var<uniform> atmosphere: Atmosphere;
// Transmittance to the top of the air (Bruneton's layout, `TransmittanceLut`).
@group(0) @binding(2) var transmittance_lut: texture_2d<f32>;
// Multiply scattered light per unit scattering (`MultipleScatteringLut`).
@group(0) @binding(3) var multiple_scattering_lut: texture_2d<f32>;
@group(0) @binding(4) var lut_sampler: sampler;

// Distance along a unit ray from a point `h` above the sphere in the direction `up` from its
// centre to where the ray enters (x) and leaves (y) the sphere of radius sphere radius +
// `shell_m`, computed from the height so that no large number is squared in f32. Returns
// y < x when the ray misses.
fn shell_span_from(up: vec3<f32>, h: f32, dir: vec3<f32>, shell_m: f32) -> vec2<f32> {
    let r0 = atmosphere.shell.x;
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

// A unit quantity to the texture coordinate that puts 0 and 1 on the first and last texels'
// centres.
fn lut_coord(unit: f32, size: f32) -> f32 {
    return 0.5 / size + unit * (1.0 - 1.0 / size);
}

// Rayleigh, Mie and ozone densities (0..1) at `h` metres.
fn air_densities(h: f32) -> vec3<f32> {
    let hc = max(h, 0.0);
    return vec3<f32>(
        exp(-hc / atmosphere.rayleigh.w),
        exp(-hc / atmosphere.mie.z),
        max(1.0 - abs(hc - atmosphere.ozone.w) / atmosphere.shell.z, 0.0),
    );
}

fn air_extinction(d: vec3<f32>) -> vec3<f32> {
    return atmosphere.rayleigh.xyz * d.x + vec3<f32>(atmosphere.mie.y * d.y) + atmosphere.ozone.xyz * d.z;
}

// Transmittance from `h` metres along a ray of vertical cosine `mu` to the top of the air.
fn transmittance_to_top(h: f32, mu: f32) -> vec3<f32> {
    let r0 = atmosphere.shell.x;
    let top = atmosphere.shell.y;
    let horizon = atmosphere.shell.w;
    let hc = clamp(h, 0.0, top);
    let rho = sqrt(hc * (2.0 * r0 + hc));
    let r = r0 + hc;
    let c = (top - hc) * (2.0 * r0 + top + hc);
    let d = max(-r * mu + sqrt(max(r * r * mu * mu + c, 0.0)), 0.0);
    let d_min = top - hc;
    let d_max = rho + horizon;
    let x_mu = clamp((d - d_min) / (d_max - d_min), 0.0, 1.0);
    let size = vec2<f32>(textureDimensions(transmittance_lut));
    let uv = vec2<f32>(lut_coord(x_mu, size.x), lut_coord(rho / horizon, size.y));
    return textureSampleLevel(transmittance_lut, lut_sampler, uv, 0.0).rgb;
}

// Sunlight reaching a point `h` metres up whose vertical has cosine `mu_s` with the Sun:
// what the air lets through, faded out as the Sun's disc sets behind the body's horizon.
fn sun_light(h: f32, mu_s: f32) -> vec3<f32> {
    if (atmosphere.shell.y <= 0.0) {
        return vec3<f32>(1.0);
    }
    let hc = max(h, 0.0);
    let horizon_mu = -sqrt(hc * (2.0 * atmosphere.shell.x + hc)) / (atmosphere.shell.x + hc);
    let visible = smoothstep(horizon_mu - SUN_HALF_WIDTH, horizon_mu + SUN_HALF_WIDTH, mu_s);
    return transmittance_to_top(h, mu_s) * visible;
}

// Half the Sun's apparent width, as a cosine step near the horizon (radians).
const SUN_HALF_WIDTH: f32 = 0.0046;

// Multiply scattered light per unit scattering at `h` metres, Sun at vertical cosine `mu_s`.
fn multiple_scattering(h: f32, mu_s: f32) -> vec3<f32> {
    let size = f32(textureDimensions(multiple_scattering_lut).x);
    let uv = vec2<f32>(
        lut_coord(clamp(mu_s * 0.5 + 0.5, 0.0, 1.0), size),
        lut_coord(clamp(h / atmosphere.shell.y, 0.0, 1.0), size),
    );
    return textureSampleLevel(multiple_scattering_lut, lut_sampler, uv, 0.0).rgb;
}

// The Sun's direction in the atmosphere's space.
fn air_sun() -> vec3<f32> {
    return normalize(frame.sun.xyz * atmosphere.stretch.xyz);
}

struct Air {
    // Light scattered towards the eye.
    inscatter: vec3<f32>,
    // Fraction of the light from behind that gets through, per channel.
    transmittance: vec3<f32>,
}

// Rayleigh (x) and Cornette-Shanks Mie (y) phase functions at cosine `cos_theta` between the
// ray and the Sun.
fn air_phases(cos_theta: f32) -> vec2<f32> {
    let g = atmosphere.mie.w;
    return vec2<f32>(
        3.0 / (16.0 * PI) * (1.0 + cos_theta * cos_theta),
        3.0 / (8.0 * PI) * (1.0 - g * g) / (2.0 + g * g) * (1.0 + cos_theta * cos_theta)
            / pow(1.0 + g * g - 2.0 * g * cos_theta, 1.5),
    );
}

// `acc` carried over the stretch from `a` to `b` along the ray from `origin` in the unit
// direction `dir` (Hillaire 2020, equation 6's per-step integral at the stretch's middle):
// sunlight singly scattered (the phases of `air_phases`, the body's shadow) and multiply
// scattered (the table) towards the eye, in units of the Sun's illuminance and before the
// inscatter gain; the transmittance multiplies by the stretch's.
fn air_step(acc: Air, origin: vec3<f32>, dir: vec3<f32>, a: f32, b: f32, sun: vec3<f32>, phases: vec2<f32>) -> Air {
    let dt = b - a;
    let p = origin + dir * (0.5 * (a + b));
    let r = length(p);
    let hp = r - atmosphere.shell.x;
    let mu_s = dot(p, sun) / r;
    let d = air_densities(hp);
    let rayleigh = atmosphere.rayleigh.xyz * d.x;
    let mie = atmosphere.mie.x * d.y;
    let source = sun_light(hp, mu_s) * (rayleigh * phases.x + vec3<f32>(mie * phases.y))
        + (rayleigh + vec3<f32>(mie)) * multiple_scattering(hp, mu_s);
    let extinction = air_extinction(d);
    let step = exp(-extinction * dt);
    return Air(
        acc.inscatter + acc.transmittance * source * (vec3<f32>(1.0) - step) / max(extinction, vec3<f32>(1e-12)),
        acc.transmittance * step,
    );
}

// What the inscatter of `air_step` is multiplied by for display.
fn air_gain() -> f32 {
    return atmosphere.stretch.w * frame.planet.z;
}

// The air between a point `h` above the sphere (unit direction `up` from its centre) and a
// point `dist` away along the unit ray `dir` (the sky beyond, when `dist` is huge), all in the
// atmosphere's space, marched in `steps` of `air_step`, scaled by `planet.z` relative to the
// sunlit ground.
fn air_march(up: vec3<f32>, h: f32, dir: vec3<f32>, dist: f32, steps: i32) -> Air {
    let clear = Air(vec3<f32>(0.0), vec3<f32>(1.0));
    if (atmosphere.shell.y <= 0.0) {
        return clear;
    }
    let span = shell_span_from(up, h, dir, atmosphere.shell.y);
    if (span.y <= 0.0 || span.y < span.x) {
        return clear;
    }
    let ground = shell_span_from(up, h, dir, 0.0);
    var far = min(span.y, dist);
    if (ground.y >= ground.x && ground.x > 0.0) {
        far = min(far, ground.x);
    }
    let near = max(span.x, 0.0);
    if (far <= near) {
        return clear;
    }
    let sun = air_sun();
    let phases = air_phases(dot(dir, sun));
    let origin = up * (atmosphere.shell.x + h);
    // Samples crowd towards the ray's lowest point, where the air is densest (the eye's end
    // looking up, the ground's looking down, the tangent point along the limb): on each side
    // of it the segments grow with the square of their index.
    let lowest = clamp(-dot(origin, dir), near, far);
    let before = lowest - near;
    let after = far - lowest;
    let tiny = 0.01 * (far - near);
    var split = 0;
    if (before > tiny) {
        split = select(steps / 2, steps, after <= tiny);
    }
    var acc = clear;
    for (var i = 0; i < steps; i = i + 1) {
        var a: f32;
        var b: f32;
        if (i < split) {
            let n = f32(split);
            let k = f32(split - 1 - i);
            a = lowest - before * ((k + 1.0) / n) * ((k + 1.0) / n);
            b = lowest - before * (k / n) * (k / n);
        } else {
            let n = f32(steps - split);
            let k = f32(i - split);
            a = lowest + after * (k / n) * (k / n);
            b = lowest + after * ((k + 1.0) / n) * ((k + 1.0) / n);
        }
        acc = air_step(acc, origin, dir, a, b, sun, phases);
    }
    return Air(acc.inscatter * air_gain(), acc.transmittance);
}

// The air between the eye and a point `dist` away along a unit ray (ECEF axes), or the sky
// beyond when `dist` is huge.
fn air(dir: vec3<f32>, dist: f32, steps: i32) -> Air {
    let d = dir * atmosphere.stretch.xyz;
    let k = length(d);
    return air_march(frame.eye_up_height.xyz, frame.eye_up_height.w, d / k, dist * k, steps);
}

// Where an orthographic camera's ray through `eye_offset` (ECEF axes, from the eye) leaves
// the eye's plane, in the atmosphere's space: unit up (xyz) and height (w).
fn ortho_start(eye_offset: vec3<f32>, forward: vec3<f32>) -> vec4<f32> {
    let across = (eye_offset - forward * dot(eye_offset, forward)) * atmosphere.stretch.xyz;
    let start = frame.eye_up_height.xyz * (atmosphere.shell.x + frame.eye_up_height.w) + across;
    let r = length(start);
    return vec4<f32>(start / r, r - atmosphere.shell.x);
}

// The air along an orthographic camera's ray to a point at `eye_offset` from the eye (or the
// sky beyond, when `sky`): from where the ray leaves the eye's plane, along the view.
fn air_ortho(eye_offset: vec3<f32>, sky: bool, steps: i32) -> Air {
    let f = ortho_forward();
    let start = ortho_start(eye_offset, f);
    let d = f * atmosphere.stretch.xyz;
    let k = length(d);
    var dist = 1e30;
    if (!sky) {
        dist = dot(eye_offset, f) * k;
    }
    return air_march(start.xyz, start.w, d / k, dist, steps);
}

// The aerial-perspective table (Hillaire 2020's froxels, `aerial.wgsl`, `aerial.rs`): the air
// between the eye and points along the rays through a grid of AP_COLUMNS screen points, at
// AP_SLICES depths along each. The columns' rays go through a regular grid of points spanning
// `frame.aerial` edge to edge, column (i, j) the i-th from the left and the j-th from the top.
const AP_COLUMNS: vec2<u32> = vec2<u32>(32u, 32u);
const AP_SLICES: u32 = 32u;

// The unit ray through the centre of column `c`, in the atmosphere's space.
fn ap_ray(c: vec2<u32>) -> vec3<f32> {
    let px = mix(frame.aerial.xy, frame.aerial.zw, vec2<f32>(c) / vec2<f32>(AP_COLUMNS - 1u));
    let uv = px * frame.viewport.zw;
    let ndc = vec2<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0);
    // Reversed-Z: depth 1 is the near plane; the point there gives the view ray.
    let near = frame.eye_from_clip * vec4<f32>(ndc, 1.0, 1.0);
    let d = normalize(near.xyz / near.w) * atmosphere.stretch.xyz;
    return d / length(d);
}

// Whether the eye is in the air: then a column's slices crowd towards it (the square of the
// depth); from space they crowd towards the column's far end, near the ground, where the air
// is dense.
fn ap_in_air() -> bool {
    return frame.eye_up_height.w < atmosphere.shell.y;
}

// The distance along a column whose air spans `range` (from the eye, atmosphere's space) at
// depth `w` (0 at the range's start, 1 at its end).
fn ap_distance(range: vec2<f32>, w: f32) -> f32 {
    let x = select(1.0 - (1.0 - w) * (1.0 - w), w * w, ap_in_air());
    return range.x + (range.y - range.x) * x;
}

// The inverse of `ap_distance`, clamped to the range.
fn ap_depth(range: vec2<f32>, t: f32) -> f32 {
    let x = clamp((t - range.x) / max(range.y - range.x, 1e-6), 0.0, 1.0);
    return select(1.0 - sqrt(1.0 - x), sqrt(x), ap_in_air());
}

// Along a unit ray from the eye (atmosphere's space): where it enters the air (x; 0 from
// inside it) and where it meets the body's sphere (y), or, if it misses, the distance to the
// body's silhouette, which is where rays that just meet it do (so it is continuous across
// the silhouette); z is 1 if it meets it. Points of neighbouring rays at the same share of
// the way from x to y are at about the same height, which is how the table's columns are
// matched to a pixel's ray from space.
fn ap_entry_and_ground(dir: vec3<f32>) -> vec3<f32> {
    let up = frame.eye_up_height.xyz;
    let h = frame.eye_up_height.w;
    let span = shell_span_from(up, h, dir, atmosphere.shell.y);
    let ground = shell_span_from(up, h, dir, 0.0);
    if (ground.y >= ground.x && ground.x > 0.0) {
        return vec3<f32>(max(span.x, 0.0), ground.x, 1.0);
    }
    return vec3<f32>(max(span.x, 0.0), sqrt(max(h, 1.0) * (2.0 * atmosphere.shell.x + max(h, 1.0))), 0.0);
}

// Filmic-ish tone curve so bright sunlit snow does not clip hard.
fn tone(c: vec3<f32>) -> vec3<f32> {
    let x = c * frame.planet.w;
    return x / (1.0 + 0.15 * x);
}
