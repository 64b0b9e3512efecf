//! Replaying a [`Record`]: the clock moves, and each step yields the [`Batch`] of reports that
//! became due, for a [`crate::Fleet`] to interpolate between.
//!
//! A fleet interpolates between an object's last two samples, so a replay keeps every flight
//! one report *ahead* of the clock: once the clock reaches a report's time, the next report
//! is handed over too. At any moment `t` the fleet then holds the two reports around `t`
//! (`t_k <= t < t_(k+1)`) and draws the aircraft exactly where straight-line interpolation of
//! the record puts it, at any frame rate and speed. A flight appears at its first report
//! and is removed [`ReplayOptions::linger_s`] after its last.
//!
//! Flights wait in a min-heap keyed by the moment they next need a report, so a step costs
//! O(reports handed over · log flights), not O(flights). Moving the clock backwards, or
//! forwards by more than [`ReplayOptions::jump_s`], is a *seek*: the fleet is to be emptied
//! and refilled with each flight's reports of the last trail length around the new moment
//! ([`Step::Reset`]).
//!
//! Each flight is its own object: its id is `track index << 24 | icao24`
//! ([`Replay::icao24_of`] gives the address back), so an aircraft flying twice in one record
//! (two tracks) never has one flight's removal end the other.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::fleet::{Batch, Sample, callsign_bytes, flags};
use crate::kind::AircraftKind;
use crate::record::{Record, Report, Track};

/// How a replay hands reports over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayOptions {
    /// How long an aircraft stays after its last report, seconds.
    pub linger_s: f64,
    /// How far back a seek hands reports over (the trail length drawn), seconds.
    pub history_s: f64,
    /// A forward step longer than this is a seek, seconds.
    pub jump_s: f64,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        Self {
            linger_s: 10.0,
            history_s: 600.0,
            jump_s: 600.0,
        }
    }
}

/// What a step of the clock did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// The batch holds the reports that became due: apply it to the fleet as it is.
    Advance,
    /// The clock jumped: empty the fleet, then apply the batch (every flight's state at the
    /// new moment, with its recent history for the trail).
    Reset,
}

/// Heap entry: a flight needing attention at a moment (a min-heap through reversed order).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Due {
    at_s: f64,
    track: u32,
}

impl Eq for Due {}

impl Ord for Due {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .at_s
            .total_cmp(&self.at_s)
            .then(other.track.cmp(&self.track))
    }
}

impl PartialOrd for Due {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// A record played against a clock; see the module documentation.
#[derive(Clone, Debug)]
pub struct Replay {
    record: Record,
    options: ReplayOptions,
    /// Track indices by first report time.
    starts: Vec<u32>,
    /// Per track: the next report not yet handed over (`u32::MAX`: not started, or removed).
    next: Vec<u32>,
    /// Per track: whether it is in the fleet.
    live: Vec<bool>,
    /// Tracks not yet started are `starts[next_start..]`.
    next_start: usize,
    due: BinaryHeap<Due>,
    time_s: f64,
    /// Per track: its kind and call sign as the fleet takes them.
    kinds: Vec<u8>,
    callsigns: Vec<[u8; crate::fleet::CALLSIGN_BYTES]>,
}

const NOT_STARTED: u32 = u32::MAX;

impl Replay {
    /// A replay of `record`, its clock before the first report.
    pub fn new(record: Record, options: ReplayOptions) -> Self {
        let mut starts: Vec<u32> = (0..record.tracks.len() as u32)
            .filter(|&i| !record.tracks[i as usize].reports.is_empty())
            .collect();
        starts.sort_by(|&a, &b| {
            first_time(&record.tracks[a as usize])
                .total_cmp(&first_time(&record.tracks[b as usize]))
                .then(a.cmp(&b))
        });
        let kinds = record
            .tracks
            .iter()
            .map(|t| AircraftKind::from_typecode(&t.typecode).index())
            .collect();
        let callsigns = record
            .tracks
            .iter()
            .map(|t| callsign_bytes(&t.callsign))
            .collect();
        let n = record.tracks.len();
        Self {
            record,
            options,
            starts,
            next: vec![NOT_STARTED; n],
            live: vec![false; n],
            next_start: 0,
            due: BinaryHeap::new(),
            time_s: f64::NEG_INFINITY,
            kinds,
            callsigns,
        }
    }

