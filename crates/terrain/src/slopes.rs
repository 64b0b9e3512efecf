//! How steep terrain is: the share of an area steeper than an angle, the figure issue 20 asks
//! of the procedural mountains (real alpine terrain at about 30 m spacing has 20-30 % of its
//! area steeper than 30 degrees).

use globus_geo::{Cartographic, DVec3};

use crate::ProceduralPlanet;

/// The share (0..1) of the cells of a `side` x `side` grid of heights `h` (row-major,
/// `spacing_m` apart both ways) whose slope exceeds `threshold_deg`; each interior sample's
/// slope is taken from central differences. 0 for grids smaller than 3 x 3.
pub fn steep_share(h: &[f64], side: usize, spacing_m: f64, threshold_deg: f64) -> f64 {
    if side < 3 || h.len() != side * side {
        return 0.0;
    }
    let limit = threshold_deg.to_radians().tan();
    let (mut steep, mut all) = (0u64, 0u64);
    for y in 1..side - 1 {
        for x in 1..side - 1 {
            let gx = (h[y * side + x + 1] - h[y * side + x - 1]) / (2.0 * spacing_m);
            let gy = (h[(y + 1) * side + x] - h[(y - 1) * side + x]) / (2.0 * spacing_m);
            steep += u64::from(gx.hypot(gy) > limit);
            all += 1;
        }
    }
    steep as f64 / all as f64
}

impl ProceduralPlanet {
    /// Heights (metres, at least 0: the sea surface) of a square window `window_m` wide
    /// centred on (`lon_deg`, `lat_deg`), sampled `spacing_m` apart east-west and north-south
    /// with every octave down to twice the spacing; returns them with the side.
    pub fn height_window(
        &self,
        (lon_deg, lat_deg): (f64, f64),
        window_m: f64,
        spacing_m: f64,
    ) -> (Vec<f64>, usize) {
        let e = self.ellipsoid();
        let side = ((window_m / spacing_m).round() as usize).max(2) + 1;
        let r = e.mean_radius();
        let (lon0, lat0) = (lon_deg.to_radians(), lat_deg.to_radians());
        let half = (side - 1) as f64 / 2.0;
        let mut out = Vec::with_capacity(side * side);
        for j in 0..side {
            let lat = lat0 - (j as f64 - half) * spacing_m / r;
            for i in 0..side {
                let lon = lon0 + (i as f64 - half) * spacing_m / (r * lat.cos());
                let p: DVec3 = e.cartographic_to_ecef(Cartographic::new(lon, lat, 0.0));
                out.push(self.height_m(p, 2.0 * spacing_m).max(0.0));
            }
        }
        (out, side)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_steep_or_not_by_its_slope() {
        let side = 9;
        let plane = |deg: f64| -> Vec<f64> {
            let t = deg.to_radians().tan();
            (0..side * side)
                .map(|k| (k % side) as f64 * 30.0 * t)
                .collect()
        };
        assert_eq!(steep_share(&plane(29.0), side, 30.0, 30.0), 0.0);
        assert_eq!(steep_share(&plane(31.0), side, 30.0, 30.0), 1.0);
        // Half the grid steep, half flat: the interior columns split 4 / 3.
        let mut half = plane(45.0);
        for (k, v) in half.iter_mut().enumerate() {
            if k % side >= 4 {
                *v = 4.0 * 30.0;
            }
        }
        assert!((steep_share(&half, side, 30.0, 30.0) - 3.0 / 7.0).abs() < 1e-12);
        assert_eq!(steep_share(&[1.0; 4], 2, 30.0, 30.0), 0.0);
    }
}
