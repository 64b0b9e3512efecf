//! How a feature is drawn: the simplestyle properties (`stroke`, `stroke-width`,
//! `stroke-opacity`, `fill`, `fill-opacity`, `marker-color`, `marker-size`, `marker-symbol`;
//! mapbox/simplestyle-spec 1.1.0) plus Globus's own: `extrude`, `lower`, `upper` (vertical
//! limits with units `m`, `ft` or `FL`), `clamp` (`ground` drapes, `absolute` keeps the
//! coordinates' third value as metres above the ellipsoid, `relative` above the ground),
//! `path` (`geodesic` or `rhumb`) and `marker-outline`, and SVG's `stroke-linejoin` (`round`,
//! `miter`, `bevel`), `stroke-linecap` (`round`, `butt`, `square`) and `stroke-dasharray`
//! (dash and gap lengths in pixels, e.g. `"8 4"` or `[8, 4, 2, 4]`).
//! Points can carry a name: `label` is its text, with `{property}` replaced by the feature's
//! property of that name (MapLibre's token form, e.g. `{name}`), `label-size` its height in
//! pixels (default 12) and `label-color` its colour (default: the marker's, lightened).
//!
//! Each value is looked up, in order, in the layer's overrides (`--vector FILE#key=value`),
//! the feature's properties, the layer's defaults (config file), and the built-in defaults
//! (simplestyle's, but for lines, which default to 2 px: a 1 px hairline vanishes on a
//! high-DPI screen). A value that does not parse is a warning for that feature and falls back
//! to the next source.

use serde_json::{Map, Value};

/// An sRGB colour with straight (not premultiplied) alpha.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rgba(pub [u8; 4]);

impl Rgba {
    /// Parses `#rgb`, `#rrggbb` or `#rrggbbaa` (the `#` optional, as simplestyle allows).
    pub fn parse(text: &str) -> Option<Self> {
        let hex = text.trim().strip_prefix('#').unwrap_or(text.trim());
        let digit = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
        let b = hex.as_bytes();
        let pair = |i: usize| Some(digit(b[i])? * 16 + digit(b[i + 1])?);
        match b.len() {
            3 => Some(Self([
                digit(b[0])? * 17,
                digit(b[1])? * 17,
                digit(b[2])? * 17,
                255,
            ])),
            6 => Some(Self([pair(0)?, pair(2)?, pair(4)?, 255])),
            8 => Some(Self([pair(0)?, pair(2)?, pair(4)?, pair(6)?])),
            _ => None,
        }
    }

    /// The colour with its alpha multiplied by `opacity` (0..1).
    pub fn with_opacity(self, opacity: f64) -> Self {
        let [r, g, b, a] = self.0;
        let a = (f64::from(a) * opacity.clamp(0.0, 1.0)).round() as u8;
        Self([r, g, b, a])
    }

    /// Packed little-endian RGBA8 (red in the low byte), as shaders unpack it.
    pub fn packed(self) -> u32 {
        u32::from_le_bytes(self.0)
    }
}

/// What a height is measured from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clamp {
    /// On the terrain drawn this frame (draped); any third coordinate is ignored.
    Ground,
    /// Metres above the ellipsoid.
    Absolute,
    /// Metres above the terrain under each vertex.
    Relative,
}

/// How a line runs between two vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// The shortest path on the ellipsoid.
    Geodesic,
    /// Constant bearing (a straight line on a Mercator map).
    Rhumb,
}

/// How a line's segments meet (SVG `stroke-linejoin`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineJoin {
    /// An arc round the joint.
    Round,
    /// The outer edges extended until they meet; beyond twice the half width (a turn
    /// sharper than 120 degrees, MapLibre's miter limit 2) a bevel.
    Miter,
    /// The outer corners joined by a straight edge.
    Bevel,
}

/// How a line's ends are drawn (SVG `stroke-linecap`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineCap {
    /// A half disc beyond the end.
    Round,
    /// Square, at the end.
    Butt,
    /// Square, half the width beyond the end.
    Square,
}

/// Largest number of values in a dash pattern.
pub const MAX_DASHES: usize = 4;

