//! A body's atmosphere: the physical model the renderer's sky and aerial perspective and the
//! level-of-detail fog are computed from, and the lookup tables the GPU reads.
//!
//! The model is Hillaire's (2020, "A Scalable and Production Ready Sky and Atmosphere
//! Rendering Technique", EGSR), with Bruneton's (2017) Earth parameters: a spherical shell
//! of air whose Rayleigh scattering and Mie scattering and absorption fall off exponentially
//! with height, plus an ozone layer (a tent 30 km wide at 25 km) that absorbs but does not
//! scatter. Light reaches the eye by single scattering of sunlight (Rayleigh and
//! Cornette-Shanks phase functions, the Earth's shadow) and by multiple scattering of all
//! orders, taken as isotropic and summed as a geometric series from the second order
//! (Hillaire's section 5.5, [`MultipleScatteringLut`]).
//!
//! A body that is not a sphere is made one: coordinates are stretched along each axis by the
//! equatorial radius over that axis's radius ([`Atmosphere::stretch`]), which turns the
//! ellipsoid into the sphere of its equatorial radius and the air into a shell over it;
//! distances change by at most the flattening (0.34 % for the Earth), heights over the
//! ellipsoid map to heights over the sphere exactly at the poles and equator.
//!
//! Everything here is f64 and deterministic; the renderer uploads [`TransmittanceLut`] and
//! [`MultipleScatteringLut`] once per atmosphere and ray-marches the rest per pixel in f32
//! with the same formulas. [`Atmosphere::sky`] is the reference the rendering tests compare
//! the GPU's pictures with. No Rust crate models a planet's atmosphere, hence this module.

use glam::DVec3;

use crate::Ellipsoid;

/// Width and height of the transmittance table (cosine of the view zenith angle, height).
pub const TRANSMITTANCE_SIZE: (u32, u32) = (256, 64);
/// Half the Sun's apparent width, radians (as a step of the cosine near the horizon).
const SUN_HALF_WIDTH: f64 = 0.0046;
/// Side of the multiple-scattering table (cosine of the sun zenith angle, height).
pub const MULTIPLE_SCATTERING_SIZE: u32 = 32;

/// The air over a body (see the module docs). `Atmosphere::none` is airless.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Atmosphere {
    /// Radius of the sphere the body becomes once stretched: its equatorial radius, metres.
    pub bottom_radius_m: f64,
    /// Height of the top of the air above it, metres (nothing scatters above).
    pub thickness_m: f64,
    /// Rayleigh scattering at the ground, per metre, red green blue.
    pub rayleigh_scattering: DVec3,
    /// Height over which Rayleigh density falls by e, metres.
    pub rayleigh_scale_height_m: f64,
    /// Mie scattering at the ground, per metre.
    pub mie_scattering: f64,
    /// Mie extinction (scattering plus absorption) at the ground, per metre.
    pub mie_extinction: f64,
    /// Height over which aerosol density falls by e, metres.
    pub mie_scale_height_m: f64,
    /// Mie asymmetry (0: isotropic, towards 1: forward).
    pub mie_g: f64,
    /// Ozone absorption at the layer's peak, per metre, red green blue.
    pub ozone_absorption: DVec3,
    /// Height of the ozone layer's peak, metres.
    pub ozone_peak_m: f64,
    /// Half the ozone layer's width, metres (its density falls linearly to 0 there).
    pub ozone_half_width_m: f64,
    /// Average reflectance of the ground seen by multiply scattered light.
    pub ground_albedo: f64,
    /// The body's semi-axes, metres (for [`Atmosphere::stretch`]).
    radii: DVec3,
}

impl Atmosphere {
    /// The Earth's air (Bruneton 2017's parameters, as in Hillaire 2020) over `body`.
    pub fn earth(body: &Ellipsoid) -> Self {
        let radii = body.radii();
        Self {
            bottom_radius_m: radii.x,
            thickness_m: 100_000.0,
            rayleigh_scattering: DVec3::new(5.802e-6, 13.558e-6, 33.1e-6),
            rayleigh_scale_height_m: 8_000.0,
            mie_scattering: 3.996e-6,
            mie_extinction: 4.440e-6,
            mie_scale_height_m: 1_200.0,
            mie_g: 0.8,
            ozone_absorption: DVec3::new(0.650e-6, 1.881e-6, 0.085e-6),
            ozone_peak_m: 25_000.0,
            ozone_half_width_m: 15_000.0,
            ground_albedo: 0.3,
            radii,
        }
    }

    /// No air over `body` (the Moon): black sky, no haze.
    pub fn none(body: &Ellipsoid) -> Self {
        Self {
            thickness_m: 0.0,
            rayleigh_scattering: DVec3::ZERO,
            mie_scattering: 0.0,
            mie_extinction: 0.0,
            ozone_absorption: DVec3::ZERO,
            ..Self::earth(body)
        }
    }

    /// The Earth's air for a body the size of the Earth (equatorial radius within 2 % of
    /// WGS84's), none for any other.
    pub fn for_body(body: &Ellipsoid) -> Self {
        let earth = Ellipsoid::WGS84.radii().x;
        if (body.radii().x / earth - 1.0).abs() < 0.02 {
            Self::earth(body)
        } else {
            Self::none(body)
        }
    }

