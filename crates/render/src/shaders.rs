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

/// Builds the aerial-perspective table (compute).
pub const AERIAL: &str = concat!(
    include_str!("shaders/common.wgsl"),
    "\n",
    include_str!("shaders/aerial.wgsl")
);

/// Reads one pixel of the depth buffer (picking).
pub const PICK: &str = include_str!("shaders/pick.wgsl");

/// Every shader, with a name, for validation.
pub const ALL: [(&str, &str); 4] = [
    ("terrain", TERRAIN),
    ("sky", SKY),
    ("aerial", AERIAL),
    ("pick", PICK),
];
