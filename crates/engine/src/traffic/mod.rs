//! [`TrafficLayer`]: the engine's built-in overlay for moving aircraft: a heading-oriented
//! symbol of a few pixels far away, the aircraft's 3D model close in (never smaller than
//! its symbol, cross-faded so nothing pops), and a trail of its last minutes fading with
//! age.
//!
//! The CPU state is a [`Fleet`] (columnar, O(batch) updates, interpolation to the frame's
//! moment, trail ring buffers); a [`Replay`] feeds it from a record ([`TrafficLayer::play`]).
//! Per frame the layer samples every aircraft at the layer's time, places it (raised by the
//! elevation exaggeration like the terrain; on the terrain when on the ground; never below
//! it), and writes one 64-byte row per aircraft slot: its offset from the eye (computed in
//! f64), its attitude and its trail ring. Trail points live on the GPU as offsets from a
//! per-aircraft anchor (re-anchored every few hundred kilometres), uploaded once when the
//! fleet writes them, so a tick costs O(new points), not O(trail length x aircraft).
//!
//! Draw calls: one for all trails, one per model kind drawn, one for all symbols.
//!
//! Picking: symbols and models write `pick_base + slot` into the id buffer;
//! [`TrafficLayer::aircraft_for_pick`] maps a [`crate::Pick::object`] back to the aircraft.

mod blocks;
pub mod glb;
mod gpu;
pub mod models;

use std::time::Instant;

use globus_geo::{BoundingSphere, Cartographic, DVec3, Ellipsoid, Frustum, Intersection};
use globus_traffic::fleet::flags;
use globus_traffic::{Fleet, FleetError, Sampled};

use crate::labels::LabelRequest;
use crate::labels::gpu::{LabelBatch, LabelGpu};
use crate::overlay::{FrameContext, Overlay, OverlayPass};
use crate::text::GlyphAtlas;
use blocks::{BlockContent, LaidOut};
pub use glb::{ModelError, read_glb, write_glb};
use globus_geo::EllipsoidalOccluder;
pub use globus_traffic::fleet::{callsign_bytes, flags as aircraft_flags};
pub use globus_traffic::{
    AircraftKind, Batch, FleetError as BatchError, FleetOptions, Record, Replay, ReplayOptions,
    Sample, Step, read_record,
};
pub use gpu::SHADER;
use gpu::{AircraftGpu, Gpu, MODEL_DRAWS, MODEL_LODS, PAGE_POINTS, TRAIL_BUCKETS, Uniforms, bits};
pub use models::{MODEL_LOD_CELLS, MODEL_LOD_FULL_PX, ModelMesh, aircraft_mesh};

/// Pick ids of a layer made with [`TrafficLayer::new`] start here (clear of a
/// [`crate::VectorLayer`]'s, which start at 1).
pub const DEFAULT_PICK_BASE: u32 = 1 << 30;

/// Trail points more than this from their aircraft's anchor move the anchor (f32 offsets
/// keep about 3 cm at this distance).
const REANCHOR_M: f64 = 300_000.0;
/// Below this altitude an aircraft may meet the ground (nothing on Earth is higher).
const GROUND_CHECK_BELOW_M: f64 = 9_000.0;
/// Ground heights looked up per frame at most (the rest use their last answer).
const GROUND_QUERIES_PER_FRAME: u32 = 256;
/// How far an aircraft near the ground moves before its ground height is looked up again,
/// degrees (ten times as far when it is 2 km above it).
const GROUND_REFRESH_DEG: f64 = 0.002;
/// How much nearer than its depth the terrain may be at a symbol's centre before the symbol
/// is hidden (fraction of the depth).
const SYMBOL_TOLERANCE: f32 = 1.0e-4;
/// Length of a drawn trail segment, pixels: far trails skip points down to this.
const TRAIL_SEGMENT_PX: f64 = 4.0;
/// Room round a label's text, pixels.
const LABEL_PAD_PX: f32 = 2.0;
/// Light on faces turned away from the sun.
const AMBIENT: f32 = 0.35;

/// How the layer draws.
#[derive(Clone, Debug, PartialEq)]
pub struct TrafficStyle {
    /// Symbol size per kind (light, narrow-body, wide-body, helicopter), pixels: also the
    /// least size a model is drawn at.
    pub symbol_px: [f32; 4],
    /// Trail width, pixels (twice that for the selected aircraft).
    pub trail_width_px: f32,
    /// Draw trails.
    pub trails: bool,
    /// Draw models close in (symbols only otherwise).
    pub models: bool,
    /// Draw data-block labels (decluttered: never overlapping).
    pub labels: bool,
    /// Label text size: pixels from one line to the next.
    pub label_px: f32,
    /// How long a label takes to fade in or out, seconds.
    pub label_fade_s: f32,
}

