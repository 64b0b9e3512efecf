//! Stage 3, GPU residency: puts the planned tiles into the GPU pools within the frame's
//! upload budget, drawn tiles' late colours first.
//!
//! Imagery that loads on its own ([`TileColour`]) arrives after its tile's geometry: the
//! tile is uploaded without it, reading its nearest resident ancestor's colour cropped and
//! scaled (a root is uploaded first if no ancestor has colour on the GPU), and its own colour
//! follows when it arrives. Drawn tiles' colours go up before new tiles: they are on screen.
//!
//! A tile goes up with its morph targets on its parent's surface ([`MorphVertex`]), as the
//! loader thread found them, or from the parent's mesh in the CPU cache (a drawn tile's
//! ancestors are in use, so they are there); without them (a root) it shows its own surface
//! at once.

use std::borrow::Cow;

use globus_render::TilePool;
use globus_stream::{TerrainLayer, TileColour};
use globus_terrain::MorphVertex;
use globus_tiling::{DrawTile, GLOBE_SCHEME, TileKey};

use super::plan::FramePlan;

/// What the residency stage did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Residency {
    /// The pools could not make room for a wanted tile without evicting one in use: the view
    /// needs more than they hold (detail must drop).
    pub pool_full: bool,
    /// Drawn tiles showing an ancestor's colour while their own loads or waits for upload.
    pub colours_pending: u32,
}

/// Marks the tiles in use, uploads drawn tiles' arrived colours, then new tiles.
pub(crate) fn make_resident(
    pool: &mut TilePool,
    queue: &wgpu::Queue,
    layer: &TerrainLayer,
    plan: &FramePlan,
    drawn: &[DrawTile],
) -> Residency {
    for &k in &plan.in_use {
        pool.touch(k);
    }
    let mut colours_pending = 0;
    for d in drawn {
        if pool.resident(d.key).is_none_or(|r| r.own_colour) {
            continue;
        }
        match layer.colour(d.key) {
            Some(TileColour::Ready(c)) => {
                if !pool.upload_colour(queue, d.key, c) {
                    colours_pending += 1;
                }
            }
            Some(TileColour::Loading) => colours_pending += 1,
            Some(TileColour::Borrowed) | None => {}
        }
    }
    let mut pool_full = false;
    for r in &plan.to_upload {
        if !pool.can_upload() {
            break;
        }
        let (Some(data), Some(colour)) = (layer.get(r.key), layer.colour(r.key)) else {
            continue;
        };
        let own = match colour {
            TileColour::Ready(c) => Some(c),
            TileColour::Loading | TileColour::Borrowed => None,
        };
        if own.is_none() && !colour_to_borrow(pool, queue, layer, r.key) {
            continue;
        }
        // The root may have taken the frame's last upload.
        if !pool.can_upload() {
            break;
        }
        // Evicted tiles need no bookkeeping here: selection asks the pools what is resident.
        let morph = morph_targets(layer, r.key);
        let mut evicted = Vec::new();
        if pool
            .upload(queue, r.key, &data.mesh, &morph, own, &mut evicted)
            .is_none()
        {
            pool_full = true;
            break;
        }
    }
    Residency {
        pool_full,
        colours_pending,
    }
}

/// Makes sure a tile about to be uploaded without its own colour has colour to borrow on the
/// GPU: the nearest ancestor's that is resident (kept for this frame), else the root's (loaded
/// with its colour and never evicted from the CPU cache), uploaded now. False if neither can
/// be had this frame.
fn colour_to_borrow(
    pool: &mut TilePool,
    queue: &wgpu::Queue,
    layer: &TerrainLayer,
    key: TileKey,
) -> bool {
    if let Some(source) = pool.colour_source(key) {
        pool.touch(source.from);
        return true;
    }
    let Some(root) = GLOBE_SCHEME.ancestor_at(key, 0) else {
        return false;
    };
    let (Some(data), Some(TileColour::Ready(colour))) = (layer.get(root), layer.colour(root))
    else {
        return false;
    };
    if pool.is_resident(root) {
        pool.upload_colour(queue, root, colour)
    } else {
        let mut evicted = Vec::new();
        pool.upload(queue, root, &data.mesh, &[], Some(colour), &mut evicted)
            .is_some()
    }
}

/// Where the vertices of a loaded tile's mesh lie on its parent's surface: as its loader
/// thread found them ([`globus_stream::TerrainData::morph`]), else from the parent's data in
/// the CPU cache; empty for roots, tiles not loaded, or a parent gone from the cache (the
/// tile then shows its own surface at once).
pub(crate) fn morph_targets(layer: &TerrainLayer, key: TileKey) -> Cow<'_, [MorphVertex]> {
    let Some(data) = layer.get(key) else {
        return Cow::Borrowed(&[]);
    };
    if data.morph.len() == data.mesh.vertices.len() {
        return Cow::Borrowed(&data.morph);
    }
    let Some(parent) = GLOBE_SCHEME.parent(key).and_then(|p| layer.get(p)) else {
        return Cow::Borrowed(&[]);
    };
    Cow::Owned(MorphVertex::towards_parent(
        &data.tile,
        &data.mesh,
        &parent.tile,
        &parent.mesh,
        layer.ellipsoid(),
    ))
}
