//! The traffic layer on lavapipe, pictures checked against the CPU's projection of where the
//! samples put each aircraft: symbols at the interpolated moment within a pixel, from orbit
//! and close in; picking returns the aircraft; aircraft behind the planet are not drawn;
//! trails follow the flown path and fade with age; a close view draws the lit model.

mod common;

use std::time::Duration;

use globus_engine::traffic::{AircraftKind, Batch, Sample, callsign_bytes};
use globus_engine::{
    Cartographic, DVec2, DVec3, Globe, Headless, RgbaImage, StyleRules, TrafficLayer, VectorLayer,
    View, save_png,
};

const TIMEOUT: Duration = Duration::from_secs(300);
const MAGENTA: [u8; 4] = [255, 0, 255, 255];
const CYAN: [u8; 4] = [0, 255, 255, 255];

fn sample(id: u64, t: f64, lon: f64, lat: f64, alt: f64, heading: f32, colour: [u8; 4]) -> Sample {
    Sample {
        id,
        time_s: t,
        position: [lon, lat, alt],
        attitude_deg: [heading, 0.0, 0.0],
        kind: AircraftKind::NarrowBody.index(),
        colour,
        flags: 0,
        speeds: [230.0, 0.0],
        callsign: callsign_bytes("TEST1"),
    }
}

fn render(off: &mut Headless, view: &View, layer: &mut TrafficLayer, name: &str) -> RgbaImage {
    let frame = off
        .render_complete(view, TIMEOUT, &mut [layer])
        .expect("render");
    let dir = globus_test_support::output_dir("traffic");
    save_png(&frame.image, &dir.join(format!("{name}.png"))).expect("save");
    frame.image
}

fn close(p: [u8; 4], c: [u8; 4]) -> bool {
    (0..3).all(|k| (i32::from(p[k]) - i32::from(c[k])).abs() < 40)
}

/// Pixels of `colour` within `radius` of `around`.
fn pixels_of(img: &RgbaImage, colour: [u8; 4], around: DVec2, radius: f64) -> Vec<DVec2> {
    let mut out = Vec::new();
    let (x0, x1) = (
        (around.x - radius).max(0.0) as u32,
        (around.x + radius).min(f64::from(img.width) - 1.0) as u32,
    );
    let (y0, y1) = (
        (around.y - radius).max(0.0) as u32,
        (around.y + radius).min(f64::from(img.height) - 1.0) as u32,
    );
    for y in y0..=y1 {
        for x in x0..=x1 {
            if close(img.get(x, y), colour) {
                out.push(DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
            }
        }
    }
    out
}

fn project(globe: &Globe, lon: f64, lat: f64, alt: f64) -> DVec2 {
    let world = globe.world_position(Cartographic::from_degrees(lon, lat, alt));
    globe
        .camera()
        .and_then(|c| c.project(world))
        .expect("in front of the camera")
}

/// A north-bound symbol is symmetric about the line through its centre along the heading,
/// and reaches as far ahead as behind: its centre from its pixels.
fn symbol_centre(px: &[DVec2]) -> DVec2 {
    let n = px.len() as f64;
    let x = px.iter().map(|p| p.x).sum::<f64>() / n;
    let (lo, hi) = px
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.y), hi.max(p.y))
        });
    DVec2::new(x, (lo + hi) * 0.5)
}

