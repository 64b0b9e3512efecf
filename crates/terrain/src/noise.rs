//! Seeded 3D gradient noise in f64, evaluated on the planet in ECEF metres.
//!
//! Perlin's improved gradient noise (Perlin, "Improving Noise", SIGGRAPH 2002) with the
//! permutation table replaced by an integer hash of the lattice cell. A 256-entry table would
//! repeat every 256 cells, which at a 0.25 m wavelength is a 64 m pattern: visible from 1 m
//! above the ground. Hashing 64-bit lattice coordinates never repeats on a planet.
//!
//! Each octave is rotated and offset differently ([`Octaves`]) so lattice axes never line up
//! between octaves (no grid-aligned artefacts). Values lie in about [-1, 1]; [`NOISE_BOUND`]
//! is a proven upper bound of the magnitude.

use globus_geo::{DMat3, DQuat, DVec3};

/// A safe upper bound of `|noise(p)|` for this gradient set. The maximum of improved Perlin
/// noise is close to 1 (sampling never exceeds it; see the tests); 10 % margin on top.
pub const NOISE_BOUND: f64 = 1.1;

/// 16 gradient directions: the 12 cube-edge midpoints of Perlin's improved noise, with four
/// repeated so a 4-bit hash selects one uniformly without bias.
const GRADIENTS: [[f64; 3]; 16] = [
    [1.0, 1.0, 0.0],
    [-1.0, 1.0, 0.0],
    [1.0, -1.0, 0.0],
    [-1.0, -1.0, 0.0],
    [1.0, 0.0, 1.0],
    [-1.0, 0.0, 1.0],
    [1.0, 0.0, -1.0],
    [-1.0, 0.0, -1.0],
    [0.0, 1.0, 1.0],
    [0.0, -1.0, 1.0],
    [0.0, 1.0, -1.0],
    [0.0, -1.0, -1.0],
    [1.0, 1.0, 0.0],
    [0.0, -1.0, 1.0],
    [-1.0, 1.0, 0.0],
    [0.0, -1.0, -1.0],
];

const KX: u64 = 0x9e37_79b9_7f4a_7c15;
const KY: u64 = 0xc2b2_ae3d_27d4_eb4f;
const KZ: u64 = 0x1656_67b1_9e37_79f9;

/// Final mixing of a combined lattice hash (the `splitmix64`/murmur finaliser, shortened).
#[inline(always)]
fn mix(mut h: u64) -> u64 {
    h ^= h >> 32;
    h = h.wrapping_mul(0xd6e8_feb8_6659_fd93);
    h ^= h >> 32;
    h
}

/// Hash of a lattice point and seed.
#[inline]
fn hash(ix: i64, iy: i64, iz: i64, seed: u64) -> u64 {
    mix(seed
        ^ (ix as u64).wrapping_mul(KX)
        ^ (iy as u64).wrapping_mul(KY)
        ^ (iz as u64).wrapping_mul(KZ))
}

#[inline(always)]
fn grad(h: u64, x: f64, y: f64, z: f64) -> f64 {
    let g = GRADIENTS[(h & 15) as usize];
    g[0] * x + g[1] * y + g[2] * z
}

#[inline(always)]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline(always)]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + t * (b - a)
}

/// The lattice cell (as wrapping u64) and fractional part of `v`. `f64::floor` is a libm
/// call on baseline x86-64 (no SSE4.1); truncation and a correction are a few instructions.
#[inline(always)]
fn floor_split(v: f64) -> (u64, f64) {
    let t = v as i64;
    let t = if (t as f64) > v { t - 1 } else { t };
    (t as u64, v - t as f64)
}

/// The lattice cell around a point: its fractional position and the per-axis parts of the
/// corners' hashes (combined by xor for the eight corners, see [`Cell::hash`]).
struct Cell {
    frac: [f64; 3],
    hx: [u64; 2],
    hy: [u64; 2],
    hz: [u64; 2],
}

