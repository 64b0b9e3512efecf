// Vector overlay: draped and absolute fills (triangles) and lines and points (screen-space
// quads; joins, caps and dashes decided per fragment). Positions are f32 offsets from an
// anchor (a tile's centre, or a chunk centre of geometry at altitude) whose offset from the
// eye is computed in f64 on the CPU each frame. Draped geometry follows the terrain's
// geomorphing: each point carries the morph height of the ground under it and is lifted
// along the body's normal by it times how much of its tile is still its parent's.

struct Frame {
    clip_from_eye: mat4x4<f32>,
    // Width, height, 1 / width, 1 / height (pixels).
    viewport: vec4<f32>,
    // x: how much nearer than its true depth a draped fill is tested (fraction of depth),
    // y: the same for a line's centre against the terrain around it.
    tolerance: vec4<f32>,
    // The eye in ECEF (f32: for directions only); w: the body's squared eccentricity.
    eye: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
// Per anchor: anchor minus eye, metres (xyz); w: how far its tile has grown out of its
// parent (1: its own surface, and for geometry at altitude).
@group(0) @binding(1) var<storage, read> anchors: array<vec4<f32>>;
// The depth the terrain pass left (reversed-Z: nearer is greater).
// Bound as an unfilterable float texture: read with textureLoad on every backend (GL
// cannot textureLoad a depth texture).
@group(0) @binding(2) var terrain_depth: texture_2d<f32>;

// A point `p` from `anchor`, lifted as the terrain under it is (`lift`: its morph height),
// relative to the eye.
fn lifted(anchor: u32, p: vec3<f32>, lift: f32) -> vec3<f32> {
    let a = anchors[anchor];
    var eye = a.xyz + p;
    let parent = 1.0 - a.w;
    if (lift != 0.0 && parent > 0.0) {
        let q = frame.eye.xyz + eye;
        let up = normalize(vec3<f32>(q.xy, q.z / (1.0 - frame.eye.w)));
        eye = eye + up * (lift * parent);
    }
    return eye;
}

// ---- fills ----

struct FillIn {
    @location(0) position: vec3<f32>,
    @location(1) anchor: u32,
    @location(2) colour: u32,
    @location(3) id: u32,
    @location(4) lift: f32,
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
    let eye = lifted(v.anchor & ~DRAPED_BIT, v.position, v.lift);
    var clip = frame.clip_from_eye * vec4<f32>(eye, 1.0);
    if ((v.anchor & DRAPED_BIT) != 0u) {
        clip.z = clip.z * (1.0 + frame.tolerance.x);
    }
    return FillOut(clip, srgb_to_linear(v.colour), v.id);
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
    let eye = lifted(v.anchor & ~DRAPED_BIT, v.position, v.lift);
    let clip = frame.clip_from_eye * vec4<f32>(eye, 1.0);
    return OitOut(clip, srgb_to_linear(v.colour), length(eye));
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

// One segment or point (mirrors `LineInstance`, 80 bytes), six vertices each: read by
// vertex index, so every drawn entry's range is one record of a multi-draw, and a segment
// reads its neighbours (the records before and after it) for its joins.
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
    // Low 16 bits: a point's icon, its layer plus one (0: the symbol); high 16: the flags
    // below (`line_flags` in gpu.rs).
    icon_flags: u32,
    // Metres along the line at a and b (less a multiple of 2^21 m).
    along_a: f32,
    along_b: f32,
    // Dash pattern, pixels, a byte each: dash, gap, dash, gap (0: solid).
    dash: u32,
    // Morph heights at a and b (see `lifted`).
    lift: vec2<f32>,
}

const JOINED_PREV: u32 = 0x10000u;
const JOINED_NEXT: u32 = 0x20000u;
const START: u32 = 0x40000u;
const END: u32 = 0x80000u;
const JOIN_SHIFT: u32 = 20u;
const CAP_SHIFT: u32 = 22u;
const SEAM_PREV: u32 = 0x1000000u;
const SEAM_NEXT: u32 = 0x2000000u;
const ROUND: u32 = 0u;
const MITER: u32 = 1u;
const BUTT: u32 = 1u;
const SQUARE: u32 = 2u;

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
    // Per end: the normal (along the travel) of the line dividing this segment from its
    // neighbour, zero where there is none; the outer side of the turn.
    @location(7) @interpolate(flat) join_a: vec4<f32>,
    @location(8) @interpolate(flat) join_b: vec4<f32>,
    // How far the outer corner reaches along the outer side at each end (a bevel; huge for a
    // miter); metres along the line at a and b.
    @location(9) @interpolate(flat) reach_along: vec4<f32>,
    // Flags (ends and styles), dash pattern.
    @location(10) @interpolate(flat) flags_dash: vec2<u32>,
}