/// A feature's resolved style.
#[derive(Clone, Debug, PartialEq)]
pub struct Style {
    /// Line colour (alpha includes `stroke-opacity`).
    pub stroke: Rgba,
    /// Line width, pixels on screen (0: no outline).
    pub stroke_width_px: f32,
    /// How line segments meet.
    pub line_join: LineJoin,
    /// How lines end.
    pub line_cap: LineCap,
    /// Dash pattern, pixels (dash, gap, dash, gap; an odd list repeated as SVG does); `None`:
    /// solid.
    pub dash_px: Option<[u8; MAX_DASHES]>,
    /// Fill colour (alpha includes `fill-opacity`).
    pub fill: Rgba,
    /// Point symbol colour.
    pub marker_color: Rgba,
    /// Point symbol diameter, pixels.
    pub marker_size_px: f32,
    /// Point symbol shape.
    pub marker_square: bool,
    /// A PNG drawn as the point's symbol (`marker-size` pixels a side), instead of the
    /// circle or square.
    pub marker_icon: Option<String>,
    /// Point outline colour.
    pub marker_outline: Rgba,
    /// The text drawn beside each point (tokens replaced; at most [`MAX_LABEL_CHARS`]
    /// characters), if any.
    pub label: Option<String>,
    /// Label text height, pixels.
    pub label_size_px: f32,
    /// Label colour (`None`: the marker's, lightened).
    pub label_color: Option<Rgba>,
    /// How heights are measured.
    pub clamp: Clamp,
    /// How lines and polygon edges run between vertices.
    pub path: PathKind,
    /// Vertical limits of an extruded polygon (lower, upper), metres in `clamp`'s reference
    /// (`None`: drawn flat).
    pub extrude: Option<(f64, f64)>,
    /// Lines hang a curtain (`fill` colour) from themselves down to the ground.
    pub wall: bool,
    /// Lines are drawn as a tube (`fill` colour) of this horizontal radius and vertical half
    /// height, metres (Kaiser's flight-plan tunnel: 5 NM and one flight level).
    pub corridor: Option<(f64, f64)>,
}

impl Default for Style {
    fn default() -> Self {
        Self {
            stroke: Rgba([0x55, 0x55, 0x55, 255]),
            stroke_width_px: 2.0,
            line_join: LineJoin::Round,
            line_cap: LineCap::Round,
            dash_px: None,
            fill: Rgba([0x55, 0x55, 0x55, 153]),
            marker_color: Rgba([0x7e, 0x7e, 0x7e, 255]),
            marker_size_px: 12.0,
            marker_square: false,
            marker_icon: None,
            marker_outline: Rgba([255, 255, 255, 255]),
            label: None,
            label_size_px: 12.0,
            label_color: None,
            clamp: Clamp::Ground,
            path: PathKind::Geodesic,
            extrude: None,
            wall: false,
            corridor: None,
        }
    }
}

/// Longest label text kept, characters.
pub const MAX_LABEL_CHARS: usize = 64;

/// `template` with every `{key}` replaced by the property `key` (strings as they are,
/// numbers and booleans printed; missing or other values: nothing), trimmed and cut to
/// [`MAX_LABEL_CHARS`]; `None` when nothing is left.
pub fn label_text(template: &str, properties: &Map<String, Value>) -> Option<String> {
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let after = &rest[open + 1..];
        let Some(close) = after.find('}') else {
            out.push_str(&rest[open..]);
            rest = "";
            break;
        };
        match properties.get(&after[..close]) {
            Some(Value::String(s)) => out.push_str(s),
            Some(v @ (Value::Number(_) | Value::Bool(_))) => out.push_str(&v.to_string()),
            _ => {}
        }
        rest = &after[close + 1..];
    }
    out.push_str(rest);
    let text: String = out
        .trim()
        .chars()
        .filter(|c| !c.is_control())
        .take(MAX_LABEL_CHARS)
        .collect();
    (!text.is_empty()).then_some(text)
}

/// Simplestyle's marker sizes, pixels.
const MARKER_SMALL_PX: f32 = 8.0;
const MARKER_MEDIUM_PX: f32 = 12.0;
const MARKER_LARGE_PX: f32 = 18.0;

/// Widest line or largest symbol, pixels.
pub const MAX_PIXELS: f32 = 256.0;

/// One international foot, metres.
pub const FOOT_M: f64 = 0.3048;

/// One nautical mile, metres.
pub const NAUTICAL_MILE_M: f64 = 1852.0;

