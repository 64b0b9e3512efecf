//! LOD selection cost with an in-memory oracle (bounds cached), along views of the Alps dive.
//! The real per-frame figures over the whole path come from `globus bench`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use globus_geo::{Cartographic, Ellipsoid, View};
use globus_test_support::{LoadRule, MemoryOracle};
use globus_tiling::{Selection, SelectionOptions, TilingScheme, select_into};

fn views() -> Vec<(&'static str, View)> {
    let v = |alt: f64, heading: f64, pitch: f64| {
        View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, alt),
            heading.to_radians(),
            pitch.to_radians(),
            60f64.to_radians(),
            1920,
            1080,
        )
    };
    vec![
        ("orbit 3 radii", v(2.0 * 6_378_137.0, 0.0, -90.0)),
        ("100 km down", v(100_000.0, 0.0, -90.0)),
        ("3 km horizon", v(3_000.0, 0.0, 0.0)),
    ]
}

fn selection(c: &mut Criterion) {
    let mut oracle = MemoryOracle::new(TilingScheme::Geographic);
    oracle.load = LoadRule::All;
    oracle.leaf_level = 24;
    oracle.root_error_m = 60_000.0;
    let options = SelectionOptions::default();
    let mut out = Selection::default();
    for (name, view) in views() {
        // Warm the bounds cache so the bench measures selection, not bound computation.
        select_into(&view, &oracle, &options, &mut out);
        c.bench_function(&format!("select {name} ({} tiles)", out.draw.len()), |b| {
            b.iter(|| select_into(black_box(&view), &oracle, &options, &mut out))
        });
    }
}

criterion_group!(benches, selection);
criterion_main!(benches);
