//! The vector overlay on lavapipe, pictures compared with what the CPU expects: a draped line
//! over the real SRTM relief of N57E011 at five altitudes and a low pitch (colour along its
//! projected centre line, width within 1 px); the countries file from orbit against an
//! even-odd point-in-polygon of the file's own coordinates (Fiji and Russia across the
//! antimeridian, Antarctica round the pole); picking a feature; bad files.

mod common;

use std::path::Path;
use std::time::Duration;

use globus_engine::{
    CameraSpec, Cartographic, DVec3, Globe, GlobeBuilder, Headless, RgbaImage, StyleRules,
    VectorLayer, View, save_png,
};

/// The point of the loaded ground at a longitude and latitude (degrees).
fn on_ground(globe: &Globe, lon_deg: f64, lat_deg: f64) -> DVec3 {
    let (lon, lat) = (lon_deg.to_radians(), lat_deg.to_radians());
    globe.world_position(Cartographic::new(lon, lat, globe.ground_height_m(lon, lat)))
}

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

/// Loads the ground under `cam` completely, then its view placed over that ground (a camera
/// `above_ground` stands on the loaded surface).
fn placed(off: &mut Headless, cam: &CameraSpec, (w, h): (u32, u32)) -> View {
    let view = cam.view(off.globe(), 60.0, w, h);
    off.render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    cam.view(off.globe(), 60.0, w, h)
}

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

/// A headless globe over the SRTM pyramid and a layer with one east-west line along
/// [`LINE_LAT`] from 11.05 to 11.95 E, styled by the simplestyle `properties` (JSON members),
/// written to the scratch folder `name`.
fn srtm_and_line(name: &str, properties: &str, (w, h): (u32, u32)) -> (Headless, VectorLayer) {
    let builder = common::srtm_builder("vectors");
    let off = Headless::new(&builder, w, h).expect("a GPU or lavapipe, and the pyramid");
    let dir = common::scratch("vectors", name);
    let file = write_geojson(
        &dir,
        "line.geojson",
        &format!(
            r##"{{"type": "Feature", "properties": {{{properties}}},
                "geometry": {{"type": "LineString", "coordinates": [[11.05, {LINE_LAT}], [11.95, {LINE_LAT}]]}}}}"##
        ),
    );
    let mut layer = VectorLayer::new();
    layer
        .add_file(&file, &StyleRules::default())
        .expect("line file");
    (off, layer)
}

