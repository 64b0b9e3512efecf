// Terrain: every tile's mesh from the shared vertex and index pools, all drawn by one
// multi-draw-indirect. Positions are f32 offsets from the tile's centre; each vertex carries
// its tile's slot, which gives the centre-to-eye offset computed in f64 on the CPU (so
// nothing large reaches f32) and where its colour is: a layer of the colour texture array
// and the part of it over the tile (the whole of its own layer, or a crop of an ancestor's
// while its own imagery loads).
//
// Geomorphing: a tile grows out of its parent over the last part of its level of detail.
// Each vertex carries where it lies on the parent's surface (a height along the ellipsoid's
// normal, and the parent's normal there) and each tile how far it has grown (`morph`, 0 at
// the split, 1 when it splits in turn, from the LOD selection); the vertex, its normal and
// the colour (the parent's, cropped, against the tile's own) are that blend.

struct VsIn {
    // Metres from the tile centre.
    @location(0) position: vec3<f32>,
    // Oct-encoded unit normal, snorm16 x 2.
    @location(1) normal_oct: u32,
    // Texture coordinates over the tile.
    @location(2) uv: vec2<f32>,
    // Pool slot of the vertex's tile.
    @location(3) slot: u32,
    // Drawn metres from the vertex to its parent's surface, along the ellipsoid's normal.
    @location(4) morph_dh: f32,
    // The parent surface's normal there, oct-encoded as `normal_oct`.
    @location(5) parent_normal_oct: u32,
}

// Per slot: where the tile's colour and its parent's are, and how far it has grown.
struct TileMap {
    // uv scale (u, v), uv offset (u, v): the tile's part of its colour layer.
    colour: vec4<f32>,
    // The same in the layer its parent shows.
    parent_colour: vec4<f32>,
    // x: how far the tile has grown out of its parent (0 to 1); y: the parent colour's layer;
    // z: how much of the tile's own colour shows over the parent's (its growth, and its own
    // imagery fading in when it has just replaced an ancestor's).
    morph: vec4<f32>,
}

// Per slot: tile centre minus eye position, metres (f64 on the CPU, rounded once).
// Per slot: the tile centre's offset from the eye, and its colour layer.
@group(1) @binding(0) var<storage, read> offsets: array<vec4<f32>>;
@group(1) @binding(1) var colours: texture_2d_array<f32>;
@group(1) @binding(2) var colour_sampler: sampler;
@group(1) @binding(3) var<storage, read> tile_maps: array<TileMap>;
// City lights: luminance, equirectangular (u east from 180 W, v south from the north pole).
@group(1) @binding(4) var night_lights: texture_2d<f32>;
@group(1) @binding(5) var night_sampler: sampler;

// The aerial-perspective table of this frame (`aerial.wgsl`): inscattered light and
// transmittance per column and slice, and each column's range.
@group(2) @binding(0) var ap_inscatter: texture_3d<f32>;
@group(2) @binding(1) var ap_transmittance: texture_3d<f32>;
@group(2) @binding(2) var<storage, read> ap_ranges: array<vec4<f32>>;

// The air along column `c` to the point standing for a pixel's ground: from the air at the
// pixel's distance `dist`, from space at share `share` of the way from where the column enters
// the air to its ground (`ap_entry_and_ground`). Its slices interpolated, and from clear air
// at the start to the first slice's end (with the square of the depth in the air, where the
// light builds up with the distance). `valid` is 0 for a column that misses the air.
struct ApSample {
    air: Air,
    valid: f32,
    // 1 if the column meets the body's sphere.
    ground: f32,
}

fn aerial_column(c: vec2<u32>, share: f32, dist: f32) -> ApSample {
    let range = ap_ranges[c.y * AP_COLUMNS.x + c.x];
    if (range.y <= range.x) {
        return ApSample(Air(vec3<f32>(0.0), vec3<f32>(1.0)), 0.0, 0.0);
    }
    let slices = f32(AP_SLICES);
    // Slice k's value stands at u = k + 1.
    let t = select(range.x + share * (range.z - range.x), dist, ap_in_air());
    let u = ap_depth(range.xy, t) * slices;
    // The two slices either side, read and blended here: a filtered read would also blend
    // in the neighbouring columns, at the wrong distances.
    let z = clamp(u - 1.0, 0.0, slices - 1.0);
    let k0 = min(u32(z), AP_SLICES - 2u);
    let f = z - f32(k0);
    let at0 = vec3<u32>(c, k0);
    let at1 = vec3<u32>(c, k0 + 1u);
    let inscatter = mix(textureLoad(ap_inscatter, at0, 0).rgb, textureLoad(ap_inscatter, at1, 0).rgb, f);
    let transmittance = mix(textureLoad(ap_transmittance, at0, 0).rgb, textureLoad(ap_transmittance, at1, 0).rgb, f);
    let first = clamp(u, 0.0, 1.0);
    let built = select(first, first * first, ap_in_air());
    return ApSample(Air(inscatter * built, mix(vec3<f32>(1.0), transmittance, built)), 1.0, range.w);
}

