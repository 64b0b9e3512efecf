//! Text for labels: a signed-distance-field glyph atlas of one monospaced font, made at
//! start-up, and the layout of short lines of text in it.
//!
//! The font is Hack (MIT / Bitstream Vera licence), the monospaced face egui ships in the
//! `epaint_default_fonts` crate: it comes with the build, so a fresh machine needs nothing
//! installed. Outlines and metrics come from `ab_glyph` (a well-kept pure-Rust OpenType
//! reader). Labels here are data blocks (call signs, flight levels, speeds) in ASCII plus a
//! few symbols, laid out on a fixed grid of advances; complex scripts, bidirectional text and
//! ligatures never occur, so a full shaper (cosmic-text, rustybuzz) would add a dependency
//! stack without changing a pixel. Kerning of the font is applied all the same (Hack has
//! none).
//!
//! Each glyph is rasterised at [`EM_PX`] and turned into a distance field ([`sdf`]) with a
//! [`SPREAD_PX`] reach, so one atlas draws crisp text at any size from a few pixels to a
//! hundred and gives halos for free.

pub mod sdf;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};

/// Pixel height the atlas's glyphs are rasterised at.
pub const EM_PX: f32 = 32.0;
/// How far (atlas pixels) the distance field reaches on either side of an edge.
pub const SPREAD_PX: f32 = 6.0;

/// The characters the atlas holds: printable ASCII, then these.
const EXTRA: [char; 4] = ['↑', '↓', '→', '°'];

/// One glyph's place in the atlas.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Glyph {
    /// Top-left texel and size in the atlas.
    pub rect: [u32; 4],
    /// Where the rect's top-left lies from the pen on the baseline (atlas pixels, `y` down).
    pub offset: [f32; 2],
    /// Advance to the next pen position, atlas pixels.
    pub advance: f32,
}

/// A distance-field atlas of the label font.
#[derive(Clone, Debug)]
pub struct GlyphAtlas {
    /// Width and height, texels.
    pub size: [u32; 2],
    /// One byte per texel: 128 - 127 * distance / [`SPREAD_PX`] (distance positive outside),
    /// clamped: the glyph's edge is at [`GlyphAtlas::EDGE`].
    pub texels: Vec<u8>,
    /// Glyphs, by [`glyph_index`].
    pub glyphs: Vec<Glyph>,
    /// Baseline to baseline, atlas pixels.
    pub line_height: f32,
    /// Baseline below the top of a line, atlas pixels.
    pub ascent: f32,
}

/// The atlas could not be made (the embedded font is unreadable: a build problem).
#[derive(Debug, thiserror::Error)]
#[error("the label font cannot be read: {0}")]
pub struct FontError(String);

/// The atlas index of a character (`None` for characters it lacks: they are drawn as `?`).
pub fn glyph_index(c: char) -> Option<u16> {
    match c {
        ' '..='~' => Some(c as u16 - 32),
        _ => EXTRA.iter().position(|&e| e == c).map(|i| 95 + i as u16),
    }
}

impl GlyphAtlas {
    /// The texel value of a glyph's edge.
    pub const EDGE: f32 = 128.0 / 255.0;

    /// The atlas of the embedded font.
    pub fn new() -> Result<Self, FontError> {
        let font = FontRef::try_from_slice(epaint_default_fonts::HACK_REGULAR)
            .map_err(|e| FontError(e.to_string()))?;
        let scale = PxScale::from(EM_PX);
        let scaled = font.as_scaled(scale);
        let chars: Vec<char> = (' '..='~').chain(EXTRA).collect();
        let pad = SPREAD_PX.ceil() as u32;
        let cell_w = (scaled.h_advance(font.glyph_id('M')).ceil() as u32) + 2 * pad + 2;
        let cell_h = (scaled.height().ceil() as u32) + 2 * pad + 2;
        let columns = 16u32;
        let rows = (chars.len() as u32).div_ceil(columns);
        let size = [columns * cell_w, rows * cell_h];
        let mut texels = vec![0u8; (size[0] * size[1]) as usize];
        let mut glyphs = Vec::with_capacity(chars.len());
        for (i, &c) in chars.iter().enumerate() {
            let (cx, cy) = ((i as u32 % columns) * cell_w, (i as u32 / columns) * cell_h);
            let id = font.glyph_id(c);
            let advance = scaled.h_advance(id);
            let mut glyph = Glyph {
                rect: [cx, cy, 0, 0],
                offset: [0.0; 2],
                advance,
            };
            if let Some(outlined) =
                font.outline_glyph(id.with_scale_and_position(scale, point(0.0, 0.0)))
            {
                let b = outlined.px_bounds();
                // Coverage with room for the field around it.
                let w = (b.width() as u32 + 2 * pad).min(cell_w);
                let h = (b.height() as u32 + 2 * pad).min(cell_h);
                let mut coverage = vec![0.0f32; (w * h) as usize];
                outlined.draw(|x, y, a| {
                    let (x, y) = (x + pad, y + pad);
                    if x < w && y < h {
                        coverage[(y * w + x) as usize] = a;
                    }
                });
                let field = sdf::signed_distance(&coverage, w as usize, h as usize);
                for y in 0..h {
                    for x in 0..w {
                        let d = field[(y * w + x) as usize];
                        let v = 128.0 - 127.0 * d / SPREAD_PX;
                        texels[((cy + y) * size[0] + cx + x) as usize] = v.clamp(0.0, 255.0) as u8;
                    }
                }
                glyph.rect = [cx, cy, w, h];
                glyph.offset = [b.min.x - pad as f32, b.min.y - pad as f32];
            }
            glyphs.push(glyph);
        }
        Ok(Self {
            size,
            texels,
            glyphs,
            line_height: scaled.height() + scaled.line_gap(),
            ascent: scaled.ascent(),
        })
    }

