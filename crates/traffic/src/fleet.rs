//! Moving objects, column by column: per tick a [`Batch`] of samples (ids, f64 positions,
//! attitude, kind, colour, flags, label fields) and removals; per frame the state of every
//! object at one moment, interpolated between its last two samples or briefly extrapolated
//! past the newest.
//!
//! The [`Fleet`] keeps struct-of-arrays columns indexed by a dense slot (a removed object's
//! slot is reused), and an id-to-slot map. Applying a batch is O(batch): a map lookup and a
//! few column writes per sample, no allocation once the columns have grown to the fleet's
//! size (a new id is an add; removing an unknown id is ignored and counted). Sampling a moment
//! ([`Fleet::sample`]) writes every live object's interpolated state into reusable columns.
//!
//! Interpolation is linear in longitude (unwrapped across the antimeridian), latitude and
//! altitude between the two samples around the moment; heading turns the short way. Past the
//! newest sample an object moves on at its last velocity for at most
//! [`FleetOptions::extrapolate_s`] and then waits there, marked [`flags::STALE`]. Every
//! object is drawn at the moment its label is, because both read the same sampled columns.
//!
//! Trails are per-object ring buffers of past samples ([`FleetOptions::trail_points`] each,
//! one shared allocation): a sample appends in O(1), overwriting the oldest; what is drawn is
//! the part newer than [`FleetOptions::trail_s`].

use rustc_hash::FxHashMap;

/// Flag bits of an object.
pub mod flags {
    /// On the ground: drawn on the terrain, whatever its altitude says.
    pub const ON_GROUND: u32 = 1;
    /// Selected by the user.
    pub const SELECTED: u32 = 1 << 1;
    /// Set by [`super::Fleet::sample`]: no sample newer than the extrapolation allows.
    pub const STALE: u32 = 1 << 2;
}

/// Up to this many bytes of call sign (ASCII; shorter ones end in zeros).
pub const CALLSIGN_BYTES: usize = 8;

/// One tick's changes, as columns of equal length (plus removals). Reuse it: [`Batch::clear`]
/// keeps the columns' capacity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// Object ids (e.g. the 24-bit ICAO address).
    pub ids: Vec<u64>,
    /// The moment of each sample, seconds (any clock, the same as [`Fleet::sample`]'s).
    pub times_s: Vec<f64>,
    /// Longitude and latitude in degrees, altitude in metres above the ellipsoid.
    pub positions: Vec<[f64; 3]>,
    /// Heading (degrees clockwise from north), pitch and roll (degrees).
    pub attitudes_deg: Vec<[f32; 3]>,
    /// Model kind (e.g. [`crate::AircraftKind::index`]).
    pub kinds: Vec<u8>,
    /// Colour, sRGB with alpha.
    pub colours: Vec<[u8; 4]>,
    /// [`flags`] bits.
    pub flags: Vec<u32>,
    /// Label fields: ground speed m/s and vertical rate m/s (NaN unknown).
    pub speeds: Vec<[f32; 2]>,
    /// Call signs, ASCII, zero-padded.
    pub callsigns: Vec<[u8; CALLSIGN_BYTES]>,
    /// Ids to remove (after this batch's samples).
    pub removed: Vec<u64>,
}

/// One sample, for [`Batch::push`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Object id.
    pub id: u64,
    /// Moment, seconds.
    pub time_s: f64,
    /// Longitude, latitude (degrees), altitude (m).
    pub position: [f64; 3],
    /// Heading, pitch, roll, degrees.
    pub attitude_deg: [f32; 3],
    /// Model kind.
    pub kind: u8,
    /// Colour.
    pub colour: [u8; 4],
    /// [`flags`] bits.
    pub flags: u32,
    /// Ground speed and vertical rate, m/s.
    pub speeds: [f32; 2],
    /// Call sign.
    pub callsign: [u8; CALLSIGN_BYTES],
}

impl Batch {
    /// Empties every column, keeping its capacity.
    pub fn clear(&mut self) {
        self.ids.clear();
        self.times_s.clear();
        self.positions.clear();
        self.attitudes_deg.clear();
        self.kinds.clear();
        self.colours.clear();
        self.flags.clear();
        self.speeds.clear();
        self.callsigns.clear();
        self.removed.clear();
    }

    /// Appends one sample to every column.
    pub fn push(&mut self, s: Sample) {
        self.ids.push(s.id);
        self.times_s.push(s.time_s);
        self.positions.push(s.position);
        self.attitudes_deg.push(s.attitude_deg);
        self.kinds.push(s.kind);
        self.colours.push(s.colour);
        self.flags.push(s.flags);
        self.speeds.push(s.speeds);
        self.callsigns.push(s.callsign);
    }