// The air between the eye and the ground `dist` metres away along the unit ray `dir` (ECEF
// axes) seen at framebuffer position `at`: the four nearest columns of the table, each at the
// same share of the way from the air's edge to its ground as the pixel's own ray (so at about
// the same height, and columns whose ranges differ either side of the body's silhouette still
// agree), weighted by how near the pixel is to each; columns that miss the air are left out.
// Marched when all four do.
// From space, rays meeting the ground at a cosine under this are marched, and so are those
// whose columns' light differs by more than this share of the brightest.
const AP_GRAZING: f32 = 0.25;
const AP_CONTRAST: f32 = 0.3;

fn aerial_perspective(at: vec2<f32>, dir: vec3<f32>, dist: f32) -> Air {
    let d = dir * atmosphere.stretch.xyz;
    let k = length(d);
    let own = ap_entry_and_ground(d / k);
    // In the air the columns are read at the pixel's distance (they are nearly parallel where
    // it matters, near the horizon); from space at its share of the way from the air's edge
    // to the ground (rays that enter the air kilometres apart reach the same height there).
    // Either way the pixel's own ray stops at the body's sphere, as `air_march`'s does.
    var t = dist * k;
    if (own.z > 0.0) {
        t = min(t, own.y);
    }
    let w = (t - own.x) / max(own.y - own.x, 1.0);
    let columns = vec2<f32>(AP_COLUMNS);
    let f = (at - frame.aerial.xy) / (frame.aerial.zw - frame.aerial.xy) * (columns - 1.0);
    let c0 = clamp(floor(f), vec2<f32>(0.0), columns - 2.0);
    let near = clamp(f - c0, vec2<f32>(0.0), vec2<f32>(1.0));
    let c = vec2<u32>(c0);
    let s = array<ApSample, 4>(
        aerial_column(c, w, t),
        aerial_column(c + vec2<u32>(1u, 0u), w, t),
        aerial_column(c + vec2<u32>(0u, 1u), w, t),
        aerial_column(c + vec2<u32>(1u, 1u), w, t),
    );
    let weights = vec4<f32>(
        (1.0 - near.x) * (1.0 - near.y) * s[0].valid,
        near.x * (1.0 - near.y) * s[1].valid,
        (1.0 - near.x) * near.y * s[2].valid,
        near.x * near.y * s[3].valid,
    );
    let total = weights.x + weights.y + weights.z + weights.w;
    // From space, about the body's silhouette (rays that graze the ground, and columns either
    // side of it), where the air to a point changes fast across the screen, the pixel marches
    // its own ray.
    var graze = false;
    if (!ap_in_air()) {
        let origin = frame.eye_up_height.xyz * (atmosphere.shell.x + frame.eye_up_height.w);
        let hit = origin + (d / k) * own.y;
        graze = own.z == 0.0 || -dot(d / k, hit) < AP_GRAZING * length(hit);
        // And where the columns' light differs by more than a share of itself (the
        // terminator, where the body's shadow crosses the rays).
        var lo = 1e30;
        var hi = 0.0;
        for (var i = 0; i < 4; i = i + 1) {
            graze = graze || (s[i].valid > 0.0 && s[i].ground != own.z);
            let light = dot(s[i].air.inscatter, vec3<f32>(1.0)) * frame.planet.w;
            if (s[i].valid > 0.0) {
                lo = min(lo, light);
                hi = max(hi, light);
            }
        }
        graze = graze || hi - lo > AP_CONTRAST * hi + 0.01;
    }
    if (total <= 1e-6 || graze) {
        return air(dir, dist, GROUND_STEPS);
    }
    var inscatter = vec3<f32>(0.0);
    var transmittance = vec3<f32>(0.0);
    for (var i = 0; i < 4; i = i + 1) {
        inscatter = inscatter + s[i].air.inscatter * weights[i];
        transmittance = transmittance + s[i].air.transmittance * weights[i];
    }
    return Air(inscatter / total, transmittance / total);
}

// Sodium-lamp orange of city lights, and their brightness before tone mapping.
const LIGHT_COLOUR: vec3<f32> = vec3<f32>(1.0, 0.72, 0.38);
const LIGHT_GAIN: f32 = 2.5;
const LIGHT_FLOOR: f32 = 0.04;

// A 32-bit hash of a lattice cell (integer mixing, the same on every GPU).
fn hash_cell(c: vec3<i32>) -> u32 {
    var h = (u32(c.x) * 0x8da6b343u) ^ (u32(c.y) * 0xd8163841u) ^ (u32(c.z) * 0xcb1ab31fu);
    h = (h ^ (h >> 16u)) * 0x7feb352du;
    h = (h ^ (h >> 15u)) * 0x846ca68bu;
    return h ^ (h >> 16u);
}

