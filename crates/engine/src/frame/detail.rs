//! How the memory and triangle budgets move the error bound: up while one of them binds,
//! back down towards the configured (or frame-time) bound once all of them have room.
//!
//! Live frames move the bound by a few percent a frame. Selection's morph follows the bound
//! (a tile's blend of its own and its parent's surface is a function of its error over the
//! bound), so a slow rise merges tiles after they have grown back into their parents and a
//! slow fall splits them as usual: nothing pops. A step of 1.25, as before, merged hundreds
//! of tiles at a fraction of their morph in one frame. The room needed to relax is well
//! below the limit that raises (a band about 1.3x wide in the bound, since tiles, bytes and
//! triangles go as the inverse square of the bound), so the bound settles inside the band
//! instead of oscillating across a single threshold.
//!
//! A frame that must settle (an offline render, a benchmark's loaded frame) is not shown
//! while it settles: it steps by 1.25 and never relaxes, so the same view always settles on
//! the same tiles.

/// Live frames: the factor per frame while a budget binds.
pub(crate) const LIVE_RAISE: f64 = 1.04;
/// Live frames: the factor per frame back down with room.
pub(crate) const LIVE_RELAX: f64 = 1.02;
/// Settling frames: the factor per frame while a budget binds.
pub(crate) const SETTLE_RAISE: f64 = 1.25;

/// The GPU pool's slots, the CPU cache's bytes and the software rasteriser's triangles:
/// what the frame used of each.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct BudgetUse {
    /// Pool slots needed (the drawn tiles and the ancestors selection walks through) and
    /// held, and whether an upload found the pool full.
    pub slots_needed: f64,
    pub slots: f64,
    pub pool_full: bool,
    /// Cache bytes this frame uses, the budget, and whether what is in use is over it.
    pub cache_in_use: f64,
    pub cache_budget: f64,
    pub cache_over: bool,
    /// Triangles drawn and the cap, if there is one.
    pub triangles: f64,
    pub triangle_cap: Option<f64>,
}

impl BudgetUse {
    /// Whether a budget binds: less detail.
    pub(crate) fn binds(&self) -> bool {
        self.pool_full
            || self.slots_needed > 0.9 * self.slots
            || self.cache_over
            || self.triangle_cap.is_some_and(|cap| self.triangles > cap)
    }

    /// Whether every budget has room for more detail.
    pub(crate) fn has_room(&self) -> bool {
        self.slots_needed < 0.6 * self.slots
            && self.cache_in_use < 0.6 * self.cache_budget
            && self
                .triangle_cap
                .is_none_or(|cap| self.triangles < 0.75 * cap)
    }
}

/// The next frame's error bound from this frame's `bound`, the least it may fall to
/// (`floor`: the configured bound, or the frame-time loop's), what the budgets say, and
/// whether frames are live (shown as they come) or settling.
pub(crate) fn next_bound(bound: f64, floor: f64, budgets: &BudgetUse, live: bool) -> f64 {
    if budgets.binds() {
        return bound * if live { LIVE_RAISE } else { SETTLE_RAISE };
    }
    if bound < floor {
        // The frame-time loop asks for less detail (it moves smoothly itself).
        return floor;
    }
    if live && bound > floor && budgets.has_room() {
        return (bound / LIVE_RELAX).max(floor);
    }
    bound
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stand-in frame at `bound`: tiles, cache bytes and triangles go as the inverse
    /// square of the bound; `scale` sets how much the view needs (2 px needs `scale` of
    /// each budget).
    fn frame(bound: f64, scale: f64) -> BudgetUse {
        let need = scale * (2.0 / bound).powi(2);
        BudgetUse {
            slots_needed: 0.3 * need * 1000.0,
            slots: 1000.0,
            pool_full: false,
            cache_in_use: need * 1e9,
            cache_budget: 1e9,
            cache_over: need > 1.0,
            triangles: 0.5 * need * 1e6,
            triangle_cap: Some(1e6),
        }
    }

    #[test]
    fn a_binding_budget_moves_the_bound_a_few_percent_a_frame_and_it_settles_without_swinging() {
        for scale in [1.5, 3.0, 10.0] {
            let mut bound = 2.0;
            let mut history = vec![bound];
            for _ in 0..400 {
                bound = next_bound(bound, 2.0, &frame(bound, scale), true);
                history.push(bound);
            }
            // Every step is small: morphing carries the splits and merges.
            for w in history.windows(2) {
                let ratio = w[1] / w[0];
                assert!(
                    (1.0 / LIVE_RELAX - 1e-12..=LIVE_RAISE + 1e-12).contains(&ratio),
                    "{scale}: {ratio}"
                );
            }
            // It ends where the cache holds what is in use, and stays there: the last 200
            // frames do not move.
            let last = history[history.len() - 1];
            assert!(!frame(last, scale).binds(), "{scale}: {last}");
            assert!(
                history[200..].iter().all(|&b| b == last),
                "{scale}: the bound keeps moving: {:?}",
                &history[200..220]
            );
            // Within one raise of the least bound that fits (the cache: 2 * sqrt(scale)).
            let least = 2.0 * scale.sqrt();
            assert!(
                last >= least && last <= least * LIVE_RAISE,
                "{scale}: {last}"
            );
        }
    }

    #[test]
    fn with_room_again_the_bound_falls_back_to_the_floor_and_no_further() {
        let mut bound = 8.0;
        for _ in 0..200 {
            bound = next_bound(bound, 2.0, &frame(bound, 0.2), true);
        }
        assert_eq!(bound, 2.0);
        // Between the two limits it holds.
        let between = frame(2.0, 0.8);
        assert!(!between.binds() && !between.has_room());
        assert_eq!(next_bound(2.5, 2.0, &between, true), 2.5);
        // The frame-time loop's floor is followed at once.
        assert_eq!(next_bound(2.0, 3.0, &frame(2.0, 0.2), true), 3.0);
    }

    #[test]
    fn settling_frames_only_rise_and_in_larger_steps() {
        assert_eq!(next_bound(2.0, 2.0, &frame(2.0, 3.0), false), 2.5);
        assert_eq!(next_bound(4.0, 2.0, &frame(4.0, 0.1), false), 4.0);
    }
}
