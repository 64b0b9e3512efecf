//! Tiling schemes: how tile keys map to rectangles on the globe, and how tiles are named.
//!
//! * [`TilingScheme::Geographic`]: EPSG:4326 "plate carree" tiles, two 180 x 180 degree roots
//!   at level 0 (x = 0 west, x = 1 east), `2^(L+1) x 2^L` tiles at level L. Covers the poles.
//!   This is the layout Cesium uses for terrain and the one Globus prefers.
//! * [`TilingScheme::WebMercator`]: EPSG:3857 tiles as served by OSM, Google and Bing, one root,
//!   `2^L x 2^L` tiles, latitude limited to +-85.0511 degrees (where the square ends).
//!
//! Naming: XYZ (`y` from the north, used by keys), TMS (`y` from the south) and Bing-style
//! quadkeys. Quadkeys are defined by Bing for Web Mercator; for the geographic scheme Globus
//! writes the root column (`0` or `1`) as an extra leading digit.

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;
use std::str::FromStr;

use crate::{Direction, GeoRect, TileKey};

/// The latitude where the Web Mercator square ends: `atan(sinh(pi))`, degrees.
pub const WEB_MERCATOR_MAX_LAT_DEG: f64 = 85.051_128_779_806_59;

/// How the globe is cut into tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum TilingScheme {
    /// EPSG:4326, two roots.
    #[default]
    Geographic,
    /// EPSG:3857, one root.
    WebMercator,
}

/// A tile name that could not be parsed or is out of range.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseTileNameError(pub String);

impl fmt::Display for ParseTileNameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ParseTileNameError {}

const GEOGRAPHIC_ROOTS: [TileKey; 2] = [TileKey::ROOT_WEST, TileKey::ROOT_EAST];
const MERCATOR_ROOTS: [TileKey; 1] = [TileKey::ROOT_WEST];

impl TileKey {
    /// Level 0, x 0, y 0: the western geographic root, or the one Web Mercator root.
    pub const ROOT_WEST: TileKey = TileKey::from_bits_unchecked(0);
    /// Level 0, x 1, y 0: the eastern geographic root.
    pub const ROOT_EAST: TileKey = TileKey::from_bits_unchecked(1 << 29);

    /// The neighbour across one edge, wrapping across the antimeridian; `None` past a pole
    /// or the Web Mercator edge.
    pub fn neighbor(self, scheme: TilingScheme, direction: Direction) -> Option<TileKey> {
        let (nx, ny) = (scheme.tiles_x(self.level()), scheme.tiles_y(self.level()));
        let (x, y) = (u64::from(self.x()), u64::from(self.y()));
        let (x, y) = match direction {
            Direction::North => (x, y.checked_sub(1)?),
            Direction::South => (x, Some(y + 1).filter(|&y| y < ny)?),
            Direction::East => ((x + 1) % nx, y),
            Direction::West => ((x + nx - 1) % nx, y),
        };
        TileKey::try_new(self.level(), x as u32, y as u32)
    }
}

