//! `globus mesh` as a user runs it, and its quantized-mesh files checked against two
//! independent implementations: the PyPI packages `quantized-mesh-tile` (reads what Globus
//! writes) and `quantized-mesh-encoder` (writes what Globus reads).

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{fails_with_one_line, globus, json, s};

use globus_geo::{DVec3, Ellipsoid};
use globus_terrain::encoding::ElevationEncoding;
use globus_terrain::quantized_mesh::{
    QuantizedMesh, QuantizedMeshOptions, TileProjection, WaterMask, from_adaptive_mesh,
    oct_decode_u8,
};
use globus_tiling::{TileKey, TilingScheme};
use serde_json::Value;

fn globus_json(args: &[&str]) -> Value {
    json(&globus(args))
}

fn scratch(name: &str) -> PathBuf {
    common::scratch("mesh_cli", name)
}

fn python(args: &[&str]) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/qm_peers.py");
    let out = Command::new("python3")
        .arg(script)
        .args(args)
        .output()
        .expect("python3 (with quantized-mesh-tile and quantized-mesh-encoder) must be installed");
    assert!(
        out.status.success(),
        "qm_peers.py {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A `side` x `side` window of the SRTM file from row `row0`, column `col0` (row 0 and
/// columns 640 on hold its hilliest part).
fn srtm_window(side: usize, row0: usize, col0: usize) -> Vec<f32> {
    let bytes = std::fs::read(globus_test_support::shared_data("N57E011.hgt")).unwrap();
    let n = ((bytes.len() / 2) as f64).sqrt() as usize;
    let mut h = Vec::with_capacity(side * side);
    for y in row0..row0 + side {
        for x in col0..col0 + side {
            let i = 2 * (y * n + x);
            h.push(f32::from(i16::from_be_bytes([bytes[i], bytes[i + 1]])));
        }
    }
    h
}

fn write_terrarium(path: &Path, side: usize, heights: &[f32]) {
    let mut rgb = Vec::with_capacity(side * side * 3);
    for &h in heights {
        rgb.extend_from_slice(&ElevationEncoding::Terrarium.encode(f64::from(h)));
    }
    image::save_buffer(path, &rgb, side as u32, side as u32, image::ColorType::Rgb8).unwrap();
}

#[test]
fn both_methods_keep_the_bound_on_real_terrain() {
    let dir = scratch("bound");
    let png = dir.join("srtm.png");
    write_terrarium(&png, 257, &srtm_window(257, 0, 640));
    let mut triangles = Vec::new();
    for method in ["rtin", "decimate"] {
        let r = globus_json(&[
            "mesh",
            "--in",
            s(&png),
            "--encoding",
            "terrarium",
            "--max-error",
            "2",
            "--method",
            method,
            "--json",
        ]);
        assert_eq!(r["grid"], 257);
        assert!(
            r["max_error_m"].as_f64().unwrap() <= 2.0 + 1e-3,
            "{method}: {r}"
        );
        let t = r["triangles"].as_u64().unwrap();
        assert!(t > 2 && t < 2 * 256 * 256 / 2, "{method}: {t} triangles");
        assert!(r["build_ms"].as_f64().unwrap() > 0.0);
        triangles.push(t);
    }
    assert!(triangles[1] < triangles[0], "decimate {triangles:?}");
}

#[test]
fn tiles_written_by_globus_tile_are_resampled_to_a_power_of_two_plus_one() {
    let dir = scratch("tiler_tile");
    let out = dir.join("pyramid");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let o = globus(&[
        "tile",
        "dem",
        "--in",
        s(&hgt),
        "--out",
        s(&out),
        "--max-level",
        "7",
        "--min-level",
        "7",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let tile = std::fs::read_dir(out.join("7"))
        .unwrap()
        .flat_map(|x| std::fs::read_dir(x.unwrap().path()).unwrap())
        .map(|f| f.unwrap().path())
        .next()
        .unwrap();
    let qm = dir.join("tile.terrain");
    let r = globus_json(&[
        "mesh",
        "--in",
        s(&tile),
        "--encoding",
        "terrarium",
        "--max-error",
        "5",
        "--out",
        s(&qm),
        "--json",
    ]);
    assert_eq!(r["resampled_from"], 256);
    assert_eq!(r["grid"], 257);
    // Placed by its path .../7/X/Y.png: the header centre lies on that tile.
    let d = globus_json(&["mesh", "--in", s(&qm), "--json"]);
    assert_eq!(d["triangles"], r["triangles"]);
    let c = &d["centre"];
    let centre = DVec3::new(
        c[0].as_f64().unwrap(),
        c[1].as_f64().unwrap(),
        c[2].as_f64().unwrap(),
    );
    let carto = Ellipsoid::WGS84.ecef_to_cartographic(centre).unwrap();
    let (lon, lat) = (carto.lon_rad.to_degrees(), carto.lat_rad.to_degrees());
    assert!(
        (11.0..=12.5).contains(&lon) && (55.5..=58.5).contains(&lat),
        "{lon} {lat}"
    );
}

/// Globus writes, quantized-mesh-tile reads: same vertices (within one quantum), same
/// triangles, same edge lists, normals pointing up.
#[test]
fn quantized_mesh_tile_reads_what_globus_writes() {
    let dir = scratch("to_python");
    let png = dir.join("srtm.png");
    let side = 129;
    let heights = srtm_window(side, 64, 700);
    write_terrarium(&png, side, &heights);
    let (qm, dump) = (dir.join("tile.terrain.gz"), dir.join("mesh.json"));
    let key = "9/544/92";
    globus_json(&[
        "mesh",
        "--in",
        s(&png),
        "--encoding",
        "terrarium",
        "--max-error",
        "1",
        "--tile",
        key,
        "--out",
        s(&qm),
        "--dump",
        s(&dump),
        "--json",
    ]);
    let rect = TilingScheme::Geographic.rect(TileKey::new(9, 544, 92));
    let [w, so, e, n] = rect.to_degrees();
    let py = python(&[
        "read",
        s(&qm),
        &w.to_string(),
        &so.to_string(),
        &e.to_string(),
        &n.to_string(),
        "0",
    ]);
    let mesh: Value = serde_json::from_str(&std::fs::read_to_string(&dump).unwrap()).unwrap();
    let verts = mesh["vertices"].as_array().unwrap();
    let coords = py["lon_lat_h"].as_array().unwrap();
    assert_eq!(coords.len(), verts.len());
    let (lo, hi) = (
        py["min_height"].as_f64().unwrap(),
        py["max_height"].as_f64().unwrap(),
    );
    let cells = (side - 1) as f64;
    for (v, c) in verts.iter().zip(coords) {
        let (x, y) = (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
        let lon = w + (e - w) * x / cells;
        let lat = n - (n - so) * y / cells;
        let h = f64::from(heights[y as usize * side + x as usize]);
        let c: Vec<f64> = c
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(
            (c[0] - lon).abs() <= (e - w) / 32767.0,
            "lon {} vs {lon}",
            c[0]
        );
        assert!(
            (c[1] - lat).abs() <= (n - so) / 32767.0,
            "lat {} vs {lat}",
            c[1]
        );
        assert!(
            (c[2] - h).abs() <= (hi - lo) / 32767.0 + 0.01,
            "h {} vs {h}",
            c[2]
        );
    }
    let ours: Vec<u64> = mesh["triangles"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|t| t.as_array().unwrap().iter().map(|i| i.as_u64().unwrap()))
        .collect();
    let theirs: Vec<u64> = py["indices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i.as_u64().unwrap())
        .collect();
    assert_eq!(ours, theirs);
    for (edge, column, value) in [
        ("west", 0, 0.0),
        ("east", 0, cells),
        ("north", 1, 0.0),
        ("south", 1, cells),
    ] {
        let mut listed: Vec<u64> = py[edge]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i.as_u64().unwrap())
            .collect();
        let mut expected: Vec<u64> = (0..verts.len() as u64)
            .filter(|&i| verts[i as usize][column].as_f64().unwrap() == value)
            .collect();
        listed.sort_unstable();
        expected.sort_unstable();
        assert_eq!(listed, expected, "{edge} edge");
    }
    let up = Ellipsoid::WGS84.geodetic_normal_from_lon_lat(rect.centre().0, rect.centre().1);
    // Their decoding of our oct-encoded normals agrees with ours, and they point up.
    let ours = QuantizedMesh::decode(&std::fs::read(&qm).unwrap()).unwrap();
    let normals = ours.normals.unwrap();
    let theirs = py["normals"].as_array().unwrap();
    assert_eq!(theirs.len(), normals.len());
    for (t, o) in theirs.iter().zip(&normals) {
        let t = DVec3::new(
            t[0].as_f64().unwrap(),
            t[1].as_f64().unwrap(),
            t[2].as_f64().unwrap(),
        );
        assert!(t.dot(oct_decode_u8(*o)) > 0.9999, "normal {t} vs {o:?}");
        assert!(t.dot(up) > 0.5, "normal {t}");
    }
}

/// A 256 x 256 water mask written by Globus comes back byte for byte.
#[test]
fn quantized_mesh_tile_reads_a_globus_water_mask() {
    let dir = scratch("water_mask");
    let side = 33;
    let grid = globus_terrain::adaptive::HeightGrid::new(side, srtm_window(side, 10, 660)).unwrap();
    let mesh = globus_terrain::adaptive::Rtin::new(&grid).mesh(0.5);
    let rect = TilingScheme::Geographic.rect(TileKey::new(10, 1089, 184));
    let mask: Vec<u8> = (0..65536u32)
        .map(|i| if (i / 256 + i % 256) % 7 == 0 { 255 } else { 0 })
        .collect();
    let options = QuantizedMeshOptions {
        normals: true,
        water_mask: Some(WaterMask::Grid(mask.clone())),
        ..QuantizedMeshOptions::default()
    };
    let qm = from_adaptive_mesh(
        &mesh,
        &grid,
        &rect,
        TileProjection::Geographic,
        &Ellipsoid::WGS84,
        &options,
    );
    let path = dir.join("masked.terrain");
    std::fs::write(&path, qm.encode(false)).unwrap();
    let [w, so, e, n] = rect.to_degrees();
    let py = python(&[
        "read",
        s(&path),
        &w.to_string(),
        &so.to_string(),
        &e.to_string(),
        &n.to_string(),
        "1",
    ]);
    let rows = py["watermask"].as_array().unwrap();
    let flat: Vec<u8> = rows
        .iter()
        .flat_map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap() as u8)
        })
        .collect();
    assert_eq!(flat, mask);
}

/// quantized-mesh-encoder writes, Globus reads: every triangle's corners at the positions the
/// encoder was given, within one quantum; extensions decoded.
#[test]
fn globus_reads_what_quantized_mesh_encoder_writes() {
    let dir = scratch("from_python");
    let path = dir.join("encoder.terrain");
    let py = python(&["write", s(&path)]);
    let d = globus_json(&["mesh", "--in", s(&path), "--json"]);
    assert_eq!(d["vertices"], 81);
    assert_eq!(d["triangles"], 128);
    assert_eq!(d["water_mask"], 255);
    assert_eq!(d["normals"], true);
    let qm = QuantizedMesh::decode(&std::fs::read(&path).unwrap()).unwrap();
    let positions = py["positions"].as_array().unwrap();
    let indices = py["indices"].as_array().unwrap();
    let b: Vec<f64> = py["bounds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (lo, hi) = (
        f64::from(qm.header.min_height_m),
        f64::from(qm.header.max_height_m),
    );
    for (k, i) in indices.iter().enumerate() {
        let want: Vec<f64> = positions[i.as_u64().unwrap() as usize]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let v = qm.indices[k] as usize;
        let lon = b[0] + (b[2] - b[0]) * f64::from(qm.u[v]) / 32767.0;
        let lat = b[1] + (b[3] - b[1]) * f64::from(qm.v[v]) / 32767.0;
        assert!(
            (lon - want[0]).abs() <= (b[2] - b[0]) / 32767.0,
            "corner {k}: lon {lon} vs {}",
            want[0]
        );
        assert!(
            (lat - want[1]).abs() <= (b[3] - b[1]) / 32767.0,
            "corner {k}: lat {lat} vs {}",
            want[1]
        );
        assert!(
            (qm.height_m(v) - want[2]).abs() <= (hi - lo) / 32767.0 + 1e-3,
            "corner {k}: height"
        );
    }
    // The encoder's normals face away from the globe at the patch.
    let up = qm.header.centre.normalize();
    for n in qm.normals.as_ref().unwrap() {
        assert!(oct_decode_u8(*n).dot(up) > 0.5);
    }
    // The peak of the hill sits where the encoder put it: the highest vertex is (i, j) = (4, 3).
    let top = (0..qm.vertex_count())
        .max_by_key(|&v| qm.height[v])
        .unwrap();
    // (The encoder truncates where Globus rounds: allow one quantum.)
    let (u, v) = (f64::from(qm.u[top]), f64::from(qm.v[top]));
    assert!(
        (u - 4.0 / 8.0 * 32767.0).abs() <= 1.0 && (v - 3.0 / 8.0 * 32767.0).abs() <= 1.0,
        "peak at {u}, {v}"
    );
}

#[test]
fn bad_input_gets_one_line() {
    let dir = scratch("bad");
    let png = dir.join("ok.png");
    write_terrarium(&png, 17, &vec![10.0; 17 * 17]);
    let odd = dir.join("odd.png");
    write_terrarium(&odd, 100, &vec![10.0; 100 * 100]);
    let wide = dir.join("wide.png");
    image::save_buffer(
        &wide,
        &vec![0u8; 33 * 17 * 3],
        33,
        17,
        image::ColorType::Rgb8,
    )
    .unwrap();
    let junk = dir.join("junk.terrain");
    std::fs::write(&junk, b"this is not a terrain tile at all").unwrap();
    let cut = dir.join("cut.terrain");
    let full = globus_terrain::adaptive::HeightGrid::new(17, srtm_window(17, 0, 650)).unwrap();
    let mesh = globus_terrain::adaptive::Rtin::new(&full).mesh(0.0);
    let rect = TilingScheme::Geographic.rect(TileKey::new(5, 33, 4));
    let bytes = from_adaptive_mesh(
        &mesh,
        &full,
        &rect,
        TileProjection::Geographic,
        &Ellipsoid::WGS84,
        &QuantizedMeshOptions::default(),
    )
    .encode(false);
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.join("x.terrain");
    // Pixels that cannot hold an RGB encoding (decoded as Terrarium before, without a word).
    let grey = dir.join("grey.png");
    image::save_buffer(&grey, &vec![90u8; 33 * 33], 33, 33, image::ColorType::L8).unwrap();
    let grey16 = dir.join("grey16.png");
    let g16: Vec<u8> = (0..33 * 33).flat_map(|_| 1000u16.to_be_bytes()).collect();
    image::save_buffer(&grey16, &g16, 33, 33, image::ColorType::L16).unwrap();
    let colour16 = dir.join("colour16.png");
    image::save_buffer(
        &colour16,
        &vec![7u8; 33 * 33 * 6],
        33,
        33,
        image::ColorType::Rgb16,
    )
    .unwrap();
    // Random colours read as Mapbox: heights of up to 1.6e6 m.
    let noise = dir.join("noise.png");
    let rgb: Vec<u8> = (0..33 * 33 * 3).map(|i| (i * 7919 % 251) as u8).collect();
    image::save_buffer(&noise, &rgb, 33, 33, image::ColorType::Rgb8).unwrap();
    // A valid mesh request for `input`, then `extra` arguments.
    let mesh = |input: &Path, extra: &[&str]| {
        let mut args = vec!["--in".to_owned(), s(input).to_owned()];
        for a in ["--encoding", "terrarium", "--max-error", "1"]
            .iter()
            .chain(extra)
        {
            args.push((*a).to_owned());
        }
        args
    };
    let own = |args: &[&str]| args.iter().map(|a| (*a).to_owned()).collect::<Vec<_>>();
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        (
            own(&["--in", s(&png), "--max-error", "1"]),
            vec!["--encoding"],
        ),
        (
            own(&["--in", s(&png), "--encoding", "terrarium"]),
            vec!["--max-error"],
        ),
        (
            own(&[
                "--in",
                s(&png),
                "--encoding",
                "terrarium",
                "--max-error",
                "-1",
            ]),
            vec!["non-negative"],
        ),
        (
            own(&[
                "--in",
                s(&png),
                "--encoding",
                "elevation",
                "--max-error",
                "1",
            ]),
            vec!["elevation"],
        ),
        (mesh(&png, &["--method", "fast"]), vec!["fast"]),
        (mesh(&grey, &[]), vec!["grey.png", "greyscale PNG"]),
        (mesh(&grey16, &[]), vec!["grey16.png", "greyscale PNG"]),
        (mesh(&colour16, &[]), vec!["colour16.png", "16-bit colour"]),
        (
            own(&[
                "--in",
                s(&noise),
                "--encoding",
                "mapbox",
                "--max-error",
                "5",
            ]),
            vec!["noise.png", "beyond any height", "wrong --encoding"],
        ),
        (mesh(&odd, &[]), vec!["odd.png", "2^k"]),
        (mesh(&wide, &[]), vec!["wide.png", "not square"]),
        (own(&["--in", s(&junk)]), vec!["junk.terrain"]),
        (
            own(&["--in", s(&cut)]),
            vec!["cut.terrain", "quantized-mesh"],
        ),
        (
            own(&["--in", "/nonexistent/t.png"]),
            vec!["/nonexistent/t.png"],
        ),
        (mesh(&png, &["--out", s(&out)]), vec!["--tile"]),
        (
            mesh(&png, &["--out", s(&out), "--tile", "3/99/0"]),
            vec!["3/99/0"],
        ),
    ];
    for (args, needles) in cases {
        let mut all = vec!["mesh"];
        all.extend(args.iter().map(String::as_str));
        fails_with_one_line(&all, &needles);
    }
}

