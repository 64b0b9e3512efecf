//! Selection invariants over random cameras, perspective and orthographic (property tests
//! with an in-memory oracle).

use std::collections::{HashMap, HashSet};

use globus_geo::{Cartographic, Ellipsoid, View};
use globus_test_support::{LoadRule, MemoryOracle};
use globus_tiling::{Quadrants, SelectionOptions, TileKey, TileOracle, TilingScheme, select};
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct Camera {
    lon: f64,
    lat: f64,
    alt: f64,
    heading: f64,
    pitch: f64,
    width: u32,
    height: u32,
    /// An orthographic top-down view this many metres high (looking straight down from
    /// `alt`, whatever `pitch` says).
    ortho_m: Option<f64>,
}

fn camera() -> impl Strategy<Value = Camera> {
    (
        -180.0f64..180.0,
        -90.0f64..90.0,
        0.0f64..7.5,
        -180.0f64..180.0,
        -90.0f64..30.0,
        (64u32..400, 64u32..300),
        prop::option::weighted(0.25, 1.0f64..7.3),
    )
        .prop_map(
            |(lon, lat, log_alt, heading, pitch, (width, height), log_ortho)| Camera {
                lon,
                lat,
                alt: 10f64.powf(log_alt),
                heading,
                pitch,
                width,
                height,
                ortho_m: log_ortho.map(|l| 10f64.powf(l)),
            },
        )
}

/// Cameras near and over either pole, or across the antimeridian, at every altitude.
fn polar_camera() -> impl Strategy<Value = Camera> {
    (
        camera(),
        0.0f64..12.0,
        prop::bool::ANY,
        -3.0f64..3.0,
        prop::bool::ANY,
    )
        .prop_map(|(mut c, from_pole, north, lon, antimeridian)| {
            c.lat = if north {
                90.0 - from_pole
            } else {
                from_pole - 90.0
            };
            if antimeridian {
                c.lon = if lon < 0.0 { -180.0 - lon } else { 180.0 - lon };
            }
            c
        })
}

fn view_of(c: &Camera) -> View {
    let view = |pitch: f64| {
        View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(c.lon, c.lat, c.alt),
            c.heading.to_radians(),
            pitch.to_radians(),
            60f64.to_radians(),
            c.width,
            c.height,
        )
    };
    match c.ortho_m {
        Some(m) => view(-90.0).orthographic(m),
        None => view(c.pitch),
    }
}

fn oracle(scheme: TilingScheme, load: LoadRule) -> MemoryOracle {
    let mut o = MemoryOracle::new(scheme);
    o.load = load;
    o.error_variation = 0.5;
    o.leaf_level = 20;
    o
}

/// Surface points seen through a grid of pixels: the first hit of each ray with the ellipsoid.
fn visible_surface_points(view: &View) -> Vec<(f64, f64)> {
    let e = Ellipsoid::WGS84;
    let mut pts = Vec::new();
    for j in 0..12 {
        for i in 0..16 {
            let x = (f64::from(i) + 0.5) / 16.0 * f64::from(view.width_px);
            let y = (f64::from(j) + 0.5) / 12.0 * f64::from(view.height_px);
            let (origin, dir) = view.ray(x, y);
            if let Some(hit) = e.ray_hit(origin, dir)
                && let Some(c) = e.ecef_to_cartographic(hit)
            {
                pts.push((c.lon_rad, c.lat_rad));
            }
        }
    }
    pts
}

