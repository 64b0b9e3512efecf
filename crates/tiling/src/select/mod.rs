//! Level-of-detail selection: which tiles to draw this frame and which to load.
//!
//! This is the hierarchical LOD (HLOD) traversal of Zeitler (2015, ch. 4) and Cesium's
//! `QuadtreePrimitive`, written as a pure function. It walks the quadtree from the roots and,
//! for every tile it reaches:
//!
//! 1. culls it if its oriented box is outside the view frustum, or its horizon culling point
//!    is hidden behind the occluder ellipsoid (both tests are conservative);
//! 2. computes its screen-space error
//!    `sse = geometric_error * viewport_height / (distance * 2 tan(fov_y / 2))`, times the
//!    share of contrast the air lets through from the tile to the eye when there is fog;
//! 3. draws it if `sse <= max_sse_px`, or if it has no finer data;
//! 4. otherwise refines into the children the view sees. Those that are loaded are visited in
//!    turn; the area of those that are not (loading, failed or without data) stays covered
//!    by this tile, drawn in part: only its quadrants under the missing children
//!    ([`DrawTile::parts`], CesiumJS's fill tiles with the parent's own surface). When no
//!    child in view is loaded, this tile is drawn whole. Missing children that can load are
//!    requested with priority `sse`.
//!
//! Every drawn tile carries how far it has grown out of its parent's surface
//! ([`morph_fraction`]): the renderer draws that blend, so splits and merges do not pop.
//!
//! Every drawn tile is loaded, and the drawn parts never overlap: a tile is drawn in part
//! only where its children are not drawn. Together with the culled tiles they partition the
//! globe, so there are no holes. Only the roots can be missing (before their first load),
//! and they are requested first. Drawing the loaded children at once, instead of the parent
//! whole until the last of its children in view arrives, keeps a view from falling back
//! to coarse tiles when the camera turns and one new tile comes into view next to detailed
//! ones: on `paths/alps-dive.json` at 1 km, whole parents drew 12-25 tiles for three frames
//! between frames of about 400.
//!
//! The traversal visits each tile at most once and asks the [`TileOracle`] once per tile:
//! for a refined tile's children, all at once.

mod oracle;
mod quadrants;

pub use oracle::{TileInfo, TileOracle, TileState};
pub use quadrants::{Quadrants, merge_touching};

use globus_geo::{Atmosphere, Ellipsoid, EllipsoidalOccluder, Frustum, View};

use crate::{TileBounds, TileKey};

/// Knobs of the selection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelectionOptions {
    /// The screen-space error bound in pixels (default 2).
    pub max_sse_px: f64,
    /// The body that hides what is behind it: the ellipsoid at the lowest terrain height.
    pub occluder: Ellipsoid,
    /// Distance of the near plane in metres, for frustum culling.
    pub near_m: f64,
    /// No tile deeper than this is selected or requested.
    pub max_level: u8,
    /// Air whose haze lowers the detail needed (CesiumJS's fog, from the physical model):
    /// a tile's error counts times the contrast the air between the eye and the tile's
    /// nearest point lets through ([`Atmosphere::contrast_kept`]), so the error a viewer can
    /// see stays within the bound. `None`: no fog.
    pub fog: Option<Atmosphere>,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        Self {
            max_sse_px: 2.0,
            occluder: Ellipsoid::WGS84,
            near_m: 0.1,
            max_level: TileKey::MAX_LEVEL,
            fog: None,
        }
    }
}

/// A tile to draw this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawTile {
    /// The tile (always loaded).
    pub key: TileKey,
    /// Its screen-space error in pixels.
    pub sse_px: f64,
    /// Distance from the eye to its bounding box, metres.
    pub distance_m: f64,
    /// How far the tile has grown out of its parent's surface into its own, 0 to 1 (see
    /// [`morph_fraction`]): the renderer draws that blend of the two, so a split or a merge
    /// never moves a pixel in one frame. 1 for roots.
    pub morph: f64,
    /// The quadrants to draw: all of them, or, while some of its children in view are not
    /// loaded, those under the missing children (the loaded ones are drawn over the rest).
    pub parts: Quadrants,
}

