use super::*;

/// Numbers in 0..1 from a fixed seed.
struct Rng(globus_test_support::SplitMix64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(globus_test_support::SplitMix64(seed))
    }

    fn next(&mut self) -> f32 {
        self.0.unit() as f32
    }
}

const VIEW: [f32; 2] = [1920.0, 1080.0];

fn crowd(n: usize, seed: u64) -> (Vec<LabelRequest>, Vec<[f32; 2]>) {
    let mut rng = Rng::new(seed);
    let mut requests = Vec::new();
    let mut velocities = Vec::new();
    for id in 0..n {
        requests.push(LabelRequest {
            id: id as u64 * 7 + 3,
            anchor_px: [rng.next() * VIEW[0], rng.next() * VIEW[1]],
            clearance_px: 10.0,
            size_px: [48.0 + rng.next() * 24.0, 42.0],
            priority: rng.next(),
        });
        velocities.push([rng.next() * 2.0 - 1.0, rng.next() * 2.0 - 1.0]);
    }
    (requests, velocities)
}

fn assert_no_overlaps(placed: &[PlacedLabel], what: &str) {
    for (i, a) in placed.iter().enumerate() {
        for b in &placed[i + 1..] {
            assert!(
                !overlaps(&a.bounds, &b.bounds),
                "{what}: labels {} and {} overlap: {:?} {:?}",
                a.id,
                b.id,
                a.bounds,
                b.bounds
            );
        }
    }
}

#[test]
fn four_thousand_moving_labels_never_overlap_on_any_frame_even_while_fading() {
    let (mut requests, velocities) = crowd(4000, 1);
    let mut placer = LabelPlacer::new(0.3);
    let mut placed = Vec::new();
    let mut drawn_total = 0;
    for frame in 0..120 {
        placer.place(&requests, &[], VIEW, 1.0 / 30.0, &mut placed);
        assert_no_overlaps(&placed, &format!("frame {frame}"));
        for p in &placed {
            let b = p.bounds;
            assert!(b[0] >= 0.0 && b[1] >= 0.0 && b[2] <= VIEW[0] && b[3] <= VIEW[1]);
            // Each label is at its own anchor: one of the four corners, clear of the symbol.
            let r = &requests[p.request];
            assert_eq!(r.id, p.id);
            assert_eq!(p.corner.place(r.anchor_px, r.clearance_px, r.size_px), b);
        }
        drawn_total += placed.len();
        for (r, v) in requests.iter_mut().zip(&velocities) {
            r.anchor_px[0] += v[0] * 3.0;
            r.anchor_px[1] += v[1] * 3.0;
        }
    }
    // A crowd this dense still shows hundreds of labels.
    assert!(drawn_total / 120 > 200, "{}", drawn_total / 120);
}

#[test]
fn the_highest_priority_label_always_gets_a_place() {
    let (mut requests, _) = crowd(3000, 2);
    requests[1234].priority = 1.0e9;
    requests[1234].anchor_px = [900.0, 500.0];
    let mut placer = LabelPlacer::new(0.3);
    let mut placed = Vec::new();
    for _ in 0..3 {
        placer.place(&requests, &[], VIEW, 1.0 / 30.0, &mut placed);
        assert_eq!(placed.iter().filter(|p| p.request == 1234).count(), 1);
    }
    // Placed first, at its first corner.
    assert_eq!(
        placed.iter().find(|p| p.request == 1234).map(|p| p.corner),
        Some(Corner::NorthEast)
    );
}

#[test]
fn labels_keep_their_corner_while_it_stays_free() {
    let mut placer = LabelPlacer::new(0.3);
    let mut placed = Vec::new();
    let label = |id, x: f32, y: f32, priority| LabelRequest {
        id,
        anchor_px: [x, y],
        clearance_px: 8.0,
        size_px: [50.0, 30.0],
        priority,
    };
    // B (lower priority) sits north-east of A's anchor, so A takes its second corner...
    let mut a = label(1, 500.0, 500.0, 2.0);
    let b = label(2, 540.0, 490.0, 3.0);
    placer.place(&[a, b], &[], VIEW, 0.1, &mut placed);
    let corner_of =
        |placed: &[PlacedLabel], id| placed.iter().find(|p| p.id == id).map(|p| p.corner);
    let first = corner_of(&placed, 1);
    assert_ne!(first, Some(Corner::NorthEast));
    // ... and keeps it when B leaves, although north-east is free again and tried first
    // for new labels.
    for k in 0..10 {
        a.anchor_px[0] += 2.0;
        placer.place(&[a], &[], VIEW, 0.1, &mut placed);
        assert_eq!(corner_of(&placed, 1), first, "frame {k}");
    }
    // Near the right edge the label moves to a corner that fits on screen.
    a.anchor_px = [1900.0, 500.0];
    placer.place(&[a], &[], VIEW, 0.1, &mut placed);
    let c = corner_of(&placed, 1);
    assert!(
        matches!(c, Some(Corner::NorthWest | Corner::SouthWest)),
        "{c:?}"
    );
}