fn check_invariants(
    scheme: TilingScheme,
    cam: &Camera,
    load: LoadRule,
) -> Result<(), TestCaseError> {
    let view = view_of(cam);
    let oracle = oracle(scheme, load);
    let options = SelectionOptions {
        max_level: 20,
        ..SelectionOptions::default()
    };
    let sel = select(&view, &oracle, &options);
    let drawn: HashSet<TileKey> = sel.draw.iter().map(|d| d.key).collect();
    prop_assert_eq!(drawn.len(), sel.draw.len(), "a tile drawn twice");

    // No overlaps: a drawn tile's drawn ancestors are drawn in part, without the quadrant
    // over it.
    let parts_of: HashMap<TileKey, Quadrants> = sel.draw.iter().map(|d| (d.key, d.parts)).collect();
    for d in &sel.draw {
        prop_assert!(!d.parts.is_empty(), "{:?} drawn with no part", d.key);
        let mut k = d.key;
        while let Some(p) = scheme.parent(k) {
            if let Some(parts) = parts_of.get(&p) {
                let q = Quadrants::of_child(scheme, p, k);
                prop_assert!(
                    q.is_some_and(|q| q.0 & parts.0 == 0),
                    "{:?} and its ancestor {:?} both drawn ({:?} of it)",
                    d.key,
                    p,
                    parts
                );
            }
            k = p;
        }
        // Only loaded data is drawn: ancestors stand in for loading children.
        prop_assert!(oracle.is_loaded(d.key), "{:?} drawn but not loaded", d.key);
        // A tile drawn in part has a loaded child drawn (or refined) over the rest.
        if !d.parts.is_all() {
            prop_assert!(
                scheme.children(d.key).iter().any(|&c| oracle.is_loaded(c)),
                "{:?} drawn in part with no loaded child",
                d.key
            );
        }
    }

    // Exact coverage of the visible surface.
    let roots_loaded = scheme.roots().iter().all(|r| oracle.is_loaded(*r));
    if roots_loaded {
        for (lon, lat) in visible_surface_points(&view) {
            let Some(_) = scheme.tile_at(lon, lat, 0) else {
                continue;
            };
            // The drawn tiles over the point, level by level (a scan of every drawn tile per
            // point took minutes on views near a pole of the plain geographic grid, with tens
            // of thousands of tiles), each counted where its drawn part is: its child's
            // quadrants there (Web Mercator's halve in y, not in latitude).
            let covering = (0..=options.max_level)
                .filter_map(|level| {
                    let key = scheme.tile_at(lon, lat, level)?;
                    let parts = parts_of.get(&key)?;
                    let over = || {
                        let child = scheme.tile_at(lon, lat, level + 1)?;
                        Quadrants::of_child(scheme, key, child)
                    };
                    (parts.is_all() || over().is_some_and(|q| q.0 & parts.0 != 0)).then_some(())
                })
                .count();
            prop_assert_eq!(
                covering,
                1,
                "visible point ({}, {}) covered {} times",
                lon.to_degrees(),
                lat.to_degrees(),
                covering
            );
        }
    }

    // The error bound holds wherever the data allows; elsewhere children are on their way.
    let requested: HashSet<TileKey> = sel.requests.iter().map(|r| r.key).collect();
    for d in &sel.draw {
        if d.sse_px > options.max_sse_px
            && d.key.level() < options.max_level
            && oracle.tile(d.key).has_children
        {
            let children = scheme.children(d.key);
            prop_assert!(!children.is_empty());
            prop_assert!(
                children.iter().any(|c| requested.contains(c)),
                "{:?} has sse {} but no child requested",
                d.key,
                d.sse_px
            );
        }
    }

    // Morphing: roots show their own surface; siblings grow out of their parent together;
    // a tile whose own error is over the bound (its children loading) shows all of its own.
    let mut families: HashMap<TileKey, Vec<&globus_tiling::DrawTile>> = HashMap::new();
    for d in &sel.draw {
        if let Some(parent) = scheme.parent(d.key) {
            families.entry(parent).or_default().push(d);
        }
    }
    for d in &sel.draw {
        prop_assert!(
            (0.0..=1.0).contains(&d.morph),
            "{:?} morph {}",
            d.key,
            d.morph
        );
        let Some(parent) = scheme.parent(d.key) else {
            prop_assert_eq!(d.morph, 1.0);
            continue;
        };
        // Siblings under the bound share the family's morph.
        for s in families.get(&parent).into_iter().flatten() {
            if s.sse_px <= options.max_sse_px && d.sse_px <= options.max_sse_px {
                prop_assert_eq!(s.morph, d.morph, "{:?} and {:?}", d.key, s.key);
            }
        }
        let ratio = scheme
            .children(parent)
            .iter()
            .map(|&c| oracle.tile(c).geometric_error_m / oracle.tile(parent).geometric_error_m)
            .fold(0.0, f64::max);
        if d.sse_px > options.max_sse_px && ratio < 1.0 {
            prop_assert!(
                d.morph == 1.0,
                "{:?} over the bound at morph {}",
                d.key,
                d.morph
            );
        }
    }

    // Requests: parents are drawn, priorities descend, no tile with its descendant.
    for w in sel.requests.windows(2) {
        prop_assert!(w[0].priority >= w[1].priority);
    }
    for r in &sel.requests {
        prop_assert!(!oracle.is_loaded(r.key));
        if let Some(p) = scheme.parent(r.key) {
            // Drawn over the requested tile's area.
            let over = parts_of.get(&p).copied().unwrap_or_default();
            let q = Quadrants::of_child(scheme, p, r.key).unwrap_or_default();
            prop_assert!(
                !q.is_empty() && q.0 & over.0 == q.0,
                "{:?} requested but parent not drawn over it",
                r.key
            );
        }
    }
    let s = sel.stats;
    prop_assert_eq!(s.selected as usize, sel.draw.len());
    prop_assert!(s.nodes_visited >= s.selected + s.culled_frustum + s.culled_horizon);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn geographic_all_loaded(cam in camera()) {
        check_invariants(TilingScheme::Geographic, &cam, LoadRule::All)?;
    }

    #[test]
    fn geographic_partially_loaded(cam in camera(), p in 0.0f64..1.0, seed in any::<u64>()) {
        check_invariants(TilingScheme::Geographic, &cam, LoadRule::Random { probability: p, seed })?;
    }

    #[test]
    fn geographic_loaded_to_a_level(cam in camera(), level in 0u8..8) {
        check_invariants(TilingScheme::Geographic, &cam, LoadRule::UpToLevel(level))?;
    }

    #[test]
    fn reduced_all_loaded(cam in camera()) {
        check_invariants(TilingScheme::GeographicReduced, &cam, LoadRule::All)?;
    }

    #[test]
    fn reduced_partially_loaded(cam in camera(), p in 0.0f64..1.0, seed in any::<u64>()) {
        check_invariants(
            TilingScheme::GeographicReduced,
            &cam,
            LoadRule::Random { probability: p, seed },
        )?;
    }

    #[test]
    fn reduced_near_the_poles_and_the_antimeridian(
        cam in polar_camera(),
        p in 0.3f64..1.0,
        seed in any::<u64>(),
        level in 0u8..9,
    ) {
        check_invariants(TilingScheme::GeographicReduced, &cam, LoadRule::All)?;
        check_invariants(
            TilingScheme::GeographicReduced,
            &cam,
            LoadRule::Random { probability: p, seed },
        )?;
        check_invariants(TilingScheme::GeographicReduced, &cam, LoadRule::UpToLevel(level))?;
        check_invariants(TilingScheme::Geographic, &cam, LoadRule::Random { probability: p, seed })?;
    }

    #[test]
    fn web_mercator_partially_loaded(cam in camera(), p in 0.3f64..1.0, seed in any::<u64>()) {
        check_invariants(TilingScheme::WebMercator, &cam, LoadRule::Random { probability: p, seed })?;
    }
}