/// How far a tile has grown out of its parent's surface (0) into its own (1), given the
/// parent's screen-space error over the bound (`parent_excess`, above 1 once the parent is
/// split) and the tile's error over its parent's (`error_ratio`, about 1/2).
///
/// A blend `t` of the two surfaces is off the full-resolution one by at most
/// `(1 - t) e_parent + t e_child` (each surface's error bound, the blend's by convexity),
/// so on screen by `bound * excess * (1 - t (1 - ratio))`. The fraction is the least `t`
/// that keeps that within the bound: 0 when the parent has just split (the tile shows
/// exactly the surface the parent showed), rising as the eye comes closer or the bound
/// falls, and 1 when the tile's own error reaches the bound, the moment it splits in turn
/// (so its children start from the surface it showed). This is Strugar's CDLOD morph
/// (2010) driven by screen-space error instead of distance rings, per tile: siblings share
/// it; neighbours with other parents may differ, and the skirts that already close cracks
/// between levels close that step too. (Selection shows all of a tile's own surface once its
/// own error is over the bound, whatever its parent's says: near the roots a child's box
/// can be nearer the eye than its parent's.)
pub fn morph_fraction(parent_excess: f64, error_ratio: f64) -> f64 {
    // NaN excess: no split; NaN ratio: nothing known to grow into.
    if parent_excess.is_nan() || parent_excess <= 1.0 {
        return 0.0;
    }
    let gained = 1.0 - error_ratio;
    if gained.is_nan() || gained <= 1e-9 {
        return 1.0;
    }
    ((1.0 - 1.0 / parent_excess) / gained).clamp(0.0, 1.0)
}

/// Levels up to this one are the last a cache or GPU pool gives up.
const KEPT_LONGER_LEVEL: u8 = 2;

/// Whether caches and GPU pools should keep `key` until no finer tile is left to give up:
/// the tiles of levels 0 to 2 (at most 42 on the engine's grid). Some of them are under
/// every view, and selection draws a parent whole while any visible child is missing, so one
/// of them evicted by plain recency (a quadrant out of view for a while) sends its whole quadrant
/// back to the root for the frames it takes to load again: on `paths/alps-dive.json` with a
/// full cache, two frames drew the 2 roots between frames of 300-450 tiles while the camera
/// turned (with this rule, none does).
pub fn keeps_longer(key: TileKey) -> bool {
    key.level() <= KEPT_LONGER_LEVEL
}

/// A tile the selection wants loaded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileRequest {
    /// The tile.
    pub key: TileKey,
    /// Higher first: the screen-space error of the drawn ancestor that needs it, in pixels.
    pub priority: f64,
}

/// Counters of one selection.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SelectionStats {
    /// Tiles whose bounds were tested.
    pub nodes_visited: u32,
    /// Tiles outside the frustum.
    pub culled_frustum: u32,
    /// Tiles inside the frustum but behind the horizon.
    pub culled_horizon: u32,
    /// Tiles selected for drawing.
    pub selected: u32,
    /// The deepest level among drawn tiles.
    pub max_level: u8,
    /// The largest screen-space error among drawn tiles, pixels.
    pub max_sse_px: f64,
    /// Drawn tiles whose error is above the bound because their children are still loading.
    pub waiting_for_children: u32,
    /// Tiles drawn only over some of their quadrants, beside loaded children
    /// ([`DrawTile::parts`]).
    pub drawn_in_part: u32,
}

/// The result of one selection; reuse it across frames with [`select_into`] to avoid
/// allocating.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Tiles to draw, in traversal order (front-to-back within each parent).
    pub draw: Vec<DrawTile>,
    /// Tiles to load, highest priority first. Never contains a tile and its descendant.
    pub requests: Vec<TileRequest>,
    /// Counters.
    pub stats: SelectionStats,
}

/// Priority given to missing roots: nothing can be drawn without them.
const ROOT_PRIORITY: f64 = 1e30;

/// Selects the tiles to draw for `view`; see the module documentation.
pub fn select(view: &View, oracle: &impl TileOracle, options: &SelectionOptions) -> Selection {
    let mut out = Selection::default();
    select_into(view, oracle, options, &mut out);
    out
}

