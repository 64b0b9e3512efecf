//! An in-memory tile oracle for selection tests.

use std::cell::RefCell;

use globus_geo::Ellipsoid;
use globus_tiling::{TileBounds, TileInfo, TileKey, TileOracle, TileState, TilingScheme};
use rustc_hash::FxHashMap;

/// Which tiles count as loaded.
#[derive(Clone, Debug)]
pub enum LoadRule {
    /// Every tile.
    All,
    /// Tiles up to and including this level.
    UpToLevel(u8),
    /// Roots always; other tiles by a hash of the key, with this probability (0..1), and a
    /// seed so different test cases see different patterns.
    Random {
        /// Probability of a non-root tile being loaded.
        probability: f64,
        /// Varies the pattern.
        seed: u64,
    },
}

/// A tile oracle with bounds from the rectangle and a height range, a geometric error that
/// halves per level (optionally varied per tile), and load states from a [`LoadRule`].
pub struct MemoryOracle {
    /// Tiling scheme.
    pub scheme: TilingScheme,
    /// The planet.
    pub ellipsoid: Ellipsoid,
    /// The horizon occluder.
    pub occluder: Ellipsoid,
    /// Lowest and highest terrain height, metres.
    pub height_range_m: (f64, f64),
    /// Geometric error of level-0 tiles, metres; halves per level.
    pub root_error_m: f64,
    /// Multiply each tile's error by a factor in [1 - v, 1 + v] from a hash of its key.
    pub error_variation: f64,
    /// Tiles at this level have no children.
    pub leaf_level: u8,
    /// Load states.
    pub load: LoadRule,
    /// Tiles with no data (and their descendants).
    pub no_data: Vec<TileKey>,
    /// Tiles not loaded whatever `load` says (and their descendants).
    pub unloaded: Vec<TileKey>,
    cache: RefCell<FxHashMap<TileKey, TileBounds>>,
}

impl MemoryOracle {
    /// A WGS84 geographic oracle with every tile loaded.
    pub fn new(scheme: TilingScheme) -> Self {
        Self {
            scheme,
            ellipsoid: Ellipsoid::WGS84,
            occluder: Ellipsoid::WGS84,
            height_range_m: (0.0, 9000.0),
            root_error_m: 200_000.0,
            error_variation: 0.0,
            leaf_level: 22,
            load: LoadRule::All,
            no_data: Vec::new(),
            unloaded: Vec::new(),
            cache: RefCell::new(FxHashMap::default()),
        }
    }

    /// Whether the rule marks `key` loaded.
    pub fn is_loaded(&self, key: TileKey) -> bool {
        if self.unloaded.iter().any(|u| self.scheme.contains(*u, key)) {
            return false;
        }
        match self.load {
            LoadRule::All => true,
            LoadRule::UpToLevel(l) => key.level() <= l,
            LoadRule::Random { probability, seed } => {
                key.level() == 0 || unit_hash(key, seed) < probability
            }
        }
    }

    /// The geometric error the oracle reports for `key`.
    pub fn error_of(&self, key: TileKey) -> f64 {
        let v = self.error_variation * (2.0 * unit_hash(key, 0x5eed) - 1.0);
        self.root_error_m * (1.0 + v) / f64::from(1u32 << key.level().min(31))
    }

    /// The bounds the oracle reports for `key`.
    pub fn bounds_of(&self, key: TileKey) -> TileBounds {
        if let Some(b) = self.cache.borrow().get(&key) {
            return *b;
        }
        let b = TileBounds::from_rect(
            &self.ellipsoid,
            &self.occluder,
            &self.scheme.rect(key),
            self.height_range_m.0,
            self.height_range_m.1,
        );
        self.cache.borrow_mut().insert(key, b);
        b
    }
}

impl TileOracle for MemoryOracle {
    fn scheme(&self) -> TilingScheme {
        self.scheme
    }

    fn tile(&self, key: TileKey) -> TileInfo {
        let state = if self.no_data.iter().any(|n| self.scheme.contains(*n, key)) {
            TileState::NoData
        } else if self.is_loaded(key) {
            TileState::Loaded
        } else {
            TileState::Unloaded
        };
        TileInfo {
            bounds: self.bounds_of(key),
            geometric_error_m: self.error_of(key),
            state,
            has_children: key.level() < self.leaf_level,
            children_at: TileInfo::NOWHERE,
        }
    }
}

/// A hash of a key and seed mapped to [0, 1).
fn unit_hash(key: TileKey, seed: u64) -> f64 {
    let mut z = key.to_bits() ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}
