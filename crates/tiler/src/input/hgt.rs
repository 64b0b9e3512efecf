//! SRTM `.hgt` files: square grids of big-endian i16 metres, -32768 for voids, sample
//! centres on whole arc-second multiples (pixel-is-point); the file name gives the south-west
//! corner (`N57E011.hgt` covers 57..58 N, 11..12 E; its first row is the north edge).
//! Neighbouring files repeat their shared edge row or column.

use std::path::{Path, PathBuf};

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use rustc_hash::{FxHashMap, FxHashSet};

use crate::error::{Result, TilerError};
use crate::fill::fill_voids;
use crate::lru::Lru;
use crate::raster::{Crs, Georef, Registration, RowSource};

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

/// Bytes of decoded files a mosaic keeps in memory by default.
pub const DEFAULT_CACHE_BYTES: usize = 1 << 30;

/// SRTM files as one grid covering their bounding box, loaded on demand: only the files
/// the tiles being built touch are decoded, and at most a byte budget of them is kept (least
/// recently used first out), so a planet of SRTM tiles needs no more memory than a few.
/// Each file's voids are filled (push-pull) when it loads; where the box has no file (SRTM
/// has none over the sea) heights are 0 m.
pub struct HgtMosaic {
    files: FxHashMap<(i32, i32), PathBuf>,
    /// Samples per file side (1201 or 3601).
    n: usize,
    west: i32,
    north: i32,
    cols_deg: usize,
    rows_deg: usize,
    georef: Georef,
    cache: Mutex<FileCache>,
    voids: AtomicUsize,
}

struct FileCache {
    files: Lru<(i32, i32), Vec<f32>>,
    /// Files whose voids are already counted.
    counted: FxHashSet<(i32, i32)>,
}

