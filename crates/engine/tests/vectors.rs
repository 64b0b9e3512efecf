//! The vector overlay on lavapipe, pictures compared with what the CPU expects: a draped line
//! over the real SRTM relief of N57E011 at five altitudes and a low pitch (colour along its
//! projected centre line, width within 1 px); the countries file from orbit against an
//! even-odd point-in-polygon of the file's own coordinates (Fiji and Russia across the
//! antimeridian, Antarctica round the pole); picking a feature; bad files.

mod common;

use std::path::Path;
use std::time::Duration;

use globus_engine::{
    CameraSpec, Cartographic, DVec3, GlobeBuilder, Headless, RgbaImage, StyleRules, VectorLayer,
    View, save_png,
};

const TIMEOUT: Duration = Duration::from_secs(300);

fn write_geojson(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write geojson");
    path
}

fn pixel(img: &RgbaImage, x: i64, y: i64) -> Option<[f64; 3]> {
    if x < 0 || y < 0 || x >= i64::from(img.width) || y >= i64::from(img.height) {
        return None;
    }
    let p = img.get(x as u32, y as u32);
    Some([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
}

/// How much of `colour` a pixel carries over the same pixel of `background` (0..1).
fn coverage(img: &RgbaImage, bg: &RgbaImage, x: i64, y: i64, colour: [f64; 3]) -> f64 {
    let (Some(p), Some(b)) = (pixel(img, x, y), pixel(bg, x, y)) else {
        return 0.0;
    };
    let d = |a: [f64; 3], c: [f64; 3]| {
        ((a[0] - c[0]).powi(2) + (a[1] - c[1]).powi(2) + (a[2] - c[2]).powi(2)).sqrt()
    };
    let full = d(colour, b);
    if full < 60.0 {
        return f64::NAN; // the background is too close to the colour to tell
    }
    // Projection of (p - b) on (colour - b).
    let dot: f64 = (0..3).map(|k| (p[k] - b[k]) * (colour[k] - b[k])).sum();
    (dot / (full * full)).clamp(0.0, 1.0)
}

const MAGENTA: [f64; 3] = [255.0, 0.0, 255.0];
const LINE_PX: f64 = 4.0;
const LINE_LAT: f64 = 57.45;

/// Renders `view` with and without `layer`; saves both.
fn with_and_without(
    off: &mut Headless,
    view: &View,
    layer: &mut VectorLayer,
    name: &str,
) -> (RgbaImage, RgbaImage) {
    let frame = off.render_complete(view, TIMEOUT, &mut []).expect("render");
    assert!(frame.complete, "{name}: tiles still loading");
    let plain = frame.image;
    let drawn = off
        .render_complete(view, TIMEOUT, &mut [layer])
        .expect("render")
        .image;
    let dir = globus_test_support::output_dir("vectors");
    save_png(&drawn, &dir.join(format!("{name}.png"))).expect("save");
    (drawn, plain)
}

#[test]
fn a_draped_line_over_srtm_keeps_its_colour_and_width_from_100_km_to_50_m() {
    let builder = common::srtm_builder("vectors", "srtm");
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe, and the pyramid");
    let dir = common::scratch("vectors", "line");
    let file = write_geojson(
        &dir,
        "line.geojson",
        &format!(
            r##"{{"type": "FeatureCollection", "features": [{{"type": "Feature",
                "properties": {{"stroke": "#ff00ff", "stroke-width": {LINE_PX}, "path": "rhumb"}},
                "geometry": {{"type": "LineString", "coordinates": [[11.05, {LINE_LAT}], [11.95, {LINE_LAT}]]}}}}]}}"##
        ),
    );
    let mut layer = VectorLayer::new();
    layer
        .add_file(&file, &StyleRules::default())
        .expect("line file");
    // Straight down at five altitudes above the ground, then low over the line looking along
    // a hillside at it.
    let views = [
        (11.5, LINE_LAT, 100_000.0, 0.0, -90.0),
        (11.5, LINE_LAT, 10_000.0, 0.0, -90.0),
        (11.5, LINE_LAT, 1_000.0, 30.0, -90.0),
        (11.5, LINE_LAT, 200.0, 0.0, -90.0),
        (11.5, LINE_LAT, 50.0, 0.0, -90.0),
        (11.47, LINE_LAT - 0.012, 120.0, 20.0, -12.0),
    ];
    for (k, &(lon, lat, alt, heading, pitch)) in views.iter().enumerate() {
        let cam = common::camera(lon, lat, alt, heading, pitch, true);
        let mut view = cam.view(off.globe(), 60.0, w, h);
        off.render_complete(&view, TIMEOUT, &mut [])
            .expect("render");
        view = cam.view(off.globe(), 60.0, w, h); // placed over the loaded ground
        let name = format!("line_{k}_{alt}m_pitch{pitch}");
        let (img, bg) = with_and_without(&mut off, &view, &mut layer, &name);
        let globe = off.globe();
        let camera = *globe.camera().expect("a frame camera");
        let eye = view.position;
        let (mut expected, mut hit, mut widths) = (0usize, 0usize, Vec::new());
        // Samples along the part of the line the view can hold.
        let reach = if pitch > -45.0 { alt * 30.0 } else { alt * 2.0 };
        let span = (reach / (111_320.0 * LINE_LAT.to_radians().cos())).min(0.45);
        let (from, to) = ((lon - span).max(11.05), (lon + span).min(11.95));
        for s in 0..=4000 {
            let lon = from + (to - from) * f64::from(s) / 4000.0;
            let (lon_r, lat_r) = (lon.to_radians(), LINE_LAT.to_radians());
            let at = globe.world_position(Cartographic::new(
                lon_r,
                lat_r,
                globe.ground_height_m(lon_r, lat_r),
            ));
            let Some(px) = camera.project(at) else {
                continue;
            };
            let (x, y) = (px.x.floor() as i64, px.y.floor() as i64);
            if x < 3 || y < 3 || x >= i64::from(w) - 3 || y >= i64::from(h) - 3 {
                continue;
            }
            // Terrain in front of the line there (a hill between it and the eye) hides it.
            let hidden = globe
                .ray_pick(eye, (at - eye).normalize())
                .is_some_and(|p| (p - eye).length() < (at - eye).length() * 0.99 - 1.0);
            if hidden {
                continue;
            }
            let c = coverage(&img, &bg, x, y, MAGENTA);
            if c.is_nan() {
                continue;
            }
            expected += 1;
            hit += usize::from(c > 0.5);
            // Width across the line: summed coverage along the pixel column (the line runs
            // east-west, so across the screen), corrected for its slope there.
            if s % 40 == 0 {
                let next = globe.world_position(Cartographic::new(
                    (lon + 0.0005).to_radians(),
                    lat_r,
                    globe.ground_height_m((lon + 0.0005).to_radians(), lat_r),
                ));
                let Some(q) = camera.project(next) else {
                    continue;
                };
                let d = (q - px).normalize_or_zero();
                if d.x.abs() < 0.5 {
                    continue;
                }
                let sum: f64 = (-12..=12)
                    .map(|dy| coverage(&img, &bg, x, y + dy, MAGENTA))
                    .filter(|c| c.is_finite())
                    .sum();
                widths.push(sum * d.x.abs());
            }
        }
        assert!(
            expected > 100,
            "{name}: only {expected} centre-line pixels in view"
        );
        let share = hit as f64 / expected as f64;
        widths.sort_by(f64::total_cmp);
        let median = widths.get(widths.len() / 2).copied().unwrap_or(f64::NAN);
        eprintln!(
            "{name}: {hit}/{expected} centre pixels magenta ({:.1} %), median width {median:.2} px over {} columns",
            share * 100.0,
            widths.len()
        );
        assert!(
            share >= 0.98,
            "{name}: {:.1} % of the centre line carries the colour",
            share * 100.0
        );
        assert!(
            (median - LINE_PX).abs() <= 1.0,
            "{name}: width {median:.2} px, asked {LINE_PX}"
        );
    }
}