/// [`select`] into a reused [`Selection`].
pub fn select_into(
    view: &View,
    oracle: &impl TileOracle,
    options: &SelectionOptions,
    out: &mut Selection,
) {
    out.draw.clear();
    out.requests.clear();
    out.stats = SelectionStats::default();
    let mut walk = Walk {
        oracle,
        options,
        eye: view.position,
        frustum: Frustum::from_view(view, options.near_m),
        occluder: EllipsoidalOccluder::new(&options.occluder, view.occlusion_eye()),
        sse_factor: view.sse_factor(),
        ortho_px_per_m: view.ortho_height_m().map(|h| f64::from(view.height_px) / h),
        out,
    };
    for &root in oracle.scheme().roots() {
        let info = oracle.tile(root);
        if !walk.is_visible(&info.bounds) {
            continue;
        }
        match info.state {
            TileState::Loaded => walk.visit(root, &info, 1.0),
            TileState::Unloaded => walk.out.requests.push(TileRequest {
                key: root,
                priority: ROOT_PRIORITY,
            }),
            TileState::NoData | TileState::Failed => {}
        }
    }
    // Highest priority first; ties broken by level (ancestors first) and key for determinism
    // (keys are unique, so the order is total and an unstable sort, which does not allocate,
    // gives the same list).
    out.requests.sort_unstable_by(|a, b| {
        b.priority
            .total_cmp(&a.priority)
            .then(a.key.level().cmp(&b.key.level()))
            .then(a.key.cmp(&b.key))
    });
}

struct Walk<'a, O> {
    oracle: &'a O,
    options: &'a SelectionOptions,
    eye: globus_geo::DVec3,
    frustum: Frustum,
    occluder: EllipsoidalOccluder,
    sse_factor: f64,
    /// Pixels per metre of an orthographic view (the same at every distance).
    ortho_px_per_m: Option<f64>,
    out: &'a mut Selection,
}

impl<O: TileOracle> Walk<'_, O> {
    /// Counts the visit and tests the frustum, then the horizon.
    fn is_visible(&mut self, bounds: &TileBounds) -> bool {
        let stats = &mut self.out.stats;
        stats.nodes_visited += 1;
        // The sphere contains the box: its cheaper test settles most planes, and only those
        // it straddles need the box's.
        if self.frustum.culls(&bounds.sphere, &bounds.obb) {
            stats.culled_frustum += 1;
            return false;
        }
        if let Some(hp) = bounds.horizon_point
            && !self.occluder.is_scaled_point_visible(hp)
        {
            stats.culled_horizon += 1;
            return false;
        }
        true
    }

    /// A visible, loaded tile: draw it or refine it.
    /// Distance from the eye (metres) and screen-space error (pixels) of a tile, and whether
    /// it is to be refined.
    fn error(&self, key: TileKey, info: &TileInfo) -> (f64, f64, bool) {
        let distance_m = info.bounds.obb.distance_to(self.eye);
        let px_per_m = self
            .ortho_px_per_m
            .unwrap_or(self.sse_factor / distance_m.max(1e-6));
        let mut sse_px = info.geometric_error_m * px_per_m;
        // Only an error that would refine is worth the march (the fog only lowers it), and
        // only if the least the air can keep over the distance might bring it under.
        if sse_px > self.options.max_sse_px
            && let Some(air) = &self.options.fog
            && sse_px * (-air.clearest_extinction() * distance_m).exp() <= self.options.max_sse_px
        {
            sse_px *= air.contrast_kept(self.eye, info.bounds.obb.closest_point(self.eye));
        }
        let can_refine = info.has_children && key.level() < self.options.max_level;
        (
            distance_m,
            sse_px,
            can_refine && sse_px > self.options.max_sse_px,
        )
    }

    /// `morph`: how far the tile and its siblings have grown out of their parent (1 for
    /// roots).
    fn visit(&mut self, key: TileKey, info: &TileInfo, morph: f64) {
        let (distance_m, sse_px, refine) = self.error(key, info);
        let morph = if sse_px > self.options.max_sse_px {
            1.0
        } else {
            morph
        };
        let drawn = DrawTile {
            key,
            sse_px,
            distance_m,
            morph,
            parts: Quadrants::ALL,
        };
        if !refine {
            self.draw(drawn);
            return;
        }
        let children = self.oracle.scheme().children(key);
        if children.is_empty() {
            self.draw(drawn);
            return;
        }
        let mut visible = [None; 4];
        self.oracle.child_tiles(key, info, &children, &mut visible);
        let n = children.len();
        // The children in view: loaded ones are visited, the others leave their quadrants
        // to this tile.
        let mut missing = Quadrants::NONE;
        let mut any_loaded = false;
        let mut in_parts = true;
        let mut waiting = false;
        for (i, slot) in visible.iter_mut().enumerate().take(n) {
            let Some(child_info) = slot else {
                continue;
            };
            if !self.is_visible(&child_info.bounds) {
                *slot = None;
                continue;
            }
            let state = child_info.state;
            if state == TileState::Loaded {
                any_loaded = true;
                continue;
            }
            if state == TileState::Unloaded {
                waiting = true;
                self.out.requests.push(TileRequest {
                    key: children[i],
                    priority: sse_px,
                });
            }
            match Quadrants::of_child(self.oracle.scheme(), key, children[i]) {
                Some(q) => missing = missing.union(q),
                None => in_parts = false,
            }
            *slot = None;
        }
        if waiting {
            self.out.stats.waiting_for_children += 1;
        }
        if !missing.is_empty() {
            if !any_loaded || !in_parts {
                self.draw(drawn);
                return;
            }
            self.out.stats.drawn_in_part += 1;
            self.draw(DrawTile {
                parts: missing,
                ..drawn
            });
        }
        // Nearest child first: front-to-back order helps early depth rejection. (Four
        // elements: an insertion sort over distances computed once.)
        let mut order = [0usize, 1, 2, 3];
        let order = &mut order[..n];
        let mut dist = [f64::INFINITY; 4];
        for (d, ci) in dist.iter_mut().zip(&visible) {
            if let Some(ci) = ci {
                *d = ci.bounds.sphere.centre.distance_squared(self.eye);
            }
        }
        for k in 1..n {
            let mut j = k;
            while j > 0 && dist[order[j]] < dist[order[j - 1]] {
                order.swap(j, j - 1);
                j -= 1;
            }
        }
        // Siblings morph together (they share edges): by the family's largest error ratio,
        // which keeps every one of them within the bound.
        let excess = sse_px / self.options.max_sse_px;
        let ratio = visible
            .iter()
            .flatten()
            .map(|ci| ci.geometric_error_m / info.geometric_error_m)
            .fold(0.0, f64::max);
        let morph = morph_fraction(excess, ratio);
        for &mut i in order {
            if let Some(ci) = visible[i].as_ref() {
                self.visit(children[i], ci, morph);
            }
        }
    }

    fn draw(&mut self, tile: DrawTile) {
        let stats = &mut self.out.stats;
        stats.selected += 1;
        stats.max_level = stats.max_level.max(tile.key.level());
        stats.max_sse_px = stats.max_sse_px.max(tile.sse_px);
        self.out.draw.push(tile);
    }
}

