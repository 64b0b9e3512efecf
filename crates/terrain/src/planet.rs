//! The procedural planet: a height and surface model defined in 3D on the ellipsoid.
//!
//! Every quantity is a function of the ECEF point on the ellipsoid surface (f64 metres), never
//! of longitude and latitude, so there are no seams at tile borders or the antimeridian and no
//! pinching at the poles. The model is a sum of *fields* and *octaves*:
//!
//! * fields, smooth at the scale of continents (wavelengths of 300 km and more): a
//!   domain-warped continent shape that decides land and sea, a mountain-belt mask, a
//!   hilliness and a moisture field;
//! * relief octaves: ridged noise for mountain ranges (300 km down to 4.7 km, weighted by the
//!   mountain mask); below them gully octaves (3 km down to 23 m, also in the mountains) that
//!   carve V-shaped gullies running down the slope of everything coarser, each finer one
//!   down the flanks of the coarser ones, so valleys branch as drainage does (see
//!   [`ProceduralPlanet::relief_term`]); and a power-law ("fractal", Hurst exponent 0.7)
//!   detail series from 150 km down to 0.15 m, weighted by a roughness derived from the
//!   fields, so plains stay gentle and mountains get crags;
//! * texture octaves below that (7 cm to 1.75 cm), which vary only the colour.
//!
//! Because the relief is a sum of octaves with known amplitudes, a tile generator can evaluate
//! each octave at the resolution it needs, and bound exactly how much the octaves it leaves
//! out could add (see [`ProceduralPlanet::omitted_amplitude_m`]). A gully octave's shape also
//! depends on the coarser octaves' gradient at the same point ([`Drainage`], from analytic
//! noise derivatives): a function of the point alone, carried from coarse to fine samples
//! like the heights.
//!
//! Why gullies by hand: ridged noise alone gives crests but its basins are isolated pits
//! (rounded "snow dunes" from 3 km), and a hydraulic erosion pass needs whole heightmaps,
//! neither per point nor continuous across tiles and levels. Stripes that follow the slope
//! (Johansen's erosion filter, after his "phacelle" noise) give connected, branching valleys
//! point by point; no crate offers them over 3D planet coordinates.

use globus_geo::{DVec3, Ellipsoid};

use crate::noise::{NOISE_BOUND, Octaves};

/// Wavelength of the largest detail octave, metres.
const DETAIL_BASE_M: f64 = 150_000.0;
/// Amplitude of the largest detail octave at roughness 1, metres.
const DETAIL_AMPLITUDE_M: f64 = 250.0;
/// Hurst exponent of the detail series: amplitude scales as wavelength^H.
const DETAIL_HURST: f64 = 0.7;
/// Number of detail octaves: 150 km / 2^20 = 0.14 m is the finest.
const DETAIL_OCTAVES: usize = 21;
/// Wavelength of the largest colour-only texture octave, metres (half the finest detail).
const TEXTURE_BASE_M: f64 = 0.07;
/// Number of texture octaves (down to 1.75 cm).
const TEXTURE_OCTAVES: usize = 3;
/// Wavelength of the largest ridge octave, metres.
const RIDGE_BASE_M: f64 = 300_000.0;
/// Amplitude of the largest ridge octave, metres.
const RIDGE_AMPLITUDE_M: f64 = 5_200.0;
/// Amplitude ratio between successive ridge octaves.
const RIDGE_GAIN: f64 = 0.67;
/// Number of ridge octaves (down to 4.7 km; the gullies carve below that).
const RIDGE_OCTAVES: usize = 7;
/// Wavelength (stripe spacing) of the largest gully octave, metres.
const GULLY_BASE_M: f64 = 3_000.0;
/// Number of gully octaves (down to 23 m).
const GULLY_OCTAVES: usize = 8;
/// Amplitude of a gully octave as a fraction of its wavelength: its flanks rise at 4 x this
/// (19 degrees) across the slope they run down. The gullies set the slopes: 0.085 puts
/// 26-38 % of the highest ranges' area above 30 degrees at 30 m spacing (real alpine
/// terrain: 20-30 %; see the README); 0.06 gave 13 %.
const GULLY_DEPTH: f64 = 0.085;
/// Slope (m/m) at which gullies reach full depth; gentler ground gets shallower ones.
const GULLY_FULL_SLOPE: f64 = 0.15;
/// Turn of the drainage direction within one wavelength (radians) at which a gully octave
/// has faded to half.
const GULLY_MAX_TURN: f64 = 4.0;
/// The ridge shape `(1 - |n|)^2 - RIDGE_BIAS` lies in `[-RIDGE_BIAS, 1 - RIDGE_BIAS]`.
const RIDGE_BIAS: f64 = 0.55;

