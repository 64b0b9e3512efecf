//! WGSL sources. WGSL has no includes, so each pipeline's source is the shared
//! `common.wgsl` followed by its own file.

/// The terrain pipeline's shader.
pub const TERRAIN: &str = concat!(
    include_str!("shaders/common.wgsl"),
    "\n",
    include_str!("shaders/terrain.wgsl")
);

/// The sky pipeline's shader.
pub const SKY: &str = concat!(
    include_str!("shaders/common.wgsl"),
    "\n",
    include_str!("shaders/sky.wgsl")
);

/// Every shader, with a name, for validation.
pub const ALL: [(&str, &str); 2] = [("terrain", TERRAIN), ("sky", SKY)];