#[test]
fn aircraft_are_drawn_where_their_samples_put_them_within_a_pixel_from_orbit_and_close_in() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    // Straight down from 2,000 km, from 60 km, and from 25 km above the aircraft's level;
    // then the orthographic top-down camera showing 150 km and 20 km.
    for (alt, ortho_m, name) in [
        (2.0e6, None, "orbit"),
        (60_000.0, None, "high"),
        (35_000.0, None, "close"),
        (0.0, Some(150_000.0), "ortho-150km"),
        (0.0, Some(20_000.0), "ortho-20km"),
    ] {
        // Two aircraft heading north at FL330, a fifth of the view's width either side of
        // its centre, sampled 10 s apart; drawn 3.7 s after the first sample.
        let dlon = match ortho_m {
            // 4:3, at 40 degrees north.
            Some(m) => 0.2 * m * 4.0 / 3.0 / (111_320.0 * 40f64.to_radians().cos()),
            None => 0.2 * (alt - 10_000.0) / 85_000.0,
        };
        let (lon_a, lon_b) = (-29.75 - dlon, -29.75 + dlon);
        let dlat = dlon * 0.05;
        let mut layer = TrafficLayer::new();
        let mut batch = Batch::default();
        batch.push(sample(1, 100.0, lon_a, 40.0, 10_000.0, 0.0, MAGENTA));
        batch.push(sample(2, 100.0, lon_b, 40.0, 10_000.0, 0.0, CYAN));
        batch.push(sample(1, 110.0, lon_a, 40.0 + dlat, 10_100.0, 0.0, MAGENTA));
        batch.push(sample(2, 110.0, lon_b, 40.0 + dlat, 10_000.0, 0.0, CYAN));
        layer.apply(&batch).expect("apply");
        layer.set_time(103.7);
        let lat = 40.0 + dlat * 0.37;
        let alt_a = 10_000.0 + 100.0 * 0.37;
        let spec = common::camera(-29.75, 40.0, alt, 0.0, -90.0, false);
        let view = match ortho_m {
            Some(m) => spec.orthographic_view(off.globe(), m, 60.0, w, h),
            None => spec.view(off.globe(), 60.0, w, h),
        };
        let img = render(&mut off, &view, &mut layer, &format!("fidelity-{name}"));
        for (colour, lon, alt_m) in [(MAGENTA, lon_a, alt_a), (CYAN, lon_b, 10_000.0)] {
            let want = project(off.globe(), lon, lat, alt_m);
            let px = pixels_of(&img, colour, want, 20.0);
            assert!(
                px.len() > 20,
                "{name}: {} pixels of {colour:?} near {want:?}",
                px.len()
            );
            let got = symbol_centre(&px);
            assert!(
                (got - want).length() < 1.0,
                "{name}: {colour:?} drawn at {got:?}, samples say {want:?}"
            );
        }
        // Picking at the projected centre finds each aircraft.
        for (id, lon, alt_m) in [(1, lon_a, alt_a), (2, lon_b, 10_000.0)] {
            let at = project(off.globe(), lon, lat, alt_m);
            let pick = off.globe().pick(at.x, at.y).expect("pick").expect("inside");
            let object = pick.object().expect("an object at the aircraft");
            assert_eq!(layer.aircraft_for_pick(object), Some(id), "{name}");
        }
        assert_eq!(layer.stats().aircraft, 2);
        // Trails, symbols, label leaders and glyphs: a draw call each here.
        assert!(layer.stats().draw_calls <= 4, "{:?}", layer.stats());
    }
}

#[test]
fn aircraft_behind_the_planet_are_not_drawn() {
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let mut layer = TrafficLayer::new();
    let mut batch = Batch::default();
    // One over the point below the camera, one on the far side (behind the globe's disc).
    batch.push(sample(1, 0.0, 10.0, 0.0, 11_000.0, 90.0, MAGENTA));
    batch.push(sample(2, 0.0, 10.0, 40.0, 11_000.0, 90.0, CYAN));
    batch.push(sample(3, 0.0, -170.0, 0.0, 11_000.0, 90.0, CYAN));
    layer.apply(&batch).expect("apply");
    layer.set_time(0.0);
    let view = common::camera(10.0, 0.0, 2.0e7, 0.0, -90.0, false).view(off.globe(), 40.0, w, h);
    let img = render(&mut off, &view, &mut layer, "far-side");
    let centre = DVec2::new(f64::from(w) / 2.0, f64::from(h) / 2.0);
    assert!(pixels_of(&img, MAGENTA, centre, 15.0).len() > 10);
    // The far one projects onto the disc too, near its centre, but the planet hides it: the
    // only cyan is the one at 40 N.
    let far = project(off.globe(), -170.0, 0.0, 11_000.0);
    assert!((far - centre).length() < 5.0, "{far:?}");
    assert!(
        pixels_of(&img, CYAN, far, 12.0).is_empty(),
        "the far side's aircraft shows"
    );
    let north = project(off.globe(), 10.0, 40.0, 11_000.0);
    assert!(pixels_of(&img, CYAN, north, 12.0).len() > 10);
}

