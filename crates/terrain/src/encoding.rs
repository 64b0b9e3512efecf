//! Elevation as 24-bit RGB, the way tile clients read it from lossless PNG.
//!
//! | encoding | decode (metres) | step | range |
//! |---|---|---|---|
//! | Terrarium | `R * 256 + G + B / 256 - 32768` | 1/256 m | -32768 .. 32767.996 |
//! | Mapbox Terrain-RGB | `-10000 + (R * 65536 + G * 256 + B) * 0.1` | 0.1 m | -10000 .. 1667721.5 |
//! | Centimetre (Kaiser 2018, section 3.3) | `c = R * 65536 + G * 256 + B; c / 16 / 100 - 1000` | 0.01 m | -1000 .. 9485.75 |
//!
//! Encoding rounds to the nearest step, so a decoded height is within half a step of the
//! original; heights outside the range are clamped to it. The centimetre encoding shifts the
//! centimetre count left by four bits, as the thesis does, so its low bits show in blue.

/// How heights are stored in RGB.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElevationEncoding {
    /// Mapzen/AWS Terrarium.
    Terrarium,
    /// Mapbox Terrain-RGB v1.
    Mapbox,
    /// Kaiser's centimetre encoding.
    Centimetre,
}

impl ElevationEncoding {
    /// Parses `terrarium`, `mapbox` or `centimetre`.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "terrarium" => Some(Self::Terrarium),
            "mapbox" | "terrain-rgb" => Some(Self::Mapbox),
            "centimetre" | "centimeter" => Some(Self::Centimetre),
            _ => None,
        }
    }

    /// The name used on the command line and in archive metadata.
    pub fn name(self) -> &'static str {
        match self {
            Self::Terrarium => "terrarium",
            Self::Mapbox => "mapbox",
            Self::Centimetre => "centimetre",
        }
    }

    /// The quantisation step in metres; decoded heights are within half of it.
    pub fn step_m(self) -> f64 {
        match self {
            Self::Terrarium => 1.0 / 256.0,
            Self::Mapbox => 0.1,
            Self::Centimetre => 0.01,
        }
    }

    /// The smallest and largest heights the encoding can hold, metres.
    pub fn range_m(self) -> (f64, f64) {
        let max_code = f64::from((1u32 << 24) - 1);
        match self {
            Self::Terrarium => (-32768.0, -32768.0 + max_code / 256.0),
            Self::Mapbox => (-10000.0, -10000.0 + max_code * 0.1),
            Self::Centimetre => (-1000.0, -1000.0 + (max_code / 16.0).floor() / 100.0),
        }
    }

    /// The 24-bit code of a height (clamped to the range; `NaN` encodes as 0 m).
    #[inline]
    pub fn code(self, height_m: f64) -> u32 {
        let h = if height_m.is_nan() { 0.0 } else { height_m };
        let (lo, hi) = self.range_m();
        let h = h.clamp(lo, hi);
        let code = match self {
            Self::Terrarium => ((h + 32768.0) * 256.0).round(),
            Self::Mapbox => ((h + 10000.0) * 10.0).round(),
            Self::Centimetre => ((h + 1000.0) * 100.0).round() * 16.0,
        };
        (code as u32).min((1 << 24) - 1)
    }

    /// The RGB bytes of a height.
    #[inline]
    pub fn encode(self, height_m: f64) -> [u8; 3] {
        let c = self.code(height_m);
        [(c >> 16) as u8, (c >> 8) as u8, c as u8]
    }

    /// The height, metres, stored in RGB bytes.
    #[inline]
    pub fn decode(self, rgb: [u8; 3]) -> f64 {
        let [r, g, b] = rgb.map(f64::from);
        match self {
            Self::Terrarium => r * 256.0 + g + b / 256.0 - 32768.0,
            Self::Mapbox => -10000.0 + (r * 65536.0 + g * 256.0 + b) * 0.1,
            Self::Centimetre => {
                let c = (r * 65536.0 + g * 256.0 + b) / 16.0;
                c.floor() / 100.0 - 1000.0
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ALL: [ElevationEncoding; 3] = [
        ElevationEncoding::Terrarium,
        ElevationEncoding::Mapbox,
        ElevationEncoding::Centimetre,
    ];

    #[test]
    fn published_examples_decode() {
        // Terrarium: (128, 0, 0) is sea level; Mapbox: (1, 134, 160) is 0 m.
        assert_eq!(ElevationEncoding::Terrarium.decode([128, 0, 0]), 0.0);
        assert_eq!(ElevationEncoding::Terrarium.encode(0.0), [128, 0, 0]);
        assert!(ElevationEncoding::Mapbox.decode([1, 134, 160]).abs() < 1e-9);
        assert_eq!(ElevationEncoding::Mapbox.encode(0.0), [1, 134, 160]);
        // Mount Everest, 8848.86 m, in the centimetre encoding: (884886 + 100000) * 16.
        let c = ElevationEncoding::Centimetre.code(8848.86);
        assert_eq!(c, 984_886 * 16);
        assert!(
            (ElevationEncoding::Centimetre.decode(ElevationEncoding::Centimetre.encode(8848.86))
                - 8848.86)
                .abs()
                < 1e-9
        );
    }

    #[test]
    fn out_of_range_heights_clamp_instead_of_wrapping() {
        for e in ALL {
            let (lo, hi) = e.range_m();
            assert!((e.decode(e.encode(lo - 5000.0)) - lo).abs() <= e.step_m());
            assert!((e.decode(e.encode(hi + 1e7)) - hi).abs() <= e.step_m());
            assert!(e.decode(e.encode(f64::NAN)).abs() < e.step_m());
        }
    }

    proptest! {
        #[test]
        fn round_trip_within_half_a_step(h in -999.0f64..9485.0) {
            for e in ALL {
                let back = e.decode(e.encode(h));
                prop_assert!((back - h).abs() <= e.step_m() * 0.5 + 1e-9, "{:?} {} -> {}", e, h, back);
            }
        }

        #[test]
        fn codes_are_monotonic(a in -999.0f64..9485.0, d in 0.0f64..100.0) {
            for e in ALL {
                prop_assert!(e.code(a + d) >= e.code(a));
            }
        }
    }
}