#[cfg(test)]
mod tests {
    use super::morph_fraction;

    #[test]
    fn the_morph_starts_at_the_split_ends_at_the_next_and_keeps_the_bound() {
        // Just split: the parent's surface.
        assert_eq!(morph_fraction(1.0, 0.5), 0.0);
        assert_eq!(morph_fraction(0.7, 0.5), 0.0);
        // Errors halving per level: the tile's own error reaches the bound at twice the
        // parent's, and then it is all its own.
        assert_eq!(morph_fraction(2.0, 0.5), 1.0);
        assert_eq!(morph_fraction(5.0, 0.5), 1.0);
        // In between it rises, and the blend's error bound, excess * (1 - t (1 - ratio)),
        // never passes 1 (the bound) until the tile's own does (excess * ratio > 1: it
        // splits).
        let mut last = 0.0;
        for k in 1..=100 {
            let excess = 1.0 + f64::from(k) / 100.0;
            for ratio in [0.25, 0.5, 0.8].into_iter().filter(|r| excess * r <= 1.0) {
                let t = morph_fraction(excess, ratio);
                assert!(
                    excess * (1.0 - t * (1.0 - ratio)) <= 1.0 + 1e-12,
                    "{excess} {ratio}"
                );
            }
            let t = morph_fraction(excess, 0.5);
            assert!(t > last, "{excess}: {t} after {last}");
            last = t;
        }
        // A child no better than its parent (or a NaN) has nothing to grow into.
        assert_eq!(morph_fraction(1.5, 1.0), 1.0);
        assert_eq!(morph_fraction(1.5, f64::NAN), 1.0);
        assert_eq!(morph_fraction(f64::NAN, 0.5), 0.0);
    }
}
