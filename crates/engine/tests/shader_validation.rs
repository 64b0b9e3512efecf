//! The engine's own shaders (the vector overlay's) parse and validate with naga, without a
//! GPU.

use naga::valid::{Capabilities, ValidationFlags, Validator};

#[test]
fn vector_shader_validates() {
    let source = globus_engine::vector::SHADER;
    let module = naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("vector.wgsl: {}", e.emit_to_string(source)));
    Validator::new(ValidationFlags::all(), Capabilities::all())
        .validate(&module)
        .unwrap_or_else(|e| panic!("vector.wgsl: {}", e.emit_to_string(source)));
}
