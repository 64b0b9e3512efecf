//! Building a quantized-mesh tile from an [`AdaptiveMesh`] of a tile's height grid.

use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_tiling::{GeoRect, TileBounds, lat_to_mercator_y, mercator_y_to_lat};

use super::{Header, QUANTIZED_MAX, QuantizedMesh, WaterMask, oct_encode_u8};
use crate::adaptive::{AdaptiveMesh, HeightGrid};

/// How grid rows map to latitude inside the tile rectangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileProjection {
    /// Rows are evenly spaced in latitude (geographic tiling, Cesium's default).
    Geographic,
    /// Rows are evenly spaced in Web Mercator y.
    WebMercator,
}

impl TileProjection {
    /// Latitude of the row at fraction `t` from the north edge (0) to the south edge (1).
    pub fn lat_at(self, rect: &GeoRect, t: f64) -> f64 {
        match self {
            Self::Geographic => rect.north + (rect.south - rect.north) * t,
            Self::WebMercator => {
                let (n, s) = (lat_to_mercator_y(rect.north), lat_to_mercator_y(rect.south));
                mercator_y_to_lat(n + (s - n) * t)
            }
        }
    }
}

/// What goes into the tile besides the mesh.
#[derive(Clone, Debug, Default)]
pub struct QuantizedMeshOptions {
    /// Write oct-encoded vertex normals (extension 1).
    pub normals: bool,
    /// Write this water mask (extension 2).
    pub water_mask: Option<WaterMask>,
    /// Write this JSON metadata (extension 4).
    pub metadata: Option<String>,
    /// Heights just outside the grid, from the neighbouring tiles, for the normals.
    pub border: BorderRing,
}

/// The heights one sample outside a tile's grid on each side, taken from the neighbouring
/// tiles (which share the tile's edge samples): with them the normals on the tile's edges
/// are central differences over the same samples the neighbour uses, so both tiles shade a
/// shared edge alike. A side without a neighbour (`None`, or the wrong length) falls back to
/// one-sided differences.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BorderRing {
    /// The row north of the grid, west to east (`side` samples).
    pub north: Option<Vec<f32>>,
    /// The row south of the grid, west to east.
    pub south: Option<Vec<f32>>,
    /// The column west of the grid, north to south.
    pub west: Option<Vec<f32>>,
    /// The column east of the grid, north to south.
    pub east: Option<Vec<f32>>,
}

impl BorderRing {
    /// The ring's height at grid position (x, y) just outside the grid, if known.
    fn at(&self, side: usize, x: i64, y: i64) -> Option<f32> {
        let n = side as i64;
        let inside = |v: i64| (0..n).contains(&v);
        let (row, i) = if y == -1 && inside(x) {
            (&self.north, x)
        } else if y == n && inside(x) {
            (&self.south, x)
        } else if x == -1 && inside(y) {
            (&self.west, y)
        } else if x == n && inside(y) {
            (&self.east, y)
        } else {
            return None;
        };
        row.as_ref()
            .filter(|r| r.len() == side)
            .map(|r| r[i as usize])
    }
}

/// Quantizes `mesh` over `grid`, placed on `rect` of `ellipsoid`. Normals come from the grid
/// by central differences, on the tile's edges over `options.border` where it is known and
/// one-sided where not.
pub fn from_adaptive_mesh(
    mesh: &AdaptiveMesh,
    grid: &HeightGrid,
    rect: &GeoRect,
    projection: TileProjection,
    ellipsoid: &Ellipsoid,
    options: &QuantizedMeshOptions,
) -> QuantizedMesh {
    let n = (grid.side() - 1) as f64;
    let place = |x: f64, y: f64, h: f32| {
        let lon = rect.west + rect.width() * x / n;
        let lat = projection.lat_at(rect, y / n);
        ellipsoid.cartographic_to_ecef(Cartographic::new(lon, lat, f64::from(h)))
    };
    let position = |x: usize, y: usize| place(x as f64, y as f64, grid.at(x, y));
    // A grid or ring sample next to (x, y), or (x, y) itself where neither is known.
    let beside = |x: usize, y: usize, dx: i64, dy: i64| {
        let (bx, by) = (x as i64 + dx, y as i64 + dy);
        let last = grid.side() as i64 - 1;
        if (0..=last).contains(&bx) && (0..=last).contains(&by) {
            position(bx as usize, by as usize)
        } else {
            match options.border.at(grid.side(), bx, by) {
                Some(h) => place(bx as f64, by as f64, h),
                None => position(x, y),
            }
        }
    };
    let heights: Vec<f32> = mesh
        .vertices
        .iter()
        .map(|&[x, y]| grid.at(usize::from(x), usize::from(y)))
        .collect();
    let lo = heights.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = heights.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
    let points: Vec<DVec3> = mesh
        .vertices
        .iter()
        .map(|&[x, y]| position(usize::from(x), usize::from(y)))
        .collect();
    let bounds = TileBounds::from_points(ellipsoid, ellipsoid, rect, &points)
        .unwrap_or_else(|| TileBounds::from_rect(ellipsoid, ellipsoid, rect, 0.0, 0.0));
    let header = Header {
        centre: bounds.obb.centre,
        min_height_m: lo,
        max_height_m: hi,
        sphere_centre: bounds.sphere.centre,
        sphere_radius_m: bounds.sphere.radius,
        horizon_occlusion_point: bounds.horizon_point.unwrap_or(DVec3::ZERO),
    };
    let q = |f: f64| (f * f64::from(QUANTIZED_MAX)).round() as u16;
    let range = f64::from(hi) - f64::from(lo);
    let height = heights
        .iter()
        .map(|&h| {
            if range > 0.0 {
                q((f64::from(h) - f64::from(lo)) / range)
            } else {
                0
            }
        })
        .collect();
    let normals = options.normals.then(|| {
        mesh.vertices
            .iter()
            .map(|&[x, y]| {
                let (x, y) = (usize::from(x), usize::from(y));
                let east = beside(x, y, 1, 0) - beside(x, y, -1, 0);
                let north = beside(x, y, 0, -1) - beside(x, y, 0, 1);
                let up = ellipsoid
                    .geodetic_normal(position(x, y))
                    .unwrap_or(DVec3::Z);
                let normal = east.cross(north).try_normalize().unwrap_or(up);
                oct_encode_u8(normal)
            })
            .collect()
    });
    let [north, east, south, west] = mesh.edge_vertices();
    QuantizedMesh {
        header,
        u: mesh
            .vertices
            .iter()
            .map(|&[x, _]| q(f64::from(x) / n))
            .collect(),
        v: mesh
            .vertices
            .iter()
            .map(|&[_, y]| q(1.0 - f64::from(y) / n))
            .collect(),
        height,
        indices: mesh.triangles.as_flattened().to_vec(),
        west,
        south,
        east,
        north,
        normals,
        water_mask: options.water_mask.clone(),
        metadata: options.metadata.clone(),
    }
}