// Eye-space depth below which a line end is moved along the line (in front of the camera).
const NEAR_W: f32 = 1e-3;

fn to_pixels(clip: vec4<f32>) -> vec2<f32> {
    let ndc = clip.xy / clip.w;
    return vec2<f32>((ndc.x * 0.5 + 0.5) * frame.viewport.x, (0.5 - ndc.y * 0.5) * frame.viewport.y);
}

fn project(anchor: u32, p: vec3<f32>, lift: f32) -> vec4<f32> {
    return frame.clip_from_eye * vec4<f32>(lifted(anchor, p, lift), 1.0);
}

// Unit direction from one screen point to another; zero if they (nearly) coincide.
fn direction(p0: vec2<f32>, p1: vec2<f32>) -> vec2<f32> {
    let d = p1 - p0;
    let len = length(d);
    if (len > 1e-4) {
        return d / len;
    }
    return vec2<f32>(0.0);
}

struct Join {
    // Normal of the dividing line, along the travel, and the outer side; zero: no join.
    e_o: vec4<f32>,
    reach: f32,
}

// The join where direction `din` turns into `dout` (both segments compute it from the same
// values, so they divide the plane along the same line and neither overlaps the other).
fn join_at(din: vec2<f32>, dout: vec2<f32>, hw: f32, style: u32) -> Join {
    var j: Join;
    j.reach = 1e30;
    let sum = din + dout;
    if (length(sum) < 1e-3 || all(din == vec2<f32>(0.0)) || all(dout == vec2<f32>(0.0))) {
        j.e_o = vec4<f32>(0.0); // a reversal or a degenerate end: drawn round
        return j;
    }
    let e = normalize(sum);
    let m = vec2<f32>(-e.y, e.x);
    let cos_half = abs(dot(m, vec2<f32>(-dout.y, dout.x)));
    let side = dot(m, din - dout);
    var o = vec2<f32>(0.0);
    if (side != 0.0) {
        o = m * sign(side);
    }
    // A miter until its tip would pass twice the half width (MapLibre's limit 2), then a
    // bevel; a bevel joins the outer corners.
    if (style != MITER || cos_half < 0.5) {
        j.reach = hw * cos_half;
    }
    j.e_o = vec4<f32>(e, o);
    return j;
}

