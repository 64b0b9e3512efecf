use super::*;
use crate::adaptive::{HeightGrid, Rtin, test_grids::rough};
use globus_geo::Ellipsoid;
use globus_tiling::GeoRect;
use proptest::prelude::*;

fn sample_tile(
    side: usize,
    max_error: f64,
) -> (HeightGrid, crate::adaptive::AdaptiveMesh, QuantizedMesh) {
    let grid = rough(side, 11, 800.0);
    let mesh = Rtin::new(&grid).mesh(max_error);
    let rect = GeoRect::from_degrees(10.0, 45.0, 11.25, 46.25);
    let options = QuantizedMeshOptions {
        normals: true,
        water_mask: Some(WaterMask::Uniform(0)),
        metadata: Some(r#"{"available":[]}"#.into()),
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
    (grid, mesh, qm)
}

#[test]
fn round_trips_with_every_extension_plain_and_gzipped() {
    let (_, _, qm) = sample_tile(65, 5.0);
    for gzip in [false, true] {
        let bytes = qm.encode(gzip);
        assert_eq!(bytes.starts_with(&[0x1f, 0x8b]), gzip);
        assert_eq!(QuantizedMesh::decode(&bytes), Ok(qm.clone()));
    }
}

#[test]
fn grid_mask_and_wide_indices_round_trip() {
    // More than 65536 vertices: the index section switches to 32 bits after padding.
    let (_, mesh, mut qm) = sample_tile(513, 0.0);
    assert!(mesh.vertices.len() > 65536);
    qm.water_mask = Some(WaterMask::Grid(
        (0..65536).map(|i| (i % 251) as u8).collect(),
    ));
    let bytes = qm.encode(false);
    let back = QuantizedMesh::decode(&bytes).expect("decodes");
    assert_eq!(back, qm);
    assert_eq!(back.triangle_count(), mesh.triangles.len());
}

#[test]
fn quantized_vertices_land_on_the_grid_and_heights_within_a_step() {
    let (grid, mesh, qm) = sample_tile(257, 2.0);
    let step = (qm.header.max_height_m - qm.header.min_height_m) as f64 / 32767.0;
    for (i, &[x, y]) in mesh.vertices.iter().enumerate() {
        let gx = (f64::from(qm.u[i]) / 32767.0 * 256.0).round() as u16;
        let gy = 256 - (f64::from(qm.v[i]) / 32767.0 * 256.0).round() as u16;
        assert_eq!([gx, gy], [x, y]);
        let h = f64::from(grid.at(usize::from(x), usize::from(y)));
        assert!((qm.height_m(i) - h).abs() <= step / 2.0 + 1e-3);
    }
    // Edge lists hold exactly the vertices on each edge.
    let on = |pred: &dyn Fn(usize) -> bool| (0..qm.vertex_count()).filter(|&i| pred(i)).count();
    assert_eq!(qm.west.len(), on(&|i| qm.u[i] == 0));
    assert_eq!(qm.east.len(), on(&|i| qm.u[i] == 32767));
    assert_eq!(qm.south.len(), on(&|i| qm.v[i] == 0));
    assert_eq!(qm.north.len(), on(&|i| qm.v[i] == 32767));
}

#[test]
fn header_bounds_hold_every_vertex() {
    let (_, _, qm) = sample_tile(129, 1.0);
    let rect = GeoRect::from_degrees(10.0, 45.0, 11.25, 46.25);
    for i in 0..qm.vertex_count() {
        let lon = rect.west + rect.width() * f64::from(qm.u[i]) / 32767.0;
        let lat = rect.south + rect.height() * f64::from(qm.v[i]) / 32767.0;
        let p = Ellipsoid::WGS84.cartographic_to_ecef(globus_geo::Cartographic::new(
            lon,
            lat,
            qm.height_m(i),
        ));
        assert!(qm.header.sphere_centre.distance(p) <= qm.header.sphere_radius_m + 0.1);
    }
    assert!(qm.header.horizon_occlusion_point.length() > 1.0);
}

#[test]
fn normals_point_up_and_round_trip() {
    let (_, _, qm) = sample_tile(65, 3.0);
    let up = qm.header.centre.normalize();
    for e in qm.normals.as_ref().expect("normals") {
        assert!(oct_decode_u8(*e).dot(up) > 0.2);
    }
    for n in [
        DVec3::X,
        DVec3::NEG_Y,
        DVec3::new(0.2, -0.3, -0.9).normalize(),
        DVec3::new(-0.6, 0.1, 0.7).normalize(),
    ] {
        assert!(oct_decode_u8(oct_encode_u8(n)).dot(n) > 0.999, "{n}");
    }
}

#[test]
fn every_truncation_is_an_error_not_a_panic() {
    let (_, _, qm) = sample_tile(33, 1.0);
    let bytes = qm.encode(false);
    for len in 0..bytes.len() {
        let cut = &bytes[..len];
        // A cut between extensions is a valid shorter tile; anything else must fail cleanly.
        if let Ok(back) = QuantizedMesh::decode(cut) {
            assert_eq!(back.indices, qm.indices, "cut at {len}");
        }
    }
    let gz = qm.encode(true);
    for len in [0, 1, 2, 10, gz.len() / 2, gz.len() - 1] {
        assert!(
            QuantizedMesh::decode(&gz[..len]).is_err(),
            "gzip cut at {len}"
        );
    }
}

#[test]
fn huge_counts_are_refused_before_allocating() {
    let mut bytes = vec![0u8; HEADER_BYTES];
    bytes.extend_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        QuantizedMesh::decode(&bytes),
        Err(DecodeError::CountTooLarge { what: "vertex", .. })
    ));
    // A gzip bomb: 300 MiB of zeros.
    let bomb = {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        let zeros = vec![0u8; 1 << 20];
        for _ in 0..300 {
            enc.write_all(&zeros).expect("write");
        }
        enc.finish().expect("finish")
    };
    assert!(matches!(
        QuantizedMesh::decode(&bomb),
        Err(DecodeError::Gzip(_))
    ));
}