/// Parses a height or distance: a number in `default_unit`, or a number followed by `m`,
/// `km`, `ft` or `NM`, or preceded by `FL` (flight level: hundreds of feet), e.g. `FL195`,
/// `3500 ft`, `120m`, `5NM`, `"GND"`/`"SFC"` (0). Returns metres.
pub fn parse_height(value: &Value, default_unit: &str) -> Option<f64> {
    let (number, unit) = match value {
        Value::Number(n) => (n.as_f64()?, default_unit.to_owned()),
        Value::String(s) => {
            let s = s.trim();
            let upper = s.to_ascii_uppercase();
            if matches!(upper.as_str(), "GND" | "SFC") {
                return Some(0.0);
            }
            if let Some(rest) = upper.strip_prefix("FL") {
                (rest.trim().parse::<f64>().ok()?, "FL".to_owned())
            } else {
                let split = s.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(s.len());
                let (n, u) = s.split_at(split);
                let unit = if u.is_empty() { default_unit } else { u.trim() };
                (n.trim().parse::<f64>().ok()?, unit.to_owned())
            }
        }
        _ => return None,
    };
    let metres = match unit.to_ascii_lowercase().as_str() {
        "m" => number,
        "km" => number * 1000.0,
        "nm" => number * NAUTICAL_MILE_M,
        "ft" | "feet" => number * FOOT_M,
        "fl" => number * 100.0 * FOOT_M,
        _ => return None,
    };
    (metres.is_finite() && metres.abs() <= 1.0e7).then_some(metres)
}

/// Style values by key: overrides, then a feature's properties, then defaults.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StyleRules {
    /// Values that win over the features' own (`--vector FILE#key=value`).
    pub overrides: Map<String, Value>,
    /// Values for features that have none (the config file's).
    pub defaults: Map<String, Value>,
}

impl StyleRules {
    /// Rules from a URL-fragment-like list, `key=value&key=value` with %-escapes (`%23` for
    /// `#`), as overrides. Errors name the bad pair.
    pub fn from_fragment(fragment: &str) -> Result<Self, StyleError> {
        let mut overrides = Map::new();
        for pair in fragment.split('&').filter(|p| !p.is_empty()) {
            let (k, v) = pair
                .split_once('=')
                .ok_or_else(|| StyleError::NotKeyValue(pair.to_owned()))?;
            let escape = || StyleError::BadEscape(pair.to_owned());
            let v = percent_decode(v).ok_or_else(escape)?;
            let k = percent_decode(k).ok_or_else(escape)?;
            check_key(&k)?;
            overrides.insert(k, Value::String(v));
        }
        Ok(Self {
            overrides,
            defaults: Map::new(),
        })
    }

