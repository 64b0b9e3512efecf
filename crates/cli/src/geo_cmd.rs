//! `globus geo`: conversions on the command line, printed as JSON.

use anyhow::{Context, bail};
use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_tiling::TilingScheme;
use serde_json::json;

/// `globus geo ecef LON LAT H`.
pub fn ecef(lon_deg: f64, lat_deg: f64, height_m: f64) -> anyhow::Result<String> {
    check_lon_lat(lon_deg, lat_deg)?;
    if !height_m.is_finite() {
        bail!("height {height_m} is not a number of metres");
    }
    let p = Ellipsoid::WGS84
        .cartographic_to_ecef(Cartographic::from_degrees(lon_deg, lat_deg, height_m));
    Ok(json!({"x": p.x, "y": p.y, "z": p.z}).to_string())
}

/// `globus geo cartographic X Y Z`.
pub fn cartographic(x: f64, y: f64, z: f64) -> anyhow::Result<String> {
    let p = DVec3::new(x, y, z);
    if !p.is_finite() {
        bail!("ECEF position ({x}, {y}, {z}) is not finite");
    }
    let c = Ellipsoid::WGS84.ecef_to_cartographic(p).with_context(|| {
        format!("({x}, {y}, {z}) is at the centre of the Earth, where latitude is undefined")
    })?;
    Ok(json!({"lon": c.lon_deg(), "lat": c.lat_deg(), "height": c.height_m}).to_string())
}

/// `globus geo slopes --lon LON --lat LAT`: the procedural planet's steepness around a point.
pub fn slopes(
    (lon_deg, lat_deg): (f64, f64),
    window_km: f64,
    spacing_m: f64,
    seed: u64,
) -> anyhow::Result<String> {
    check_lon_lat(lon_deg, lat_deg)?;
    if lat_deg.abs() > 85.0 {
        bail!("latitude {lat_deg}: the window would wrap round the pole (at most 85 degrees)");
    }
    if !(1.0..=10_000.0).contains(&spacing_m) {
        bail!("--spacing-m {spacing_m} must be from 1 to 10000 metres");
    }
    let samples = window_km * 1000.0 / spacing_m;
    if !(2.0..=4096.0).contains(&samples) {
        bail!(
            "--window-km {window_km} at --spacing-m {spacing_m} is {samples:.0} samples across \
             (2 to 4096)"
        );
    }
    let planet = globus_terrain::ProceduralPlanet::new(seed);
    let (h, side) = planet.height_window((lon_deg, lat_deg), window_km * 1000.0, spacing_m);
    let share = |deg| globus_terrain::slopes::steep_share(&h, side, spacing_m, deg);
    let highest = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mean = h.iter().sum::<f64>() / h.len() as f64;
    Ok(json!({
        "lon": lon_deg, "lat": lat_deg, "window_km": window_km, "spacing_m": spacing_m,
        "seed": seed, "samples": side * side,
        "steeper_than_20_deg": share(20.0),
        "steeper_than_30_deg": share(30.0),
        "steeper_than_40_deg": share(40.0),
        "highest_m": highest, "mean_height_m": mean,
    })
    .to_string())
}

/// `globus geo tile --scheme S --lon LON --lat LAT --level Z`.
pub fn tile(scheme: &str, lon_deg: f64, lat_deg: f64, level: u8) -> anyhow::Result<String> {
    let scheme: TilingScheme = scheme.parse()?;
    check_lon_lat(lon_deg, lat_deg)?;
    if level > globus_tiling::TileKey::MAX_LEVEL {
        bail!(
            "level {level} is deeper than the deepest level, {}",
            globus_tiling::TileKey::MAX_LEVEL
        );
    }
    let key = scheme
        .tile_at(lon_deg.to_radians(), lat_deg.to_radians(), level)
        .with_context(|| {
            format!(
                "latitude {lat_deg} is outside the {} scheme (+-{:.4} degrees)",
                scheme.name(),
                globus_tiling::WEB_MERCATOR_MAX_LAT_DEG
            )
        })?;
    let [w, s, e, n] = scheme.rect(key).to_degrees();
    Ok(json!({
        "scheme": scheme.name(),
        "z": key.level(), "x": key.x(), "y": key.y(),
        "tms_y": scheme.tms_y(key),
        "quadkey": scheme.quadkey(key),
        "bounds": {"west": w, "south": s, "east": e, "north": n},
    })
    .to_string())
}

/// Longitude in [-180, 180] and latitude in [-90, 90], or a one-line error.
pub fn check_lon_lat(lon_deg: f64, lat_deg: f64) -> anyhow::Result<()> {
    if !(-180.0..=180.0).contains(&lon_deg) {
        bail!("longitude {lon_deg} is outside -180..180 degrees");
    }
    if !(-90.0..=90.0).contains(&lat_deg) {
        bail!("latitude {lat_deg} is outside -90..90 degrees");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_json_has_names_and_bounds() {
        let v: serde_json::Value =
            serde_json::from_str(&tile("webmercator", 7.6, 46.0, 3).unwrap()).unwrap();
        assert_eq!(
            (v["x"].as_u64(), v["y"].as_u64(), v["tms_y"].as_u64()),
            (Some(4), Some(2), Some(5))
        );
        assert_eq!(v["quadkey"], "120");
        assert!(tile("utm", 0.0, 0.0, 1).is_err());
        assert!(tile("webmercator", 0.0, 89.0, 1).is_err());
    }

    #[test]
    fn ecef_round_trip_through_json() {
        let v: serde_json::Value = serde_json::from_str(&ecef(7.6, 46.0, 1000.0).unwrap()).unwrap();
        let c = cartographic(
            v["x"].as_f64().unwrap(),
            v["y"].as_f64().unwrap(),
            v["z"].as_f64().unwrap(),
        )
        .unwrap();
        let c: serde_json::Value = serde_json::from_str(&c).unwrap();
        assert!((c["height"].as_f64().unwrap() - 1000.0).abs() < 1e-6);
        assert!(ecef(200.0, 0.0, 0.0).is_err());
        assert!(cartographic(0.0, 0.0, 0.0).is_err());
    }
}