impl Default for TrafficStyle {
    fn default() -> Self {
        Self {
            symbol_px: [14.0, 18.0, 22.0, 18.0],
            trail_width_px: 2.0,
            trails: true,
            models: true,
            labels: true,
            label_px: 13.0,
            label_fade_s: 0.3,
        }
    }
}

/// What the layer holds and what its last frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrafficStats {
    /// Aircraft in the fleet.
    pub aircraft: usize,
    /// Aircraft drawn as models in the last frame.
    pub models: u32,
    /// Of those, drawn at the coarse level of detail (under [`MODEL_LOD_FULL_PX`]).
    pub models_coarse: u32,
    /// Draw calls of the last frame.
    pub draw_calls: u32,
    /// GPU bytes of the layer's buffers.
    pub gpu_bytes: u64,
    /// Trail points placed (converted to offsets from their anchor) in the last frame.
    pub trail_points_encoded: u32,
    /// Trail points uploaded in the last frame.
    pub trail_points_uploaded: u32,
    /// Trail segments drawn (at most) in the last frame.
    pub trail_segments: u32,
    /// Labels drawn in the last frame (fading ones included).
    pub labels: u32,
    /// Labels asked for (aircraft on screen) in the last frame.
    pub labels_wanted: u32,
    /// CPU seconds the last frame's label placement took.
    pub label_placement_s: f64,
    /// Ground heights looked up in the last frame.
    pub ground_queries: u32,
    /// CPU seconds of the last frame's prepare (sampling, placing, uploads).
    pub prepare_s: f64,
    /// CPU seconds the last batch took to apply.
    pub apply_s: f64,
}

/// Per-slot state kept between frames.
#[derive(Clone, Copy, Debug)]
struct SlotState {
    /// Trail anchor (ECEF, as drawn).
    anchor: Option<DVec3>,
    /// Ground height last looked up (true metres), where, and in which frame.
    ground_m: f64,
    ground_at: [f64; 2],
    ground_frame: u64,
}

impl Default for SlotState {
    fn default() -> Self {
        Self {
            anchor: None,
            ground_m: f64::NAN,
            ground_at: [f64::NAN; 2],
            ground_frame: 0,
        }
    }
}

/// Moving aircraft over the globe. See the module documentation.
pub struct TrafficLayer {
    fleet: Fleet,
    sampled: Sampled,
    batch: Batch,
    time_s: f64,
    epoch_s: Option<f64>,
    style: TrafficStyle,
    meshes: [ModelMesh; 4],
    extents_m: [f32; 4],
    pick_base: u32,
    slots: Vec<SlotState>,
    rows: Vec<AircraftGpu>,
    /// Per slot: where the aircraft was drawn last frame (ECEF), NaN when not live.
    drawn_at: Vec<DVec3>,
    /// The GPU trail buffer's contents (offset from the slot's anchor, time since epoch).
    trail_encoded: Vec<[f32; 4]>,
    dirty_pages: Vec<bool>,
    reencode_all: bool,
    upload_all: bool,
    built_for: Option<(Ellipsoid, f64)>,
    writes: Vec<u32>,
    /// Model instances per kind and level of detail (`kind * MODEL_LODS + level`).
    instances: [Vec<u32>; MODEL_DRAWS],
    /// Slots whose trails are drawn, by bucket, with the most segments one needs.
    trail_lists: [(Vec<u32>, u32); 3],
    gpu: Option<Gpu>,
    stats: TrafficStats,
    frame: u64,
    selected: Option<u64>,
    labels: Labels,
}

/// The label side of the layer: the atlas, the placer and this frame's labels.
#[derive(Default)]
struct Labels {
    /// Made on the first frame that draws labels (`None` before, or when the font failed).
    atlas: Option<GlyphAtlas>,
    failed: bool,
    /// Per slot: its data block laid out.
    blocks: Vec<LaidOut>,
    /// This frame's requests (items: slots) and placed labels; the symbols are obstacles.
    batch: LabelBatch,
}

impl Default for TrafficLayer {
    fn default() -> Self {
        Self::new()
    }
}

impl TrafficLayer {
    /// An empty layer with the default fleet options and style, pick ids from
    /// [`DEFAULT_PICK_BASE`].
    pub fn new() -> Self {
        Self::with_options(
            FleetOptions::default(),
            TrafficStyle::default(),
            DEFAULT_PICK_BASE,
        )
    }

