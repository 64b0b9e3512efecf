//! WMS GetMap: one request per tile, the BBOX built from the tile's rectangle.
//!
//! * Geographic tiles ask for EPSG:4326. WMS 1.1.1 (`SRS=`) orders the BBOX
//!   `minlon,minlat,maxlon,maxlat`; WMS 1.3.0 (`CRS=`) follows the EPSG axis order of
//!   EPSG:4326, latitude first: `minlat,minlon,maxlat,maxlon`.
//! * Web Mercator tiles ask for EPSG:3857 in metres (`minx,miny,maxx,maxy` in both versions).

use std::fmt::Write;
use std::sync::Arc;

use globus_tiling::{TileKey, TilingScheme, lat_to_mercator_y};

use super::{Cancel, Fetch, FetchError, Fetched, HttpClient, OpenError};

/// Half the side of the Web Mercator square, metres (pi times the WGS84 semi-major axis).
const MERCATOR_HALF_M: f64 = std::f64::consts::PI * 6_378_137.0;

/// The WMS version spoken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WmsVersion {
    /// 1.1.1: `SRS`, longitude first.
    V1_1_1,
    /// 1.3.0: `CRS`, EPSG axis order (latitude first for EPSG:4326).
    V1_3_0,
}

/// Tiles from a WMS.
pub struct WmsFetch {
    client: Arc<HttpClient>,
    base: String,
    layers: String,
    version: WmsVersion,
    scheme: TilingScheme,
    format: String,
    tile_size: u32,
}

impl WmsFetch {
    /// GetMap requests to `base` (the service URL, with or without a query) for `layers`.
    pub fn new(
        client: Arc<HttpClient>,
        base: &str,
        layers: &str,
        version: WmsVersion,
        scheme: TilingScheme,
        format: &str,
        tile_size: u32,
    ) -> Result<Self, OpenError> {
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            return Err(OpenError::Spec(format!(
                "WMS URL {base:?} must start with http:// or https://"
            )));
        }
        if layers.is_empty() {
            return Err(OpenError::Spec(format!("WMS {base}: no layers named")));
        }
        Ok(Self {
            client,
            base: base.to_string(),
            layers: layers.to_string(),
            version,
            scheme,
            format: format.to_string(),
            tile_size,
        })
    }

    /// The GetMap URL of a tile.
    pub fn url(&self, key: TileKey) -> String {
        let r = self.scheme.rect(key);
        let [w, s, e, n] = r.to_degrees();
        let (crs_param, version) = match self.version {
            WmsVersion::V1_1_1 => ("SRS", "1.1.1"),
            WmsVersion::V1_3_0 => ("CRS", "1.3.0"),
        };
        let (crs, bbox) = match self.scheme {
            TilingScheme::Geographic | TilingScheme::GeographicReduced => {
                let b = match self.version {
                    WmsVersion::V1_1_1 => [w, s, e, n],
                    WmsVersion::V1_3_0 => [s, w, n, e],
                };
                ("EPSG:4326", b)
            }
            TilingScheme::WebMercator => {
                let x = |lon: f64| lon.to_radians() / std::f64::consts::PI * MERCATOR_HALF_M;
                let y =
                    |lat: f64| (1.0 - 2.0 * lat_to_mercator_y(lat.to_radians())) * MERCATOR_HALF_M;
                ("EPSG:3857", [x(w), y(s), x(e), y(n)])
            }
        };
        let mut url = self.base.clone();
        url.push(if self.base.contains('?') { '&' } else { '?' });
        let _ = write!(
            url,
            "SERVICE=WMS&REQUEST=GetMap&VERSION={version}&LAYERS={}&STYLES=&{crs_param}={crs}&BBOX={},{},{},{}&WIDTH={}&HEIGHT={}&FORMAT={}&TRANSPARENT=TRUE",
            encode(&self.layers),
            fmt(bbox[0]),
            fmt(bbox[1]),
            fmt(bbox[2]),
            fmt(bbox[3]),
            self.tile_size,
            self.tile_size,
            encode(&self.format),
        );
        url
    }
}

/// Shortest exact-enough decimal (1e-9 degrees is 0.1 mm).
fn fmt(v: f64) -> String {
    let s = format!("{v:.9}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Percent-encodes what must not appear raw in a query value.
fn encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' | b',' | b':' => {
                out.push(char::from(b));
            }
            _ => {
                let _ = write!(out, "%{b:02X}");
            }
        }
    }
    out
}

impl Fetch for WmsFetch {
    fn name(&self) -> &str {
        &self.base
    }

    fn locate(&self, key: TileKey) -> String {
        self.url(key)
    }

    fn fetch(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        let url = self.url(key);
        let Some(body) = self.client.get(&url, None, cancel)? else {
            return Ok(None);
        };
        // A WMS reports errors as XML with status 200.
        let head = &body.fetched.bytes[..body.fetched.bytes.len().min(256)];
        let text = String::from_utf8_lossy(head);
        if text.trim_start().starts_with('<') {
            let snippet: String = text.chars().take(160).collect();
            return Err(FetchError::Permanent(format!(
                "{url}: the WMS answered with XML, not an image: {snippet}"
            )));
        }
        Ok(Some(body.fetched))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fetch::HttpOptions;

    fn wms(version: WmsVersion, scheme: TilingScheme) -> WmsFetch {
        let client = Arc::new(HttpClient::new(HttpOptions::default()));
        WmsFetch::new(
            client,
            "https://maps.example/wms?map=x",
            "relief,borders",
            version,
            scheme,
            "image/png",
            256,
        )
        .unwrap()
    }

    fn bbox(url: &str) -> Vec<f64> {
        let b = url
            .split("BBOX=")
            .nth(1)
            .unwrap()
            .split('&')
            .next()
            .unwrap();
        b.split(',').map(|v| v.parse().unwrap()).collect()
    }

    #[test]
    fn bbox_axis_order_follows_the_version() {
        // Geographic level 1, x 1, y 0: lon -90..0, lat 0..90.
        let k = TileKey::new(1, 1, 0);
        let v111 = wms(WmsVersion::V1_1_1, TilingScheme::Geographic).url(k);
        assert!(v111.starts_with("https://maps.example/wms?map=x&SERVICE=WMS&REQUEST=GetMap"));
        assert!(v111.contains("VERSION=1.1.1") && v111.contains("SRS=EPSG:4326"));
        assert!(v111.contains("LAYERS=relief,borders") && v111.contains("FORMAT=image%2Fpng"));
        assert_eq!(bbox(&v111), vec![-90.0, 0.0, 0.0, 90.0]);
        let v130 = wms(WmsVersion::V1_3_0, TilingScheme::Geographic).url(k);
        assert!(v130.contains("VERSION=1.3.0") && v130.contains("CRS=EPSG:4326"));
        assert_eq!(bbox(&v130), vec![0.0, -90.0, 90.0, 0.0]);
        // Web Mercator level 1, x 0, y 0: the north-west quarter of the square, in metres.
        let m = wms(WmsVersion::V1_3_0, TilingScheme::WebMercator).url(TileKey::new(1, 0, 0));
        assert!(m.contains("CRS=EPSG:3857"));
        let b = bbox(&m);
        let expect = [-20_037_508.342789244, 0.0, 0.0, 20_037_508.342789244];
        for (got, want) in b.iter().zip(expect) {
            assert!((got - want).abs() < 1e-3, "{b:?}");
        }
    }
}