/// Four tiles of a pyramid (`Z/X/Y.png`) cut from one surface, sharing their edge samples:
/// meshed one by one, a tile's normals on an edge it shares with a neighbour are the
/// neighbour's there, to the bit (central differences over the same samples); a tile meshed
/// with no neighbours beside it (one-sided differences on its edges) differs.
#[test]
fn normals_agree_across_tile_edges_in_a_pyramid() {
    let side = 33;
    let (z, x0, y0) = (12u8, 4300u32, 1200u32);
    // Hills about a kilometre across on samples about 150 m apart.
    let height = |gx: usize, gy: usize| {
        let (gx, gy) = (gx as f64, gy as f64);
        (300.0 * (0.5 * gx).sin() * (0.37 * gy).cos() + 2.0 * gx) as f32
    };
    let tile_heights = |tx: u32, ty: u32| -> Vec<f32> {
        let (ox, oy) = (
            (tx - x0) as usize * (side - 1),
            (ty - y0) as usize * (side - 1),
        );
        (0..side * side)
            .map(|k| height(ox + k % side, oy + k / side))
            .collect()
    };
    let pyramid = scratch("normals_pyramid");
    let alone = scratch("normals_alone");
    let png = |root: &Path, tx: u32, ty: u32| {
        let dir = root.join(z.to_string()).join(tx.to_string());
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(format!("{ty}.png"))
    };
    for (tx, ty) in [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)] {
        write_terrarium(&png(&pyramid, tx, ty), side, &tile_heights(tx, ty));
    }
    write_terrarium(&png(&alone, x0, y0), side, &tile_heights(x0, y0));
    let mesh = |input: PathBuf| -> (QuantizedMesh, Value) {
        let out = input.with_extension("terrain");
        let report = globus_json(&[
            "mesh",
            "--in",
            s(&input),
            "--encoding",
            "terrarium",
            "--max-error",
            "0",
            "--out",
            s(&out),
            "--json",
        ]);
        let qm = QuantizedMesh::decode(&std::fs::read(&out).unwrap()).unwrap();
        (qm, report)
    };
    let (a, a_report) = mesh(png(&pyramid, x0, y0));
    let (east, _) = mesh(png(&pyramid, x0 + 1, y0));
    let (south, _) = mesh(png(&pyramid, x0, y0 + 1));
    let (lonely, lonely_report) = mesh(png(&alone, x0, y0));
    assert_eq!(
        a_report["normals_across_edges"],
        serde_json::json!(["east", "south"])
    );
    assert_eq!(lonely_report["normals_across_edges"], serde_json::json!([]));
    // How many of `p`'s vertices on edge `pe` have the normal of `q`'s vertex on edge `qe` at
    // the same place (matched by the coordinate along the edge), of how many matched.
    let agreeing = |p: &QuantizedMesh, pe: &[u32], q: &QuantizedMesh, qe: &[u32], along_u: bool| {
        let along = |m: &QuantizedMesh, i: u32| {
            if along_u {
                m.u[i as usize]
            } else {
                m.v[i as usize]
            }
        };
        let normal = |m: &QuantizedMesh, i: u32| m.normals.as_ref().unwrap()[i as usize];
        let (mut same, mut matched) = (0, 0);
        for &i in pe {
            if let Some(&j) = qe.iter().find(|&&j| along(q, j) == along(p, i)) {
                matched += 1;
                same += usize::from(normal(p, i) == normal(q, j));
            }
        }
        assert_eq!(
            matched, side,
            "every edge sample is a vertex at --max-error 0"
        );
        same
    };
    assert_eq!(agreeing(&a, &a.east, &east, &east.west, false), side);
    assert_eq!(agreeing(&a, &a.south, &south, &south.north, true), side);
    let lonely_east = agreeing(&lonely, &lonely.east, &east, &east.west, false);
    let lonely_south = agreeing(&lonely, &lonely.south, &south, &south.north, true);
    assert!(
        lonely_east < side / 2 && lonely_south < side / 2,
        "one-sided edge normals agree at {lonely_east} and {lonely_south} of {side} vertices"
    );
}