#[test]
fn labels_fade_in_and_out_instead_of_flickering() {
    let mut placer = LabelPlacer::new(0.3);
    let mut placed = Vec::new();
    let small = LabelRequest {
        id: 9,
        anchor_px: [300.0, 300.0],
        clearance_px: 8.0,
        size_px: [40.0, 20.0],
        priority: 1.0,
    };
    let opacity = |placed: &[PlacedLabel], id| {
        placed
            .iter()
            .find(|p| p.id == id)
            .map_or(0.0, |p| p.opacity)
    };
    let mut seen = Vec::new();
    for _ in 0..4 {
        placer.place(&[small], &[], VIEW, 0.1, &mut placed);
        seen.push(opacity(&placed, 9));
    }
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5);
    assert!(close(&seen, &[1.0 / 3.0, 2.0 / 3.0, 1.0, 1.0]), "{seen:?}");
    // A higher-priority label arrives over every corner of the first: the first fades out
    // where it was while the newcomer waits, then the newcomer fades in; never both.
    let big = LabelRequest {
        id: 10,
        anchor_px: [300.0, 300.0],
        clearance_px: -150.0,
        size_px: [300.0, 300.0],
        priority: 5.0,
    };
    let mut both = Vec::new();
    for frame in 0..7 {
        placer.place(&[small, big], &[], VIEW, 0.1, &mut placed);
        assert_no_overlaps(&placed, &format!("frame {frame}"));
        both.push((opacity(&placed, 9), opacity(&placed, 10)));
    }
    let (out, inn): (Vec<f32>, Vec<f32>) = both.into_iter().unzip();
    assert!(
        close(&out, &[2.0 / 3.0, 1.0 / 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        "{out:?}"
    );
    assert!(
        close(&inn, &[0.0, 0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0, 1.0, 1.0]),
        "{inn:?}"
    );
    // A shown label moved under another shown one (all its corners taken) goes at once:
    // fading there would overlap a label that is on screen.
    let elsewhere = LabelRequest {
        id: 11,
        anchor_px: [1500.0, 800.0],
        ..small
    };
    for _ in 0..4 {
        placer.place(&[elsewhere, big], &[], VIEW, 0.1, &mut placed);
    }
    assert!((opacity(&placed, 11) - 1.0).abs() < 1e-5);
    let moved = LabelRequest {
        anchor_px: [300.0, 300.0],
        ..elsewhere
    };
    placer.place(&[moved, big], &[], VIEW, 0.1, &mut placed);
    assert_no_overlaps(&placed, "moved under");
    assert_eq!(opacity(&placed, 11), 0.0);
    assert_eq!(opacity(&placed, 10), 1.0);
}

#[test]
fn labels_keep_off_obstacles() {
    let mut placer = LabelPlacer::new(0.3);
    let mut placed = Vec::new();
    let r = LabelRequest {
        id: 1,
        anchor_px: [500.0, 500.0],
        clearance_px: 8.0,
        size_px: [50.0, 30.0],
        priority: 1.0,
    };
    // Another aircraft's symbol where the north-east box would go.
    let symbol = [520.0, 470.0, 536.0, 486.0];
    placer.place(&[r], &[symbol], VIEW, 0.1, &mut placed);
    assert_eq!(placed.len(), 1);
    assert_ne!(placed[0].corner, Corner::NorthEast);
    assert!(!overlaps(&placed[0].bounds, &symbol));
}

#[test]
fn the_obstacle_table_never_misses_an_overlap_and_refuses_only_near_ones() {
    let mut rng = Rng::new(5);
    let obstacles: Vec<[f32; 4]> = (0..3_000)
        .map(|_| {
            let (x, y) = (rng.next() * VIEW[0], rng.next() * VIEW[1]);
            [
                x,
                y,
                x + 6.0 + rng.next() * 20.0,
                y + 6.0 + rng.next() * 20.0,
            ]
        })
        .collect();
    let mut map = ObstacleMap::default();
    map.build(&obstacles, VIEW);
    assert!(map.dense);
    // Few obstacles take the exact path: no refusals beyond true overlaps.
    let mut few = ObstacleMap::default();
    few.build(&obstacles[..100], VIEW);
    assert!(!few.dense);
    for _ in 0..5_000 {
        let (x, y) = (rng.next() * VIEW[0], rng.next() * VIEW[1]);
        let b = [
            x,
            y,
            x + 10.0 + rng.next() * 60.0,
            y + 10.0 + rng.next() * 40.0,
        ];
        assert_eq!(
            few.meets(&b),
            obstacles[..100].iter().any(|o| overlaps(o, &b))
        );
    }
    let grown = |b: &[f32; 4], by: f32| [b[0] - by, b[1] - by, b[2] + by, b[3] + by];
    for _ in 0..20_000 {
        let (x, y) = (rng.next() * VIEW[0], rng.next() * VIEW[1]);
        let b = [
            x,
            y,
            x + 10.0 + rng.next() * 60.0,
            y + 10.0 + rng.next() * 40.0,
        ];
        let truly = obstacles.iter().any(|o| overlaps(o, &b));
        let near = obstacles
            .iter()
            .any(|o| overlaps(&grown(o, OBSTACLE_CELL_PX), &b));
        let meets = map.meets(&b);
        assert!(!truly || meets, "missed an obstacle under {b:?}");
        assert!(
            !meets || near,
            "refused {b:?} with no obstacle within a cell"
        );
    }
}
