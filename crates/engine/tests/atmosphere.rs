//! The sky and the haze on the GPU against the CPU's model of the same air
//! (`globus_geo::Atmosphere`, marched in f64 with 400 steps): the colour of the sky from the
//! ground at noon and at sunset, the atmosphere's rim round the planet from space, and the
//! contrast distant ground loses. Pictures go to `target/test-output/atmosphere/`.

mod common;

use std::time::Duration;

use common::camera;
use globus_engine::{
    Atmosphere, DVec3, GlobeBuilder, Headless, Lighting, RgbaImage, View, save_png,
};
use globus_geo::AtmosphereTables;

const TIMEOUT: Duration = Duration::from_secs(240);

fn shot(off: &mut Headless, view: &View, name: &str, sun: Lighting) -> RgbaImage {
    off.globe_mut().set_lighting(Some(sun));
    let frame = off.render_complete(view, TIMEOUT, &mut []).expect("render");
    assert!(frame.complete, "{name}: tiles still loading");
    let dir = globus_test_support::output_dir("atmosphere");
    save_png(&frame.image, &dir.join(format!("{name}.png"))).expect("save");
    frame.image
}

fn pixel(img: &RgbaImage, x: u32, y: u32) -> [f64; 4] {
    let i = ((y * img.width + x) * 4) as usize;
    let p = &img.pixels[i..i + 4];
    [p[0], p[1], p[2], p[3]].map(f64::from)
}

/// The shaders' tone curve and the target's sRGB encoding, to 0..255.
fn displayed(radiance: DVec3, exposure: f64) -> [f64; 3] {
    let tone = |c: f64| {
        let x = c * exposure;
        let y = x / (1.0 + 0.15 * x);
        let s = if y <= 0.003_130_8 {
            12.92 * y
        } else {
            1.055 * y.powf(1.0 / 2.4) - 0.055
        };
        255.0 * s.clamp(0.0, 1.0)
    };
    [tone(radiance.x), tone(radiance.y), tone(radiance.z)]
}

/// The model's sky through pixel (x, y) of `view`, as displayed.
fn expected_sky(
    air: &Atmosphere,
    tables: &AtmosphereTables,
    view: &View,
    sun: &Lighting,
    (x, y): (u32, u32),
) -> [f64; 3] {
    let s = air.stretch();
    let eye = view.position * s;
    let up = eye.normalize();
    let h = eye.length() - air.bottom_radius_m;
    // Any frame whose z is the eye's vertical.
    let east = DVec3::Z.cross(up).normalize();
    let north = up.cross(east);
    let local = |d: DVec3| {
        let d = (d * s).normalize();
        DVec3::new(d.dot(east), d.dot(north), d.dot(up))
    };
    let dir = view.ray_direction(f64::from(x) + 0.5, f64::from(y) + 0.5);
    let (light, _) = air.sky(
        tables,
        h,
        local(dir),
        local(sun.sun_direction),
        f64::INFINITY,
    );
    let radiance = light * std::f64::consts::PI * f64::from(sun.inscatter_gain);
    displayed(radiance, f64::from(sun.exposure))
}

/// Largest channel difference between the picture's sky and the model's over a grid of
/// uncovered pixels, and how many were compared.
fn sky_error(
    img: &RgbaImage,
    air: &Atmosphere,
    tables: &AtmosphereTables,
    view: &View,
    sun: &Lighting,
) -> (f64, u32) {
    let (mut worst, mut n) = (0.0f64, 0);
    for y in (2..img.height).step_by(9) {
        for x in (2..img.width).step_by(9) {
            let p = pixel(img, x, y);
            if p[3] == 255.0 {
                continue;
            }
            let e = expected_sky(air, tables, view, sun, (x, y));
            for c in 0..3 {
                worst = worst.max((p[c] - e[c]).abs());
            }
            n += 1;
        }
    }
    (worst, n)
}

/// Blue over red of a pixel.
fn blueness(p: [f64; 4]) -> f64 {
    p[2] / p[0].max(1.0)
}

fn brightness(p: [f64; 4]) -> f64 {
    p[0] + p[1] + p[2]
}