/// A tile inside a pyramid (`ROOT/Z/X/Y.png`) takes its encoding from the pyramid's
/// `metadata.json` when --encoding is not given.
#[test]
fn a_pyramid_tile_reads_its_encoding_from_the_metadata() {
    let root = scratch("pyramid_encoding");
    let dir = root.join("7").join("68");
    std::fs::create_dir_all(&dir).unwrap();
    let tile = dir.join("19.png");
    let heights = srtm_window(65, 0, 640);
    let mut rgb = Vec::new();
    for &h in &heights {
        rgb.extend_from_slice(&ElevationEncoding::Mapbox.encode(f64::from(h)));
    }
    image::save_buffer(&tile, &rgb, 65, 65, image::ColorType::Rgb8).unwrap();
    fails_with_one_line(
        &["mesh", "--in", s(&tile), "--max-error", "1"],
        &["19.png", "--encoding"],
    );
    std::fs::write(root.join("metadata.json"), r#"{"encoding": "mapbox"}"#).unwrap();
    let d = globus_json(&["mesh", "--in", s(&tile), "--max-error", "1", "--json"]);
    // Decoded as Mapbox (as Terrarium the heights would be tens of kilometres off).
    assert!(d["max_error_m"].as_f64().unwrap() <= 1.0, "{d}");
    assert_eq!(d["encoding"], "mapbox", "{d}");
    let lo = heights.iter().copied().fold(f32::MAX, f32::min);
    let got = d["height_range_m"][0].as_f64().unwrap();
    // Mapbox steps are 0.1 m.
    assert!((got - f64::from(lo)).abs() <= 0.1, "{d}: lowest {lo}");
    std::fs::write(root.join("metadata.json"), r#"{"encoding": "float"}"#).unwrap();
    fails_with_one_line(
        &["mesh", "--in", s(&tile), "--max-error", "1"],
        &["metadata.json", "float"],
    );
}