    /// Samples in the batch.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the batch holds no samples and no removals.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty() && self.removed.is_empty()
    }

    fn check(&self) -> Result<(), FleetError> {
        let n = self.ids.len();
        let lengths = [
            self.times_s.len(),
            self.positions.len(),
            self.attitudes_deg.len(),
            self.kinds.len(),
            self.colours.len(),
            self.flags.len(),
            self.speeds.len(),
            self.callsigns.len(),
        ];
        if lengths.iter().any(|&l| l != n) {
            return Err(FleetError::ColumnLengths {
                ids: n,
                lengths: lengths.to_vec(),
            });
        }
        Ok(())
    }
}

/// A call sign as zero-padded ASCII bytes (longer ones cut, non-ASCII dropped).
pub fn callsign_bytes(text: &str) -> [u8; CALLSIGN_BYTES] {
    let mut out = [0u8; CALLSIGN_BYTES];
    for (o, b) in out
        .iter_mut()
        .zip(text.bytes().filter(u8::is_ascii_graphic))
    {
        *o = b;
    }
    out
}

/// A batch that cannot be applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FleetError {
    /// The columns are not all as long as `ids`.
    #[error("batch columns differ in length: {ids} ids, other columns {lengths:?}")]
    ColumnLengths {
        /// Length of `ids`.
        ids: usize,
        /// Lengths of the other columns, in field order.
        lengths: Vec<usize>,
    },
}

/// How a fleet moves its objects between samples and keeps their trails.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FleetOptions {
    /// Longest extrapolation past an object's newest sample, seconds.
    pub extrapolate_s: f64,
    /// Trail samples kept per object.
    pub trail_points: usize,
    /// Age of the oldest trail sample drawn, seconds.
    pub trail_s: f64,
    /// Least time between two trail samples, seconds: samples closer to the previous trail
    /// sample than this move the object but leave no trail point, so `trail_points` cover
    /// `trail_s` whatever the report rate (64 points 10 s apart hold 10 minutes).
    pub trail_spacing_s: f64,
}

impl Default for FleetOptions {
    fn default() -> Self {
        FleetOptions {
            extrapolate_s: 20.0,
            trail_points: 64,
            trail_s: 600.0,
            trail_spacing_s: 10.0,
        }
    }
}

/// What applying batches did, summed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FleetCounts {
    /// Samples for ids not seen before.
    pub added: u64,
    /// Samples for known ids.
    pub updated: u64,
    /// Ids removed.
    pub removed: u64,
    /// Removals of ids the fleet did not hold (ignored).
    pub unknown_removals: u64,
    /// Samples older than the object's newest (ignored).
    pub out_of_order: u64,
    /// Samples with a non-finite or out-of-range position (ignored).
    pub invalid: u64,
}

/// One trail point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrailPoint {
    /// Moment, seconds.
    pub time_s: f64,
    /// Longitude, latitude (degrees), altitude (m).
    pub position: [f64; 3],
}

/// Every live object at one moment, as columns (reused between frames).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sampled {
    /// The moment.
    pub time_s: f64,
    /// Ids.
    pub ids: Vec<u64>,
    /// Slots (for [`Fleet::trail`]).
    pub slots: Vec<u32>,
    /// Longitude, latitude (degrees), altitude (m).
    pub positions: Vec<[f64; 3]>,
    /// Heading, pitch, roll, degrees.
    pub attitudes_deg: Vec<[f32; 3]>,
    /// Kinds.
    pub kinds: Vec<u8>,
    /// Colours.
    pub colours: Vec<[u8; 4]>,
    /// Flags ([`flags::STALE`] set here).
    pub flags: Vec<u32>,
    /// Ground speed, vertical rate, m/s.
    pub speeds: Vec<[f32; 2]>,
    /// Call signs.
    pub callsigns: Vec<[u8; CALLSIGN_BYTES]>,
}

impl Sampled {
    fn clear(&mut self) {
        self.ids.clear();
        self.slots.clear();
        self.positions.clear();
        self.attitudes_deg.clear();
        self.kinds.clear();
        self.colours.clear();
        self.flags.clear();
        self.speeds.clear();
        self.callsigns.clear();
    }

    /// Objects sampled.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether none are.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The row of an id.
    pub fn find(&self, id: u64) -> Option<usize> {
        self.ids.iter().position(|&i| i == id)
    }
}

