//! The camera controller without a window or a GPU: driven with pixel positions over an
//! analytic ground of 1 km hills, as `globus view` and embedding programs drive it.

use std::time::Duration;

use globus_engine::{CameraController, Cartographic, DVec3, Ellipsoid, Ground, View, ray_march};

/// Hills between 500 and 2,500 m around the Alps, a few kilometres apart.
struct Hills;

impl Hills {
    fn height(lon: f64, lat: f64) -> f64 {
        1500.0 + 1000.0 * (lon * 500.0).sin() * (lat * 700.0).cos()
    }
}

impl Ground for Hills {
    fn ellipsoid(&self) -> Ellipsoid {
        Ellipsoid::WGS84
    }

    fn drawn_ground_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        Self::height(lon_rad, lat_rad)
    }

    fn ray_pick(&self, origin: DVec3, direction: DVec3) -> Option<DVec3> {
        ray_march(
            &Ellipsoid::WGS84,
            |lon, lat| Some(Self::height(lon, lat)),
            (500.0, 2500.0),
            origin,
            direction,
        )
    }
}

const W: u32 = 800;
const H: u32 = 600;

fn view_at(lon: f64, lat: f64, above_ground_m: f64, heading: f64, pitch: f64) -> View {
    let ground = Hills::height(lon.to_radians(), lat.to_radians());
    View::from_geodetic(
        &Ellipsoid::WGS84,
        Cartographic::from_degrees(lon, lat, ground + above_ground_m),
        heading.to_radians(),
        pitch.to_radians(),
        60f64.to_radians(),
        W,
        H,
    )
}

fn off_by(c: &CameraController, point: DVec3, x: f64, y: f64) -> f64 {
    let p = c.project(point).expect("in front of the camera");
    (p.x - x).hypot(p.y - y)
}

#[test]
fn a_long_pan_keeps_the_grabbed_point_under_the_cursor() {
    for (name, start) in [
        ("close in", view_at(7.6, 46.0, 3_000.0, 30.0, -35.0)),
        ("from orbit", view_at(7.6, 46.0, 8_000_000.0, 0.0, -90.0)),
    ] {
        let mut c = CameraController::new(start);
        let (x0, y0) = (400.0, 380.0);
        assert!(
            c.begin_pan(&Hills, x0, y0),
            "{name}: ground under the cursor"
        );
        let grabbed = c.ground_under(&Hills, x0, y0).expect("ground");
        let mut worst: f64 = 0.0;
        // A loop of 600 px over 400 steps: right, up, round and back.
        for k in 1..=400 {
            let a = f64::from(k) / 400.0 * std::f64::consts::TAU;
            let (x, y) = (x0 + 250.0 * a.sin(), y0 - 120.0 * (1.0 - a.cos()));
            c.pan_to(&Hills, x, y);
            worst = worst.max(off_by(&c, grabbed, x, y));
            assert!(
                c.height_above_ground_m(&Hills) >= 1.0 - 1e-6,
                "{name}: below ground"
            );
        }
        c.end_pan();
        assert!(
            worst < 0.5,
            "{name}: the grabbed point strayed {worst:.3} px"
        );
        // Panned round a loop back to the start pixel: the camera is where it began.
        assert!(
            (c.view().position - start.position).length() < 1e-3 * start.position.length(),
            "{name}"
        );
    }
}

#[test]
fn zooming_keeps_the_point_under_the_cursor_and_never_enters_the_ground() {
    let mut c = CameraController::new(view_at(7.6, 46.0, 5_000.0, 120.0, -25.0));
    let (x, y) = (530.0, 410.0);
    let target = c.ground_under(&Hills, x, y).expect("ground");
    let mut heights = vec![c.height_above_ground_m(&Hills)];
    for _ in 0..60 {
        c.zoom(&Hills, x, y, 2.0);
        assert!(off_by(&c, target, x, y) < 0.5, "zoom in moved the point");
        let h = c.height_above_ground_m(&Hills);
        assert!(h >= 1.0 - 1e-6, "{h} m above the ground");
        heights.push(h);
    }
    // Steps proportional to the height above the ground: fast far away, slow close in, and
    // at the end just short of the target, not inside it.
    assert!(heights[0] - heights[1] > 100.0 * (heights[50] - heights[51]).abs());
    let left = (c.view().position - target).length();
    assert!((0.99..50.0).contains(&left), "{left} m from the target");
    for _ in 0..30 {
        c.zoom(&Hills, x, y, -3.0);
        assert!(off_by(&c, target, x, y) < 0.5, "zoom out moved the point");
    }
    assert!(c.height_above_ground_m(&Hills) > heights[10]);
}