#[test]
fn trails_follow_the_flown_path_and_fade_with_age() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let mut layer = TrafficLayer::new();
    // Eastbound along 20 N for ten minutes, a report every 10 s.
    for k in 0..=60 {
        let t = f64::from(k) * 10.0;
        let mut batch = Batch::default();
        batch.push(sample(
            7,
            t,
            -40.0 + t * 0.002,
            20.0,
            11_000.0,
            90.0,
            MAGENTA,
        ));
        layer.apply(&batch).expect("apply");
    }
    layer.set_time(600.0);
    let view =
        common::camera(-39.4, 20.0, 400_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let plain = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let img = render(&mut off, &view, &mut layer, "trail");
    // How much each point of the path changed towards magenta, from old to new.
    let mut strengths = Vec::new();
    for k in [2, 10, 20, 30, 40, 50] {
        let t = f64::from(k) * 10.0;
        let at = project(off.globe(), -40.0 + t * 0.002, 20.0, 11_000.0);
        let (x, y) = (at.x as u32, at.y as u32);
        let best = (y.saturating_sub(1)..=y + 1)
            .map(|yy| {
                let (p, b) = (img.get(x, yy), plain.get(x, yy));
                // Towards magenta: red and blue up, green down.
                (i32::from(p[0]) - i32::from(b[0])) + (i32::from(p[2]) - i32::from(b[2]))
                    - (i32::from(p[1]) - i32::from(b[1]))
            })
            .max()
            .unwrap_or(0);
        strengths.push(best);
    }
    assert!(
        strengths.iter().all(|&s| s > 20),
        "the trail is missing somewhere: {strengths:?}"
    );
    assert!(
        strengths.windows(2).all(|w| w[1] >= w[0] - 8) && strengths[5] > strengths[0] + 40,
        "the trail does not fade with age: {strengths:?}"
    );
    // Off the path, nothing changed.
    let off_path = project(off.globe(), -39.7, 20.3, 11_000.0);
    let (p, b) = (
        img.get(off_path.x as u32, off_path.y as u32),
        plain.get(off_path.x as u32, off_path.y as u32),
    );
    assert_eq!(p, b);
}

