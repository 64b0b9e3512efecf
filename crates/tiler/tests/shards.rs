//! Jobs split into shards and merged give the same archive as one run, byte for byte.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;

use common::*;
use globus_tiler::shard::{MergeJob, ShardSpec, merge};
use globus_tiler::{ElevationEncoding, ImageFormat, JobKind};
use globus_tiling::TilingScheme;

fn split_and_merge(
    kind: JobKind,
    input: &str,
    scheme: TilingScheme,
    max: u8,
    shards: u32,
    shard_ext: &str,
    out_ext: &str,
) {
    let name = format!("{scheme}-{shards}-{}", out_ext.trim_start_matches('.'));
    let single = fresh("tiler_shards", &format!("{name}-single{out_ext}"));
    let mut j = job(kind, &[shared_data(input)], &single, scheme);
    j.max_level = Some(max);
    j.min_level = 1;
    let one = globus_tiler::run(&j).unwrap();
    let mut parts = Vec::new();
    let mut shard_tiles = 0;
    for k in 0..shards {
        let out = fresh("tiler_shards", &format!("{name}-part{k}{shard_ext}"));
        let mut js = j.clone();
        js.output = out.clone();
        js.shard = Some(ShardSpec {
            index: k,
            count: shards,
        });
        shard_tiles += globus_tiler::run(&js).unwrap().tiles;
        parts.push(out);
    }
    let merged = fresh("tiler_shards", &format!("{name}-merged{out_ext}"));
    let m = merge(&MergeJob {
        inputs: parts.clone(),
        output: merged.clone(),
        force: false,
        threads: 2,
    })
    .unwrap();
    assert_eq!(m.tiles, one.tiles, "merged tile count");
    assert!(
        shard_tiles < one.tiles,
        "the shards leave the top levels to merge"
    );
    if single.is_dir() {
        assert!(
            read_tree(&single) == read_tree(&merged),
            "{name}: trees differ"
        );
    } else {
        assert!(
            std::fs::read(&single).unwrap() == std::fs::read(&merged).unwrap(),
            "{name}: archives differ"
        );
    }
    // A missing shard is named.
    let e = merge(&MergeJob {
        inputs: parts[1..].to_vec(),
        output: fresh("tiler_shards", &format!("{name}-incomplete{out_ext}")),
        force: false,
        threads: 1,
    })
    .unwrap_err()
    .to_string();
    assert!(e.contains("shards 0 of") && e.contains("missing"), "{e}");
}

#[test]
fn imagery_shards_merge_into_the_single_run_pmtiles() {
    let kind = JobKind::Imagery {
        format: ImageFormat::Jpeg { quality: 75 },
    };
    split_and_merge(
        kind,
        "bmng-5400x2700.jpg",
        TilingScheme::Geographic,
        4,
        3,
        "",
        ".pmtiles",
    );
}

#[test]
fn elevation_shards_merge_into_the_single_run_mbtiles_and_directory() {
    let kind = JobKind::Dem {
        encoding: ElevationEncoding::Mapbox,
        height_scale: None,
    };
    split_and_merge(
        kind,
        "N57E011.hgt",
        TilingScheme::WebMercator,
        11,
        4,
        ".mbtiles",
        ".mbtiles",
    );
    split_and_merge(kind, "N57E011.hgt", TilingScheme::Geographic, 10, 2, "", "");
}