/// The smooth, continent-scale fields at a point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Fields {
    /// Height of the land/sea shape before relief, metres (negative: sea floor).
    pub base_m: f64,
    /// Mountain-belt weight of the ridge octaves, 0..1.
    pub mountains: f64,
    /// Weight of the detail octaves, about 0.1..1.3.
    pub roughness: f64,
    /// Wet (1) to dry (-1).
    pub moisture: f64,
}

/// What the gully octaves follow at a point: the ridge and gully octaves coarser than the
/// one being evaluated, summed as they are weighted (see [`ProceduralPlanet::relief_term`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drainage {
    /// Their gradient, m/m (ECEF; only its part along the surface matters).
    pub gradient: DVec3,
    /// An estimate of how fast that gradient changes (the size of its derivative), 1/m.
    pub bend: f64,
}

/// One octave of relief, and how it is weighted by the fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Relief {
    /// Ridge octave `k`, weighted by [`Fields::mountains`].
    Ridge(usize),
    /// Gully octave `k`, weighted by [`Fields::mountains`]: stripes running down the slope
    /// of the coarser ridges and gullies (see [`ProceduralPlanet::relief_term`]).
    Gully(usize),
    /// Detail octave `k`, weighted by [`Fields::roughness`].
    Detail(usize),
    /// Texture octave `k`: below the finest relief, it varies only the ground colour (grain,
    /// pebbles, grass) and has no height.
    Texture(usize),
}

/// A seeded, deterministic Earth-sized planet.
#[derive(Clone, Debug)]
pub struct ProceduralPlanet {
    ellipsoid: Ellipsoid,
    seed: u64,
    warp: [Octaves; 3],
    continents: Octaves,
    belts: Octaves,
    belt_strength: Octaves,
    hilliness: Octaves,
    moisture: Octaves,
    ridges: Octaves,
    gullies: Octaves,
    detail: Octaves,
    colour: Octaves,
    texture: Octaves,
}

impl ProceduralPlanet {
    /// The planet for `seed` on the WGS84 ellipsoid.
    pub fn new(seed: u64) -> Self {
        Self::with_ellipsoid(seed, Ellipsoid::WGS84)
    }

    /// The planet for `seed` on any body (continent sizes are in metres, so small bodies get
    /// fewer, relatively larger continents).
    pub fn with_ellipsoid(seed: u64, ellipsoid: Ellipsoid) -> Self {
        let s = |k: u64| {
            seed.wrapping_mul(0x2545_f491_4f6c_dd1d)
                .wrapping_add(k * 0x9e37)
        };
        Self {
            ellipsoid,
            seed,
            warp: [
                Octaves::new(s(1), 4_000_000.0, 3),
                Octaves::new(s(2), 4_000_000.0, 3),
                Octaves::new(s(3), 4_000_000.0, 3),
            ],
            continents: Octaves::new(s(4), 9_000_000.0, 6),
            belts: Octaves::new(s(5), 3_500_000.0, 2),
            belt_strength: Octaves::new(s(6), 5_000_000.0, 1),
            hilliness: Octaves::new(s(7), 1_500_000.0, 2),
            moisture: Octaves::new(s(8), 4_000_000.0, 2),
            ridges: Octaves::new(s(9), RIDGE_BASE_M, RIDGE_OCTAVES),
            gullies: Octaves::new(s(13), GULLY_BASE_M, GULLY_OCTAVES),
            detail: Octaves::new(s(10), DETAIL_BASE_M, DETAIL_OCTAVES),
            colour: Octaves::new(s(11), 8_000.0, 2),
            texture: Octaves::new(s(12), TEXTURE_BASE_M, TEXTURE_OCTAVES),
        }
    }