/// NaN heights panicked inside refinement, min = 1e30 > max = -1e30 loaded 12,540 tiles into
/// 8.7 GB, and a 112-byte all-zero file was accepted: each header is refused with its reason.
#[test]
fn nonsense_headers_and_empty_tiles_are_refused() {
    let (_, _, qm) = sample_tile(33, 5.0);
    let with = |f: &dyn Fn(&mut Header)| {
        let mut q = qm.clone();
        f(&mut q.header);
        QuantizedMesh::decode(&q.encode(false))
    };
    assert!(with(&|_| {}).is_ok());
    for (what, f) in [
        (
            "NaN minimum",
            &(|h: &mut Header| h.min_height_m = f32::NAN) as &dyn Fn(&mut Header),
        ),
        ("infinite maximum", &|h: &mut Header| {
            h.max_height_m = f32::INFINITY
        }),
        ("1e30 over -1e30", &|h: &mut Header| {
            h.min_height_m = 1e30;
            h.max_height_m = -1e30;
        }),
        ("min above max", &|h: &mut Header| {
            h.min_height_m = 500.0;
            h.max_height_m = 400.0;
        }),
        ("NaN radius", &|h: &mut Header| h.sphere_radius_m = f64::NAN),
        ("far centre", &|h: &mut Header| {
            h.centre = DVec3::splat(1e30)
        }),
    ] {
        match with(f) {
            Err(DecodeError::BadHeader(why)) => assert!(!why.is_empty(), "{what}"),
            other => panic!("{what}: {other:?}"),
        }
    }
    assert_eq!(
        QuantizedMesh::decode(&[0u8; 112]),
        Err(DecodeError::Empty {
            vertices: 0,
            triangles: 0
        })
    );
}

#[test]
fn out_of_range_indices_are_refused() {
    let (_, _, mut qm) = sample_tile(17, 0.0);
    qm.north.push(qm.vertex_count() as u32 + 3);
    let err = QuantizedMesh::decode(&qm.encode(false)).expect_err("bad edge index");
    assert!(
        matches!(err, DecodeError::IndexOutOfRange { what: "north", .. }),
        "{err}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let _ = QuantizedMesh::decode(&bytes);
    }

    #[test]
    fn mutated_tiles_never_panic(at in 0usize..4000, value in any::<u8>()) {
        let (_, _, qm) = sample_tile(17, 0.5);
        let mut bytes = qm.encode(false);
        let i = at % bytes.len();
        bytes[i] = value;
        let _ = QuantizedMesh::decode(&bytes);
    }
}

/// Mutations of real tiles (plain and gzip'd): every one decodes or is refused, none panics.
#[test]
fn fuzz_quantized_mesh() {
    let r = globus_test_support::fuzz::run("quantized-mesh", |b| QuantizedMesh::decode(b).is_ok());
    assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
}
