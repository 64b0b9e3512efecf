//! Tiling schemes: how tile keys map to rectangles on the globe, and how tiles are named.
//!
//! * [`TilingScheme::Geographic`]: EPSG:4326 "plate carree" tiles, two 180 x 180 degree roots
//!   at level 0 (x = 0 west, x = 1 east), `2^(L+1) x 2^L` tiles at level L. Covers the poles.
//!   This is the layout Cesium uses for terrain and the one Globus prefers.
//! * [`TilingScheme::WebMercator`]: EPSG:3857 tiles as served by OSM, Google and Bing, one root,
//!   `2^L x 2^L` tiles, latitude limited to +-85.0511 degrees (where the square ends).
//! * [`TilingScheme::GeographicReduced`]: the engine's own tiles, the geographic quadtree
//!   *reduced* towards the poles, as reduced Gaussian grids are: a tile spans as many
//!   geographic columns (a power of two, [`TilingScheme::columns`]) as keep it about as wide
//!   as it is tall, so tiles near a pole cost what their area costs instead of multiplying
//!   as the meridians converge (a 300 km high view of the pole drew 499 level-7 tiles of
//!   the plain quadtree against 22 over the equator), and their texels are not wedges.
//!   Data pyramids stay geographic or Web Mercator; engine tiles sample them by position.
//!
//! Why this and not the alternatives peers chose: polar cap tiles (harp.gl) need a second
//! projection and seams where it meets the grid; scaling the error by latitude
//! (osgEarth#809, mapbox-gl-js#11508) draws coarser tiles near the poles but keeps their
//! sliver shape, so imagery there stays streaked; an equal-area projection of engine tiles
//! would resample every geographic pyramid. The reduced tree keeps geographic rectangles
//! (every source and draping rule holds as it was; only wide polar edges need care in the
//! meshes, `globus_terrain::mesh`), keys as they were (a reduced tile is named by its
//! westernmost column) and ancestor fallback (every tile still has one parent that
//! contains it).
//!
//! A tile at level L, row y spans `2^k` columns where `2^k` is the largest power of two with
//! `2^k cos(phi) <= 1.6`, `phi` the latitude of the row's edge nearer the equator, so its
//! width there is from 0.8 to 1.6 times its height (tiles below 36.9 degrees do not merge).
//! Halving a row moves that edge at most half a row polewards, which at most halves its
//! cosine; so a child spans half its parent's width or, in the poleward half, possibly the
//! whole of it: children nest in their parent, and a tile has four children or, where its
//! poleward half stays whole, three.
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

/// The widest a reduced tile is at its equatorward edge, in heights: tiles start to merge at
/// 36.9 degrees, where they are 0.8 as wide as tall, and are never narrower than that; the
/// range (0.8, 1.6] is centred a little above 1 because a tile narrows polewards.
const MAX_ASPECT: f64 = 1.6;

/// How the globe is cut into tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum TilingScheme {
    /// EPSG:4326, two roots.
    #[default]
    Geographic,
    /// EPSG:3857, one root.
    WebMercator,
    /// The geographic grid reduced towards the poles (the engine's tiles; see the module
    /// documentation). Never a data pyramid's scheme: it is not parsed from names.
    GeographicReduced,
}

/// The children of a tile: four, or three where the tile's poleward row stays whole in a
/// reduced scheme. North row first, each row west to east.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Children {
    keys: [TileKey; 4],
    len: u8,
}

impl Children {
    /// The children as a slice.
    pub fn as_slice(&self) -> &[TileKey] {
        &self.keys[..usize::from(self.len)]
    }

    /// How many there are (0 at the deepest level).
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether there are none (the deepest level).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Where `key` is among them.
    pub fn position(&self, key: TileKey) -> Option<usize> {
        self.as_slice().iter().position(|k| *k == key)
    }
}