#[test]
fn a_draped_line_over_srtm_keeps_its_colour_and_width_from_100_km_to_50_m() {
    let (w, h) = (480u32, 360u32);
    let (mut off, mut layer) = srtm_and_line(
        "line",
        &format!(r##""stroke": "#ff00ff", "stroke-width": {LINE_PX}, "path": "rhumb""##),
        (w, h),
    );
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
        let view = placed(&mut off, &cam, (w, h));
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
            let at = on_ground(globe, lon, LINE_LAT);
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
                let next = on_ground(globe, lon + 0.0005, LINE_LAT);
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

/// A translucent line is as strong where it crosses a drawn tile's midline or border as
/// anywhere else: its pieces are kept by quadrant (so a tile drawn in part draws only its
/// quadrants'), and the two runs meeting at a midline, or at the border between two tiles,
/// are cut square and abut instead of overlapping their round ends, which showed a darker dot
/// at every crossing.
#[test]
fn a_translucent_line_has_no_dots_where_it_crosses_a_tiles_midline_or_border() {
    let (w, h) = (480u32, 360u32);
    let (mut off, mut layer) = srtm_and_line(
        "translucent",
        r##""stroke": "#ff00ff", "stroke-opacity": 0.5, "stroke-width": 6, "path": "rhumb""##,
        (w, h),
    );
    let cam = common::camera(11.5, LINE_LAT, 20_000.0, 0.0, -90.0, true);
    let view = placed(&mut off, &cam, (w, h));
    let (img, bg) = with_and_without(&mut off, &view, &mut layer, "translucent_line");
    let globe = off.globe();
    let camera = *globe.camera().expect("a frame camera");
    // Where the line crosses drawn tiles' borders and midlines, in screen x.
    let (mut borders, mut midlines) = (Vec::new(), Vec::new());
    let screen_x = |lon_rad: f64| {
        camera
            .project(on_ground(globe, lon_rad.to_degrees(), LINE_LAT))
            .map(|p| p.x)
    };
    for d in globe.drawn_tiles() {
        let r = globus_tiling::GLOBE_SCHEME.rect(d.key);
        let lat = LINE_LAT.to_radians();
        if lat < r.south || lat > r.north {
            continue;
        }
        borders.extend([r.west, r.east].into_iter().filter_map(screen_x));
        if d.parts.is_all() {
            midlines.extend(screen_x((r.west + r.east) / 2.0));
        }
    }
    let near = |xs: &[f64], x: f64, px: f64| xs.iter().any(|&e| (e - x).abs() < px);
    let (mut plain, mut at_midlines, mut at_borders) = (Vec::new(), Vec::new(), Vec::new());
    for s in 0..=4000 {
        let lon = 11.05 + 0.9 * f64::from(s) / 4000.0;
        let Some(px) = camera.project(on_ground(globe, lon, LINE_LAT)) else {
            continue;
        };
        let (x, y) = (px.x.floor() as i64, px.y.floor() as i64);
        if x < 3 || y < 3 || x >= i64::from(w) - 3 || y >= i64::from(h) - 3 {
            continue;
        }
        let c = coverage(&img, &bg, x, y, MAGENTA);
        if c.is_nan() {
            continue;
        }
        if near(&midlines, px.x, 1.5) {
            at_midlines.push(c);
        } else if near(&borders, px.x, 1.5) {
            at_borders.push(c);
        } else if !near(&midlines, px.x, 6.0) && !near(&borders, px.x, 6.0) {
            plain.push(c);
        }
    }
    plain.sort_by(f64::total_cmp);
    let median = plain[plain.len() / 2];
    let strongest = |cs: &[f64]| cs.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "{} tiles, {} midlines and {} borders crossed; coverage {median:.3} along the line \
         (p1 {:.3}, p99 {:.3}), at most {:.3} over {} samples at midlines, {:.3} over {} at borders",
        globe.drawn_tiles().len(),
        midlines.len(),
        borders.len(),
        plain[plain.len() / 100],
        plain[plain.len() * 99 / 100],
        strongest(&at_midlines),
        at_midlines.len(),
        strongest(&at_borders),
        at_borders.len(),
    );
    assert!(
        plain.len() > 1_000 && (0.3..0.8).contains(&median),
        "{} samples, median coverage {median:.3}",
        plain.len()
    );
    for (what, cs) in [("midline", &at_midlines), ("border", &at_borders)] {
        assert!(cs.len() >= 10, "{} samples at {what}s", cs.len());
        assert!(
            strongest(cs) < median + 0.08,
            "coverage {:.3} at a {what} against {median:.3} along the line",
            strongest(cs)
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
        // Measured: 0.022, 0.050, 0.035 and 0.047 %. The south pole was 0.198 % while line
        // simplification dropped Antarctica's corners at the pole (a spiral hole there).
        assert!(
            share < 0.001,
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
    let q = camera
        .project(on_ground(globe, 7.45, 46.25))
        .expect("in view");
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
    let view = placed(&mut off, &cam, (w, h));
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

/// The alpha a pixel shows `colour` blended with over `background` at, in linear light
/// (where blending happens): least squares over the three channels.
fn linear_alpha(img: &RgbaImage, bg: &RgbaImage, x: i64, y: i64, colour: [f64; 3]) -> f64 {
    let (Some(p), Some(b)) = (pixel(img, x, y), pixel(bg, x, y)) else {
        return f64::NAN;
    };
    let lin = |v: f64| {
        let s = v / 255.0;
        if s <= 0.04045 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }
    };
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..3 {
        let (pk, bk, ck) = (lin(p[k]), lin(b[k]), lin(colour[k]));
        num += (pk - bk) * (ck - bk);
        den += (ck - bk) * (ck - bk);
    }
    num / den
}

/// Coverage of `colour` along the screen path from world `a` to `b`, every quarter pixel:
/// (pixels along the path, coverage).
fn along_path(
    img: &RgbaImage,
    bg: &RgbaImage,
    camera: &globus_engine::FrameCamera,
    (a, b): (DVec3, DVec3),
    colour: [f64; 3],
) -> Vec<(f64, f64)> {
    let (Some(pa), Some(pb)) = (camera.project(a), camera.project(b)) else {
        return Vec::new();
    };
    let steps = ((pb - pa).length() * 4.0).ceil() as usize;
    (0..=steps)
        .filter_map(|i| {
            let t = i as f64 / steps as f64;
            let q = pa + (pb - pa) * t;
            let c = coverage(img, bg, q.x.floor() as i64, q.y.floor() as i64, colour);
            c.is_finite().then_some(((pb - pa).length() * t, c))
        })
        .collect()
}

/// Lengths (pixels) of the runs of samples on and off (coverage above / below one half),
/// without the first and last (cut by the path's ends).
fn runs(samples: &[(f64, f64)]) -> (Vec<f64>, Vec<f64>) {
    let (mut on, mut off) = (Vec::new(), Vec::new());
    let mut start = 0;
    for i in 1..samples.len() {
        let (was, is) = (samples[i - 1].1 > 0.5, samples[i].1 > 0.5);
        if was != is {
            if start > 0 {
                let len = samples[i].0 - samples[start].0;
                if was { on.push(len) } else { off.push(len) }
            }
            start = i;
        }
    }
    (on, off)
}

#[test]
fn joins_caps_and_dashes_are_drawn_as_svg_draws_them_and_dashes_stay_on_the_ground() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let cam = common::camera(10.0, 0.0, 60_000.0, 0.0, -90.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    // Right-angled turns (16 px wide) with each join; straight lines with each cap; all at
    // 20 km, straight below the camera. One dashed line at 20 km and one draped.
    let hw = 8.0;
    let (z, step) = (20_000.0, 0.06);
    let mut layer = VectorLayer::new();
    let mut features = Vec::new();
    let joins = ["miter", "round", "bevel"];
    for (k, join) in joins.iter().enumerate() {
        let x = 9.82 + 0.13 * k as f64;
        features.push(feature(
            k,
            &format!(
                r##"{{"type": "Feature", "properties": {{"stroke": "#ff00ff", "stroke-width": {sw},
                    "stroke-linejoin": "{join}", "clamp": "absolute"}},
                    "geometry": {{"type": "LineString", "coordinates": [[{x}, 0.13, {z}], [{x}, 0.19, {z}], [{e}, 0.19, {z}]]}}}}"##,
                sw = 2.0 * hw,
                e = x + step,
            ),
        ));
    }
    let caps = ["butt", "round", "square"];
    for (k, cap) in caps.iter().enumerate() {
        let x = 9.82 + 0.13 * k as f64;
        features.push(feature(
            3 + k,
            &format!(
                r##"{{"type": "Feature", "properties": {{"stroke": "#ff00ff", "stroke-width": {sw},
                    "stroke-linecap": "{cap}", "clamp": "absolute"}},
                    "geometry": {{"type": "LineString", "coordinates": [[{x}, 0.05, {z}], [{e}, 0.05, {z}]]}}}}"##,
                sw = 2.0 * hw,
                e = x + step,
            ),
        ));
    }
    // Half-transparent zigzags: a joint is not drawn twice.
    for (k, join) in ["miter", "round"].iter().enumerate() {
        let x = 9.82 + 0.2 * k as f64;
        features.push(feature(
            6 + k,
            &format!(
                r##"{{"type": "Feature", "properties": {{"stroke": "#ff00ff", "stroke-width": 10,
                    "stroke-opacity": 0.5, "stroke-linejoin": "{join}", "clamp": "absolute"}},
                    "geometry": {{"type": "LineString", "coordinates": [[{x}, -0.05, {z}], [{m}, -0.02, {z}], [{e}, -0.05, {z}]]}}}}"##,
                m = x + 0.05,
                e = x + 0.1,
            ),
        ));
    }
    for (k, clamp) in ["absolute", "ground"].iter().enumerate() {
        // Far enough apart on the screen: the draped one is three times as far from the eye.
        let lat = [-0.09, -0.28][k];
        features.push(feature(
            8 + k,
            &format!(
                r##"{{"type": "Feature", "properties": {{"stroke": "#ff00ff", "stroke-width": 6,
                    "stroke-dasharray": "16 8", "stroke-linecap": "butt", "clamp": "{clamp}"}},
                    "geometry": {{"type": "LineString", "coordinates": [[9.6, {lat}, {z}], [10.4, {lat}, {z}]]}}}}"##
            ),
        ));
    }
    layer.add_batch(features);
    let (img, bg) = with_and_without(&mut off, &view, &mut layer, "joins_caps_dashes");
    let globe = off.globe();
    let camera = *globe.camera().expect("a frame camera");
    let at = |lon: f64, lat: f64, h: f64| {
        globe.world_position(Cartographic::new(lon.to_radians(), lat.to_radians(), h))
    };
    let px = |p: DVec3| camera.project(p).expect("in view");
    let cov = |q: globus_engine::DVec2| {
        coverage(&img, &bg, q.x.floor() as i64, q.y.floor() as i64, MAGENTA)
    };
    // Joins: the outer corner of the turn (south-east of the vertex, half way between the
    // segments' outer edges) at 0.85 and 1.2 half widths: a miter covers both, a round join
    // the nearer, a bevel (which reaches 0.71) neither; inside the turn, all cover.
    for (k, join) in joins.iter().enumerate() {
        let x = 9.82 + 0.13 * k as f64;
        let v = px(at(x, 0.19, z));
        let back = (px(at(x, 0.13, z)) - v).normalize();
        let fwd = (px(at(x + step, 0.19, z)) - v).normalize();
        let outer = -(back + fwd).normalize();
        let (near, far) = (cov(v + outer * 0.85 * hw), cov(v + outer * 1.2 * hw));
        let inner = cov(v - outer * 1.2 * hw);
        eprintln!(
            "join {join}: outer corner at 0.85 hw {near:.2}, at 1.2 hw {far:.2}, inner {inner:.2}"
        );
        assert!(inner > 0.9, "{join}: inside of the turn {inner:.2}");
        let (want_near, want_far) = match *join {
            "miter" => (true, true),
            "round" => (true, false),
            _ => (false, false),
        };
        assert_eq!(
            (near > 0.5, far > 0.5),
            (want_near, want_far),
            "{join}: {near:.2} {far:.2}"
        );
    }
    // Caps: 0.6 half widths beyond the end on the axis (round and square cover it, butt
    // not), and 0.8 beyond and 0.8 off the axis (only square).
    for (k, cap) in caps.iter().enumerate() {
        let x = 9.82 + 0.13 * k as f64;
        let end = px(at(x + step, 0.05, z));
        let d = (end - px(at(x, 0.05, z))).normalize();
        let n = globus_engine::DVec2::new(-d.y, d.x);
        let axis = cov(end + d * 0.6 * hw);
        let corner = cov(end + d * 0.8 * hw + n * 0.8 * hw);
        let before = cov(end - d * 0.5 * hw);
        eprintln!(
            "cap {cap}: before the end {before:.2}, beyond on the axis {axis:.2}, corner {corner:.2}"
        );
        assert!(before > 0.9, "{cap}: the line before its end {before:.2}");
        let want = match *cap {
            "butt" => (false, false),
            "round" => (true, false),
            _ => (true, true),
        };
        assert_eq!(
            (axis > 0.5, corner > 0.5),
            want,
            "{cap}: {axis:.2} {corner:.2}"
        );
    }
    // Translucent joints: the vertex carries the same alpha as the middle of a segment
    // (drawn twice it would carry 0.75 instead of 0.5).
    let alpha = |q: globus_engine::DVec2| {
        linear_alpha(&img, &bg, q.x.floor() as i64, q.y.floor() as i64, MAGENTA)
    };
    for (k, join) in ["miter", "round"].iter().enumerate() {
        let x = 9.82 + 0.2 * k as f64;
        let joint = alpha(px(at(x + 0.05, -0.02, z)));
        let middle = alpha(px(at(x + 0.025, -0.035, z)));
        eprintln!("translucent {join}: joint {joint:.3}, segment {middle:.3}");
        assert!(
            (joint - middle).abs() < 0.06 && middle > 0.3,
            "{join}: joint {joint:.3} vs segment {middle:.3}"
        );
    }
    // Dashes: 16 on, 8 off, drawn between 0.7 and 1.42 times that, every dash and gap alike
    // (no phase jump at tile borders or chunk ends).
    let check_dashes = |name: &str, samples: &[(f64, f64)]| -> f64 {
        let (on, offs) = runs(samples);
        assert!(on.len() >= 10, "{name}: only {} dashes", on.len());
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (dash, gap) = (mean(&on), mean(&offs));
        eprintln!(
            "{name}: {} dashes of {dash:.1} px (from {:.1} to {:.1}), gaps {gap:.1} px",
            on.len(),
            on.iter().copied().fold(f64::INFINITY, f64::min),
            on.iter().copied().fold(0.0, f64::max),
        );
        let scale = (dash + gap) / 24.0;
        assert!(
            (0.69..=1.43).contains(&scale),
            "{name}: pattern scale {scale:.2}"
        );
        assert!(
            (dash / (dash + gap) - 16.0 / 24.0).abs() < 0.06,
            "{name}: dashes {dash:.1} px, gaps {gap:.1} px"
        );
        for r in on.iter().chain(&offs) {
            let nominal = if on.contains(r) { dash } else { gap };
            assert!(
                (r - nominal).abs() < 2.0,
                "{name}: a run of {r:.1} px among {nominal:.1}"
            );
        }
        scale
    };
    let ground = |lon: f64, lat: f64| {
        let (l, b) = (lon.to_radians(), lat.to_radians());
        at(lon, lat, globe.ground_height_m(l, b))
    };
    // The pattern's scale level along each line (log2 of its period in metres): the views
    // are chosen so that it stays clear of a switch (a half) along the sampled parts.
    let level = |a: DVec3, b: DVec3| {
        let px_per_m = (px(b) - px(a)).length() / (b - a).length();
        (24.0 / px_per_m).log2()
    };
    for (name, a, b) in [
        ("at 20 km", at(9.8, -0.09, z), at(10.2, -0.09, z)),
        ("draped", ground(9.8, -0.28), ground(10.2, -0.28)),
    ] {
        let mid = a.lerp(b, 0.5);
        let ks = [
            level(a, a.lerp(b, 0.01)),
            level(mid, mid.lerp(b, 0.01)),
            level(b.lerp(a, 0.01), b),
        ];
        eprintln!("dash level {name}: {ks:.2?}");
        assert!(
            ks.iter().all(|k| (k.fract() - 0.5).abs() > 0.05),
            "{name}: levels {ks:?}"
        );
        assert!(
            ks.iter().all(|k| k.round() == ks[0].round()),
            "{name}: levels {ks:?}"
        );
    }
    let high = along_path(
        &img,
        &bg,
        &camera,
        (at(9.8, -0.09, z), at(10.2, -0.09, z)),
        MAGENTA,
    );
    check_dashes("dashes at 20 km", &high);
    // Draped: sampled along its projected ground points, a piece at a time.
    let mut draped = Vec::new();
    for i in 0..40 {
        let (l0, l1) = (9.8 + 0.01 * f64::from(i), 9.81 + 0.01 * f64::from(i));
        let piece = along_path(
            &img,
            &bg,
            &camera,
            (ground(l0, -0.28), ground(l1, -0.28)),
            MAGENTA,
        );
        let base = draped.last().map_or(0.0, |&(s, _)| s);
        draped.extend(piece.into_iter().skip(1).map(|(s, c)| (base + s, c)));
    }
    check_dashes("draped dashes", &draped);
    // Panned east by a few kilometres, the dashes stay where they were on the ground.
    let moved =
        common::camera(10.03, 0.0, 60_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let (img2, bg2) = with_and_without(&mut off, &moved, &mut layer, "dashes_panned");
    let camera2 = *off.globe().camera().expect("a frame camera");
    let globe = off.globe();
    let at2 = |lon: f64| {
        globe.world_position(Cartographic::new(
            lon.to_radians(),
            (-0.09f64).to_radians(),
            z,
        ))
    };
    let (mut same, mut total) = (0, 0);
    for i in 0..=2000 {
        let lon = 9.8 + 0.2 * f64::from(i) / 2000.0;
        let (Some(p1), Some(p2)) = (camera.project(at2(lon)), camera2.project(at2(lon))) else {
            continue;
        };
        let c1 = coverage(&img, &bg, p1.x.floor() as i64, p1.y.floor() as i64, MAGENTA);
        let c2 = coverage(
            &img2,
            &bg2,
            p2.x.floor() as i64,
            p2.y.floor() as i64,
            MAGENTA,
        );
        if c1.is_finite() && c2.is_finite() && (c1 - 0.5).abs() > 0.2 && (c2 - 0.5).abs() > 0.2 {
            total += 1;
            same += usize::from((c1 > 0.5) == (c2 > 0.5));
        }
    }
    let share = same as f64 / total.max(1) as f64;
    eprintln!("panned: {same}/{total} samples of the dashed line agree on the ground");
    assert!(
        total > 500 && share > 0.97,
        "dashes moved on the ground: {same}/{total}"
    );
}

