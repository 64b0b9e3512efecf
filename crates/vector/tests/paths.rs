//! Densified geodesics and rhumb lines against an independent library: geographiclib (the
//! PyPI package, through `paths_peers.py`) checks the middle of every straight piece Globus
//! draws, draped (linear in longitude/latitude) and at altitude (3D chords), within 1 m.

use std::io::Write;
use std::process::{Command, Stdio};

use globus_geo::{Cartographic, Ellipsoid};
use globus_vector::PathKind;
use globus_vector::shape::{Straight, densify};

#[test]
fn drawn_pieces_stay_within_a_metre_of_geographiclibs_paths() {
    let e = Ellipsoid::WGS84;
    let pairs: [([f64; 2], [f64; 2]); 6] = [
        ([8.55, 47.45], [-73.78, 40.64]),    // Zurich - New York
        ([151.18, -33.95], [-118.4, 33.94]), // Sydney - Los Angeles, over the antimeridian
        ([2.35, 48.85], [2.35, -48.85]),     // along a meridian
        ([-60.0, 80.0], [120.0, 80.0]),      // over the pole (geodesic), round it (rhumb)
        ([0.0, 0.0], [90.0, 0.0]),           // along the equator
        ([11.05, 57.45], [11.95, 57.45]),    // a short piece
    ];
    let mut paths = Vec::new();
    let mut counts = Vec::new();
    for kind in [PathKind::Geodesic, PathKind::Rhumb] {
        for (straight, h) in [(Straight::LonLat, 0.0), (Straight::Chord, 10_000.0)] {
            for (a, b) in pairs {
                let mut b = b;
                b[0] = globus_vector::shape::unwrap_near(b[0], a[0]);
                let pts = densify(
                    &e,
                    &[[a[0], a[1], h], [b[0], b[1], h]],
                    false,
                    kind,
                    straight,
                    1.0,
                );
                let mids: Vec<[f64; 3]> = pts
                    .windows(2)
                    .map(|w| match straight {
                        Straight::LonLat => {
                            [(w[0][0] + w[1][0]) / 2.0, (w[0][1] + w[1][1]) / 2.0, h]
                        }
                        Straight::Chord => {
                            let p = |q: [f64; 3]| {
                                e.cartographic_to_ecef(Cartographic::new(
                                    q[0].to_radians(),
                                    q[1].to_radians(),
                                    q[2],
                                ))
                            };
                            let c = e
                                .ecef_to_cartographic((p(w[0]) + p(w[1])) / 2.0)
                                .expect("midpoint");
                            [c.lon_deg(), c.lat_deg(), c.height_m]
                        }
                    })
                    .collect();
                counts.push((kind, straight, a, pts.len()));
                paths.push(serde_json::json!({
                    "kind": if kind == PathKind::Geodesic { "geodesic" } else { "rhumb" },
                    "a": a, "b": b, "h": h, "mids": mids,
                }));
            }
        }
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/paths_peers.py");
    let mut child = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 with geographiclib (pip install geographiclib)");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(serde_json::to_string(&paths).expect("json").as_bytes())
        .expect("write");
    let out = child.wait_with_output().expect("python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let worst: Vec<f64> = serde_json::from_slice(&out.stdout).expect("deviations");
    for (d, (kind, straight, a, n)) in worst.iter().zip(&counts) {
        eprintln!("{kind:?} {straight:?} from {a:?}: {n} vertices, worst midpoint {d:.3} m");
        assert!(
            *d <= 1.0,
            "{kind:?} {straight:?} from {a:?}: a drawn midpoint {d:.3} m off"
        );
    }
}
