//! [`TileBounds`]: everything culling and screen-space error need to know about where a tile
//! is: an oriented box (frustum test, distance), a bounding sphere and a horizon culling point.

use globus_geo::{BoundingSphere, DMat3, DVec3, Ellipsoid, EllipsoidalOccluder, OrientedBox};

use crate::GeoRect;

/// Where a tile's surface lies, in f64 ECEF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileBounds {
    /// A box containing the whole tile (including skirts).
    pub obb: OrientedBox,
    /// A sphere containing the box.
    pub sphere: BoundingSphere,
    /// The horizon culling point in the scaled space of the occluder ellipsoid (see
    /// [`EllipsoidalOccluder`]); `None` if the tile is too large to be horizon-culled.
    pub horizon_point: Option<DVec3>,
}

/// Samples per rectangle edge when bounding a rectangle without its data.
const RECT_SAMPLES: usize = 9;

impl TileBounds {
    /// Bounds of the surface points of a tile, with the box axes aligned to east-north-up at
    /// the rectangle's centre. `occluder` is the ellipsoid used for horizon culling.
    /// `None` for an empty point set.
    pub fn from_points(
        ellipsoid: &Ellipsoid,
        occluder: &Ellipsoid,
        rect: &GeoRect,
        points: &[DVec3],
    ) -> Option<Self> {
        let (lon, lat) = rect.centre();
        let axes = ellipsoid.enu_frame(lon, lat).world_from_local();
        let obb = OrientedBox::from_points_with_axes(axes, points.iter().copied())?;
        let centre_dir = ellipsoid.geodetic_normal_from_lon_lat(lon, lat);
        let horizon_point = EllipsoidalOccluder::horizon_culling_point(
            occluder,
            centre_dir,
            points.iter().copied(),
        );
        Some(Self {
            obb,
            sphere: obb.bounding_sphere(),
            horizon_point,
        })
    }

    /// Conservative bounds of everything between heights `min_height_m` and `max_height_m`
    /// over a rectangle, for tiles whose data is not loaded yet.
    ///
    /// The rectangle is sampled on a grid and the box grown by the largest bulge of the
    /// ellipsoid between samples, so it contains the curved surface and not only the samples.
    pub fn from_rect(
        ellipsoid: &Ellipsoid,
        occluder: &Ellipsoid,
        rect: &GeoRect,
        min_height_m: f64,
        max_height_m: f64,
    ) -> Self {
        let mut points = Vec::with_capacity(RECT_SAMPLES * RECT_SAMPLES * 2);
        let n = RECT_SAMPLES - 1;
        for j in 0..=n {
            for i in 0..=n {
                let (lon, lat) = rect.lon_lat_at(i as f64 / n as f64, j as f64 / n as f64);
                for h in [min_height_m, max_height_m] {
                    points.push(
                        ellipsoid.cartographic_to_ecef(globus_geo::Cartographic::new(lon, lat, h)),
                    );
                }
            }
        }
        let (lon, lat) = rect.centre();
        let axes: DMat3 = ellipsoid.enu_frame(lon, lat).world_from_local();
        // The ellipsoid bulges between samples by at most r (1 - cos(step / 2)) for the
        // largest radius of curvature r (a^2 / b on an ellipsoid of revolution).
        let step = rect.width().max(rect.height()) / n as f64;
        let a = ellipsoid.maximum_radius() + max_height_m.max(0.0);
        let r = a * a / ellipsoid.minimum_radius();
        let bulge = r * (1.0 - (step * 0.5).cos());
        let obb = OrientedBox::from_points_with_axes(axes, points.iter().copied())
            .unwrap_or(OrientedBox::new(DVec3::ZERO, axes, DVec3::ZERO))
            .grown(bulge);
        let centre_dir = ellipsoid.geodetic_normal_from_lon_lat(lon, lat);
        let horizon_point =
            EllipsoidalOccluder::horizon_culling_point(occluder, centre_dir, obb.corners());
        Self {
            obb,
            sphere: obb.bounding_sphere(),
            horizon_point,
        }
    }
}
