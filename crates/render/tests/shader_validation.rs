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

#[test]
fn terrain_layout_constants_match_the_terrain_crate() {
    use globus_terrain::grid::{GRID_VERTICES, MESH_SEGMENTS, MESH_SIDE, VERTICES_PER_TILE};
    let src = globus_render::shaders::TERRAIN;
    assert!(src.contains(&format!("const MESH_SIDE: u32 = {MESH_SIDE}u;")));
    assert!(src.contains(&format!("const GRID_VERTICES: u32 = {GRID_VERTICES}u;")));
    assert!(src.contains(&format!(
        "const VERTICES_PER_TILE: u32 = {VERTICES_PER_TILE}u;"
    )));
    assert!(src.contains(&format!("const SEGMENTS: f32 = {MESH_SEGMENTS}.0;")));
}
