//! Real rendering on whatever adapter wgpu finds (lavapipe in CI): the pictures are checked
//! against geometry computed independently in f64, and written to
//! `target/test-output/rendering/` to be looked at.

mod common;

use std::time::Duration;

use common::camera;
use globus_engine::{
    CameraSpec, Ellipsoid, GlobeBuilder, Headless, RenderedFrame, RgbaImage, TileKey, View,
    holes_inside, save_png,
};

const TIMEOUT: Duration = Duration::from_secs(240);

fn render(name: &str, cam: CameraSpec, width: u32, height: u32) -> (RenderedFrame, View) {
    render_with(&GlobeBuilder::new(), name, cam, width, height)
}

/// [`render`] with a globe of `builder`'s options.
fn render_with(
    builder: &GlobeBuilder,
    name: &str,
    cam: CameraSpec,
    width: u32,
    height: u32,
) -> (RenderedFrame, View) {
    let mut off = Headless::new(builder, width, height).expect("a GPU or lavapipe");
    let view = cam.view(off.globe(), 60.0, width, height);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    let dir = globus_test_support::output_dir("rendering");
    save_png(&frame.image, &dir.join(format!("{name}.png"))).expect("save");
    assert!(
        frame.complete,
        "{name}: tiles still loading after {:?}",
        TIMEOUT
    );
    assert_eq!(
        frame.report.draw.missing, 0,
        "{name}: drawn tiles not resident"
    );
    (frame, view)
}

fn covered(img: &RgbaImage, x: u32, y: u32) -> bool {
    img.pixels[((y * img.width + x) * 4 + 3) as usize] == 255
}

fn coverage(img: &RgbaImage) -> f64 {
    let n = img.pixels.chunks_exact(4).filter(|p| p[3] == 255).count();
    n as f64 / f64::from(img.width * img.height)
}

#[test]
fn planet_disc_from_three_earth_radii_matches_the_analytic_silhouette() {
    let (w, h) = (1920, 1080);
    let e = Ellipsoid::WGS84;
    let a = e.radii().x;
    let b = e.radii().z;
    // Camera on the equator 3 equatorial radii from the centre, looking at the centre.
    let (frame, _) = render(
        "orbit_3_radii",
        camera(10.0, 0.0, 2.0 * a, 0.0, -90.0, false),
        w,
        h,
    );
    // Seen from the equatorial plane at distance D the WGS84 silhouette is an ellipse with
    // angular half-extents atan(a / sqrt(D^2 - a^2)) and atan(b / sqrt(D^2 - a^2)).
    let d = 3.0 * a;
    let k = (d * d - a * a).sqrt();
    let focal_px = f64::from(h) / 2.0 / 30f64.to_radians().tan();
    let expected =
        std::f64::consts::PI * (a / k * focal_px) * (b / k * focal_px) / f64::from(w * h);
    let got = coverage(&frame.image);
    let rel = (got - expected).abs() / expected;
    assert!(
        rel < 0.02,
        "disc covers {got:.5} of the image, analytic {expected:.5} ({:.2} % off)",
        rel * 100.0
    );
    let tiles = frame.report.draw.tiles;
    assert!(tiles < 50, "{tiles} tiles drawn at 3 Earth radii");
    assert!(
        frame.report.selection.culled_horizon > 0,
        "the far side is culled by the horizon"
    );
    assert!(frame.report.draw.draw_calls <= 10);
}

