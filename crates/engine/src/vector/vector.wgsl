// Vector overlay: draped and absolute fills (triangles) and lines and points (screen-space
// capsules). Positions are f32 offsets from an anchor (a tile's centre, or a chunk centre of
// geometry at altitude) whose offset from the eye is computed in f64 on the CPU each frame.

struct Frame {
    clip_from_eye: mat4x4<f32>,
    // Width, height, 1 / width, 1 / height (pixels).
    viewport: vec4<f32>,
    // x: how much nearer than its true depth a draped fill is tested (fraction of depth),
    // y: the same for a line's centre against the terrain around it.
    tolerance: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
// Per anchor: anchor minus eye, metres (xyz).
@group(0) @binding(1) var<storage, read> anchors: array<vec4<f32>>;
// The depth the terrain pass left (reversed-Z: nearer is greater).
// Bound as an unfilterable float texture: read with textureLoad on every backend (GL
// cannot textureLoad a depth texture).
@group(0) @binding(2) var terrain_depth: texture_2d<f32>;

// Styles are sRGB; the colour targets are sRGB formats, which expect linear values.
fn unpack_colour(c: u32) -> vec4<f32> {
    let s = unpack4x8unorm(c);
    let lo = s.rgb / 12.92;
    let hi = pow((s.rgb + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return vec4<f32>(select(hi, lo, s.rgb <= vec3<f32>(0.04045)), s.a);
}

// ---- fills ----

struct FillIn {
    @location(0) position: vec3<f32>,
    @location(1) anchor: u32,
    @location(2) colour: u32,
    @location(3) id: u32,
}

// The anchor's top bit marks a draped fill: tested slightly nearer than it is, since it lies
// on the terrain's own triangles.
const DRAPED_BIT: u32 = 0x80000000u;

struct FillOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) colour: vec4<f32>,
    @location(1) @interpolate(flat) id: u32,
}

@vertex
fn fill_vs(v: FillIn) -> FillOut {
    let eye = anchors[v.anchor & ~DRAPED_BIT].xyz + v.position;
    var clip = frame.clip_from_eye * vec4<f32>(eye, 1.0);
    if ((v.anchor & DRAPED_BIT) != 0u) {
        clip.z = clip.z * (1.0 + frame.tolerance.x);
    }
    return FillOut(clip, unpack_colour(v.colour), v.id);
}

struct Target {
    @location(0) colour: vec4<f32>,
    @location(1) id: u32,
}

@fragment
fn fill_fs(in: FillOut) -> Target {
    return Target(in.colour, in.id);
}

// ---- translucent geometry at altitude: weighted blended order-independent transparency
// (McGuire and Bavoil 2013), accumulated in targets of the layer's own against the terrain's
// depth, then composited over the frame ----

struct OitOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) colour: vec4<f32>,
    @location(1) distance_m: f32,
}

@vertex
fn oit_vs(v: FillIn) -> OitOut {
    let eye = anchors[v.anchor & ~DRAPED_BIT].xyz + v.position;
    let clip = frame.clip_from_eye * vec4<f32>(eye, 1.0);
    return OitOut(clip, unpack_colour(v.colour), length(eye));
}

struct OitTargets {
    @location(0) accum: vec4<f32>,
    @location(1) reveal: vec4<f32>,
}

@fragment
fn oit_fs(in: OitOut) -> OitTargets {
    let a = in.colour.a;
    // McGuire and Bavoil's equation (9), distances in kilometres (a planet's scenes are a
    // thousand times larger than the rooms it was tuned for).
    let d = in.distance_m / 1000.0;
    let w = clamp(10.0 / (1e-5 + pow(d / 5.0, 2.0) + pow(d / 200.0, 6.0)), 1e-2, 3e3);
    return OitTargets(vec4<f32>(in.colour.rgb * a, a) * w, vec4<f32>(a));
}

@group(1) @binding(0) var oit_accum: texture_2d<f32>;
@group(1) @binding(1) var oit_reveal: texture_2d<f32>;

@vertex
fn composite_vs(@builtin(vertex_index) v: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((v << 1u) & 2u), f32(v & 2u));
    return vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn composite_fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let t = vec2<i32>(p.xy);
    let accum = textureLoad(oit_accum, t, 0);
    let reveal = textureLoad(oit_reveal, t, 0).r;
    if (accum.a < 1e-6) {
        discard;
    }
    return vec4<f32>(accum.rgb / clamp(accum.a, 1e-4, 5e4), 1.0 - reveal);
}

// ---- lines and points ----

// One segment or point (mirrors `LineInstance`, 48 bytes), six vertices each: read by
// vertex index, so every drawn entry's range is one record of a multi-draw.
struct Line {
    a: vec3<f32>,
    anchor: u32,
    b: vec3<f32>,
    id: u32,
    colour: u32,
    outline: u32,
    // Width (lines) or diameter (points), pixels.
    width_px: f32,
    // Outline width, pixels; negative: a square symbol.
    outline_px: f32,
    // A point's icon: its layer plus one (0: the symbol).
    icon: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(3) var<storage, read> lines: array<Line>;
@group(0) @binding(4) var icons: texture_2d_array<f32>;
@group(0) @binding(5) var icon_sampler: sampler;

struct LineOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) sa: vec2<f32>,
    @location(1) @interpolate(flat) sb: vec2<f32>,
    @location(2) @interpolate(flat) za_zb_w_o: vec4<f32>,
    @location(3) @interpolate(flat) colour: vec4<f32>,
    @location(4) @interpolate(flat) outline: vec4<f32>,
    @location(5) @interpolate(flat) id: u32,
    @location(6) @interpolate(flat) icon: u32,
}

