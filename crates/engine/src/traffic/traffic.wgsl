// Air traffic: trails (world pass, screen-space ribbons faded by age), models (world pass,
// instanced per kind, lit by the sun) and symbols (screen-aligned, pointing along the
// heading). Every aircraft's position reaches the GPU as an offset from the eye computed in
// f64 on the CPU; trail points are offsets from their aircraft's trail anchor, whose offset
// from the eye is likewise computed each frame.

struct Frame {
    clip_from_eye: mat4x4<f32>,
    // Width, height, 1 / width, 1 / height (pixels).
    viewport: vec4<f32>,
    // x: focal length (pixels; pixels per metre when orthographic), y: now (seconds since the layer's epoch), z: trail length
    // (seconds), w: how much nearer than its depth a symbol may be behind terrain (fraction).
    params: vec4<f32>,
    // Towards the sun (ECEF axes), w: ambient light.
    sun: vec4<f32>,
    // x: trail points per aircraft, y: first pick id, z: trail width (pixels, as bits).
    counts: vec4<u32>,
    // Per kind: x symbol size (pixels), y model extent (metres).
    kinds: array<vec4<f32>, 4>,
}

// Mirrors `AircraftGpu` (64 bytes).
struct Aircraft {
    position: vec3<f32>,
    colour: u32,
    // The geodetic normal at the aircraft (its local vertical).
    normal: vec3<f32>,
    bits: u32,
    anchor: vec3<f32>,
    // Ring head (low 16 bits) and length (high 16 bits).
    ring: u32,
    // Heading (clockwise from north) and pitch, radians.
    heading: f32,
    pitch: f32,
    // Trail points older than now (low 16 bits), and the stride drawn (high 16).
    trail: u32,
    spare: u32,
}

// Nose and up of an airframe from its local vertical, heading and pitch (directions only:
// f32 is plenty).
struct Attitude {
    forward: vec3<f32>,
    up: vec3<f32>,
}

fn attitude(a: Aircraft) -> Attitude {
    let n = a.normal;
    var east = cross(vec3<f32>(0.0, 0.0, 1.0), n);
    if (length(east) < 1e-6) {
        // At a pole: east of longitude 0.
        east = vec3<f32>(0.0, 1.0, 0.0);
    }
    east = normalize(east);
    let north = cross(n, east);
    let horizontal = north * cos(a.heading) + east * sin(a.heading);
    let forward = horizontal * cos(a.pitch) + n * sin(a.pitch);
    let up = n * cos(a.pitch) - horizontal * sin(a.pitch);
    return Attitude(forward, up);
}

const LIVE: u32 = 1u;
const SELECTED: u32 = 2u;
const STALE: u32 = 4u;

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> aircraft: array<Aircraft>;
// Per trail point: offset from its aircraft's anchor (xyz, metres), seconds since the epoch.
@group(0) @binding(2) var<storage, read> trail_points: array<vec4<f32>>;
@group(0) @binding(3) var terrain_depth: texture_2d<f32>;

fn kind_of(a: Aircraft) -> u32 {
    return (a.bits >> 8u) & 3u;
}

fn to_pixels(clip: vec4<f32>) -> vec2<f32> {
    let ndc = clip.xy / clip.w;
    return vec2<f32>((ndc.x * 0.5 + 0.5) * frame.viewport.x, (0.5 - ndc.y * 0.5) * frame.viewport.y);
}

// Clip position of a pixel position at the depth and w of `like`.
fn from_pixels(px: vec2<f32>, like: vec4<f32>) -> vec4<f32> {
    let ndc = vec2<f32>(px.x * frame.viewport.z * 2.0 - 1.0, 1.0 - px.y * frame.viewport.w * 2.0);
    return vec4<f32>(ndc * like.w, like.z, like.w);
}

// An aircraft's size on screen at its true dimensions, pixels.
fn true_px(a: Aircraft) -> f32 {
    let per_m = select(
        frame.params.x / max(length(a.position), 1e-3),
        frame.params.x,
        is_orthographic(frame.clip_from_eye),
    );
    return frame.kinds[kind_of(a)].y * per_m;
}

// How much of the symbol shows (1 far away, 0 once the model is large enough).
fn symbol_weight(a: Aircraft) -> f32 {
    let n = frame.kinds[kind_of(a)].x;
    return 1.0 - smoothstep(0.75 * n, 1.25 * n, true_px(a));
}

const OFF: vec4<f32> = vec4<f32>(0.0, 0.0, -2.0, 1.0);

struct Target {
    @location(0) colour: vec4<f32>,
    @location(1) id: u32,
}