impl Cell {
    #[inline(always)]
    fn new(p: DVec3, seed: u64) -> Self {
        let (ix, x) = floor_split(p.x);
        let (iy, y) = floor_split(p.y);
        let (iz, z) = floor_split(p.z);
        Self {
            frac: [x, y, z],
            hx: [ix.wrapping_mul(KX), ix.wrapping_add(1).wrapping_mul(KX)],
            hy: [iy.wrapping_mul(KY), iy.wrapping_add(1).wrapping_mul(KY)],
            hz: [
                iz.wrapping_mul(KZ) ^ seed,
                iz.wrapping_add(1).wrapping_mul(KZ) ^ seed,
            ],
        }
    }

    /// The hash of corner (dx, dy, dz), each 0 or 1.
    #[inline(always)]
    fn hash(&self, dx: usize, dy: usize, dz: usize) -> u64 {
        mix(self.hx[dx] ^ self.hy[dy] ^ self.hz[dz])
    }
}

/// `(sin x, cos x)` to within 1e-11 for `|x|` up to about 1e6: quadrant reduction and
/// Taylor series on `[-pi/4, pi/4]`. libm's `sin_cos` took a third of a mountain tile's
/// generation ([`Octaves::stripes`] needs four per sample and octave).
#[inline(always)]
fn sin_cos(x: f64) -> (f64, f64) {
    // pi / 2 in two parts (Cody and Waite), the first with trailing zero bits.
    const PI_2_HI: f64 = 1.570_796_326_734_125_6;
    const PI_2_LO: f64 = 6.077_100_506_506_192e-11;
    let (k, _) = floor_split(x * std::f64::consts::FRAC_2_PI + 0.5);
    let kf = k as i64 as f64;
    let r = (x - kf * PI_2_HI) - kf * PI_2_LO;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0
                    + r2 * (-1.0 / 5_040.0
                        + r2 * (1.0 / 362_880.0 + r2 * (-1.0 / 39_916_800.0))))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0
                    + r2 * (1.0 / 40_320.0
                        + r2 * (-1.0 / 3_628_800.0 + r2 * (1.0 / 479_001_600.0))))));
    match k & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Gradient noise at `p` (lattice units) for `seed`.
#[inline]
pub fn gradient_noise(p: DVec3, seed: u64) -> f64 {
    let cell = Cell::new(p, seed);
    let [x, y, z] = cell.frac;
    let (u, v, w) = (fade(x), fade(y), fade(z));
    let c = |dx: usize, dy: usize, dz: usize| {
        grad(
            cell.hash(dx, dy, dz),
            x - dx as f64,
            y - dy as f64,
            z - dz as f64,
        )
    };
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), u);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), u);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), u);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Derivative of [`fade`].
#[inline(always)]
fn fade_d(t: f64) -> f64 {
    30.0 * t * t * (t * (t - 2.0) + 1.0)
}

/// Gradient noise at `p` (lattice units) for `seed`, with its gradient (per lattice unit).
/// The value is bit-identical to [`gradient_noise`].
#[inline]
pub fn gradient_noise_d(p: DVec3, seed: u64) -> (f64, DVec3) {
    let cell = Cell::new(p, seed);
    let [x, y, z] = cell.frac;
    let (u, v, w) = (fade(x), fade(y), fade(z));
    // Corner gradients and values.
    let g = |dx: usize, dy: usize, dz: usize| GRADIENTS[(cell.hash(dx, dy, dz) & 15) as usize];
    let val = |gr: [f64; 3], dx: usize, dy: usize, dz: usize| {
        gr[0] * (x - dx as f64) + gr[1] * (y - dy as f64) + gr[2] * (z - dz as f64)
    };
    let gs = [
        g(0, 0, 0),
        g(1, 0, 0),
        g(0, 1, 0),
        g(1, 1, 0),
        g(0, 0, 1),
        g(1, 0, 1),
        g(0, 1, 1),
        g(1, 1, 1),
    ];
    let c: [f64; 8] = std::array::from_fn(|k| val(gs[k], k & 1, (k >> 1) & 1, k >> 2));
    let x00 = lerp(c[0], c[1], u);
    let x10 = lerp(c[2], c[3], u);
    let x01 = lerp(c[4], c[5], u);
    let x11 = lerp(c[6], c[7], u);
    let y0 = lerp(x00, x10, v);
    let y1 = lerp(x01, x11, v);
    let value = lerp(y0, y1, w);
    // d/du, d/dv, d/dw with the corner values held, times the fades' derivatives.
    let du = lerp(
        lerp(c[1] - c[0], c[3] - c[2], v),
        lerp(c[5] - c[4], c[7] - c[6], v),
        w,
    );
    let dv = lerp(x10 - x00, x11 - x01, w);
    let dw = y1 - y0;
    // Plus the corner gradients, blended by the same weights.
    let blend = |a: usize| {
        let x00 = lerp(gs[0][a], gs[1][a], u);
        let x10 = lerp(gs[2][a], gs[3][a], u);
        let x01 = lerp(gs[4][a], gs[5][a], u);
        let x11 = lerp(gs[6][a], gs[7][a], u);
        lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
    };
    let gradient = DVec3::new(
        blend(0) + du * fade_d(x),
        blend(1) + dv * fade_d(y),
        blend(2) + dw * fade_d(z),
    );
    (value, gradient)
}