// 0..1 from the top 24 bits of a hash.
fn unit_of(h: u32) -> f32 {
    return f32(h >> 8u) / 16777216.0;
}

// Trilinear value noise over a unit lattice, 0..1.
fn value_noise(x: vec3<f32>) -> f32 {
    let c = floor(x);
    let f = x - c;
    let w = f * f * (3.0 - 2.0 * f);
    let i = vec3<i32>(c);
    var n = 0.0;
    for (var k = 0; k < 8; k = k + 1) {
        let o = vec3<i32>(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        let corner = vec3<f32>(o);
        let weight = mix(1.0 - w.x, w.x, corner.x) * mix(1.0 - w.y, w.y, corner.y) * mix(1.0 - w.z, w.z, corner.z);
        n = n + weight * unit_of(hash_cell(i + o));
    }
    return n;
}

// Size of a town cell, metres: each holds at most one town, a ball about a point inside it
// that the ground cuts into a bright disc.
const TOWN_CELL_M: f32 = 30000.0;

// Procedural towns for the procedural planet, at ground point `p` (ECEF, metres): a town in a
// cell where a continental-scale noise says people live; seen from far enough that a cell is
// a few pixels, their mean glow instead (no sparkle).
fn procedural_lights(p: vec3<f32>, metres_per_px: f32) -> f32 {
    let settled = smoothstep(0.5, 0.8, value_noise(p / 900000.0));
    if (settled <= 0.0) {
        return 0.0;
    }
    let q = p / TOWN_CELL_M;
    let c = floor(q);
    let h = hash_cell(vec3<i32>(c));
    var town = 0.0;
    if (unit_of(h) < 0.7 * settled) {
        let h2 = hash_cell(vec3<i32>(c) + vec3<i32>(101, 0, 0));
        let h3 = hash_cell(vec3<i32>(c) + vec3<i32>(0, 101, 0));
        let h4 = hash_cell(vec3<i32>(c) + vec3<i32>(0, 0, 101));
        let radius = 0.05 + 0.2 * unit_of(h2 ^ h3);
        let centre = c + vec3<f32>(0.35, 0.35, 0.35) + 0.3 * vec3<f32>(unit_of(h2), unit_of(h3), unit_of(h4));
        // A town smaller than a pixel is drawn a pixel wide with the same light in all, so
        // it neither sparkles nor vanishes (at most 0.35 of a cell: it stays in its cell).
        let drawn = max(radius, 0.7 * metres_per_px / TOWN_CELL_M);
        let d = length(q - centre) / drawn;
        let spread = radius / drawn;
        town = max(1.0 - d * d, 0.0) * (0.6 + 0.8 * unit_of(h4 ^ h2)) * spread * spread;
    }
    // The mean over cells, once a cell is under two pixels: present 0.7 settled, the ball's
    // volume (4/3) pi E[r^3] ~ 0.013 (a random plane cuts it), profile mean 0.4, brightness
    // mean 1.
    let mean = 0.7 * settled * 0.013 * 0.4;
    let near = clamp(TOWN_CELL_M / metres_per_px - 1.0, 0.0, 1.0);
    return mix(mean, town, near);
}

// The city lights at a ground point `eye_offset` from the eye, `dist` away, weighted by how
// far the Sun is below its horizon there (none by day, all once it is 6 degrees down); the
// procedural planet's towns only on land (`land` 1).
fn night_light(eye_offset: vec3<f32>, dist: f32, land: f32) -> vec3<f32> {
    if (frame.night.x <= 0.0 && frame.night.w <= 0.0) {
        return vec3<f32>(0.0);
    }
    let p = frame.eye_position.xyz + eye_offset;
    let up = normalize(p);
    let dark = 1.0 - smoothstep(-0.105, 0.02, dot(up, frame.sun.xyz));
    if (dark <= 0.0) {
        return vec3<f32>(0.0);
    }
    var metres_per_px = frame.night.z * dist;
    if (is_ortho()) {
        metres_per_px = frame.night.z;
    }
    if (frame.night.x <= 0.0) {
        return LIGHT_COLOUR * (procedural_lights(p, metres_per_px) * land * LIGHT_GAIN * dark * frame.night.w);
    }
    let lon = atan2(p.y, p.x);
    // Geodetic latitude of a point on the ellipsoid's surface.
    let lat = atan2(p.z, (1.0 - frame.eye_position.w) * length(p.xy));
    let uv = vec2<f32>(lon / (2.0 * PI) + 0.5, 0.5 - lat / PI);
    // Mip level from the ground one pixel spans against a texel's (the longitude seam would
    // break the derivatives of an automatic choice).
    let texel_m = 2.0 * PI * frame.planet.x / frame.night.y;
    let level = max(log2(max(metres_per_px / texel_m, 1e-6)), 0.0);
    let lum = textureSampleLevel(night_lights, night_sampler, uv, level).r;
    // Less a floor: the images' faint background (JPEG noise, airglow) stays dark.
    return LIGHT_COLOUR * (max(lum - LIGHT_FLOOR, 0.0) * LIGHT_GAIN * dark * frame.night.x);
}

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) eye_offset: vec3<f32>,
    @location(3) @interpolate(flat) layer: u32,
    @location(4) parent_uv: vec2<f32>,
    @location(5) @interpolate(flat) parent_layer: u32,
    @location(6) @interpolate(flat) colour_share: f32,
}