/// Even-odd point-in-polygon on the file's own coordinates (no unwrapping: Natural Earth
/// splits its polygons at the antimeridian and draws Antarctica along -90).
fn inside_any(polys: &[Vec<Vec<[f64; 2]>>], lon: f64, lat: f64) -> bool {
    polys.iter().any(|rings| {
        let mut inside = false;
        for ring in rings {
            let n = ring.len();
            for i in 0..n {
                let (a, b) = (ring[i], ring[(i + 1) % n]);
                if (a[1] > lat) != (b[1] > lat) {
                    let x = a[0] + (lat - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                    if lon < x {
                        inside = !inside;
                    }
                }
            }
        }
        inside
    })
}

fn country_polygons() -> Vec<Vec<Vec<[f64; 2]>>> {
    let text = std::fs::read_to_string(globus_test_support::shared_data("countries-110m.geojson"))
        .expect("countries");
    let json: serde_json::Value = serde_json::from_str(&text).expect("json");
    let mut out = Vec::new();
    let ring = |r: &serde_json::Value| -> Vec<[f64; 2]> {
        r.as_array()
            .into_iter()
            .flatten()
            .filter_map(|p| Some([p[0].as_f64()?, p[1].as_f64()?]))
            .collect()
    };
    for f in json["features"].as_array().expect("features") {
        let g = &f["geometry"];
        let polys: Vec<&serde_json::Value> = match g["type"].as_str() {
            Some("Polygon") => vec![&g["coordinates"]],
            _ => g["coordinates"]
                .as_array()
                .expect("multipolygon")
                .iter()
                .collect(),
        };
        for p in polys {
            out.push(p.as_array().expect("rings").iter().map(ring).collect());
        }
    }
    out
}

#[test]
fn the_countries_from_orbit_cover_what_a_cpu_point_in_polygon_covers() {
    let (w, h) = (400u32, 400u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let mut layer = VectorLayer::new();
    let rules =
        StyleRules::from_fragment("fill=%2300ff00&fill-opacity=1&stroke-width=0").expect("rules");
    let (loaded, ids) = layer
        .add_file(
            &globus_test_support::shared_data("countries-110m.geojson"),
            &rules,
        )
        .expect("countries");
    assert_eq!((loaded.read, ids.len()), (177, 177));
    let polys = country_polygons();
    // Europe and Africa; Russia, Fiji and the antimeridian; Antarctica round the south pole.
    let views = [
        ("europe", 15.0, 30.0, 12_000_000.0),
        ("antimeridian", 178.0, 10.0, 12_000_000.0),
        ("russia_east", 175.0, 62.0, 8_000_000.0),
        ("south_pole", 0.0, -89.9, 12_000_000.0),
    ];
    for (name, lon, lat, alt) in views {
        let cam = common::camera(lon, lat, alt, 0.0, -90.0, false);
        let view = cam.view(off.globe(), 60.0, w, h);
        let (img, bg) = with_and_without(&mut off, &view, &mut layer, &format!("countries_{name}"));
        let globe = off.globe();
        let e = globe.ellipsoid();
        let mut expected = vec![None; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let dir = view.ray_direction(f64::from(x) + 0.5, f64::from(y) + 0.5);
                let Some(hit) = globe
                    .ray_pick(view.position, dir)
                    .or_else(|| e.ray_hit(view.position, dir))
                else {
                    continue;
                };
                let Some(c) = e.ecef_to_cartographic(hit) else {
                    continue;
                };
                expected[(y * w + x) as usize] = Some(inside_any(&polys, c.lon_deg(), c.lat_deg()));
            }
        }
        let at = |x: i64, y: i64| -> Option<bool> {
            if x < 0 || y < 0 || x >= i64::from(w) || y >= i64::from(h) {
                return None;
            }
            expected[(y as u32 * w + x as u32) as usize]
        };
        let (mut checked, mut wrong, mut land) = (0usize, 0usize, 0usize);
        for y in 0..i64::from(h) {
            for x in 0..i64::from(w) {
                let Some(want) = at(x, y) else { continue };
                // Within 1 px of a border either answer is right.
                let border = (-1..=1)
                    .any(|dy| (-1..=1).any(|dx| at(x + dx, y + dy).is_some_and(|o| o != want)));
                if border {
                    continue;
                }
                let c = coverage(&img, &bg, x, y, [0.0, 255.0, 0.0]);
                if c.is_nan() {
                    continue;
                }
                checked += 1;
                land += usize::from(want);
                if (c > 0.5) != want {
                    wrong += 1;
                }
            }
        }
        let share = wrong as f64 / checked.max(1) as f64;
        eprintln!(
            "countries {name}: {wrong} of {checked} pixels differ ({:.3} %), {land} inside",
            share * 100.0
        );
        assert!(
            checked > 20_000 && land > 1_000,
            "{name}: {checked} checked, {land} inside"
        );
        assert!(
            share < 0.002,
            "{name}: {wrong} of {checked} pixels differ from the CPU reference"
        );
    }
}

#[test]
fn clicking_a_feature_returns_its_id_and_properties() {
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let mut layer = VectorLayer::with_pick_base(1000);
    layer
        .add_file(
            &globus_test_support::shared_data("countries-110m.geojson"),
            &StyleRules::default(),
        )
        .expect("countries");
    let cam = CameraSpec {
        lon_deg: 2.5,
        lat_deg: 46.5,
        alt_m: 3_000_000.0,
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    };
    let view = cam.view(off.globe(), 60.0, w, h);
    off.render_complete(&view, TIMEOUT, &mut [&mut layer])
        .expect("render");
    let globe = off.globe();
    let pick = globe
        .pick(160.0, 120.0)
        .expect("pick")
        .expect("inside the frame");
    let object = pick.object().expect("France is under the centre");
    let (_, feature) = layer.feature_for_pick(object).expect("one of the layer's");
    assert_eq!(feature.properties["name"], "France");
    let _ = DVec3::ZERO;
}

#[test]
fn a_file_that_is_not_geojson_is_one_error_naming_it() {
    let dir = common::scratch("vectors", "bad");
    let csv = write_geojson(&dir, "airports.geojson", "icao,lat,lon\nEGLL,51.4,-0.4\n");
    let mut layer = VectorLayer::new();
    let e = layer.add_file(&csv, &StyleRules::default()).unwrap_err();
    assert!(
        e.to_string().contains("airports.geojson") && e.to_string().contains("not GeoJSON"),
        "{e}"
    );
    assert!(layer.is_empty());
}

fn point_feature(index: usize, lon: f64, lat: f64, colour: &str) -> globus_engine::Feature {
    let text = format!(
        r##"{{"type": "Feature", "properties": {{"marker-color": "{colour}", "marker-size": 6, "clamp": "absolute"}},
            "geometry": {{"type": "Point", "coordinates": [{lon}, {lat}, 20000]}}}}"##
    );
    feature(index, &text)
}