#[test]
fn the_orthographic_planet_is_its_exact_silhouette_without_holes() {
    // Looking straight down on the equator with a parallel projection 14,000 km high: the
    // WGS84 outline is the ellipse of semi-axes a and b itself, whatever the eye's height.
    let (w, h) = (640u32, 480u32);
    let e = Ellipsoid::WGS84;
    let (a, b) = (e.radii().x, e.radii().z);
    let size = 14.0e6;
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let view =
        camera(10.0, 0.0, 0.0, 0.0, -90.0, false).orthographic_view(off.globe(), size, 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    let dir = globus_test_support::output_dir("rendering");
    save_png(&frame.image, &dir.join("ortho_planet.png")).expect("save");
    assert!(frame.complete);
    let metres_per_px = size / f64::from(h);
    let expected =
        std::f64::consts::PI * a * b / (metres_per_px * metres_per_px) / f64::from(w * h);
    let got = coverage(&frame.image);
    let rel = (got - expected).abs() / expected;
    assert!(
        rel < 0.01,
        "disc covers {got:.5} of the image, analytic {expected:.5} ({:.2} % off)",
        rel * 100.0
    );
    // Every pixel whose parallel ray meets the body (less the deepest trench) shows ground.
    let (inside, holes) = holes_inside(&frame.image, &view, &e.grown(-11_000.0));
    assert!(inside > 100_000, "{inside}");
    assert_eq!(
        holes, 0,
        "{holes} of {inside} pixels inside the outline show no terrain"
    );
    // At 22 km a pixel, the eight level-1 tiles meet the bound.
    assert!(
        frame.report.draw.tiles <= 16,
        "{:?}",
        frame.report.selection
    );
    // The space round it is dark (the sky is space along parallel rays).
    let corner = frame.image.get(2, 2);
    assert!(corner[..3].iter().all(|&c| c < 20), "{corner:?}");
}

/// Local orientation of the image's texture: for each 16 x 16 block, the structure tensor of
/// its luminance gradients as the doubled-angle vector `((Jxx - Jyy), 2 Jxy) / (Jxx + Jyy)`
/// (its length is the block's coherence: 0 for isotropic texture, 1 for lines). Returns the
/// mean coherence, and the mean component of that vector along the direction streaks
/// converging on the image centre would give (gradients across the radius): about 0 for
/// ground noise whatever its coherence, near the coherence for radial streaks.
fn texture_orientation(img: &RgbaImage) -> (f64, f64) {
    let (w, h) = (img.width as usize, img.height as usize);
    let lum = |x: usize, y: usize| {
        let p = &img.pixels[(y * w + x) * 4..];
        0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])
    };
    const B: usize = 16;
    let (mut coherence, mut radial, mut blocks) = (0.0, 0.0, 0);
    for by in (1..h - B).step_by(B) {
        for bx in (1..w - B).step_by(B) {
            let (mut jxx, mut jyy, mut jxy) = (0.0, 0.0, 0.0);
            for y in by..by + B {
                for x in bx..bx + B {
                    let gx = (lum(x + 1, y) - lum(x - 1, y)) * 0.5;
                    let gy = (lum(x, y + 1) - lum(x, y - 1)) * 0.5;
                    jxx += gx * gx;
                    jyy += gy * gy;
                    jxy += gx * gy;
                }
            }
            let t = jxx + jyy;
            if t <= 1e-9 {
                continue;
            }
            let (vx, vy) = ((jxx - jyy) / t, 2.0 * jxy / t);
            let centre = |b: usize, n: usize| (b + B / 2) as f64 - n as f64 / 2.0;
            let phi = centre(by, h).atan2(centre(bx, w));
            // Streaks along the radius: gradients at phi + 90 degrees, doubled: 2 phi + 180.
            let across = 2.0 * phi + std::f64::consts::PI;
            coherence += vx.hypot(vy);
            radial += vx * across.cos() + vy * across.sin();
            blocks += 1;
        }
    }
    let n = f64::from(blocks.max(1));
    (coherence / n, radial / n)
}

/// Straight down on each pole from 1 km, 100 km and 3,000 km: the reduced polar tiles
/// (a handful round the pole instead of hundreds of slivers) and their skirts leave no crack,
/// and the ground shows no radial streaks. With the plain geographic tree the streak index
/// was 0.73 from 1 km and 0.40 from 100 km (0.04 and -0.03 at 45 N), and from 100 km the
/// texture's coherence was 0.44 at the pole against 0.36 at 45 N; now it is lower there.
#[test]
fn the_poles_seen_from_above_have_no_cracks_and_no_streaks() {
    let e = Ellipsoid::WGS84;
    let (w, h) = (320, 240);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let dir = globus_test_support::output_dir("rendering");
    let mut shot = |name: &str, lat: f64, alt: f64| {
        let view = camera(0.0, lat, alt, 0.0, -90.0, true).view(off.globe(), 60.0, w, h);
        let frame = off
            .render_complete(&view, TIMEOUT, &mut [])
            .expect("render");
        save_png(&frame.image, &dir.join(format!("{name}.png"))).expect("save");
        assert!(frame.complete, "{name}: tiles still loading");
        let (inside, holes) = holes_inside(&frame.image, &view, &e.grown(-3_000.0));
        assert!(inside > 10_000, "{name}: {inside} pixels on the planet");
        assert_eq!(holes, 0, "{name}: {holes} cracks of {inside} pixels");
        (texture_orientation(&frame.image), frame.report.draw.tiles)
    };
    for (alt, km) in [(1_000.0, "1"), (100_000.0, "100"), (3_000_000.0, "3000")] {
        let ((coherence_45, _), tiles_45) = shot(&format!("lat45_from_{km}km"), 45.0, alt);
        for (lat, pole) in [(90.0, "north"), (-90.0, "south")] {
            let ((coherence, streaks), tiles) = shot(&format!("pole_{pole}_from_{km}km"), lat, alt);
            // From 3,000 km coastlines, not texels, make the gradients.
            if alt < 1e6 {
                assert!(
                    streaks < 0.15,
                    "{pole} pole from {km} km: radial streak index {streaks:.3}"
                );
            }
            if alt == 100_000.0 {
                assert!(
                    coherence <= coherence_45,
                    "{pole} pole from {km} km: coherence {coherence:.3} vs {coherence_45:.3} at 45 N"
                );
            }
            assert!(
                tiles <= tiles_45 * 2,
                "{pole} pole from {km} km: {tiles} tiles vs {tiles_45} at 45 N"
            );
        }
    }
}

