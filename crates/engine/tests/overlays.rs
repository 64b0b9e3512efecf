//! The open renderer, through the public API only: overlays drawn into the terrain's kept
//! depth buffer, the frame camera's projection against where the GPU draws, and picking.
//! Pictures go to `target/test-output/overlays/` to be looked at.

mod common;

use std::time::Duration;

use common::{Marker, Markers, marker_centroid, marker_pixels};
use globus_engine::{
    CameraSpec, Cartographic, DVec3, GlobeBuilder, Headless, OverlayPass, View, save_png,
};

const TIMEOUT: Duration = Duration::from_secs(240);
const SIZE: (u32, u32) = (640, 360);

/// A camera `alt` metres above the ground.
fn camera(lon: f64, lat: f64, alt: f64, heading: f64, pitch: f64) -> CameraSpec {
    common::camera(lon, lat, alt, heading, pitch, true)
}

/// The procedural planet at `cam`, every tile loaded.
fn loaded(cam: CameraSpec) -> (Headless, View) {
    let mut off = Headless::new(&GlobeBuilder::new(), SIZE.0, SIZE.1).expect("a GPU or lavapipe");
    let view = cam.view(off.globe(), 60.0, SIZE.0, SIZE.1);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    assert!(frame.complete, "tiles still loading");
    (off, view)
}

/// Renders `markers` over the loaded view and saves the picture as `name`.
fn draw(
    off: &mut Headless,
    view: &View,
    markers: Vec<Marker>,
    name: &str,
) -> globus_engine::RgbaImage {
    off.update(view);
    let mut overlay = Markers::new(markers);
    let image = off.draw_and_read(&mut [&mut overlay]).expect("render");
    let dir = globus_test_support::output_dir("overlays");
    save_png(&image, &dir.join(format!("{name}.png"))).expect("save");
    image
}

/// A point behind a mountain (in the air again beyond the terrain the ray through its pixel
/// meets first, with the terrain covering every ray within `margin_px` of it) and a point in
/// the air in front of that terrain on the same ray.
fn behind_and_in_front(off: &Headless, view: &View, margin_px: f64) -> (DVec3, DVec3) {
    let globe = off.globe();
    let eye = view.position;
    let hit_distance = |x: f64, y: f64| {
        let dir = view.ray_direction(x, y);
        globe.ray_pick(eye, dir).map(|p| (p - eye).length())
    };
    for y in (10..SIZE.1 - 10).step_by(3) {
        for x in (20..SIZE.0 - 20).step_by(17) {
            let (x, y) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let Some(d) = hit_distance(x, y) else {
                continue;
            };
            let dir = view.ray_direction(x, y);
            // Out of the mountain again, 100 m above the ground behind it.
            let behind = (1..=300)
                .map(|k| d * (1.0 + f64::from(k) / 100.0))
                .find(|&t| {
                    let c = globe.cartographic(eye + dir * t).expect("on the body");
                    c.height_m - globe.ground_height_m(c.lon_rad, c.lat_rad) > 100.0
                });
            let Some(t) = behind else {
                continue;
            };
            // Every ray of the marker's disc meets terrain well before it.
            let covered = [
                (-1.0, 0.0),
                (1.0, 0.0),
                (0.0, -1.0),
                (0.0, 1.0),
                (0.7, 0.7),
                (-0.7, -0.7),
            ]
            .iter()
            .all(|(dx, dy)| {
                hit_distance(x + dx * margin_px, y + dy * margin_px).is_some_and(|h| h < 0.9 * t)
            });
            if covered {
                return (eye + dir * t, eye + dir * (0.5 * d));
            }
        }
    }
    panic!("no ridge with air behind it in view");
}

#[test]
fn markers_behind_a_mountain_are_hidden_and_markers_in_front_are_seen() {
    let (mut off, view) = loaded(camera(7.6, 46.0, 2_500.0, 200.0, -10.0));
    let (behind, front) = behind_and_in_front(&off, &view, 6.0);
    let on_screen = view.project(behind).expect("in front of the eye");
    assert!(on_screen.0 > 0.0 && on_screen.0 < f64::from(SIZE.0));
    // Metres per pixel at a point's depth along the view axis (a disc facing the camera
    // plane is that many pixels across wherever it is on the screen).
    let metres_per_px = |at: DVec3| {
        (at - view.position).dot(view.forward()) * 2.0 * (view.fov_y_rad / 2.0).tan()
            / f64::from(SIZE.1)
    };
    for (pass, in_metres, label) in [
        (OverlayPass::World, true, "world"),
        (OverlayPass::ScreenAligned, false, "aligned"),
    ] {
        let marker = |at: DVec3| Marker {
            at,
            radius: if in_metres {
                (3.0 * metres_per_px(at)) as f32
            } else {
                3.0
            },
            in_metres,
            id: 1,
            pass,
        };
        let hidden = draw(
            &mut off,
            &view,
            vec![marker(behind)],
            &format!("{label}_behind"),
        );
        let seen = draw(
            &mut off,
            &view,
            vec![marker(front)],
            &format!("{label}_in_front"),
        );
        assert_eq!(
            marker_pixels(&hidden),
            0,
            "{label}: a marker behind the mountain shows through it"
        );
        let n = marker_pixels(&seen);
        assert!(
            (15..=40).contains(&n),
            "{label}: a 3 px marker in front of the mountain covers {n} pixels"
        );
    }
}

