//! SRTM `.hgt` files: square grids of big-endian i16 metres, -32768 for voids, sample
//! centres on whole arc-second multiples (pixel-is-point); the file name gives the south-west
//! corner (`N57E011.hgt` covers 57..58 N, 11..12 E; its first row is the north edge).

use std::path::{Path, PathBuf};

use crate::error::{Result, TilerError};
use crate::raster::{Crs, ElevationRaster, Georef, Registration};

/// The void marker of SRTM files.
pub const HGT_VOID: i16 = -32768;

/// The south-west corner encoded in an SRTM file name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HgtName {
    /// Latitude of the southern edge, degrees.
    pub lat: i32,
    /// Longitude of the western edge, degrees.
    pub lon: i32,
}

impl HgtName {
    /// Parses `N57E011` (case-insensitive) from the start of a file name.
    pub fn parse(file_name: &str) -> Option<Self> {
        let b = file_name.as_bytes();
        if b.len() < 7 {
            return None;
        }
        let lat_sign = match b[0].to_ascii_uppercase() {
            b'N' => 1,
            b'S' => -1,
            _ => return None,
        };
        let lon_sign = match b[3].to_ascii_uppercase() {
            b'E' => 1,
            b'W' => -1,
            _ => return None,
        };
        let lat: i32 = file_name.get(1..3)?.parse().ok()?;
        let lon: i32 = file_name.get(4..7)?.parse().ok()?;
        let (lat, lon) = (lat_sign * lat, lon_sign * lon);
        ((-90..90).contains(&lat) && (-180..180).contains(&lon)).then_some(Self { lat, lon })
    }
}

struct HgtFile {
    path: PathBuf,
    name: HgtName,
    samples: usize,
    bytes: Vec<u8>,
}

fn open_hgt(path: &Path) -> Result<HgtFile> {
    let file_name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let name = HgtName::parse(file_name).ok_or_else(|| {
        TilerError::bad_input(
            path,
            "an SRTM file name must start with its south-west corner, like N57E011.hgt",
        )
    })?;
    let bytes = std::fs::read(path).map_err(|e| TilerError::io(path, e))?;
    let samples = match bytes.len() {
        n if n == 1201 * 1201 * 2 => 1201,
        n if n == 3601 * 3601 * 2 => 3601,
        n => {
            return Err(TilerError::bad_input(
                path,
                format!(
                    "{n} bytes is neither an SRTM3 (1201x1201, {} bytes) nor an SRTM1 (3601x3601, {} bytes) file; truncated?",
                    1201 * 1201 * 2,
                    3601 * 3601 * 2
                ),
            ));
        }
    };
    Ok(HgtFile {
        path: path.to_owned(),
        name,
        samples,
        bytes,
    })
}

/// Reads one or more SRTM files of the same resolution into one raster covering their
/// bounding box. Voids and the parts of the box no file covers are `NaN`.
pub fn read_hgt_mosaic(paths: &[PathBuf]) -> Result<ElevationRaster> {
    let files = paths
        .iter()
        .map(|p| open_hgt(p))
        .collect::<Result<Vec<_>>>()?;
    let Some(first) = files.first() else {
        return Err(TilerError::BadOptions("no input files".into()));
    };
    let n = first.samples;
    if let Some(other) = files.iter().find(|f| f.samples != n) {
        return Err(TilerError::bad_input(
            &other.path,
            format!(
                "has {} samples a side but {} has {n}; mixing SRTM1 and SRTM3 is not supported",
                other.samples,
                first.path.display()
            ),
        ));
    }
    let west = files.iter().map(|f| f.name.lon).min().unwrap_or(0);
    let east = files.iter().map(|f| f.name.lon + 1).max().unwrap_or(0);
    let south = files.iter().map(|f| f.name.lat).min().unwrap_or(0);
    let north = files.iter().map(|f| f.name.lat + 1).max().unwrap_or(0);
    let per_degree = n - 1;
    let width = (east - west) as usize * per_degree + 1;
    let height = (north - south) as usize * per_degree + 1;
    let mut data = vec![f32::NAN; width * height];
    for f in &files {
        let col0 = (f.name.lon - west) as usize * per_degree;
        let row0 = (north - f.name.lat - 1) as usize * per_degree;
        for (r, row) in f.bytes.chunks_exact(n * 2).enumerate() {
            let out = &mut data[(row0 + r) * width + col0..][..n];
            for (o, v) in out.iter_mut().zip(row.chunks_exact(2)) {
                let h = i16::from_be_bytes([v[0], v[1]]);
                *o = if h == HGT_VOID {
                    f32::NAN
                } else {
                    f32::from(h)
                };
            }
        }
    }
    let step = 1.0 / per_degree as f64;
    Ok(ElevationRaster {
        width,
        height,
        data,
        georef: Georef {
            crs: Crs::Geographic,
            x0: f64::from(west),
            y0: f64::from(north),
            dx: step,
            dy: step,
            registration: Registration::Point,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_give_the_south_west_corner() {
        assert_eq!(
            HgtName::parse("N57E011.hgt"),
            Some(HgtName { lat: 57, lon: 11 })
        );
        assert_eq!(
            HgtName::parse("s01w180.HGT"),
            Some(HgtName { lat: -1, lon: -180 })
        );
        assert_eq!(HgtName::parse("X57E011.hgt"), None);
        assert_eq!(HgtName::parse("N95E011.hgt"), None);
        assert_eq!(HgtName::parse("N57"), None);
    }

    #[test]
    fn two_files_share_their_edge() {
        let dir = globus_test_support::output_dir("hgt_mosaic");
        let mut paths = Vec::new();
        for (name, value) in [("N10E020.hgt", 100i16), ("N10E021.hgt", 200)] {
            let mut bytes = Vec::with_capacity(1201 * 1201 * 2);
            for i in 0..1201 * 1201 {
                let v = if i == 5 { HGT_VOID } else { value };
                bytes.extend_from_slice(&v.to_be_bytes());
            }
            let p = dir.join(name);
            std::fs::write(&p, bytes).unwrap();
            paths.push(p);
        }
        let r = read_hgt_mosaic(&paths).unwrap();
        assert_eq!((r.width, r.height), (2401, 1201));
        assert_eq!(r.get(0, 0), 100.0);
        assert!(r.get(5, 0).is_nan(), "void becomes NaN");
        assert_eq!(r.get(2400, 1200), 200.0);
        let f = r.footprint();
        assert_eq!(
            f.to_degrees().map(|d| (d * 1e9).round() / 1e9),
            [20.0, 10.0, 22.0, 11.0]
        );
    }

    #[test]
    fn truncated_file_is_refused_with_its_name() {
        let dir = globus_test_support::output_dir("hgt_truncated");
        let p = dir.join("N10E020.hgt");
        std::fs::write(&p, vec![0u8; 1000]).unwrap();
        let e = read_hgt_mosaic(&[p]).unwrap_err().to_string();
        assert!(e.contains("N10E020.hgt") && e.contains("truncated"), "{e}");
    }
}