// Eye-space depth below which a line end is moved along the line (in front of the camera).
const NEAR_W: f32 = 1e-3;

fn to_pixels(clip: vec4<f32>) -> vec2<f32> {
    let ndc = clip.xy / clip.w;
    return vec2<f32>((ndc.x * 0.5 + 0.5) * frame.viewport.x, (0.5 - ndc.y * 0.5) * frame.viewport.y);
}

@vertex
fn line_vs(@builtin(vertex_index) vertex: u32) -> LineOut {
    let v = lines[vertex / 6u];
    var out: LineOut;
    let anchor = anchors[v.anchor].xyz;
    var ca = frame.clip_from_eye * vec4<f32>(anchor + v.a, 1.0);
    var cb = frame.clip_from_eye * vec4<f32>(anchor + v.b, 1.0);
    if (ca.w < NEAR_W && cb.w < NEAR_W) {
        out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0); // behind the camera: outside the frame
        return out;
    }
    if (ca.w < NEAR_W) {
        ca = mix(ca, cb, (NEAR_W - ca.w) / (cb.w - ca.w));
    } else if (cb.w < NEAR_W) {
        cb = mix(cb, ca, (NEAR_W - cb.w) / (ca.w - cb.w));
    }
    let sa = to_pixels(ca);
    let sb = to_pixels(cb);
    let delta = sb - sa;
    let len = length(delta);
    var d = vec2<f32>(1.0, 0.0);
    if (len > 1e-4) {
        d = delta / len;
    }
    let n = vec2<f32>(-d.y, d.x);
    // Half width plus a pixel for antialiasing (and the outline's reach).
    let r = 0.5 * v.width_px + 1.0;
    // Two triangles: corners (along, across) in {-1, 1}.
    let corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[vertex % 6u];
    var base = sa - d * r;
    if (c.x > 0.0) {
        base = sb + d * r;
    }
    let p = base + n * (c.y * r);
    let ndc = vec2<f32>(p.x * frame.viewport.z * 2.0 - 1.0, 1.0 - p.y * frame.viewport.w * 2.0);
    let za = ca.z / ca.w;
    let zb = cb.z / cb.w;
    // Depth is tested in the fragment shader; this only has to be inside the depth range.
    out.clip = vec4<f32>(ndc, clamp(max(za, zb), 0.0, 1.0), 1.0);
    out.sa = sa;
    out.sb = sb;
    out.za_zb_w_o = vec4<f32>(za, zb, v.width_px, v.outline_px);
    out.colour = unpack_colour(v.colour);
    out.outline = unpack_colour(v.outline);
    out.id = v.id;
    out.icon = v.icon;
    return out;
}

// The terrain's depth at a texel, 0 (infinitely far) outside the frame.
fn terrain_at(t: vec2<i32>) -> f32 {
    let size = vec2<i32>(textureDimensions(terrain_depth));
    if (any(t < vec2<i32>(0)) || any(t >= size)) {
        return 0.0;
    }
    return textureLoad(terrain_depth, t, 0).r;
}

@fragment
fn line_fs(in: LineOut) -> Target {
    let p = in.clip.xy;
    let ab = in.sb - in.sa;
    let l2 = dot(ab, ab);
    var t = 0.0;
    if (l2 > 1e-8) {
        t = clamp(dot(p - in.sa, ab) / l2, 0.0, 1.0);
    }
    let centre = in.sa + ab * t;
    let width = in.za_zb_w_o.z;
    let outline_px = in.za_zb_w_o.w;
    let off = abs(p - centre);
    var dist = length(p - centre);
    if (outline_px < 0.0) {
        dist = max(off.x, off.y);
    }
    let r = 0.5 * width;
    let coverage = clamp(r + 0.5 - dist, 0.0, 1.0);
    if (coverage <= 0.0) {
        discard;
    }
    // Hidden where the terrain is in front of the centre line: at all four texels around
    // the centre point (on the surface the line lies on, some are at or behind it).
    let z = mix(in.za_zb_w_o.x, in.za_zb_w_o.y, t);
    let q = vec2<i32>(floor(centre - vec2<f32>(0.5)));
    let nearest_far = min(
        min(terrain_at(q), terrain_at(q + vec2<i32>(1, 0))),
        min(terrain_at(q + vec2<i32>(0, 1)), terrain_at(q + vec2<i32>(1, 1))),
    );
    if (nearest_far > z * (1.0 + frame.tolerance.y)) {
        discard;
    }
    if (in.icon != 0u) {
        // An icon: the square of the symbol's size, textured.
        let uv = (p - centre) / max(width, 1.0) + vec2<f32>(0.5);
        if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0))) {
            discard;
        }
        let texel = textureSampleLevel(icons, icon_sampler, uv, i32(in.icon - 1u), 0.0);
        if (texel.a <= 0.0) {
            discard;
        }
        return Target(texel, in.id);
    }
    var colour = in.colour;
    let ow = abs(outline_px);
    if (ow > 0.0 && dist > r - ow) {
        colour = in.outline;
    }
    return Target(vec4<f32>(colour.rgb, colour.a * coverage), in.id);
}
