//! `globus-geo`: the f64 geometry everything on the planet is built from.
//!
//! * [`Ellipsoid`]: a body (WGS84 by default, any other as a value) with conversions between
//!   [`Cartographic`] (longitude, latitude, height) and ECEF, geodetic normals, east-north-up
//!   frames, ray intersection and great-circle distance.
//! * [`BoundingSphere`] and [`OrientedBox`]: bounding volumes of tiles.
//! * [`View`] and [`Frustum`]: a camera in f64 ECEF (perspective or orthographic) and the
//!   planes of what it sees.
//! * [`EllipsoidalOccluder`]: horizon culling (Cesium's ellipsoid-scaled occluder point).
//! * [`Atmosphere`]: a body's air (Hillaire 2020's model) and the tables the GPU reads.
//! * [`SunPosition`]: where the Sun is at a moment (Meeus/NOAA, checked against NREL's SPA).
//!
//! Everything is in metres and radians, f64, in Earth-centred Earth-fixed (ECEF) coordinates
//! unless the name says otherwise. The only dependency is `glam`.

mod atmosphere;
mod bounds;
mod cartographic;
mod ellipsoid;
mod frustum;
mod horizon;
mod sun;
mod view;

pub use atmosphere::{
    Atmosphere, AtmosphereTables, LutGeometry, MULTIPLE_SCATTERING_SIZE, MultipleScatteringLut,
    SKY_IRRADIANCE_MIN_MU, SKY_IRRADIANCE_SIZE, TRANSMITTANCE_SIZE, TransmittanceLut,
    cornette_shanks, sky_irradiance_mu,
};
pub use bounds::{BoundingSphere, OrientedBox};
pub use cartographic::Cartographic;
pub use ellipsoid::{Ellipsoid, EnuFrame};
pub use frustum::{Frustum, Intersection, Plane};
pub use glam::{DMat3, DMat4, DQuat, DVec2, DVec3, DVec4};
pub use horizon::EllipsoidalOccluder;
pub use sun::SunPosition;
pub use view::{Projection, View};
