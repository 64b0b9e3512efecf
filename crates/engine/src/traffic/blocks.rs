//! Data blocks: the text of each aircraft's label (what an ATC display shows), laid out into
//! glyphs once and kept until what it says changes.
//!
//! ```text
//!  SWR123      call sign (the address in hex when there is none)
//!  FL350↑      flight level (hundreds of feet) and climbing ↑ / descending ↓; GND on the ground
//!  452kt       ground speed, knots
//!  +1200fpm    selected only: vertical rate (feet per minute) and the 24-bit address
//! ```

use std::hash::{Hash, Hasher};

use rustc_hash::FxHasher;

use crate::text::GlyphAtlas;

/// Vertical rate beyond which an aircraft counts as climbing or descending, m/s (about
/// 300 ft/min).
const LEVEL_MPS: f32 = 1.5;

/// What a data block says, as numbers (compared each frame; text is made only on change).
#[derive(Clone, Copy, Debug, PartialEq, Hash)]
pub(crate) struct BlockContent {
    pub id: u64,
    pub callsign: [u8; 8],
    /// Flight level, or `None` on the ground.
    pub flight_level: Option<i32>,
    /// -1 descending, 0 level, 1 climbing.
    pub trend: i8,
    /// Knots, or `None` when unknown.
    pub knots: Option<i32>,
    /// Feet per minute in steps of 100, shown when selected.
    pub selected_fpm: Option<i32>,
}

impl BlockContent {
    /// The content for an aircraft at `altitude_m` with `speeds` (ground speed, vertical
    /// rate, m/s; NaN unknown).
    pub fn new(
        id: u64,
        callsign: [u8; 8],
        altitude_m: f64,
        on_ground: bool,
        speeds: [f32; 2],
        selected: bool,
    ) -> Self {
        let [gs, vr] = speeds;
        let trend = if vr.is_finite() && vr > LEVEL_MPS {
            1
        } else if vr.is_finite() && vr < -LEVEL_MPS {
            -1
        } else {
            0
        };
        Self {
            id,
            callsign,
            flight_level: (!on_ground).then(|| (altitude_m / 0.3048 / 100.0).round() as i32),
            trend,
            knots: gs
                .is_finite()
                .then(|| (gs * 3600.0 / 1852.0).round() as i32),
            selected_fpm: selected.then(|| {
                if vr.is_finite() {
                    ((vr / 0.3048 * 60.0) / 100.0).round() as i32
                } else {
                    0
                }
            }),
        }
    }

    /// A key that changes when the text does.
    pub fn key(&self) -> u64 {
        let mut h = FxHasher::default();
        self.hash(&mut h);
        h.finish()
    }

    /// The lines of text.
    pub fn lines(&self) -> Vec<String> {
        let callsign: String = self
            .callsign
            .iter()
            .take_while(|&&b| b != 0)
            .map(|&b| b as char)
            .collect();
        let callsign = callsign.trim();
        let name = if callsign.is_empty() {
            format!("{:06x}", self.id & 0xff_ffff)
        } else {
            callsign.to_string()
        };
        let level = match self.flight_level {
            None => "GND".to_string(),
            Some(fl) => {
                let arrow = match self.trend {
                    1 => "\u{2191}",
                    -1 => "\u{2193}",
                    _ => "",
                };
                format!("FL{:03}{arrow}", fl.clamp(-99, 999))
            }
        };
        let speed = self.knots.map_or_else(
            || "---kt".to_string(),
            |k| format!("{}kt", k.clamp(0, 9999)),
        );
        let mut lines = vec![name, level, speed];
        if let Some(fpm) = self.selected_fpm {
            lines.push(format!("{:+}fpm {:06x}", fpm * 100, self.id & 0xff_ffff));
        }
        lines
    }
}

/// A data block laid out: glyphs (atlas index, top-left from the block's origin) and size.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct LaidOut {
    pub key: u64,
    pub glyphs: Vec<(u16, [f32; 2])>,
    pub size: [f32; 2],
}

impl LaidOut {
    /// Lays `content` out at `px` pixels per line, unless it is what is there already.
    pub fn update(&mut self, atlas: &GlyphAtlas, content: &BlockContent, px: f32) -> bool {
        let key = content.key() ^ u64::from(px.to_bits());
        if key == self.key && !self.glyphs.is_empty() {
            return false;
        }
        self.key = key;
        self.glyphs.clear();
        let lines = content.lines();
        let glyphs = &mut self.glyphs;
        self.size = atlas.layout(lines.iter().map(String::as_str), px, |g, x, y| {
            glyphs.push((g, [x, y]));
        });
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use globus_traffic::fleet::callsign_bytes;

    #[test]
    fn data_blocks_say_what_atc_displays_say() {
        let c = BlockContent::new(
            0x4b1805,
            callsign_bytes("SWR123"),
            10_668.0,
            false,
            [232.5, 6.0],
            false,
        );
        assert_eq!(c.lines(), ["SWR123", "FL350\u{2191}", "452kt"]);
        let c = BlockContent::new(0x4b1805, [0; 8], 1_000.0, false, [f32::NAN, -8.0], true);
        assert_eq!(
            c.lines(),
            ["4b1805", "FL033\u{2193}", "---kt", "-1600fpm 4b1805"]
        );
        let c = BlockContent::new(7, callsign_bytes("HBZZA"), 0.0, true, [5.0, 0.0], false);
        assert_eq!(c.lines()[1], "GND");
        // The key follows the text.
        let a = BlockContent::new(1, [0; 8], 10_000.0, false, [200.0, 0.0], false);
        let b = BlockContent::new(1, [0; 8], 10_010.0, false, [200.1, 0.0], false);
        let d = BlockContent::new(1, [0; 8], 10_100.0, false, [200.0, 0.0], false);
        assert_eq!(a.key(), b.key());
        assert_ne!(a.key(), d.key());
    }

    #[test]
    fn a_block_is_laid_out_again_only_when_its_text_changes() {
        let atlas = GlyphAtlas::new().expect("font");
        let mut block = LaidOut::default();
        let c = BlockContent::new(
            1,
            callsign_bytes("AB1"),
            10_000.0,
            false,
            [200.0, 0.0],
            false,
        );
        assert!(block.update(&atlas, &c, 13.0));
        // "AB1", "FL328", "389kt": 13 glyphs with ink.
        assert_eq!(block.glyphs.len(), 13);
        assert!((block.size[1] - 39.0).abs() < 1e-4);
        assert!(!block.update(&atlas, &c, 13.0));
        let climbing = BlockContent { trend: 1, ..c };
        assert!(block.update(&atlas, &climbing, 13.0));
        assert_eq!(block.glyphs.len(), 14);
    }
}
