//! [`NightLights`]: the lights of cities seen on the night side, from an equirectangular image
//! of the whole planet (NASA's Black Marble, `earth-night-*.jpg` in the shared data).
//!
//! The image is kept as one channel (see [`NightLights::from_rgb`]) with its mip chain (a 4096 x 2048 image takes
//! 11 MiB on the GPU rather than 45 as RGBA), and the terrain shader tints it sodium-lamp
//! orange. The shader finds a fragment's longitude and geodetic latitude from its ECEF position
//! (the eye's, rounded to f32 once, plus the fragment's offset from the eye: about a metre
//! off, a ten-thousandth of a texel), picks the mip level from the ground a pixel covers (the
//! longitude seam would break the derivatives a hardware mip choice uses), and adds the lights
//! where the Sun is below the horizon, fading in through twilight.

/// Why an image cannot be night lights.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum NightLightsError {
    /// Not twice as wide as tall, empty, or wider than [`NightLights::MAX_WIDTH`].
    #[error(
        "night lights must be an equirectangular image twice as wide as tall, at most {} wide: \
         got {width} x {height}",
        NightLights::MAX_WIDTH
    )]
    BadSize {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The pixel data does not match the size.
    #[error("{width} x {height} pixels need {expected} bytes, got {got}")]
    WrongLength {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Bytes expected.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
}

/// A whole planet's night lights: luminance, equirectangular (column 0 at 180 degrees west,
/// row 0 at the north pole), level 0 first then each mip level.
#[derive(Clone, Debug, PartialEq)]
pub struct NightLights {
    levels: Vec<(u32, u32, Vec<u8>)>,
}

impl NightLights {
    /// Widest image taken (the texture limit every wgpu device has is 8192).
    pub const MAX_WIDTH: u32 = 8192;

    /// From one byte of luminance per pixel, row-major.
    pub fn from_luminance(
        width: u32,
        height: u32,
        data: Vec<u8>,
    ) -> Result<Self, NightLightsError> {
        if height == 0 || width != 2 * height || width > Self::MAX_WIDTH {
            return Err(NightLightsError::BadSize { width, height });
        }
        let expected = width as usize * height as usize;
        if data.len() != expected {
            return Err(NightLightsError::WrongLength {
                width,
                height,
                expected,
                got: data.len(),
            });
        }
        let mut levels = vec![(width, height, data)];
        while let Some((w, h, data)) = levels.last()
            && (*w > 1 || *h > 1)
        {
            let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
            let at = |x: u32, y: u32| u32::from(data[(y.min(h - 1) * w + x.min(w - 1)) as usize]);
            let mut next = Vec::with_capacity((nw * nh) as usize);
            for y in 0..nh {
                for x in 0..nw {
                    let sum = at(2 * x, 2 * y)
                        + at(2 * x + 1, 2 * y)
                        + at(2 * x, 2 * y + 1)
                        + at(2 * x + 1, 2 * y + 1);
                    next.push(((sum + 2) / 4) as u8);
                }
            }
            levels.push((nw, nh, next));
        }
        Ok(Self { levels })
    }

    /// From RGB pixels (three bytes each, row-major): their white part, the least of the
    /// three channels. City lights are white or yellow-white, while NASA's Black Marble
    /// shows the moonlit land and sea around them in blue and teal with little red (the
    /// Sahara is (10, 52, 77), Paris (88, 87, 88)): this keeps the lights and drops the land.
    pub fn from_rgb(width: u32, height: u32, rgb: &[u8]) -> Result<Self, NightLightsError> {
        let expected = width as usize * height as usize * 3;
        if rgb.len() != expected {
            return Err(NightLightsError::WrongLength {
                width,
                height,
                expected,
                got: rgb.len(),
            });
        }
        let luminance = rgb
            .chunks_exact(3)
            .map(|p| p[0].min(p[1]).min(p[2]))
            .collect();
        Self::from_luminance(width, height, luminance)
    }

    /// Width of the full-resolution image, pixels.
    pub fn width(&self) -> u32 {
        self.levels[0].0
    }

    /// Height of the full-resolution image, pixels.
    pub fn height(&self) -> u32 {
        self.levels[0].1
    }

    /// GPU bytes of the texture with its mips.
    pub fn gpu_bytes(&self) -> u64 {
        self.levels.iter().map(|(_, _, d)| d.len() as u64).sum()
    }

    /// The full-resolution luminance (0..1) of the pixel holding longitude `lon` and geodetic
    /// latitude `lat` (radians).
    pub fn luminance_at(&self, lon: f64, lat: f64) -> f32 {
        let (w, h, data) = &self.levels[0];
        let u = (lon / std::f64::consts::TAU + 0.5).rem_euclid(1.0);
        let v = (0.5 - lat / std::f64::consts::PI).clamp(0.0, 1.0);
        let x = ((u * f64::from(*w)) as u32).min(w - 1);
        let y = ((v * f64::from(*h)) as u32).min(h - 1);
        f32::from(data[(y * w + x) as usize]) / 255.0
    }

    /// The mip levels, full resolution first: width, height, pixels.
    pub(crate) fn levels(&self) -> &[(u32, u32, Vec<u8>)] {
        &self.levels
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_checked_and_mips_average() {
        assert!(matches!(
            NightLights::from_luminance(3, 2, vec![0; 6]),
            Err(NightLightsError::BadSize { .. })
        ));
        assert!(matches!(
            NightLights::from_luminance(4, 2, vec![0; 7]),
            Err(NightLightsError::WrongLength { .. })
        ));
        assert!(NightLights::from_rgb(4, 2, &[0; 23]).is_err());
        let lights = NightLights::from_luminance(4, 2, vec![0, 0, 200, 100, 0, 0, 100, 0])
            .expect("a 4 x 2 image");
        let sizes: Vec<_> = lights.levels().iter().map(|(w, h, _)| (*w, *h)).collect();
        assert_eq!(sizes, [(4, 2), (2, 1), (1, 1)]);
        assert_eq!(lights.levels()[1].2, [0, 100]);
        assert_eq!(lights.levels()[2].2, [50]);
        assert_eq!(lights.gpu_bytes(), 8 + 2 + 1);
        // Column 2 of 4 starts at the prime meridian; row 0 is the northern half.
        assert_eq!(lights.luminance_at(0.1, 0.5), 200.0 / 255.0);
        assert_eq!(lights.luminance_at(-0.1, 0.5), 0.0);
        assert_eq!(lights.luminance_at(0.1, -0.5), 100.0 / 255.0);
    }
}
