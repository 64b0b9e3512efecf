//! Surface colour of the procedural planet from height, slope, latitude and moisture:
//! water, beaches, grass, forest, desert, tundra, rock and snow.
//!
//! Colours are authored in sRGB, blended in linear light and written back as sRGB bytes.

use std::sync::LazyLock;

use crate::planet::smoothstep;

/// What the colour of a texel depends on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Surface {
    /// Raw height, metres (negative: under water, the depth).
    pub height_m: f64,
    /// Cosine of the slope angle (1 flat, 0 vertical).
    pub slope_cos: f64,
    /// Absolute latitude, radians.
    pub abs_lat_rad: f64,
    /// Moisture field, wet (1) to dry (-1).
    pub moisture: f64,
    /// Vegetation patch field, about [-1, 1].
    pub patches: f64,
    /// Small-scale relief relative to its typical amplitude, about [-1, 1]: bumps lighter,
    /// hollows darker, so the ground keeps texture at every scale.
    pub micro: f64,
}

type Rgb = [f64; 3];

fn srgb(r: u8, g: u8, b: u8) -> Rgb {
    let lin = |c: u8| {
        let c = f64::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    [lin(r), lin(g), lin(b)]
}

/// Linear [0, 1] to an sRGB byte through a 4096-entry table (the exact curve costs a `powf`
/// per channel, which dominated tile generation).
fn to_srgb8(c: f64) -> u8 {
    static TABLE: LazyLock<Vec<u8>> = LazyLock::new(|| {
        (0..4096)
            .map(|i| {
                let c = (f64::from(i) + 0.5) / 4096.0;
                let s = if c <= 0.003_130_8 {
                    c * 12.92
                } else {
                    1.055 * c.powf(1.0 / 2.4) - 0.055
                };
                (s * 255.0 + 0.5) as u8
            })
            .collect()
    });
    TABLE[((c.clamp(0.0, 1.0) * 4095.0) as usize).min(4095)]
}

fn mix(a: Rgb, b: Rgb, t: f64) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// The palette, in linear light.
struct Palette {
    deep: Rgb,
    shallow: Rgb,
    coast: Rgb,
    sand: Rgb,
    desert: Rgb,
    dry: Rgb,
    grass: Rgb,
    forest: Rgb,
    tundra: Rgb,
    rock: Rgb,
    dark_rock: Rgb,
    snow: Rgb,
}

fn palette() -> &'static Palette {
    static PALETTE: LazyLock<Palette> = LazyLock::new(make_palette);
    &PALETTE
}

fn make_palette() -> Palette {
    Palette {
        deep: srgb(6, 22, 62),
        shallow: srgb(18, 70, 118),
        coast: srgb(38, 118, 140),
        sand: srgb(212, 196, 150),
        desert: srgb(196, 164, 112),
        dry: srgb(150, 142, 88),
        grass: srgb(92, 128, 54),
        forest: srgb(34, 72, 32),
        tundra: srgb(122, 116, 92),
        rock: srgb(124, 114, 104),
        dark_rock: srgb(82, 76, 72),
        snow: srgb(238, 242, 248),
    }
}

/// The sRGB colour and water flag (alpha 0 on water, 255 on land) of a surface point.
pub fn colour(s: &Surface) -> [u8; 4] {
    let p = palette();
    let lat_deg = s.abs_lat_rad.to_degrees();
    if s.height_m < 0.0 {
        let depth = -s.height_m;
        let c = mix(p.coast, p.shallow, smoothstep(0.0, 60.0, depth));
        let c = mix(c, p.deep, smoothstep(60.0, 2500.0, depth));
        let c = mix(c, p.snow, smoothstep(76.0, 82.0, lat_deg)); // polar sea ice
        return [to_srgb8(c[0]), to_srgb8(c[1]), to_srgb8(c[2]), 0];
    }
    let h = s.height_m;
    // Temperature falls with latitude and height; dryness peaks in the subtropics.
    let temperature = 1.0 - lat_deg / 75.0 - h / 6_000.0;
    let subtropics = smoothstep(8.0, 20.0, lat_deg) * (1.0 - smoothstep(32.0, 42.0, lat_deg));
    let wet = (s.moisture * 1.4 + 0.35 - subtropics * 0.6 + s.patches * 0.25).clamp(-1.0, 1.0);
    let lowland = if wet < 0.0 {
        mix(p.dry, p.desert, smoothstep(0.0, 0.6, -wet))
    } else {
        let forest = smoothstep(0.15, 0.45, wet + s.patches * 0.35);
        mix(
            mix(p.dry, p.grass, smoothstep(0.0, 0.3, wet)),
            p.forest,
            forest,
        )
    };
    let cold = 1.0 - smoothstep(0.05, 0.3, temperature);
    let mut c = mix(lowland, p.tundra, cold);
    // Beaches just above the water line.
    c = mix(c, p.sand, 1.0 - smoothstep(2.0, 7.0 + s.micro * 3.0, h));
    // Bare rock on steep slopes and above the tree line.
    let slope_deg = s.slope_cos.clamp(-1.0, 1.0).acos().to_degrees();
    let snowline = 6_000.0 * (1.0 - (lat_deg / 72.0).min(1.0).powf(1.6)) + s.patches * 250.0;
    let rock =
        smoothstep(28.0, 40.0, slope_deg).max(smoothstep(snowline - 900.0, snowline - 400.0, h));
    let rock_colour = mix(p.rock, p.dark_rock, 0.5 + 0.5 * s.micro);
    c = mix(c, rock_colour, rock);
    // Snow above the snow line and on the polar caps, sliding off steep faces.
    let snow = smoothstep(snowline - 150.0, snowline + 150.0, h)
        .max(smoothstep(74.0, 80.0, lat_deg))
        * (1.0 - smoothstep(32.0, 46.0, slope_deg));
    c = mix(c, p.snow, snow);
    // Texture at every scale: micro relief lightens bumps and darkens hollows.
    let shade = 1.0 + 0.35 * s.micro;
    [
        to_srgb8(c[0] * shade),
        to_srgb8(c[1] * shade),
        to_srgb8(c[2] * shade),
        255,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(height_m: f64, slope_deg: f64, lat_deg: f64) -> [u8; 4] {
        colour(&Surface {
            height_m,
            slope_cos: slope_deg.to_radians().cos(),
            abs_lat_rad: lat_deg.to_radians(),
            moisture: 0.3,
            patches: 0.0,
            micro: 0.0,
        })
    }

    #[test]
    fn water_is_blue_and_flagged() {
        let c = at(-3000.0, 0.0, 10.0);
        assert!(c[2] > c[0] && c[2] > c[1] && c[3] == 0);
    }

    #[test]
    fn high_peaks_are_snowy_and_cliffs_rocky() {
        let snow = at(6000.0, 10.0, 30.0);
        assert!(snow.iter().take(3).all(|&v| v > 200));
        let cliff = at(1500.0, 60.0, 30.0);
        let (r, g, b) = (cliff[0] as i32, cliff[1] as i32, cliff[2] as i32);
        assert!(
            (r - g).abs() < 30 && (g - b).abs() < 30,
            "grey rock {cliff:?}"
        );
    }

    #[test]
    fn lowlands_are_green_and_beaches_sandy() {
        let grass = at(200.0, 5.0, 48.0);
        assert!(grass[1] > grass[0] && grass[1] > grass[2], "{grass:?}");
        let beach = at(1.0, 2.0, 20.0);
        assert!(beach[0] > 180, "{beach:?}");
    }
}