    /// Resolves the style of a feature with `properties`; values that do not parse are
    /// reported in `warnings` (and fall back).
    pub fn resolve(&self, properties: &Map<String, Value>, warnings: &mut Vec<String>) -> Style {
        let sources = [&self.overrides, properties, &self.defaults];
        let get = |key: &str| lookup(&sources, key);
        let mut style = Style::default();
        let mut bad = |key: &str, v: &Value| warnings.push(format!("style `{key}`: {v} ignored"));
        if let Some(v) = get("label") {
            match v {
                Value::String(t) => style.label = label_text(t, properties),
                Value::Number(_) | Value::Bool(_) => {
                    style.label = label_text(&v.to_string(), properties)
                }
                _ => bad("label", v),
            }
        }
        if let Some(v) = get("label-size") {
            match number(v).filter(|s| *s >= 4.0 && *s <= 96.0) {
                Some(s) => style.label_size_px = s as f32,
                None => bad("label-size", v),
            }
        }
        if let Some(v) = get("label-color") {
            match colour(v) {
                Some(c) => style.label_color = Some(c),
                None => bad("label-color", v),
            }
        }
        for (key, slot) in [
            ("stroke", &mut style.stroke),
            ("marker-color", &mut style.marker_color),
            ("marker-outline", &mut style.marker_outline),
        ] {
            if let Some(v) = get(key) {
                match colour(v) {
                    Some(c) => *slot = c,
                    None => bad(key, v),
                }
            }
        }
        if let Some(v) = get("fill") {
            match colour(v) {
                Some(c) => style.fill = Rgba([c.0[0], c.0[1], c.0[2], style.fill.0[3]]),
                None => bad("fill", v),
            }
        }
        if let Some(v) = get("stroke-width") {
            match number(v).filter(|w| (0.0..=f64::from(MAX_PIXELS)).contains(w)) {
                Some(w) => style.stroke_width_px = w as f32,
                None => bad("stroke-width", v),
            }
        }
        if let Some(v) = get("stroke-linejoin") {
            match v.as_str() {
                Some("round") => style.line_join = LineJoin::Round,
                Some("miter") => style.line_join = LineJoin::Miter,
                Some("bevel") => style.line_join = LineJoin::Bevel,
                _ => bad("stroke-linejoin", v),
            }
        }
        if let Some(v) = get("stroke-linecap") {
            match v.as_str() {
                Some("round") => style.line_cap = LineCap::Round,
                Some("butt") => style.line_cap = LineCap::Butt,
                Some("square") => style.line_cap = LineCap::Square,
                _ => bad("stroke-linecap", v),
            }
        }
        if let Some(v) = get("stroke-dasharray") {
            match dashes(v) {
                Some(d) => style.dash_px = d,
                None => bad("stroke-dasharray", v),
            }
        }
        if let Some(v) = get("marker-size") {
            let size = match v.as_str() {
                Some("small") => Some(MARKER_SMALL_PX),
                Some("medium") => Some(MARKER_MEDIUM_PX),
                Some("large") => Some(MARKER_LARGE_PX),
                _ => number(v)
                    .filter(|s| *s > 0.0 && *s <= f64::from(MAX_PIXELS))
                    .map(|s| s as f32),
            };
            match size {
                Some(s) => style.marker_size_px = s,
                None => bad("marker-size", v),
            }
        }
        if let Some(v) = get("marker-symbol") {
            style.marker_square = matches!(v.as_str(), Some("square"));
        }
        if let Some(v) = get("marker-icon") {
            match v.as_str().filter(|p| !p.is_empty()) {
                Some(p) => style.marker_icon = Some(p.to_owned()),
                None => bad("marker-icon", v),
            }
        }
        if let Some(v) = get("stroke-opacity") {
            match number(v).filter(|o| (0.0..=1.0).contains(o)) {
                Some(o) => style.stroke = style.stroke.with_opacity(o),
                None => bad("stroke-opacity", v),
            }
        }
        if let Some(v) = get("fill-opacity") {
            match number(v).filter(|o| (0.0..=1.0).contains(o)) {
                Some(o) => {
                    let [r, g, b, _] = style.fill.0;
                    style.fill = Rgba([r, g, b, 255]).with_opacity(o);
                }
                None => bad("fill-opacity", v),
            }
        }
        if let Some(v) = get("clamp") {
            match v.as_str() {
                Some("ground") => style.clamp = Clamp::Ground,
                Some("absolute") => style.clamp = Clamp::Absolute,
                Some("relative") => style.clamp = Clamp::Relative,
                _ => bad("clamp", v),
            }
        }
        if let Some(v) = get("path") {
            match v.as_str() {
                Some("geodesic") => style.path = PathKind::Geodesic,
                Some("rhumb") => style.path = PathKind::Rhumb,
                _ => bad("path", v),
            }
        }
        let extrude = match get("extrude") {
            Some(Value::Bool(b)) => *b,
            Some(Value::String(s)) if s == "true" => true,
            Some(Value::String(s)) if s == "false" => false,
            Some(v) => {
                bad("extrude", v);
                false
            }
            None => false,
        };
        match get("wall") {
            Some(Value::Bool(b)) => style.wall = *b,
            Some(Value::String(s)) if s == "true" || s == "false" => style.wall = s == "true",
            Some(v) => bad("wall", v),
            None => {}
        }
        if let Some(v) = get("corridor") {
            let unit = get("units").and_then(Value::as_str).unwrap_or("m");
            let radius = parse_height(v, unit).filter(|r| *r > 0.0 && *r <= 1.0e6);
            let half = match get("corridor-height") {
                Some(h) => parse_height(h, unit).filter(|r| *r > 0.0 && *r <= 1.0e6),
                None => radius,
            };
            match (radius, half) {
                (Some(r), Some(h)) => style.corridor = Some((r, h)),
                _ => bad("corridor", v),
            }
        }
        if extrude || get("lower").is_some() || get("upper").is_some() {
            let unit = get("units").and_then(Value::as_str).unwrap_or("m");
            let lower = limit(&sources, "lower", ("LOWERLIMIT", "LOWERUNIT"), unit);
            let upper = limit(&sources, "upper", ("UPPERLIMIT", "UPPERUNIT"), unit);
            match (lower, upper) {
                (Some((Some(lo), _)), Some((Some(hi), _))) if lo < hi => {
                    style.extrude = Some((lo, hi));
                    if get("clamp").is_none() {
                        // Vertical limits are altitudes (flight levels, feet AMSL).
                        style.clamp = Clamp::Absolute;
                    }
                }
                (Some((Some(lo), _)), Some((Some(hi), _))) => warnings.push(format!(
                    "extrusion: lower limit {lo:.0} m is not below upper limit {hi:.0} m"
                )),
                (lo, hi) => {
                    for (name, l) in [("lower", lo), ("upper", hi)] {
                        match l {
                            None => warnings.push(format!("extrusion: no `{name}` limit")),
                            Some((None, v)) => {
                                warnings.push(format!("extrusion: `{name}` {v} is not a height"))
                            }
                            Some((Some(_), _)) => {}
                        }
                    }
                }
            }
        }
        style
    }
}

