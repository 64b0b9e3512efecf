//! [`Feature`]: one GeoJSON feature checked and styled, its geometry split into points,
//! lines and polygons (a GeometryCollection contributes all its members).

use serde_json::{Map, Value};

use crate::shape::{self, Position};
use crate::style::{Style, StyleRules};

/// A feature ready to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct Feature {
    /// Its index in its file.
    pub index: usize,
    /// Its properties (printed when it is picked).
    pub properties: Map<String, Value>,
    /// How it is drawn.
    pub style: Style,
    /// Points (and the members of MultiPoints).
    pub points: Vec<Position>,
    /// Lines: consecutive duplicates dropped, longitudes unwrapped, not yet densified.
    pub lines: Vec<Vec<Position>>,
    /// Polygons: exterior ring then holes, each checked by [`shape::ring`].
    pub polygons: Vec<Vec<Vec<Position>>>,
}

impl Feature {
    /// Whether nothing is left to draw.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty() && self.lines.is_empty() && self.polygons.is_empty()
    }

    /// Positions in all its geometry.
    pub fn position_count(&self) -> usize {
        self.points.len()
            + self.lines.iter().map(Vec::len).sum::<usize>()
            + self
                .polygons
                .iter()
                .flat_map(|p| p.iter().map(Vec::len))
                .sum::<usize>()
    }
}

/// Checks and styles a GeoJSON feature. Every problem is pushed to `warnings`; a part that
/// is bad (a ring, a line, a point) is left out, and a feature with nothing left is `None`.
pub fn from_geojson(
    index: usize,
    feature: geojson::Feature,
    rules: &StyleRules,
    warnings: &mut Vec<String>,
) -> Option<Feature> {
    let properties = feature.properties.unwrap_or_default();
    let style = rules.resolve(&properties, warnings);
    let mut out = Feature {
        index,
        properties,
        style,
        points: Vec::new(),
        lines: Vec::new(),
        polygons: Vec::new(),
    };
    let Some(geometry) = feature.geometry else {
        warnings.push("no geometry".to_owned());
        return None;
    };
    add_geometry(&mut out, geometry.value, warnings, 0);
    if out.is_empty() {
        if warnings.is_empty() {
            warnings.push("empty geometry".to_owned());
        }
        return None;
    }
    Some(out)
}

/// Deepest nesting of GeometryCollections followed.
const MAX_NESTING: u32 = 8;

fn add_geometry(out: &mut Feature, value: geojson::Value, warnings: &mut Vec<String>, depth: u32) {
    use geojson::Value as G;
    match value {
        G::Point(p) => match shape::position(&p) {
            Ok(p) => out.points.push(p),
            Err(e) => warnings.push(e.to_string()),
        },
        G::MultiPoint(ps) => {
            for p in ps {
                add_geometry(out, G::Point(p), warnings, depth);
            }
        }
        G::LineString(l) => match shape::line(&l) {
            Ok(l) => out.lines.push(l),
            Err(e) => warnings.push(e.to_string()),
        },
        G::MultiLineString(ls) => {
            for l in ls {
                add_geometry(out, G::LineString(l), warnings, depth);
            }
        }
        G::Polygon(rings) => {
            let mut checked = Vec::with_capacity(rings.len());
            for (k, r) in rings.iter().enumerate() {
                match shape::ring(r) {
                    Ok(r) => {
                        if shape::self_intersects(&r) {
                            warnings.push(format!(
                                "ring {k} crosses itself (drawn as triangulated, may show gaps)"
                            ));
                        }
                        checked.push(r);
                    }
                    Err(e) if k == 0 => {
                        warnings.push(format!("exterior ring: {e}"));
                        return;
                    }
                    Err(e) => warnings.push(format!("hole {k} left out: {e}")),
                }
            }
            if !checked.is_empty() {
                out.polygons.push(checked);
            }
        }
        G::MultiPolygon(ps) => {
            for p in ps {
                add_geometry(out, G::Polygon(p), warnings, depth);
            }
        }
        G::GeometryCollection(gs) => {
            if depth >= MAX_NESTING {
                warnings.push("geometry collections nested too deep".to_owned());
                return;
            }
            for g in gs {
                add_geometry(out, g.value, warnings, depth + 1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feature(json: &str) -> geojson::Feature {
        json.parse::<geojson::GeoJson>()
            .ok()
            .and_then(|g| geojson::Feature::try_from(g).ok())
            .expect("test feature")
    }

    #[test]
    fn bad_parts_are_left_out_with_a_warning_each() {
        let f = feature(
            r#"{"type": "Feature", "properties": {"name": "x"}, "geometry": {"type": "GeometryCollection", "geometries": [
                {"type": "Point", "coordinates": [1, 2]},
                {"type": "Point", "coordinates": [1, 200]},
                {"type": "LineString", "coordinates": [[1, 2], [1, 2]]},
                {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]], [[0.1, 0.1], [0.2, 0.1], [0.2, 0.2]]]}
            ]}}"#,
        );
        let mut w = Vec::new();
        let f = from_geojson(3, f, &StyleRules::default(), &mut w).expect("something is left");
        assert_eq!(f.points.len(), 1);
        assert!(f.lines.is_empty());
        assert_eq!(f.polygons.len(), 1);
        assert_eq!(f.polygons[0].len(), 1, "the unclosed hole is left out");
        assert_eq!(w.len(), 3, "{w:?}");
    }

    #[test]
    fn a_feature_with_nothing_left_is_none() {
        let f = feature(
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [200, 0]}}"#,
        );
        let mut w = Vec::new();
        assert!(from_geojson(0, f, &StyleRules::default(), &mut w).is_none());
        assert_eq!(w.len(), 1);
        let f = feature(r#"{"type": "Feature", "properties": {}, "geometry": null}"#);
        assert!(from_geojson(0, f, &StyleRules::default(), &mut w).is_none());
    }
}