@vertex
fn line_vs(@builtin(vertex_index) vertex: u32) -> LineOut {
    let index = vertex / 6u;
    let v = lines[index];
    var out: LineOut;
    var ca = project(v.anchor, v.a, v.lift.x);
    var cb = project(v.anchor, v.b, v.lift.y);
    if (ca.w < NEAR_W && cb.w < NEAR_W) {
        out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0); // behind the camera: outside the frame
        return out;
    }
    var flags = v.icon_flags & 0xffff0000u;
    if (ca.w < NEAR_W) {
        ca = mix(ca, cb, (NEAR_W - ca.w) / (cb.w - ca.w));
        flags &= ~(JOINED_PREV | START | SEAM_PREV);
    } else if (cb.w < NEAR_W) {
        cb = mix(cb, ca, (NEAR_W - cb.w) / (ca.w - cb.w));
        flags &= ~(JOINED_NEXT | END | SEAM_NEXT);
    }
    let sa = to_pixels(ca);
    let sb = to_pixels(cb);
    let dir = direction(sa, sb);
    var d = dir;
    if (all(d == vec2<f32>(0.0))) {
        d = vec2<f32>(1.0, 0.0);
    }
    let n = vec2<f32>(-d.y, d.x);
    let hw = 0.5 * v.width_px;
    let join = (flags >> JOIN_SHIFT) & 3u;
    var ja = Join(vec4<f32>(0.0), 1e30);
    var jb = Join(vec4<f32>(0.0), 1e30);
    if ((flags & JOINED_PREV) != 0u) {
        let prev = lines[index - 1u];
        let cp = project(prev.anchor, prev.a, prev.lift.x);
        if (cp.w >= NEAR_W) {
            ja = join_at(direction(to_pixels(cp), sa), dir, hw, join);
        }
    }
    if ((flags & JOINED_NEXT) != 0u) {
        let next = lines[index + 1u];
        let cn = project(next.anchor, next.b, next.lift.y);
        if (cn.w >= NEAR_W) {
            jb = join_at(dir, direction(sb, to_pixels(cn)), hw, join);
        }
    }
    // A seam: the line goes on in a record drawn apart that starts (ends) exactly here; both
    // cut square across this segment's direction, so they abut without overlapping.
    if ((flags & SEAM_PREV) != 0u) {
        ja = Join(vec4<f32>(dir, 0.0, 0.0), 1e30);
    }
    if ((flags & SEAM_NEXT) != 0u) {
        jb = Join(vec4<f32>(dir, 0.0, 0.0), 1e30);
    }
    // Half width plus a pixel for antialiasing across; along, room for a miter's tip.
    let r = hw + 1.0;
    var ext_a = r;
    var ext_b = r;
    if (any(ja.e_o.xy != vec2<f32>(0.0))) {
        ext_a += hw;
    }
    if (any(jb.e_o.xy != vec2<f32>(0.0))) {
        ext_b += hw;
    }
    // Two triangles: corners (along, across) in {-1, 1}.
    let corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[vertex % 6u];
    var base = sa - d * ext_a;
    if (c.x > 0.0) {
        base = sb + d * ext_b;
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
    out.colour = srgb_to_linear(v.colour);
    out.outline = srgb_to_linear(v.outline);
    out.id = v.id;
    out.icon = v.icon_flags & 0xffffu;
    out.join_a = ja.e_o;
    out.join_b = jb.e_o;
    out.reach_along = vec4<f32>(ja.reach, jb.reach, v.along_a, v.along_b);
    out.flags_dash = vec2<u32>(flags, v.dash);
    return out;
}

// Distance deciding coverage (coverage = half width + 0.5 - distance) beyond one end of a
// segment, `beyond` pixels past its vertex `v`, `across` pixels off its centre line.
fn end_distance(
    p: vec2<f32>,
    v: vec2<f32>,
    beyond: f32,
    across: f32,
    hw: f32,
    join: vec4<f32>,
    reach: f32,
    flags: u32,
    is_end: bool,
) -> f32 {
    if (any(join.xy != vec2<f32>(0.0))) {
        if (((flags >> JOIN_SHIFT) & 3u) == ROUND) {
            return length(p - v);
        }
        // Miter (the slab up to the dividing line) or bevel (cut across the outer corner).
        return max(across, hw - reach + dot(p - v, join.zw));
    }
    if (is_end) {
        let cap = (flags >> CAP_SHIFT) & 3u;
        if (cap == BUTT) {
            return max(across, hw + beyond);
        }
        if (cap == SQUARE) {
            return max(across, beyond);
        }
    }
    // A round cap, or a break where the line leaves a tile or a chunk.
    return length(p - v);
}

// Signed distance, pixels, from `u` (pattern pixels at nominal scale, `scale` drawn pixels
// each) to the dashes of `dash`: negative inside a dash.
fn dash_signed(u: f32, dash: u32, scale: f32) -> f32 {
    let l = vec4<f32>(unpack4xU8(dash));
    let total = l.x + l.y + l.z + l.w;
    var best = 1e30;
    for (var k = -1; k <= 1; k++) {
        let x = u - f32(k) * total;
        let s0 = max(-x, x - l.x);
        let s1 = max(l.x + l.y - x, x - (l.x + l.y + l.z));
        best = min(best, min(s0, s1));
    }
    return best * scale;
}