#[test]
fn unloaded_roots_are_requested_first() {
    let o = oracle(TilingScheme::Geographic, LoadRule::UpToLevel(0));
    let far = Camera {
        lon: 0.0,
        lat: 0.0,
        alt: 2e7,
        heading: 0.0,
        pitch: -90.0,
        width: 800,
        height: 600,
        ortho_m: None,
    };
    let sel = select(&view_of(&far), &o, &SelectionOptions::default());
    // From 20,000 km the level-0 tiles are far too coarse: their children are wanted.
    assert!(!sel.requests.is_empty());
    assert!(sel.requests.iter().all(|r| r.key.level() == 1));
    assert!(sel.draw.iter().all(|d| d.key.level() == 0));
}

#[test]
fn no_data_stops_refinement_and_keeps_the_ancestor() {
    let mut o = oracle(TilingScheme::Geographic, LoadRule::All);
    let near_alps = Camera {
        lon: 7.6,
        lat: 46.0,
        alt: 2000.0,
        heading: 0.0,
        pitch: -90.0,
        width: 640,
        height: 480,
        ortho_m: None,
    };
    let view = view_of(&near_alps);
    let full = select(&view, &o, &SelectionOptions::default());
    let deep = full.stats.max_level;
    let cut = TilingScheme::Geographic
        .tile_at(7.6f64.to_radians(), 46f64.to_radians(), 8)
        .expect("valid");
    o.no_data = cut.children().expect("children").to_vec();
    let sel = select(&view, &o, &SelectionOptions::default());
    assert!(deep > 9);
    assert!(
        sel.draw.iter().any(|d| d.key == cut),
        "the ancestor covers the no-data area"
    );
    assert!(sel.requests.is_empty());
}