    /// The same air over another body (its radii replace this one's).
    pub fn over(self, body: &Ellipsoid) -> Self {
        let radii = body.radii();
        Self {
            bottom_radius_m: radii.x,
            radii,
            ..self
        }
    }

    /// Whether there is no air at all.
    pub fn is_none(&self) -> bool {
        self.thickness_m <= 0.0
            || (self.rayleigh_scattering == DVec3::ZERO
                && self.mie_extinction == 0.0
                && self.ozone_absorption == DVec3::ZERO)
    }

    /// Radius of the top of the air, metres.
    pub fn top_radius_m(&self) -> f64 {
        self.bottom_radius_m + self.thickness_m
    }

    /// Per-axis factors that map ECEF coordinates into the model's space, where the body is
    /// the sphere of [`Atmosphere::bottom_radius_m`].
    pub fn stretch(&self) -> DVec3 {
        DVec3::splat(self.bottom_radius_m) / self.radii
    }

    /// Rayleigh, Mie and ozone densities (0..1) at `h` metres above the sphere.
    pub fn densities(&self, h: f64) -> (f64, f64, f64) {
        let h = h.max(0.0);
        let rayleigh = (-h / self.rayleigh_scale_height_m).exp();
        let mie = (-h / self.mie_scale_height_m).exp();
        let ozone = (1.0 - (h - self.ozone_peak_m).abs() / self.ozone_half_width_m).max(0.0);
        (rayleigh, mie, ozone)
    }

    /// Extinction per metre at `h` metres, red green blue.
    pub fn extinction(&self, h: f64) -> DVec3 {
        if h >= self.thickness_m {
            return DVec3::ZERO;
        }
        let (r, m, o) = self.densities(h);
        self.rayleigh_scattering * r
            + DVec3::splat(self.mie_extinction * m)
            + self.ozone_absorption * o
    }

    /// Distance from a point `h` metres above the sphere along a ray whose cosine with the
    /// local vertical is `mu` to where it leaves the top of the air (0 above it or going
    /// away from it).
    pub fn distance_to_top(&self, h: f64, mu: f64) -> f64 {
        let r = self.bottom_radius_m + h;
        // top^2 - r^2 without squaring planet-sized numbers twice.
        let c = (self.thickness_m - h) * (2.0 * self.bottom_radius_m + self.thickness_m + h);
        let disc = r * r * mu * mu + c;
        if disc < 0.0 {
            return 0.0;
        }
        (-r * mu + disc.sqrt()).max(0.0)
    }

    /// Distance from a point `h` metres above the sphere along a ray of vertical cosine
    /// `mu` to the ground, if the ray hits it.
    pub fn distance_to_ground(&self, h: f64, mu: f64) -> Option<f64> {
        let r = self.bottom_radius_m + h;
        let c = -h * (2.0 * self.bottom_radius_m + h);
        let disc = r * r * mu * mu + c;
        if mu >= 0.0 || disc < 0.0 {
            return None;
        }
        Some((-r * mu - disc.sqrt()).max(0.0))
    }

    /// Height above the sphere and vertical cosine of a point `t` metres along a ray from
    /// `h` metres with vertical cosine `mu`.
    fn along(&self, h: f64, mu: f64, t: f64) -> (f64, f64) {
        let r = self.bottom_radius_m + h;
        let rt = (r * r + t * t + 2.0 * r * mu * t).sqrt();
        (rt - self.bottom_radius_m, (r * mu + t) / rt)
    }

    /// Transmittance from `h` metres along vertical cosine `mu` to the top of the air,
    /// ignoring the ground (the table's content), by a 500-step march.
    pub fn transmittance_to_top(&self, h: f64, mu: f64) -> DVec3 {
        let d = self.distance_to_top(h, mu);
        (-self.optical_depth(h, mu, d, 500)).exp()
    }

    /// Optical depth along `length` metres of a ray from `h` metres with vertical cosine
    /// `mu`, by the midpoint rule over `steps`.
    pub fn optical_depth(&self, h: f64, mu: f64, length: f64, steps: u32) -> DVec3 {
        let dt = length / f64::from(steps.max(1));
        (0..steps.max(1))
            .map(|i| self.extinction(self.along(h, mu, (f64::from(i) + 0.5) * dt).0) * dt)
            .sum()
    }

    /// The transmittance table (Bruneton's parametrisation, see
    /// [`TransmittanceLut::uv`]).
    pub fn transmittance_lut(&self) -> TransmittanceLut {
        let (w, h) = TRANSMITTANCE_SIZE;
        let mut data = Vec::with_capacity((w * h) as usize);
        let geometry = LutGeometry::new(self);
        for y in 0..h {
            for x in 0..w {
                let (height, mu) = geometry.height_mu(
                    from_texel(f64::from(x) + 0.5, w),
                    from_texel(f64::from(y) + 0.5, h),
                );
                let d = self.distance_to_top(height, mu);
                let t = (-self.optical_depth(height, mu, d, 64)).exp();
                data.push([t.x as f32, t.y as f32, t.z as f32, 1.0]);
            }
        }
        TransmittanceLut {
            geometry,
            width: w,
            height: h,
            data,
        }
    }