impl TilingScheme {
    /// The level-0 tiles.
    pub fn roots(self) -> &'static [TileKey] {
        match self {
            TilingScheme::Geographic => &GEOGRAPHIC_ROOTS,
            TilingScheme::WebMercator => &MERCATOR_ROOTS,
        }
    }

    /// The number of columns at `level`.
    pub fn tiles_x(self, level: u8) -> u64 {
        match self {
            TilingScheme::Geographic => 2u64 << level,
            TilingScheme::WebMercator => 1u64 << level,
        }
    }

    /// The number of rows at `level`.
    pub fn tiles_y(self, level: u8) -> u64 {
        1u64 << level
    }

    /// Whether the key names a tile of this scheme.
    pub fn is_valid(self, key: TileKey) -> bool {
        u64::from(key.x()) < self.tiles_x(key.level())
            && u64::from(key.y()) < self.tiles_y(key.level())
    }

    /// The key for (level, x, y) if it is a tile of this scheme.
    pub fn key(self, level: u8, x: u32, y: u32) -> Option<TileKey> {
        TileKey::try_new(level, x, y).filter(|k| self.is_valid(*k))
    }

    /// The tile's rectangle in longitude and latitude, radians.
    pub fn rect(self, key: TileKey) -> GeoRect {
        let level = key.level();
        let nx = self.tiles_x(level) as f64;
        let ny = self.tiles_y(level) as f64;
        let west = -PI + 2.0 * PI * f64::from(key.x()) / nx;
        let east = -PI + 2.0 * PI * f64::from(key.x() + 1) / nx;
        let (north, south) = match self {
            TilingScheme::Geographic => (
                FRAC_PI_2 - PI * f64::from(key.y()) / ny,
                FRAC_PI_2 - PI * f64::from(key.y() + 1) / ny,
            ),
            TilingScheme::WebMercator => (
                mercator_y_to_lat(f64::from(key.y()) / ny),
                mercator_y_to_lat(f64::from(key.y() + 1) / ny),
            ),
        };
        GeoRect {
            west,
            south,
            east,
            north,
        }
    }

    /// The tile at `level` containing a longitude and latitude (radians). Points on a border
    /// belong to the tile to their east and south, except on the east and south edges of the
    /// world. `None` outside the scheme's latitude range or for non-finite input.
    pub fn tile_at(self, lon_rad: f64, lat_rad: f64, level: u8) -> Option<TileKey> {
        if !lon_rad.is_finite() || !lat_rad.is_finite() || level > TileKey::MAX_LEVEL {
            return None;
        }
        let nx = self.tiles_x(level);
        let ny = self.tiles_y(level);
        let fx = (lon_rad + PI) / (2.0 * PI);
        let fy = match self {
            TilingScheme::Geographic => {
                if lat_rad.abs() > FRAC_PI_2 {
                    return None;
                }
                (FRAC_PI_2 - lat_rad) / PI
            }
            TilingScheme::WebMercator => {
                if lat_rad.abs() > WEB_MERCATOR_MAX_LAT_DEG.to_radians() {
                    return None;
                }
                lat_to_mercator_y(lat_rad)
            }
        };
        let x = ((fx.rem_euclid(1.0) * nx as f64).floor() as u64).min(nx - 1);
        // Longitude exactly 180 E wraps to 180 W by rem_euclid; keep it in the last column.
        let x = if lon_rad >= PI { nx - 1 } else { x };
        let y = ((fy * ny as f64).floor().max(0.0) as u64).min(ny - 1);
        TileKey::try_new(level, x as u32, y as u32)
    }

    /// The TMS row (counted from the south) of a key.
    pub fn tms_y(self, key: TileKey) -> u32 {
        (self.tiles_y(key.level()) - 1 - u64::from(key.y())) as u32
    }

    /// The key for a TMS-named tile.
    pub fn from_tms(self, level: u8, x: u32, tms_y: u32) -> Option<TileKey> {
        let ny = self.tiles_y(level.min(TileKey::MAX_LEVEL));
        let y = ny.checked_sub(1)?.checked_sub(u64::from(tms_y))?;
        self.key(level, x, y as u32)
    }

    /// The quadkey of a tile (Bing: level 3, x 3, y 5 is "213"). Geographic quadkeys start with
    /// the root column digit.
    pub fn quadkey(self, key: TileKey) -> String {
        let level = key.level();
        let mut s = String::with_capacity(usize::from(level) + 1);
        if self == TilingScheme::Geographic {
            s.push(if key.x() >> level == 0 { '0' } else { '1' });
        }
        for i in (1..=level).rev() {
            let bit = 1u32 << (i - 1);
            let mut digit = b'0';
            if key.x() & bit != 0 {
                digit += 1;
            }
            if key.y() & bit != 0 {
                digit += 2;
            }
            s.push(char::from(digit));
        }
        s
    }

    /// The key named by a quadkey.
    pub fn from_quadkey(self, quadkey: &str) -> Result<TileKey, ParseTileNameError> {
        let bad = |why: &str| ParseTileNameError(format!("quadkey {quadkey:?}: {why}"));
        let mut digits = quadkey.bytes();
        let mut x: u32 = 0;
        let mut y: u32 = 0;
        if self == TilingScheme::Geographic {
            x = match digits.next() {
                Some(b'0') => 0,
                Some(b'1') => 1,
                _ => return Err(bad("a geographic quadkey starts with its root, 0 or 1")),
            };
        }
        let mut level: u8 = 0;
        for d in digits {
            if level >= TileKey::MAX_LEVEL {
                return Err(bad("too many digits"));
            }
            let d = match d {
                b'0'..=b'3' => u32::from(d - b'0'),
                _ => return Err(bad("digits must be 0 to 3")),
            };
            x = (x << 1) | (d & 1);
            y = (y << 1) | (d >> 1);
            level += 1;
        }
        self.key(level, x, y).ok_or_else(|| bad("out of range"))
    }

    /// The scheme's name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            TilingScheme::Geographic => "geographic",
            TilingScheme::WebMercator => "webmercator",
        }
    }
}

impl FromStr for TilingScheme {
    type Err = ParseTileNameError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "geographic" | "epsg:4326" | "4326" => Ok(TilingScheme::Geographic),
            "webmercator" | "web-mercator" | "mercator" | "epsg:3857" | "3857" => {
                Ok(TilingScheme::WebMercator)
            }
            _ => Err(ParseTileNameError(format!(
                "unknown tiling scheme {s:?}: expected geographic (or epsg:4326, 4326) or webmercator (or web-mercator, mercator, epsg:3857, 3857)"
            ))),
        }
    }
}