/// Moving objects by id; see the module doc.
#[derive(Clone, Debug, Default)]
pub struct Fleet {
    options: FleetOptions,
    slot_of: FxHashMap<u64, u32>,
    free: Vec<u32>,
    live: Vec<bool>,
    ids: Vec<u64>,
    /// Older and newer sample per slot.
    times: Vec<[f64; 2]>,
    positions: Vec<[[f64; 3]; 2]>,
    attitudes: Vec<[[f32; 3]; 2]>,
    kinds: Vec<u8>,
    colours: Vec<[u8; 4]>,
    flags: Vec<u32>,
    speeds: Vec<[f32; 2]>,
    callsigns: Vec<[u8; CALLSIGN_BYTES]>,
    /// `trail_points` per slot; `trail_heads[slot]` is the next write, `trail_lens` how many.
    trails: Vec<TrailPoint>,
    trail_heads: Vec<u32>,
    trail_lens: Vec<u32>,
    /// Indices into `trails` written since [`Fleet::take_trail_writes`] last ran; cleared
    /// (and `trails_rewritten` set) when it would outgrow the ring storage itself.
    trail_writes: Vec<u32>,
    trails_rewritten: bool,
    counts: FleetCounts,
}

impl Fleet {
    /// An empty fleet.
    pub fn new(options: FleetOptions) -> Fleet {
        Fleet {
            options: FleetOptions {
                trail_points: options.trail_points.max(1),
                ..options
            },
            ..Fleet::default()
        }
    }

    /// The options.
    pub fn options(&self) -> &FleetOptions {
        &self.options
    }

    /// Live objects.
    pub fn len(&self) -> usize {
        self.slot_of.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.slot_of.is_empty()
    }

    /// Removes every object (slots, trails and counts are kept for reuse; counts go on).
    pub fn clear(&mut self) {
        let ids: Vec<u64> = self.slot_of.keys().copied().collect();
        for id in ids {
            self.remove(id);
        }
    }

    /// The slot of a live object (its row in the GPU mirror of a drawing layer).
    pub fn slot_of(&self, id: u64) -> Option<u32> {
        self.slot_of.get(&id).copied()
    }

    /// A live object's flags.
    pub fn flags_of(&self, id: u64) -> Option<u32> {
        self.slot_of.get(&id).map(|&s| self.flags[s as usize])
    }

    /// The live object in a slot.
    pub fn id_in_slot(&self, slot: u32) -> Option<u64> {
        let s = slot as usize;
        (*self.live.get(s)?).then(|| self.ids[s])
    }

    /// Slots the columns hold (live or free): slot numbers are below this.
    pub fn slot_capacity(&self) -> usize {
        self.ids.len()
    }

    /// Every slot's trail ring, `trail_points` per slot (slot `s` holds
    /// `[s * trail_points, (s + 1) * trail_points)`); see [`Fleet::trail_ring`].
    pub fn trail_storage(&self) -> &[TrailPoint] {
        &self.trails
    }

    /// A slot's ring: the index (within the slot's part of [`Fleet::trail_storage`]) the
    /// next point goes to, and how many points it holds (the newest is just before the
    /// head, wrapping round).
    pub fn trail_ring(&self, slot: u32) -> (u32, u32) {
        let s = slot as usize;
        match (self.trail_heads.get(s), self.trail_lens.get(s)) {
            (Some(&h), Some(&l)) => (h, l),
            _ => (0, 0),
        }
    }

    /// Hands over the indices into [`Fleet::trail_storage`] written since the last call
    /// (for mirrors such as a GPU copy), appending them to `out`. Returns `true` when more
    /// was written than the log holds (the ring storage's size): then every point may have
    /// changed and `out` is left as it was.
    pub fn take_trail_writes(&mut self, out: &mut Vec<u32>) -> bool {
        let all = std::mem::take(&mut self.trails_rewritten);
        if !all {
            out.extend_from_slice(&self.trail_writes);
        }
        self.trail_writes.clear();
        all
    }

    /// What applying batches did so far.
    pub fn counts(&self) -> FleetCounts {
        self.counts
    }

    /// Whether an object is live.
    pub fn contains(&self, id: u64) -> bool {
        self.slot_of.contains_key(&id)
    }

    /// Bytes the columns hold (capacity), for memory figures.
    pub fn heap_bytes(&self) -> usize {
        let per_slot = std::mem::size_of::<u64>()
            + std::mem::size_of::<bool>()
            + std::mem::size_of::<[f64; 2]>()
            + std::mem::size_of::<[[f64; 3]; 2]>()
            + std::mem::size_of::<[[f32; 3]; 2]>()
            + 1
            + 4
            + 4
            + 8
            + CALLSIGN_BYTES
            + 8
            + self.options.trail_points * std::mem::size_of::<TrailPoint>();
        // The map: key, value and about one control byte per entry, at its capacity.
        let map = self.slot_of.capacity() * (8 + 4 + 1);
        self.ids.capacity() * per_slot + map + self.trail_writes.capacity() * 4
    }