/// Where the GPU draws a marker (the Gaussian-weighted centre of its pixels) against the
/// frame camera's f64 projection of its world point.
fn projection_errors(off: &mut Headless, view: &View, points: &[DVec3], name: &str) -> Vec<f64> {
    let markers = points
        .iter()
        .map(|&at| Marker {
            at,
            radius: 6.0,
            in_metres: false,
            id: 0,
            pass: OverlayPass::ScreenAligned,
        })
        .collect();
    let image = draw(off, view, markers, name);
    let camera = *off.globe().camera().expect("a frame camera");
    points
        .iter()
        .map(|&p| {
            let want = camera.project(p).expect("on screen");
            let ((x, y), n) =
                marker_centroid(&image, (want.x, want.y), 8.0).expect("the marker is drawn");
            assert!(n > 80, "{name}: only {n} marker pixels near {want}");
            println!("{name}: drawn at ({x:.3}, {y:.3}), projected to {want:.3}");
            (x - want.x).hypot(y - want.y)
        })
        .collect()
}

#[test]
fn the_frame_camera_projects_points_where_the_renderer_draws_them() {
    // From three Earth radii: points 100 km above the ground over three continents.
    let (mut off, view) = loaded(CameraSpec {
        above_ground: false,
        ..camera(10.0, 0.0, 2.0 * 6_378_137.0, 0.0, -90.0)
    });
    let globe = off.globe();
    let points: Vec<DVec3> = [(20.0, 30.0), (-20.0, -10.0), (40.0, 10.0)]
        .iter()
        .map(|&(lon, lat)| globe.world_position(Cartographic::from_degrees(lon, lat, 100_000.0)))
        .collect();
    let orbit = projection_errors(&mut off, &view, &points, "projection_orbit");

    // One metre above the ground a tenth of a degree from the north pole, where f32 world
    // coordinates would be off by half a metre: points 1.2 to 2 m in front of the eye.
    let (mut off, view) = loaded(camera(179.9, 89.9, 1.0, 30.0, -25.0));
    let points: Vec<DVec3> = [
        (320.3, 150.7, 1.5),
        (120.5, 120.5, 1.2),
        (519.8, 170.15, 2.0),
    ]
    .iter()
    .map(|&(x, y, d)| view.position + view.ray_direction(x, y) * d)
    .collect();
    let pole = projection_errors(&mut off, &view, &points, "projection_pole_1m");
    println!("drawn vs projected, px: orbit {orbit:.3?}, pole at 1 m {pole:.3?}");
    for e in orbit.iter().chain(&pole) {
        assert!(
            *e < 0.5,
            "drawn {e:.3} px from the projection: orbit {orbit:.3?}, pole {pole:.3?}"
        );
    }
}

#[test]
fn picking_returns_the_object_and_the_ground_under_the_cursor() {
    let (mut off, view) = loaded(camera(7.6, 46.0, 2_500.0, 200.0, -10.0));
    let (_, front) = behind_and_in_front(&off, &view, 6.0);
    let other = view.position + view.ray_direction(150.5, 300.5) * 300.0;
    let markers = vec![
        Marker {
            at: front,
            radius: 8.0,
            in_metres: false,
            id: 42,
            pass: OverlayPass::ScreenAligned,
        },
        Marker {
            at: other,
            radius: 8.0,
            in_metres: false,
            id: 7,
            pass: OverlayPass::World,
        },
    ];
    draw(&mut off, &view, markers, "picking");
    let globe = off.globe();
    let camera = *globe.camera().expect("camera");
    for (at, id) in [(front, 42), (other, 7)] {
        let px = camera.project(at).expect("on screen");
        let pick = globe
            .pick(px.x, px.y)
            .expect("read back")
            .expect("in the frame");
        assert_eq!(pick.object(), Some(id));
        // The ground behind the marker.
        let ground = pick.surface().expect("terrain behind the marker");
        let through = globe
            .ray_pick(view.position, view.ray_direction(px.x, px.y))
            .expect("terrain");
        assert!((ground - through).length() < 1.0, "{ground} vs {through}");
    }

    // Bare terrain at several pixels: no object, a point within a pixel of the cursor and
    // within the drawn tile's own error of the true ground.
    let e = globe.ellipsoid();
    for (x, y) in [
        (40.5, 340.5),
        (600.25, 300.75),
        (320.0, 250.0),
        (500.5, 200.5),
    ] {
        let pick = globe.pick(x, y).expect("read back").expect("in the frame");
        assert_eq!(pick.object(), None, "({x}, {y})");
        let p = pick.surface().expect("terrain there");
        let drawn = camera.project(p).expect("on screen");
        assert!(
            (drawn.x - x).hypot(drawn.y - y) < 1.0,
            "({x}, {y}): the picked point is drawn at {drawn}"
        );
        let c = e.ecef_to_cartographic(p).expect("on the body");
        let truth = globe.ground_height_m(c.lon_rad, c.lat_rad);
        let error = globe
            .height_at(c.lon_rad, c.lat_rad)
            .expect("loaded")
            .error_m();
        assert!(
            (c.height_m - truth).abs() <= error,
            "({x}, {y}): picked {:.2} m, ground {truth:.2} m, tile error {error:.2} m",
            c.height_m
        );
    }
    // The sky: nothing.
    let sky = globe
        .pick(320.0, 3.0)
        .expect("read back")
        .expect("in the frame");
    assert_eq!((sky.object(), sky.surface()), (None, None));
    // Outside the frame: no answer.
    assert!(globe.pick(-1.0, 10.0).expect("no read").is_none());
    assert!(globe.pick(10.0, 1e6).expect("no read").is_none());
}