/// A GeoJSON feature, checked and styled with the default rules.
fn feature(index: usize, json: &str) -> globus_engine::Feature {
    let f: geojson::Feature = json.parse().expect("feature");
    let mut warnings = Vec::new();
    globus_vector::from_geojson(index, f, &StyleRules::default(), &mut warnings).expect("drawable")
}

#[test]
fn updates_cost_what_changed_and_an_unchanged_frame_rebuilds_nothing() {
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let mut layer = VectorLayer::new();
    let ids = layer.add_batch((0..100).map(|k| {
        point_feature(
            k,
            7.0 + f64::from(k as u32 % 10) * 0.1,
            46.0 + f64::from(k as u32 / 10) * 0.1,
            "#ff0000",
        )
    }));
    let cam = common::camera(7.45, 46.45, 300_000.0, 0.0, -90.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    off.render_complete(&view, TIMEOUT, &mut [&mut layer])
        .expect("render");
    let frame = |off: &mut Headless, layer: &mut VectorLayer| {
        off.update(&view);
        off.draw_and_read(&mut [layer]).expect("draw")
    };
    frame(&mut off, &mut layer);
    let idle = layer.stats();
    assert_eq!(
        (idle.features_built, idle.rebuilt, idle.tiles_draped),
        (0, false, 0),
        "{idle:?}"
    );
    assert_eq!(idle.line_instances, 100);
    assert!(idle.draw_calls <= 2);
    // Recolour one point: one feature is built again, and the picture shows it.
    let target = ids[55];
    let camera = *off.globe().camera().expect("camera");
    let at = off.globe().world_position(Cartographic::new(
        7.5f64.to_radians(),
        46.5f64.to_radians(),
        20_000.0,
    ));
    let px = camera.project(at).expect("in view");
    let before = frame(&mut off, &mut layer);
    assert!(layer.update(target, point_feature(55, 7.5, 46.5, "#0000ff")));
    let after = frame(&mut off, &mut layer);
    assert_eq!(layer.stats().features_built, 1);
    let (x, y) = (px.x as u32, px.y as u32);
    assert!(
        before.get(x, y)[0] > 200 && before.get(x, y)[2] < 60,
        "{:?}",
        before.get(x, y)
    );
    assert!(
        after.get(x, y)[2] > 200 && after.get(x, y)[0] < 60,
        "{:?}",
        after.get(x, y)
    );
    // Remove it: 99 left, the pixel shows the ground again.
    assert!(layer.remove(target));
    assert!(!layer.remove(target));
    let gone = frame(&mut off, &mut layer);
    assert_eq!(layer.stats().line_instances, 99);
    assert!(
        gone.get(x, y)[2] < 200 || gone.get(x, y)[0] > 60,
        "{:?}",
        gone.get(x, y)
    );
    // A draped line: recoloured in the tiles already draped (only that feature redraped).
    let line = |colour: &str| {
        let text = format!(
            r##"{{"type": "Feature", "properties": {{"stroke": "{colour}", "stroke-width": 5}},
                "geometry": {{"type": "LineString", "coordinates": [[7.0, 46.25], [7.9, 46.25]]}}}}"##
        );
        feature(0, &text)
    };
    let id = layer.add(line("#ff00ff"));
    let drawn = frame(&mut off, &mut layer);
    let globe = off.globe();
    let (lon, lat) = (7.45f64.to_radians(), 46.25f64.to_radians());
    let on_ground =
        globe.world_position(Cartographic::new(lon, lat, globe.ground_height_m(lon, lat)));
    let q = camera.project(on_ground).expect("in view");
    let (lx, ly) = (q.x as u32, q.y as u32);
    let magenta = drawn.get(lx, ly);
    assert!(
        magenta[0] > 200 && magenta[1] < 80 && magenta[2] > 200,
        "{magenta:?}"
    );
    assert!(layer.update(id, line("#00ffff")));
    let recoloured = frame(&mut off, &mut layer);
    let cyan = recoloured.get(lx, ly);
    assert!(cyan[0] < 80 && cyan[1] > 200 && cyan[2] > 200, "{cyan:?}");
    assert_eq!(
        layer.stats().tiles_draped,
        0,
        "tiles were redraped, not draped anew"
    );
}

