//! The quality factor with frame-time feedback (Kaiser 2012, 4.3.2): the screen-space error
//! bound follows the measured frame time towards a target frame rate.
//!
//! Frames slower than the target raise the bound (coarser tiles, fewer triangles, fewer
//! loads); frames with headroom lower it again, never outside a configured range. The loop:
//!
//! 1. smooths the frame time, scaled by the model below to what it would be at the finest
//!    bound, exponentially over [`SMOOTHING_S`] of *time*, not frames, so that it reacts
//!    alike at 10 and at 100 frames per second, and one hitch moves it little;
//! 2. holds the bound while the smoothed time lies in a dead band round the target, from
//!    [`RAISE_ABOVE`] down to [`LOWER_BELOW`] of it: the hysteresis that keeps it from hunting
//!    after it has settled, or from trading detail back and forth on noise;
//! 3. outside the band, moves the bound towards the one its model says meets the target
//!    (aiming at the target when raising and inside the band when lowering), a fraction
//!    `1 - exp(-frame / RESPONSE_S)` of the way in log space per frame.
//!
//! The model: drawing and loading cost scales with the tiles drawn, and a cut bounded by `e`
//! pixels draws about `1 / e^2` tiles (tile sizes halve per level while their count per area
//! quadruples), so the frame time goes as `e^-2` and the bound that meets the target is
//! `e * (t / target)^(1/2)`. A scene whose cost follows another power still converges (the
//! step is then too long or too short, and the smoothing damps it), as the tests check.
//!
//! Written by hand: it is a dozen lines of control, with no crate in this field to trust for
//! them.

/// Time constant of the frame-time smoothing, seconds.
pub const SMOOTHING_S: f64 = 0.2;
/// Time constant of the bound's response, seconds.
pub const RESPONSE_S: f64 = 0.25;
/// The bound rises while the smoothed frame time is above this fraction of the target.
pub const RAISE_ABOVE: f64 = 1.03;
/// The bound falls while the smoothed frame time is below this fraction of the target.
pub const LOWER_BELOW: f64 = 0.85;
/// When lowering, the bound aims at this fraction of the target (inside the dead band).
const LOWER_AIM: f64 = 0.92;
/// The cost model's exponent: frame time goes as `bound^-COST_EXPONENT`.
const COST_EXPONENT: f64 = 2.0;
/// A frame longer than this many smoothed frame times counts as this many (a stall while a
/// window was moved or a shader compiled must not throw the bound to its limit).
const MAX_FRAME_RATIO: f64 = 4.0;

/// A quality loop's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QualityOptions {
    /// The frame time to reach, seconds (1 / target frames per second).
    pub target_frame_s: f64,
    /// The finest error bound, pixels: the bound with headroom to spare.
    pub min_sse_px: f64,
    /// The coarsest error bound, pixels: never raised past it however slow frames are.
    pub max_sse_px: f64,
}

/// Settings a quality loop cannot work with.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum QualityError {
    /// The target frame rate is not a positive, finite number of frames per second.
    #[error("target frame rate {0} must be above 0 and at most 1000 frames per second")]
    TargetFps(f64),
    /// The bound's range is empty or not positive.
    #[error("error bound range {min} to {max} px must run upwards from above 0")]
    Range {
        /// The finest bound.
        min: f64,
        /// The coarsest bound.
        max: f64,
    },
}

impl QualityOptions {
    /// Settings for `fps` frames per second, the bound between `min_sse_px` and `max_sse_px`.
    pub fn new(fps: f64, min_sse_px: f64, max_sse_px: f64) -> Result<Self, QualityError> {
        if !(fps > 0.0 && fps <= 1000.0) {
            return Err(QualityError::TargetFps(fps));
        }
        if !(min_sse_px > 0.0 && min_sse_px <= max_sse_px && max_sse_px.is_finite()) {
            return Err(QualityError::Range {
                min: min_sse_px,
                max: max_sse_px,
            });
        }
        Ok(Self {
            target_frame_s: 1.0 / fps,
            min_sse_px,
            max_sse_px,
        })
    }
}

/// The error bound under frame-time feedback; see the module documentation.
#[derive(Clone, Debug)]
pub struct QualityLoop {
    options: QualityOptions,
    sse_px: f64,
    smoothed_s: Option<f64>,
    /// The smoothed frame time scaled by the model to the finest bound.
    finest_cost_s: Option<f64>,
}

