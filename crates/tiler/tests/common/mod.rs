//! Helpers for the tiler's tests: jobs over the shared data and independent references.

#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use globus_tiler::{JobKind, TileJob};
use globus_tiling::TilingScheme;

pub use globus_test_support::{output_dir, shared_data};

/// A job with the defaults of the command line.
pub fn job(kind: JobKind, inputs: &[PathBuf], out: &Path, scheme: TilingScheme) -> TileJob {
    TileJob {
        scheme,
        threads: Some(2),
        ..TileJob::new(kind, inputs.to_vec(), out.to_owned())
    }
}

/// A fresh, empty output path under `target/test-output/<test>/<name>`.
pub fn fresh(test: &str, name: &str) -> PathBuf {
    let p = output_dir(test).join(name);
    let _ = std::fs::remove_dir_all(&p);
    let _ = std::fs::remove_file(&p);
    p
}

/// Every file under `dir` (relative path -> bytes).
pub fn read_tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// RGB(A) pixels of a PNG/JPEG tile file.
pub fn decode_rgba(path: &Path) -> image::RgbaImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .into_rgba8()
}

/// The raw SRTM file `N57E011.hgt`, read here independently of the tiler: heights by
/// (row from north, column from west), 1201 x 1201, 3 arc-seconds apart.
pub struct Hgt {
    pub samples: Vec<i16>,
}

impl Hgt {
    pub fn load() -> Self {
        let bytes = std::fs::read(shared_data("N57E011.hgt")).expect("../shared/data/N57E011.hgt");
        Self {
            samples: bytes
                .chunks_exact(2)
                .map(|b| i16::from_be_bytes([b[0], b[1]]))
                .collect(),
        }
    }

    /// Bilinear height at (lon, lat) degrees inside 11..12 E, 57..58 N.
    pub fn height(&self, lon: f64, lat: f64) -> f64 {
        let c = ((lon - 11.0) * 1200.0).clamp(0.0, 1200.0);
        let r = ((58.0 - lat) * 1200.0).clamp(0.0, 1200.0);
        let (c0, r0) = (c.floor().min(1199.0), r.floor().min(1199.0));
        let (fc, fr) = (c - c0, r - r0);
        let at = |rr: f64, cc: f64| f64::from(self.samples[rr as usize * 1201 + cc as usize]);
        let top = at(r0, c0) * (1.0 - fc) + at(r0, c0 + 1.0) * fc;
        let bottom = at(r0 + 1.0, c0) * (1.0 - fc) + at(r0 + 1.0, c0 + 1.0) * fc;
        top * (1.0 - fr) + bottom * fr
    }
}

/// Longitude (degrees) of column `i` of an `n`-sample corner grid in tile column `x` of a
/// level with `nx` columns.
pub fn corner_lon(x: u32, i: usize, n: usize, nx: f64) -> f64 {
    -180.0 + (f64::from(x) + i as f64 / (n - 1) as f64) * 360.0 / nx
}

/// Latitude (degrees) of row `j` of an `n`-sample corner grid in tile row `y`.
pub fn corner_lat(scheme: TilingScheme, y: u32, j: usize, n: usize, ny: f64) -> f64 {
    let f = (f64::from(y) + j as f64 / (n - 1) as f64) / ny;
    match scheme {
        TilingScheme::Geographic | TilingScheme::GeographicReduced => 90.0 - f * 180.0,
        TilingScheme::WebMercator => (std::f64::consts::PI * (1.0 - 2.0 * f))
            .sinh()
            .atan()
            .to_degrees(),
    }
}

/// The mean absolute difference between the level-`z` tiles of an elevation pyramid (XYZ
/// directory, 256-sample corner grids, encoding `enc`) and the SRTM file, over every
/// `step`-th sample inside 11..12 E, 57..58 N shrunk by `margin` degrees; and the number of
/// samples compared.
pub fn mean_error_against_hgt(
    dir: &Path,
    scheme: TilingScheme,
    z: u8,
    enc: globus_tiler::ElevationEncoding,
    step: usize,
    margin: f64,
) -> (f64, u32) {
    let hgt = Hgt::load();
    let (nx, ny) = (scheme.tiles_x(z) as f64, scheme.tiles_y(z) as f64);
    let (mut sum, mut n) = (0.0, 0u32);
    for (name, _) in read_tree(&dir.join(z.to_string())) {
        let (x, y) = name.trim_end_matches(".png").split_once('/').unwrap();
        let (x, y): (u32, u32) = (x.parse().unwrap(), y.parse().unwrap());
        let img = decode_rgba(&dir.join(format!("{z}/{name}")));
        for j in (0..256).step_by(step) {
            let lat = corner_lat(scheme, y, j, 256, ny);
            for i in (0..256).step_by(step) {
                let lon = corner_lon(x, i, 256, nx);
                if (11.0 + margin..=12.0 - margin).contains(&lon)
                    && (57.0 + margin..=58.0 - margin).contains(&lat)
                {
                    let p = img.get_pixel(i as u32, j as u32);
                    sum += (enc.decode([p[0], p[1], p[2]]) - hgt.height(lon, lat)).abs();
                    n += 1;
                }
            }
        }
    }
    (sum / f64::from(n.max(1)), n)
}