    /// An empty layer: how its fleet interpolates and keeps trails, how it draws, and the
    /// first pick id it writes (one per aircraft slot from there).
    pub fn with_options(fleet: FleetOptions, style: TrafficStyle, pick_base: u32) -> Self {
        let meshes = globus_traffic::AircraftKind::ALL.map(aircraft_mesh);
        let extents_m = [0, 1, 2, 3].map(|k| meshes[k].extent_m());
        Self {
            fleet: Fleet::new(fleet),
            sampled: Sampled::default(),
            batch: Batch::default(),
            time_s: 0.0,
            epoch_s: None,
            style,
            meshes,
            extents_m,
            pick_base: pick_base.max(1),
            slots: Vec::new(),
            rows: Vec::new(),
            drawn_at: Vec::new(),
            trail_encoded: Vec::new(),
            dirty_pages: Vec::new(),
            reencode_all: true,
            upload_all: true,
            built_for: None,
            writes: Vec::new(),
            instances: Default::default(),
            trail_lists: Default::default(),
            gpu: None,
            stats: TrafficStats::default(),
            frame: 0,
            selected: None,
            labels: Labels::default(),
        }
    }

    /// Replaces a kind's model (e.g. one read from a glTF file); the mesh's extent sets where
    /// the symbol gives way to it.
    pub fn set_model(&mut self, kind: globus_traffic::AircraftKind, mesh: ModelMesh) {
        let k = usize::from(kind.index());
        self.extents_m[k] = mesh.extent_m().max(0.1);
        self.meshes[k] = mesh;
        // The GPU copy is made again with the new meshes.
        self.gpu = None;
        self.upload_all = true;
    }

    /// The style.
    pub fn style(&self) -> &TrafficStyle {
        &self.style
    }

    /// Changes the style.
    pub fn set_style(&mut self, style: TrafficStyle) {
        self.style = style;
    }

    /// The fleet (every aircraft's samples and trails).
    pub fn fleet(&self) -> &Fleet {
        &self.fleet
    }

    /// Applies one tick's batch (see [`Fleet::apply`]).
    pub fn apply(&mut self, batch: &Batch) -> Result<(), FleetError> {
        let started = Instant::now();
        let result = self.fleet.apply(batch);
        self.stats.apply_s = started.elapsed().as_secs_f64();
        result
    }

    /// Moves `replay` to `time_s` and applies what it hands over (emptying the fleet first
    /// when the replay seeks), then draws that moment.
    pub fn play(&mut self, replay: &mut Replay, time_s: f64) -> Result<Step, FleetError> {
        let started = Instant::now();
        let mut batch = std::mem::take(&mut self.batch);
        let step = replay.advance_to(time_s, &mut batch);
        if step == Step::Reset {
            self.fleet.clear();
        }
        let result = self.fleet.apply(&batch);
        self.batch = batch;
        self.set_time(time_s);
        self.stats.apply_s = started.elapsed().as_secs_f64();
        result.map(|()| step)
    }

    /// The moment drawn (the fleet's clock, seconds).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Draws the aircraft as they are at `time_s`.
    pub fn set_time(&mut self, time_s: f64) {
        if time_s.is_finite() {
            self.time_s = time_s;
        }
    }

    /// Selects an aircraft (highlighted, its trail emphasised), or none; false when the id
    /// is not in the fleet.
    pub fn select(&mut self, id: Option<u64>) -> bool {
        if let Some(previous) = self.selected.take() {
            self.fleet.set_selected(previous, false);
        }
        match id {
            Some(id) if self.fleet.set_selected(id, true) => {
                self.selected = Some(id);
                true
            }
            Some(_) => false,
            None => true,
        }
    }

    /// The selected aircraft, if it is still in the fleet.
    pub fn selected(&self) -> Option<u64> {
        self.selected.filter(|&id| self.fleet.contains(id))
    }

    /// The aircraft whose symbol or model wrote `object` (a [`crate::Pick::object`]) in
    /// the last frame, if it is this layer's and still in the fleet.
    pub fn aircraft_for_pick(&self, object: u32) -> Option<u64> {
        let slot = object.checked_sub(self.pick_base)?;
        self.fleet.id_in_slot(slot)
    }

    /// Where an aircraft was drawn in the last frame (ECEF, exaggerated as drawn): the point
    /// a camera following it looks at.
    pub fn drawn_position(&self, id: u64) -> Option<DVec3> {
        let slot = self.fleet.slot_of(id)? as usize;
        self.drawn_at.get(slot).copied().filter(|p| p.is_finite())
    }

