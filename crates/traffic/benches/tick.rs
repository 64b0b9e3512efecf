//! What a simulation tick costs on the CPU: a batch of 4,000 aircraft applied to a fleet
//! that holds them (all update, as when every aircraft reports at once), sampling the whole
//! fleet at a moment (what a frame does), and a replay handing 4,000 reports over.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use globus_traffic::fleet::callsign_bytes;
use globus_traffic::record::{Record, Report, Track};
use globus_traffic::{Batch, Fleet, FleetOptions, Replay, ReplayOptions, Sample, Sampled};

const AIRCRAFT: u64 = 4_000;

fn batch_at(t: f64) -> Batch {
    let mut b = Batch::default();
    for id in 0..AIRCRAFT {
        let k = id as f64;
        b.push(Sample {
            id,
            time_s: t,
            position: [
                -10.0 + (k * 0.37) % 40.0 + t * 1e-4,
                36.0 + (k * 0.11) % 24.0,
                11_000.0,
            ],
            attitude_deg: [(k * 7.0) as f32 % 360.0, 0.0, 0.0],
            kind: 1,
            colour: [255, 255, 255, 255],
            flags: 0,
            speeds: [230.0, 0.0],
            callsign: callsign_bytes("ABC123"),
        });
    }
    b
}

fn tick(c: &mut Criterion) {
    let mut fleet = Fleet::new(FleetOptions::default());
    fleet.apply(&batch_at(0.0)).expect("apply");
    let batches: Vec<Batch> = (1..=64).map(|k| batch_at(f64::from(k) * 10.0)).collect();
    let mut k = 0;
    c.bench_function("apply 4000 updates", |b| {
        b.iter(|| {
            k = (k + 1) % batches.len();
            fleet.apply(black_box(&batches[k])).expect("apply");
        })
    });
    let mut sampled = Sampled::default();
    c.bench_function("sample 4000 aircraft", |b| {
        b.iter(|| fleet.sample(black_box(645.0), &mut sampled))
    });
    // A record of 4,000 flights reporting together every 10 s.
    let tracks = (0..AIRCRAFT as u32)
        .map(|i| Track {
            icao24: i,
            callsign: format!("T{i}"),
            typecode: "A320".into(),
            reports: (0..400)
                .map(|k| Report {
                    time_s: f64::from(k) * 10.0,
                    lat_deg: 40.0 + f64::from(i % 100) * 0.1,
                    lon_deg: f64::from(i / 100) * 0.1 + f64::from(k) * 0.01,
                    altitude_m: 11_000.0,
                    velocity_mps: 230.0,
                    heading_deg: 90.0,
                    vertical_rate_mps: 0.0,
                    on_ground: false,
                })
                .collect(),
        })
        .collect();
    let record = Record {
        tracks,
        skipped: Vec::new(),
        rows: 0,
    };
    let mut replay = Replay::new(record, ReplayOptions::default());
    let mut batch = Batch::default();
    replay.advance_to(5.0, &mut batch);
    let mut t = 5.0;
    c.bench_function("replay hands over 4000 reports", |b| {
        b.iter(|| {
            // Every step crosses one report time of every flight.
            t += 10.0;
            if t > 3_900.0 {
                t = 5.0;
                replay.advance_to(t, &mut batch);
                t += 10.0;
            }
            replay.advance_to(black_box(t), &mut batch);
            assert_eq!(batch.len(), AIRCRAFT as usize);
        })
    });
}

criterion_group!(benches, tick);
criterion_main!(benches);
