use super::*;

fn sample(id: u64, t: f64, lon: f64, lat: f64, alt: f64, heading: f32) -> Sample {
    Sample {
        id,
        time_s: t,
        position: [lon, lat, alt],
        attitude_deg: [heading, 0.0, 0.0],
        kind: 1,
        colour: [255, 255, 255, 255],
        flags: 0,
        speeds: [200.0, 0.0],
        callsign: callsign_bytes("SWR12"),
    }
}

fn batch(samples: &[Sample], removed: &[u64]) -> Batch {
    let mut b = Batch::default();
    for s in samples {
        b.push(*s);
    }
    b.removed.extend_from_slice(removed);
    b
}

#[test]
fn positions_between_samples_are_interpolated_and_past_them_extrapolated_for_a_while() {
    let mut fleet = Fleet::new(FleetOptions::default());
    fleet
        .apply(&batch(&[sample(1, 100.0, 7.0, 46.0, 10_000.0, 80.0)], &[]))
        .expect("apply");
    fleet
        .apply(&batch(&[sample(1, 110.0, 7.1, 46.2, 10_100.0, 100.0)], &[]))
        .expect("apply");
    let at = |t| fleet.state_of(1, t).expect("live");
    let (p, a) = at(104.0);
    assert!((p[0] - 7.04).abs() < 1e-12 && (p[1] - 46.08).abs() < 1e-12);
    assert!((p[2] - 10_040.0).abs() < 1e-9 && (a[0] - 88.0).abs() < 1e-4);
    // At the samples exactly.
    assert_eq!(at(110.0).0, [7.1, 46.2, 10_100.0]);
    assert_eq!(at(90.0).0, [7.0, 46.0, 10_000.0]);
    // On at the last velocity for 20 s, then waiting and stale.
    let (p, _) = at(115.0);
    assert!((p[0] - 7.15).abs() < 1e-12 && (p[1] - 46.3).abs() < 1e-12);
    let mut out = Sampled::default();
    fleet.sample(125.0, &mut out);
    assert_eq!(out.flags[0] & flags::STALE, 0);
    fleet.sample(200.0, &mut out);
    assert!((out.positions[0][0] - 7.3).abs() < 1e-12);
    assert_ne!(out.flags[0] & flags::STALE, 0);
}

#[test]
fn the_antimeridian_and_north_are_crossed_the_short_way() {
    let mut fleet = Fleet::new(FleetOptions::default());
    let a = sample(9, 0.0, 179.9, 10.0, 0.0, 350.0);
    let b = sample(9, 10.0, -179.9, 10.0, 0.0, 10.0);
    fleet.apply(&batch(&[a, b], &[])).expect("apply");
    let (p, att) = fleet.state_of(9, 7.5).expect("live");
    assert!((p[0] - -179.95).abs() < 1e-9, "{p:?}");
    assert!((att[0] - 5.0).abs() < 1e-4, "{att:?}");
    let (p, att) = fleet.state_of(9, 2.5).expect("live");
    assert!((p[0] - 179.95).abs() < 1e-9 && (att[0] - 355.0).abs() < 1e-4);
}