    /// Where an aircraft is drawn at the layer's time (ECEF, exaggerated; on the ground it
    /// last had under it when on or near it), computed now from its samples: a camera
    /// following it moves by this before the frame is drawn. `None` before the first frame
    /// (the body is not known yet) or for an id not in the fleet.
    pub fn position_now(&self, id: u64) -> Option<DVec3> {
        let (ellipsoid, exaggeration) = self.built_for?;
        let slot = self.fleet.slot_of(id)? as usize;
        let ([lon, lat, alt], _) = self.fleet.state_of(id, self.time_s)?;
        let on_ground = self
            .fleet
            .flags_of(id)
            .is_some_and(|f| f & flags::ON_GROUND != 0);
        let ground = self.slots.get(slot).map_or(f64::NAN, |s| s.ground_m);
        let alt_m = drawn_altitude_m(alt, on_ground, ground);
        Some(crate::globe::exaggerated(
            &ellipsoid,
            exaggeration,
            Cartographic::from_degrees(lon, lat, alt_m),
        ))
    }

    /// What the layer holds and what its last frame cost.
    pub fn stats(&self) -> TrafficStats {
        TrafficStats {
            aircraft: self.fleet.len(),
            ..self.stats
        }
    }

    /// The ground (true metres) under a slot's aircraft, looked up again when it moved or
    /// the answer is old, within the frame's allowance.
    fn ground_m(
        &mut self,
        frame: &FrameContext<'_>,
        slot: usize,
        lon_deg: f64,
        lat_deg: f64,
        alt_m: f64,
    ) -> f64 {
        let s = &mut self.slots[slot];
        let moved = (s.ground_at[0] - lon_deg)
            .abs()
            .max((s.ground_at[1] - lat_deg).abs());
        // The higher above the ground it was, the farther it may go before the ground can
        // have risen to it.
        let clearance = alt_m - s.ground_m;
        let reach = if clearance > 2_000.0 {
            GROUND_REFRESH_DEG * 10.0
        } else if clearance > 300.0 {
            GROUND_REFRESH_DEG * 3.0
        } else {
            GROUND_REFRESH_DEG
        };
        let stale = moved.is_nan() || moved > reach || self.frame - s.ground_frame > 60;
        if stale && (s.ground_m.is_nan() || self.stats.ground_queries < GROUND_QUERIES_PER_FRAME) {
            s.ground_m = frame.loaded_ground_m(lon_deg.to_radians(), lat_deg.to_radians());
            s.ground_at = [lon_deg, lat_deg];
            s.ground_frame = self.frame;
            self.stats.ground_queries += 1;
        }
        s.ground_m
    }

    /// Where a trail point is drawn (never below the ground under it).
    fn trail_world(frame: &FrameContext<'_>, p: [f64; 3]) -> DVec3 {
        let mut alt = p[2];
        if alt < GROUND_CHECK_BELOW_M {
            alt = alt.max(frame.loaded_ground_m(p[0].to_radians(), p[1].to_radians()));
        }
        frame.world_position(Cartographic::from_degrees(p[0], p[1], alt))
    }

    fn encode_point(&mut self, frame: &FrameContext<'_>, index: usize, epoch: f64) {
        let n = self.fleet.options().trail_points;
        let slot = index / n;
        let p = self.fleet.trail_storage()[index];
        let world = Self::trail_world(frame, p.position);
        let anchor = match self.slots[slot].anchor {
            Some(a) if (world - a).length() <= REANCHOR_M => a,
            _ => {
                // A new anchor: every point of the ring is re-encoded from it.
                self.slots[slot].anchor = Some(world);
                for k in slot * n..(slot + 1) * n {
                    if k != index {
                        let q = self.fleet.trail_storage()[k];
                        let w = Self::trail_world(frame, q.position);
                        self.trail_encoded[k] = encode(w - world, q.time_s - epoch);
                    }
                }
                self.dirty_pages[slot * n / PAGE_POINTS..=((slot + 1) * n - 1) / PAGE_POINTS]
                    .fill(true);
                world
            }
        };
        self.trail_encoded[index] = encode(world - anchor, p.time_s - epoch);
        self.dirty_pages[index / PAGE_POINTS] = true;
    }

    /// Brings the CPU mirror of the trail buffer up to date with the fleet.
    fn encode_trails(&mut self, frame: &FrameContext<'_>, epoch: f64) -> u32 {
        let n = self.fleet.options().trail_points;
        let points = self.fleet.slot_capacity() * n;
        if self.trail_encoded.len() < points {
            self.trail_encoded.resize(points, [0.0; 4]);
            self.upload_all = true;
        }
        self.dirty_pages.resize(points.div_ceil(PAGE_POINTS), false);
        let mut writes = std::mem::take(&mut self.writes);
        writes.clear();
        let everything = self.fleet.take_trail_writes(&mut writes) || self.reencode_all;
        let mut encoded = 0u32;
        if everything {
            writes.clear();
            for s in &mut self.slots {
                s.anchor = None;
            }
            for slot in 0..self.fleet.slot_capacity() {
                if self.fleet.id_in_slot(slot as u32).is_none() {
                    continue;
                }
                let (head, len) = self.fleet.trail_ring(slot as u32);
                if len > 0 {
                    // Re-anchors at this point and encodes the whole ring.
                    let newest = slot * n + (head as usize + n - 1) % n;
                    self.encode_point(frame, newest, epoch);
                    encoded += n as u32;
                }
            }
            self.upload_all = true;
            self.reencode_all = false;
        } else {
            for &i in &writes {
                self.encode_point(frame, i as usize, epoch);
                encoded += 1;
            }
        }
        self.writes = writes;
        encoded
    }

