use super::*;
use crate::traffic::models::aircraft_mesh;
use globus_traffic::AircraftKind;

/// A hand-made .glb: one triangle (glTF axes) under a node translated by (1, 2, 3) and turned
/// a quarter round +Y, material named `accent`, indexed with u16.
fn one_triangle_glb() -> Vec<u8> {
    let mut bin = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    // Rotation of 90 degrees about +Y: quaternion (0, sin 45, 0, cos 45).
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"children":[1],"translation":[1,2,3]}},{{"mesh":0,"rotation":[0,{h},0,{h}]}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],"materials":[{{"name":"accent"}}],"buffers":[{{"byteLength":44}}],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}]}}"#
    );
    pack_glb(json.into_bytes(), bin)
}

#[test]
fn a_glb_triangle_lands_where_its_nodes_put_it_in_model_axes() {
    let m = model_from_glb(&one_triangle_glb(), Path::new("t.glb")).expect("read");
    assert_eq!(m.triangles(), 1);
    assert_eq!(m.accents, [1, 1, 1]);
    // glTF: rotate (x, y, z) by 90 degrees about +Y: x -> -z, z -> x; then translate.
    // (1, 0, 0) -> (0, 0, -1) + (1, 2, 3) = (1, 2, 2); (0, 1, 0) -> (1, 3, 3).
    // Model axes: (x, y, z)_model = (z, x, y)_glTF.
    let want = [[3.0, 1.0, 2.0], [2.0, 1.0, 2.0], [3.0, 1.0, 3.0]];
    for (got, want) in m.positions.iter().zip(want) {
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 1e-5,
                "{:?} vs {want:?}",
                m.positions
            );
        }
    }
}

#[test]
fn built_in_shapes_survive_a_round_trip_through_glb() {
    for kind in AircraftKind::ALL {
        let mesh = aircraft_mesh(kind);
        let bytes = write_glb(&mesh);
        // A reader other than ours accepts it and sees every triangle.
        let doc = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
        let counted: usize = doc
            .meshes()
            .flat_map(|m| m.primitives())
            .map(|p| p.get(&gltf::Semantic::Positions).map_or(0, |a| a.count()))
            .sum();
        assert_eq!(counted, mesh.positions.len());
        let back = model_from_glb(&bytes, Path::new("x.glb")).expect("read back");
        assert_eq!(back.triangles(), mesh.triangles(), "{kind:?}");
        assert!((back.extent_m() - mesh.extent_m()).abs() < 1e-4);
        // Accents are kept (triangles are regrouped by paint, so compare counts).
        let accents = |m: &ModelMesh| m.accents.iter().filter(|&&a| a == 1).count();
        assert_eq!(accents(&back), accents(&mesh));
    }
}

#[test]
fn bad_glb_files_are_one_error_naming_the_file() {
    let name = Path::new("plane.glb");
    let good = one_triangle_glb();
    // A header declaring fewer bytes than a header holds (the fuzzer's find: gltf 1.4
    // subtracts unchecked).
    let mut short = good.clone();
    short[8..12].copy_from_slice(&0u32.to_le_bytes());
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"not a model".to_vec(), "not a usable glTF"),
        (good[..good.len() - 10].to_vec(), "not a usable glTF"),
        (Vec::new(), "not a usable glTF"),
        (short, "header declares 0 bytes"),
    ];
    for (bytes, needle) in cases {
        let e = model_from_glb(&bytes, name)
            .expect_err("refused")
            .to_string();
        assert!(e.contains("plane.glb") && e.contains(needle), "{e}");
    }
    // An index past the vertices.
    let mut bad = good.clone();
    let at = bad.len() - 8;
    bad[at..at + 2].copy_from_slice(&7u16.to_le_bytes());
    let e = model_from_glb(&bad, name).expect_err("refused").to_string();
    assert!(e.contains("plane.glb"), "{e}");
    // A NaN position.
    let mut nan = good;
    let at = nan.len() - 44;
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = model_from_glb(&nan, name).expect_err("refused").to_string();
    assert!(e.contains("plane.glb") && e.contains("not finite"), "{e}");
}

/// Mutated .glb files (seeds in `fuzz/seeds/glb`: the triangle above and the light
/// aircraft as written) never panic the reader.
#[test]
fn fuzz_glb() {
    let r =
        globus_test_support::fuzz::run("glb", |b| model_from_glb(b, Path::new("fuzz.glb")).is_ok());
    assert!(r.cases > 0);
}