/// Thirty named fixes crowded over the Alps and one on the far side of the planet: labels
/// sit beside their own point (at the corner the placer chose, 9 px off: the 12 px marker's
/// half and a 3 px gap), never overlap one another, show their text (the picture changes
/// inside each box), and the far one has none.
#[test]
fn named_points_get_decluttered_labels_beside_them_and_none_behind_the_planet() {
    let (w, h) = (480u32, 360u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let dir = common::scratch("vectors", "fixes");
    let mut features = Vec::new();
    let mut fixes = Vec::new();
    for k in 0..30 {
        let (lon, lat) = (7.0 + f64::from(k % 6) * 0.45, 45.6 + f64::from(k / 6) * 0.3);
        fixes.push((lon, lat));
        features.push(format!(
            r#"{{"type":"Feature","properties":{{"name":"FX{k:02}"}},"geometry":{{"type":"Point","coordinates":[{lon},{lat}]}}}}"#
        ));
    }
    features.push(
        r#"{"type":"Feature","properties":{"name":"FAR"},"geometry":{"type":"Point","coordinates":[-172.0,-46.0]}}"#
            .to_string(),
    );
    let file = write_geojson(
        &dir,
        "fixes.geojson",
        &format!(
            r#"{{"type":"FeatureCollection","features":[{}]}}"#,
            features.join(",")
        ),
    );
    let mut layer = VectorLayer::new();
    let rules = StyleRules::from_fragment("label={name}&marker-color=%23ff00ff&label-size=13")
        .expect("rules");
    let (_, ids) = layer.add_file(&file, &rules).expect("fixes");
    assert_eq!(ids.len(), 31);
    let view =
        common::camera(8.1, 46.2, 700_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let (drawn, plain) = with_and_without(&mut off, &view, &mut layer, "fix-labels");
    let stats = layer.stats();
    assert_eq!(stats.labels, 31, "{stats:?}");
    let labels: Vec<_> = layer.drawn_labels().collect();
    assert_eq!(labels.len() as u32, stats.labels_drawn);
    assert!(
        (8..30).contains(&labels.len()),
        "{} of 30 crowded labels drawn",
        labels.len()
    );
    assert!(
        labels.iter().all(|l| l.0 != ids[30]),
        "the far side's label is drawn"
    );
    let globe = off.globe();
    let camera = globe.camera().expect("a frame");
    for (i, a) in labels.iter().enumerate() {
        assert_eq!(a.3, 1.0, "a still picture shows its labels whole");
        for b in &labels[i + 1..] {
            let overlap = a.2[0] < b.2[2] && b.2[0] < a.2[2] && a.2[1] < b.2[3] && b.2[1] < a.2[3];
            assert!(!overlap, "{:?} and {:?} overlap", a, b);
        }
        // Its own point, 9 px from the box's nearest corner on both axes.
        let k = ids.iter().position(|id| *id == a.0).expect("one of ours");
        let (lon, lat) = fixes[k];
        let ground = globe.drawn_ground_m(lon.to_radians(), lat.to_radians());
        let at = camera
            .project(globe.world_position(Cartographic::from_degrees(lon, lat, ground)))
            .expect("in view");
        let dx = (at.x - f64::from(a.2[0]))
            .abs()
            .min((at.x - f64::from(a.2[2])).abs());
        let dy = (at.y - f64::from(a.2[1]))
            .abs()
            .min((at.y - f64::from(a.2[3])).abs());
        assert!(
            (dx - 9.0).abs() < 1.5 && (dy - 9.0).abs() < 1.5,
            "label {:?} is {dx:.1}, {dy:.1} px from its point {at:?}",
            a.2
        );
        // Text: the picture changed inside the box.
        let mut changed = 0;
        for y in a.2[1].ceil() as u32..a.2[3].floor() as u32 {
            for x in a.2[0].ceil() as u32..a.2[2].floor() as u32 {
                let (p, q) = (drawn.get(x, y), plain.get(x, y));
                if (0..3).any(|c| (i32::from(p[c]) - i32::from(q[c])).abs() > 40) {
                    changed += 1;
                }
            }
        }
        assert!(changed > 40, "label {:?}: {changed} pixels of text", a.2);
    }
    // Two more draw calls than without labels: leaders (none drawn) and glyphs.
    assert!(stats.draw_calls <= 4, "{stats:?}");
}

/// A deterministic random walk of `n` vertices from `from`, steps of `step` degrees.
fn random_walk(n: usize, from: [f64; 2], step: f64) -> Vec<[f64; 3]> {
    let mut s = 99u64;
    let [mut lon, mut lat] = from;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let a = (s >> 11) as f64 / (1u64 << 53) as f64 * std::f64::consts::TAU;
            lon += step * a.cos();
            lat += step * a.sin();
            [lon, lat, 0.0]
        })
        .collect()
}