// ---- trails ----

struct TrailOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) across_px: f32,
    @location(1) age_s: f32,
    @location(2) @interpolate(flat) colour: vec4<f32>,
    @location(3) @interpolate(flat) half_width: f32,
}

// Eye-space depth below which a segment end is moved along it (in front of the camera).
const NEAR_W: f32 = 1e-3;

fn ring_point(slot: u32, a: Aircraft, k: u32) -> vec4<f32> {
    let n = frame.counts.x;
    let len = a.ring >> 16u;
    let head = a.ring & 0xffffu;
    return trail_points[slot * n + (head + n - len + k) % n];
}

// Segment `m` of a trail, newest first: 0 joins the aircraft to its newest past point, each
// next one goes `stride` points further back (the CPU picks the stride so segments stay a
// few pixels long).
@vertex
fn trail_vs(@builtin(vertex_index) vi: u32, @location(0) slot: u32) -> TrailOut {
    var out: TrailOut;
    out.clip = OFF;
    let m = i32(vi / 6u);
    let corner = vi % 6u;
    let a = aircraft[slot];
    let past = i32(a.trail & 0xffffu);
    let stride = max(i32(a.trail >> 16u), 1);
    if ((a.bits & LIVE) == 0u || past == 0) {
        return out;
    }
    let now = frame.params.y;
    let newest = past - 1;
    var pb = vec4<f32>(a.position - a.anchor, now);
    if (m > 0) {
        let k = newest - (m - 1) * stride;
        if (k <= 0) {
            return out;
        }
        pb = ring_point(slot, a, u32(k));
    }
    let pa = ring_point(slot, a, u32(max(newest - m * stride, 0)));
    let age_a = now - pa.w;
    let age_b = now - pb.w;
    if (age_b > frame.params.z) {
        return out;
    }
    var ca = frame.clip_from_eye * vec4<f32>(a.anchor + pa.xyz, 1.0);
    var cb = frame.clip_from_eye * vec4<f32>(a.anchor + pb.xyz, 1.0);
    if (ca.w < NEAR_W && cb.w < NEAR_W) {
        return out;
    }
    var wa = age_a;
    var wb = age_b;
    if (ca.w < NEAR_W) {
        let f = (NEAR_W - ca.w) / (cb.w - ca.w);
        ca = mix(ca, cb, f);
        wa = mix(age_a, age_b, f);
    } else if (cb.w < NEAR_W) {
        let f = (NEAR_W - cb.w) / (ca.w - cb.w);
        cb = mix(cb, ca, f);
        wb = mix(age_b, age_a, f);
    }
    let sa = to_pixels(ca);
    let sb = to_pixels(cb);
    var dir = sb - sa;
    let l = length(dir);
    dir = select(vec2<f32>(1.0, 0.0), dir / l, l > 1e-4);
    let perp = vec2<f32>(-dir.y, dir.x);
    let selected = (a.bits & SELECTED) != 0u;
    let hw = bitcast<f32>(frame.counts.z) * select(0.5, 1.0, selected);
    let reach = hw + 1.0;
    // Corners: 0 1 2 / 2 1 3 of (end, side).
    let ends = array<u32, 6>(0u, 0u, 1u, 1u, 0u, 1u);
    let sides = array<f32, 6>(-1.0, 1.0, -1.0, -1.0, 1.0, 1.0);
    let e = ends[corner];
    let side = sides[corner];
    // Butt ends: consecutive segments meet edge to edge, so a translucent trail is not
    // drawn twice where they join.
    let base = select(sa, sb, e == 1u);
    let like = select(ca, cb, e == 1u);
    out.clip = from_pixels(base + perp * side * reach, like);
    out.across_px = side * reach;
    out.age_s = select(wa, wb, e == 1u);
    var colour = srgb_to_linear(a.colour);
    if (selected) {
        colour = vec4<f32>(mix(colour.rgb, vec3<f32>(1.0, 0.9, 0.2), 0.6), 1.0);
    }
    out.colour = colour;
    out.half_width = hw;
    return out;
}

@fragment
fn trail_fs(in: TrailOut) -> @location(0) vec4<f32> {
    let coverage = clamp(in.half_width + 0.5 - abs(in.across_px), 0.0, 1.0);
    // Full near the aircraft, nothing at the trail's age.
    let fade = clamp(1.0 - in.age_s / frame.params.z, 0.0, 1.0);
    let a = in.colour.a * coverage * 0.9 * sqrt(fade);
    if (a <= 0.004) {
        discard;
    }
    return vec4<f32>(in.colour.rgb, a);
}