    /// One row per slot for this frame, the model instances and the trails to draw.
    fn place_aircraft(&mut self, frame: &FrameContext<'_>, epoch: f64) {
        let camera = frame.camera();
        let view = *camera.view();
        let frustum = Frustum::from_view(&view, camera.near_m());
        let sees = |centre: DVec3, radius: f64| {
            frustum.intersect_sphere(&BoundingSphere { centre, radius }) != Intersection::Outside
        };
        let ellipsoid = *frame.ellipsoid();
        let capacity = self.fleet.slot_capacity();
        let n = self.fleet.options().trail_points;
        let now = (self.time_s - epoch) as f32;
        let trail_s = self.fleet.options().trail_s as f32;
        self.rows.clear();
        self.rows.resize(capacity, AircraftGpu::default());
        self.drawn_at.clear();
        self.drawn_at.resize(capacity, DVec3::NAN);
        for list in &mut self.instances {
            list.clear();
        }
        for (list, segments) in &mut self.trail_lists {
            list.clear();
            *segments = 0;
        }
        let labels_on = self.style.labels && self.labels.atlas.is_some();
        self.labels.batch.begin();
        self.labels.blocks.resize_with(capacity, LaidOut::default);
        let occluder = EllipsoidalOccluder::new(&ellipsoid, view.occlusion_eye());
        let sampled = std::mem::take(&mut self.sampled);
        for r in 0..sampled.len() {
            let slot = sampled.slots[r] as usize;
            let [lon, lat, alt] = sampled.positions[r];
            let on_ground = sampled.flags[r] & flags::ON_GROUND != 0;
            let ground = if on_ground || alt < GROUND_CHECK_BELOW_M {
                self.ground_m(frame, slot, lon, lat, alt)
            } else {
                f64::NAN
            };
            let alt_m = drawn_altitude_m(alt, on_ground, ground);
            let world = frame.world_position(Cartographic::from_degrees(lon, lat, alt_m));
            let normal = ellipsoid.geodetic_normal(world).unwrap_or(DVec3::Z);
            let kind = usize::from(sampled.kinds[r] & 3);
            let f = sampled.flags[r];
            let mut b = bits::LIVE | ((kind as u32) << bits::KIND_SHIFT);
            if f & flags::SELECTED != 0 {
                b |= bits::SELECTED;
            }
            if f & flags::STALE != 0 {
                b |= bits::STALE;
            }
            let (head, len) = self.fleet.trail_ring(slot as u32);
            let position = camera.relative(world);
            let anchor = self.slots[slot]
                .anchor
                .map_or(position, |a| camera.relative(a));
            let [heading, pitch, _roll] = sampled.attitudes_deg[r];
            let extent = f64::from(self.extents_m[kind]);
            let distance = (world - view.position).length().max(1e-3);
            let px_per_m = view.pixels_per_metre(distance);
            let trail = if self.style.trails {
                self.trail_to_draw(slot, head, len, now, trail_s)
            } else {
                TrailSpan::default()
            };
            let trail_reach = f64::from(trail.span_m) + extent;
            let mut trail_bits = 0;
            if trail.past > 0 && sees(world, trail_reach) {
                // Segments a few pixels long: far trails skip points.
                let on_screen_px = f64::from(trail.span_m) * px_per_m;
                let wanted = (on_screen_px / TRAIL_SEGMENT_PX).ceil().max(1.0);
                let points = f64::from(trail.past - trail.first_visible);
                let stride = (points / wanted).ceil().clamp(1.0, f64::from(n as u32)) as u32;
                let segments = 2 + (trail.past - 1 - trail.first_visible) / stride;
                trail_bits = trail.past | (stride << 16);
                let bucket = TRAIL_BUCKETS
                    .iter()
                    .position(|&cap| segments <= cap)
                    .unwrap_or(TRAIL_BUCKETS.len() - 1);
                let (list, most) = &mut self.trail_lists[bucket];
                list.push(slot as u32);
                *most = (*most).max(segments);
            }
            self.rows[slot] = AircraftGpu {
                position: position.to_array(),
                colour: u32::from_le_bytes(sampled.colours[r]),
                normal: normal.as_vec3().to_array(),
                bits: b,
                anchor: anchor.to_array(),
                ring: (head & 0xffff) | (len.min(0xffff) << 16),
                heading_rad: heading.to_radians(),
                pitch_rad: pitch.to_radians(),
                trail: trail_bits,
                spare: 0,
            };
            self.drawn_at[slot] = world;
            if labels_on
                && occluder.is_point_visible(world)
                && let Some((px, depth)) = camera.project_with_depth(world)
                && px.x >= 0.0
                && px.y >= 0.0
                && px.x <= f64::from(view.width_px)
                && px.y <= f64::from(view.height_px)
            {
                let selected = f & flags::SELECTED != 0;
                let content = BlockContent::new(
                    sampled.ids[r],
                    sampled.callsigns[r],
                    alt_m,
                    on_ground,
                    sampled.speeds[r],
                    selected,
                );
                if let Some(atlas) = &self.labels.atlas {
                    self.labels.blocks[slot].update(atlas, &content, self.style.label_px);
                }
                let [w, h] = self.labels.blocks[slot].size;
                let half = self.style.symbol_px[kind] * 0.5;
                let (x, y) = (px.x as f32, px.y as f32);
                let request = LabelRequest {
                    id: sampled.ids[r],
                    anchor_px: [px.x as f32, px.y as f32],
                    clearance_px: self.style.symbol_px[kind] * 0.5 + 4.0,
                    size_px: [w + 2.0 * LABEL_PAD_PX, h + 2.0 * LABEL_PAD_PX],
                    // Selected first, then by size on screen: nearer, then larger.
                    priority: if selected {
                        f32::MAX
                    } else {
                        (extent * px_per_m) as f32
                    },
                };
                self.labels.batch.request(
                    request,
                    slot as u32,
                    depth as f32,
                    [x - half, y - half, x + half, y + half],
                );
            }
            if self.style.models {
                let true_px = extent * px_per_m;
                if true_px >= 0.75 * f64::from(self.style.symbol_px[kind])
                    && sees(world, extent * 2.0)
                {
                    // The coarse level until the model is large on screen.
                    let level = usize::from(true_px < MODEL_LOD_FULL_PX);
                    self.instances[kind * MODEL_LODS + level].push(slot as u32);
                }
            }
        }
        self.sampled = sampled;
    }