#[test]
fn orbiting_never_flips_over_nor_goes_below_the_ground() {
    // 3 km above the ground, always above the highest hill.
    let start = view_at(7.6, 46.0, 3_000.0, 0.0, -30.0);
    let mut c = CameraController::new(start);
    let (cx, cy) = (400.0, 300.0);
    assert!(c.begin_orbit(&Hills, cx, cy));
    let pivot = c.ground_under(&Hills, cx, cy).expect("ground");
    let up = Ellipsoid::WGS84.geodetic_normal(pivot).expect("up");
    let per_px = std::f64::consts::PI / f64::from(H);
    let elevation = |c: &CameraController| {
        (c.view().position - pivot)
            .normalize()
            .dot(up)
            .asin()
            .to_degrees()
    };
    // A full turn about the vertical comes back to the same place, the pivot at its pixel.
    let steps = 720;
    for _ in 0..steps {
        c.orbit_by(&Hills, 1.0, 0.0, std::f64::consts::TAU / f64::from(steps));
        assert!(off_by(&c, pivot, cx, cy) < 0.5, "the pivot left its pixel");
    }
    let moved = (c.view().position - start.position).length();
    assert!(moved < 0.01, "a full turn ended {moved} m away");
    // Up over the top (dragging down): stops short of straight above, upright.
    for _ in 0..200 {
        c.orbit_by(&Hills, 3.0, 25.0, per_px);
        assert!(c.view().up().dot(up) > 0.0, "the camera flipped over");
        assert!(elevation(&c) <= 89.5 + 1e-6);
        assert!(off_by(&c, pivot, cx, cy) < 0.5, "the pivot left its pixel");
    }
    assert!(
        elevation(&c) > 89.0,
        "never got near the top: {}",
        elevation(&c)
    );
    // Down below the horizon (dragging up): stops above the ground.
    for _ in 0..400 {
        c.orbit_by(&Hills, -7.0, -25.0, per_px);
        assert!(c.height_above_ground_m(&Hills) >= 1.0 - 1e-6, "underground");
        assert!(elevation(&c) >= 0.5 - 1e-6);
        assert!(c.view().up().dot(up) > 0.0);
        assert!(off_by(&c, pivot, cx, cy) < 0.5, "the pivot left its pixel");
    }
    c.end_orbit();
}

#[test]
fn looking_around_turns_and_tilts_where_the_camera_stands() {
    let mut c = CameraController::new(view_at(7.6, 46.0, 500.0, 0.0, 0.0));
    let at = c.view().position;
    c.look(&Hills, 200.0, 0.0);
    let (heading, pitch) = c.view().heading_pitch(&Ellipsoid::WGS84).expect("frame");
    // 200 px of a 600 px, 60 degree field: 20 degrees, to the right (the view follows the
    // cursor).
    assert!(
        (heading.to_degrees() - 20.0).abs() < 1e-6,
        "{}",
        heading.to_degrees()
    );
    assert!(pitch.abs() < 1e-6, "{pitch}");
    for _ in 0..50 {
        c.look(&Hills, 0.0, 100.0);
    }
    let (_, pitch) = c.view().heading_pitch(&Ellipsoid::WGS84).expect("frame");
    assert!(
        pitch.to_degrees() < -85.0 && pitch.to_degrees() > -90.0,
        "{}",
        pitch.to_degrees()
    );
    assert_eq!(c.view().position, at);
}

#[test]
fn a_flight_rises_with_the_distance_and_ends_exactly_at_its_target() {
    let from = view_at(7.6, 46.0, 2_000.0, 0.0, -20.0);
    let to = view_at(-17.4, 14.7, 3_000.0, 250.0, -35.0);
    let mut c = CameraController::new(from);
    c.fly_to(&Hills, to, Duration::from_secs(3));
    let e = Ellipsoid::WGS84;
    let mut peak: f64 = 0.0;
    let mut steps = 0;
    // Uneven frame times.
    while c.is_flying() {
        let dt = Duration::from_millis(if steps % 3 == 0 { 40 } else { 11 });
        assert!(c.update(&Hills, dt));
        let h = e
            .ecef_to_cartographic(c.view().position)
            .expect("on the body")
            .height_m;
        peak = peak.max(h);
        assert!(c.height_above_ground_m(&Hills) >= 1.0 - 1e-6);
        steps += 1;
        assert!(steps < 1000, "the flight never ends");
    }
    assert_eq!(c.view().position, to.position);
    assert_eq!(c.view().orientation, to.orientation);
    // 5,300 km apart: up to 40 % of that, far above both ends.
    let distance = e.great_circle_distance(
        e.ecef_to_cartographic(from.position).expect("on the body"),
        e.ecef_to_cartographic(to.position).expect("on the body"),
    );
    assert!(peak > 0.3 * distance, "peak {peak} m for {distance} m");
    assert!(
        !c.update(&Hills, Duration::from_millis(10)),
        "a finished flight stays put"
    );
    // A short hop barely rises.
    let near = view_at(7.61, 46.0, 2_000.0, 0.0, -20.0);
    let mut c = CameraController::new(from);
    c.fly_to(&Hills, near, Duration::from_secs(1));
    let mut peak: f64 = 0.0;
    while c.is_flying() {
        c.update(&Hills, Duration::from_millis(16));
        peak = peak.max(
            e.ecef_to_cartographic(c.view().position)
                .expect("body")
                .height_m,
        );
    }
    let ends = e
        .ecef_to_cartographic(from.position)
        .expect("body")
        .height_m;
    assert!(peak < ends + 1_000.0, "a 770 m hop rose to {peak} m");
    assert_eq!(c.view().position, near.position);
}

