// Sky and space: one full-screen triangle at the far plane, drawn after the terrain where the
// depth is still cleared (no depth written).
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

// Samples along a ray through the sky.
const SKY_STEPS: i32 = 24;

// The sky seen from the eye (Hillaire's sky-view table, rebuilt every frame while the eye is
// in the air): 192 x 108 texels of inscattered light, x the azimuth from the Sun's (0 to
// 180 degrees: the sky is symmetric about the Sun's vertical plane), y the elevation from
// the zenith (row 0) to the horizon (row 53) and from just under it (row 54) to the nadir,
// rows crowded towards the horizon (the square of the angle from it). Nothing filters across
// the horizon, where the light changes fastest.
@group(1) @binding(0) var sky_view: texture_2d<f32>;
@group(1) @binding(1) var sky_view_sampler: sampler;

const SKY_VIEW_SIZE: vec2<f32> = vec2<f32>(192.0, 108.0);
const HALF_PI: f32 = 1.57079633;

// The eye's frame in the atmosphere's space: z its vertical, x towards the Sun's azimuth.
fn sky_frame() -> mat3x3<f32> {
    let up = frame.eye_up_height.xyz;
    let sun = air_sun();
    var x = sun - up * dot(sun, up);
    if (dot(x, x) < 1e-8) {
        // The Sun straight up or down: any horizontal direction.
        x = cross(up, select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), abs(up.x) > 0.9));
    }
    x = normalize(x);
    return mat3x3<f32>(x, cross(up, x), up);
}

// Elevation of the body's horizon from the eye (radians, at most 0).
fn horizon_elevation() -> f32 {
    let h = max(frame.eye_up_height.w, 0.0);
    return -acos(clamp(atmosphere.shell.x / (atmosphere.shell.x + h), -1.0, 1.0));
}

// Table coordinates of a unit direction in the atmosphere's space.
fn sky_view_uv(dir: vec3<f32>, basis: mat3x3<f32>) -> vec2<f32> {
    let local = transpose(basis) * dir;
    let azimuth = abs(atan2(local.y, local.x));
    let elevation = asin(clamp(local.z, -1.0, 1.0));
    let beta = horizon_elevation();
    let rows = SKY_VIEW_SIZE.y * 0.5;
    var row: f32;
    if (elevation >= beta) {
        let t = sqrt(clamp((elevation - beta) / (HALF_PI - beta), 0.0, 1.0));
        row = (1.0 - t) * (rows - 1.0);
    } else {
        let t = sqrt(clamp((beta - elevation) / (HALF_PI + beta), 0.0, 1.0));
        row = rows + t * (rows - 1.0);
    }
    let column = azimuth / PI * (SKY_VIEW_SIZE.x - 1.0);
    return (vec2<f32>(column, row) + 0.5) / SKY_VIEW_SIZE;
}

// Builds the sky-view table: one texel's direction, marched.
@fragment
fn fs_sky_view(@builtin(position) at: vec4<f32>) -> @location(0) vec4<f32> {
    let texel = floor(at.xy);
    let rows = SKY_VIEW_SIZE.y * 0.5;
    let beta = horizon_elevation();
    var elevation: f32;
    if (texel.y < rows) {
        let t = 1.0 - texel.y / (rows - 1.0);
        elevation = beta + (HALF_PI - beta) * t * t;
    } else {
        let t = (texel.y - rows) / (rows - 1.0);
        elevation = beta - (HALF_PI + beta) * t * t;
    }
    let azimuth = texel.x / (SKY_VIEW_SIZE.x - 1.0) * PI;
    let local = vec3<f32>(cos(elevation) * cos(azimuth), cos(elevation) * sin(azimuth), sin(elevation));
    let dir = sky_frame() * local;
    let sky = air_march(frame.eye_up_height.xyz, frame.eye_up_height.w, dir, 1e30, SKY_VIEW_STEPS);
    return vec4<f32>(sky.inscatter, 1.0);
}

// Samples along each direction of the sky-view table.
const SKY_VIEW_STEPS: i32 = 30;

@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let space = vec3<f32>(0.0004, 0.0005, 0.0012);
    // An orthographic view's rays are parallel, each from its own point on the eye's plane:
    // space, and the atmosphere's rim round the planet.
    if (is_ortho()) {
        let p = frame.eye_from_clip * vec4<f32>(in.ndc, 1.0, 1.0);
        let rim = air_ortho(p.xyz / p.w, true, SKY_STEPS).inscatter;
        return vec4<f32>(tone(space + rim), 0.0);
    }
    // Reversed-Z: depth 1 is the near plane; the point there gives the view ray.
    let near = frame.eye_from_clip * vec4<f32>(in.ndc, 1.0, 1.0);
    let dir = normalize(near.xyz / near.w);
    let d = dir * atmosphere.stretch.xyz;
    let air_dir = d / length(d);
    var sky: vec3<f32>;
    var through = vec3<f32>(1.0);
    let mu = dot(air_dir, frame.eye_up_height.xyz);
    let ground = shell_span_from(frame.eye_up_height.xyz, frame.eye_up_height.w, air_dir, 0.0);
    let hits_ground = ground.y >= ground.x && ground.x > 0.0;
    if (frame.eye_up_height.w < atmosphere.shell.y) {
        // In the air: the table (one lookup instead of a march per pixel).
        sky = textureSampleLevel(sky_view, sky_view_sampler, sky_view_uv(air_dir, sky_frame()), 0.0).rgb;
        if (!hits_ground) {
            through = transmittance_to_top(frame.eye_up_height.w, mu);
        }
    } else {
        // From space most rays miss the air, and those that do not are marched.
        let marched = air_march(frame.eye_up_height.xyz, frame.eye_up_height.w, air_dir, 1e30, SKY_STEPS);
        sky = marched.inscatter;
        through = marched.transmittance;
    }
    if (hits_ground) {
        through = vec3<f32>(0.0);
    }
    // The Sun's disc (0.53 degree across, softened over as much again outside), through the
    // air between it and the eye.
    let disc = smoothstep(0.99996, 0.999989, dot(dir, frame.sun.xyz));
    let sun = vec3<f32>(disc * 3.0) * through;
    return vec4<f32>(tone(space * through + sky + sun), 0.0);
}