@vertex
fn vs_main(v: VsIn) -> VsOut {
    let map = tile_maps[v.slot];
    let morph = map.morph.x;
    var eye_offset = offsets[v.slot].xyz + v.position;
    if (morph < 1.0) {
        // The ellipsoid's normal from the vertex's ECEF position (f32 is plenty for a
        // direction).
        let p = frame.eye_position.xyz + eye_offset;
        let up = normalize(vec3<f32>(p.xy, p.z / (1.0 - frame.eye_position.w)));
        eye_offset = eye_offset + up * (v.morph_dh * (1.0 - morph));
    }
    var out: VsOut;
    out.clip = frame.clip_from_eye * vec4<f32>(eye_offset, 1.0);
    out.uv = v.uv * map.colour.xy + map.colour.zw;
    out.parent_uv = v.uv * map.parent_colour.xy + map.parent_colour.zw;
    out.normal = mix(decode_oct(v.parent_normal_oct), decode_oct(v.normal_oct), morph);
    out.eye_offset = eye_offset;
    out.layer = u32(offsets[v.slot].w + 0.5);
    out.parent_layer = u32(map.morph.y + 0.5);
    out.colour_share = map.morph.z;
    return out;
}

// Samples along a ray from the eye to the ground.
const GROUND_STEPS: i32 = 8;

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let own = textureSample(colours, colour_sampler, in.uv, in.layer);
    let parent = textureSample(colours, colour_sampler, in.parent_uv, in.parent_layer);
    let texel = mix(parent, own, in.colour_share);
    let albedo = texel.rgb;
    let water = 1.0 - texel.a;
    let n = normalize(in.normal);
    let sun = frame.sun.xyz;
    let ambient = frame.sun.w;
    let diffuse = max(dot(n, sun), 0.0);
    let dist = length(in.eye_offset);
    // Towards the eye (an orthographic camera's rays are parallel: against its view).
    var view = -in.eye_offset / max(dist, 1e-6);
    if (is_ortho()) {
        view = -ortho_forward();
    }
    // The sunlight that reaches this ground through the air (reddened and dimmed when low).
    let ground = frame.eye_up_height.xyz * (atmosphere.shell.x + frame.eye_up_height.w)
        + in.eye_offset * atmosphere.stretch.xyz;
    let r = length(ground);
    let mu_s = dot(ground, air_sun()) / r;
    let sunlight = sun_light(r - atmosphere.shell.x, mu_s);
    // Skylight: what the sky sends onto level ground, on a face tilted away from the zenith
    // the part of the sky it still sees ((1 + cos tilt) / 2). The ambient term is a floor
    // under it (0 for the real Sun: the night side is dark but for its lights).
    let up = ground / r;
    let sky = sky_irradiance(mu_s) * (0.5 + 0.5 * dot(n, up));
    // Sun glint on water (Blinn-Phong).
    let h = normalize(sun + view);
    let glint = water * pow(max(dot(n, h), 0.0), 200.0) * 0.35 * step(0.0, dot(n, sun));
    var colour = albedo * (max(vec3<f32>(ambient), sky) + (1.0 - ambient) * diffuse * sunlight)
        + glint * sunlight + night_light(in.eye_offset, dist, texel.a);
    // Aerial perspective: the air between the eye and the ground dims and tints it.
    // An orthographic camera's rays start from points of its plane, not from the eye, so
    // they are marched; so are all when the frame asks for the reference (`planet.y`).
    var haze: Air;
    if (is_ortho()) {
        haze = air_ortho(in.eye_offset, false, GROUND_STEPS);
    } else if (frame.planet.y > 0.5 || atmosphere.shell.y <= 0.0) {
        haze = air(-view, dist, GROUND_STEPS);
    } else {
        haze = aerial_perspective(in.clip.xy, -view, dist);
    }
    colour = colour * haze.transmittance + haze.inscatter;
    // Alpha 1 marks terrain coverage (read back by tests; forced opaque in saved images).
    return vec4<f32>(tone(colour), 1.0);
}
