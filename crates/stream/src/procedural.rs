//! The procedural planet as a [`TileSource`].

use globus_geo::Ellipsoid;
use globus_terrain::grid::MESH_SEGMENTS;
use globus_terrain::{ProceduralPlanet, TerrainTile, TileMesh};
use globus_tiling::{TileBounds, TileKey, TilingScheme};

use crate::{SourceError, TerrainData, TerrainSource, TileSource};

/// Generates terrain tiles of a [`ProceduralPlanet`] (geographic scheme).
pub struct ProceduralSource {
    planet: ProceduralPlanet,
    occluder: Ellipsoid,
    max_level: u8,
    name: String,
}

impl ProceduralSource {
    /// The planet of `seed` on WGS84, with tiles down to `max_level`.
    pub fn new(seed: u64, max_level: u8) -> Self {
        let planet = ProceduralPlanet::new(seed);
        // Nothing is lower than the sea surface, so the ellipsoid itself hides what is behind it.
        let occluder = planet.ellipsoid().grown(planet.min_surface_height_m());
        Self {
            planet,
            occluder,
            max_level: max_level.min(globus_tiling::TileKey::MAX_LEVEL),
            name: format!("procedural planet (seed {seed})"),
        }
    }

    /// The planet.
    pub fn planet(&self) -> &ProceduralPlanet {
        &self.planet
    }

    /// Builds everything the engine needs from a generated tile.
    pub fn prepare(&self, tile: TerrainTile) -> TerrainData {
        let ellipsoid = self.planet.ellipsoid();
        let mesh = TileMesh::build(&tile, ellipsoid, &self.occluder);
        let child_bounds = child_bounds(&tile, ellipsoid, &self.occluder);
        TerrainData {
            tile,
            mesh,
            child_bounds,
        }
    }
}

/// Conservative bounds of the four children from the parent's heights in each quadrant:
/// children stay within the parent's geometric error of its mesh, and their skirts hang a
/// few errors lower.
pub fn child_bounds(
    tile: &TerrainTile,
    ellipsoid: &Ellipsoid,
    occluder: &Ellipsoid,
) -> [TileBounds; 4] {
    let half = (MESH_SEGMENTS / 2) as i32;
    let Some(children) = tile.key.children() else {
        let b = TileBounds::from_rect(
            ellipsoid,
            occluder,
            &tile.rect,
            tile.min_height_m,
            tile.max_height_m,
        );
        return [b; 4];
    };
    let spacing_m = tile.rect.height() / f64::from(MESH_SEGMENTS) * ellipsoid.mean_radius();
    children.map(|child| {
        let (qx, qy) = ((child.x() & 1) as i32, (child.y() & 1) as i32);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for j in qy * half..=(qy + 1) * half {
            for i in qx * half..=(qx + 1) * half {
                let h = f64::from(tile.height_at(i, j));
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        let margin = tile.geometric_error_m;
        let skirt = 4.0 * tile.geometric_error_m + 0.02 * spacing_m;
        let rect = TilingScheme::Geographic.rect(child);
        TileBounds::from_rect(ellipsoid, occluder, &rect, lo - margin - skirt, hi + margin)
    })
}

impl TileSource for ProceduralSource {
    type Tile = TerrainData;

    fn name(&self) -> &str {
        &self.name
    }

    fn scheme(&self) -> TilingScheme {
        TilingScheme::Geographic
    }

    fn load(&self, key: TileKey) -> Result<Option<TerrainData>, SourceError> {
        if key.level() > self.max_level || !TilingScheme::Geographic.is_valid(key) {
            return Ok(None);
        }
        Ok(Some(self.prepare(self.planet.generate_tile(key))))
    }

    fn byte_size(&self, tile: &TerrainData) -> usize {
        tile.byte_size()
    }
}

impl TerrainSource for ProceduralSource {
    fn ellipsoid(&self) -> &Ellipsoid {
        self.planet.ellipsoid()
    }

    fn occluder(&self) -> &Ellipsoid {
        &self.occluder
    }

    fn height_range_m(&self) -> (f64, f64) {
        (
            self.planet.min_surface_height_m(),
            self.planet.max_surface_height_m(),
        )
    }

    fn max_level(&self) -> u8 {
        self.max_level
    }

    fn height_at(&self, lon_rad: f64, lat_rad: f64) -> Option<f64> {
        let p = self
            .planet
            .ellipsoid()
            .cartographic_to_ecef(globus_geo::Cartographic::new(lon_rad, lat_rad, 0.0));
        Some(
            self.planet
                .height_m(p, FINEST_QUERY_WAVELENGTH_M)
                .max(self.planet.min_surface_height_m()),
        )
    }
}

/// Height queries include every octave down to this wavelength (the planet's finest).
const FINEST_QUERY_WAVELENGTH_M: f64 = 0.05;