    /// The multiple-scattering table from the transmittance table (Hillaire's section 5.5:
    /// second-order light from 64 directions with an isotropic phase, each further order a
    /// fraction `f_ms` of the one before).
    pub fn multiple_scattering_lut(
        &self,
        transmittance: &TransmittanceLut,
    ) -> MultipleScatteringLut {
        let n = MULTIPLE_SCATTERING_SIZE;
        let mut data = Vec::with_capacity((n * n) as usize);
        // 64 directions spread evenly over the sphere (a Fibonacci lattice).
        const DIRECTIONS: u32 = 64;
        const STEPS: u32 = 20;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let directions: Vec<DVec3> = (0..DIRECTIONS)
            .map(|i| {
                let z = 1.0 - (f64::from(i) + 0.5) * 2.0 / f64::from(DIRECTIONS);
                let s = (1.0 - z * z).sqrt();
                let a = golden * f64::from(i);
                DVec3::new(s * a.cos(), s * a.sin(), z)
            })
            .collect();
        let isotropic = 1.0 / (4.0 * std::f64::consts::PI);
        for y in 0..n {
            for x in 0..n {
                let mu_s = from_texel(f64::from(x) + 0.5, n) * 2.0 - 1.0;
                let h = (from_texel(f64::from(y) + 0.5, n) * self.thickness_m).max(1.0);
                let sun = DVec3::new((1.0 - mu_s * mu_s).max(0.0).sqrt(), 0.0, mu_s);
                let mut second = DVec3::ZERO;
                let mut transfer = DVec3::ZERO;
                for dir in &directions {
                    let mu = dir.z;
                    let ground = self.distance_to_ground(h, mu);
                    let length = ground.unwrap_or_else(|| self.distance_to_top(h, mu));
                    let dt = length / f64::from(STEPS);
                    let mut through = DVec3::ONE;
                    for i in 0..STEPS {
                        let t = (f64::from(i) + 0.5) * dt;
                        let (ht, up) = self.point(h, *dir, t);
                        let scattering = self.scattering_total(ht);
                        let extinction = self.extinction(ht);
                        let step = (-extinction * dt).exp();
                        // Analytic integration over the step (Hillaire's equation 6's form).
                        let weight = (DVec3::ONE - step) / extinction.max(DVec3::splat(1e-12));
                        let sun_t = self.sunlight(transmittance, ht, up.dot(sun));
                        second += through * scattering * sun_t * isotropic * weight;
                        transfer += through * scattering * weight;
                        through *= step;
                    }
                    if let Some(g) = ground {
                        let (_, up) = self.point(h, *dir, g);
                        let cos = up.dot(sun).max(0.0);
                        let sun_t = transmittance.sample(0.0, up.dot(sun));
                        second += through * sun_t * cos * self.ground_albedo / std::f64::consts::PI;
                    }
                }
                second /= f64::from(DIRECTIONS);
                transfer /= f64::from(DIRECTIONS);
                let psi = second / (DVec3::ONE - transfer);
                data.push([psi.x as f32, psi.y as f32, psi.z as f32, 1.0]);
            }
        }
        MultipleScatteringLut { size: n, data }
    }

    /// Height and unit up of the point `t` metres along unit `dir` (in a frame whose z is the
    /// vertical) from a point `h` metres above the sphere.
    fn point(&self, h: f64, dir: DVec3, t: f64) -> (f64, DVec3) {
        let p = DVec3::new(0.0, 0.0, self.bottom_radius_m + h) + dir * t;
        let r = p.length();
        (r - self.bottom_radius_m, p / r)
    }

    /// Scattering (Rayleigh plus Mie) per metre at `h`.
    fn scattering_total(&self, h: f64) -> DVec3 {
        if h >= self.thickness_m {
            return DVec3::ZERO;
        }
        let (r, m, _) = self.densities(h);
        self.rayleigh_scattering * r + DVec3::splat(self.mie_scattering * m)
    }

    /// Sunlight reaching a point `h` metres up whose vertical has cosine `mu_s` with the
    /// Sun: the table's transmittance, faded out as the Sun's disc (half a degree) sets
    /// behind the body's horizon.
    fn sunlight(&self, transmittance: &TransmittanceLut, h: f64, mu_s: f64) -> DVec3 {
        let h = h.max(0.0);
        let r = self.bottom_radius_m + h;
        let horizon_mu = -(h * (2.0 * self.bottom_radius_m + h)).sqrt() / r;
        let x = ((mu_s - horizon_mu + SUN_HALF_WIDTH) / (2.0 * SUN_HALF_WIDTH)).clamp(0.0, 1.0);
        let visible = x * x * (3.0 - 2.0 * x);
        if visible == 0.0 {
            return DVec3::ZERO;
        }
        transmittance.sample(h, mu_s) * visible
    }