impl QualityLoop {
    /// A loop starting at the finest bound.
    pub fn new(options: QualityOptions) -> Self {
        Self {
            options,
            sse_px: options.min_sse_px,
            smoothed_s: None,
            finest_cost_s: None,
        }
    }

    /// Its settings.
    pub fn options(&self) -> &QualityOptions {
        &self.options
    }

    /// The error bound to select the next frame with, pixels.
    pub fn sse_px(&self) -> f64 {
        self.sse_px
    }

    /// The smoothed frame time, seconds (`None` before the first frame).
    pub fn smoothed_frame_s(&self) -> Option<f64> {
        self.smoothed_s
    }

    /// Feeds the time the last frame took (seconds) and returns the bound for the next.
    /// Times that are not positive and finite are ignored.
    pub fn record(&mut self, frame_s: f64) -> f64 {
        if !(frame_s > 0.0 && frame_s.is_finite()) {
            return self.sse_px;
        }
        let frame_s = self
            .smoothed_s
            .map_or(frame_s, |s| frame_s.min(s * MAX_FRAME_RATIO));
        let weight = 1.0 - (-frame_s / SMOOTHING_S).exp();
        let smooth = |old: Option<f64>, new: f64| old.map_or(new, |o| o + (new - o) * weight);
        self.smoothed_s = Some(smooth(self.smoothed_s, frame_s));
        // What this frame would have cost at the finest bound, by the model: smoothing this
        // instead of the frame time itself keeps the smoothing's lag out of the loop (the
        // bound's own changes do not read as changes of the scene), so it does not overshoot.
        let min = self.options.min_sse_px;
        let scale = (self.sse_px / min).powf(COST_EXPONENT);
        let cost_s = smooth(self.finest_cost_s, frame_s * scale);
        self.finest_cost_s = Some(cost_s);
        let ratio = cost_s / scale / self.options.target_frame_s;
        let aim = if ratio > RAISE_ABOVE {
            ratio
        } else if ratio < LOWER_BELOW {
            ratio / LOWER_AIM
        } else {
            return self.sse_px;
        };
        let step = 1.0 - (-frame_s / RESPONSE_S).exp();
        let log_sse = self.sse_px.ln() + step * aim.ln() / COST_EXPONENT;
        self.sse_px = log_sse.exp().clamp(min, self.options.max_sse_px);
        self.sse_px
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A renderer stand-in whose frame costs `base_s * (min / bound)^exponent`, plus noise
    /// from a fixed generator: returns the (time, frame time, bound) of every frame of
    /// `seconds` of simulated wall time, the cost changing to `then_base_s` at `switch_s`.
    fn simulate(
        q: &mut QualityLoop,
        base_s: f64,
        exponent: f64,
        noise: f64,
        seconds: f64,
        switch: Option<(f64, f64)>,
    ) -> Vec<(f64, f64, f64)> {
        let min = q.options().min_sse_px;
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let (mut t, mut out) = (0.0, Vec::new());
        while t < seconds {
            let base = match switch {
                Some((at, b)) if t >= at => b,
                _ => base_s,
            };
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            let jitter = 1.0 + noise * ((rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0);
            let frame = base * (min / q.sse_px()).powf(exponent) * jitter;
            t += frame;
            q.record(frame);
            out.push((t, frame, q.sse_px()));
        }
        out
    }

    /// The frames after `from_s`: their smoothed-over-a-second frame times all lie within
    /// `tolerance` of the target, and their bounds within the loop's range.
    fn settled_within(frames: &[(f64, f64, f64)], from_s: f64, target: f64, tolerance: f64) {
        let later: Vec<_> = frames.iter().filter(|f| f.0 >= from_s).collect();
        assert!(later.len() > 10, "{} frames after {from_s} s", later.len());
        // The mean frame time over every window of 10 frames (what a user sees as the rate).
        for w in later.windows(10) {
            let mean = w.iter().map(|f| f.1).sum::<f64>() / 10.0;
            assert!(
                (mean / target - 1.0).abs() <= tolerance,
                "frames of {:.1} ms at {:.2} s for a target of {:.1} ms",
                mean * 1e3,
                w[0].0,
                target * 1e3
            );
        }
    }

    fn options(fps: f64) -> QualityOptions {
        QualityOptions::new(fps, 2.0, 16.0).expect("valid")
    }

    #[test]
    fn a_renderer_twice_as_slow_as_the_target_converges_within_two_seconds() {
        for fps in [20.0, 30.0, 60.0, 120.0] {
            let mut q = QualityLoop::new(options(fps));
            let target = 1.0 / fps;
            let frames = simulate(&mut q, 2.0 * target, 2.0, 0.0, 10.0, None);
            settled_within(&frames, 2.0, target, 0.10);
            // The bound that halves an e^-2 cost: 2 * sqrt(2) px, within the dead band.
            let last = frames.last().expect("frames").2;
            assert!((2.6..=2.9).contains(&last), "bound {last} at {fps} fps");
        }
    }

    #[test]
    fn costs_that_scale_otherwise_and_noisy_frames_still_settle() {
        for (exponent, noise) in [(1.0, 0.0), (3.0, 0.0), (2.0, 0.15), (1.5, 0.25)] {
            let mut q = QualityLoop::new(options(30.0));
            let frames = simulate(&mut q, 2.0 / 30.0, exponent, noise, 12.0, None);
            // Noise of +-25 % per frame averages to under 10 % over 10 frames only loosely.
            settled_within(&frames, 2.0, 1.0 / 30.0, 0.10 + noise * 0.4);
        }
    }

    #[test]
    fn headroom_brings_the_bound_back_and_it_never_leaves_its_range() {
        let mut q = QualityLoop::new(options(30.0));
        // Ten times too slow, in a scene whose cost goes as 1 / bound: the bound rises to its
        // limit (16 px cuts the cost only 8x) and stays there.
        let frames = simulate(&mut q, 10.0 / 30.0, 1.0, 0.0, 6.0, Some((3.0, 0.2 / 30.0)));
        let at = |t: f64| {
            frames
                .iter()
                .find(|f| f.0 >= t)
                .map(|f| f.2)
                .expect("a frame then")
        };
        assert!(at(2.9) > 15.9, "bound {} while far too slow", at(2.9));
        assert!(frames.iter().all(|f| (2.0..=16.0).contains(&f.2)));
        // Then the scene becomes cheap (a fifth of the target at the finest bound): back to
        // the finest within two seconds.
        assert_eq!(at(5.0), 2.0);
    }

    #[test]
    fn inside_the_dead_band_the_bound_holds() {
        let mut q = QualityLoop::new(options(30.0));
        let frames = simulate(&mut q, 1.0 / 30.0, 2.0, 0.0, 5.0, None);
        assert!(frames.iter().all(|f| f.2 == 2.0));
        // Slower by 2 %, then faster by 10 %: both inside the band.
        let mut q = QualityLoop::new(QualityOptions::new(30.0, 4.0, 8.0).expect("valid"));
        for cost in [1.02, 0.9] {
            for _ in 0..200 {
                q.record(cost / 30.0);
            }
            assert_eq!(q.sse_px(), 4.0);
        }
    }

    #[test]
    fn one_stall_moves_the_bound_little() {
        let mut q = QualityLoop::new(options(60.0));
        for _ in 0..120 {
            q.record(1.0 / 60.0);
        }
        // A 2 s stall (a window dragged): counted as two frames. time at most.
        q.record(2.0);
        assert!(q.sse_px() < 4.0, "bound {} after one stall", q.sse_px());
        for _ in 0..120 {
            q.record(1.0 / 60.0);
        }
        assert!(q.sse_px() < 4.0);
    }

    #[test]
    fn bad_settings_and_bad_times_are_refused() {
        for fps in [0.0, -30.0, f64::NAN, f64::INFINITY, 1e6] {
            assert!(matches!(
                QualityOptions::new(fps, 2.0, 8.0),
                Err(QualityError::TargetFps(_))
            ));
        }
        for (min, max) in [
            (0.0, 8.0),
            (8.0, 2.0),
            (2.0, f64::INFINITY),
            (f64::NAN, 4.0),
        ] {
            assert!(matches!(
                QualityOptions::new(30.0, min, max),
                Err(QualityError::Range { .. })
            ));
        }
        let mut q = QualityLoop::new(options(30.0));
        for t in [f64::NAN, -1.0, 0.0, f64::INFINITY] {
            assert_eq!(q.record(t), 2.0);
        }
        assert_eq!(q.smoothed_frame_s(), None);
    }
}
