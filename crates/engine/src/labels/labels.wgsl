// Placed labels, drawn in the screen-aligned pass: a leader line from the object to the
// box's nearest corner, and the text as signed-distance-field glyphs over a dark halo. Every
// label (a traffic data block, a fix's name) is a box at a pixel position; a label whose
// object the terrain hides is dropped whole in the vertex stage.

struct LabelFrame {
    // Width, height, 1 / width, 1 / height (pixels).
    viewport: vec4<f32>,
    // x: pixels per atlas pixel, y: atlas width, z: atlas height, w: halo width in field
    // units at one pixel per atlas pixel.
    scale: vec4<f32>,
    // x: how much nearer than its depth the terrain may be at the object before its label
    // goes (fraction of the depth).
    params: vec4<f32>,
}

// A placed label (mirrors `LabelGpu`, 48 bytes).
struct Label {
    // The object on screen (pixels), its depth (reversed-Z; 0 never hidden), the opacity.
    anchor: vec2<f32>,
    depth: f32,
    opacity: f32,
    // The box's top-left and size (pixels).
    origin: vec2<f32>,
    size: vec2<f32>,
    // Text colour (sRGB), and how far from the anchor the leader starts (pixels; negative:
    // no leader).
    colour: u32,
    clearance: f32,
    // Pixels per atlas pixel of its text (0: the frame's).
    scale: f32,
    spare: f32,
}

// One glyph of the atlas (mirrors `GlyphGpu`): its texels, and where the quad lies from the
// pen (atlas pixels).
struct AtlasGlyph {
    rect: vec4<f32>,
    offset: vec2<f32>,
    spare: vec2<f32>,
}

// One glyph drawn (mirrors `GlyphInstance`).
struct GlyphInstance {
    label: u32,
    glyph: u32,
    // Top-left of the quad from the label's origin, pixels.
    at: vec2<f32>,
}

@group(0) @binding(0) var<uniform> frame: LabelFrame;
@group(0) @binding(1) var terrain_depth: texture_2d<f32>;
@group(0) @binding(2) var atlas: texture_2d<f32>;
@group(0) @binding(3) var atlas_sampler: sampler;
@group(0) @binding(4) var<storage, read> atlas_glyphs: array<AtlasGlyph>;
@group(0) @binding(5) var<storage, read> labels: array<Label>;
@group(0) @binding(6) var<storage, read> glyphs: array<GlyphInstance>;

// Outside the clip volume: a vertex that draws nothing.
const OFF: vec4<f32> = vec4<f32>(0.0, 0.0, -2.0, 1.0);

// Whether the terrain hides the object a label belongs to.
fn label_hidden(l: Label) -> bool {
    return l.depth > 0.0 && terrain_farthest_around(l.anchor) > l.depth * (1.0 + frame.params.x);
}

fn pixels_to_clip(px: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(px.x * frame.viewport.z * 2.0 - 1.0, 1.0 - px.y * frame.viewport.w * 2.0, 0.0, 1.0);
}

fn label_colour(l: Label) -> vec4<f32> {
    let c = srgb_to_linear(l.colour);
    return vec4<f32>(c.rgb, l.opacity);
}

struct LeaderOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) across_px: f32,
    @location(1) @interpolate(flat) colour: vec4<f32>,
}

// A thin line from the edge of the symbol to the label's nearest corner.
@vertex
fn leader_vs(@builtin(vertex_index) vi: u32) -> LeaderOut {
    var out: LeaderOut;
    out.clip = OFF;
    let l = labels[vi / 6u];
    if (l.clearance < 0.0 || label_hidden(l)) {
        return out;
    }
    let corner = vec2<f32>(
        select(l.origin.x, l.origin.x + l.size.x, l.anchor.x > l.origin.x + l.size.x * 0.5),
        select(l.origin.y, l.origin.y + l.size.y, l.anchor.y > l.origin.y + l.size.y * 0.5),
    );
    var dir = corner - l.anchor;
    let len = length(dir);
    if (len <= l.clearance) {
        return out;
    }
    dir = dir / len;
    let a = l.anchor + dir * l.clearance * 0.75;
    let perp = vec2<f32>(-dir.y, dir.x);
    let ends = array<u32, 6>(0u, 0u, 1u, 1u, 0u, 1u);
    let sides = array<f32, 6>(-1.0, 1.0, -1.0, -1.0, 1.0, 1.0);
    let c = vi % 6u;
    let p = select(a, corner, ends[c] == 1u) + perp * sides[c] * 1.5;
    out.clip = pixels_to_clip(p);
    out.across_px = sides[c] * 1.5;
    out.colour = label_colour(l);
    return out;
}

@fragment
fn leader_fs(in: LeaderOut) -> @location(0) vec4<f32> {
    let coverage = clamp(1.0 - abs(in.across_px), 0.0, 1.0);
    return vec4<f32>(in.colour.rgb, in.colour.a * coverage * 0.8);
}

struct GlyphOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) colour: vec4<f32>,
    // The halo's edge in field units.
    @location(2) @interpolate(flat) halo: f32,
}

@vertex
fn glyph_vs(@builtin(vertex_index) vi: u32) -> GlyphOut {
    var out: GlyphOut;
    out.clip = OFF;
    let g = glyphs[vi / 6u];
    let l = labels[g.label];
    if (label_hidden(l)) {
        return out;
    }
    let a = atlas_glyphs[g.glyph];
    let xs = array<f32, 6>(0.0, 1.0, 0.0, 0.0, 1.0, 1.0);
    let ys = array<f32, 6>(0.0, 0.0, 1.0, 1.0, 0.0, 1.0);
    let corner = vec2<f32>(xs[vi % 6u], ys[vi % 6u]);
    let scale = select(frame.scale.x, l.scale, l.scale > 0.0);
    let size = a.rect.zw * scale;
    let p = l.origin + g.at + corner * size;
    out.clip = pixels_to_clip(p);
    out.uv = (a.rect.xy + corner * a.rect.zw) / frame.scale.yz;
    out.colour = label_colour(l);
    out.halo = frame.scale.w / scale;
    return out;
}

@fragment
fn glyph_fs(in: GlyphOut) -> @location(0) vec4<f32> {
    let d = textureSample(atlas, atlas_sampler, in.uv).r;
    let edge = 128.0 / 255.0;
    let aa = max(fwidth(d) * 0.75, 1e-4);
    let ink = smoothstep(edge - aa, edge + aa, d);
    let halo_edge = edge - in.halo;
    let halo = smoothstep(halo_edge - aa, halo_edge + aa, d);
    // Text over a dark halo: readable on bright snow and dark sea alike.
    let rgb = mix(vec3<f32>(0.0, 0.0, 0.0), in.colour.rgb, ink);
    let a = max(ink, halo * 0.75) * in.colour.a;
    if (a < 0.01) {
        discard;
    }
    return vec4<f32>(rgb, a);
}