    /// Light scattered towards an eye `h` metres above the sphere from the air along the
    /// unit ray `view` (a frame whose z is the eye's vertical), up to `max_distance` or the
    /// ground, with the Sun towards unit `sun` giving illuminance 1; and the transmittance
    /// along the same stretch. The reference the GPU's march is tested against.
    pub fn sky(
        &self,
        tables: &AtmosphereTables,
        h: f64,
        view: DVec3,
        sun: DVec3,
        max_distance: f64,
    ) -> (DVec3, DVec3) {
        self.sky_marched(tables, h, view, sun, max_distance, 400)
    }

    /// The light the whole sky sends onto level ground (`h` = 0) with the Sun at cosine
    /// `mu_s` from the zenith, for a Sun of illuminance 1: the integral of [`Atmosphere::sky`]
    /// times the cosine over the upper hemisphere (96 directions, cosine-weighted, each
    /// marched in 32 steps). Zero without air; it fades through twilight as the air above
    /// loses the Sun.
    pub fn ground_sky_irradiance(&self, tables: &AtmosphereTables, mu_s: f64) -> DVec3 {
        const RINGS: u32 = 8;
        const AZIMUTHS: u32 = 12;
        if self.is_none() {
            return DVec3::ZERO;
        }
        let mu_s = mu_s.clamp(-1.0, 1.0);
        let sun = DVec3::new((1.0 - mu_s * mu_s).sqrt(), 0.0, mu_s);
        let mut sum = DVec3::ZERO;
        for i in 0..RINGS {
            // Cosine-weighted rings: sin^2 of the zenith angle uniform.
            let sin2 = (f64::from(i) + 0.5) / f64::from(RINGS);
            let (sin, cos) = (sin2.sqrt(), (1.0 - sin2).sqrt());
            for j in 0..AZIMUTHS {
                let phi = (f64::from(j) + 0.5) / f64::from(AZIMUTHS) * std::f64::consts::TAU;
                let view = DVec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                sum += self
                    .sky_marched(tables, 0.0, view, sun, f64::INFINITY, 32)
                    .0;
            }
        }
        sum * (std::f64::consts::PI / f64::from(RINGS * AZIMUTHS))
    }

    fn sky_marched(
        &self,
        tables: &AtmosphereTables,
        h: f64,
        view: DVec3,
        sun: DVec3,
        max_distance: f64,
        steps: u32,
    ) -> (DVec3, DVec3) {
        let (mut start, mut end) = (0.0_f64, max_distance);
        // Only the stretch inside the air counts.
        let r = self.bottom_radius_m + h;
        let top = self.top_radius_m();
        let b = r * view.z;
        let c = (h - self.thickness_m) * (2.0 * self.bottom_radius_m + h + self.thickness_m);
        let disc = b * b - c;
        if disc < 0.0 || self.is_none() {
            return (DVec3::ZERO, DVec3::ONE);
        }
        let (enter, leave) = (-b - disc.sqrt(), -b + disc.sqrt());
        if leave <= 0.0 || r > top && enter < 0.0 {
            return (DVec3::ZERO, DVec3::ONE);
        }
        start = start.max(enter);
        end = end.min(leave);
        if let Some(g) = self.distance_to_ground(h, view.z) {
            end = end.min(g);
        }
        if end <= start {
            return (DVec3::ZERO, DVec3::ONE);
        }
        let cos = view.dot(sun);
        let rayleigh_phase = 3.0 / (16.0 * std::f64::consts::PI) * (1.0 + cos * cos);
        let mie_phase = cornette_shanks(self.mie_g, cos);
        let dt = (end - start) / f64::from(steps);
        let mut through = DVec3::ONE;
        let mut light = DVec3::ZERO;
        for i in 0..steps {
            let t = start + (f64::from(i) + 0.5) * dt;
            let (ht, up) = self.point(h, view, t);
            if ht >= self.thickness_m {
                continue;
            }
            let (rd, md, _) = self.densities(ht);
            let mu_s = up.dot(sun);
            let sun_t = self.sunlight(&tables.transmittance, ht, mu_s);
            let multiple = tables.multiple_scattering.sample(self, ht, mu_s);
            let scattering_r = self.rayleigh_scattering * rd;
            let scattering_m = self.mie_scattering * md;
            let source = sun_t
                * (scattering_r * rayleigh_phase + DVec3::splat(scattering_m * mie_phase))
                + (scattering_r + DVec3::splat(scattering_m)) * multiple;
            let extinction = self.extinction(ht);
            let step = (-extinction * dt).exp();
            let weight = (DVec3::ONE - step) / extinction.max(DVec3::splat(1e-12));
            light += through * source * weight;
            through *= step;
        }
        (light, through)
    }

    /// The share of a contrast at `to` that reaches `from` (both ECEF): the transmittance
    /// between them in the channel the air dims least, marched in 6 steps crowded towards
    /// the lowest point (the level-of-detail fog, which calls it per tile: about 100 ns).
    pub fn contrast_kept(&self, from: DVec3, to: DVec3) -> f64 {
        let s = self.stretch();
        (-self
            .optical_depth_between(from * s, to * s, 6)
            .min_element())
        .exp()
    }