#[test]
fn a_million_vertex_line_draws_in_bounded_instances_where_the_cpu_puts_it() {
    // Two lines of half a million vertices each: a wavy "coast" sampled every 2 m (all of it
    // needed only a metre from the ground), and a random walk that fills its area (no
    // tolerance a tile can show makes it sparse: the per-tile budget does). Drawn whole,
    // they were a million instances in every tile that covered them.
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let coast_lat = |lon: f64| {
        46.3 + 0.02 * (std::f64::consts::TAU * lon * 7.0).sin()
            + 0.004 * (std::f64::consts::TAU * lon * 61.0).sin()
    };
    let n = 500_000;
    let coast: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let lon = 7.0 + i as f64 / (n - 1) as f64;
            [lon, coast_lat(lon), 0.0]
        })
        .collect();
    let style = |colour: &str| {
        feature(
            0,
            &format!(
                r##"{{"type": "Feature", "properties": {{"stroke": "{colour}", "stroke-width": 3}},
                    "geometry": {{"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}}}"##
            ),
        )
    };
    let mut coast_feature = style("#ff00ff");
    coast_feature.lines = vec![coast.clone()];
    let mut walk_feature = style("#00ffff");
    walk_feature.lines = vec![random_walk(n, [7.5, 46.7], 0.0001)];
    let mut layer = VectorLayer::new();
    layer.add_batch([coast_feature, walk_feature]);
    let cam = common::camera(7.5, 46.45, 150_000.0, 0.0, -90.0, true);
    let view = placed(&mut off, &cam, (w, h));
    let (img, bg) = with_and_without(&mut off, &view, &mut layer, "million_vertices");
    let stats = layer.stats();
    let tiles = off.update(&view).draw.tiles;
    eprintln!("million vertices: {stats:?}, {tiles} tiles drawn");
    assert!(
        stats.line_instances < 60_000,
        "{} instances for {tiles} tiles",
        stats.line_instances
    );
    // The coast lies where the CPU projects it, along its whole length in view.
    let globe = off.globe();
    let camera = *globe.camera().expect("a frame camera");
    let (mut expected, mut hit) = (0usize, 0usize);
    for p in coast.iter().step_by(250) {
        let Some(px) = camera.project(on_ground(globe, p[0], p[1])) else {
            continue;
        };
        let (x, y) = (px.x.floor() as i64, px.y.floor() as i64);
        if x < 2 || y < 2 || x >= i64::from(w) - 2 || y >= i64::from(h) - 2 {
            continue;
        }
        let c = coverage(&img, &bg, x, y, MAGENTA);
        if c.is_nan() {
            continue;
        }
        expected += 1;
        hit += usize::from(c > 0.5);
    }
    assert!(expected > 500, "only {expected} coast pixels in view");
    let share = hit as f64 / expected as f64;
    assert!(share >= 0.98, "{:.1} % of the coast drawn", share * 100.0);
}

#[test]
fn a_polygon_of_200000_vertices_fills_what_a_cpu_point_in_polygon_fills_in_bounded_vertices() {
    // A wavy disc of 200,000 vertices: simplified and cut per tile, it must still cover
    // exactly what the CPU finds inside its own ring.
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let n = 200_000;
    let ring: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let r = 0.3 + 0.03 * (a * 23.0).sin() + 0.002 * (a * 401.0).sin();
            [7.5 + r * a.cos() * 1.45, 46.4 + r * a.sin(), 0.0]
        })
        .collect();
    let mut polygon = feature(
        0,
        r##"{"type": "Feature", "properties": {"fill": "#ff0000", "fill-opacity": 1, "stroke-width": 0},
            "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}}"##,
    );
    polygon.polygons = vec![vec![ring.clone()]];
    let mut layer = VectorLayer::new();
    layer.add(polygon);
    let cam = common::camera(7.5, 46.4, 100_000.0, 0.0, -90.0, true);
    let view = placed(&mut off, &cam, (w, h));
    let (img, bg) = with_and_without(&mut off, &view, &mut layer, "big_polygon");
    let stats = layer.stats();
    eprintln!("big polygon: {stats:?}");
    assert!(
        stats.fill_vertices < 300_000,
        "{} fill vertices",
        stats.fill_vertices
    );
    let globe = off.globe();
    let camera = *globe.camera().expect("a frame camera");
    let flat: Vec<[f64; 2]> = ring.iter().map(|p| [p[0], p[1]]).collect();
    let inside = |lon: f64, lat: f64| inside_any(&[vec![flat.clone()]], lon, lat);
    let (mut checked, mut wrong) = (0usize, 0usize);
    for j in 0..60 {
        for i in 0..60 {
            let lon = 6.8 + 1.4 * f64::from(i) / 59.0;
            let lat = 45.95 + 0.9 * f64::from(j) / 59.0;
            let Some(px) = camera.project(on_ground(globe, lon, lat)) else {
                continue;
            };
            let (x, y) = (px.x.floor() as i64, px.y.floor() as i64);
            // Not within 2 px of the border (a pixel is about 0.006 degrees here).
            let near = flat
                .iter()
                .step_by(10)
                .any(|p| ((p[0] - lon) * 0.69).hypot(p[1] - lat) < 0.013);
            let c = coverage(&img, &bg, x, y, [255.0, 0.0, 0.0]);
            if near || c.is_nan() {
                continue;
            }
            checked += 1;
            let want = inside(lon, lat);
            wrong += usize::from(want != (c > 0.5));
        }
    }
    assert!(checked > 1000, "only {checked} samples");
    assert!(
        wrong * 1000 <= checked,
        "{wrong} of {checked} samples differ from the CPU's point-in-polygon"
    );
}

