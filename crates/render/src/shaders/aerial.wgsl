// Builds the aerial-perspective table (`aerial.rs`): one invocation per column marches its ray
// once through the air, storing what has built up at the far end of each slice. Slice k's
// texel holds the air from the column's start to `ap_distance(range, (k + 1) / AP_SLICES)`;
// nothing is stored for the start itself, where the air is clear.

@group(1) @binding(0) var ap_inscatter_out: texture_storage_3d<rgba16float, write>;
@group(1) @binding(1) var ap_transmittance_out: texture_storage_3d<rgba16float, write>;
// Per column (rows first), distances from the eye in the atmosphere's space: x, where its ray
// enters the air (0 from inside); y, where it leaves it or meets the body's sphere (from
// the air: AP_BELOW_M under it; x = y when the ray misses the air); z, its ground, and w, 1
// if that is where it meets the body's sphere (`ap_entry_and_ground`).
@group(1) @binding(2) var<storage, read_write> ap_ranges_out: array<vec4<f32>>;

// How far under the body's sphere the columns go on from the air.
const AP_BELOW_M: f32 = 12000.0;

// Samples of the march in each slice.
const AP_SLICE_STEPS: u32 = 2u;

@compute @workgroup_size(8, 8, 1)
fn cs_aerial(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= AP_COLUMNS.x || id.y >= AP_COLUMNS.y) {
        return;
    }
    let dir = ap_ray(id.xy);
    let up = frame.eye_up_height.xyz;
    let h = frame.eye_up_height.w;
    let entry_ground = ap_entry_and_ground(dir);
    var range = vec2<f32>(0.0);
    if (atmosphere.shell.y > 0.0) {
        let span = shell_span_from(up, h, dir, atmosphere.shell.y);
        if (span.y > 0.0 && span.y >= span.x) {
            // Up to the air's edge or the body's sphere, where `air_march` stops too (ground
            // under it, or a coarse mesh's chords sagging under it, gets the air to the
            // sphere). From the air, where columns are read at a pixel's distance, on to a
            // sphere AP_BELOW_M lower: a column that meets the ground sooner than its
            // neighbour goes on as the neighbour does.
            var end = span.y;
            let ground = shell_span_from(up, h, dir, select(0.0, -AP_BELOW_M, ap_in_air()));
            if (ground.y >= ground.x && ground.x > 0.0) {
                end = min(end, ground.x);
            }
            range = vec2<f32>(entry_ground.x, end);
        }
    }
    ap_ranges_out[id.y * AP_COLUMNS.x + id.x] = vec4<f32>(range, entry_ground.yz);
    let origin = up * (atmosphere.shell.x + h);
    let sun = air_sun();
    let phases = air_phases(dot(dir, sun));
    let gain = air_gain();
    var acc = Air(vec3<f32>(0.0), vec3<f32>(1.0));
    for (var k = 0u; k < AP_SLICES; k = k + 1u) {
        if (range.y > range.x) {
            let a = ap_distance(range, f32(k) / f32(AP_SLICES));
            let b = ap_distance(range, f32(k + 1u) / f32(AP_SLICES));
            for (var s = 0u; s < AP_SLICE_STEPS; s = s + 1u) {
                let n = f32(AP_SLICE_STEPS);
                acc = air_step(acc, origin, dir, mix(a, b, f32(s) / n), mix(a, b, f32(s + 1u) / n), sun, phases);
            }
        }
        let at = vec3<u32>(id.x, id.y, k);
        textureStore(ap_inscatter_out, at, vec4<f32>(acc.inscatter * gain, 1.0));
        textureStore(ap_transmittance_out, at, vec4<f32>(acc.transmittance, 1.0));
    }
}