    /// The smallest extinction per metre anywhere, in the channel the air dims least at the
    /// ground: `exp(-it * distance)` is a floor under [`Atmosphere::contrast_kept`] over
    /// that distance (density never exceeds the ground's, ozone aside, which only adds).
    pub fn clearest_extinction(&self) -> f64 {
        (self.rayleigh_scattering + DVec3::splat(self.mie_extinction)).min_element()
    }

    /// Transmittance between two points given in the model's space (ECEF already
    /// [`Atmosphere::stretch`]ed), marched over the stretch inside the air in `steps`
    /// crowded towards the stretch's lowest point, where the air is densest (as the
    /// shaders do): how much of a contrast at `to` survives to `from`.
    pub fn transmittance_between(&self, from: DVec3, to: DVec3, steps: u32) -> DVec3 {
        (-self.optical_depth_between(from, to, steps)).exp()
    }

    /// Optical depth between two points of the model's space (see
    /// [`Atmosphere::transmittance_between`]); densities in f32, which is ample for them
    /// and twice as fast.
    fn optical_depth_between(&self, from: DVec3, to: DVec3, steps: u32) -> DVec3 {
        if self.is_none() {
            return DVec3::ZERO;
        }
        let length = from.distance(to);
        if length <= 0.0 {
            return DVec3::ZERO;
        }
        let dir = (to - from) / length;
        // The part of the segment inside the top sphere.
        let top = self.top_radius_m();
        let b = from.dot(dir);
        let disc = b * b - (from.length_squared() - top * top);
        if disc <= 0.0 {
            return DVec3::ZERO;
        }
        let near = (-b - disc.sqrt()).max(0.0);
        let far = (-b + disc.sqrt()).min(length);
        if far <= near {
            return DVec3::ZERO;
        }
        let lowest = (-b).clamp(near, far);
        let (before, after) = (lowest - near, far - lowest);
        let steps = steps.max(2);
        let tiny = 0.01 * (far - near);
        let split = if before <= tiny {
            0
        } else if after <= tiny {
            steps
        } else {
            steps / 2
        };
        let (inv_rayleigh, inv_mie) = (
            (1.0 / self.rayleigh_scale_height_m) as f32,
            (1.0 / self.mie_scale_height_m) as f32,
        );
        let (mut rayleigh, mut mie, mut ozone) = (0.0, 0.0, 0.0);
        for i in 0..steps {
            let (a, b) = if i < split {
                let n = f64::from(split);
                let k = f64::from(split - 1 - i);
                (
                    lowest - before * ((k + 1.0) / n).powi(2),
                    lowest - before * (k / n).powi(2),
                )
            } else {
                let n = f64::from(steps - split);
                let k = f64::from(i - split);
                (
                    lowest + after * (k / n).powi(2),
                    lowest + after * ((k + 1.0) / n).powi(2),
                )
            };
            let h = ((from + dir * (0.5 * (a + b))).length() - self.bottom_radius_m).max(0.0);
            if h >= self.thickness_m {
                continue;
            }
            let dt = b - a;
            let hf = h as f32;
            rayleigh += f64::from((-hf * inv_rayleigh).exp()) * dt;
            mie += f64::from((-hf * inv_mie).exp()) * dt;
            ozone += (1.0 - (h - self.ozone_peak_m).abs() / self.ozone_half_width_m).max(0.0) * dt;
        }
        self.rayleigh_scattering * rayleigh
            + DVec3::splat(self.mie_extinction * mie)
            + self.ozone_absorption * ozone
    }
}

/// The Cornette-Shanks phase function (Mie scattering by aerosols), per steradian.
pub fn cornette_shanks(g: f64, cos: f64) -> f64 {
    let k = 3.0 / (8.0 * std::f64::consts::PI) * (1.0 - g * g) / (2.0 + g * g);
    k * (1.0 + cos * cos) / (1.0 + g * g - 2.0 * g * cos).powf(1.5)
}

/// Entries of [`AtmosphereTables::sky_irradiance`].
pub const SKY_IRRADIANCE_SIZE: usize = 32;
/// The Sun's cosine from the zenith at the table's first entry (about 17 degrees below the
/// horizon, where twilight has gone); below it the sky sends nothing.
pub const SKY_IRRADIANCE_MIN_MU: f64 = -0.3;

/// The tables, built together.
#[derive(Clone, Debug)]
pub struct AtmosphereTables {
    /// Transmittance to the top of the air.
    pub transmittance: TransmittanceLut,
    /// Multiply scattered light.
    pub multiple_scattering: MultipleScatteringLut,
    /// The sky's light on level ground ([`Atmosphere::ground_sky_irradiance`]) for the Sun's
    /// cosine from [`SKY_IRRADIANCE_MIN_MU`] to 1 in even steps.
    pub sky_irradiance: Vec<DVec3>,
}

impl AtmosphereTables {
    /// The tables of `atmosphere` (a few tens of milliseconds).
    pub fn new(atmosphere: &Atmosphere) -> Self {
        let transmittance = atmosphere.transmittance_lut();
        let multiple_scattering = atmosphere.multiple_scattering_lut(&transmittance);
        let mut tables = Self {
            transmittance,
            multiple_scattering,
            sky_irradiance: Vec::new(),
        };
        tables.sky_irradiance = (0..SKY_IRRADIANCE_SIZE)
            .map(|i| atmosphere.ground_sky_irradiance(&tables, sky_irradiance_mu(i)))
            .collect();
        tables
    }

