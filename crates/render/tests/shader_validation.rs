//! Every shader parses and validates with naga, without a GPU.

use naga::valid::{Capabilities, ValidationFlags, Validator};

#[test]
fn all_shaders_validate() {
    for (name, source) in globus_render::shaders::ALL {
        let module = naga::front::wgsl::parse_str(source)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        Validator::new(ValidationFlags::all(), Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
    }
}