impl TilingScheme {
    /// The scheme a container's metadata names (`metadata.json`, an MBTiles `scheme` row):
    /// `None` for `tms` or `xyz`, which some writers put there to name the row order, not the
    /// projection; an error for anything else that is not a scheme.
    pub fn parse_container(s: &str) -> Result<Option<Self>, ParseTileNameError> {
        if s.eq_ignore_ascii_case("tms") || s.eq_ignore_ascii_case("xyz") {
            Ok(None)
        } else {
            s.parse().map(Some)
        }
    }
}

impl fmt::Display for TilingScheme {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Web Mercator: latitude (radians) to the fraction of the square from the top, in [0, 1].
pub fn lat_to_mercator_y(lat_rad: f64) -> f64 {
    let y = lat_rad.tan().asinh();
    (1.0 - y / PI) * 0.5
}

/// Inverse of [`lat_to_mercator_y`].
pub fn mercator_y_to_lat(fy: f64) -> f64 {
    (PI * (1.0 - 2.0 * fy)).sinh().atan()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bing_quadkey_example() {
        let k = TileKey::new(3, 3, 5);
        assert_eq!(TilingScheme::WebMercator.quadkey(k), "213");
        assert_eq!(TilingScheme::WebMercator.from_quadkey("213"), Ok(k));
        assert_eq!(
            TilingScheme::WebMercator.from_quadkey(""),
            Ok(TileKey::ROOT_WEST)
        );
        assert!(TilingScheme::WebMercator.from_quadkey("14").is_err());
    }

    #[test]
    fn geographic_quadkeys_carry_the_root() {
        let g = TilingScheme::Geographic;
        assert_eq!(g.quadkey(TileKey::ROOT_EAST), "1");
        let k = TileKey::new(2, 6, 1); // east root; x 2 (digits 1, 0) and y 1 (digits 0, 1) within it
        assert_eq!(g.quadkey(k), "112");
        assert_eq!(g.from_quadkey("112"), Ok(k));
        assert!(g.from_quadkey("").is_err());
    }

    #[test]
    fn geographic_roots_split_at_greenwich() {
        let g = TilingScheme::Geographic;
        assert_eq!(
            g.rect(TileKey::ROOT_WEST).to_degrees(),
            [-180.0, -90.0, 0.0, 90.0]
        );
        assert_eq!(
            g.rect(TileKey::ROOT_EAST).to_degrees(),
            [0.0, -90.0, 180.0, 90.0]
        );
        assert_eq!(
            g.tile_at(0.1f64.to_radians(), 89.0f64.to_radians(), 0),
            Some(TileKey::ROOT_EAST)
        );
        assert_eq!(
            g.tile_at(std::f64::consts::PI, -std::f64::consts::FRAC_PI_2, 3),
            Some(TileKey::new(3, 15, 7))
        );
    }

    #[test]
    fn neighbours_wrap_in_longitude_and_stop_at_poles() {
        let g = TilingScheme::Geographic;
        let k = TileKey::new(2, 0, 0);
        assert_eq!(k.neighbor(g, Direction::West), Some(TileKey::new(2, 7, 0)));
        assert_eq!(k.neighbor(g, Direction::North), None);
        assert_eq!(
            TileKey::new(2, 7, 3).neighbor(g, Direction::East),
            Some(TileKey::new(2, 0, 3))
        );
        assert_eq!(TileKey::new(2, 7, 3).neighbor(g, Direction::South), None);
        let m = TilingScheme::WebMercator;
        assert_eq!(
            TileKey::new(1, 0, 1).neighbor(m, Direction::West),
            Some(TileKey::new(1, 1, 1))
        );
        assert_eq!(
            TileKey::ROOT_WEST.neighbor(m, Direction::East),
            Some(TileKey::ROOT_WEST)
        );
    }

    #[test]
    fn tms_flips_rows() {
        let m = TilingScheme::WebMercator;
        let k = TileKey::new(3, 2, 1);
        assert_eq!(m.tms_y(k), 6);
        assert_eq!(m.from_tms(3, 2, 6), Some(k));
        assert_eq!(m.from_tms(3, 2, 8), None);
    }

    #[test]
    fn parse_scheme_names() {
        assert_eq!("WebMercator".parse(), Ok(TilingScheme::WebMercator));
        assert_eq!("geographic".parse(), Ok(TilingScheme::Geographic));
        assert!("utm".parse::<TilingScheme>().is_err());
    }
}