    /// The sky's light on level ground with the Sun at cosine `mu_s` from the zenith,
    /// interpolated in the table (zero below [`SKY_IRRADIANCE_MIN_MU`]).
    pub fn sky_irradiance_at(&self, mu_s: f64) -> DVec3 {
        let n = self.sky_irradiance.len();
        if n == 0 || mu_s < SKY_IRRADIANCE_MIN_MU {
            return DVec3::ZERO;
        }
        let x = ((mu_s.min(1.0) - SKY_IRRADIANCE_MIN_MU) / (1.0 - SKY_IRRADIANCE_MIN_MU))
            * (n - 1) as f64;
        let i = (x.floor() as usize).min(n.saturating_sub(2));
        let f = (x - i as f64).clamp(0.0, 1.0);
        self.sky_irradiance[i].lerp(self.sky_irradiance[(i + 1).min(n - 1)], f)
    }
}

/// The Sun's cosine from the zenith at entry `i` of [`AtmosphereTables::sky_irradiance`].
pub fn sky_irradiance_mu(i: usize) -> f64 {
    SKY_IRRADIANCE_MIN_MU
        + (1.0 - SKY_IRRADIANCE_MIN_MU) * i as f64 / (SKY_IRRADIANCE_SIZE - 1) as f64
}

/// Maps a texel coordinate to 0..1 so that texel centres land on 0 and 1 exactly
/// (Bruneton's `GetUnitRangeFromTextureCoord`).
fn from_texel(coord: f64, size: u32) -> f64 {
    let n = f64::from(size);
    ((coord / n) - 0.5 / n) / (1.0 - 1.0 / n)
}

/// Inverse of [`from_texel`], to texture coordinates 0..1.
fn to_texel(unit: f64, size: u32) -> f64 {
    let n = f64::from(size);
    0.5 / n + unit * (1.0 - 1.0 / n)
}

/// The sphere and shell the transmittance table is parametrised by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LutGeometry {
    /// Bottom radius, metres.
    pub bottom_m: f64,
    /// Thickness of the air, metres.
    pub thickness_m: f64,
    /// Distance from the ground to the top along the horizon: sqrt(top^2 - bottom^2).
    pub horizon_m: f64,
}

impl LutGeometry {
    fn new(a: &Atmosphere) -> Self {
        let t = a.thickness_m.max(1.0);
        Self {
            bottom_m: a.bottom_radius_m,
            thickness_m: t,
            horizon_m: (t * (2.0 * a.bottom_radius_m + t)).sqrt(),
        }
    }

    /// Height and vertical cosine of the table coordinates (0..1 over texel centres).
    fn height_mu(&self, x_mu: f64, x_r: f64) -> (f64, f64) {
        let rho = self.horizon_m * x_r;
        let r = (rho * rho + self.bottom_m * self.bottom_m).sqrt();
        let h = r - self.bottom_m;
        let d_min = self.thickness_m - h;
        let d_max = rho + self.horizon_m;
        let d = d_min + x_mu * (d_max - d_min);
        let mu = if d <= 0.0 {
            1.0
        } else {
            ((self.horizon_m * self.horizon_m - rho * rho - d * d) / (2.0 * r * d)).clamp(-1.0, 1.0)
        };
        (h, mu)
    }
}

/// Transmittance from a height along a direction to the top of the air, ignoring the
/// ground: 256 x 64 texels, x from the distance to the top (between the shortest, straight
/// up, and the longest, along the horizon), y from the distance to the horizon, as
/// Bruneton (2017) lays it out so that low heights and grazing rays get most texels.
#[derive(Clone, Debug)]
pub struct TransmittanceLut {
    /// The shell it was built for.
    pub geometry: LutGeometry,
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// RGBA texels, rows from the ground up (alpha 1).
    pub data: Vec<[f32; 4]>,
}

impl TransmittanceLut {
    /// Texture coordinates (0..1) of a height and vertical cosine.
    pub fn uv(&self, h: f64, mu: f64) -> (f64, f64) {
        let g = &self.geometry;
        let h = h.clamp(0.0, g.thickness_m);
        let rho = (h * (2.0 * g.bottom_m + h)).sqrt();
        let r = g.bottom_m + h;
        let c = (g.thickness_m - h) * (2.0 * g.bottom_m + g.thickness_m + h);
        let d = (-r * mu + (r * r * mu * mu + c).max(0.0).sqrt()).max(0.0);
        let d_min = g.thickness_m - h;
        let d_max = rho + g.horizon_m;
        let x_mu = ((d - d_min) / (d_max - d_min)).clamp(0.0, 1.0);
        let x_r = rho / g.horizon_m;
        (to_texel(x_mu, self.width), to_texel(x_r, self.height))
    }