    /// The body the planet is built on.
    pub fn ellipsoid(&self) -> &Ellipsoid {
        &self.ellipsoid
    }

    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Lowest height of the rendered surface (the sea surface), metres.
    pub fn min_surface_height_m(&self) -> f64 {
        0.0
    }

    /// An upper bound of the surface height anywhere, metres.
    pub fn max_surface_height_m(&self) -> f64 {
        let ridges: f64 = (0..RIDGE_OCTAVES)
            .map(|k| self.amplitude_m(Relief::Ridge(k)))
            .sum();
        let gullies: f64 = (0..GULLY_OCTAVES)
            .map(|k| self.amplitude_m(Relief::Gully(k)))
            .sum();
        let detail: f64 = (0..DETAIL_OCTAVES)
            .map(|k| self.amplitude_m(Relief::Detail(k)))
            .sum();
        BASE_LAND_M + ridges * (1.0 - RIDGE_BIAS) + gullies + detail * MAX_ROUGHNESS * NOISE_BOUND
    }

    /// The continent-scale fields at a surface point.
    pub fn fields(&self, p: DVec3) -> Fields {
        let fbm = |o: &Octaves, gain: f64, q: DVec3| {
            let mut w = 1.0;
            let mut sum = 0.0;
            for k in 0..o.len() {
                sum += w * o.octave(k, q);
                w *= gain;
            }
            sum
        };
        let warp = DVec3::new(
            fbm(&self.warp[0], 0.5, p),
            fbm(&self.warp[1], 0.5, p),
            fbm(&self.warp[2], 0.5, p),
        ) * 700_000.0;
        let land = fbm(&self.continents, 0.55, p + warp) - 0.18;
        let base_m = if land >= 0.0 {
            BASE_LAND_M * (land / 0.3).tanh().powf(1.3)
        } else {
            -4_500.0 * (-land / 0.12).tanh()
        };
        let inland = smoothstep(0.0, 0.12, land);
        let belt = 1.0 - smoothstep(0.0, 0.3, fbm(&self.belts, 0.5, p + warp * 0.5).abs());
        let strength = smoothstep(-0.45, 0.25, self.belt_strength.octave(0, p));
        let mountains = belt * strength * inland;
        let hills = smoothstep(-0.3, 0.5, fbm(&self.hilliness, 0.5, p));
        let roughness = (0.12 + 0.45 * hills + 0.75 * mountains).min(MAX_ROUGHNESS);
        let moisture = fbm(&self.moisture, 0.5, p).clamp(-1.0, 1.0);
        Fields {
            base_m,
            mountains,
            roughness,
            moisture,
        }
    }

    /// All relief octaves; ridge and gully octaves coarsest first, as
    /// [`ProceduralPlanet::relief_term`] needs them.
    pub fn relief_octaves(&self) -> impl Iterator<Item = Relief> + use<> {
        (0..RIDGE_OCTAVES)
            .map(Relief::Ridge)
            .chain((0..GULLY_OCTAVES).map(Relief::Gully))
            .chain((0..DETAIL_OCTAVES).map(Relief::Detail))
            .chain((0..TEXTURE_OCTAVES).map(Relief::Texture))
    }

