//! The procedural planet as a [`TileSource`].

use globus_geo::Ellipsoid;
use globus_terrain::{MeshOptions, ProceduralPlanet, TerrainTile};
use globus_tiling::{GLOBE_SCHEME, TileKey, TilingScheme};

use crate::fetch::Cancel;
use crate::{SourceError, TerrainData, TerrainSource, TileSource};

/// Generates terrain tiles of a [`ProceduralPlanet`] (geographic scheme).
pub struct ProceduralSource {
    planet: ProceduralPlanet,
    occluder: Ellipsoid,
    max_level: u8,
    name: String,
    mesh_options: MeshOptions,
}

impl ProceduralSource {
    /// The planet of `seed` on WGS84, with tiles down to `max_level`.
    pub fn new(seed: u64, max_level: u8) -> Self {
        Self::on(ProceduralPlanet::new(seed), max_level)
    }

    /// The planet of `seed` on any body, with tiles down to `max_level`.
    pub fn with_ellipsoid(seed: u64, ellipsoid: Ellipsoid, max_level: u8) -> Self {
        Self::on(ProceduralPlanet::with_ellipsoid(seed, ellipsoid), max_level)
    }

    fn on(planet: ProceduralPlanet, max_level: u8) -> Self {
        let mesh_options = MeshOptions::default();
        Self {
            occluder: occluder_of(&planet, &mesh_options),
            name: format!("procedural planet (seed {})", planet.seed()),
            planet,
            max_level: max_level.min(globus_tiling::TileKey::MAX_LEVEL),
            mesh_options,
        }
    }

    /// The planet.
    pub fn planet(&self) -> &ProceduralPlanet {
        &self.planet
    }

    /// Builds everything the engine needs from a generated tile.
    pub fn prepare(&self, tile: TerrainTile) -> TerrainData {
        TerrainData {
            generated: true,
            ..TerrainData::build(
                tile,
                self.planet.ellipsoid(),
                &self.occluder,
                &self.mesh_options,
            )
        }
    }

    /// Cuts (and raises) meshes with `options` instead of the default.
    pub fn with_mesh_options(mut self, options: MeshOptions) -> Self {
        self.mesh_options = options;
        self.occluder = occluder_of(&self.planet, &options);
        self
    }
}

/// The body below every drawn point: nothing is lower than the sea surface (raised by the
/// exaggeration, as the meshes are), so the ellipsoid grown to it hides what is behind it.
fn occluder_of(planet: &ProceduralPlanet, options: &MeshOptions) -> Ellipsoid {
    planet
        .ellipsoid()
        .grown(planet.min_surface_height_m() * options.exaggeration)
}

impl TileSource for ProceduralSource {
    type Tile = TerrainData;

    fn name(&self) -> &str {
        &self.name
    }

    fn scheme(&self) -> TilingScheme {
        GLOBE_SCHEME
    }

    fn load(&self, key: TileKey, _cancel: &Cancel) -> Result<Option<TerrainData>, SourceError> {
        if key.level() > self.max_level || !GLOBE_SCHEME.is_valid(key) {
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
        let e = self.mesh_options.exaggeration;
        (
            self.planet.min_surface_height_m() * e,
            self.planet.max_surface_height_m() * e,
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
