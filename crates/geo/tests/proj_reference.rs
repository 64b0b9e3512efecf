//! Conversions against PROJ (pyproj, EPSG:4979 -> EPSG:4978), an independent implementation.
//! The table comes from `tools/make_reference_tables.py`.

use globus_geo::{Cartographic, DVec3, Ellipsoid};

struct Row {
    lon: f64,
    lat: f64,
    h: f64,
    ecef: DVec3,
}

fn rows() -> Vec<Row> {
    let text = include_str!("data/proj_wgs84.json");
    let v: serde_json::Value = serde_json::from_str(text).expect("table parses");
    let f = |r: &serde_json::Value, k: &str| r[k].as_f64().expect("number");
    v["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| Row {
            lon: f(r, "lon"),
            lat: f(r, "lat"),
            h: f(r, "h"),
            ecef: DVec3::new(f(r, "x"), f(r, "y"), f(r, "z")),
        })
        .collect()
}

#[test]
fn table_covers_the_hard_places() {
    let rows = rows();
    assert!(rows.len() > 500);
    assert!(rows.iter().any(|r| r.lat == 90.0 && r.h == 40_000_000.0));
    assert!(rows.iter().any(|r| r.lon == -180.0 && r.h == -500.0));
}

#[test]
fn cartographic_to_ecef_matches_proj() {
    for r in rows() {
        let p =
            Ellipsoid::WGS84.cartographic_to_ecef(Cartographic::from_degrees(r.lon, r.lat, r.h));
        // PROJ prints to ~1e-9 m relative; allow 1 mm at 40,000 km.
        let tol = 1e-6 + 2e-11 * r.ecef.length();
        assert!(
            (p - r.ecef).length() < tol,
            "({}, {}, {}): globus {p} vs PROJ {} ({} m)",
            r.lon,
            r.lat,
            r.h,
            r.ecef,
            (p - r.ecef).length()
        );
    }
}

#[test]
fn ecef_to_cartographic_matches_proj() {
    for r in rows() {
        let c = Ellipsoid::WGS84
            .ecef_to_cartographic(r.ecef)
            .expect("not at the centre");
        let tol_h = 1e-6 + 2e-11 * r.ecef.length();
        assert!(
            (c.height_m - r.h).abs() < tol_h,
            "height at {} {} {}: {}",
            r.lon,
            r.lat,
            r.h,
            c.height_m
        );
        assert!(
            (c.lat_deg() - r.lat).abs() < 1e-9,
            "lat at {} {} {}",
            r.lon,
            r.lat,
            r.h
        );
        if r.lat.abs() < 89.99 {
            let dlon = (c.lon_deg() - r.lon + 540.0).rem_euclid(360.0) - 180.0;
            assert!(
                dlon.abs() < 1e-9,
                "lon at {} {} {}: {}",
                r.lon,
                r.lat,
                r.h,
                c.lon_deg()
            );
        }
    }
}

#[test]
fn round_trip_error_is_under_a_micrometre_from_minus_500_m_to_40000_km() {
    let e = Ellipsoid::WGS84;
    let mut worst: f64 = 0.0;
    for i in 0..20_000 {
        let t = i as f64;
        let lon = (t * 0.618_033_988_7).fract() * 360.0 - 180.0;
        let lat = ((t * 0.414_213_562_3).fract() * 180.0 - 90.0).clamp(-90.0, 90.0);
        let h = -500.0 + (t * 0.732_050_807_5).fract().powi(3) * 40_000_500.0;
        let p = e.cartographic_to_ecef(Cartographic::from_degrees(lon, lat, h));
        let back = e.ecef_to_cartographic(p).expect("not at centre");
        let p2 = e.cartographic_to_ecef(back);
        worst = worst.max((p - p2).length());
    }
    assert!(worst < 1e-6, "worst round trip {worst} m");
}
