//! URL and path templates: `{z}/{x}/{y}.png` and friends.
//!
//! | placeholder | replaced by |
//! |---|---|
//! | `{z}` | level |
//! | `{x}` | column from the west |
//! | `{y}` | row from the north (XYZ, as OpenStreetMap and Google) |
//! | `{-y}`, `{reverseY}` | row from the south (TMS) |
//! | `{q}`, `{quadkey}` | Bing quadkey (geographic quadkeys start with the root digit) |
//! | `{s}` | a subdomain, chosen per tile from the list given |
//!
//! The template is parsed once; an unknown placeholder or an unclosed brace is refused with
//! the template named. Only numbers and quadkey digits are ever substituted, so a tile key
//! cannot smuggle `..` or a separator into a path.

use std::fmt::Write;

use globus_tiling::{TileKey, TilingScheme};

use super::OpenError;

#[derive(Clone, Debug, PartialEq, Eq)]
enum Part {
    Text(String),
    Z,
    X,
    Y,
    ReverseY,
    Quadkey,
    Subdomain,
}

/// A parsed template.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UrlTemplate {
    text: String,
    parts: Vec<Part>,
    subdomains: Vec<String>,
}

impl UrlTemplate {
    /// Parses `template`; `{s}` rotates through `subdomains` (default `a`, `b`, `c`).
    pub fn parse(template: &str, subdomains: &[&str]) -> Result<Self, OpenError> {
        let mut parts = Vec::new();
        let mut rest = template;
        while let Some(open) = rest.find('{') {
            if open > 0 {
                parts.push(Part::Text(rest[..open].to_string()));
            }
            let close = rest[open..]
                .find('}')
                .ok_or_else(|| OpenError::Spec(format!("template {template:?}: unclosed '{{'")))?
                + open;
            let part = match &rest[open + 1..close] {
                "z" => Part::Z,
                "x" => Part::X,
                "y" => Part::Y,
                "-y" | "reverseY" => Part::ReverseY,
                "q" | "quadkey" => Part::Quadkey,
                "s" => Part::Subdomain,
                other => {
                    return Err(OpenError::Spec(format!(
                        "template {template:?}: unknown placeholder {{{other}}} (known: {{z}} {{x}} {{y}} {{-y}} {{reverseY}} {{q}} {{quadkey}} {{s}})"
                    )));
                }
            };
            parts.push(part);
            rest = &rest[close + 1..];
        }
        if !rest.is_empty() {
            parts.push(Part::Text(rest.to_string()));
        }
        let has = |p: &Part| parts.contains(p);
        let has_row = has(&Part::Y) || has(&Part::ReverseY);
        let names_tile = has(&Part::Quadkey) || (has(&Part::Z) && has(&Part::X) && has_row);
        if !names_tile {
            return Err(OpenError::Spec(format!(
                "template {template:?} names no tile: it needs {{z}}, {{x}} and {{y}} (or {{-y}}), or {{q}}"
            )));
        }
        let subdomains = if subdomains.is_empty() {
            vec!["a".into(), "b".into(), "c".into()]
        } else {
            subdomains.iter().map(|s| (*s).to_string()).collect()
        };
        Ok(Self {
            text: template.to_string(),
            parts,
            subdomains,
        })
    }

    /// The template as given.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// Which subdomain `key` goes to: spread evenly and stable per tile, so a tile is always
    /// fetched from (and cached by the browser-style caches of) the same host.
    pub fn subdomain_index(&self, key: TileKey) -> usize {
        ((key.x() as usize) + (key.y() as usize)) % self.subdomains.len()
    }

    /// The subdomains.
    pub fn subdomains(&self) -> &[String] {
        &self.subdomains
    }

    /// The template filled in for `key` of `scheme`.
    pub fn expand(&self, scheme: TilingScheme, key: TileKey) -> String {
        let mut out = String::with_capacity(self.text.len() + 16);
        for p in &self.parts {
            // Writing to a String cannot fail.
            let _ = match p {
                Part::Text(t) => {
                    out.push_str(t);
                    Ok(())
                }
                Part::Z => write!(out, "{}", key.level()),
                Part::X => write!(out, "{}", key.x()),
                Part::Y => write!(out, "{}", key.y()),
                Part::ReverseY => write!(out, "{}", scheme.tms_y(key)),
                Part::Quadkey => {
                    out.push_str(&scheme.quadkey(key));
                    Ok(())
                }
                Part::Subdomain => {
                    out.push_str(&self.subdomains[self.subdomain_index(key)]);
                    Ok(())
                }
            };
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expands_known_examples() {
        let merc = TilingScheme::WebMercator;
        // OpenStreetMap: Zurich (47.3769 N, 8.5417 E) at level 12 is tile 12/2145/1434
        // (XYZ), TMS row 2661 (the slippy-map formulas).
        let osm = UrlTemplate::parse("https://{s}.tile.example/{z}/{x}/{y}.png", &[]).unwrap();
        let k = TileKey::new(12, 2145, 1434);
        assert_eq!(
            osm.expand(merc, k),
            "https://a.tile.example/12/2145/1434.png"
        );
        let tms = UrlTemplate::parse("/t/{z}/{x}/{-y}.png", &[]).unwrap();
        assert_eq!(tms.expand(merc, k), "/t/12/2145/2661.png");
        let rev = UrlTemplate::parse("/t/{z}/{x}/{reverseY}.png", &[]).unwrap();
        assert_eq!(rev.expand(merc, k), "/t/12/2145/2661.png");
        // Bing Maps Tile System: level 3, x 3, y 5 is quadkey "213".
        let bing =
            UrlTemplate::parse("http://ecn.{s}.example/a{q}.jpeg?g=1", &["t0", "t1"]).unwrap();
        assert_eq!(
            bing.expand(merc, TileKey::new(3, 3, 5)),
            "http://ecn.t0.example/a213.jpeg?g=1"
        );
        // Geographic: two roots, so TMS rows count 2^z of them and quadkeys start with the
        // root column.
        let geo = TilingScheme::Geographic;
        let g = UrlTemplate::parse("{z}-{x}-{-y}-{quadkey}", &[]).unwrap();
        assert_eq!(g.expand(geo, TileKey::new(1, 3, 0)), "1-3-1-11");
    }

    #[test]
    fn subdomains_rotate_and_stay_put_per_tile() {
        let t = UrlTemplate::parse("http://{s}.x/{z}/{x}/{y}", &["a", "b", "c", "d"]).unwrap();
        let merc = TilingScheme::WebMercator;
        let hosts: std::collections::BTreeSet<String> = (0..8)
            .map(|x| t.expand(merc, TileKey::new(4, x, 3)))
            .map(|u| u[7..9].to_string())
            .collect();
        assert_eq!(hosts.len(), 4);
        let k = TileKey::new(9, 100, 200);
        assert_eq!(t.expand(merc, k), t.expand(merc, k));
    }

    #[test]
    fn refuses_bad_templates_by_name() {
        for bad in ["{z}/{x}/{w}.png", "{z}/{x/{y}", "tiles/{z}.png", "plain"] {
            let e = UrlTemplate::parse(bad, &[]).unwrap_err();
            assert!(matches!(&e, OpenError::Spec(m) if m.contains(bad)), "{e}");
        }
    }
}
