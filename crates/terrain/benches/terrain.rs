//! Micro-benchmarks of the procedural terrain: noise octaves, tile generation, meshes.

use criterion::{Criterion, criterion_group, criterion_main};
use globus_geo::DVec3;
use globus_terrain::noise::Octaves;
use std::hint::black_box;

fn noise(c: &mut Criterion) {
    let o = Octaves::new(1, 1000.0, 1);
    c.bench_function("octave", |b| {
        let mut p = DVec3::new(6_378_137.0, 1234.5, 777.0);
        b.iter(|| {
            p.x += 0.37;
            black_box(o.octave(0, black_box(p)))
        })
    });
}

criterion_group!(benches, noise);

fn noise_throughput(c: &mut Criterion) {
    let o = Octaves::new(1, 1000.0, 1);
    let pts: Vec<DVec3> = (0..1024)
        .map(|i| DVec3::new(6_378_137.0 + i as f64 * 0.37, 1234.5 + i as f64, 777.0))
        .collect();
    c.bench_function("octave x1024", |b| {
        b.iter(|| {
            let mut s = 0.0;
            for p in &pts {
                s += o.octave(0, *p);
            }
            black_box(s)
        })
    });
    c.bench_function("raw noise x1024", |b| {
        b.iter(|| {
            let mut s = 0.0;
            for p in &pts {
                s += globus_terrain::noise::gradient_noise(*p * 0.001, 5);
            }
            black_box(s)
        })
    });
}
criterion_group!(more, noise_throughput);
criterion_main!(benches, more, tilegen, adaptive);

fn tiles(c: &mut Criterion) {
    use globus_terrain::{MeshOptions, ProceduralPlanet, TileMesh};
    use globus_tiling::TileKey;
    let planet = ProceduralPlanet::new(1);
    for key in [
        TileKey::new(3, 8, 2),
        TileKey::new(12, 2_134, 1_000),
        TileKey::new(24, 8_700_000, 4_100_000),
    ] {
        c.bench_function(&format!("generate_tile level {}", key.level()), |b| {
            b.iter(|| black_box(planet.generate_tile(black_box(key))))
        });
    }
    // In the default planet's highest range (7.6 E 46 N), where ridges and gullies run.
    let alps = ProceduralPlanet::new(24);
    for key in [
        TileKey::new(10, 1_067, 250),
        TileKey::new(14, 17_075, 4_004),
    ] {
        c.bench_function(&format!("generate_tile alps level {}", key.level()), |b| {
            b.iter(|| black_box(alps.generate_tile(black_box(key))))
        });
    }
    let tile = planet.generate_tile(TileKey::new(12, 2_134, 1_000));
    for (name, options) in [
        ("build_mesh adaptive", MeshOptions::default()),
        ("build_mesh full grid", MeshOptions::FULL_GRID),
    ] {
        c.bench_function(name, |b| {
            b.iter(|| {
                black_box(TileMesh::build(
                    &tile,
                    &globus_geo::Ellipsoid::WGS84,
                    &globus_geo::Ellipsoid::WGS84,
                    &options,
                ))
            })
        });
    }
    // Morph targets (computed on the render thread as a tile goes up), against the mesh
    // build above: a level-12 tile on its level-11 parent, both cut adaptively.
    let parent_key = TileKey::new(11, 1_067, 500);
    let parent = planet.generate_tile(parent_key);
    let child = globus_tiling::GLOBE_SCHEME.children(parent_key)[0];
    let tile = planet.generate_tile(child);
    let e = globus_geo::Ellipsoid::WGS84;
    let options = MeshOptions::default();
    let parent_mesh = TileMesh::build(&parent, &e, &e, &options);
    let mesh = TileMesh::build(&tile, &e, &e, &options);
    c.bench_function("morph targets adaptive", |b| {
        b.iter(|| {
            black_box(globus_terrain::MorphVertex::towards_parent(
                black_box(&tile),
                &mesh,
                &parent,
                &parent_mesh,
                &e,
            ))
        })
    });
}
criterion_group!(tilegen, tiles);

/// RTIN and the decimator on a 257 x 257 ridged grid (the full comparison with martini and
/// delatin on 513 x 513 real data is `tools/compare-meshers.py`).
fn adaptive_meshes(c: &mut Criterion) {
    use globus_terrain::adaptive::{HeightGrid, Rtin, decimate};
    let side = 257;
    let h = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32 / 40.0, (i / side) as f32 / 40.0);
            1500.0 * (1.0 - (x.sin() * y.cos()).abs()) + 60.0 * (x * 7.1 + y * 3.3).sin()
        })
        .collect();
    let Ok(grid) = HeightGrid::new(side, h) else {
        return;
    };
    c.bench_function("rtin 257 errors", |b| {
        b.iter(|| black_box(Rtin::new(&grid)))
    });
    let rtin = Rtin::new(&grid);
    c.bench_function("rtin 257 mesh 5 m", |b| {
        b.iter(|| black_box(rtin.mesh(5.0)))
    });
    c.bench_function("decimate 257 5 m", |b| {
        b.iter(|| black_box(decimate::decimate(&grid, 5.0)))
    });
}
criterion_group!(adaptive, adaptive_meshes);
