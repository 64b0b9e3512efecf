//! The engine's own shaders (the vector, traffic and label overlays') parse and validate with naga,
//! without a GPU.

use naga::valid::{Capabilities, ValidationFlags, Validator};

fn validate(name: &str, source: &str) {
    let module = naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
    Validator::new(ValidationFlags::all(), Capabilities::all())
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
}

#[test]
fn vector_shader_validates() {
    validate("vector.wgsl", globus_engine::vector::SHADER);
}

#[test]
fn traffic_shader_validates() {
    validate("traffic.wgsl", globus_engine::traffic::SHADER);
}

#[test]
fn label_shader_validates() {
    validate("labels.wgsl", globus_engine::labels::SHADER);
}