    /// Wavelength of a relief octave, metres.
    pub fn wavelength_m(&self, r: Relief) -> f64 {
        match r {
            Relief::Ridge(k) => self.ridges.wavelength(k),
            Relief::Gully(k) => self.gullies.wavelength(k),
            Relief::Detail(k) => self.detail.wavelength(k),
            Relief::Texture(k) => self.texture.wavelength(k),
        }
    }

    /// Amplitude of a relief octave at weight 1, metres.
    pub fn amplitude_m(&self, r: Relief) -> f64 {
        match r {
            Relief::Ridge(k) => RIDGE_AMPLITUDE_M * RIDGE_GAIN.powi(k as i32),
            Relief::Gully(k) => GULLY_DEPTH * self.gullies.wavelength(k),
            Relief::Detail(k) => {
                DETAIL_AMPLITUDE_M * (self.detail.wavelength(k) / DETAIL_BASE_M).powf(DETAIL_HURST)
            }
            Relief::Texture(_) => 0.0,
        }
    }

    /// The unweighted shape of relief octave `r` at `p`, in [-1, 1] (multiply by its
    /// amplitude `amplitude_m` and its field weight `weight`, see
    /// [`ProceduralPlanet::relief_weight`]).
    ///
    /// `drainage` describes the ridge and gully octaves coarser than `r` at `p` (see
    /// [`Drainage`]); ridge and gully octaves add themselves to it, so call this for the
    /// octaves in [`ProceduralPlanet::relief_octaves`] order, starting from
    /// `Drainage::default()`. A gully octave follows it: its stripes run down the drainage
    /// slope, cross-sections are a sharp crest and a V-shaped gully (a triangle wave), and it
    /// fades in as the slope steepens. Each finer gully octave runs down the flanks of the
    /// coarser gullies, so the gullies branch as drainage does (in the manner of Johansen's
    /// erosion filter). Everything is a function of `p` alone, which keeps every octave
    /// deterministic and continuous.
    #[inline]
    pub fn relief_term(
        &self,
        r: Relief,
        p: DVec3,
        amplitude_m: f64,
        weight: f64,
        drainage: &mut Drainage,
    ) -> f64 {
        match r {
            Relief::Ridge(k) if weight <= 0.0 => {
                // Outside the mountains nothing follows the ridges: no gradient needed.
                let crest = 1.0 - self.ridges.octave(k, p).abs();
                crest * crest - RIDGE_BIAS
            }
            Relief::Ridge(k) => {
                let (n, g) = self.ridges.octave_d(k, p);
                let crest = 1.0 - n.abs();
                // The crest's kink is rounded in the drainage slope (n / (|n| + e) for the
                // sign), or finer gullies would turn abruptly across it; it still turns fast
                // there, which the bend records.
                let e = 0.05;
                let side = n / (n.abs() + e);
                let a = amplitude_m * weight;
                drainage.gradient += g * (-2.0 * crest * side * a);
                let turn = (crest * e / (n.abs() + e).powi(2) - side.abs()).abs();
                drainage.bend += 2.0 * a * g.length_squared() * turn;
                crest * crest - RIDGE_BIAS
            }
            Relief::Gully(k) => gully(&self.gullies, k, p, amplitude_m * weight, drainage),
            Relief::Detail(k) => self.detail.octave(k, p),
            Relief::Texture(k) => self.texture.octave(k, p),
        }
    }

    /// The field weight of a relief octave.
    #[inline]
    pub fn relief_weight(r: Relief, f: &Fields) -> f64 {
        match r {
            Relief::Ridge(_) | Relief::Gully(_) => f.mountains,
            Relief::Detail(_) => f.roughness,
            Relief::Texture(_) => 0.0,
        }
    }