/// Adaptive meshes of every size meet at tile borders of different levels (ocean tiles cut to
/// a few dozen triangles beside mountain tiles keeping most of their grid): skirts must close
/// every crack.
/// Rays that hit the ellipsoid 3 km below the surface must hit terrain (no surface is lower
/// than the sea, and meshes sag below it by far less than 3 km), and the planet fills at least
/// 10,000 pixels of the view.
fn assert_ground_closed(name: &str, img: &RgbaImage, view: &View) {
    let (inside, holes) = holes_inside(img, view, &Ellipsoid::WGS84.grown(-3_000.0));
    assert!(
        inside > 10_000,
        "{name}: the planet fills the lower part of the view"
    );
    assert_eq!(
        holes, 0,
        "{name}: {holes} background pixels inside the planet's silhouette"
    );
}

#[test]
fn mixed_level_adaptive_meshes_leave_no_cracks() {
    // Oblique views where tiles of many levels meet: over mountains, over a coast and over the
    // north pole.
    for (name, cam) in [
        (
            "mixed_levels_mountains",
            camera(7.6, 46.0, 2_500.0, 200.0, -12.0, true),
        ),
        (
            "mixed_levels_coast",
            camera(11.5, 18.0, 20_000.0, 90.0, -20.0, true),
        ),
        (
            "mixed_levels_pole",
            camera(30.0, 89.5, 20_000.0, 0.0, -25.0, true),
        ),
    ] {
        let (frame, view) = render(name, cam, 640, 360);
        let sel = &frame.report.selection;
        assert!(
            sel.max_level >= 8,
            "{name}: deepest level {}",
            sel.max_level
        );
        // The meshes are adaptive: fewer triangles than full grids would have.
        let draw = &frame.report.draw;
        let full = u64::from(draw.tiles) * u64::from(globus_render::MAX_TILE_INDICES / 3);
        assert!(
            draw.triangles < full * 9 / 10,
            "{name}: {} triangles for {} tiles",
            draw.triangles,
            draw.tiles
        );
        assert_eq!(draw.draw_calls, 2, "{name}: sky and one multi-draw");
        assert_ground_closed(name, &frame.image, &view);
    }
}

/// The default planet with some tiles failing for good: at odd levels 9 to 13, one tile in
/// three (by key). Their parents are drawn over just the failed children's quadrants.
struct FailingTiles(std::sync::Arc<dyn globus_engine::TerrainSource>);

impl FailingTiles {
    fn fails(key: TileKey) -> bool {
        let level = key.level();
        (9..=13).contains(&level) && level % 2 == 1 && (key.x() + 2 * key.y()).is_multiple_of(3)
    }
}

impl globus_stream::TileSource for FailingTiles {
    type Tile = globus_stream::TerrainData;
    fn name(&self) -> &str {
        "failing tiles"
    }
    fn scheme(&self) -> globus_tiling::TilingScheme {
        self.0.scheme()
    }
    fn load(
        &self,
        key: TileKey,
        cancel: &globus_stream::fetch::Cancel,
    ) -> Result<Option<Self::Tile>, globus_stream::SourceError> {
        if Self::fails(key) {
            return Err(globus_stream::SourceError::Failed {
                key,
                source_name: self.name().into(),
                message: "held back by the test".into(),
            });
        }
        self.0.load(key, cancel)
    }
    fn byte_size(&self, tile: &Self::Tile) -> usize {
        self.0.byte_size(tile)
    }
}

impl globus_engine::TerrainSource for FailingTiles {
    fn ellipsoid(&self) -> &Ellipsoid {
        self.0.ellipsoid()
    }
    fn occluder(&self) -> &Ellipsoid {
        self.0.occluder()
    }
    fn height_range_m(&self) -> (f64, f64) {
        self.0.height_range_m()
    }
    fn max_level(&self) -> u8 {
        self.0.max_level()
    }
    fn height_at(&self, lon_rad: f64, lat_rad: f64) -> Option<f64> {
        self.0.height_at(lon_rad, lat_rad)
    }
}

/// Where some children cannot load, their parents are drawn over just those quadrants
/// beside the loaded siblings: the ground stays closed (the midline walls under a parent's
/// quadrants cover the step to a finer sibling) and looks like the ground with everything
/// loaded.
#[test]
fn parents_drawn_in_part_beside_loaded_children_leave_no_cracks() {
    let cam = camera(7.6, 46.0, 2_500.0, 200.0, -12.0, true);
    let (w, h) = (640, 360);
    let (whole, _) = render("in_part_reference", cam, w, h);
    let mut builder = GlobeBuilder::new();
    let planet = builder.open_source().expect("the procedural planet");
    builder.source(std::sync::Arc::new(FailingTiles(planet)));
    let (frame, view) = render_with(&builder, "in_part", cam, w, h);
    let sel = &frame.report.selection;
    assert!(
        sel.drawn_in_part >= 5,
        "{} tiles drawn in part of {}",
        sel.drawn_in_part,
        sel.selected
    );
    assert_ground_closed("in_part", &frame.image, &view);
    // The parents' coarser surface stands in for the failed children: the same ground,
    // a little smoother.
    let (mut sum, mut far) = (0.0, 0u32);
    let n = (w * h) as usize;
    for (a, b) in whole
        .image
        .pixels
        .chunks_exact(4)
        .zip(frame.image.pixels.chunks_exact(4))
    {
        let d: u32 = (0..3).map(|c| u32::from(a[c].abs_diff(b[c]))).sum();
        sum += f64::from(d);
        far += u32::from(d > 96);
    }
    let mean = sum / n as f64;
    println!(
        "{} of {} tiles drawn in part; mean difference {mean:.2}, {far} pixels far off",
        sel.drawn_in_part, sel.selected
    );
    assert!(
        mean < 16.0,
        "mean difference {mean:.2} from the loaded ground"
    );
    assert!(
        f64::from(far) < 0.04 * n as f64,
        "{far} pixels far from the loaded ground"
    );
}

