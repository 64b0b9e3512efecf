//! Stage 2, plan: from the selection, what this frame loads, uploads and defers, and which
//! tiles it uses (for recency, tracked once for the CPU cache and the GPU pools).
//!
//! Pure CPU: a function of the selection, what the layer has cached, what is resident, and
//! the camera's motion.

use globus_geo::{DVec3, Frustum, Intersection, View};
use globus_render::Residency;
use globus_stream::TerrainLayer;
use globus_tiling::{GLOBE_SCHEME, Selection, TileKey, TileOracle, TileRequest};
use rustc_hash::FxHashSet;

/// What one frame does with the selection's wishes.
#[derive(Debug, Default)]
pub(crate) struct FramePlan {
    /// Every drawn tile and every ancestor of one: used this frame, never evicted from the
    /// CPU cache or the GPU pools this frame.
    pub in_use: Vec<TileKey>,
    /// Wanted tiles on the CPU but not on the GPU, in priority order.
    pub to_upload: Vec<TileRequest>,
    /// Wanted tiles to load, in priority order.
    pub to_load: Vec<TileRequest>,
    /// Wanted tiles not requested because the moving camera will have left them behind.
    pub deferred: u32,
    seen: FxHashSet<TileKey>,
}

/// How the camera moves, for request deferral.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Motion<'a> {
    pub view: &'a View,
    /// The eye of the previous frame.
    pub last_eye: Option<DVec3>,
    pub lookahead_frames: f64,
    pub near_m: f64,
    /// The eye's height above the ground, metres.
    pub above_ground_m: f64,
}

impl FramePlan {
    /// Fills the plan for `selection` (reusing its buffers).
    pub fn make(
        &mut self,
        selection: &Selection,
        layer: &TerrainLayer,
        residency: &Residency,
        motion: Motion<'_>,
    ) {
        self.in_use.clear();
        self.seen.clear();
        for d in &selection.draw {
            let mut key = Some(d.key);
            // Ancestors are shared: stop at the first one already counted.
            while let Some(k) = key
                && self.seen.insert(k)
            {
                self.in_use.push(k);
                key = GLOBE_SCHEME.parent(k);
            }
        }
        self.to_upload.clear();
        self.to_load.clear();
        for r in &selection.requests {
            if layer.get(r.key).is_none() {
                self.to_load.push(*r);
            } else if !residency.contains(r.key) {
                self.to_upload.push(*r);
            }
        }
        self.deferred = defer_requests_left_behind(
            layer,
            motion,
            |key| {
                std::iter::successors(GLOBE_SCHEME.parent(key), |k| GLOBE_SCHEME.parent(*k))
                    .any(|k| layer.get(k).is_some())
            },
            &mut self.to_load,
        );
    }
}