impl std::ops::Deref for Children {
    type Target = [TileKey];
    fn deref(&self) -> &[TileKey] {
        self.as_slice()
    }
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
            TilingScheme::Geographic | TilingScheme::GeographicReduced => &GEOGRAPHIC_ROOTS,
            TilingScheme::WebMercator => &MERCATOR_ROOTS,
        }
    }

    /// The number of columns at `level` (of the unreduced grid).
    pub fn tiles_x(self, level: u8) -> u64 {
        match self {
            TilingScheme::Geographic | TilingScheme::GeographicReduced => 2u64 << level,
            TilingScheme::WebMercator => 1u64 << level,
        }
    }

    /// How many columns of the grid a tile in row `y` at `level` spans: 1 but in a reduced
    /// scheme near the poles (see the module documentation).
    pub fn columns(self, level: u8, y: u32) -> u32 {
        if self != TilingScheme::GeographicReduced || level < 2 {
            return 1;
        }
        let ny = 1u64 << level;
        // Rows from the nearer pole (0: the polar row), so both hemispheres agree exactly.
        let from_pole = u64::from(y).min(ny.saturating_sub(1 + u64::from(y)));
        let equator_edge = FRAC_PI_2 - PI * (from_pole + 1) as f64 / ny as f64;
        let cos = equator_edge.cos();
        let mut k = 0u32;
        // The next power still keeps the width at most MAX_ASPECT heights.
        while k < u32::from(level) && f64::from(2u32 << k) * cos <= MAX_ASPECT {
            k += 1;
        }
        1 << k
    }

    /// The key of the tile containing column `x` of row `y` at `level` (`x` rounded down to
    /// the tile's first column).
    fn aligned(self, level: u8, x: u32, y: u32) -> TileKey {
        let m = self.columns(level, y);
        TileKey::pack_unchecked(level, x / m * m, y)
    }

    /// The tile one level up containing `key`; `None` for a root.
    pub fn parent(self, key: TileKey) -> Option<TileKey> {
        let level = key.level().checked_sub(1)?;
        Some(self.aligned(level, key.x() >> 1, key.y() >> 1))
    }

    /// The ancestor of `key` at `level` (itself at its own level); `None` if deeper.
    pub fn ancestor_at(self, key: TileKey, level: u8) -> Option<TileKey> {
        let own = key.level();
        if level > own {
            return None;
        }
        let shift = own - level;
        Some(self.aligned(level, key.x() >> shift, key.y() >> shift))
    }

    /// Whether `ancestor` is `key` or one of its ancestors.
    pub fn contains(self, ancestor: TileKey, key: TileKey) -> bool {
        self.ancestor_at(key, ancestor.level()) == Some(ancestor)
    }

    /// The children of `key` (none at [`TileKey::MAX_LEVEL`]).
    pub fn children(self, key: TileKey) -> Children {
        let mut out = Children {
            keys: [key; 4],
            len: 0,
        };
        let level = key.level();
        if level >= TileKey::MAX_LEVEL {
            return out;
        }
        let (l, span) = (level + 1, 2 * self.columns(level, key.y()));
        for y in [2 * key.y(), 2 * key.y() + 1] {
            let step = self.columns(l, y).min(span);
            let mut x = 2 * key.x();
            while x < 2 * key.x() + span {
                out.keys[usize::from(out.len)] = TileKey::pack_unchecked(l, x, y);
                out.len += 1;
                x += step;
            }
        }
        out
    }

    /// The number of rows at `level`.
    pub fn tiles_y(self, level: u8) -> u64 {
        1u64 << level
    }

    /// Whether the key names a tile of this scheme.
    pub fn is_valid(self, key: TileKey) -> bool {
        u64::from(key.x()) < self.tiles_x(key.level())
            && u64::from(key.y()) < self.tiles_y(key.level())
            && key.x().is_multiple_of(self.columns(key.level(), key.y()))
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
        let m = self.columns(level, key.y());
        let west = -PI + 2.0 * PI * f64::from(key.x()) / nx;
        let east = -PI + 2.0 * PI * f64::from(key.x() + m) / nx;
        let (north, south) = match self {
            TilingScheme::Geographic | TilingScheme::GeographicReduced => (
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
            TilingScheme::Geographic | TilingScheme::GeographicReduced => {
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
        TileKey::try_new(level, x as u32, y as u32).map(|k| self.aligned(level, k.x(), k.y()))
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
        if matches!(
            self,
            TilingScheme::Geographic | TilingScheme::GeographicReduced
        ) {
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
        if matches!(
            self,
            TilingScheme::Geographic | TilingScheme::GeographicReduced
        ) {
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
            TilingScheme::GeographicReduced => "geographic-reduced",
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

    const REDUCED: TilingScheme = TilingScheme::GeographicReduced;

    /// Every tile of every level down to 11: its children (three or four) tile it exactly and
    /// name it their parent; it spans a power of two of columns that keeps its width at its
    /// equatorward edge 0.8 to 1.6 times its height.
    #[test]
    fn the_reduced_tree_nests_and_keeps_tiles_about_square() {
        let mut counts = Vec::new();
        let mut level_keys = REDUCED.roots().to_vec();
        for level in 0..=10u8 {
            counts.push(level_keys.len());
            let mut next = Vec::new();
            for &key in &level_keys {
                assert!(REDUCED.is_valid(key), "{key:?}");
                let m = REDUCED.columns(level, key.y());
                assert!(m.is_power_of_two() && u64::from(m) <= REDUCED.tiles_x(level));
                let r = REDUCED.rect(key);
                let equatorward = r.north.abs().min(r.south.abs());
                let equatorward = if r.north > 0.0 && r.south < 0.0 {
                    0.0
                } else {
                    equatorward
                };
                let aspect = r.width() * equatorward.cos() / r.height();
                if level >= 2 {
                    assert!((0.79..=1.601).contains(&aspect), "{key:?}: {aspect}");
                }
                let children = REDUCED.children(key);
                assert!((3..=4).contains(&children.len()), "{key:?}: {children:?}");
                let mut area = 0.0;
                for &c in children.iter() {
                    assert_eq!(REDUCED.parent(c), Some(key), "{c:?}");
                    assert!(REDUCED.contains(key, c));
                    let cr = REDUCED.rect(c);
                    assert!(
                        cr.west >= r.west - 1e-12 && cr.east <= r.east + 1e-12,
                        "{c:?}"
                    );
                    assert!(cr.south >= r.south - 1e-12 && cr.north <= r.north + 1e-12);
                    area += cr.width() * (cr.north.sin() - cr.south.sin());
                }
                let own = r.width() * (r.north.sin() - r.south.sin());
                assert!((area / own - 1.0).abs() < 1e-9, "{key:?}: {area} of {own}");
                next.extend(children.iter().copied());
            }
            level_keys = next;
        }
        // The plain grid has 2 * 4^L tiles; the reduced one about 2/pi of that (a tile per
        // unit of area instead of per unit of latitude and longitude), never fewer.
        let ratio = counts[10] as f64 / (2.0 * 4f64.powi(10));
        assert!((0.58..0.70).contains(&ratio), "{ratio} ({counts:?})");
    }

    /// A point lies in the tile `tile_at` names, at every level, in every row, including the
    /// poles and the antimeridian; keys of unaligned columns are not tiles.
    #[test]
    fn reduced_tiles_are_found_by_position() {
        for level in 0..=20u8 {
            for (lon, lat) in [
                (0.0, 0.0),
                (179.9999, 89.9999),
                (-180.0, -90.0),
                (180.0, 90.0),
                (12.3, 88.7),
                (-77.0, -89.2),
                (45.0, 60.0),
            ] {
                let (lon, lat) = (f64::to_radians(lon), f64::to_radians(lat));
                let key = REDUCED.tile_at(lon, lat, level).expect("a tile");
                assert!(REDUCED.is_valid(key), "{key:?}");
                let r = REDUCED.rect(key);
                assert!(r.contains(lon.clamp(-PI, PI), lat), "{key:?} {r:?}");
                assert_eq!(REDUCED.ancestor_at(key, 0), REDUCED.tile_at(lon, lat, 0));
            }
        }
        let polar = REDUCED.tile_at(0.1, 1.56, 10).expect("a tile");
        let m = REDUCED.columns(10, polar.y());
        assert!(m > 1);
        assert!(!REDUCED.is_valid(TileKey::new(10, polar.x() + 1, polar.y())));
        // Symmetric hemispheres.
        for level in 0..=20u8 {
            for y in [0u32, 1, 2, 5] {
                let ny = 1u32 << level;
                if y < ny {
                    assert_eq!(
                        REDUCED.columns(level, y),
                        REDUCED.columns(level, ny - 1 - y)
                    );
                }
            }
        }
    }

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