#[test]
fn one_metre_above_the_ground_shows_textured_ground() {
    let (w, h) = (640, 360);
    let (frame, _) = render("one_metre", camera(7.6, 46.0, 1.0, 90.0, -20.0, true), w, h);
    let img = &frame.image;
    // The lower half is ground everywhere.
    let mut lower = 0;
    for y in h / 2..h {
        for x in 0..w {
            lower += u32::from(covered(img, x, y));
        }
    }
    assert_eq!(
        lower,
        w * h / 2,
        "holes or sky in the ground below the horizon"
    );
    assert!(
        frame.report.selection.max_level >= 22,
        "max level {}",
        frame.report.selection.max_level
    );
    // Not a blurred smear: the ground near the camera has texture.
    let lum: Vec<f64> = (h * 3 / 4..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let i = ((y * w + x) * 4) as usize;
            0.3 * f64::from(img.pixels[i])
                + 0.6 * f64::from(img.pixels[i + 1])
                + 0.1 * f64::from(img.pixels[i + 2])
        })
        .collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let sd = (lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64).sqrt();
    assert!(
        sd > 2.0,
        "the ground at 1 m is featureless (luminance sd {sd:.2})"
    );
}

#[test]
fn moving_one_millimetre_at_one_metre_altitude_does_not_jitter() {
    let (w, h) = (480, 270);
    // Near the Alps and near the north pole, where f32 coordinates would be worst.
    for (name, lon, lat) in [("jitter_alps", 7.6, 46.0), ("jitter_pole", 179.9, 89.9)] {
        let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
        let cam = camera(lon, lat, 1.0, 30.0, -25.0, true);
        let view = cam.view(off.globe(), 60.0, w, h);
        let a = off
            .render_complete(&view, TIMEOUT, &mut [])
            .expect("render");
        let mut moved = view;
        moved.position += view.right() * 0.001;
        let b = off
            .render_complete(&moved, TIMEOUT, &mut [])
            .expect("render");
        let again = off
            .render_complete(&view, TIMEOUT, &mut [])
            .expect("render");
        let dir = globus_test_support::output_dir("rendering");
        save_png(&a.image, &dir.join(format!("{name}_a.png"))).expect("save");
        save_png(&b.image, &dir.join(format!("{name}_b.png"))).expect("save");
        let to = |f: &RenderedFrame| globus_test_support::image::Rgba {
            width: f.image.width,
            height: f.image.height,
            pixels: f.image.pixels.clone(),
        };
        assert_eq!(
            to(&a),
            to(&again),
            "{name}: the same view renders differently"
        );
        let mean = to(&a).mean_abs_diff(&to(&b));
        let changed = to(&a).fraction_differing(&to(&b), 24);
        // 1 mm at 1 m shifts the nearest ground by about a tenth of a pixel: tiny differences
        // along edges only. f32 world coordinates would shift whole tiles by centimetres.
        assert!(
            mean < 1.0 && changed < 0.01,
            "{name}: mean difference {mean:.3}, {:.2} % pixels changed",
            changed * 100.0
        );
        assert!(coverage(&a.image) > 0.5, "{name}: mostly ground");

        // A walk of 1 m in 4 cm steps: with f32 world coordinates (0.5 m apart out here) the
        // eye would stick, then jump by half a metre; camera-relative rendering moves the
        // picture a little at every step, and evenly.
        let mut diffs = Vec::new();
        let mut previous = to(&a);
        for step in 1..=25 {
            let mut v = view;
            v.position += view.right() * (0.04 * f64::from(step));
            let f = off.render_complete(&v, TIMEOUT, &mut []).expect("render");
            let img = to(&f);
            diffs.push(previous.mean_abs_diff(&img));
            previous = img;
        }
        let mut sorted = diffs.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let worst = sorted[sorted.len() - 1];
        assert!(
            sorted[0] > 0.05,
            "{name}: the camera moved 4 cm but the picture did not: {diffs:.2?}"
        );
        assert!(
            worst < 4.0 * median.max(0.5),
            "{name}: a 4 cm step changed the picture by {worst:.2} (median step {median:.2}): {diffs:.2?}"
        );
    }
}