    /// Applies one tick's batch: samples in order (an unknown id is an add), then removals.
    pub fn apply(&mut self, batch: &Batch) -> Result<(), FleetError> {
        batch.check()?;
        for i in 0..batch.ids.len() {
            self.apply_one(batch, i);
        }
        for &id in &batch.removed {
            self.remove(id);
        }
        Ok(())
    }

    fn apply_one(&mut self, b: &Batch, i: usize) {
        let (id, t, p) = (b.ids[i], b.times_s[i], b.positions[i]);
        let valid = t.is_finite()
            && p.iter().all(|v| v.is_finite())
            && p[0].abs() <= 360.0
            && p[1].abs() <= 90.0;
        if !valid {
            self.counts.invalid += 1;
            return;
        }
        let slot = match self.slot_of.get(&id) {
            Some(&s) => s as usize,
            None => {
                let s = self.allocate(id);
                self.times[s] = [t, t];
                self.positions[s] = [p, p];
                self.attitudes[s] = [b.attitudes_deg[i]; 2];
                self.counts.added += 1;
                self.write_fields(s, b, i);
                self.push_trail(s, t, p);
                return;
            }
        };
        let newest = self.times[slot][1];
        if t < newest {
            self.counts.out_of_order += 1;
            return;
        }
        self.counts.updated += 1;
        if t > newest {
            self.times[slot] = [newest, t];
            self.positions[slot] = [self.positions[slot][1], p];
            self.attitudes[slot] = [self.attitudes[slot][1], b.attitudes_deg[i]];
            self.push_trail(slot, t, p);
        } else {
            // Same moment: a correction of the newest sample.
            self.positions[slot][1] = p;
            self.attitudes[slot][1] = b.attitudes_deg[i];
        }
        self.write_fields(slot, b, i);
    }

    fn write_fields(&mut self, s: usize, b: &Batch, i: usize) {
        self.kinds[s] = b.kinds[i];
        self.colours[s] = b.colours[i];
        // Selection is the user's: updates keep it (and may set it).
        let selected = self.flags[s] & flags::SELECTED;
        self.flags[s] = (b.flags[i] & !flags::STALE) | selected;
        self.speeds[s] = b.speeds[i];
        self.callsigns[s] = b.callsigns[i];
    }

    fn allocate(&mut self, id: u64) -> usize {
        let slot = match self.free.pop() {
            Some(s) => s as usize,
            None => {
                let s = self.ids.len();
                self.ids.push(id);
                self.live.push(false);
                self.times.push([0.0; 2]);
                self.positions.push([[0.0; 3]; 2]);
                self.attitudes.push([[0.0; 3]; 2]);
                self.kinds.push(0);
                self.colours.push([0; 4]);
                self.flags.push(0);
                self.speeds.push([0.0; 2]);
                self.callsigns.push([0; CALLSIGN_BYTES]);
                let empty = TrailPoint {
                    time_s: 0.0,
                    position: [0.0; 3],
                };
                self.trails
                    .extend(std::iter::repeat_n(empty, self.options.trail_points));
                self.trail_heads.push(0);
                self.trail_lens.push(0);
                s
            }
        };
        self.ids[slot] = id;
        self.live[slot] = true;
        self.flags[slot] = 0;
        self.trail_heads[slot] = 0;
        self.trail_lens[slot] = 0;
        self.slot_of.insert(id, slot as u32);
        slot
    }

    fn push_trail(&mut self, slot: usize, time_s: f64, position: [f64; 3]) {
        let n = self.options.trail_points;
        let head = self.trail_heads[slot] as usize;
        let len = self.trail_lens[slot] as usize;
        if len > 0 {
            let newest = self.trails[slot * n + (head + n - 1) % n];
            if time_s - newest.time_s < self.options.trail_spacing_s {
                return;
            }
        }
        let index = slot * n + head;
        self.trails[index] = TrailPoint { time_s, position };
        if self.trail_writes.len() >= self.trails.len() {
            self.trail_writes.clear();
            self.trails_rewritten = true;
        }
        if !self.trails_rewritten {
            self.trail_writes.push(index as u32);
        }
        self.trail_heads[slot] = ((head + 1) % n) as u32;
        self.trail_lens[slot] = (self.trail_lens[slot] + 1).min(n as u32);
    }

