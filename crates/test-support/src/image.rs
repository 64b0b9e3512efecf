//! Helpers for looking at rendered frames in tests.

use std::path::Path;

/// An RGBA8 image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgba {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub pixels: Vec<u8>,
}

impl Rgba {
    /// The pixel at (x, y).
    pub fn get(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        [
            self.pixels[i],
            self.pixels[i + 1],
            self.pixels[i + 2],
            self.pixels[i + 3],
        ]
    }

    /// Reads an image file (PNG, JPEG, ...) as RGBA8.
    pub fn read(path: &Path) -> Result<Self, std::io::Error> {
        let img = image::open(path)
            .map_err(|e| std::io::Error::other(format!("reading {}: {e}", path.display())))?
            .to_rgba8();
        Ok(Self {
            width: img.width(),
            height: img.height(),
            pixels: img.into_raw(),
        })
    }

    /// Writes a PNG (alpha forced opaque when `opaque`), for a person to look at.
    pub fn save_png(&self, path: &Path, opaque: bool) -> Result<(), std::io::Error> {
        let mut px = self.pixels.clone();
        if opaque {
            px.chunks_exact_mut(4).for_each(|p| p[3] = 255);
        }
        image::save_buffer(path, &px, self.width, self.height, image::ColorType::Rgba8)
            .map_err(|e| std::io::Error::other(format!("writing {}: {e}", path.display())))
    }

    /// Mean absolute difference per channel (RGB) between two images of the same size, 0..255.
    pub fn mean_abs_diff(&self, other: &Rgba) -> f64 {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let mut sum = 0u64;
        for (a, b) in self
            .pixels
            .chunks_exact(4)
            .zip(other.pixels.chunks_exact(4))
        {
            for c in 0..3 {
                sum += u64::from(a[c].abs_diff(b[c]));
            }
        }
        sum as f64 / (f64::from(self.width) * f64::from(self.height) * 3.0)
    }

    /// The fraction of pixels where any RGB channel differs by more than `threshold`.
    pub fn fraction_differing(&self, other: &Rgba, threshold: u8) -> f64 {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let n = self
            .pixels
            .chunks_exact(4)
            .zip(other.pixels.chunks_exact(4))
            .filter(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > threshold))
            .count();
        n as f64 / (f64::from(self.width) * f64::from(self.height))
    }
}