// ---- models ----

struct ModelIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) slot: u32,
    @location(3) accent: u32,
}

struct ModelOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) @interpolate(flat) colour: vec4<f32>,
    @location(2) @interpolate(flat) id: u32,
    // The aircraft's up, and the direction from the eye (for the highlight).
    @location(3) @interpolate(flat) up: vec3<f32>,
    @location(4) view: vec3<f32>,
}

@vertex
fn model_vs(v: ModelIn) -> ModelOut {
    var out: ModelOut;
    out.clip = OFF;
    let a = aircraft[v.slot];
    let n = frame.kinds[kind_of(a)].x;
    let size = true_px(a);
    if ((a.bits & LIVE) == 0u || size < 0.75 * n) {
        return out;
    }
    // Never smaller than the symbol it replaces.
    let scale = max(1.0, n / max(size, 1e-3));
    let att = attitude(a);
    let left = cross(att.up, att.forward);
    let offset = (att.forward * v.position.x + left * v.position.y + att.up * v.position.z) * scale;
    out.clip = frame.clip_from_eye * vec4<f32>(a.position + offset, 1.0);
    out.normal = att.forward * v.normal.x + left * v.normal.y + att.up * v.normal.z;
    // White airframes; fin and nacelles in the aircraft's colour (as its symbol and trail).
    var base = select(vec3<f32>(0.8, 0.82, 0.85), srgb_to_linear(a.colour).rgb, v.accent != 0u);
    if ((a.bits & SELECTED) != 0u) {
        base = mix(base, vec3<f32>(1.0, 0.85, 0.1), 0.5);
    }
    out.colour = vec4<f32>(base, 1.0);
    out.id = frame.counts.y + v.slot;
    out.up = att.up;
    out.view = a.position + offset;
    return out;
}

@fragment
fn model_fs(in: ModelOut, @builtin(front_facing) front: bool) -> Target {
    let n = normalize(select(-in.normal, in.normal, front));
    let sun = frame.sun.xyz;
    let diffuse = max(dot(n, sun), 0.0);
    // Sky light: more on faces turned up than on the belly.
    let sky = frame.sun.w * (0.55 + 0.45 * dot(n, in.up));
    // A glint off the paint.
    let to_eye = -normalize(in.view);
    let glint = pow(max(dot(reflect(-sun, n), to_eye), 0.0), 24.0) * 0.35;
    let rgb = in.colour.rgb * (sky + (1.0 - frame.sun.w) * diffuse) + vec3<f32>(glint);
    return Target(vec4<f32>(rgb, 1.0), in.id);
}

// ---- symbols ----

struct SymbolOut {
    @builtin(position) clip: vec4<f32>,
    // Position in the symbol's square: x across, y along the heading, -1..1 for the symbol.
    @location(0) local: vec2<f32>,
    @location(1) @interpolate(flat) colour: vec4<f32>,
    @location(2) @interpolate(flat) id: u32,
    // Kind, selected, stale.
    @location(3) @interpolate(flat) bits: u32,
    // Centre pixel, depth at the centre, symbol half size (pixels).
    @location(4) @interpolate(flat) centre: vec4<f32>,
    @location(5) @interpolate(flat) weight: f32,
}

// How far the quad reaches beyond the symbol (outline, selection ring).
const SYMBOL_MARGIN: f32 = 1.45;

@vertex
fn symbol_vs(@builtin(vertex_index) vi: u32) -> SymbolOut {
    var out: SymbolOut;
    out.clip = OFF;
    let slot = vi / 6u;
    let corner = vi % 6u;
    let a = aircraft[slot];
    if ((a.bits & LIVE) == 0u) {
        return out;
    }
    let weight = symbol_weight(a);
    if (weight <= 0.0) {
        return out;
    }
    let c = frame.clip_from_eye * vec4<f32>(a.position, 1.0);
    if (c.w < NEAR_W) {
        return out;
    }
    let centre = to_pixels(c);
    // The heading on screen: where a point a little ahead lands.
    let forward = attitude(a).forward;
    let ahead = frame.clip_from_eye * vec4<f32>(a.position + forward * max(length(a.position) * 0.01, 1.0), 1.0);
    var along = vec2<f32>(0.0, -1.0);
    if (ahead.w > NEAR_W) {
        let d = to_pixels(ahead) - centre;
        if (length(d) > 1e-3) {
            along = normalize(d);
        }
    }
    let across = vec2<f32>(-along.y, along.x);
    let half_size = frame.kinds[kind_of(a)].x * 0.5;
    let xs = array<f32, 6>(-1.0, 1.0, -1.0, -1.0, 1.0, 1.0);
    let ys = array<f32, 6>(-1.0, -1.0, 1.0, 1.0, -1.0, 1.0);
    let local = vec2<f32>(xs[corner], ys[corner]) * SYMBOL_MARGIN;
    // Screen y grows downwards; `along` is already in screen pixels.
    let px = centre + (across * local.x + along * local.y) * half_size;
    out.clip = from_pixels(px, c);
    out.local = local;
    var colour = srgb_to_linear(a.colour);
    if ((a.bits & STALE) != 0u) {
        colour.a = colour.a * 0.45;
    }
    out.colour = colour;
    out.id = frame.counts.y + slot;
    out.bits = kind_of(a) | ((a.bits & (SELECTED | STALE)) << 4u);
    out.centre = vec4<f32>(centre, c.z / c.w, half_size);
    out.weight = weight;
    return out;
}