// Coverage of the dashes at a fragment `metres` along the line, `across` pixels off it.
// The pattern's period in metres is the power of two nearest to what the segment's pixels
// per metre ask for: the same on every segment and in every tile, so dashes stay put on the
// ground as the camera moves and continue across tile borders; they are drawn between 0.71
// and 1.41 times their size, and halve or double as the scale passes a power of two.
// (MapLibre cross-fades between zoom levels over time; a cross-fade in space would show two
// patterns at once in a still picture.)
fn dash_coverage(metres: f32, px_per_m: f32, across: f32, hw: f32, dash: u32, cap: u32) -> f32 {
    let l = vec4<f32>(unpack4xU8(dash));
    let total = l.x + l.y + l.z + l.w;
    let period = exp2(round(log2(total / px_per_m)));
    let u = fract(metres / period) * total;
    let s = dash_signed(u, dash, period * px_per_m / total);
    var dist = max(across, hw + s);
    if (cap == ROUND) {
        dist = length(vec2<f32>(max(s, 0.0), across));
    } else if (cap == SQUARE) {
        dist = max(across, s);
    }
    return clamp(hw + 0.5 - dist, 0.0, 1.0);
}

@fragment
fn line_fs(in: LineOut) -> Target {
    let p = in.clip.xy;
    let ab = in.sb - in.sa;
    let len = length(ab);
    var d = vec2<f32>(1.0, 0.0);
    if (len > 1e-4) {
        d = ab / len;
    }
    let along_px = dot(p - in.sa, d);
    let across = abs(dot(p - in.sa, vec2<f32>(-d.y, d.x)));
    let t = clamp(along_px / max(len, 1e-4), 0.0, 1.0);
    let centre = in.sa + ab * t;
    let width = in.za_zb_w_o.z;
    let hw = 0.5 * width;
    let outline_px = in.za_zb_w_o.w;
    let flags = in.flags_dash.x;
    let off = abs(p - centre);
    var dist = length(p - centre);
    if (outline_px < 0.0) {
        dist = max(off.x, off.y);
    }
    if ((flags & (JOINED_PREV | JOINED_NEXT | START | END | SEAM_PREV | SEAM_NEXT)) != 0u) {
        // A line's segment: the slab between its ends, each end joined, capped or round.
        if (dot(p - in.sa, in.join_a.xy) < 0.0 || dot(p - in.sb, in.join_b.xy) > 0.0) {
            discard; // the neighbour's side of the dividing line
        }
        dist = across;
        if (along_px < 0.0) {
            dist = end_distance(p, in.sa, -along_px, across, hw, in.join_a,
                in.reach_along.x, flags, (flags & START) != 0u);
        } else if (along_px > len) {
            dist = end_distance(p, in.sb, along_px - len, across, hw, in.join_b,
                in.reach_along.y, flags, (flags & END) != 0u);
        }
    }
    var coverage = clamp(hw + 0.5 - dist, 0.0, 1.0);
    let metres_len = in.reach_along.w - in.reach_along.z;
    if (in.flags_dash.y != 0u && len > 1e-3 && metres_len > 1e-6) {
        let px_per_m = len / metres_len;
        let metres = in.reach_along.z + along_px / px_per_m;
        let cap = (flags >> CAP_SHIFT) & 3u;
        coverage = min(coverage, dash_coverage(metres, px_per_m, across, hw, in.flags_dash.y, cap));
    }
    if (coverage <= 0.0) {
        discard;
    }
    // Hidden where the terrain is in front of the centre line: at all four texels around
    // the centre point (on the surface the line lies on, some are at or behind it).
    let z = mix(in.za_zb_w_o.x, in.za_zb_w_o.y, t);
    if (terrain_farthest_around(centre) > z * (1.0 + frame.tolerance.y)) {
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
    if (ow > 0.0 && dist > hw - ow) {
        colour = in.outline;
    }
    return Target(vec4<f32>(colour.rgb, colour.a * coverage), in.id);
}