fn box_feature(
    index: usize,
    lon: f64,
    lat: f64,
    half_deg: f64,
    lower: f64,
    upper: f64,
    fill: &str,
) -> globus_engine::Feature {
    let (w, e, s, n) = (
        lon - half_deg,
        lon + half_deg,
        lat - half_deg,
        lat + half_deg,
    );
    let text = format!(
        r##"{{"type": "Feature", "properties": {{"fill": "{fill}", "fill-opacity": 0.4, "stroke-width": 0,
            "extrude": true, "lower": {lower}, "upper": {upper}}},
            "geometry": {{"type": "Polygon", "coordinates": [[[{w}, {s}], [{e}, {s}], [{e}, {n}], [{w}, {n}], [{w}, {s}]]]}}}}"##
    );
    feature(index, &text)
}

fn mean_abs_diff(a: &RgbaImage, b: &RgbaImage) -> f64 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .sum::<f64>()
        / a.pixels.len() as f64
}

#[test]
fn translucent_volumes_composite_in_any_order_hide_behind_terrain_and_show_from_inside() {
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    // Two overlapping boxes seen from the side and above: red nearer, blue behind.
    let red = || box_feature(0, 10.0, 0.0, 0.5, 20_000.0, 60_000.0, "#ff0000");
    let blue = || box_feature(1, 10.0, 0.6, 0.5, 20_000.0, 60_000.0, "#0000ff");
    let cam = common::camera(10.0, -1.6, 80_000.0, 0.0, -25.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    let plain = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let mut red_first = VectorLayer::new();
    red_first.add_batch([red(), blue()]);
    let mut blue_first = VectorLayer::new();
    blue_first.add_batch([blue(), red()]);
    let a = off
        .render_complete(&view, TIMEOUT, &mut [&mut red_first])
        .expect("render")
        .image;
    let b = off
        .render_complete(&view, TIMEOUT, &mut [&mut blue_first])
        .expect("render")
        .image;
    let dir = globus_test_support::output_dir("vectors");
    save_png(&a, &dir.join("volumes_red_first.png")).expect("save");
    save_png(&b, &dir.join("volumes_blue_first.png")).expect("save");
    let order = mean_abs_diff(&a, &b);
    let shown = mean_abs_diff(&a, &plain);
    eprintln!("volumes: order changes {order:.3} levels on average, the volumes {shown:.2}");
    assert!(
        shown > 5.0,
        "the volumes change the picture by {shown:.2} levels only"
    );
    assert!(
        order < 0.5,
        "drawing order changes the picture by {order:.3} levels"
    );
    // Where both cover a pixel both tint it: it differs from each drawn alone.
    let mut alone = |f: globus_engine::Feature| {
        let mut l = VectorLayer::new();
        l.add(f);
        off.render_complete(&view, TIMEOUT, &mut [&mut l])
            .expect("render")
            .image
    };
    let (red_only, blue_only) = (alone(red()), alone(blue()));
    let differs = |p: [u8; 4], q: [u8; 4]| (0..3).any(|k| p[k].abs_diff(q[k]) > 12);
    let both = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let p = a.get(x, y);
            differs(p, red_only.get(x, y))
                && differs(p, blue_only.get(x, y))
                && differs(p, plain.get(x, y))
        })
        .count();
    assert!(both > 500, "only {both} pixels tinted by both volumes");
    // Clicking a volume's face picks it.
    off.render_complete(&view, TIMEOUT, &mut [&mut red_first])
        .expect("render");
    let (px, py) = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .find(|&(x, y)| {
            differs(red_only.get(x, y), plain.get(x, y))
                && !differs(a.get(x, y), red_only.get(x, y))
        })
        .expect("a pixel only the red volume covers");
    let pick = off
        .globe()
        .pick(f64::from(px) + 0.5, f64::from(py) + 0.5)
        .expect("pick")
        .expect("in frame");
    let picked = pick
        .object()
        .and_then(|o| red_first.feature_for_pick(o))
        .map(|(_, f)| f.index);
    assert_eq!(picked, Some(0), "clicking the red volume at ({px}, {py})");
    // A volume wholly under the ground (below any sea floor) is hidden by it.
    let mut buried = VectorLayer::new();
    buried.add(box_feature(
        0, 10.0, 0.0, 0.5, -30_000.0, -20_000.0, "#ff0000",
    ));
    let under = off
        .render_complete(&view, TIMEOUT, &mut [&mut buried])
        .expect("render")
        .image;
    let hidden = mean_abs_diff(&under, &plain);
    assert!(
        hidden < 0.05,
        "a buried volume shows through the terrain: {hidden:.3} levels"
    );
    // From inside a volume, everything is seen through its walls.
    let inside = common::camera(10.0, 0.0, 40_000.0, 90.0, -5.0, false);
    let view = inside.view(off.globe(), 60.0, w, h);
    let plain = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render")
        .image;
    let tinted = off
        .render_complete(&view, TIMEOUT, &mut [&mut red_first])
        .expect("render")
        .image;
    save_png(&tinted, &dir.join("volumes_inside.png")).expect("save");
    let changed = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let (p, q) = (tinted.get(x, y), plain.get(x, y));
            (0..3).any(|k| p[k].abs_diff(q[k]) > 20)
        })
        .count();
    let share = changed as f64 / f64::from(w * h);
    eprintln!("inside a volume: {:.1} % of pixels tinted", share * 100.0);
    assert!(
        share > 0.95,
        "from inside the red volume only {:.1} % of the frame is tinted",
        share * 100.0
    );
}