fn lookup<'a>(sources: &[&'a Map<String, Value>], key: &str) -> Option<&'a Value> {
    sources
        .iter()
        .filter_map(|s| s.get(key))
        .find(|v| !v.is_null())
}

fn colour(v: &Value) -> Option<Rgba> {
    v.as_str().and_then(Rgba::parse)
}

fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().parse::<f64>().ok(),
        _ => None,
    }
}

/// A dash pattern: up to [`MAX_DASHES`] lengths in whole pixels (0-255), as a JSON array or
/// a string separated by spaces or commas; an odd list is repeated (SVG); `"none"` or an
/// all-zero list is solid (`Some(None)`); anything else `None`.
fn dashes(v: &Value) -> Option<Option<[u8; MAX_DASHES]>> {
    let values: Vec<f64> = match v {
        Value::Array(a) => a.iter().map(number).collect::<Option<_>>()?,
        Value::Number(n) => vec![n.as_f64()?],
        Value::String(s) if s.trim() == "none" => return Some(None),
        Value::String(s) => s
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| t.parse::<f64>().ok())
            .collect::<Option<_>>()?,
        _ => return None,
    };
    let mut list = values;
    if list.len() % 2 == 1 {
        list.extend_from_within(..);
    }
    if list.is_empty() || list.len() > MAX_DASHES || !list.iter().all(|x| (0.0..=255.0).contains(x))
    {
        return None;
    }
    if list.iter().all(|x| x.round() == 0.0) {
        return Some(None);
    }
    let mut out = [0u8; MAX_DASHES];
    for (i, x) in list.iter().enumerate() {
        out[i] = x.round() as u8;
    }
    // A two-value pattern fills all four slots, so the shader reads one layout.
    if list.len() == 2 {
        out[2] = out[0];
        out[3] = out[1];
    }
    Some(Some(out))
}

/// A vertical limit from `key` (in `unit`), or EUROCONTROL's pair (`LOWERLIMIT` "195" with
/// `LOWERUNIT` "FL"): the metres if it parses, and the value as found.
fn limit(
    sources: &[&Map<String, Value>],
    key: &str,
    eurocontrol: (&str, &str),
    unit: &str,
) -> Option<(Option<f64>, Value)> {
    if let Some(v) = lookup(sources, key) {
        return Some((parse_height(v, unit), v.clone()));
    }
    let v = lookup(sources, eurocontrol.0)?;
    let u = lookup(sources, eurocontrol.1)
        .and_then(Value::as_str)
        .unwrap_or("m");
    Some((parse_height(v, u), v.clone()))
}

/// Why style rules cannot be read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StyleError {
    /// A pair without `=`.
    #[error("`{0}` is not key=value")]
    NotKeyValue(String),
    /// A %-escape that is not two hex digits (or not UTF-8).
    #[error("`{0}`: bad %-escape")]
    BadEscape(String),
    /// A key that is not in [`KEYS`].
    #[error("`{0}` is not a style key (one of {keys})", keys = KEYS.join(", "))]
    UnknownKey(String),
}

/// Checks that `key` is a style key.
pub fn check_key(key: &str) -> Result<(), StyleError> {
    if KEYS.contains(&key) {
        Ok(())
    } else {
        Err(StyleError::UnknownKey(key.to_owned()))
    }
}