#[test]
fn a_close_view_draws_the_lit_model_and_a_far_one_the_symbol() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let mut layer = TrafficLayer::new();
    let mut batch = Batch::default();
    batch.push(sample(5, 0.0, 8.0, 46.0, 9_500.0, 45.0, MAGENTA));
    layer.apply(&batch).expect("apply");
    layer.set_time(0.0);
    // 120 m above and behind the aircraft, looking down at it.
    let globe = off.globe();
    let at = globe.world_position(Cartographic::from_degrees(8.0, 46.0, 9_500.0));
    let enu = globe
        .ellipsoid()
        .enu_frame(8f64.to_radians(), 46f64.to_radians());
    let behind = -(enu.north + enu.east).normalize();
    let eye = at + behind * 90.0 + enu.up * 60.0;
    let view = View::look_at(eye, at, enu.up, 50f64.to_radians(), w, h).expect("view");
    let img = render(&mut off, &view, &mut layer, "model-close");
    assert!(layer.stats().models == 1, "{:?}", layer.stats());
    let centre = off
        .globe()
        .camera()
        .and_then(|c| c.project(at))
        .expect("in view");
    // The model covers its centre (its id is there) with shaded grey, not the symbol's magenta.
    let pick = off
        .globe()
        .pick(centre.x, centre.y)
        .expect("pick")
        .expect("inside");
    assert_eq!(
        pick.object().and_then(|o| layer.aircraft_for_pick(o)),
        Some(5)
    );
    let p = img.get(centre.x as u32, centre.y as u32);
    assert!(!close(p, MAGENTA), "the symbol shows close in: {p:?}");
    // Lit: the model's pixels (where the picture differs from the plain ground) are shaded,
    // faces turned to the sun brighter than those turned away, and it fills a good part of
    // the view (90 m from a 37.6 m aircraft).
    let plain = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let mut lum = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (p, b) = (img.get(x, y), plain.get(x, y));
            if (0..3).any(|k| (i32::from(p[k]) - i32::from(b[k])).abs() > 24) {
                lum.push(i32::from(p[0]) + i32::from(p[1]) + i32::from(p[2]));
            }
        }
    }
    lum.sort_unstable();
    let share = lum.len() as f64 / f64::from(w * h);
    assert!(share > 0.005 && share < 0.6, "model covers {share}");
    let (dark, bright) = (lum[lum.len() / 10], lum[lum.len() * 9 / 10]);
    assert!(bright - dark > 60, "flat shading: {dark}..{bright}");
    // The orthographic top-down camera showing 150 m: the model in plan view at the
    // projection's scale, 37.6 m nose to tail (2.4 px a metre: 90 px), about its centre.
    let top = common::camera(8.0, 46.0, 0.0, 0.0, -90.0, false).orthographic_view(
        off.globe(),
        150.0,
        60.0,
        w,
        h,
    );
    // (Without its label, which would count as model.)
    let mut style = layer.style().clone();
    style.labels = false;
    layer.set_style(style);
    let img = render(&mut off, &top, &mut layer, "model-ortho");
    assert_eq!(layer.stats().models, 1, "{:?}", layer.stats());
    let plain = off
        .render_complete(&top, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let mut changed = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (p, b) = (img.get(x, y), plain.get(x, y));
            if (0..3).any(|k| (i32::from(p[k]) - i32::from(b[k])).abs() > 24) {
                changed.push(DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
            }
        }
    }
    assert!(changed.len() > 500, "{} pixels of model", changed.len());
    let span = changed
        .iter()
        .flat_map(|a| changed.iter().map(move |b| (*a - *b).length()))
        .fold(0.0, f64::max);
    let want = 37.6 * f64::from(h) / 150.0;
    assert!(
        (span / want - 1.0).abs() < 0.12,
        "{span} px across, {want} expected"
    );
    let c = project(off.globe(), 8.0, 46.0, 9_500.0);
    let mean = changed.iter().copied().sum::<DVec2>() / changed.len() as f64;
    assert!(
        (mean - c).length() < 6.0,
        "model about {mean}, aircraft at {c}"
    );
    assert_eq!(layer.stats().models_coarse, 0, "90 px: the full mesh");
    // 400 m of view: 34 px nose to tail, the coarse level of detail, still its outline.
    let mid = common::camera(8.0, 46.0, 0.0, 0.0, -90.0, false).orthographic_view(
        off.globe(),
        400.0,
        60.0,
        w,
        h,
    );
    let img = render(&mut off, &mid, &mut layer, "model-coarse");
    assert_eq!(layer.stats().models, 1, "{:?}", layer.stats());
    assert_eq!(layer.stats().models_coarse, 1, "{:?}", layer.stats());
    let plain = off
        .render_complete(&mid, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let mut changed = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (p, b) = (img.get(x, y), plain.get(x, y));
            if (0..3).any(|k| (i32::from(p[k]) - i32::from(b[k])).abs() > 24) {
                changed.push(DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
            }
        }
    }
    let span = changed
        .iter()
        .flat_map(|a| changed.iter().map(move |b| (*a - *b).length()))
        .fold(0.0, f64::max);
    let want = 37.6 * f64::from(h) / 400.0;
    assert!(
        (span / want - 1.0).abs() < 0.15,
        "{span} px across, {want} expected"
    );
    // The same aircraft from 300 km is a magenta symbol.
    let far = common::camera(8.0, 46.0, 300_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let img = render(&mut off, &far, &mut layer, "model-far");
    assert_eq!(layer.stats().models, 0);
    let c = project(off.globe(), 8.0, 46.0, 9_500.0);
    assert!(pixels_of(&img, MAGENTA, c, 15.0).len() > 20);
}