#[test]
fn a_draped_fill_over_mountains_covers_what_the_cpu_projects_with_no_seams_between_levels() {
    let (w, h) = (480u32, 320u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let (west, south, east, north) = (7.0, 45.6, 8.6, 46.6);
    let text = format!(
        r##"{{"type": "Feature", "properties": {{"fill": "#00ff00", "fill-opacity": 1, "stroke-width": 0}},
            "geometry": {{"type": "Polygon", "coordinates": [[[{west}, {south}], [{east}, {south}], [{east}, {north}], [{west}, {north}], [{west}, {south}]]]}}}}"##
    );
    let mut layer = VectorLayer::new();
    layer.add(feature(0, &text));
    // Low over the Alps of the procedural planet, looking north across the box: tiles of
    // many levels meet inside it.
    let cam = common::camera(7.8, 45.75, 3_000.0, 0.0, -15.0, true);
    let mut view = cam.view(off.globe(), 60.0, w, h);
    off.render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    view = cam.view(off.globe(), 60.0, w, h);
    let (img, bg) = with_and_without(&mut off, &view, &mut layer, "fill_over_mountains");
    let globe = off.globe();
    let levels: std::collections::BTreeSet<u8> =
        globe.drawn_tiles().iter().map(|d| d.key.level()).collect();
    let e = globe.ellipsoid();
    let mut expected = vec![None; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let dir = view.ray_direction(f64::from(x) + 0.5, f64::from(y) + 0.5);
            let Some(hit) = globe.ray_pick(view.position, dir) else {
                continue;
            };
            let Some(c) = e.ecef_to_cartographic(hit) else {
                continue;
            };
            let (lon, lat) = (c.lon_deg(), c.lat_deg());
            expected[(y * w + x) as usize] =
                Some(lon > west && lon < east && lat > south && lat < north);
        }
    }
    let at = |x: i64, y: i64| -> Option<bool> {
        if x < 0 || y < 0 || x >= i64::from(w) || y >= i64::from(h) {
            return None;
        }
        expected[(y as u32 * w + x as u32) as usize]
    };
    let (mut checked, mut wrong, mut inside) = (0usize, 0usize, 0usize);
    for y in 0..i64::from(h) {
        for x in 0..i64::from(w) {
            let Some(want) = at(x, y) else { continue };
            // Within 1 px of the edge, or of a silhouette, either answer is right.
            let edge = (-1..=1).any(|dy| (-1..=1).any(|dx| at(x + dx, y + dy) != Some(want)));
            if edge {
                continue;
            }
            let c = coverage(&img, &bg, x, y, [0.0, 255.0, 0.0]);
            if c.is_nan() {
                continue;
            }
            checked += 1;
            inside += usize::from(want);
            wrong += usize::from((c > 0.5) != want);
        }
    }
    let share = wrong as f64 / checked.max(1) as f64;
    eprintln!(
        "fill over mountains: levels {levels:?}, {wrong} of {checked} pixels differ ({:.3} %), {inside} inside",
        share * 100.0
    );
    assert!(levels.len() >= 3, "only levels {levels:?} drawn");
    assert!(inside > 20_000, "{inside} pixels inside");
    // Without the skirts draped, 45 pixels of seams showed where levels meet.
    assert!(
        wrong <= 10,
        "{wrong} of {checked} pixels differ from the CPU projection"
    );
}