    /// Bilinear lookup, as the GPU's sampler does.
    pub fn sample(&self, h: f64, mu: f64) -> DVec3 {
        let (u, v) = self.uv(h, mu);
        bilinear(&self.data, self.width, self.height, u, v)
    }
}

/// Multiply scattered light (second order onwards, summed) per unit scattering at a height
/// and sun zenith cosine, for illuminance 1: 32 x 32 texels, x the cosine from -1 to 1, y
/// the height from the ground to the top.
#[derive(Clone, Debug)]
pub struct MultipleScatteringLut {
    /// Texels along each side.
    pub size: u32,
    /// RGBA texels, rows from the ground up (alpha 1).
    pub data: Vec<[f32; 4]>,
}

impl MultipleScatteringLut {
    /// Bilinear lookup, as the GPU's sampler does.
    pub fn sample(&self, atmosphere: &Atmosphere, h: f64, mu_s: f64) -> DVec3 {
        let u = to_texel((mu_s * 0.5 + 0.5).clamp(0.0, 1.0), self.size);
        let v = to_texel(
            (h / atmosphere.thickness_m.max(1.0)).clamp(0.0, 1.0),
            self.size,
        );
        bilinear(&self.data, self.size, self.size, u, v)
    }
}

/// Clamped bilinear filtering of RGB texels at texture coordinates (u, v).
fn bilinear(data: &[[f32; 4]], w: u32, h: u32, u: f64, v: f64) -> DVec3 {
    let x = (u * f64::from(w) - 0.5).clamp(0.0, f64::from(w - 1));
    let y = (v * f64::from(h) - 0.5).clamp(0.0, f64::from(h - 1));
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - f64::from(x0), y - f64::from(y0));
    let at = |x: u32, y: u32| {
        let t = data[(y * w + x) as usize];
        DVec3::new(f64::from(t[0]), f64::from(t[1]), f64::from(t[2]))
    };
    let top = at(x0, y0).lerp(at(x1, y0), fx);
    let bottom = at(x0, y1).lerp(at(x1, y1), fx);
    top.lerp(bottom, fy)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn earth() -> Atmosphere {
        Atmosphere::earth(&Ellipsoid::WGS84)
    }

    /// Optical depth of an exponential layer of scale height `s` over a flat ground, seen
    /// straight up from `h`: s exp(-h / s) (1 - exp(-(T - h) / s)).
    #[test]
    fn vertical_transmittance_matches_the_flat_layer_formula() {
        let a = earth();
        for h in [0.0, 1_500.0, 12_000.0] {
            let layer = |s: f64| s * (-h / s).exp() * (1.0 - (-(a.thickness_m - h) / s).exp());
            // The ozone tent's integral above h (piecewise linear, by hand).
            let ozone = {
                let (p, w) = (a.ozone_peak_m, a.ozone_half_width_m);
                let tent = |x: f64| -> f64 {
                    // Integral of max(0, 1 - |y - p| / w) from -inf to x.
                    let y = x - p;
                    if y <= -w {
                        0.0
                    } else if y <= 0.0 {
                        (y + w) * (y + w) / (2.0 * w)
                    } else if y < w {
                        w - (w - y) * (w - y) / (2.0 * w)
                    } else {
                        w
                    }
                };
                tent(a.thickness_m) - tent(h)
            };
            let depth = a.rayleigh_scattering * layer(a.rayleigh_scale_height_m)
                + DVec3::splat(a.mie_extinction * layer(a.mie_scale_height_m))
                + a.ozone_absorption * ozone;
            let expected = (-depth).exp();
            let got = a.transmittance_to_top(h, 1.0);
            assert!(
                (got - expected).abs().max_element() < 2e-4,
                "h {h}: {got} against {expected}"
            );
        }
        // Sea level, straight up: the blue loses about a quarter, the red under 6 %.
        let t = a.transmittance_to_top(0.0, 1.0);
        assert!(t.x > 0.93 && t.z < 0.77 && t.z > 0.70, "{t}");
    }

    #[test]
    fn the_table_reproduces_the_march_where_it_is_read() {
        let a = earth();
        let lut = a.transmittance_lut();
        for (h, mu) in [
            (0.0, 1.0),
            (0.0, 0.2),
            (0.0, 0.02),
            (2_000.0, -0.01),
            (30_000.0, 0.5),
            (80_000.0, -0.1),
        ] {
            let exact = a.transmittance_to_top(h, mu);
            let got = lut.sample(h, mu);
            assert!(
                (got - exact).abs().max_element() < 0.01,
                "h {h} mu {mu}: table {got}, march {exact}"
            );
        }
        // Through the horizon from the ground the air takes nearly all the blue.
        assert!(lut.sample(0.0, 0.0).z < 0.01);
    }

    #[test]
    fn the_sky_lights_the_ground_bluish_by_day_and_fades_through_twilight() {
        let a = earth();
        let tables = AtmosphereTables::new(&a);
        let mean = |v: DVec3| v.element_sum() / 3.0;
        let e = |mu: f64| tables.sky_irradiance_at(mu);
        // Noon: skylight is blue (Rayleigh) and a clear sky's diffuse light on level ground
        // is 10-25 % of the light on it (measured broadband ratios are 0.1-0.2 at high Sun).
        let noon = e(1.0);
        let direct = a.transmittance_to_top(0.0, 1.0);
        assert!(noon.z > 1.5 * noon.x, "{noon}");
        let share = mean(noon) / (mean(noon) + mean(direct));
        assert!(
            (0.08..0.25).contains(&share),
            "diffuse share {share} at noon"
        );
        // At a 30 degree Sun the sky's share of the light is larger than at noon.
        let low = e(0.5);
        let low_share = mean(low) / (mean(low) + 0.5 * mean(a.transmittance_to_top(0.0, 0.5)));
        assert!(low_share > share, "{low_share} against {share}");
        // Less light as the Sun sinks, down to nothing once twilight has gone.
        let series: Vec<f64> = [1.0, 0.5, 0.2, 0.05, 0.0, -0.05, -0.15, -0.29]
            .iter()
            .map(|&mu| mean(e(mu)))
            .collect();
        assert!(series.windows(2).all(|w| w[1] < w[0]), "{series:?}");
        assert!(series[7] < 1e-3 * series[0], "{series:?}");
        assert_eq!(e(-0.5), DVec3::ZERO);
        // The table reads back the integral between its entries.
        let exact = a.ground_sky_irradiance(&tables, 0.37);
        assert!(
            ((e(0.37) - exact).abs() / exact).max_element() < 0.03,
            "{} against {exact}",
            e(0.37)
        );
        // No air, no skylight.
        let none = Atmosphere::none(&Ellipsoid::WGS84);
        assert_eq!(
            AtmosphereTables::new(&none).sky_irradiance_at(1.0),
            DVec3::ZERO
        );
    }

    #[test]
    fn the_sky_is_blue_at_the_zenith_and_red_at_sunset() {
        let a = earth();
        let tables = AtmosphereTables::new(&a);
        let up = DVec3::Z;
        let noon = DVec3::new(0.5, 0.0, 0.866);
        let (zenith, _) = a.sky(&tables, 2.0, up, noon, f64::INFINITY);
        let horizon_dir = DVec3::new(0.0, 1.0, 0.01).normalize();
        let (horizon, _) = a.sky(&tables, 2.0, horizon_dir, noon, f64::INFINITY);
        assert!(zenith.z > zenith.x * 2.0, "zenith {zenith}");
        assert!(
            horizon.length() > zenith.length(),
            "horizon {horizon} zenith {zenith}"
        );
        assert!(
            horizon.z / horizon.x < zenith.z / zenith.x,
            "the horizon is paler"
        );
        // The Sun on the horizon: towards it the sky is red; away from it, bluer.
        let sunset = DVec3::new(1.0, 0.0, 0.02).normalize();
        let (towards, _) = a.sky(
            &tables,
            2.0,
            DVec3::new(1.0, 0.0, 0.05).normalize(),
            sunset,
            f64::INFINITY,
        );
        let (away, _) = a.sky(
            &tables,
            2.0,
            DVec3::new(-1.0, 0.0, 0.05).normalize(),
            sunset,
            f64::INFINITY,
        );
        assert!(towards.x > towards.z, "towards the setting sun {towards}");
        assert!(
            towards.x / towards.z > away.x / away.z,
            "towards {towards} away {away}"
        );
        // Multiply scattered light: some by day, bluest in the air, none deep in the night.
        let m = tables.multiple_scattering.sample(&a, 0.0, 0.866);
        assert!(m.z > m.x && m.x > 0.0 && m.z < 0.2, "noon {m}");
        let night = tables.multiple_scattering.sample(&a, 0.0, -0.5);
        assert!(
            night.max_element() < m.min_element() * 0.01,
            "night {night}"
        );
    }

    #[test]
    fn no_air_is_transparent_and_dark() {
        let a = Atmosphere::none(&Ellipsoid::MOON);
        assert!(a.is_none());
        assert!(Atmosphere::for_body(&Ellipsoid::MARS).is_none());
        assert!(!Atmosphere::for_body(&Ellipsoid::WGS84).is_none());
        let from = DVec3::new(0.0, 0.0, a.bottom_radius_m + 10.0);
        let to = from + DVec3::new(100_000.0, 0.0, 0.0);
        assert_eq!(a.transmittance_between(from, to, 8), DVec3::ONE);
    }

    #[test]
    fn distant_ground_loses_more_contrast_than_near_ground() {
        let a = earth();
        let from = DVec3::new(0.0, 0.0, a.bottom_radius_m + 3_000.0);
        let near = a.transmittance_between(from, from + DVec3::new(5_000.0, 0.0, -3_000.0), 16);
        let far = a.transmittance_between(from, from + DVec3::new(150_000.0, 0.0, -4_000.0), 16);
        assert!(
            near.y > 0.9 && far.y < 0.4 && far.z < far.x,
            "near {near} far {far}"
        );
        // The stretch makes the ellipsoid the equatorial sphere.
        let s = a.stretch();
        let pole = DVec3::new(0.0, 0.0, Ellipsoid::WGS84.radii().z) * s;
        assert!((pole.length() - a.bottom_radius_m).abs() < 1e-6);
    }
}