/// Unit phasors at 16 angles (k * 22.5 degrees), the random phases of [`Octaves::stripes`].
const PHASES: [(f64, f64); 16] = {
    const C1: f64 = 0.923_879_532_511_286_7;
    const C2: f64 = std::f64::consts::FRAC_1_SQRT_2;
    const C3: f64 = 0.382_683_432_365_089_8;
    [
        (1.0, 0.0),
        (C1, C3),
        (C2, C2),
        (C3, C1),
        (0.0, 1.0),
        (-C3, C1),
        (-C2, C2),
        (-C1, C3),
        (-1.0, 0.0),
        (-C1, -C3),
        (-C2, -C2),
        (-C3, -C1),
        (0.0, -1.0),
        (C3, -C1),
        (C2, -C2),
        (C1, -C3),
    ]
};

/// A family of octaves: octave `k` has wavelength `base_wavelength_m / 2^k`, its own rotation,
/// offset and seed.
#[derive(Clone, Debug)]
pub struct Octaves {
    transforms: Vec<(DMat3, DVec3, u64)>,
    base_wavelength_m: f64,
}

impl Octaves {
    /// `count` octaves starting at `base_wavelength_m`, derived from `seed`.
    pub fn new(seed: u64, base_wavelength_m: f64, count: usize) -> Self {
        let transforms = (0..count)
            .map(|k| {
                let s = hash(k as i64, 17, -3, seed);
                let unit = |bits: u64| (bits >> 11) as f64 / (1u64 << 53) as f64;
                let axis = DVec3::new(
                    unit(hash(1, k as i64, 0, s)) - 0.5,
                    unit(hash(2, k as i64, 0, s)) - 0.5,
                    unit(hash(3, k as i64, 0, s)) - 0.5,
                )
                .try_normalize()
                .unwrap_or(DVec3::Z);
                let angle = 0.5 + 2.0 * unit(hash(4, k as i64, 0, s));
                let wavelength = base_wavelength_m / (1u64 << k.min(62)) as f64;
                // Scale folded into the rotation: lattice = rot * p / wavelength + offset.
                let rot =
                    DMat3::from_quat(DQuat::from_axis_angle(axis, angle)) * (1.0 / wavelength);
                let offset = DVec3::new(
                    unit(hash(5, k as i64, 0, s)),
                    unit(hash(6, k as i64, 0, s)),
                    unit(hash(7, k as i64, 0, s)),
                ) * 1000.0;
                (rot, offset, s)
            })
            .collect();
        Self {
            transforms,
            base_wavelength_m,
        }
    }

    /// Number of octaves.
    pub fn len(&self) -> usize {
        self.transforms.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.transforms.is_empty()
    }

    /// Wavelength of octave `k`, metres.
    pub fn wavelength(&self, k: usize) -> f64 {
        self.base_wavelength_m / (1u64 << k.min(62)) as f64
    }