/// The refinement wrapper feeds the renderer: with the planet's data cut off at level 11
/// (about 300 m samples), a view 30 m above mountains is drawn from invented tiles many levels
/// deeper, complete and without holes.
#[test]
fn refined_terrain_below_the_data_renders_without_holes() {
    let mut builder = GlobeBuilder::new();
    builder.refine_below(Some(11));
    let (w, h) = (480, 270);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let cam = camera(7.6, 46.0, 30.0, 200.0, -10.0, true);
    let view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, TIMEOUT, &mut [])
        .expect("render");
    let dir = globus_test_support::output_dir("rendering");
    save_png(&frame.image, &dir.join("refined_ground.png")).expect("save");
    assert!(frame.complete, "refined tiles still loading");
    let sel = &frame.report.selection;
    assert!(sel.max_level >= 17, "deepest level {}", sel.max_level);
    // The camera stands 30 m above the refined ground, not inside a mountain.
    assert!(coverage(&frame.image) > 0.3);
    let e = Ellipsoid::WGS84;
    let (inside, holes) = holes_inside(&frame.image, &view, &e.grown(-3_000.0));
    assert!(inside > 1_000);
    assert_eq!(holes, 0, "{holes} background pixels inside the silhouette");
}

/// Mean of the pixels' channel sum in a box (x0..x1, y0..y1) over covered pixels.
fn mean_brightness(img: &RgbaImage, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> f64 {
    let (mut sum, mut n) = (0.0, 0u32);
    for y in y0..y1 {
        for x in x0..x1 {
            if covered(img, x, y) {
                let p = img.get(x, y);
                sum += f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]);
                n += 1;
            }
        }
    }
    assert!(n > 100, "only {n} planet pixels in the box");
    sum / f64::from(n)
}

/// Renders `view` completely under `sun`, saves it as `name` and returns the picture.
fn sunlit(off: &mut Headless, view: &View, name: &str, sun: globus_engine::Lighting) -> RgbaImage {
    off.globe_mut().set_lighting(Some(sun));
    let frame = off.render_complete(view, TIMEOUT, &mut []).expect("render");
    assert!(frame.complete, "{name}: tiles still loading");
    let dir = globus_test_support::output_dir("rendering");
    save_png(&frame.image, &dir.join(format!("{name}.png"))).expect("save");
    frame.image
}

#[test]
fn the_sun_at_a_moment_lights_the_day_side_and_leaves_the_night_side_dark() {
    // Straight down on (0, 0) from 15,000 km at the March 2026 equinox: at 12:00 UTC the
    // Sun stands near the centre, at 00:00 it is behind the planet, at 06:00 it is over
    // 90 E (the right of the picture) and at 18:00 over 90 W (the left).
    let (w, h) = (240u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let view = camera(0.0, 0.0, 15_000_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let mut shot = |name: &str, unix_s: f64| {
        let sun = globus_engine::Lighting::at_time(unix_s);
        sunlit(&mut off, &view, &format!("sun_{name}"), sun)
    };
    // 2026-03-20T12:00:00Z and the hours around it.
    let noon = 1_774_008_000.0;
    let day = shot("noon", noon);
    let night = shot("midnight", noon - 43_200.0);
    let morning = shot("0600", noon - 21_600.0);
    let evening = shot("1800", noon + 21_600.0);
    let centre = (100, 140);
    let (d, n) = (
        mean_brightness(&day, centre, centre),
        mean_brightness(&night, centre, centre),
    );
    assert!(d > 4.0 * n, "day {d:.0}, night {n:.0}");
    // The planet's disc spans about x 57..183: its left and right thirds.
    let (left, right) = ((62, 100), (140, 178));
    let rows = (100, 140);
    let (ml, mr) = (
        mean_brightness(&morning, left, rows),
        mean_brightness(&morning, right, rows),
    );
    assert!(mr > 3.0 * ml, "06:00: right {mr:.0}, left {ml:.0}");
    let (el, er) = (
        mean_brightness(&evening, left, rows),
        mean_brightness(&evening, right, rows),
    );
    assert!(el > 3.0 * er, "18:00: left {el:.0}, right {er:.0}");
}

/// City lights from an equirectangular image: lit where the image is bright and the Sun is
/// down, exactly where the image puts them, and nowhere by day.
#[test]
fn night_lights_shine_where_their_image_puts_them_and_only_at_night() {
    use globus_engine::{Cartographic, FrameCamera, Lighting, NightLights};
    // 1024 x 512: a bright box over 0..20 E, 40..60 N, black elsewhere.
    let (iw, ih) = (1024u32, 512u32);
    let data = (0..ih)
        .flat_map(|y| {
            (0..iw).map(move |x| {
                let lon = (f64::from(x) + 0.5) / f64::from(iw) * 360.0 - 180.0;
                let lat = 90.0 - (f64::from(y) + 0.5) / f64::from(ih) * 180.0;
                if (0.0..20.0).contains(&lon) && (40.0..60.0).contains(&lat) {
                    255
                } else {
                    0
                }
            })
        })
        .collect();
    let lights = NightLights::from_luminance(iw, ih, data).expect("a 2:1 image");
    let (w, h) = (240u32, 240u32);
    let mut lit_builder = GlobeBuilder::new();
    lit_builder.night_lights(Some(std::sync::Arc::new(lights)));
    let mut lit = Headless::new(&lit_builder, w, h).expect("a GPU or lavapipe");
    let mut plain = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let view = camera(10.0, 50.0, 3_000_000.0, 0.0, -90.0, false).view(lit.globe(), 60.0, w, h);
    let shot = |off: &mut Headless, name: &str, sun: Lighting| {
        sunlit(off, &view, &format!("night_{name}"), sun)
    };
    // The Sun over the antimeridian (the whole view is in night), then over the view.
    let night = Lighting::sun_over(std::f64::consts::PI, 0.0);
    let day = Lighting::sun_over(10f64.to_radians(), 50f64.to_radians());
    let (lit_night, plain_night) = (
        shot(&mut lit, "lit", night),
        shot(&mut plain, "plain", night),
    );
    let (lit_day, plain_day) = (
        shot(&mut lit, "lit_day", day),
        shot(&mut plain, "plain_day", day),
    );
    let camera = FrameCamera::new(&view, 1.0);
    // Mean channel sum of the 5 x 5 pixels around where (lon, lat) is drawn.
    let at = |img: &RgbaImage, lon: f64, lat: f64| {
        let ground = Ellipsoid::WGS84.cartographic_to_ecef(Cartographic::new(
            f64::to_radians(lon),
            f64::to_radians(lat),
            0.0,
        ));
        let (px, _) = camera
            .project_with_depth(ground)
            .expect("in front of the camera");
        let (cx, cy) = (px.x as u32, px.y as u32);
        let mut sum = 0.0;
        for y in cy - 2..=cy + 2 {
            for x in cx - 2..=cx + 2 {
                assert!(covered(img, x, y), "({lon}, {lat}) is not on the planet");
                let p = img.get(x, y);
                sum += f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]);
            }
        }
        sum / 25.0
    };
    // Inside the box, 2 degrees in from each edge: lit. Outside, 2 degrees out: as without.
    for (lon, lat) in [
        (10.0, 50.0),
        (2.0, 50.0),
        (18.0, 50.0),
        (10.0, 42.0),
        (10.0, 58.0),
    ] {
        let (l, p) = (at(&lit_night, lon, lat), at(&plain_night, lon, lat));
        assert!(
            l > p + 150.0,
            "night at ({lon}, {lat}): lit {l:.0}, plain {p:.0}"
        );
    }
    for (lon, lat) in [
        (-2.0, 50.0),
        (22.0, 50.0),
        (10.0, 38.0),
        (10.0, 62.0),
        (25.0, 45.0),
    ] {
        let (l, p) = (at(&lit_night, lon, lat), at(&plain_night, lon, lat));
        assert!(
            (l - p).abs() <= 6.0,
            "night at ({lon}, {lat}): lit {l:.0}, plain {p:.0}"
        );
    }
    // By day the lights are off.
    let (l, p) = (at(&lit_day, 10.0, 50.0), at(&plain_day, 10.0, 50.0));
    assert!((l - p).abs() <= 3.0, "day: lit {l:.0}, plain {p:.0}");
}

