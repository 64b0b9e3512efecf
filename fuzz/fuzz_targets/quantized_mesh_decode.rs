//! Untrusted bytes into the quantized-mesh decoder: it must return an error or a mesh, never
//! panic, and a mesh it accepts must survive an encode/decode round trip unchanged.
//!
//!     cargo +nightly fuzz run quantized_mesh_decode -- -max_total_time=600
#![no_main]

use globus_terrain::quantized_mesh::QuantizedMesh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = QuantizedMesh::decode(data) {
        let again = QuantizedMesh::decode(&mesh.encode(false)).expect("re-encoded tile decodes");
        // NaN header fields compare unequal; compare the bytes instead.
        assert_eq!(again.encode(false), mesh.encode(false));
    }
});