#[test]
fn a_gpu_budget_leaves_pieces_out_instead_of_growing_and_a_file_stops_at_its_positions() {
    // The countries filled over Europe take a few MiB of fill vertices; under a 1 MiB
    // budget some tiles' pieces are left out (counted), the buffers stay within it, and
    // the frame is drawn without an error. With room, nothing is left out.
    let (w, h) = (320u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let cam = common::camera(10.0, 48.0, 3_000_000.0, 0.0, -90.0, false);
    let view = cam.view(off.globe(), 60.0, w, h);
    let countries = globus_test_support::shared_data("countries-110m.geojson");
    let rules = StyleRules::from_fragment("fill=%2300ff00&fill-opacity=1").expect("rules");
    let mut drawn = Vec::new();
    for budget in [1u64 << 20, 256 << 20] {
        let mut layer = VectorLayer::new();
        layer.set_gpu_budget(budget);
        layer.add_file(&countries, &rules).expect("countries");
        off.render_complete(&view, TIMEOUT, &mut [&mut layer])
            .expect("render");
        let s = layer.stats();
        eprintln!("budget {budget}: {s:?}");
        let buffers = u64::from(s.fill_vertices) * 32 + u64::from(s.line_instances) * 64;
        assert!(buffers <= budget, "{buffers} bytes drawn under {budget}");
        drawn.push((s.left_out, s.fill_vertices));
    }
    assert!(drawn[0].0 > 0, "nothing left out under 1 MiB: {drawn:?}");
    assert_eq!(drawn[1].0, 0, "{drawn:?}");
    assert!(drawn[1].1 > drawn[0].1, "{drawn:?}");
    // Positions: a layer that may hold 10,000 reads the countries up to the one that would
    // pass it, and says so.
    let mut layer = VectorLayer::new();
    layer.set_max_positions(10_000);
    let (loaded, ids) = layer.add_file(&countries, &rules).expect("countries");
    assert!(!ids.is_empty() && ids.len() < 177, "{} features", ids.len());
    assert!(
        loaded
            .stopped
            .as_deref()
            .is_some_and(|why| why.contains("10000 positions")),
        "{:?}",
        loaded.stopped
    );
    let held: usize = ids
        .iter()
        .map(|&id| layer.feature(id).expect("held").position_count())
        .sum();
    assert!(held <= 10_000, "{held}");
}