    /// Places this frame's labels and builds what the GPU draws of them.
    fn place_labels_now(&mut self, frame: &FrameContext<'_>) {
        let now = Instant::now();
        let l = &mut self.labels;
        l.batch.place(frame, self.style.label_fade_s);
        let batch = &mut l.batch;
        for k in 0..batch.placed.len() {
            let p = batch.placed[k];
            let (slot, depth) = batch.items[p.request];
            let r = batch.requests[p.request];
            let row = self.rows[slot as usize];
            let label = LabelGpu {
                anchor: r.anchor_px,
                depth,
                opacity: p.opacity,
                origin: [p.bounds[0], p.bounds[1]],
                size: [p.bounds[2] - p.bounds[0], p.bounds[3] - p.bounds[1]],
                colour: label_colour(row.colour, row.bits & bits::SELECTED != 0),
                clearance: r.clearance_px,
                scale: 0.0,
                spare: 0.0,
            };
            batch.push_row(label, &l.blocks[slot as usize].glyphs, LABEL_PAD_PX);
        }
        let l = &self.labels.batch;
        self.stats.labels = l.placed.len() as u32;
        self.stats.labels_wanted = l.requests.len() as u32;
        self.stats.label_placement_s = now.elapsed().as_secs_f64();
    }

    /// The labels drawn in the last frame: each one's aircraft and its box on screen (min x,
    /// min y, max x, max y, pixels), and its opacity.
    pub fn drawn_labels(&self) -> impl Iterator<Item = (u64, [f32; 4], f32)> + '_ {
        self.labels
            .batch
            .placed
            .iter()
            .map(|p| (p.id, p.bounds, p.opacity))
    }

    /// Which of a slot's trail points are drawn now: those older than now (the newest may be
    /// a report ahead of the clock), from the first younger than the trail's age.
    fn trail_to_draw(&self, slot: usize, head: u32, len: u32, now: f32, trail_s: f32) -> TrailSpan {
        let n = self.fleet.options().trail_points;
        let (head, len) = (head as usize, len as usize);
        let at = |k: usize| self.trail_encoded[slot * n + (head + n - len + k) % n];
        let mut past = len;
        while past > 0 && at(past - 1)[3] >= now {
            past -= 1;
        }
        if past == 0 {
            return TrailSpan::default();
        }
        // Ring points are in time order: the first young enough, by bisection.
        let (mut lo, mut hi) = (0usize, past - 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if now - at(mid)[3] > trail_s {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        let (a, b) = (at(lo), at(past - 1));
        let span_m = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        TrailSpan {
            past: past as u32,
            first_visible: lo as u32,
            span_m,
        }
    }
}

/// The part of a trail drawn this frame.
#[derive(Clone, Copy, Debug, Default)]
struct TrailSpan {
    /// Points older than now.
    past: u32,
    /// The oldest of them younger than the trail's age.
    first_visible: u32,
    /// Straight distance from it to the newest past point, metres.
    span_m: f32,
}

/// The altitude an aircraft is drawn at: on the ground when it says so, never below it
/// (`ground_m` NaN: not known, the altitude as given).
fn drawn_altitude_m(alt_m: f64, on_ground: bool, ground_m: f64) -> f64 {
    match (on_ground, ground_m.is_nan()) {
        (_, true) => alt_m,
        (true, false) => ground_m,
        (false, false) => alt_m.max(ground_m),
    }
}

/// A camera following an aircraft: each frame, before it is drawn, the view moves as the
/// aircraft moved since the last, so the aircraft stays where it is on the screen while the
/// user still turns and zooms the view around it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Follow {
    id: u64,
    last: DVec3,
}