#[test]
fn adds_updates_and_removals_are_counted_and_slots_reused() {
    let mut fleet = Fleet::new(FleetOptions::default());
    let b = batch(
        &[
            sample(1, 0.0, 0.0, 0.0, 0.0, 0.0),
            sample(2, 0.0, 1.0, 0.0, 0.0, 0.0),
            sample(1, 10.0, 0.1, 0.0, 0.0, 0.0),
            sample(1, 5.0, 0.1, 0.0, 0.0, 0.0),
            sample(3, 0.0, f64::NAN, 0.0, 0.0, 0.0),
            sample(4, 0.0, 0.0, 95.0, 0.0, 0.0),
        ],
        &[2, 77],
    );
    fleet.apply(&b).expect("apply");
    let c = fleet.counts();
    assert_eq!(
        (
            c.added,
            c.updated,
            c.removed,
            c.unknown_removals,
            c.out_of_order,
            c.invalid
        ),
        (2, 1, 1, 1, 1, 2)
    );
    assert_eq!(fleet.len(), 1);
    assert!(fleet.contains(1) && !fleet.contains(2) && !fleet.contains(3));
    // The freed slot is reused and starts a fresh trail.
    let before = fleet.heap_bytes();
    fleet
        .apply(&batch(&[sample(5, 20.0, 2.0, 0.0, 0.0, 0.0)], &[]))
        .expect("apply");
    assert_eq!(fleet.heap_bytes(), before);
    let mut out = Sampled::default();
    fleet.sample(20.0, &mut out);
    assert_eq!(out.ids, [1, 5]);
    assert_eq!(out.slots[1], 1);
    let mut trail = Vec::new();
    fleet.trail(out.slots[1], 20.0, out.positions[1], &mut trail);
    assert_eq!(trail.len(), 1);
    // Columns of different lengths are one error, and change nothing.
    let mut bad = batch(&[sample(6, 0.0, 0.0, 0.0, 0.0, 0.0)], &[]);
    bad.kinds.clear();
    assert!(matches!(
        fleet.apply(&bad),
        Err(FleetError::ColumnLengths { ids: 1, .. })
    ));
    assert!(!fleet.contains(6));
}

#[test]
fn trails_keep_the_newest_points_younger_than_their_age_and_end_at_the_object() {
    let options = FleetOptions {
        trail_points: 8,
        trail_s: 50.0,
        ..FleetOptions::default()
    };
    let mut fleet = Fleet::new(options);
    for k in 0..20 {
        let t = f64::from(k) * 10.0;
        fleet
            .apply(&batch(&[sample(1, t, t / 1000.0, 0.0, 0.0, 0.0)], &[]))
            .expect("apply");
    }
    let mut out = Sampled::default();
    fleet.sample(195.0, &mut out);
    let mut trail = Vec::new();
    fleet.trail(out.slots[0], 195.0, out.positions[0], &mut trail);
    let times: Vec<f64> = trail.iter().map(|p| p.time_s).collect();
    // 150..190 are younger than 50 s; the last point is the object itself at 195.
    assert_eq!(times, [150.0, 160.0, 170.0, 180.0, 190.0, 195.0]);
    assert!((trail[5].position[0] - 0.195).abs() < 1e-12);
    // With a long age, only the ring's 8 newest samples remain.
    let mut long = Fleet::new(FleetOptions {
        trail_s: 1e9,
        ..options
    });
    for k in 0..20 {
        let t = f64::from(k) * 10.0;
        long.apply(&batch(&[sample(1, t, 0.0, 0.0, 0.0, 0.0)], &[]))
            .expect("apply");
    }
    long.trail(0, 195.0, [0.0; 3], &mut trail);
    assert_eq!(trail.len(), 9);
    assert_eq!(trail[0].time_s, 120.0);
}

#[test]
fn selection_is_a_flag_that_survives_updates() {
    let mut fleet = Fleet::new(FleetOptions::default());
    fleet
        .apply(&batch(&[sample(1, 0.0, 0.0, 0.0, 0.0, 0.0)], &[]))
        .expect("apply");
    assert!(fleet.set_selected(1, true));
    assert!(!fleet.set_selected(2, true));
    let mut out = Sampled::default();
    fleet.sample(0.0, &mut out);
    assert_ne!(out.flags[0] & flags::SELECTED, 0);
    // A later sample (whose flags know nothing of the selection) keeps it.
    fleet
        .apply(&batch(&[sample(1, 10.0, 0.1, 0.0, 0.0, 0.0)], &[]))
        .expect("apply");
    fleet.sample(10.0, &mut out);
    assert_ne!(out.flags[0] & flags::SELECTED, 0);
    // A new object in the freed slot starts unselected.
    fleet.remove(1);
    fleet
        .apply(&batch(&[sample(2, 10.0, 0.1, 0.0, 0.0, 0.0)], &[]))
        .expect("apply");
    fleet.sample(10.0, &mut out);
    assert_eq!(out.flags[0] & flags::SELECTED, 0);
    assert_eq!(
        (fleet.slot_of(2), fleet.id_in_slot(0), fleet.id_in_slot(1)),
        (Some(0), Some(2), None)
    );
}