#[test]
fn a_loading_child_leaves_only_its_quadrant_to_its_parent() {
    // Straight down on the Alps from 30 km, everything loaded but one child of the level-8
    // tile under the eye (and its descendants): that tile is drawn over its missing child's
    // quadrant only, the child is requested, and the rest of the view keeps its detail.
    let scheme = TilingScheme::Geographic;
    let cam = Camera {
        lon: 7.6,
        lat: 46.0,
        alt: 30_000.0,
        heading: 0.0,
        pitch: -90.0,
        width: 640,
        height: 480,
        ortho_m: None,
    };
    let view = view_of(&cam);
    let mut o = oracle(scheme, LoadRule::All);
    o.error_variation = 0.0;
    let full = select(&view, &o, &SelectionOptions::default());
    let parent = scheme
        .tile_at(7.6f64.to_radians(), 46f64.to_radians(), 8)
        .expect("valid");
    let children = scheme.children(parent);
    let missing = children.as_slice()[3];
    o.unloaded = vec![missing];
    let sel = select(&view, &o, &SelectionOptions::default());
    let drawn = sel
        .draw
        .iter()
        .find(|d| d.key == parent)
        .expect("the parent stands in for its missing child");
    assert_eq!(
        Some(drawn.parts),
        Quadrants::of_child(scheme, parent, missing)
    );
    assert_eq!(drawn.parts.count(), 1);
    assert!(sel.requests.iter().any(|r| r.key == missing));
    // The loaded siblings are refined as deep as with everything loaded.
    for &sibling in &children.as_slice()[..3] {
        let deepest = |s: &globus_tiling::Selection| {
            s.draw
                .iter()
                .filter(|d| scheme.contains(sibling, d.key))
                .map(|d| d.key.level())
                .max()
        };
        assert_eq!(deepest(&sel), deepest(&full), "under {sibling:?}");
    }
    // With no child loaded, the parent is drawn whole (one range of its mesh).
    o.unloaded = children.as_slice().to_vec();
    let sel = select(&view, &o, &SelectionOptions::default());
    let drawn = sel.draw.iter().find(|d| d.key == parent).expect("drawn");
    assert!(drawn.parts.is_all());
}

#[test]
fn an_orthographic_view_selects_by_its_scale_not_by_the_eye_height() {
    // The same 200 km orthographic view from 20 km and from 2,000 km above the ground: the
    // picture is the same, so is the cut, and its finest tiles meet the bound at that scale.
    let o = oracle(TilingScheme::Geographic, LoadRule::All);
    let at = |alt: f64| Camera {
        lon: 7.6,
        lat: 46.0,
        alt,
        heading: 30.0,
        pitch: -90.0,
        width: 800,
        height: 600,
        ortho_m: Some(200_000.0),
    };
    let options = SelectionOptions::default();
    let low = select(&view_of(&at(20_000.0)), &o, &options);
    let high = select(&view_of(&at(2.0e6)), &o, &options);
    let keys = |s: &globus_tiling::Selection| {
        let mut k: Vec<TileKey> = s.draw.iter().map(|d| d.key).collect();
        k.sort();
        k
    };
    assert_eq!(keys(&low), keys(&high));
    assert!(!low.draw.is_empty());
    for d in &low.draw {
        assert!(
            d.sse_px <= options.max_sse_px,
            "{:?}: {} px",
            d.key,
            d.sse_px
        );
    }
    // One scale everywhere: the cut spans few levels (the test oracle's errors vary by half).
    let levels = |s: &globus_tiling::Selection| {
        let l = s.draw.iter().map(|d| d.key.level());
        (l.clone().min().unwrap_or(0), l.max().unwrap_or(0))
    };
    let (lo, hi) = levels(&low);
    assert!(hi - lo <= 2, "orthographic cut spans levels {lo}..{hi}");
}