/// The procedural planet's towns light its night side (points from orbit), and nothing by day.
#[test]
fn the_procedural_planet_has_town_lights_at_night_only() {
    use globus_engine::Lighting;
    let (w, h) = (240u32, 240u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let view = camera(10.0, 48.0, 3_000_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let mut shot = |name: &str, sun: Lighting, lights: bool| {
        off.globe_mut().set_procedural_lights(lights);
        sunlit(&mut off, &view, &format!("towns_{name}"), sun)
    };
    let night = Lighting::sun_over(std::f64::consts::PI, 0.0);
    let day = Lighting::sun_over(10f64.to_radians(), 48f64.to_radians());
    let (lit, dark) = (shot("night", night, true), shot("night_off", night, false));
    let (lit_day, plain_day) = (shot("day", day, true), shot("day_off", day, false));
    // Pixels whose channel sum the towns raise by more than 30, and by how much at most.
    let raised = |a: &RgbaImage, b: &RgbaImage| {
        let mut n = 0;
        let mut most = 0i32;
        for (p, q) in a.pixels.chunks_exact(4).zip(b.pixels.chunks_exact(4)) {
            let d: i32 = (0..3).map(|k| i32::from(p[k]) - i32::from(q[k])).sum();
            n += usize::from(d > 30);
            most = most.max(d.abs());
        }
        (n, most)
    };
    let (towns, brightest) = raised(&lit, &dark);
    // Scattered points: some, but not a glow over the whole disc (57,600 pixels).
    assert!(
        (40..6_000).contains(&towns),
        "{towns} pixels lit by towns (brightest +{brightest})"
    );
    assert!(brightest > 150, "the brightest town adds only {brightest}");
    let (by_day, most_by_day) = raised(&lit_day, &plain_day);
    assert!(
        by_day == 0 && most_by_day <= 3,
        "by day: {by_day} pixels, up to {most_by_day}"
    );
}

/// Geomorphing (issue 20): the camera stands still over the Alps while the error bound falls
/// from 8 px to 1 px, every frame loaded completely, so all that changes between two frames
/// is what the finer bound split. Without morphing a split replaces a tile's surface and
/// colour in one frame; with it, the tile starts from its parent's and grows into its own
/// as the bound keeps falling. The largest change of any frame with morphing must be at most
/// a fifth of the largest without, and no frame may stand out from the others (the change
/// is spread, not saved up). Measured at 256 x 144 over the 120 steps, on the gullied
/// mountains: at most 1.29/255 without, 0.21/255 with (median 0.08). (With 60 steps each
/// frame with morphing carries twice the change: 0.36 against 1.29, more than a fifth.)
#[test]
fn lowering_the_error_bound_grows_tiles_in_instead_of_popping_them() {
    let (w, h) = (256, 144);
    let cam = camera(7.6, 46.0, 6000.0, 200.0, -10.0, false);
    let sweep = |morph: bool| {
        let mut builder = GlobeBuilder::new();
        builder.morph(morph);
        let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
        let view = cam.view(off.globe(), 60.0, w, h);
        let frames: Vec<(View, f64)> = globus_engine::geometric_steps(8.0, 1.0, 120)
            .into_iter()
            .map(|bound| (view, bound))
            .collect();
        off.sweep(&frames, 8, TIMEOUT).expect("every frame loads")
    };
    let (popping, growing) = (sweep(false), sweep(true));
    let totals = [&popping, &growing].map(|s| (s.total_mean_abs(), s.net.map(|c| c.mean_abs)));
    eprintln!("total and net change without and with morphing: {totals:?}");
    // Morphing spreads the change over the frames and adds little to it (surfaces sliding
    // past the colour on their way): 9.63 against 8.99 of 255 added up over the frames here.
    // A morph jittering by 5 % of its range from frame to frame added 16 %.
    assert!(
        totals[1].0 <= 1.15 * totals[0].0,
        "the frames' changes add up to {} of 255 with morphing, {} without",
        totals[1].0,
        totals[0].0
    );
    let (popping, growing) = (popping.frames, growing.frames);
    let changes = |frames: &[globus_engine::SweepFrame]| -> Vec<f64> {
        frames
            .iter()
            .filter_map(|f| f.change.map(|c| c.mean_abs))
            .collect()
    };
    let (before, after) = (changes(&popping), changes(&growing));
    eprintln!("without: {before:.3?}\nwith: {after:.3?}");
    // The sweep splits: the same tiles either way, several times more at the end.
    let tiles = |f: &[globus_engine::SweepFrame]| f.iter().map(|f| f.tiles).collect::<Vec<_>>();
    assert_eq!(tiles(&popping), tiles(&growing));
    assert!(
        growing[growing.len() - 1].tiles >= 3 * growing[0].tiles,
        "{:?}",
        tiles(&growing)
    );
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let (worst_before, worst_after) = (max(&before), max(&after));
    assert!(
        worst_before > 1.0,
        "splits without morphing change {worst_before}/255 at most"
    );
    assert!(
        worst_after <= worst_before / 5.0,
        "the largest change {worst_after}/255 with morphing against {worst_before}/255 without"
    );
    let mut sorted = after.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(
        worst_after <= 4.0 * median,
        "a frame stands out: {worst_after}/255 against a median of {median}/255"
    );
}

/// wgpu's OpenGL backend takes a square texture with a multiple of 6 layers for a cube map
/// array, and the colour pool's array then sampled as black: with 1,200 slots the whole
/// landscape was drawn black on llvmpipe. Pools of any size show the same ground.
#[test]
fn the_ground_has_its_colour_whatever_the_number_of_tile_slots() {
    let (w, h) = (160, 90);
    let cam = camera(7.6, 46.0, 3000.0, 20.0, -20.0, true);
    let mut ground = Vec::new();
    for slots in [301, 300] {
        let mut builder = GlobeBuilder::new();
        builder.gpu_tiles(slots);
        let (frame, _) = render_with(&builder, &format!("slots_{slots}"), cam, w, h);
        ground.push(mean_brightness(&frame.image, (0, w), (h * 3 / 4, h)));
    }
    assert!(
        ground[0] > 60.0 && (ground[1] - ground[0]).abs() < 3.0,
        "ground brightness with 301 and 300 slots: {ground:?}"
    );
}

/// Skylight: with the real Sun's lighting (no ambient floor) the ground keeps the sky's
/// light after sunset, dimming through twilight, and is black once the sky has lost the Sun
/// (before skylight, a constant ambient term lit the night side as brightly as dusk).
#[test]
fn the_sky_lights_the_ground_through_twilight_and_not_at_night() {
    use globus_engine::Lighting;
    let (w, h) = (96u32, 64u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    off.globe_mut().set_procedural_lights(false);
    let view = camera(7.6, 46.0, 20_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let frame = Ellipsoid::WGS84.enu_frame(7.6f64.to_radians(), 46f64.to_radians());
    // Mean luminance of the picture with the Sun `deg` above the horizon in the east.
    let mut at = |deg: f64, ambient: f32| -> f64 {
        let (s, c) = deg.to_radians().sin_cos();
        let sun = Lighting {
            sun_direction: (frame.up * s + frame.east * c).normalize(),
            ambient,
            ..Lighting::at_time(0.0)
        };
        let img = sunlit(&mut off, &view, &format!("skylight_{deg}_{ambient}"), sun);
        let sum: f64 = img
            .pixels
            .chunks_exact(4)
            .map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]))
            .sum();
        sum / f64::from(3 * w * h)
    };
    let (noon, dusk, late, night) = (at(60.0, 0.0), at(-3.0, 0.0), at(-9.0, 0.0), at(-25.0, 0.0));
    assert!(
        dusk > 2.5 && dusk < 0.2 * noon && late < dusk,
        "noon {noon:.1}, 3 degrees after sunset {dusk:.2}, 9 after {late:.2}"
    );
    assert!(night < 0.5, "night without lights: {night:.2}");
    // An ambient floor shows where the sky has nothing to give.
    let floored = at(-25.0, 0.1);
    assert!(floored > 5.0, "a floor of 0.1 at night: {floored:.2}");
}

/// A viewer that shows its start view complete and then flies goes on as configured: at most
/// its uploads per frame, and a bound that settling raised comes back down once the budgets
/// have room. Settling used to leave uploads unlimited and the bound unable to fall for the
/// rest of the session (`bench --realtime`, which loads its start view first, uploaded
/// everything that arrived in every frame and kept a bound of 4.88 px to the end of the
/// path).
#[test]
fn live_frames_after_a_complete_load_upload_and_relax_as_configured() {
    let (w, h) = (320, 180);
    let mut builder = GlobeBuilder::new();
    builder.gpu_tiles(48).uploads_per_frame(2);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    // A low view towards the horizon wants more tiles than 48 slots hold: settling raises
    // the bound.
    let low = camera(7.6, 46.0, 2000.0, 20.0, -5.0, true).view(off.globe(), 60.0, w, h);
    let settled = off.render_complete(&low, TIMEOUT, &mut []).expect("render");
    assert!(settled.complete, "the low view did not settle");
    let raised = settled.report.sse_bound_px;
    assert!(raised > 2.4, "settling did not raise the bound: {raised}");
    // Live frames from far above, where everything fits.
    let high = camera(7.6, 46.0, 8_000_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let mut frames = 0;
    let mut report = off.update(&high);
    while frames < 400 && !(report.sse_bound_px == 2.0 && report.is_complete()) {
        off.globe_mut()
            .layer_mut()
            .wait_for_tiles(Duration::from_millis(20));
        report = off.update(&high);
        frames += 1;
    }
    assert_eq!(
        report.sse_bound_px, 2.0,
        "the bound stayed at {} after {frames} live frames (settled at {raised})",
        report.sse_bound_px
    );
    assert!(report.is_complete(), "the high view never completed");
    // Elsewhere, with every requested tile arrived before the next frame: uploads alone
    // hold the frames back, 2 at a time.
    let other = camera(-100.0, 40.0, 300_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let uploads = uploads_until_complete(&mut off, &other, None);
    assert!(
        uploads.iter().all(|&n| n <= 2) && uploads.contains(&2),
        "tiles uploaded per live frame, 2 configured: {uploads:?}"
    );
}

/// Tiles uploaded per frame until `view` is complete (at most 200 frames), every tile
/// requested arriving before the next frame; each frame reported as lasting `frame_s`.
fn uploads_until_complete(off: &mut Headless, view: &View, frame_s: Option<f64>) -> Vec<u32> {
    let mut uploads = Vec::new();
    for _ in 0..200 {
        if let Some(s) = frame_s {
            off.globe_mut().frame_time(s);
        }
        let report = off.update(view);
        uploads.push(report.pool.uploaded_this_frame);
        if report.is_complete() {
            break;
        }
        let until = std::time::Instant::now() + Duration::from_secs(10);
        while off.globe().layer().loading() > 0 && std::time::Instant::now() < until {
            off.globe_mut()
                .layer_mut()
                .wait_for_tiles(Duration::from_millis(50));
        }
    }
    uploads
}

/// A frame reported slower than 60 fps uploads as many tiles as the 60 fps frames in its
/// time would have: a tenth of a second is 6 frames, 12 uploads at 2 a frame.
#[test]
fn a_slow_frame_uploads_what_the_frames_in_its_time_would_have() {
    let (w, h) = (320, 180);
    let mut builder = GlobeBuilder::new();
    builder.uploads_per_frame(2);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let view = camera(-100.0, 40.0, 300_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let uploads = uploads_until_complete(&mut off, &view, Some(0.1));
    let most = uploads.iter().copied().max().unwrap_or(0);
    assert!(
        most > 2 && most <= 12,
        "tiles uploaded per 0.1 s frame, 2 per 60 fps frame: {uploads:?}"
    );
    // Reported at 60 fps or faster, frames keep to the configured 2.
    let elsewhere = camera(60.0, -20.0, 300_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let uploads = uploads_until_complete(&mut off, &elsewhere, Some(0.005));
    assert!(
        uploads.iter().all(|&n| n <= 2) && uploads.contains(&2),
        "tiles uploaded per 5 ms frame: {uploads:?}"
    );
}