/// Style keys accepted on the command line and in the config file.
pub const KEYS: &[&str] = &[
    "stroke",
    "stroke-width",
    "stroke-opacity",
    "stroke-linejoin",
    "stroke-linecap",
    "stroke-dasharray",
    "fill",
    "fill-opacity",
    "marker-color",
    "marker-size",
    "marker-symbol",
    "marker-outline",
    "marker-icon",
    "label",
    "label-size",
    "label-color",
    "extrude",
    "lower",
    "upper",
    "units",
    "clamp",
    "path",
    "wall",
    "corridor",
    "corridor-height",
];

fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let h = s.get(i + 1..i + 3)?;
            out.push(u8::from_str_radix(h, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn props(v: Value) -> Map<String, Value> {
        v.as_object().cloned().unwrap_or_default()
    }

    #[test]
    fn labels_take_their_text_from_the_properties() {
        let p = props(json!({"name": "GERSA", "ident": 42, "label": "plain", "x": null}));
        assert_eq!(label_text("{name}", &p).as_deref(), Some("GERSA"));
        assert_eq!(
            label_text("{name} ({ident})", &p).as_deref(),
            Some("GERSA (42)")
        );
        assert_eq!(label_text("{missing}", &p), None);
        assert_eq!(label_text("  {x}  ", &p), None);
        assert_eq!(label_text("open {name", &p).as_deref(), Some("open {name"));
        assert_eq!(
            label_text(&"W".repeat(100), &p).map(|t| t.len()),
            Some(MAX_LABEL_CHARS)
        );
        // A feature's own `label` property is its text; an override's tokens read the
        // feature's properties.
        let mut w = Vec::new();
        let own = StyleRules::default().resolve(&p, &mut w);
        assert_eq!(own.label.as_deref(), Some("plain"));
        let rules = StyleRules::from_fragment("label={name}&label-size=15&label-color=%23ffcc00")
            .expect("rules");
        let s = rules.resolve(&p, &mut w);
        assert_eq!(s.label.as_deref(), Some("GERSA"));
        assert_eq!(s.label_size_px, 15.0);
        assert_eq!(s.label_color, Some(Rgba([255, 204, 0, 255])));
        assert!(w.is_empty(), "{w:?}");
        let bad = StyleRules::from_fragment("label-size=1000").expect("rules");
        bad.resolve(&p, &mut w);
        assert_eq!(w.len(), 1, "{w:?}");
    }

    #[test]
    fn colours_parse_as_simplestyle_writes_them() {
        assert_eq!(Rgba::parse("#ffcc00"), Some(Rgba([255, 204, 0, 255])));
        assert_eq!(Rgba::parse("f00"), Some(Rgba([255, 0, 0, 255])));
        assert_eq!(
            Rgba::parse("#11223380"),
            Some(Rgba([0x11, 0x22, 0x33, 0x80]))
        );
        assert_eq!(Rgba::parse("#ff"), None);
        assert_eq!(Rgba::parse("#gg0000"), None);
    }

    #[test]
    fn heights_in_metres_feet_and_flight_levels() {
        assert_eq!(parse_height(&json!("FL100"), "m"), Some(3048.0));
        assert_eq!(parse_height(&json!(65.0), "FL"), Some(6500.0 * FOOT_M));
        assert_eq!(parse_height(&json!("1000 ft"), "m"), Some(304.8));
        assert_eq!(parse_height(&json!("120m"), "ft"), Some(120.0));
        assert_eq!(parse_height(&json!("GND"), "ft"), Some(0.0));
        assert_eq!(parse_height(&json!("high"), "m"), None);
        assert_eq!(parse_height(&json!("12 parsecs"), "m"), None);
        assert_eq!(parse_height(&json!("1e300"), "m"), None);
    }

    #[test]
    fn overrides_win_over_properties_which_win_over_defaults() {
        let mut rules = StyleRules::from_fragment("stroke=%23ffcc00&stroke-width=3").unwrap();
        rules.defaults.insert("fill".into(), json!("#0000ff"));
        let mut w = Vec::new();
        let s = rules.resolve(
            &props(json!({"stroke": "#000000", "fill": "#00ff00", "fill-opacity": 0.5})),
            &mut w,
        );
        assert_eq!(s.stroke, Rgba([255, 204, 0, 255]));
        assert_eq!(s.stroke_width_px, 3.0);
        assert_eq!(s.fill, Rgba([0, 255, 0, 128]));
        let s = rules.resolve(&Map::new(), &mut w);
        assert_eq!(s.fill, Rgba([0, 0, 255, 153]));
        assert!(w.is_empty(), "{w:?}");
    }

    #[test]
    fn bad_values_warn_and_fall_back() {
        let mut w = Vec::new();
        let s = StyleRules::default().resolve(
            &props(json!({"stroke": "yellowish", "stroke-width": -4, "fill-opacity": 7})),
            &mut w,
        );
        assert_eq!(s, Style::default());
        assert_eq!(w.len(), 3, "{w:?}");
        assert!(StyleRules::from_fragment("strok=1").is_err());
        assert!(StyleRules::from_fragment("stroke").is_err());
        assert!(StyleRules::from_fragment("stroke=%zz").is_err());
    }

    #[test]
    fn joins_caps_and_dashes_parse_as_svg_writes_them() {
        let mut w = Vec::new();
        let s = StyleRules::default().resolve(
            &props(json!({"stroke-linejoin": "miter", "stroke-linecap": "butt",
                "stroke-dasharray": "8, 4"})),
            &mut w,
        );
        assert_eq!(s.line_join, LineJoin::Miter);
        assert_eq!(s.line_cap, LineCap::Butt);
        assert_eq!(s.dash_px, Some([8, 4, 8, 4]));
        let s = StyleRules::default().resolve(&props(json!({"stroke-dasharray": [6]})), &mut w);
        assert_eq!(s.dash_px, Some([6, 6, 6, 6]));
        let s =
            StyleRules::default().resolve(&props(json!({"stroke-dasharray": "9 3 2 3"})), &mut w);
        assert_eq!(s.dash_px, Some([9, 3, 2, 3]));
        let s = StyleRules::default().resolve(&props(json!({"stroke-dasharray": "0 0"})), &mut w);
        assert_eq!(s.dash_px, None);
        assert!(w.is_empty(), "{w:?}");
        for bad in [
            json!({"stroke-dasharray": "1 2 3 4 5 6"}),
            json!({"stroke-dasharray": "4 -1"}),
            json!({"stroke-dasharray": "4 x"}),
            json!({"stroke-dasharray": 300}),
            json!({"stroke-linejoin": "pointy"}),
            json!({"stroke-linecap": 3}),
        ] {
            let mut w = Vec::new();
            assert_eq!(
                StyleRules::default().resolve(&props(bad.clone()), &mut w),
                Style::default()
            );
            assert_eq!(w.len(), 1, "{bad}: {w:?}");
        }
    }

    #[test]
    fn corridors_take_nautical_miles_and_flight_levels() {
        let mut w = Vec::new();
        let s = StyleRules::default().resolve(
            &props(json!({"corridor": "5NM", "corridor-height": "FL1", "wall": "true"})),
            &mut w,
        );
        assert_eq!(s.corridor, Some((5.0 * NAUTICAL_MILE_M, 100.0 * FOOT_M)));
        assert!(s.wall);
        let s = StyleRules::default().resolve(&props(json!({"corridor": -3})), &mut w);
        assert_eq!(s.corridor, None);
        assert_eq!(w.len(), 1, "{w:?}");
    }

    #[test]
    fn eurocontrol_and_traffic_limits_extrude() {
        let mut w = Vec::new();
        let rules = StyleRules::from_fragment("extrude=true").unwrap();
        let fir = props(json!({"UPPERLIMIT": "195", "UPPERUNIT": "FL",
            "LOWERLIMIT": "0", "LOWERUNIT": "FT"}));
        let s = rules.resolve(&fir, &mut w);
        assert_eq!(s.extrude, Some((0.0, 19_500.0 * FOOT_M)));
        assert_eq!(s.clamp, Clamp::Absolute);
        let shape = props(json!({"lower": 0.0, "upper": 65.0, "units": "FL"}));
        let s = StyleRules::default().resolve(&shape, &mut w);
        assert_eq!(s.extrude, Some((0.0, 6500.0 * FOOT_M)));
        assert!(w.is_empty(), "{w:?}");
        let inverted = props(json!({"lower": "FL100", "upper": "FL50"}));
        assert_eq!(
            StyleRules::default().resolve(&inverted, &mut w).extrude,
            None
        );
        assert_eq!(w.len(), 1);
    }
}