#[test]
fn a_point_can_be_drawn_as_an_icon_from_a_png() {
    let dir = common::scratch("vectors", "icon");
    let icon = dir.join("icon.png");
    let mut img = image::RgbaImage::new(16, 16);
    for (x, _, p) in img.enumerate_pixels_mut() {
        *p = if x < 8 {
            image::Rgba([255, 0, 0, 255])
        } else {
            image::Rgba([0, 0, 255, 255])
        };
    }
    img.save(&icon).expect("icon");
    let text = format!(
        r##"{{"type": "FeatureCollection", "features": [
            {{"type": "Feature", "properties": {{"marker-icon": "{}", "marker-size": 32, "clamp": "absolute"}},
              "geometry": {{"type": "Point", "coordinates": [7.5, 46.5, 20000]}}}},
            {{"type": "Feature", "properties": {{"marker-icon": "{}", "marker-color": "#00ff00", "marker-size": 20, "clamp": "absolute"}},
              "geometry": {{"type": "Point", "coordinates": [7.9, 46.5, 20000]}}}}]}}"##,
        icon.display(),
        dir.join("missing.png").display()
    );
    let file = write_geojson(&dir, "icons.geojson", &text);
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let mut layer = VectorLayer::new();
    layer
        .add_file(&file, &StyleRules::default())
        .expect("icons");
    let cam = common::camera(7.7, 46.5, 300_000.0, 0.0, -90.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [&mut layer])
        .expect("render");
    save_png(
        &frame.image,
        &globus_test_support::output_dir("vectors").join("icons.png"),
    )
    .expect("save");
    let globe = off.globe();
    let camera = *globe.camera().expect("camera");
    let px = |lon: f64| {
        let p = globe.world_position(Cartographic::new(
            lon.to_radians(),
            46.5f64.to_radians(),
            20_000.0,
        ));
        camera.project(p).expect("in view")
    };
    let at = px(7.5);
    let (x, y) = (at.x as u32, at.y as u32);
    let (left, right) = (frame.image.get(x - 8, y), frame.image.get(x + 8, y));
    assert!(
        left[0] > 200 && left[2] < 60,
        "left half of the icon: {left:?}"
    );
    assert!(
        right[2] > 200 && right[0] < 60,
        "right half of the icon: {right:?}"
    );
    // An icon that cannot be read: the point is drawn as its symbol (warned about).
    let fallback = px(7.9);
    let c = frame.image.get(fallback.x as u32, fallback.y as u32);
    assert!(
        c[1] > 200 && c[0] < 60 && c[2] < 60,
        "fallback symbol: {c:?}"
    );
}