    /// Largest possible magnitude of everything finer than `finest_wavelength_m` where the
    /// field weights are at most those of `max` (its mountain and roughness weights), metres:
    /// the error bound of leaving those octaves out.
    pub fn omitted_amplitude_m(&self, finest_wavelength_m: f64, max: &Fields) -> f64 {
        self.relief_octaves()
            .filter(|r| self.wavelength_m(*r) < finest_wavelength_m)
            .map(|r| {
                let shape_bound = match r {
                    Relief::Ridge(_) => RIDGE_BIAS.max(1.0 - RIDGE_BIAS),
                    Relief::Gully(_) => 1.0,
                    Relief::Detail(_) | Relief::Texture(_) => NOISE_BOUND,
                };
                self.amplitude_m(r) * shape_bound * Self::relief_weight(r, max)
            })
            .sum()
    }

    /// The raw height (negative under the sea) at a surface point with every octave down to
    /// `finest_wavelength_m`, evaluated directly. Tile generation computes the same sum
    /// faster; this is the reference it is tested against.
    pub fn height_m(&self, p: DVec3, finest_wavelength_m: f64) -> f64 {
        let f = self.fields(p);
        let mut h = f.base_m;
        let mut drainage = Drainage::default();
        for r in self.relief_octaves() {
            if self.wavelength_m(r) >= finest_wavelength_m && !matches!(r, Relief::Texture(_)) {
                let (a, w) = (self.amplitude_m(r), Self::relief_weight(r, &f));
                h += a * w * self.relief_term(r, p, a, w, &mut drainage);
            }
        }
        h
    }

    /// Vegetation patches (forest versus open land) at `p`, in about [-1, 1]: a field with
    /// an 8 km wavelength.
    #[inline]
    pub fn patches(&self, p: DVec3) -> f64 {
        self.colour.octave(0, p) + 0.5 * self.colour.octave(1, p)
    }

    /// The geodetic up vector at a surface point.
    pub fn up(&self, p: DVec3) -> DVec3 {
        self.ellipsoid.geodetic_normal(p).unwrap_or(DVec3::Z)
    }
}

/// Gully octave `k` of `octaves` at `p` (its shape, in [-1, 1]) following `drainage`, with
/// `amplitude_m` (its amplitude times its weight) to add its own slope to the drainage: see
/// [`ProceduralPlanet::relief_term`].
#[inline]
pub(crate) fn gully(
    octaves: &Octaves,
    k: usize,
    p: DVec3,
    amplitude_m: f64,
    drainage: &mut Drainage,
) -> f64 {
    let across = p.normalize_or_zero().cross(drainage.gradient);
    let slope = across.length();
    if slope < 1e-9 || amplitude_m <= 0.0 {
        return 0.0;
    }
    let wavelength = octaves.wavelength(k);
    let dir = across / slope;
    let (re, im) = octaves.stripes(k, p, dir);
    // (hypot's care for overflow cost a tenth of a mountain tile; |re|, |im| <= 1 here.)
    let length = (re * re + im * im).sqrt();
    if length < 1e-12 {
        return 0.0;
    }
    // Where the corners' waves cancel the phasor is short and its angle unsteady: fade there
    // (continuously). Where the drainage direction turns within a wavelength (across a
    // coarser crest or floor, or near a flat summit, saddle or floor) the stripes would shear
    // and tear: fade there too, by the turn per wavelength (bend / slope x wavelength,
    // radians).
    let coherence = (length / 0.5).min(1.0);
    let turn = drainage.bend * wavelength / slope / GULLY_MAX_TURN;
    let fade = coherence * smoothstep(0.0, GULLY_FULL_SLOPE, slope) / (1.0 + turn * turn);
    let angle = im.atan2(re);
    let triangle = 1.0 - 2.0 * angle.abs() / std::f64::consts::PI;
    // The drainage takes the slope of the matching sine wave rather than the triangle's (equal
    // at mid-flank): the triangle's slope flips at crests and floors. Its bend is that sine's
    // second derivative.
    let a = amplitude_m * fade;
    let k2 = 4.0 / wavelength;
    drainage.gradient += dir * (-k2 * (im / length) * a);
    drainage.bend += k2 * (re / length).abs() * a * std::f64::consts::TAU / wavelength;
    triangle * fade
}