#[test]
fn the_orthographic_camera_keeps_scale_and_centre_zooms_about_the_cursor_and_pans() {
    // Straight down from 20 km above the hills: the centre of the screen and the scale
    // there carry over to the orthographic camera, and back.
    let start = view_at(7.6, 46.0, 20_000.0, 25.0, -90.0);
    let mut c = CameraController::new(start);
    let (cx, cy) = (f64::from(W) * 0.5, f64::from(H) * 0.5);
    let centre = c.ground_under(&Hills, cx, cy).expect("ground");
    let px_per_m = c
        .view()
        .pixels_per_metre((c.view().position - centre).length());
    c.set_orthographic(&Hills, true);
    assert!(c.is_orthographic());
    let size = c.view().ortho_height_m().expect("orthographic");
    assert!((c.view().pixels_per_metre(1.0) / px_per_m - 1.0).abs() < 1e-9);
    assert!(
        (size - 2.0 * 20_000.0 * 30f64.to_radians().tan()).abs() < 1.0,
        "{size}"
    );
    assert!(off_by(&c, centre, cx, cy) < 0.01);
    let (heading, pitch) = c.view().heading_pitch(&Ellipsoid::WGS84).expect("heading");
    assert!((heading.to_degrees() - 25.0).abs() < 1e-6 && pitch.to_degrees() < -89.999);
    let eye = Ellipsoid::WGS84
        .ecef_to_cartographic(c.view().position)
        .expect("eye");
    assert!((eye.height_m - globus_engine::ORTHO_EYE_HEIGHT_M).abs() < 1e-3);

    // Zoom: the projection's size, 0.8x a notch in and 1.25x out, about the cursor; the eye
    // stays at its height and looks straight down.
    let (x, y) = (610.0, 140.0);
    let target = c.ground_under(&Hills, x, y).expect("ground");
    for _ in 0..10 {
        c.zoom(&Hills, x, y, 1.0);
        assert!(off_by(&c, target, x, y) < 0.05, "zoom in moved the point");
    }
    let zoomed = c.view().ortho_height_m().expect("orthographic");
    assert!((zoomed / size - 0.8f64.powi(10)).abs() < 1e-9, "{zoomed}");
    c.zoom(&Hills, x, y, -1.0);
    assert!(off_by(&c, target, x, y) < 0.05, "zoom out moved the point");
    let eye = Ellipsoid::WGS84
        .ecef_to_cartographic(c.view().position)
        .expect("eye");
    assert!((eye.height_m - globus_engine::ORTHO_EYE_HEIGHT_M).abs() < 1.0);

    // Pan: the grabbed point follows the cursor over a loop and the camera comes back.
    let before = *c.view();
    let grabbed = c.ground_under(&Hills, 300.0, 300.0).expect("ground");
    assert!(c.begin_pan(&Hills, 300.0, 300.0));
    let mut worst: f64 = 0.0;
    for k in 1..=100 {
        let a = f64::from(k) / 100.0 * std::f64::consts::TAU;
        let (px, py) = (300.0 + 200.0 * a.sin(), 300.0 - 100.0 * (1.0 - a.cos()));
        c.pan_to(&Hills, px, py);
        worst = worst.max(off_by(&c, grabbed, px, py));
    }
    c.end_pan();
    assert!(worst < 0.5, "the grabbed point strayed {worst:.3} px");
    assert!((c.view().position - before.position).length() < 1e-3);

    // Looking around only turns: it never tilts off straight down.
    c.look(&Hills, 40.0, 120.0);
    let (h2, p2) = c.view().heading_pitch(&Ellipsoid::WGS84).expect("heading");
    assert!(p2.to_degrees() < -89.999, "tilted to {}", p2.to_degrees());
    assert!((h2 - heading).abs() > 0.01, "did not turn");

    // Back to perspective: straight down over the same centre at the same scale.
    let centre = c.ground_under(&Hills, cx, cy).expect("ground");
    let px_per_m = c.view().pixels_per_metre(1.0);
    c.set_orthographic(&Hills, false);
    assert!(!c.is_orthographic());
    assert!(off_by(&c, centre, cx, cy) < 0.01);
    let d = (c.view().position - centre).length();
    assert!((c.view().pixels_per_metre(d) / px_per_m - 1.0).abs() < 1e-3);
}
