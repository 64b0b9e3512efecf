//! LOD selection against the real terrain layer (procedural planet, loaded tiles cached), at
//! 1920x1080 along the Alps dive: the cost `globus bench` reports per frame, without the
//! rasteriser and tile generation competing for the CPU. With the Earth's air as fog, as the
//! engine selects by default (`GlobeBuilder::fog`).

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use globus_geo::{Atmosphere, Cartographic, Ellipsoid, View};
use globus_stream::{ProceduralSource, TerrainLayer, TerrainLayerOptions, TerrainSource};
use globus_tiling::{Selection, SelectionOptions, TileOracle, TileRequest, select_into};

fn loaded_layer(view: &View, options: &SelectionOptions) -> TerrainLayer {
    let source: Arc<dyn TerrainSource> = Arc::new(ProceduralSource::new(24, 26));
    let mut layer = TerrainLayer::new(source, TerrainLayerOptions::default());
    let mut sel = Selection::default();
    loop {
        select_into(view, &layer, options, &mut sel);
        if sel.requests.is_empty() {
            return layer;
        }
        // Loaded tiles are drawable here (no GPU residency to wait for).
        let to_load: Vec<TileRequest> = sel
            .requests
            .iter()
            .filter(|r| layer.get(r.key).is_none())
            .copied()
            .collect();
        let in_use: Vec<_> = sel.draw.iter().map(|d| d.key).collect();
        layer.update(&sel.draw, &in_use, &to_load);
        if to_load.len() == sel.requests.len() {
            layer.wait_for_tiles(Duration::from_millis(500));
        }
    }
}

fn selection(c: &mut Criterion) {
    let ground = ProceduralSource::new(24, 26)
        .height_at(7.6f64.to_radians(), 46f64.to_radians())
        .unwrap_or(0.0);
    for (name, alt, pitch) in [
        ("3 radii", 2.0 * 6_378_137.0, -90.0),
        ("150 km down", 150_000.0, -90.0),
        ("1 km above ground, down", ground + 1_000.0, -90.0),
        ("1 km above ground, horizon", ground + 1_000.0, 0.0),
    ] {
        let view = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, alt),
            0.0,
            f64::to_radians(pitch),
            60f64.to_radians(),
            1920,
            1080,
        );
        let fog = Some(Atmosphere::for_body(&Ellipsoid::WGS84));
        let layer = loaded_layer(
            &view,
            &SelectionOptions {
                fog,
                ..SelectionOptions::default()
            },
        );
        let options = SelectionOptions {
            occluder: *layer.occluder(),
            fog,
            ..SelectionOptions::default()
        };
        let mut sel = Selection::default();
        select_into(&view, &layer, &options, &mut sel);
        let label = format!(
            "select {name} ({} tiles, {} nodes, {} culled by the frustum, {} by the horizon)",
            sel.draw.len(),
            sel.stats.nodes_visited,
            sel.stats.culled_frustum,
            sel.stats.culled_horizon
        );
        c.bench_function(&label, |b| {
            b.iter(|| select_into(black_box(&view), &layer, &options, &mut sel))
        });
        let mut trash = vec![0u64; 4 << 20];
        c.bench_function(&format!("{label} cold"), |b| {
            b.iter_batched(
                || {
                    for (i, t) in trash.iter_mut().enumerate() {
                        *t = t.wrapping_add(i as u64);
                    }
                },
                |()| select_into(black_box(&view), &layer, &options, &mut sel),
                criterion::BatchSize::PerIteration,
            )
        });
        assert_eq!(layer.scheme(), globus_tiling::GLOBE_SCHEME);
    }
}

criterion_group!(benches, selection);
criterion_main!(benches);