    /// An atlas with no glyphs (stands in where the font could not be read: nothing is
    /// drawn from it).
    pub fn empty() -> Self {
        Self {
            size: [1, 1],
            texels: vec![0],
            glyphs: vec![Glyph::default()],
            line_height: 1.0,
            ascent: 1.0,
        }
    }

    /// The glyph of a character (`?` for those the atlas lacks).
    pub fn glyph(&self, c: char) -> (u16, &Glyph) {
        let i = glyph_index(c).or_else(|| glyph_index('?')).unwrap_or(0);
        (i, &self.glyphs[usize::from(i)])
    }

    /// Lays out lines of text at `px` pixels per line height: calls `place(glyph index,
    /// top-left x, y)` (pixels from the block's top-left) for each visible glyph and returns
    /// the block's width and height in pixels.
    pub fn layout<'a>(
        &self,
        lines: impl IntoIterator<Item = &'a str>,
        px: f32,
        mut place: impl FnMut(u16, f32, f32),
    ) -> [f32; 2] {
        let s = px / self.line_height;
        let mut width: f32 = 0.0;
        let mut rows = 0u32;
        for (row, line) in lines.into_iter().enumerate() {
            rows = row as u32 + 1;
            let baseline = row as f32 * self.line_height + self.ascent;
            let mut pen = 0.0;
            for c in line.chars() {
                let (i, g) = self.glyph(c);
                if g.rect[2] > 0 {
                    place(i, (pen + g.offset[0]) * s, (baseline + g.offset[1]) * s);
                }
                pen += g.advance;
            }
            width = width.max(pen * s);
        }
        [width, rows as f32 * px]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_atlas_holds_every_character_labels_use_with_its_edge_at_the_outline() {
        let atlas = GlyphAtlas::new().expect("the embedded font");
        assert_eq!(atlas.glyphs.len(), 95 + EXTRA.len());
        // Monospaced: every advance is the same.
        let a = atlas.glyph('A').1.advance;
        assert!(atlas.glyphs.iter().all(|g| (g.advance - a).abs() < 1e-3));
        // Inside the stroke of an 'I' the field is above the edge, beside it below.
        let (_, i) = atlas.glyph('I');
        let [x, y, w, h] = i.rect;
        let at = |dx: u32, dy: u32| atlas.texels[((y + dy) * atlas.size[0] + x + dx) as usize];
        assert!(at(w / 2, h / 2) > 140, "centre of I: {}", at(w / 2, h / 2));
        assert!(at(0, h / 2) < 40, "left of I: {}", at(0, h / 2));
        // Every glyph with ink has a field crossing its edge; space has none.
        for c in ['0', 'Z', '↑', '°'] {
            let (_, g) = atlas.glyph(c);
            assert!(g.rect[2] > 0 && g.rect[3] > 0, "{c}");
        }
        assert_eq!(atlas.glyph(' ').1.rect[2], 0);
        // A character the atlas lacks is drawn as '?'.
        assert_eq!(atlas.glyph('€').0, glyph_index('?').unwrap_or(0));
    }

    #[test]
    fn lines_are_laid_out_on_a_grid_of_advances() {
        let atlas = GlyphAtlas::new().expect("the embedded font");
        let mut placed = Vec::new();
        let size = atlas.layout(["AB", "FL350"], 14.0, |i, x, y| placed.push((i, x, y)));
        let advance = atlas.glyph('A').1.advance * 14.0 / atlas.line_height;
        assert!((size[0] - 5.0 * advance).abs() < 1e-3);
        assert!((size[1] - 28.0).abs() < 1e-3);
        assert_eq!(placed.len(), 7);
        // 'B' one advance right of 'A' (same glyph offsets would give exactly one advance).
        let (a, b) = (placed[0], placed[1]);
        let off = |c: char| atlas.glyph(c).1.offset[0] * 14.0 / atlas.line_height;
        assert!(((b.1 - off('B')) - (a.1 - off('A')) - advance).abs() < 1e-3);
        // The second line 14 px lower.
        let f = placed[2];
        let yoff = |c: char| atlas.glyph(c).1.offset[1] * 14.0 / atlas.line_height;
        assert!(((f.2 - yoff('F')) - (a.2 - yoff('A')) - 14.0).abs() < 1e-3);
    }
}