impl Follow {
    /// Starts following `id` where it is now (`None` if it is not drawn yet).
    pub fn start(layer: &TrafficLayer, id: u64) -> Option<Self> {
        Some(Self {
            id,
            last: layer.position_now(id)?,
        })
    }

    /// The followed aircraft.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// Moves `view` with the aircraft; `false` once it has left the fleet. A perspective
    /// view moves by the aircraft's displacement; an orthographic one turns about the body's
    /// centre by the aircraft's change of direction from it, so it stays top-down at its
    /// height while the aircraft climbs or crosses the planet.
    pub fn update(&mut self, layer: &TrafficLayer, view: &mut globus_geo::View) -> bool {
        let Some(now) = layer.position_now(self.id) else {
            return false;
        };
        if view.ortho_height_m().is_some() {
            if let (Some(from), Some(to)) = (self.last.try_normalize(), now.try_normalize()) {
                let q = globus_geo::DQuat::from_rotation_arc(from, to);
                view.position = q * view.position;
                view.orientation = (q * view.orientation).normalize();
            }
            self.last = now;
            return true;
        }
        view.position += now - self.last;
        self.last = now;
        true
    }
}

/// A label's text colour: its aircraft's, lifted towards white so it reads over a dark halo;
/// the selection's yellow when selected.
fn label_colour(colour: u32, selected: bool) -> u32 {
    if selected {
        return u32::from_le_bytes([255, 230, 60, 255]);
    }
    let c = colour.to_le_bytes();
    let lift = |v: u8| ((u16::from(v) + 255) / 2) as u8;
    u32::from_le_bytes([lift(c[0]), lift(c[1]), lift(c[2]), 255])
}

fn encode(offset: DVec3, time_s: f64) -> [f32; 4] {
    [
        offset.x as f32,
        offset.y as f32,
        offset.z as f32,
        time_s as f32,
    ]
}

impl Overlay for TrafficLayer {
    fn passes(&self) -> &[OverlayPass] {
        &[OverlayPass::World, OverlayPass::ScreenAligned]
    }

    fn wants_terrain_depth(&self) -> bool {
        true
    }

