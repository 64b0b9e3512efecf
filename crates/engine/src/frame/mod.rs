//! One frame as named stages, each testable without a GPU where it does not touch one:
//!
//! 1. [`select`]: LOD selection, seeing a tile as loaded only when it is resident on the GPU
//!    (answered from the pools' own record, nothing copied into the data layer);
//! 2. [`plan`]: what to load, upload and defer, and the tiles in use (recency, walked once
//!    for both the CPU cache and the GPU pools);
//! 3. [`upload`]: GPU residency, within the frame's upload budget, then [`detail`]: the
//!    error bound the budgets allow for the next frame;
//! 4. the draw list and the render passes ([`crate::Globe::update`], [`crate::Globe::render`]).

pub(crate) mod detail;
pub(crate) mod plan;
pub(crate) mod select;
pub(crate) mod upload;