    /// Octave `k` at `p` (ECEF metres), in [-1, 1].
    #[inline]
    pub fn octave(&self, k: usize, p: DVec3) -> f64 {
        let (rot, offset, seed) = &self.transforms[k];
        let q = *rot * p + *offset;
        gradient_noise(q, *seed)
    }

    /// Octave `k` at `p` with its gradient (per metre, ECEF).
    #[inline]
    pub fn octave_d(&self, k: usize, p: DVec3) -> (f64, DVec3) {
        let (rot, offset, seed) = &self.transforms[k];
        let q = *rot * p + *offset;
        let (n, g) = gradient_noise_d(q, *seed);
        (n, rot.transpose() * g)
    }

    /// Stripes of octave `k`'s wavelength at `p` whose crests run across the unit vector
    /// `dir` (ECEF): a phasor of magnitude at most 1 whose angle grows by a full turn per
    /// wavelength along `dir`.
    ///
    /// Each of the eight lattice corners around `p` carries a plane wave through itself with
    /// a random phase; the waves are blended with the noise's fade weights. Where `dir`
    /// turns slowly the stripes stay parallel locally, while their phase wanders over a few
    /// wavelengths, so stripes begin, end and fork (Johansen's "phacelle" noise, here in 3D
    /// on the planet's surface). Where the corners' waves disagree the phasor is short; the
    /// caller fades by its length.
    #[inline]
    pub fn stripes(&self, k: usize, p: DVec3, dir: DVec3) -> (f64, f64) {
        let (rot, offset, seed) = &self.transforms[k];
        let wavelength = self.wavelength(k);
        let q = *rot * p + *offset;
        // The direction in the lattice frame, one wavelength per lattice unit.
        let e = *rot * dir * wavelength;
        let cell = Cell::new(q, *seed);
        let [x, y, z] = cell.frac;
        let tau = std::f64::consts::TAU;
        // The wave through corner (0,0,0) at p, and the factor per step to the next corner
        // along each axis.
        let (s0, c0) = sin_cos(tau * (x * e.x + y * e.y + z * e.z));
        let (sx, cx) = sin_cos(-tau * e.x);
        let (sy, cy) = sin_cos(-tau * e.y);
        let (sz, cz) = sin_cos(-tau * e.z);
        let mul = |a: (f64, f64), b: (f64, f64)| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
        let (u, v, w) = (fade(x), fade(y), fade(z));
        let mut sum = (0.0, 0.0);
        let mut wz = (c0, s0);
        for (dz, fz) in [(0usize, 1.0 - w), (1, w)] {
            let mut wy = wz;
            for (dy, fy) in [(0usize, 1.0 - v), (1, v)] {
                let mut wx = wy;
                for (dx, fx) in [(0usize, 1.0 - u), (1, u)] {
                    let phase = PHASES[(cell.hash(dx, dy, dz) >> 60) as usize];
                    let c = mul(wx, phase);
                    let weight = fx * fy * fz;
                    sum.0 += weight * c.0;
                    sum.1 += weight * c.1;
                    wx = mul(wx, (cx, sx));
                }
                wy = mul(wy, (cy, sy));
            }
            wz = mul(wz, (cz, sz));
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounded_deterministic_and_zero_on_lattice() {
        let mut max: f64 = 0.0;
        for i in 0..200_000 {
            let t = f64::from(i);
            let p = DVec3::new(t * 0.137, t * 0.0731 - 50.0, (t * 0.01).sin() * 77.0);
            let n = gradient_noise(p, 42);
            assert_eq!(n, gradient_noise(p, 42));
            max = max.max(n.abs());
        }
        assert!(max <= 1.0, "{max}");
        assert!(max > 0.5, "noise too flat: {max}");
        assert_eq!(gradient_noise(DVec3::new(3.0, -7.0, 1e6), 1), 0.0);
    }

    #[test]
    fn no_repetition_at_256_cells() {
        let a = gradient_noise(DVec3::new(0.3, 0.4, 0.5), 7);
        let b = gradient_noise(DVec3::new(256.3, 0.4, 0.5), 7);
        assert_ne!(a, b);
    }

    #[test]
    fn continuous_across_cells() {
        let e = 1e-9;
        for i in -5..5 {
            let x = f64::from(i);
            let a = gradient_noise(DVec3::new(x - e, 0.3, 0.7), 3);
            let b = gradient_noise(DVec3::new(x + e, 0.3, 0.7), 3);
            assert!((a - b).abs() < 1e-7);
        }
    }

    #[test]
    fn sin_cos_matches_libm() {
        let mut worst: f64 = 0.0;
        for i in -200_000..200_000 {
            let x = f64::from(i) * 1.37e-3 + f64::from(i % 7) * 0.1;
            let (s, c) = sin_cos(x);
            worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
        }
        for x in [1e3, -1e4, 123_456.789, std::f64::consts::FRAC_PI_4, 0.0] {
            let (s, c) = sin_cos(x);
            worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
        }
        assert!(worst < 1e-11, "{worst}");
    }

    #[test]
    fn the_gradient_is_the_derivative_of_the_value() {
        let o = Octaves::new(4, 900.0, 2);
        let h = 0.01;
        for i in 0..200 {
            let t = f64::from(i);
            let p = DVec3::new(6_378_137.0 + t * 37.1, (t * 0.7).sin() * 5_000.0, t * 91.3);
            for k in 0..2 {
                let (n, g) = o.octave_d(k, p);
                assert_eq!(n, o.octave(k, p));
                for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                    let fd = (o.octave(k, p + axis * h) - o.octave(k, p - axis * h)) / (2.0 * h);
                    let scale = 1.0 / o.wavelength(k);
                    assert!(
                        (fd - g.dot(axis)).abs() < 1e-4 * scale,
                        "octave {k} at {p}: {fd} vs {}",
                        g.dot(axis)
                    );
                }
            }
        }
    }

    #[test]
    fn stripes_turn_once_per_wavelength_across_their_direction() {
        let o = Octaves::new(8, 500.0, 1);
        let dir = DVec3::new(0.3, -0.5, 0.8).normalize();
        let (mut along, mut across, mut n) = (0.0, 0.0, 0);
        for i in 0..400 {
            let t = f64::from(i);
            let p = DVec3::new(6_378_137.0 + t * 113.0, t * 71.0, -t * 29.0);
            let z = o.stripes(0, p, dir);
            let len = z.0.hypot(z.1);
            assert!(len <= 1.0 + 1e-12, "{len}");
            if len < 0.5 {
                continue;
            }
            // A step of a tenth of a wavelength across turns the phase by 36 degrees, the
            // same step along the crests hardly at all.
            let turn = |q: DVec3| {
                let w = o.stripes(0, q, dir);
                (z.0 * w.1 - z.1 * w.0).atan2(z.0 * w.0 + z.1 * w.1)
            };
            let side = dir.cross(DVec3::new(0.1, 0.9, 0.2)).normalize();
            along += turn(p + side * 50.0).abs();
            across += turn(p + dir * 50.0);
            n += 1;
        }
        assert!(n > 100, "{n}");
        let (along, across) = (along / f64::from(n), across / f64::from(n));
        let expected = std::f64::consts::TAU / 10.0;
        assert!(
            (across - expected).abs() < 0.15 * expected,
            "{across} vs {expected}"
        );
        assert!(along < 0.3 * expected, "{along}");
    }

    #[test]
    fn precise_far_from_the_origin() {
        // On the planet surface at a 0.25 m wavelength: lattice coordinates near 2.6e7.
        let o = Octaves::new(9, 0.25, 1);
        let p = DVec3::new(6_378_137.0, 0.0, 0.0);
        let a = o.octave(0, p);
        let b = o.octave(0, p + DVec3::new(0.001, 0.0, 0.0));
        assert!((a - b).abs() < 0.2, "1 mm must not jump: {a} {b}");
        assert_ne!(a, b);
    }
}