fn check_hgt(path: &Path) -> Result<(HgtName, usize)> {
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
    let len = std::fs::metadata(path)
        .map_err(|e| TilerError::io(path, e))?
        .len();
    let samples = match len {
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
    Ok((name, samples))
}

/// Opens SRTM files of one resolution as a [`HgtMosaic`], checking names and sizes now and
/// reading samples later, as tiles need them.
pub fn read_hgt_mosaic(paths: &[PathBuf]) -> Result<HgtMosaic> {
    HgtMosaic::open(paths, DEFAULT_CACHE_BYTES)
}

impl HgtMosaic {
    /// Opens `paths` keeping at most `budget` bytes of decoded files.
    pub fn open(paths: &[PathBuf], budget: usize) -> Result<Self> {
        let mut files = FxHashMap::default();
        let mut n = None;
        for p in paths {
            let (name, samples) = check_hgt(p)?;
            match n {
                None => n = Some((samples, p)),
                Some((m, first)) if m != samples => {
                    return Err(TilerError::bad_input(
                        p,
                        format!(
                            "has {samples} samples a side but {} has {m}; mixing SRTM1 and SRTM3 is not supported",
                            first.display()
                        ),
                    ));
                }
                Some(_) => {}
            }
            if let Some(other) = files.insert((name.lat, name.lon), p.clone()) {
                return Err(TilerError::bad_input(
                    p,
                    format!("covers the same square as {}", other.display()),
                ));
            }
        }
        let Some((n, _)) = n else {
            return Err(TilerError::BadOptions("no input files".into()));
        };
        let keys: Vec<(i32, i32)> = files.keys().copied().collect();
        let west = keys.iter().map(|k| k.1).min().unwrap_or(0);
        let east = keys.iter().map(|k| k.1 + 1).max().unwrap_or(0);
        let south = keys.iter().map(|k| k.0).min().unwrap_or(0);
        let north = keys.iter().map(|k| k.0 + 1).max().unwrap_or(0);
        let step = 1.0 / (n - 1) as f64;
        Ok(Self {
            files,
            n,
            west,
            north,
            cols_deg: (east - west) as usize,
            rows_deg: (north - south) as usize,
            georef: Georef {
                crs: Crs::Geographic,
                x0: f64::from(west),
                y0: f64::from(north),
                dx: step,
                dy: step,
                registration: Registration::Point,
            },
            cache: Mutex::new(FileCache {
                files: Lru::new(budget / (n * n * 4)),
                counted: FxHashSet::default(),
            }),
            voids: AtomicUsize::new(0),
        })
    }

    /// The decoded, void-filled samples of the file at (lat, lon), if there is one.
    fn file(&self, key: (i32, i32)) -> Result<Option<Arc<Vec<f32>>>> {
        let Some(path) = self.files.get(&key) else {
            return Ok(None);
        };
        let poisoned = || TilerError::BadOptions("a worker panicked".into());
        {
            let mut cache = self.cache.lock().map_err(|_| poisoned())?;
            if let Some(data) = cache.files.get(key) {
                return Ok(Some(data));
            }
        }
        // Decode outside the lock; two threads may decode the same file once each.
        let bytes = globus_tiling::files::read_capped(path, (self.n * self.n * 2) as u64)
            .map_err(|e| TilerError::io(path, e))?;
        if bytes.len() != self.n * self.n * 2 {
            return Err(TilerError::bad_input(path, "changed size while tiling"));
        }
        let mut data: Vec<f32> = bytes
            .chunks_exact(2)
            .map(|v| match i16::from_be_bytes([v[0], v[1]]) {
                HGT_VOID => f32::NAN,
                h => f32::from(h),
            })
            .collect();
        let filled = match fill_voids(&mut data, self.n, self.n) {
            Some(k) => k,
            None => {
                // All void: nothing to interpolate from; the sea level stands in.
                data.fill(0.0);
                data.len()
            }
        };
        let data = Arc::new(data);
        let mut cache = self.cache.lock().map_err(|_| poisoned())?;
        if cache.counted.insert(key) {
            self.voids.fetch_add(filled, Ordering::Relaxed);
        }
        cache.files.insert(key, data.clone());
        Ok(Some(data))
    }
}

impl RowSource<f32> for HgtMosaic {
    fn width(&self) -> usize {
        self.cols_deg * (self.n - 1) + 1
    }

    fn height(&self) -> usize {
        self.rows_deg * (self.n - 1) + 1
    }

    fn georef(&self) -> &Georef {
        &self.georef
    }

    fn voids_filled(&self) -> usize {
        self.voids.load(Ordering::Relaxed)
    }

    fn read_row(&self, row: usize, c0: usize, out: &mut [f32]) -> Result<()> {
        let per = self.n - 1;
        // The row's file row; the southern edge row belongs to the last file row.
        let (fy, rr) = if row / per >= self.rows_deg {
            (self.rows_deg - 1, per)
        } else {
            (row / per, row % per)
        };
        let lat = self.north - 1 - fy as i32;
        let mut c = c0;
        let mut done = 0;
        while done < out.len() {
            let (fx, cc) = if c / per >= self.cols_deg {
                (self.cols_deg - 1, per)
            } else {
                (c / per, c % per)
            };
            // Up to the file's last column (shared with the next file, which owns it).
            let last = if fx + 1 == self.cols_deg {
                per
            } else {
                per - 1
            };
            let run = (last + 1 - cc).min(out.len() - done);
            let lon = self.west + fx as i32;
            let dst = &mut out[done..done + run];
            match self.file((lat, lon))? {
                Some(data) => dst.copy_from_slice(&data[rr * self.n + cc..][..run]),
                None => dst.fill(0.0),
            }
            done += run;
            c += run;
        }
        Ok(())
    }
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

    fn row(m: &HgtMosaic, r: usize, c0: usize, len: usize) -> Vec<f32> {
        let mut out = vec![0.0; len];
        m.read_row(r, c0, &mut out).unwrap();
        out
    }

    #[test]
    fn files_form_one_grid_loaded_on_demand() {
        let dir = globus_test_support::output_dir("hgt_mosaic");
        let mut paths = Vec::new();
        // Two squares side by side and one south of the first; the fourth is sea.
        for (name, value) in [
            ("N10E020.hgt", 100i16),
            ("N10E021.hgt", 200),
            ("N09E020.hgt", 300),
        ] {
            let mut bytes = Vec::with_capacity(1201 * 1201 * 2);
            for i in 0..1201 * 1201 {
                let v = if i == 5 { HGT_VOID } else { value };
                bytes.extend_from_slice(&v.to_be_bytes());
            }
            let p = dir.join(name);
            std::fs::write(&p, bytes).unwrap();
            paths.push(p);
        }
        // A budget of one file: every switch reloads, and answers stay the same.
        let m = HgtMosaic::open(&paths, 1201 * 1201 * 4).unwrap();
        assert_eq!((m.width(), m.height()), (2401, 2401));
        let f = m.footprint();
        assert_eq!(
            f.to_degrees().map(|d| (d * 1e9).round() / 1e9),
            [20.0, 9.0, 22.0, 11.0]
        );
        // Row 0 spans both northern files; the shared column 1200 belongs to the eastern one.
        let r0 = row(&m, 0, 1195, 10);
        assert_eq!(&r0[..5], &[100.0; 5]);
        assert_eq!(&r0[5..], &[200.0; 5]);
        // The void at column 5 was filled from its neighbours.
        assert_eq!(row(&m, 0, 3, 5), vec![100.0; 5]);
        assert_eq!(m.voids_filled(), 2, "{}", m.voids_filled());
        // The south-east square has no file: sea level.
        assert_eq!(row(&m, 2000, 1300, 4), vec![0.0; 4]);
        // The last row and column belong to the southern and eastern files.
        assert_eq!(row(&m, 2400, 0, 2), vec![300.0; 2]);
        assert_eq!(row(&m, 600, 2399, 2), vec![200.0; 2]);
        assert_eq!(
            row(&m, 1200, 0, 1),
            vec![300.0],
            "the shared row belongs to the southern file"
        );
    }

    #[test]
    fn truncated_file_is_refused_with_its_name() {
        let dir = globus_test_support::output_dir("hgt_truncated");
        let p = dir.join("N10E020.hgt");
        std::fs::write(&p, vec![0u8; 1000]).unwrap();
        let Err(e) = read_hgt_mosaic(&[p]) else {
            panic!("accepted a truncated file")
        };
        let e = e.to_string();
        assert!(e.contains("N10E020.hgt") && e.contains("truncated"), "{e}");
    }
}
