//! [`ColourFades`]: the imagery cross-fade. A drawn tile shows its nearest ancestor's
//! colour, cropped, while its own imagery loads; when its own arrives it fades in over
//! [`ColourFades::duration`] (200 ms by default) instead of replacing the ancestor's in one
//! frame. Plain bookkeeping per pool slot, tested without a GPU.

use std::time::{Duration, Instant};

use globus_tiling::TileKey;

/// How long a tile's own imagery takes to replace its ancestor's by default.
pub const COLOUR_FADE: Duration = Duration::from_millis(200);

/// Per pool slot: which tile was drawn there, whether with its own colour, and since when.
#[derive(Clone, Debug)]
pub struct ColourFades {
    slots: Vec<Option<Slot>>,
    duration: Duration,
}

#[derive(Clone, Copy, Debug)]
struct Slot {
    key: TileKey,
    own: bool,
    /// When its own colour first showed, if it came after the tile was drawn borrowing.
    since: Option<Instant>,
}

impl ColourFades {
    /// No tile seen yet in any of `slots` slots; fades take [`COLOUR_FADE`].
    pub fn new(slots: u32) -> Self {
        Self {
            slots: vec![None; slots as usize],
            duration: COLOUR_FADE,
        }
    }

    /// How long fades take; zero switches them off (frames that must settle, tests).
    pub fn set_duration(&mut self, duration: Duration) {
        self.duration = duration;
    }

    /// The fade's length.
    pub fn duration(&self) -> Duration {
        self.duration
    }

    /// How much of tile `key`'s own colour to show, 0 to 1, when it is drawn from `slot` at
    /// `now`, `own` saying whether it has its own colour: 1 for a tile first drawn with it,
    /// rising from 0 over the fade's length for one whose own colour has just replaced an
    /// ancestor's, and 0 while it borrows (then its own is not there to show).
    pub fn own_share(&mut self, slot: u32, key: TileKey, own: bool, now: Instant) -> f32 {
        let Some(entry) = self.slots.get_mut(slot as usize) else {
            return 1.0;
        };
        let state = match entry {
            Some(s) if s.key == key => s,
            _ => entry.insert(Slot {
                key,
                own,
                since: None,
            }),
        };
        if own && !state.own {
            state.since = Some(now);
        }
        state.own = own;
        if !own {
            return 0.0;
        }
        let Some(since) = state.since else {
            return 1.0;
        };
        let share = if self.duration.is_zero() {
            1.0
        } else {
            now.saturating_duration_since(since).as_secs_f64() / self.duration.as_secs_f64()
        };
        if share >= 1.0 {
            state.since = None;
            return 1.0;
        }
        share as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_imagery_fades_in_over_the_fade_once_it_replaces_an_ancestors() {
        let t0 = Instant::now();
        let ms = |m: u64| t0 + Duration::from_millis(m);
        let mut f = ColourFades::new(4);
        let key = TileKey::new(7, 10, 20);
        // Drawn borrowing: none of its own (the ancestor's shows).
        assert_eq!(f.own_share(2, key, false, ms(0)), 0.0);
        assert_eq!(f.own_share(2, key, false, ms(16)), 0.0);
        // Its own arrives: from 0, halfway at 100 ms, all of it from 200 ms on.
        assert_eq!(f.own_share(2, key, true, ms(32)), 0.0);
        assert!((f.own_share(2, key, true, ms(132)) - 0.5).abs() < 1e-6);
        assert_eq!(f.own_share(2, key, true, ms(232)), 1.0);
        assert_eq!(f.own_share(2, key, true, ms(240)), 1.0);
        // Another tile in the slot, drawn with its colour from the start: no fade.
        let other = TileKey::new(7, 11, 20);
        assert_eq!(f.own_share(2, other, true, ms(250)), 1.0);
        // Fades off: at once.
        let mut off = ColourFades::new(4);
        off.set_duration(Duration::ZERO);
        assert_eq!(off.own_share(0, key, false, ms(0)), 0.0);
        assert_eq!(off.own_share(0, key, true, ms(1)), 1.0);
        // A slot past the pool's: its own colour.
        assert_eq!(f.own_share(9, key, true, ms(0)), 1.0);
    }
}