#[test]
fn the_sky_from_the_ground_is_the_models_blue_by_day_and_red_at_sunset() {
    let (w, h) = (160u32, 120u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let air = off.globe().atmosphere();
    assert!(!air.is_none(), "the Earth has air by default");
    let tables = AtmosphereTables::new(&air);
    // 300 m over the ground on the equator, looking south from 10 to 70 degrees up.
    let noon_view = camera(0.0, 0.0, 300.0, 180.0, 40.0, true).view(off.globe(), 60.0, w, h);
    // The Sun 60 degrees up in the north, behind the camera.
    let noon = Lighting::sun_over(0.0, 30f64.to_radians());
    let day = shot(&mut off, &noon_view, "sky_noon", noon);
    let (error, n) = sky_error(&day, &air, &tables, &noon_view, &noon);
    assert!(n > 150, "only {n} sky pixels");
    assert!(error <= 3.0, "noon sky off the model by {error:.1} of 255");
    // The top of the picture (70 degrees up) is darker and bluer than its bottom (10).
    let (top, bottom) = (pixel(&day, w / 2, 2), pixel(&day, w / 2, h - 3));
    assert!(
        brightness(top) < brightness(bottom) && blueness(top) > blueness(bottom),
        "high {top:?}, low {bottom:?}"
    );

    // The Sun on the horizon in the east: looking at it, 0 to 20 degrees up, the sky is red
    // there and bluer looking west.
    let sunset = Lighting::sun_over(89f64.to_radians(), 0.0);
    let east = camera(0.0, 0.0, 300.0, 90.0, 10.0, true).view(off.globe(), 60.0, w, h);
    let west = camera(0.0, 0.0, 300.0, 270.0, 10.0, true).view(off.globe(), 60.0, w, h);
    let towards = shot(&mut off, &east, "sky_sunset_towards", sunset);
    let away = shot(&mut off, &west, "sky_sunset_away", sunset);
    for (img, view, name) in [(&towards, &east, "towards"), (&away, &west, "away")] {
        let (error, n) = sky_error(img, &air, &tables, view, &sunset);
        assert!(n > 100, "{name}: only {n} sky pixels");
        assert!(
            error <= 4.0,
            "sunset {name}: off the model by {error:.1} of 255"
        );
    }
    // Three pixels above the horizon (the first ground row of the middle column), beside
    // the Sun's disc and opposite it: more red towards the Sun, and redder.
    let above_horizon = |img: &RgbaImage, x: u32| {
        let ground = (0..h)
            .find(|&y| pixel(img, x, y)[3] == 255.0)
            .expect("ground");
        pixel(img, x, ground - 3)
    };
    let (t, a) = (
        above_horizon(&towards, w / 2 + 20),
        above_horizon(&away, w / 2),
    );
    assert!(t[0] > 2.0 * t[2], "towards the setting Sun {t:?}");
    assert!(
        t[0] > 1.4 * a[0] && blueness(t) < blueness(a),
        "towards {t:?}, away {a:?}"
    );
    // High above, the twilight sky is bluer than at the horizon.
    let high = pixel(&away, w / 2, 2);
    assert!(
        blueness(high) > 1.5 * blueness(a),
        "high {high:?}, low {a:?}"
    );
}

#[test]
fn from_space_the_rim_glows_on_the_day_side_only() {
    let (w, h) = (320u32, 320u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    // 8,000 km over (0, 0), the Sun over 90 E: the right half is day, the left night.
    let view = camera(0.0, 0.0, 8_000_000.0, 0.0, -90.0, false).view(off.globe(), 60.0, w, h);
    let sun = Lighting::sun_over(90f64.to_radians(), 0.0);
    let img = shot(&mut off, &view, "rim", sun);
    let space = brightness(pixel(&img, 2, 2));
    let (mut day, mut night, mut rows) = (0.0, 0.0, 0);
    for y in h / 2 - 20..h / 2 + 20 {
        let covered: Vec<u32> = (0..w).filter(|&x| pixel(&img, x, y)[3] == 255.0).collect();
        let (Some(&left), Some(&right)) = (covered.first(), covered.last()) else {
            panic!("row {y} misses the planet");
        };
        // Two pixels outside the silhouette: 45 to 90 km over the limb at 45 km a pixel.
        day += brightness(pixel(&img, right + 1, y)) + brightness(pixel(&img, right + 2, y));
        night += brightness(pixel(&img, left - 1, y)) + brightness(pixel(&img, left - 2, y));
        rows += 2;
    }
    let (day, night) = (day / f64::from(rows), night / f64::from(rows));
    assert!(day > space + 60.0, "day rim {day:.0}, space {space:.0}");
    assert!(
        night < space + 6.0,
        "night rim {night:.0}, space {space:.0}"
    );
    // Without air there is no rim.
    let body = off.globe().ellipsoid();
    off.globe_mut().set_atmosphere(Atmosphere::none(&body));
    let bare = shot(&mut off, &view, "rim_airless", sun);
    let outside: f64 = (h / 2 - 20..h / 2 + 20)
        .map(|y| {
            let right = (0..w).filter(|&x| pixel(&bare, x, y)[3] == 255.0).max();
            brightness(pixel(&bare, right.expect("planet") + 1, y))
        })
        .sum::<f64>()
        / 40.0;
    assert!(
        outside < space + 3.0,
        "airless rim {outside:.0}, space {space:.0}"
    );
}

/// Standard deviation of the luminance of the covered pixels in rows y0..y1.
fn contrast(img: &RgbaImage, (y0, y1): (u32, u32)) -> f64 {
    let values: Vec<f64> = (y0..y1)
        .flat_map(|y| (0..img.width).map(move |x| (x, y)))
        .map(|(x, y)| pixel(img, x, y))
        .filter(|p| p[3] == 255.0)
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    assert!(values.len() > 200, "only {} ground pixels", values.len());
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt()
}

#[test]
fn distant_ground_loses_more_contrast_to_the_air_than_near_ground() {
    // 3 km over the procedural Alps' northern foothills looking north, just below the
    // horizon (snow-covered ranges near and far): the same picture with
    // and without air, so that what differs is the air alone.
    let (w, h) = (320u32, 180u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let view = camera(10.0, 48.0, 3_000.0, 0.0, -4.0, true).view(off.globe(), 60.0, w, h);
    let sun = Lighting::sun_over(20f64.to_radians(), 40f64.to_radians());
    let hazy = shot(&mut off, &view, "haze", sun);
    let body = off.globe().ellipsoid();
    off.globe_mut().set_atmosphere(Atmosphere::none(&body));
    let clear = shot(&mut off, &view, "haze_airless", sun);
    // Rows near the bottom (a few km away) and rows just under the horizon (over 100 km).
    let horizon = (0..h)
        .find(|&y| (0..w).filter(|&x| pixel(&clear, x, y)[3] == 255.0).count() as u32 > w / 2)
        .expect("a horizon");
    let near = (h - 30, h);
    let far = (horizon + 2, horizon + 14);
    let kept_near = contrast(&hazy, near) / contrast(&clear, near);
    let kept_far = contrast(&hazy, far) / contrast(&clear, far);
    assert!(
        kept_near > 0.7,
        "near ground keeps {kept_near:.2} of its contrast"
    );
    assert!(
        kept_far < 0.75 * kept_near,
        "far ground keeps {kept_far:.2}, near {kept_near:.2}"
    );
}

/// Over the pixels both pictures cover with ground: the mean and largest channel difference
/// (of 255) and the share of pixels with a channel more than 4 apart.
fn ground_difference(a: &RgbaImage, b: &RgbaImage) -> (f64, f64, f64, u32) {
    let (mut sum, mut worst, mut over, mut n) = (0.0, 0.0f64, 0u32, 0u32);
    for y in 0..a.height {
        for x in 0..a.width {
            let (p, q) = (pixel(a, x, y), pixel(b, x, y));
            if p[3] != 255.0 || q[3] != 255.0 {
                continue;
            }
            let d = (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f64::max);
            sum += d;
            worst = worst.max(d);
            over += u32::from(d > 4.0);
            n += 1;
        }
    }
    let n_f = f64::from(n.max(1));
    (sum / n_f, worst, f64::from(over) / n_f, n)
}

#[test]
fn the_aerial_perspective_table_draws_the_haze_the_march_does() {
    // The frame's table (32 x 32 rays, 32 slices, read at four columns per pixel) against
    // every ground pixel marching its own line of sight, in the same frames: from the ground
    // to beyond the Moon's distance, with the Sun high, low ahead and on the terminator.
    let (w, h) = (320u32, 180u32);
    let mut off = Headless::new(&GlobeBuilder::new(), w, h).expect("a GPU or lavapipe");
    let deg = f64::to_radians;
    let cases = [
        (
            "horizon",
            camera(7.6, 46.0, 1_000.0, 270.0, 0.0, true),
            (20.0, 30.0),
        ),
        (
            "into_sun",
            camera(7.6, 46.0, 1_000.0, 270.0, 0.0, true),
            (-75.0, 20.0),
        ),
        (
            "steep_30km",
            camera(7.6, 46.0, 30_000.0, 0.0, -35.0, false),
            (20.0, 40.0),
        ),
        (
            "oblique_300km",
            camera(7.6, 40.0, 300_000.0, 0.0, -30.0, false),
            (7.6, 23.0),
        ),
        (
            "planet",
            camera(10.0, 30.0, 15_000_000.0, 0.0, -90.0, false),
            (80.0, 20.0),
        ),
    ];
    for (name, spec, (sun_lon, sun_lat)) in cases {
        let view = spec.view(off.globe(), 60.0, w, h);
        let sun = Lighting::sun_over(deg(sun_lon), deg(sun_lat));
        off.globe_mut().set_marched_haze(false);
        let table = shot(&mut off, &view, &format!("table_{name}"), sun);
        off.globe_mut().set_marched_haze(true);
        let marched = shot(&mut off, &view, &format!("marched_{name}"), sun);
        let (mean, worst, over, n) = ground_difference(&table, &marched);
        eprintln!(
            "{name}: {n} ground pixels, mean {mean:.3}, largest {worst}, {:.3} % over 4",
            over * 100.0
        );
        assert!(n > 2_000, "{name}: only {n} ground pixels");
        // (From 300 km the two differ by about 1 of 255 over much of the ground: the march's
        // 8 steps against the table's 64; a 128-step march is nearer the table.)
        assert!(mean < 1.0, "{name}: mean difference {mean:.2} of 255");
        assert!(
            over < 0.01,
            "{name}: {:.2} % of pixels over 4 of 255",
            over * 100.0
        );
        assert!(worst <= 16.0, "{name}: a pixel {worst} of 255 off");
    }
}