    /// The record played.
    pub fn record(&self) -> &Record {
        &self.record
    }

    /// The options.
    pub fn options(&self) -> &ReplayOptions {
        &self.options
    }

    /// The moment the clock was last moved to (negative infinity before the first step).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Flights in the fleet now.
    pub fn live_flights(&self) -> usize {
        self.live.iter().filter(|&&l| l).count()
    }

    /// The object id of a track (see the module documentation).
    pub fn id_of(track: usize, icao24: u32) -> u64 {
        ((track as u64) << 24) | u64::from(icao24 & 0xff_ffff)
    }

    /// The ICAO address of an object id made by a replay.
    pub fn icao24_of(id: u64) -> u32 {
        (id & 0xff_ffff) as u32
    }

    /// The track of an object id made by a replay, if it is one of this record's.
    pub fn track_of(&self, id: u64) -> Option<&Track> {
        let track = self.record.tracks.get((id >> 24) as usize)?;
        (track.icao24 == Self::icao24_of(id)).then_some(track)
    }

    /// Moves the clock to `time_s`, writing into `batch` (cleared first) what the fleet must
    /// be told; see [`Step`].
    pub fn advance_to(&mut self, time_s: f64, batch: &mut Batch) -> Step {
        batch.clear();
        if !time_s.is_finite() {
            return Step::Advance;
        }
        let forward = time_s - self.time_s;
        if self.time_s.is_finite() && (0.0..=self.options.jump_s).contains(&forward) {
            self.step(time_s, batch);
            Step::Advance
        } else {
            self.seek(time_s, batch);
            Step::Reset
        }
    }

    fn step(&mut self, t: f64, batch: &mut Batch) {
        self.time_s = t;
        while let Some(&track) = self.starts.get(self.next_start) {
            if first_time(&self.record.tracks[track as usize]) > t {
                break;
            }
            self.next_start += 1;
            self.next[track as usize] = 0;
            self.live[track as usize] = true;
            self.hand_over(track as usize, t, batch);
        }
        while let Some(&top) = self.due.peek() {
            if top.at_s > t {
                break;
            }
            self.due.pop();
            let track = top.track as usize;
            if self.next[track] as usize >= self.record.tracks[track].reports.len() {
                // Past its last report and the linger: gone.
                let t = &self.record.tracks[track];
                batch.removed.push(Self::id_of(track, t.icao24));
                self.live[track] = false;
                self.next[track] = NOT_STARTED;
            } else {
                self.hand_over(track, t, batch);
            }
        }
    }

    /// Hands over the track's reports up to and including the first after `t`, and queues it
    /// for when that one is reached (or for its removal).
    fn hand_over(&mut self, track: usize, t: f64, batch: &mut Batch) {
        let reports = &self.record.tracks[track].reports;
        let mut k = self.next[track] as usize;
        while k < reports.len() {
            self.push_report(track, k, batch);
            k += 1;
            if reports[k - 1].time_s > t {
                break;
            }
        }
        self.next[track] = k as u32;
        let last = &reports[k - 1];
        let at_s = if k < reports.len() {
            last.time_s
        } else {
            last.time_s + self.options.linger_s
        };
        self.due.push(Due {
            at_s,
            track: track as u32,
        });
    }

    fn seek(&mut self, t: f64, batch: &mut Batch) {
        self.time_s = t;
        self.due.clear();
        self.next.fill(NOT_STARTED);
        self.live.fill(false);
        self.next_start = self
            .starts
            .partition_point(|&i| first_time(&self.record.tracks[i as usize]) <= t);
        for &track in &self.starts[..self.next_start] {
            let reports = &self.record.tracks[track as usize].reports;
            let Some(last) = reports.last() else { continue };
            if last.time_s + self.options.linger_s < t {
                continue;
            }
            let from = reports.partition_point(|r| r.time_s < t - self.options.history_s);
            // At least the report before `t`, so the fleet can interpolate.
            let before = reports.partition_point(|r| r.time_s <= t).saturating_sub(1);
            self.next[track as usize] = from.min(before) as u32;
            self.live[track as usize] = true;
        }
        let live: Vec<usize> = (0..self.live.len()).filter(|&i| self.live[i]).collect();
        for track in live {
            self.hand_over(track, t, batch);
        }
    }