    /// Removes an object (unknown ids are ignored and counted).
    pub fn remove(&mut self, id: u64) {
        match self.slot_of.remove(&id) {
            Some(slot) => {
                self.live[slot as usize] = false;
                self.free.push(slot);
                self.counts.removed += 1;
            }
            None => self.counts.unknown_removals += 1,
        }
    }

    /// Sets or clears [`flags::SELECTED`] of one object; false when it is not live.
    pub fn set_selected(&mut self, id: u64, selected: bool) -> bool {
        let Some(&slot) = self.slot_of.get(&id) else {
            return false;
        };
        let f = &mut self.flags[slot as usize];
        *f = if selected {
            *f | flags::SELECTED
        } else {
            *f & !flags::SELECTED
        };
        true
    }

    /// Writes every live object's state at `time_s` into `out` (in slot order).
    pub fn sample(&self, time_s: f64, out: &mut Sampled) {
        out.clear();
        out.time_s = time_s;
        for slot in 0..self.ids.len() {
            if !self.live[slot] {
                continue;
            }
            let (position, attitude, stale) = self.state_at(slot, time_s);
            out.ids.push(self.ids[slot]);
            out.slots.push(slot as u32);
            out.positions.push(position);
            out.attitudes_deg.push(attitude);
            out.kinds.push(self.kinds[slot]);
            out.colours.push(self.colours[slot]);
            out.flags
                .push(self.flags[slot] | if stale { flags::STALE } else { 0 });
            out.speeds.push(self.speeds[slot]);
            out.callsigns.push(self.callsigns[slot]);
        }
    }

    /// One object's state at `time_s`, or `None` when it is not live.
    pub fn state_of(&self, id: u64, time_s: f64) -> Option<([f64; 3], [f32; 3])> {
        let &slot = self.slot_of.get(&id)?;
        let (p, a, _) = self.state_at(slot as usize, time_s);
        Some((p, a))
    }

    fn state_at(&self, slot: usize, t: f64) -> ([f64; 3], [f32; 3], bool) {
        let [t0, t1] = self.times[slot];
        let [p0, p1] = self.positions[slot];
        let [a0, a1] = self.attitudes[slot];
        let span = t1 - t0;
        if t == t1 {
            return (p1, a1, false);
        }
        if span <= 0.0 || t <= t0 {
            let p = if t <= t0 { p0 } else { p1 };
            let a = if t <= t0 { a0 } else { a1 };
            return (p, a, t > t1 + self.options.extrapolate_s);
        }
        // Past the newest sample: on at the last velocity, for a while.
        let over = t - t1;
        let stale = over > self.options.extrapolate_s;
        let f = if over > 0.0 {
            (span + over.min(self.options.extrapolate_s)) / span
        } else {
            (t - t0) / span
        };
        let dlon = (p1[0] - p0[0] + 540.0).rem_euclid(360.0) - 180.0;
        let mut lon = p0[0] + dlon * f;
        if lon > 180.0 {
            lon -= 360.0;
        } else if lon < -180.0 {
            lon += 360.0;
        }
        let lat = (p0[1] + (p1[1] - p0[1]) * f).clamp(-90.0, 90.0);
        let alt = p0[2] + (p1[2] - p0[2]) * f;
        let fa = f.min(1.0) as f32;
        let turn = (a1[0] - a0[0] + 540.0).rem_euclid(360.0) - 180.0;
        let attitude = [
            (a0[0] + turn * fa).rem_euclid(360.0),
            a0[1] + (a1[1] - a0[1]) * fa,
            a0[2] + (a1[2] - a0[2]) * fa,
        ];
        ([lon, lat, alt], attitude, stale)
    }

    /// The trail of a slot (from [`Sampled::slots`]), oldest first, newer than
    /// `time_s - trail_s` and not after `time_s`, ending at `now` (the object's sampled
    /// position) so the trail meets its object.
    pub fn trail(&self, slot: u32, time_s: f64, now: [f64; 3], out: &mut Vec<TrailPoint>) {
        out.clear();
        let slot = slot as usize;
        if slot >= self.ids.len() || !self.live[slot] {
            return;
        }
        let n = self.options.trail_points;
        let len = self.trail_lens[slot] as usize;
        let head = self.trail_heads[slot] as usize;
        let oldest = time_s - self.options.trail_s;
        for k in 0..len {
            let p = self.trails[slot * n + (head + n - len + k) % n];
            if p.time_s >= oldest && p.time_s < time_s {
                out.push(p);
            }
        }
        out.push(TrailPoint {
            time_s,
            position: now,
        });
    }
}

#[cfg(test)]
mod tests;
