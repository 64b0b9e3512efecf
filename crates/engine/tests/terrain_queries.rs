//! Terrain queries through the public API: heights against independent reads of the SRTM
//! tile N57E011 through a pyramid `globus tile` made of it, the same on both sides of tile
//! edges; and elevation exaggeration applied alike to heights, meshes, bounds and culling.

mod common;

use std::time::Duration;

use globus_engine::{CameraSpec, Cartographic, DVec3, Ellipsoid, GlobeBuilder, Headless};
use globus_tiling::{GLOBE_SCHEME, TileKey};

const TIMEOUT: Duration = Duration::from_secs(240);

/// The SRTM3 tile N57E011 read directly: 1201 x 1201 big-endian i16 samples on the grid
/// points of 3 arc-seconds from 58 N, 11 E.
struct Hgt(Vec<i16>);

impl Hgt {
    const SIDE: usize = 1201;

    fn read() -> Self {
        let bytes = std::fs::read(globus_test_support::shared_data("N57E011.hgt")).expect("hgt");
        assert_eq!(bytes.len(), Self::SIDE * Self::SIDE * 2);
        Self(
            bytes
                .chunks_exact(2)
                .map(|b| i16::from_be_bytes([b[0], b[1]]))
                .collect(),
        )
    }

    /// Bilinear height at a longitude and latitude in degrees.
    fn height(&self, lon: f64, lat: f64) -> f64 {
        let n = (Self::SIDE - 1) as f64;
        let (x, y) = ((lon - 11.0) * n, (58.0 - lat) * n);
        let (i, j) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - i as f64, y - j as f64);
        let h = |i: usize, j: usize| f64::from(self.0[j * Self::SIDE + i]);
        let top = h(i, j) * (1.0 - fx) + h(i + 1, j) * fx;
        let bottom = h(i, j + 1) * (1.0 - fx) + h(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// The globe over a pyramid of N57E011 (Terrarium PNG, geographic, to the source's own
/// resolution), no procedural refinement below it, loaded for a view straight down from
/// 8 km over (11.95 E, 57.7 N).
fn srtm_globe(exaggeration: f64) -> Headless {
    let mut builder = common::srtm_builder("terrain_queries");
    builder.exaggeration(exaggeration);
    let mut off = Headless::new(&builder, 320, 240).expect("a GPU or lavapipe, and the pyramid");
    let cam = CameraSpec {
        lon_deg: 11.95,
        lat_deg: 57.7,
        alt_m: 8_000.0,
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    };
    let view = cam.view(off.globe(), 60.0, 320, 240);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    assert!(frame.complete, "tiles still loading");
    off
}

#[test]
fn heights_match_the_srtm_tile_and_agree_across_tile_edges() {
    let hgt = Hgt::read();
    let off = srtm_globe(1.0);
    let globe = off.globe();
    let scheme = GLOBE_SCHEME;
    let (mut worst_excess, mut sum, mut n) = (f64::NEG_INFINITY, 0.0, 0);
    let mut deepest = 0;
    for i in 0..=20 {
        for j in 0..=20 {
            let lon = 11.93 + 0.002 * f64::from(i);
            let lat = 57.68 + 0.002 * f64::from(j);
            let (lon_r, lat_r) = (lon.to_radians(), lat.to_radians());
            let h = globe
                .height_at(lon_r, lat_r)
                .expect("loaded under the camera");
            let key = scheme.tile_at(lon_r, lat_r, h.level()).expect("tile");
            let error = globe
                .layer()
                .get(key)
                .expect("loaded")
                .tile
                .geometric_error_m;
            let d = h.height_m() - hgt.height(lon, lat);
            // Terrarium stores heights to 1/256 m.
            worst_excess = worst_excess.max(d.abs() - error - 0.01);
            sum += d * d;
            n += 1;
            deepest = deepest.max(h.level());
        }
    }
    let rms = (sum / f64::from(n)).sqrt();
    println!("N57E011 through the pyramid: rms {rms:.2} m, deepest level {deepest}");
    assert!(
        worst_excess <= 0.0,
        "a height is {worst_excess:.2} m further from the SRTM tile than its tile's error"
    );
    assert!(deepest >= 11, "deepest level {deepest}: too coarse to tell");
    // At 57.7 N a reduced tile spans two geographic columns: its cells are about square on
    // the ground, no longer half as wide as tall, so 1-arcsecond data (31 x 17 m here) is
    // sampled a little more coarsely east-west at the same level (rms 5.01 m; each height
    // still within its tile's error, above).
    assert!(rms < 6.0, "rms {rms:.2} m from the SRTM tile");

    // Along the edges of the tile under the centre, whose neighbours are loaded at the same
    // level: the answer does not depend on the side a point is approached from.
    let centre = globe
        .height_at(11.95f64.to_radians(), 57.7f64.to_radians())
        .expect("h");
    let key = scheme
        .tile_at(11.95f64.to_radians(), 57.7f64.to_radians(), centre.level())
        .expect("tile");
    let rect = scheme.rect(key);
    let mut edges_checked = 0;
    for k in 1..10 {
        let t = f64::from(k) / 10.0;
        let lat = rect.south + (rect.north - rect.south) * t;
        let lon = rect.west + (rect.east - rect.west) * t;
        for (lon_a, lat_a, lon_b, lat_b) in [
            (rect.west - 1e-12, lat, rect.west + 1e-12, lat),
            (rect.east - 1e-12, lat, rect.east + 1e-12, lat),
            (lon, rect.north - 1e-12, lon, rect.north + 1e-12),
            (lon, rect.south - 1e-12, lon, rect.south + 1e-12),
        ] {
            let (Some(a), Some(b)) = (globe.height_at(lon_a, lat_a), globe.height_at(lon_b, lat_b))
            else {
                continue;
            };
            if a.level() != b.level() {
                continue;
            }
            let on = globe
                .height_at((lon_a + lon_b) / 2.0, (lat_a + lat_b) / 2.0)
                .expect("on the edge");
            assert!(
                (a.height_m() - b.height_m()).abs() < 1e-6
                    && (a.height_m() - on.height_m()).abs() < 1e-6,
                "across the edge of {key}: {} | {} | {} m",
                a.height_m(),
                on.height_m(),
                b.height_m()
            );
            edges_checked += 1;
        }
    }
    // (Reduced tiles at 57.7 N are twice as wide: fewer neighbours share the centre tile's
    // level in this 320 x 240 view, 9 of the 36 edge points.)
    assert!(
        edges_checked >= 8,
        "only {edges_checked} edge points had neighbours"
    );
}

/// Normals of the drawn surface against the SRTM tile's own slopes taken the same distance
/// apart: the slope a normal stands for (rise over run along east and north), divided by the
/// exaggeration, is the true slope, plain and raised 100 times.
#[test]
fn normals_follow_the_srtm_slopes_plain_and_raised() {
    let hgt = Hgt::read();
    let e = Ellipsoid::WGS84;
    let mut mean_errors = Vec::new();
    for factor in [1.0, 100.0] {
        let off = srtm_globe(factor);
        let globe = off.globe();
        let (mut sum, mut worst, mut n, mut steep) = (0.0, 0.0f64, 0, 0);
        for i in 0..=10 {
            for j in 0..=10 {
                let (lon, lat) = (11.93 + 0.004 * f64::from(i), 57.68 + 0.004 * f64::from(j));
                let (lon_r, lat_r) = (lon.to_radians(), lat.to_radians());
                let normal = globe.normal_at(lon_r, lat_r).expect("loaded");
                let level = globe.height_at(lon_r, lat_r).expect("loaded").level();
                let enu = e.enu_frame(lon_r, lat_r);
                // The slope the normal stands for, in true metres per metre.
                let up = normal.dot(enu.up);
                let slope = (
                    -normal.dot(enu.east) / up / factor,
                    -normal.dot(enu.north) / up / factor,
                );
                // The SRTM's, one sample spacing of that level to each side.
                let step = 180.0 / f64::from(1u32 << level) / 32.0;
                let metres = step.to_radians() * e.mean_radius();
                let reference = (
                    (hgt.height(lon + step, lat) - hgt.height(lon - step, lat))
                        / (2.0 * metres * lat_r.cos()),
                    (hgt.height(lon, lat + step) - hgt.height(lon, lat - step)) / (2.0 * metres),
                );
                let d = (slope.0 - reference.0).hypot(slope.1 - reference.1);
                steep += usize::from(reference.0.hypot(reference.1) > 0.05);
                sum += d;
                worst = worst.max(d);
                n += 1;
            }
        }
        let mean = sum / f64::from(n);
        println!(
            "normals, exaggeration {factor}: slopes off the SRTM's by {mean:.4} on average, {worst:.4} at worst ({steep} of {n} steeper than 5 %)"
        );
        assert!(steep > 10, "a flat test area");
        assert!(
            mean < 0.02 && worst < 0.1,
            "x{factor}: mean {mean:.4}, worst {worst:.4}"
        );
        mean_errors.push(mean);
    }
    // Raised, the drawn slopes are 100 times steeper, and no less faithful.
    assert!(
        mean_errors[1] < 2.0 * mean_errors[0] + 0.005,
        "{mean_errors:?}"
    );
}

/// Exaggeration 100 over real mountains of real data: true heights from the queries, drawn
/// heights 100 times, bounds holding the raised vertices, and nothing visible culled.
#[test]
fn exaggeration_raises_meshes_bounds_and_culling_together() {
    let plain = srtm_globe(1.0);
    let raised = srtm_globe(100.0);
    let e = Ellipsoid::WGS84;
    let (lon, lat) = (11.95f64.to_radians(), 57.7f64.to_radians());
    let (a, b) = (
        plain.globe().height_at(lon, lat).expect("h"),
        raised.globe().height_at(lon, lat).expect("h"),
    );
    // Queries answer true heights; the raised surface's errors are 100 times larger in drawn
    // metres, so LOD selection refined it further.
    assert!(
        (a.height_m() - b.height_m()).abs() <= a.error_m() + b.error_m(),
        "{} m at level {} vs {} m at level {}",
        a.height_m(),
        a.level(),
        b.height_m(),
        b.level()
    );
    assert!(
        b.level() > a.level(),
        "levels {} and {}",
        a.level(),
        b.level()
    );
    assert_eq!(raised.globe().exaggeration(), 100.0);
    let drawn = raised
        .globe()
        .world_position(Cartographic::new(lon, lat, b.height_m()));
    let c = e.ecef_to_cartographic(drawn).expect("on the body");
    assert!((c.height_m - 100.0 * b.height_m()).abs() < 1e-6);

    // Every loaded tile's vertices stand at 100 times their heights (the edge vertices: no
    // grid sample is dropped there), inside the tile's bounds.
    let layer = raised.globe().layer();
    let key = GLOBE_SCHEME.tile_at(lon, lat, b.level()).expect("tile");
    let data = layer.get(key).expect("loaded");
    let mesh = &data.mesh;
    let mut checked = 0;
    for v in &mesh.vertices[..mesh.vertices.len().min(4000)] {
        let p = mesh.centre
            + DVec3::new(
                v.position[0].into(),
                v.position[1].into(),
                v.position[2].into(),
            );
        assert!(
            mesh.bounds.obb.contains(p, 0.5),
            "a vertex outside its tile's bounds"
        );
        let c = e.ecef_to_cartographic(p).expect("on the body");
        let (u, w) = data.tile.rect.uv(c.lon_rad, c.lat_rad);
        let (i, j) = ((u * 32.0).round() as i32, (w * 32.0).round() as i32);
        let on_grid =
            (u * 32.0 - f64::from(i)).abs() < 1e-4 && (w * 32.0 - f64::from(j)).abs() < 1e-4;
        if on_grid && (i == 0 || j == 0 || i == 32 || j == 32) && c.height_m > -1.0 {
            let true_h = f64::from(data.tile.height_at(i, j));
            if (c.height_m - 100.0 * true_h).abs() < 0.5 {
                checked += 1;
            } else {
                // A skirt vertex hangs below its edge vertex.
                assert!(
                    c.height_m < 100.0 * true_h,
                    "{} vs 100 x {true_h}",
                    c.height_m
                );
            }
        }
    }
    assert!(checked > 20, "only {checked} edge vertices checked");
    assert!(
        data.tile.max_height_m - data.tile.min_height_m > 20.0,
        "the test tile is flat"
    );
}

/// The procedural planet raised 100 times seen from a low camera over the sea looking at the
/// horizon: mountains hundreds of kilometres tall stand far beyond the horizon of the plain
/// planet.
/// Every point of the drawn surface that a pixel sees must lie in a drawn tile: nothing
/// visible is culled by the frustum or the horizon.
#[test]
fn a_hundredfold_exaggeration_never_culls_a_visible_tile() {
    let mut builder = GlobeBuilder::new();
    builder.exaggeration(100.0);
    let (w, h) = (320, 180);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    // 10 km above the sea, 1,100 km west of a range of 2 km mountains, looking east: the
    // plain horizon is 360 km away, the raised range (over 200 km tall) stands above it.
    let cam = CameraSpec {
        lon_deg: -50.0,
        lat_deg: 48.0,
        alt_m: 10_000.0,
        heading_deg: 90.0,
        pitch_deg: 0.0,
        above_ground: true,
    };
    let view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    globus_engine::save_png(
        &frame.image,
        &globus_test_support::output_dir("terrain_queries").join("exaggerated_100.png"),
    )
    .expect("save");
    assert!(frame.complete);
    let globe = off.globe();
    let drawn: Vec<TileKey> = globe.drawn_tiles().iter().map(|d| d.key).collect();
    let scheme = GLOBE_SCHEME;
    let e = globe.ellipsoid();
    let (mut seen, mut beyond_plain_horizon) = (0, 0);
    for y in (0..h).step_by(6) {
        for x in (0..w).step_by(6) {
            let dir = view.ray_direction(f64::from(x) + 0.5, f64::from(y) + 0.5);
            let Some(p) = globe.ray_pick(view.position, dir) else {
                continue;
            };
            seen += 1;
            let c = e.ecef_to_cartographic(p).expect("on the body");
            // Would the plain planet have hidden the ground there? Then only the exaggeration
            // shows it.
            let ground = e.cartographic_to_ecef(Cartographic { height_m: 0.0, ..c });
            let to_ground = ground - view.position;
            if e.ray_hit(view.position, to_ground.normalize())
                .is_some_and(|q| (q - view.position).length() < to_ground.length() - 1.0)
            {
                beyond_plain_horizon += 1;
            }
            let covered = drawn
                .iter()
                .any(|k| scheme.rect(*k).contains(c.lon_rad, c.lat_rad));
            assert!(
                covered,
                "pixel ({x}, {y}) sees terrain at {:.3}, {:.3} that no drawn tile covers",
                c.lon_deg(),
                c.lat_deg()
            );
        }
    }
    assert!(seen > 300, "{seen} pixels see terrain");
    assert!(
        beyond_plain_horizon > 10,
        "only {beyond_plain_horizon} visible points are beyond the plain horizon: the test proves nothing"
    );
}