/// Height of the continental interior plateaus, metres.
const BASE_LAND_M: f64 = 1_000.0;
/// Roughness never exceeds this.
const MAX_ROUGHNESS: f64 = 1.3;

/// Hermite smoothstep of `x` between `e0` and `e1`.
pub(crate) fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use globus_geo::Cartographic;

    /// The engine's default seed (`globus_engine::DEFAULT_SEED`), whose highest range stands
    /// at 7.6 E 46 N.
    const SEED: u64 = 24;

    fn surface(p: &ProceduralPlanet, lon: f64, lat: f64) -> DVec3 {
        p.ellipsoid()
            .cartographic_to_ecef(Cartographic::from_degrees(lon, lat, 0.0))
    }

    #[test]
    fn deterministic_for_a_seed_and_different_between_seeds() {
        let a = ProceduralPlanet::new(1);
        let b = ProceduralPlanet::new(1);
        let c = ProceduralPlanet::new(2);
        let p = surface(&a, 7.6, 46.0);
        assert_eq!(a.height_m(p, 0.1), b.height_m(p, 0.1));
        assert_ne!(a.height_m(p, 0.1), c.height_m(p, 0.1));
    }

    /// Land fraction, highest point and share of land above 2500 m for a seed.
    fn survey(seed: u64) -> (f64, f64, f64) {
        let planet = ProceduralPlanet::new(seed);
        let (mut land, mut high, mut max) = (0u32, 0u32, f64::MIN);
        let n = 3000;
        for i in 0..n {
            let t = f64::from(i);
            let lon = (t * 0.618_034).fract() * 360.0 - 180.0;
            let lat = ((t * 0.754_878).fract() * 2.0 - 1.0).asin().to_degrees();
            let h = planet.height_m(surface(&planet, lon, lat), 1000.0);
            max = max.max(h);
            land += u32::from(h > 0.0);
            high += u32::from(h > 2500.0);
        }
        (
            f64::from(land) / f64::from(n),
            max,
            f64::from(high) / f64::from(land.max(1)),
        )
    }

    #[test]
    fn has_oceans_and_land_and_mountains() {
        let surveys: Vec<(f64, f64, f64)> = (1..=8).map(survey).collect();
        let mean_land = surveys.iter().map(|s| s.0).sum::<f64>() / surveys.len() as f64;
        // Earth: 29 % land, highest point 8.8 km, about 5 % of land above 2.5 km.
        assert!(
            (0.2..0.5).contains(&mean_land),
            "mean land fraction {mean_land}: {surveys:?}"
        );
        for (land, max, high) in &surveys {
            assert!(*land > 0.02 && *land < 0.9, "{surveys:?}");
            assert!(*max > 2500.0 && *max < 9000.0, "{surveys:?}");
            assert!(*high < 0.3, "{surveys:?}");
        }
        assert!(
            surveys.iter().filter(|s| s.2 > 0.005).count() >= 6,
            "mountains on most planets: {surveys:?}"
        );
        let max_bound = ProceduralPlanet::new(1).max_surface_height_m();
        assert!(surveys.iter().all(|s| s.1 < max_bound));
    }

    #[test]
    fn same_point_across_the_antimeridian_and_at_the_pole() {
        let planet = ProceduralPlanet::new(3);
        let e = planet.ellipsoid();
        let a = e.cartographic_to_ecef(Cartographic::from_degrees(180.0, 10.0, 0.0));
        let b = e.cartographic_to_ecef(Cartographic::from_degrees(-180.0, 10.0, 0.0));
        assert!((planet.height_m(a, 0.5) - planet.height_m(b, 0.5)).abs() < 1e-6);
        let hs: Vec<f64> = [0.0, 90.0, -170.0]
            .iter()
            .map(|lon| planet.height_m(surface(&planet, *lon, 90.0), 0.5))
            .collect();
        assert!((hs[0] - hs[1]).abs() < 1e-6 && (hs[0] - hs[2]).abs() < 1e-6);
    }

    #[test]
    fn detail_exists_below_a_metre() {
        let planet = ProceduralPlanet::new(5);
        let p = surface(&planet, 7.6, 46.0);
        let n = planet.up(p);
        let mut diffs = 0;
        for i in 1..20 {
            let q = p + planet.ellipsoid().enu_frame(0.13, 0.8).east * (f64::from(i) * 0.05);
            let coarse = planet.height_m(q, 2.0) - planet.height_m(p, 2.0);
            let fine = planet.height_m(q, 0.1) - planet.height_m(p, 0.1);
            if (fine - coarse).abs() > 1e-3 {
                diffs += 1;
            }
        }
        assert!(n.length() > 0.99);
        assert!(diffs > 10, "sub-metre octaves change the surface");
    }

    /// Issue 20's figure: in the highest range, at 30 m spacing, at least 15 % of the area is
    /// steeper than 30 degrees (real alpine terrain: 20-30 %), and not a wall of cliffs.
    #[test]
    fn the_highest_range_is_as_steep_as_the_alps() {
        let planet = ProceduralPlanet::new(SEED);
        let (h, side) = planet.height_window((7.6, 46.0), 6_000.0, 30.0);
        let steep = crate::slopes::steep_share(&h, side, 30.0, 30.0);
        let cliffs = crate::slopes::steep_share(&h, side, 30.0, 55.0);
        assert!((0.15..0.5).contains(&steep), "{steep}");
        assert!(cliffs < 0.01, "{cliffs}");
        let highest = h.iter().copied().fold(0.0, f64::max);
        assert!(highest > 2_500.0, "{highest}");
    }

    /// Gullies run down the slope they follow: across it each octave rises and falls a full
    /// turn per wavelength, along it hardly at all.
    #[test]
    fn gullies_run_down_the_slope() {
        let planet = ProceduralPlanet::new(SEED);
        let r = Relief::Gully(4);
        let step = planet.wavelength_m(r) / 8.0;
        let (mut along, mut across) = (0.0, 0.0);
        let n = 400;
        for i in 0..n {
            let t = f64::from(i);
            let p = surface(
                &planet,
                7.0 + (t * 0.618_034).fract(),
                45.5 + (t * 0.754_878).fract(),
            );
            let up = planet.up(p);
            // A steep drainage slope (0.5 m/m) falling towards the west.
            let east = DVec3::Z.cross(up).normalize();
            let slope = east * 0.5;
            let shape = |q: DVec3| {
                let mut d = Drainage {
                    gradient: slope,
                    bend: 0.0,
                };
                planet.relief_term(r, q, 1.0, 1.0, &mut d)
            };
            let north = up.cross(east);
            let s0 = shape(p);
            along += (shape(p + east * step) - s0).abs();
            across += (shape(p + north * step) - s0).abs();
        }
        let (along, across) = (along / f64::from(n), across / f64::from(n));
        // A triangle wave moves 2 x 2 / 8 = 0.5 per eighth of a wavelength across.
        assert!(across > 0.3, "{across}");
        assert!(along < 0.3 * across, "along {along}, across {across}");
    }

    #[test]
    fn omitted_amplitude_shrinks_with_wavelength() {
        let planet = ProceduralPlanet::new(1);
        let max = Fields {
            mountains: 1.0,
            roughness: 1.0,
            ..Fields::default()
        };
        let a = planet.omitted_amplitude_m(10.0, &max);
        let b = planet.omitted_amplitude_m(1.0, &max);
        assert!(a > b && b > 0.0);
        assert_eq!(planet.omitted_amplitude_m(0.01, &max), 0.0);
        // Gullies are left out of mountains only.
        let plains = Fields {
            roughness: 1.0,
            ..Fields::default()
        };
        assert!(
            planet.omitted_amplitude_m(100.0, &plains) < planet.omitted_amplitude_m(100.0, &max)
        );
    }
}