    fn prepare(&mut self, frame: &FrameContext<'_>) {
        let started = Instant::now();
        self.frame += 1;
        self.stats.ground_queries = 0;
        let key = (*frame.ellipsoid(), frame.exaggeration());
        if self.built_for != Some(key) {
            self.built_for = Some(key);
            self.reencode_all = true;
        }
        let epoch = match self.epoch_s {
            Some(e) if (self.time_s - e).abs() < 1.0e5 => e,
            _ => {
                self.epoch_s = Some(self.time_s);
                self.reencode_all = true;
                self.time_s
            }
        };
        if self.style.labels && self.labels.atlas.is_none() && !self.labels.failed {
            match GlyphAtlas::new() {
                Ok(a) => self.labels.atlas = Some(a),
                Err(e) => {
                    tracing::warn!("traffic labels are off: {e}");
                    self.labels.failed = true;
                }
            }
        }
        self.fleet.sample(self.time_s, &mut self.sampled);
        let capacity = self.fleet.slot_capacity();
        self.slots.resize(capacity, SlotState::default());
        self.stats.trail_points_encoded = self.encode_trails(frame, epoch);
        self.place_aircraft(frame, epoch);

        self.labels.batch.claim_symbols(frame);
        if self.gpu.is_none() {
            let fallback;
            let atlas = match &self.labels.atlas {
                Some(a) => a,
                None => {
                    fallback = GlyphAtlas::empty();
                    &fallback
                }
            };
            self.gpu = Some(Gpu::new(frame, &self.meshes, atlas));
            self.upload_all = true;
        }
        let Some(gpu) = self.gpu.as_mut() else {
            return;
        };
        let n = self.fleet.options().trail_points;
        if gpu.reserve_trails(frame, capacity * n) {
            self.upload_all = true;
        }
        let mut uploaded = 0usize;
        if self.upload_all {
            gpu.upload_trails(frame, &self.trail_encoded, 0..self.trail_encoded.len());
            uploaded = self.trail_encoded.len();
            self.dirty_pages.fill(false);
            self.upload_all = false;
        } else {
            let mut page = 0;
            while page < self.dirty_pages.len() {
                if !self.dirty_pages[page] {
                    page += 1;
                    continue;
                }
                let start = page;
                while page < self.dirty_pages.len() && self.dirty_pages[page] {
                    self.dirty_pages[page] = false;
                    page += 1;
                }
                let range = start * PAGE_POINTS..page * PAGE_POINTS;
                uploaded += range.len();
                gpu.upload_trails(frame, &self.trail_encoded, range);
            }
        }
        let camera = frame.camera();
        let (w, h) = camera.viewport_px();
        let (w, h) = (w.max(1) as f32, h.max(1) as f32);
        // Perspective: the focal length (pixels per metre at 1 m); orthographic: pixels per
        // metre everywhere.
        let focal_px = camera.pixels_per_metre(1.0) as f32;
        let sun = frame.sun_direction().as_vec3();
        let mut kinds = [[0f32; 4]; 4];
        for (k, row) in kinds.iter_mut().enumerate() {
            *row = [self.style.symbol_px[k], self.extents_m[k], 0.0, 0.0];
        }
        let uniforms = Uniforms {
            clip_from_eye: camera.clip_from_eye().to_cols_array_2d(),
            viewport: [w, h, 1.0 / w, 1.0 / h],
            params: [
                focal_px,
                (self.time_s - epoch) as f32,
                self.fleet.options().trail_s as f32,
                SYMBOL_TOLERANCE,
            ],
            sun: [sun.x, sun.y, sun.z, AMBIENT],
            counts: [
                n as u32,
                self.pick_base,
                self.style.trail_width_px.to_bits(),
                0,
            ],
            kinds,
        };
        gpu.write_frame(
            frame,
            &uniforms,
            &self.rows,
            &self.instances,
            &self.trail_lists,
        );
        let model_draws = self.instances.iter().filter(|l| !l.is_empty()).count() as u32;
        let trail_draws = self.trail_lists.iter().filter(|l| !l.0.is_empty()).count() as u32;
        self.stats.draw_calls = u32::from(!self.rows.is_empty()) + model_draws + trail_draws;
        self.stats.trail_segments = self
            .trail_lists
            .iter()
            .map(|(l, s)| l.len() as u32 * s)
            .sum();
        self.stats.models = self.instances.iter().map(|l| l.len() as u32).sum();
        self.stats.models_coarse = self
            .instances
            .iter()
            .skip(1)
            .step_by(MODEL_LODS)
            .map(|l| l.len() as u32)
            .sum();
        self.stats.gpu_bytes = gpu.gpu_bytes();
        self.stats.trail_points_uploaded = uploaded as u32;
        self.stats.prepare_s = started.elapsed().as_secs_f64();
    }

    fn place_labels(&mut self, frame: &FrameContext<'_>) {
        let started = Instant::now();
        self.place_labels_now(frame);
        if let Some(gpu) = self.gpu.as_mut()
            && self.labels.atlas.is_some()
        {
            gpu.write_labels(
                frame,
                self.style.label_px,
                SYMBOL_TOLERANCE,
                &self.labels.batch.rows,
                &self.labels.batch.glyphs,
            );
        }
        self.stats.draw_calls += 2 * u32::from(!self.labels.batch.rows.is_empty());
        self.stats.prepare_s += started.elapsed().as_secs_f64();
    }

    fn draw(
        &self,
        pass: OverlayPass,
        _frame: &FrameContext<'_>,
        render_pass: &mut wgpu::RenderPass<'_>,
    ) {
        let Some(gpu) = &self.gpu else {
            return;
        };
        match pass {
            OverlayPass::World => {
                gpu.draw_world(render_pass);
            }
            OverlayPass::ScreenAligned => {
                gpu.draw_symbols(render_pass);
            }
            OverlayPass::Screen => {}
        }
    }
}