/// Two hundred aircraft crowded over the Alps: the labels drawn never overlap, each sits at
/// a corner of its own aircraft, every changed pixel of the picture is a label's (inside its
/// box or on its leader), and the aircraft behind the planet has none.
#[test]
fn labels_are_decluttered_at_their_aircraft_and_hidden_behind_the_planet() {
    let (w, h) = (640u32, 480u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let style_without_labels = globus_engine::TrafficStyle {
        labels: false,
        trails: false,
        ..Default::default()
    };
    let mut with = TrafficLayer::new();
    let mut without = TrafficLayer::with_options(
        Default::default(),
        style_without_labels,
        globus_engine::traffic::DEFAULT_PICK_BASE,
    );
    with.set_style(globus_engine::TrafficStyle {
        trails: false,
        ..Default::default()
    });
    let mut batch = Batch::default();
    let mut rng = globus_test_support::SplitMix64(7);
    let mut next = || rng.unit();
    for id in 0..200u64 {
        let (lon, lat) = (2.0 + next() * 12.0, 43.5 + next() * 6.0);
        let mut s = sample(
            id + 1,
            0.0,
            lon,
            lat,
            9_000.0 + next() * 3_000.0,
            (next() * 360.0) as f32,
            MAGENTA,
        );
        s.callsign = callsign_bytes(&format!("T{id}"));
        batch.push(s);
    }
    // And one on the far side of the planet.
    batch.push(sample(999, 0.0, -172.0, -46.0, 11_000.0, 0.0, MAGENTA));
    for layer in [&mut with, &mut without] {
        layer.apply(&batch).expect("apply");
        layer.set_time(0.0);
    }
    let view =
        common::camera(8.0, 46.5, 900_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let plain = render(&mut off, &view, &mut without, "labels-off");
    let img = render(&mut off, &view, &mut with, "labels");
    let labels: Vec<(u64, [f32; 4], f32)> = with.drawn_labels().collect();
    assert!(labels.len() > 15, "only {} labels", labels.len());
    assert!(
        labels.iter().all(|l| l.0 != 999),
        "a label for the aircraft behind the planet"
    );
    for (i, a) in labels.iter().enumerate() {
        for b in &labels[i + 1..] {
            let o = a.1[0] < b.1[2] && b.1[0] < a.1[2] && a.1[1] < b.1[3] && b.1[1] < a.1[3];
            assert!(!o, "labels of {} and {} overlap", a.0, b.0);
        }
        // At a corner of its own aircraft: the box's nearest corner within the symbol's
        // clearance (9 px + 4 px) of where the aircraft projects, diagonally.
        let s = &batch;
        let k = s
            .ids
            .iter()
            .position(|&id| id == a.0)
            .expect("a known aircraft");
        let [lon, lat, alt] = s.positions[k];
        let at = project(off.globe(), lon, lat, alt);
        let dx = (at.x - f64::from(a.1[0]))
            .abs()
            .min((at.x - f64::from(a.1[2])).abs());
        let dy = (at.y - f64::from(a.1[1]))
            .abs()
            .min((at.y - f64::from(a.1[3])).abs());
        assert!(
            (dx - 13.0).abs() < 1.0 && (dy - 13.0).abs() < 1.0,
            "label of {} off its aircraft: {dx} {dy}",
            a.0
        );
        assert!(
            (a.2 - 1.0).abs() < 1e-6,
            "a still picture shows labels whole"
        );
    }
    // Every pixel the labels changed lies in a box (with its halo) or on a leader, and
    // every box has ink in it.
    let inside = |x: f64, y: f64, b: &[f32; 4], m: f64| {
        x >= f64::from(b[0]) - m
            && x <= f64::from(b[2]) + m
            && y >= f64::from(b[1]) - m
            && y <= f64::from(b[3]) + m
    };
    let mut ink = vec![0u32; labels.len()];
    let mut stray = 0;
    for y in 0..h {
        for x in 0..w {
            let (p, b) = (img.get(x, y), plain.get(x, y));
            if (0..3).all(|c| (i32::from(p[c]) - i32::from(b[c])).abs() <= 12) {
                continue;
            }
            let (fx, fy) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let mut owned = false;
            for (i, l) in labels.iter().enumerate() {
                if inside(fx, fy, &l.1, 1.0) {
                    ink[i] += 1;
                    owned = true;
                }
            }
            // Leaders run from the symbol's edge to the box: within the 13 px clearance
            // square round some aircraft and its box.
            if !owned && !labels.iter().any(|l| inside(fx, fy, &l.1, 14.0)) {
                stray += 1;
            }
        }
    }
    assert_eq!(stray, 0, "pixels changed away from every label");
    assert!(ink.iter().all(|&n| n > 20), "a label without text: {ink:?}");
}

/// A replayed record: clicking an aircraft gives back its ICAO address, and a camera
/// following it keeps it at the centre of the picture while it flies on.
#[test]
fn picking_returns_the_icao24_and_following_keeps_the_aircraft_centred() {
    use globus_engine::traffic::{Record, Replay, ReplayOptions};
    use globus_traffic::record::{Report, Track};
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    // Three aircraft eastbound over the Atlantic, a report every 10 s.
    let track = |icao24: u32, lat: f64| Track {
        icao24,
        callsign: format!("X{icao24:x}"),
        typecode: "B77W".into(),
        reports: (0..120)
            .map(|k| Report {
                time_s: f64::from(k) * 10.0,
                lat_deg: lat + f64::from(k) * 0.001,
                lon_deg: -40.0 + f64::from(k) * 0.03,
                altitude_m: 11_000.0,
                velocity_mps: 250.0,
                heading_deg: 87.0,
                vertical_rate_mps: 0.0,
                on_ground: false,
            })
            .collect(),
    };
    let record = Record {
        tracks: vec![
            track(0x3c6444, 30.0),
            track(0x4ca123, 30.05),
            track(0xa1b2c3, 30.1),
        ],
        skipped: Vec::new(),
        rows: 0,
    };
    let followed = record.tracks[1].clone();
    let mut replay = Replay::new(record, ReplayOptions::default());
    let mut layer = TrafficLayer::new();
    layer.play(&mut replay, 100.0).expect("play");
    // A first frame makes the body known to the layer; then look at the middle aircraft
    // from 3 km behind and above.
    let first =
        common::camera(-37.0, 30.0, 500_000.0, 0.0, -90.0, false).view(off.globe(), 50.0, w, h);
    render(&mut off, &first, &mut layer, "follow-0");
    let id = Replay::id_of(1, followed.icao24);
    let at = layer.position_now(id).expect("drawn");
    let up = off.globe().ellipsoid().geodetic_normal(at).expect("up");
    let enu = off.globe().ellipsoid().enu_frame_at(at).expect("frame");
    let eye = at - enu.east * 2_500.0 + up * 1_500.0;
    let mut view = View::look_at(eye, at, up, 50f64.to_radians(), w, h).expect("view");
    let mut follow = globus_engine::Follow::start(&layer, id).expect("follow");
    let centre = DVec2::new(f64::from(w) / 2.0, f64::from(h) / 2.0);
    for step in 1..=5 {
        let t = 100.0 + f64::from(step) * 23.0;
        layer.play(&mut replay, t).expect("play");
        assert!(follow.update(&layer, &mut view));
        render(&mut off, &view, &mut layer, &format!("follow-{step}"));
        // Where the record puts it now (interpolated here from the raw reports).
        let k = (t / 10.0).floor() as usize;
        let f = t / 10.0 - k as f64;
        let (a, b) = (&followed.reports[k], &followed.reports[k + 1]);
        let lon = a.lon_deg + (b.lon_deg - a.lon_deg) * f;
        let lat = a.lat_deg + (b.lat_deg - a.lat_deg) * f;
        let p = project(off.globe(), lon, lat, 11_000.0);
        assert!(
            (p - centre).length() < 1.0,
            "step {step}: the aircraft is at {p:?}"
        );
        let pick = off
            .globe()
            .pick(centre.x, centre.y)
            .expect("pick")
            .expect("inside");
        let picked = pick
            .object()
            .and_then(|o| layer.aircraft_for_pick(o))
            .expect("an aircraft");
        assert_eq!(Replay::icao24_of(picked), 0x4ca123);
        assert_eq!(
            replay.track_of(picked).map(|t| t.callsign.as_str()),
            Some("X4ca123")
        );
    }
}

/// Altitudes follow the exaggeration, as the terrain's do; an aircraft on the ground sits on
/// the terrain as drawn whatever altitude it reports, and one reporting an altitude under the ground
/// is drawn on it.
#[test]
fn aircraft_follow_the_exaggeration_and_sit_on_the_ground() {
    let (w, h) = (160u32, 120u32);
    let mut builder = Globe::builder();
    builder.exaggeration(2.0);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let mut layer = TrafficLayer::new();
    let mut batch = Batch::default();
    let mut taxiing = sample(1, 0.0, 7.6, 46.0, 0.0, 10.0, MAGENTA);
    taxiing.flags = globus_engine::traffic::aircraft_flags::ON_GROUND;
    batch.push(taxiing);
    // Reports 10 m above the ellipsoid in the (procedural) Alps: under the ground there.
    batch.push(sample(2, 0.0, 7.7, 46.1, 10.0, 10.0, MAGENTA));
    batch.push(sample(3, 0.0, 7.8, 46.2, 9_000.0, 10.0, MAGENTA));
    layer.apply(&batch).expect("apply");
    layer.set_time(0.0);
    let view = common::camera(7.7, 46.1, 60_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    render(&mut off, &view, &mut layer, "ground");
    let globe = off.globe();
    // Drawn height above the ellipsoid (exaggerated), and the true one it stands for.
    let drawn = |id| {
        let p = layer.position_now(id).expect("drawn");
        globe
            .ellipsoid()
            .ecef_to_cartographic(p)
            .expect("on the body")
            .height_m
    };
    let height = |id| {
        let p = layer.position_now(id).expect("drawn");
        globe.cartographic(p).expect("on the body").height_m
    };
    // The ground as drawn: the loaded tiles' heights.
    let ground = |lon: f64, lat: f64| {
        globe
            .height_at(lon.to_radians(), lat.to_radians())
            .expect("loaded")
            .height_m()
    };
    let (g1, g2) = (ground(7.6, 46.0), ground(7.7, 46.1));
    assert!(
        g1 > 100.0 && g2 > 100.0,
        "the Alps should be above sea level: {g1} {g2}"
    );
    assert!((height(1) - g1).abs() < 0.01, "{} vs {g1}", height(1));
    assert!((height(2) - g2).abs() < 0.01, "{} vs {g2}", height(2));
    assert!((height(3) - 9_000.0).abs() < 0.01, "{}", height(3));
    // Drawn twice as high, as the terrain is.
    assert!((drawn(1) - 2.0 * g1).abs() < 0.01 && (drawn(3) - 18_000.0).abs() < 0.01);
}

/// Low over the procedural Alps, an aircraft with a mountain between it and the camera shows
/// neither its symbol nor its label, though its label has a place on the screen; one in the
/// open sky shows both.
#[test]
fn a_mountain_hides_an_aircraft_and_its_label() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let spec = common::camera(7.6, 46.0, 300.0, 0.0, 0.0, true);
    let view = spec.view(off.globe(), 60.0, w, h);
    let plain = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render")
        .image;
    // On a ray at or a little above the line of sight, past the first terrain it meets, find
    // the first point at least 1 km further that is in the open air, 100 m above the ground:
    // hidden by the mountain (an aircraft below the ground would be drawn on it). And one in
    // the sky above it: seen.
    let eye = view.position;
    let ahead = view.forward();
    let up = off.globe().ellipsoid().geodetic_normal(eye).expect("up");
    let tilted =
        |deg: f64| (ahead * deg.to_radians().cos() + up * deg.to_radians().sin()).normalize();
    let place = |p| off.globe().cartographic(p).expect("on the body");
    let behind = |ray: DVec3| {
        let d = (off.globe().ray_pick(eye, ray)? - eye).length();
        (0..200)
            .map(|k| eye + ray * (d + 1_000.0 + 50.0 * f64::from(k)))
            .find(|p| {
                let c = place(*p);
                c.height_m > off.globe().ground_height_m(c.lon_rad, c.lat_rad) + 100.0
            })
            .map(|p| (d, p))
    };
    let (d, hidden_at) = (0..16)
        .find_map(|k| behind(tilted(0.5 * f64::from(k))))
        .expect("a mountain with open air behind it ahead");
    assert!(d > 500.0, "the mountain is {d} m away");
    // Ten degrees above the line of sight, 6 km out, with nothing in front of it.
    let raised = tilted(10.0);
    let seen_at = eye + raised * 6_000.0;
    assert!(
        off.globe()
            .ray_pick(eye, raised)
            .is_none_or(|p| (p - eye).length() > 6_000.0),
        "the open aircraft is hidden too"
    );
    let (hc, sc) = (place(hidden_at), place(seen_at));
    let mut layer = TrafficLayer::new();
    let mut batch = Batch::default();
    batch.push(sample(
        1,
        0.0,
        hc.lon_deg(),
        hc.lat_deg(),
        hc.height_m,
        90.0,
        MAGENTA,
    ));
    batch.push(sample(
        2,
        0.0,
        sc.lon_deg(),
        sc.lat_deg(),
        sc.height_m,
        90.0,
        CYAN,
    ));
    layer.apply(&batch).expect("apply");
    layer.set_time(0.0);
    let img = render(&mut off, &view, &mut layer, "behind-a-mountain");
    let labels: Vec<(u64, [f32; 4], f32)> = layer.drawn_labels().collect();
    let changed_in = |b: &[f32; 4]| {
        let mut n = 0;
        for y in (b[1].max(0.0) as u32)..(b[3].min(h as f32) as u32) {
            for x in (b[0].max(0.0) as u32)..(b[2].min(w as f32) as u32) {
                let (p, q) = (img.get(x, y), plain.get(x, y));
                if (0..3).any(|c| (i32::from(p[c]) - i32::from(q[c])).abs() > 12) {
                    n += 1;
                }
            }
        }
        n
    };
    let hidden_label = labels.iter().find(|l| l.0 == 1).expect("placed on the CPU");
    let seen_label = labels.iter().find(|l| l.0 == 2).expect("placed");
    assert_eq!(
        changed_in(&hidden_label.1),
        0,
        "the hidden aircraft's label shows"
    );
    assert!(
        changed_in(&seen_label.1) > 20,
        "the visible aircraft's label is missing"
    );
    let hp = project(off.globe(), hc.lon_deg(), hc.lat_deg(), hc.height_m);
    assert!(
        pixels_of(&img, MAGENTA, hp, 12.0).is_empty(),
        "the hidden symbol shows"
    );
    let sp = project(off.globe(), sc.lon_deg(), sc.lat_deg(), sc.height_m);
    assert!(
        pixels_of(&img, CYAN, sp, 12.0).len() > 10,
        "the visible symbol is missing"
    );
}

/// Named fixes and aircraft crowded over the same few hundred pixels, the vector layer
/// prepared first: the aircraft's data blocks keep off the fixes' names and markers, so no
/// two labels of the scene overlap, whichever layer they belong to.
#[test]
fn data_blocks_keep_off_the_names_of_fixes_drawn_in_the_same_view() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&Globe::builder(), w, h).expect("a GPU or lavapipe");
    let mut fixes = VectorLayer::new();
    let rules = StyleRules::from_fragment("label={name}").expect("rules");
    let mut traffic = TrafficLayer::new();
    let mut batch = Batch::default();
    for k in 0..24u32 {
        let (lon, lat) = (7.2 + f64::from(k % 6) * 0.3, 45.8 + f64::from(k / 6) * 0.25);
        let json = format!(
            r#"{{"type":"Feature","properties":{{"name":"FIX{k:02}"}},"geometry":{{"type":"Point","coordinates":[{lon},{lat}]}}}}"#
        );
        let f: geojson::Feature = json.parse().expect("feature");
        let mut warnings = Vec::new();
        fixes.add(
            globus_vector::from_geojson(k as usize, f, &rules, &mut warnings).expect("a point"),
        );
        batch.push(sample(
            100 + u64::from(k),
            0.0,
            lon + 0.12,
            lat + 0.1,
            10_000.0,
            45.0,
            CYAN,
        ));
    }
    traffic.apply(&batch).expect("apply");
    traffic.set_time(0.0);
    let view =
        common::camera(8.0, 46.2, 200_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [&mut fixes, &mut traffic])
        .expect("render");
    let dir = globus_test_support::output_dir("traffic");
    save_png(&frame.image, &dir.join("fixes-and-blocks.png")).expect("save");
    let names: Vec<[f32; 4]> = fixes.drawn_labels().map(|l| l.2).collect();
    let blocks: Vec<[f32; 4]> = traffic.drawn_labels().map(|l| l.1).collect();
    assert!(
        names.len() >= 4 && blocks.len() >= 2,
        "{} names, {} blocks",
        names.len(),
        blocks.len()
    );
    let overlap =
        |a: &[f32; 4], b: &[f32; 4]| a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
    for b in &blocks {
        for n in &names {
            assert!(!overlap(b, n), "data block {b:?} over the name {n:?}");
        }
    }
    // And no label of either layer covers a symbol of either: the aircraft's and the
    // fixes' 12 px markers.
    let globe = off.globe();
    let half =
        f64::from(traffic.style().symbol_px[AircraftKind::NarrowBody.index() as usize]) * 0.5;
    let mut symbols = Vec::new();
    for k in 0..24u32 {
        let (lon, lat) = (7.2 + f64::from(k % 6) * 0.3, 45.8 + f64::from(k / 6) * 0.25);
        let ground = globe.drawn_ground_m(lon.to_radians(), lat.to_radians());
        for (p, r) in [
            (project(globe, lon + 0.12, lat + 0.1, 10_000.0), half),
            (project(globe, lon, lat, ground), 6.0),
        ] {
            let r = r - 0.5;
            symbols.push([
                (p.x - r) as f32,
                (p.y - r) as f32,
                (p.x + r) as f32,
                (p.y + r) as f32,
            ]);
        }
    }
    for l in names.iter().chain(&blocks) {
        for s in &symbols {
            assert!(!overlap(l, s), "label {l:?} over the symbol {s:?}");
        }
    }
}