    fn push_report(&self, track: usize, k: usize, batch: &mut Batch) {
        let tr = &self.record.tracks[track];
        let r = &tr.reports[k];
        let heading = if r.heading_deg.is_finite() {
            r.heading_deg
        } else {
            track_bearing_deg(&tr.reports, k)
        };
        let pitch = if r.vertical_rate_mps.is_finite() && r.velocity_mps > 1.0 {
            r.vertical_rate_mps.atan2(r.velocity_mps).to_degrees()
        } else {
            0.0
        };
        let altitude = if r.altitude_m.is_finite() {
            r.altitude_m
        } else {
            0.0
        };
        batch.push(Sample {
            id: Self::id_of(track, tr.icao24),
            time_s: r.time_s,
            position: [r.lon_deg, r.lat_deg, altitude],
            attitude_deg: [heading, pitch, 0.0],
            kind: self.kinds[track],
            colour: altitude_colour(if r.on_ground { 0.0 } else { altitude }),
            flags: if r.on_ground || !r.altitude_m.is_finite() {
                flags::ON_GROUND
            } else {
                0
            },
            speeds: [r.velocity_mps, r.vertical_rate_mps],
            callsign: self.callsigns[track],
        });
    }
}

fn first_time(track: &Track) -> f64 {
    track.reports.first().map_or(f64::INFINITY, |r| r.time_s)
}

/// The direction of travel at report `k` from its neighbours (degrees clockwise from north;
/// 0 when the flight does not move).
fn track_bearing_deg(reports: &[Report], k: usize) -> f32 {
    let a = &reports[k.saturating_sub(1)];
    let b = &reports[(k + 1).min(reports.len() - 1)];
    let (lat_a, lat_b) = (a.lat_deg.to_radians(), b.lat_deg.to_radians());
    let dlon = ((b.lon_deg - a.lon_deg + 540.0).rem_euclid(360.0) - 180.0).to_radians();
    let y = dlon.sin() * lat_b.cos();
    let x = lat_a.cos() * lat_b.sin() - lat_a.sin() * lat_b.cos() * dlon.cos();
    if x == 0.0 && y == 0.0 {
        return 0.0;
    }
    y.atan2(x).to_degrees().rem_euclid(360.0) as f32
}

/// The colour of an aircraft at an altitude: the altitude ramp radar and flight-tracking
/// displays use (orange on the ground and low, through green and cyan, to blue and violet at
/// cruise above 12 km), sRGB.
pub fn altitude_colour(altitude_m: f64) -> [u8; 4] {
    const RAMP: [(f64, [f64; 3]); 6] = [
        (0.0, [255.0, 140.0, 0.0]),
        (1_500.0, [230.0, 220.0, 40.0]),
        (4_000.0, [60.0, 220.0, 90.0]),
        (7_000.0, [40.0, 210.0, 230.0]),
        (10_000.0, [70.0, 120.0, 255.0]),
        (12_500.0, [190.0, 90.0, 255.0]),
    ];
    let a = if altitude_m.is_finite() {
        altitude_m
    } else {
        0.0
    };
    let mut rgb = RAMP[RAMP.len() - 1].1;
    for w in RAMP.windows(2) {
        let ((a0, c0), (a1, c1)) = (w[0], w[1]);
        if a <= a0 {
            rgb = c0;
            break;
        }
        if a <= a1 {
            let f = (a - a0) / (a1 - a0);
            rgb = [0, 1, 2].map(|i| c0[i] + (c1[i] - c0[i]) * f);
            break;
        }
    }
    [rgb[0] as u8, rgb[1] as u8, rgb[2] as u8, 255]
}

#[cfg(test)]
mod tests;