fn segment_sdf(p: vec2<f32>, a: vec2<f32>, b: vec2<f32>, r: f32) -> f32 {
    let pa = p - a;
    let ba = b - a;
    let h = clamp(dot(pa, ba) / dot(ba, ba), 0.0, 1.0);
    return length(pa - ba * h) - r;
}

// The silhouette seen from above, in symbol units (the symbol spans -1..1), negative inside.
fn silhouette(p_in: vec2<f32>, kind: u32) -> f32 {
    // Mirror: shapes are symmetric about the heading.
    let p = vec2<f32>(abs(p_in.x), p_in.y);
    if (kind == 3u) {
        // Helicopter: cabin, boom, tail rotor, main rotor ring.
        var d = length(p - vec2<f32>(0.0, 0.2)) - 0.3;
        d = min(d, segment_sdf(p, vec2<f32>(0.0, 0.0), vec2<f32>(0.0, -0.85), 0.08));
        d = min(d, segment_sdf(p, vec2<f32>(0.0, -0.85), vec2<f32>(0.2, -0.85), 0.06));
        d = min(d, abs(length(p - vec2<f32>(0.0, 0.2)) - 0.8) - 0.05);
        return d;
    }
    if (kind == 0u) {
        // Light aircraft: straight high wing.
        var d = segment_sdf(p, vec2<f32>(0.0, -0.8), vec2<f32>(0.0, 0.8), 0.13);
        d = min(d, segment_sdf(p, vec2<f32>(0.0, 0.25), vec2<f32>(0.95, 0.25), 0.14));
        d = min(d, segment_sdf(p, vec2<f32>(0.0, -0.72), vec2<f32>(0.36, -0.72), 0.09));
        return d;
    }
    // Airliners: swept wings, tailplane.
    var d = segment_sdf(p, vec2<f32>(0.0, -0.88), vec2<f32>(0.0, 0.9), 0.12);
    d = min(d, segment_sdf(p, vec2<f32>(0.0, 0.2), vec2<f32>(0.92, -0.22), 0.11));
    d = min(d, segment_sdf(p, vec2<f32>(0.0, -0.66), vec2<f32>(0.38, -0.86), 0.08));
    return d;
}

@fragment
fn symbol_fs(in: SymbolOut) -> Target {
    // Hidden when the terrain at its centre is nearer than the aircraft (reversed-Z: nearer
    // is greater); decided once for the whole symbol, so it never shows half cut.
    if (terrain_farthest_around(in.centre.xy) > in.centre.z * (1.0 + frame.params.w)) {
        discard;
    }
    let kind = in.bits & 3u;
    let selected = (in.bits & (SELECTED << 4u)) != 0u;
    let px_per_unit = in.centre.w;
    let d = silhouette(in.local, kind) * px_per_unit;
    let outline_px = 1.25;
    var colour = vec4<f32>(0.0);
    // Dark outline, then the fill.
    let outer = clamp(outline_px + 0.5 - d, 0.0, 1.0);
    let inner = clamp(0.5 - d, 0.0, 1.0);
    colour = vec4<f32>(mix(vec3<f32>(0.02, 0.02, 0.03), in.colour.rgb, inner), max(outer * 0.85, inner));
    colour.a = colour.a * in.colour.a;
    if (selected) {
        let ring = abs(length(in.local) - 1.3) * px_per_unit - 1.0;
        let r = clamp(0.5 - ring, 0.0, 1.0);
        colour = mix(colour, vec4<f32>(1.0, 0.9, 0.2, 1.0), r * (1.0 - colour.a * 0.5));
    }
    colour.a = colour.a * in.weight;
    if (colour.a < 0.02) {
        discard;
    }
    return Target(colour, in.id);
}