#[test]
fn exaggeration_raises_vector_geometry_with_the_terrain() {
    let (w, h) = (320u32, 240u32);
    let mut builder = GlobeBuilder::new();
    builder.exaggeration(3.0);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let mut layer = VectorLayer::new();
    layer.add(point_feature(0, 7.5, 46.5, "#ff0000"));
    // From the side: 20 km up drawn at 60 km is tens of pixels higher on screen.
    let cam = common::camera(7.5, 45.3, 40_000.0, 0.0, 0.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [&mut layer])
        .expect("render");
    let globe = off.globe();
    let camera = *globe.camera().expect("camera");
    let (lon, lat) = (7.5f64.to_radians(), 46.5f64.to_radians());
    let raised = camera
        .project(globe.world_position(Cartographic::new(lon, lat, 20_000.0)))
        .expect("in view");
    let true_height = globe
        .ellipsoid()
        .cartographic_to_ecef(Cartographic::new(lon, lat, 20_000.0));
    let unraised = camera.project(true_height).expect("in view");
    assert!(
        (raised.y - unraised.y).abs() > 20.0,
        "{raised:?} {unraised:?}"
    );
    let red = |p: [u8; 4]| p[0] > 200 && p[1] < 80 && p[2] < 80;
    assert!(
        red(frame.image.get(raised.x as u32, raised.y as u32)),
        "no point where it is raised to"
    );
    assert!(
        !red(frame.image.get(unraised.x as u32, unraised.y as u32)),
        "a point at its true height"
    );
}