/// Drops from `to_load` the tiles outside the view predicted `lookahead_frames` frames ahead
/// (same orientation, the eye moved on at its velocity since `last_eye`) whose place a loaded
/// ancestor can take meanwhile (`covered`), so no hole opens; returns how many.
fn defer_requests_left_behind(
    oracle: &impl TileOracle,
    motion: Motion<'_>,
    covered: impl Fn(TileKey) -> bool,
    to_load: &mut Vec<TileRequest>,
) -> u32 {
    let Some(last) = motion.last_eye else {
        return 0;
    };
    let step = motion.view.position - last;
    if motion.lookahead_frames <= 0.0 || step == DVec3::ZERO {
        return 0;
    }
    // The eye moved on, but never down by more than half its height above the ground: a
    // camera coming down fast (a dive slows as it nears the ground) would otherwise be
    // predicted under the ground, where nothing is in view and every request would wait.
    let mut ahead = *motion.view;
    let mut reach = step * motion.lookahead_frames;
    let up = motion.view.position.normalize_or_zero();
    let down = -reach.dot(up);
    let most = 0.5 * motion.above_ground_m.max(0.0);
    if down > most {
        reach += up * (down - most);
    }
    ahead.position += reach;
    let frustum = Frustum::from_view(&ahead, motion.near_m);
    let before = to_load.len();
    // The ancestor walk only for tiles the predicted view misses.
    to_load.retain(|r| {
        frustum.intersect_box(&oracle.tile(r.key).bounds.obb) != Intersection::Outside
            || !covered(r.key)
    });
    (before - to_load.len()) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    use globus_geo::{Cartographic, Ellipsoid};
    use globus_stream::{ProceduralSource, TerrainLayerOptions};
    use globus_tiling::DrawTile;

    /// A camera 10 km up looking north 30 degrees down, flying north at 20 km a frame: a
    /// wanted tile just inside the bottom of the view is left behind within three frames and
    /// not requested; one 100 km ahead is; nothing is dropped while the camera stands still
    /// or with the lookahead switched off.
    #[test]
    fn requests_the_camera_is_leaving_behind_are_deferred() {
        let source = Arc::new(ProceduralSource::new(crate::DEFAULT_SEED, 16));
        let layer = TerrainLayer::new(source, TerrainLayerOptions::default());
        let ellipsoid = Ellipsoid::WGS84;
        let eye = Cartographic::from_degrees(10.0, 45.0, 10_000.0);
        let view = View::from_geodetic(
            &ellipsoid,
            eye,
            0.0,
            -30f64.to_radians(),
            60f64.to_radians(),
            960,
            540,
        );
        let north_by = |km: f64| -> TileKey {
            let lat = eye.lat_rad + km * 1000.0 / 6_371_000.0;
            GLOBE_SCHEME.tile_at(eye.lon_rad, lat, 12).expect("tile")
        };
        let (behind, ahead) = (north_by(9.0), north_by(100.0));
        // Both are in today's view.
        let now = Frustum::from_view(&view, 1.0);
        for key in [behind, ahead] {
            assert_ne!(
                now.intersect_box(&layer.tile(key).bounds.obb),
                Intersection::Outside
            );
        }
        let request = |key| TileRequest { key, priority: 1.0 };
        let step = ellipsoid
            .cartographic_to_ecef(Cartographic::from_degrees(10.0, 45.18, 10_000.0))
            - view.position;
        let last_eye = Some(view.position - step);
        let motion = |last_eye, lookahead_frames| Motion {
            view: &view,
            last_eye,
            lookahead_frames,
            near_m: 1.0,
            above_ground_m: 10_000.0,
        };
        let mut to_load = vec![request(behind), request(ahead)];
        let deferred =
            defer_requests_left_behind(&layer, motion(last_eye, 3.0), |_| true, &mut to_load);
        assert_eq!(deferred, 1);
        assert_eq!(to_load.iter().map(|r| r.key).collect::<Vec<_>>(), [ahead]);
        // Standing still, lookahead off, first frame, or nothing loaded above the tile to
        // stand in for it: everything is requested.
        for (last, lookahead, covered) in [
            (Some(view.position), 3.0, true),
            (last_eye, 0.0, true),
            (None, 3.0, true),
            (last_eye, 3.0, false),
        ] {
            let mut to_load = vec![request(behind), request(ahead)];
            let deferred = defer_requests_left_behind(
                &layer,
                motion(last, lookahead),
                |_| covered,
                &mut to_load,
            );
            assert_eq!(deferred, 0);
            assert_eq!(to_load.len(), 2);
        }
    }

    /// A camera coming straight down fast, 800 m above the ground and 600 m lower every
    /// frame: three frames ahead at that speed it would be under the ground, and the tile
    /// under it would look left behind. The prediction stops halfway to the ground, so that
    /// tile is requested; one at the edge of today's view, which the narrowing view leaves,
    /// still waits.
    #[test]
    fn a_diving_camera_is_not_predicted_under_the_ground() {
        let source = Arc::new(ProceduralSource::new(crate::DEFAULT_SEED, 16));
        let layer = TerrainLayer::new(source, TerrainLayerOptions::default());
        let ellipsoid = Ellipsoid::WGS84;
        let at = |lat: f64, h: f64| Cartographic::from_degrees(10.0, lat, h);
        let view = View::from_geodetic(
            &ellipsoid,
            at(45.0, 800.0),
            0.0,
            -90f64.to_radians(),
            60f64.to_radians(),
            960,
            540,
        );
        let eye = at(45.0, 800.0);
        let below = GLOBE_SCHEME
            .tile_at(eye.lon_rad, eye.lat_rad, 14)
            .expect("tile");
        // 400 m north on the ground: inside the bottom of a 60 degree view from 800 m.
        let edge = GLOBE_SCHEME
            .tile_at(eye.lon_rad, eye.lat_rad + 400.0 / 6_371_000.0, 16)
            .expect("tile");
        let now = Frustum::from_view(&view, 1.0);
        for key in [below, edge] {
            assert_ne!(
                now.intersect_box(&layer.tile(key).bounds.obb),
                Intersection::Outside,
                "{key} in today's view"
            );
        }
        let last_eye = Some(ellipsoid.cartographic_to_ecef(at(45.0, 1_400.0)));
        let motion = Motion {
            view: &view,
            last_eye,
            lookahead_frames: 3.0,
            near_m: 1.0,
            above_ground_m: 800.0,
        };
        let request = |key| TileRequest { key, priority: 1.0 };
        let mut to_load = vec![request(below), request(edge)];
        let deferred = defer_requests_left_behind(&layer, motion, |_| true, &mut to_load);
        assert_eq!(to_load.iter().map(|r| r.key).collect::<Vec<_>>(), [below]);
        assert_eq!(deferred, 1);
    }

    /// Drawn tiles and their ancestors are in use, each once; wanted tiles split into those
    /// to load (not cached) and those to upload (cached, not resident).
    #[test]
    fn the_plan_counts_each_tile_in_use_once_and_splits_the_wishes() {
        let layer = TerrainLayer::new(
            Arc::new(ProceduralSource::new(crate::DEFAULT_SEED, 16)),
            TerrainLayerOptions::default(),
        );
        let drawn = |key| DrawTile {
            key,
            sse_px: 1.0,
            distance_m: 1.0,
            morph: 1.0,
            parts: globus_tiling::Quadrants::ALL,
        };
        let a = TileKey::new(5, 10, 7);
        let b = TileKey::new(5, 11, 7);
        let selection = Selection {
            draw: vec![drawn(a), drawn(b)],
            requests: vec![TileRequest {
                key: TileKey::new(6, 20, 14),
                priority: 2.0,
            }],
            stats: Default::default(),
        };
        let view = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(0.0, 0.0, 1e6),
            0.0,
            -1.0,
            1.0,
            100,
            100,
        );
        let mut plan = FramePlan::default();
        plan.make(
            &selection,
            &layer,
            &Residency::new(4, 100, 100),
            Motion {
                view: &view,
                last_eye: None,
                lookahead_frames: 3.0,
                near_m: 1.0,
                above_ground_m: 10_000.0,
            },
        );
        // a and b share their parent (5/10/7 and 5/11/7 are siblings) and everything above.
        let mut expected: Vec<TileKey> = vec![a, b];
        expected.extend(std::iter::successors(GLOBE_SCHEME.parent(a), |k| {
            GLOBE_SCHEME.parent(*k)
        }));
        let mut got = plan.in_use.clone();
        got.sort_by_key(|k| (k.level(), k.x(), k.y()));
        expected.sort_by_key(|k| (k.level(), k.x(), k.y()));
        assert_eq!(got, expected);
        assert_eq!(plan.to_load.len(), 1, "nothing is cached: load it");
        assert!(plan.to_upload.is_empty());
    }
}
