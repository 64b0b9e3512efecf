//! Opening a pyramid from what a user writes: a directory, an `.mbtiles` or `.pmtiles` file,
//! an HTTP URL template, a served `globus tile` directory, a PMTiles URL, or a WMS.
//!
//! A [`SourceSpec`] is a location plus optional settings, written either as a TOML table
//! (`[[terrain]] url = "..." encoding = "terrarium"`) or on the command line as the location
//! followed by `#key=value&key=value` (the fragment is never sent to a server):
//!
//! ```text
//! ./out/topo                                     (a globus tile directory: metadata.json)
//! ./srtm.pmtiles   ./world.mbtiles
//! http://127.0.0.1:8000/topo                     (a served directory: fetches metadata.json)
//! https://tiles.example/terrarium/{z}/{x}/{y}.png#encoding=terrarium&maxzoom=15
//! https://{s}.tiles.example/{z}/{x}/{y}.jpg#subdomains=a,b,c&maxzoom=19
//! https://maps.example/wms#wms_layers=relief&wms_version=1.3.0&scheme=geographic
//! ```
//!
//! What the container's metadata says (scheme, levels, tile size, sample grid, encoding,
//! bounds) is used unless the spec overrides it; bare templates default to Web Mercator,
//! 256-pixel cell-registered tiles.

use std::path::Path;
use std::sync::Arc;

use globus_terrain::encoding::ElevationEncoding;
use globus_tiling::{GeoRect, TilingScheme, files};
use serde::Deserialize;

use crate::decode::{
    DecodeLimits, HeightImage, QUANTIZED_MESH_GRID, Rgba, decode_elevation, decode_image,
    decode_quantized_mesh,
};
use crate::fetch::pmtiles::{FileRange, HttpRange, KeptHead};
use crate::fetch::{
    CachedFetch, Cancel, DirectoryFetch, DiskCacheOptions, Fetch, FetchError, HttpClient,
    MbTilesFetch, OpenError, PmTilesFetch, TemplateFetch, WmsFetch, WmsVersion,
};
use crate::pyramid::{PyramidSpec, RasterPyramid, SampleGrid};

/// Where a layer comes from, and what it is where the container does not say.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    /// A path, or an `http(s)://` URL (a template, a served directory, a `.pmtiles` file or a
    /// WMS endpoint).
    pub url: String,
    /// Elevation encoding: `terrarium`, `mapbox`, `centimetre` or `quantized-mesh` (also
    /// implied by a URL ending in `.terrain`).
    pub encoding: Option<String>,
    /// `geographic` or `webmercator`.
    pub scheme: Option<String>,
    /// Shallowest level with tiles.
    pub minzoom: Option<u8>,
    /// Deepest level with tiles.
    pub maxzoom: Option<u8>,
    /// Samples per tile side.
    pub tile_size: Option<u32>,
    /// `corners` or `cells`.
    pub grid: Option<String>,
    /// West, south, east, north in degrees: where the layer has data.
    pub bounds: Option<[f64; 4]>,
    /// Subdomains for `{s}`.
    pub subdomains: Option<Vec<String>>,
    /// WMS layers (makes the URL a WMS endpoint).
    pub wms_layers: Option<String>,
    /// WMS version, `1.1.1` or `1.3.0` (default).
    pub wms_version: Option<String>,
    /// WMS image format (default `image/png`).
    pub format: Option<String>,
}

impl SourceSpec {
    /// Parses `LOCATION[#key=value&...]`.
    pub fn parse(text: &str) -> Result<Self, OpenError> {
        let (url, opts) = text.split_once('#').unwrap_or((text, ""));
        let mut s = SourceSpec {
            url: url.to_string(),
            ..Self::default()
        };
        for kv in opts.split('&').filter(|kv| !kv.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(|| {
                spec_error(format!("source {text:?}: option {kv:?} is not key=value"))
            })?;
            let num = |v: &str| {
                v.parse::<u32>()
                    .map_err(|_| spec_error(format!("source {text:?}: {k}={v} is not a number")))
            };
            let level = |v: &str| -> Result<u8, OpenError> {
                num(v).and_then(|n| {
                    u8::try_from(n).ok().filter(|&l| l <= 29).ok_or_else(|| {
                        spec_error(format!("source {text:?}: {k}={v} is not a level (0-29)"))
                    })
                })
            };
            match k {
                "encoding" => s.encoding = Some(v.into()),
                "scheme" => s.scheme = Some(v.into()),
                "minzoom" => s.minzoom = Some(level(v)?),
                "maxzoom" => s.maxzoom = Some(level(v)?),
                "tile_size" => s.tile_size = Some(num(v)?),
                "grid" => s.grid = Some(v.into()),
                "bounds" => {
                    let b: Vec<f64> = v.split(',').filter_map(|x| x.parse().ok()).collect();
                    let [w, so, e, n] = b[..] else {
                        return Err(spec_error(format!(
                            "source {text:?}: bounds={v} is not W,S,E,N degrees"
                        )));
                    };
                    s.bounds = Some([w, so, e, n]);
                }
                "subdomains" => s.subdomains = Some(v.split(',').map(str::to_string).collect()),
                "wms_layers" => s.wms_layers = Some(v.into()),
                "wms_version" => s.wms_version = Some(v.into()),
                "format" => s.format = Some(v.replace("%2F", "/")),
                other => {
                    return Err(spec_error(format!(
                        "source {text:?}: unknown option {other:?} (known: encoding scheme minzoom maxzoom tile_size grid bounds subdomains wms_layers wms_version format)"
                    )));
                }
            }
        }
        Ok(s)
    }
}

/// What a layer is used for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerKind {
    /// Heights.
    Elevation,
    /// Colour.
    Imagery,
}

/// What the container's own metadata says.
#[derive(Default)]
struct Meta {
    scheme: Option<TilingScheme>,
    min: Option<u8>,
    max: Option<u8>,
    tile_size: Option<u32>,
    grid: Option<SampleGrid>,
    encoding: Option<String>,
    bounds: Option<[f64; 4]>,
    format: Option<String>,
    tms: bool,
}

fn meta_from_json(j: &serde_json::Value) -> Meta {
    let level = |k: &str| {
        j[k].as_u64()
            .or_else(|| j[k].as_str().and_then(|s| s.parse().ok()))
            .and_then(|v| u8::try_from(v).ok())
    };
    let bounds = match &j["bounds"] {
        serde_json::Value::Array(a) => {
            let v: Vec<f64> = a.iter().filter_map(serde_json::Value::as_f64).collect();
            <[f64; 4]>::try_from(v).ok()
        }
        serde_json::Value::String(s) => {
            let v: Vec<f64> = s.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            <[f64; 4]>::try_from(v).ok()
        }
        _ => None,
    };
    Meta {
        scheme: j["scheme"].as_str().and_then(|s| s.parse().ok()),
        min: level("minzoom"),
        max: level("maxzoom"),
        tile_size: j["tile_size"]
            .as_u64()
            .or_else(|| j["tile_size"].as_str().and_then(|s| s.parse().ok()))
            .and_then(|v| u32::try_from(v).ok()),
        grid: match j["sample_grid"].as_str() {
            Some("corners") => Some(SampleGrid::Corners),
            Some("cells") => Some(SampleGrid::Cells),
            _ => None,
        },
        encoding: j["encoding"].as_str().map(str::to_string),
        bounds,
        format: j["format"].as_str().map(str::to_string),
        tms: j["layout"].as_str() == Some("tms"),
    }
}

/// How an elevation layer's tiles encode heights.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElevationFormat {
    /// RGB-encoded images (Terrarium, Terrain-RGB, centimetre).
    Rgb(ElevationEncoding),
    /// Cesium quantized-mesh-1.0 (`.terrain`), rasterised onto a
    /// [`QUANTIZED_MESH_GRID`]-sample grid.
    QuantizedMesh,
}

/// The `encoding` value that selects quantized-mesh.
pub const QUANTIZED_MESH: &str = "quantized-mesh";

/// An opened layer: where its bytes come from and how they are laid out.
pub struct OpenedLayer {
    /// The bytes.
    pub fetch: Arc<dyn Fetch>,
    /// The layout.
    pub spec: PyramidSpec,
    /// The elevation format (elevation layers).
    pub encoding: Option<ElevationFormat>,
}

/// Opens the layer `spec` names (reading local metadata, or fetching a served directory's
/// `metadata.json` or a PMTiles header through `client`).
pub fn open_layer(
    spec: &SourceSpec,
    kind: LayerKind,
    client: &Arc<HttpClient>,
    disk_cache: Option<&DiskCacheOptions>,
) -> Result<OpenedLayer, OpenError> {
    // Tile services (and archives over HTTP) go through the disk cache, if there is one;
    // files need none.
    let cached = |f: Box<dyn Fetch>| -> Result<Arc<dyn Fetch>, OpenError> {
        Ok(match disk_cache {
            Some(o) => Arc::new(CachedFetch::new(f, o.clone())?),
            None => Arc::from(f),
        })
    };
    let url = spec.url.as_str();
    let is_http = url.starts_with("http://") || url.starts_with("https://");
    // Quantized-mesh pyramids are geographic with corner-registered tiles by nature.
    let quantized_mesh = kind == LayerKind::Elevation
        && (spec.encoding.as_deref() == Some(QUANTIZED_MESH)
            || url
                .split(['?', '#'])
                .next()
                .is_some_and(|p| p.ends_with(".terrain")));
    let template_scheme = if quantized_mesh {
        TilingScheme::Geographic
    } else {
        TilingScheme::WebMercator
    };
    let (fetch, meta): (Arc<dyn Fetch>, Meta) = if let Some(layers) = &spec.wms_layers {
        let version = match spec.wms_version.as_deref().unwrap_or("1.3.0") {
            "1.1.1" => WmsVersion::V1_1_1,
            "1.3.0" => WmsVersion::V1_3_0,
            v => {
                return Err(spec_error(format!(
                    "WMS {url}: version {v} (use 1.1.1 or 1.3.0)"
                )));
            }
        };
        let scheme = parse_scheme(spec.scheme.as_deref(), TilingScheme::Geographic)?;
        let size = spec.tile_size.unwrap_or(256);
        let w = WmsFetch::new(
            Arc::clone(client),
            url,
            layers,
            version,
            scheme,
            spec.format.as_deref().unwrap_or("image/png"),
            size,
        )?;
        (cached(Box::new(w))?, Meta::default())
    } else if url.ends_with(".pmtiles") {
        let (fetch, json): (Arc<dyn Fetch>, serde_json::Value) =
            if let (true, Some(o)) = (is_http, disk_cache) {
                // Opened offline from the kept head; tiles from the disk cache, dropped when
                // the archive changed.
                let p = PmTilesFetch::open(KeptHead::new(
                    HttpRange::new(Arc::clone(client), url),
                    &o.dir,
                ))?;
                let changed = p.reader().opened();
                let j = pm_meta(&p);
                let c = CachedFetch::new(Box::new(p), o.clone())?;
                if changed {
                    c.clear();
                }
                (Arc::new(c), j)
            } else if is_http {
                let p = PmTilesFetch::open(HttpRange::new(Arc::clone(client), url))?;
                let j = pm_meta(&p);
                (Arc::new(p), j)
            } else {
                let p = PmTilesFetch::open(FileRange::open(Path::new(url))?)?;
                let j = pm_meta(&p);
                (Arc::new(p), j)
            };
        (fetch, meta_from_json(&json))
    } else if url.ends_with(".mbtiles") {
        if is_http {
            return Err(spec_error(format!(
                "{url}: MBTiles cannot be read over HTTP (use PMTiles)"
            )));
        }
        let m = MbTilesFetch::open(Path::new(url))?;
        let j = serde_json::Value::Object(
            m.metadata()
                .iter()
                .map(|(k, v)| (k.clone(), serde_json::Value::from(v.as_str())))
                .collect(),
        );
        let mut meta = meta_from_json(&j);
        meta.scheme = Some(m.scheme());
        (Arc::new(m), meta)
    } else if is_http && url.contains('{') {
        let subs: Vec<&str> = spec
            .subdomains
            .iter()
            .flatten()
            .map(String::as_str)
            .collect();
        let scheme = parse_scheme(spec.scheme.as_deref(), template_scheme)?;
        (
            cached(Box::new(TemplateFetch::new(
                Arc::clone(client),
                url,
                &subs,
                scheme,
            )?))?,
            Meta {
                scheme: Some(scheme),
                ..Meta::default()
            },
        )
    } else if is_http {
        // A served `globus tile` directory.
        let base = url.trim_end_matches('/');
        let meta_url = format!("{base}/metadata.json");
        let json = served_metadata(client, &meta_url, disk_cache)?;
        let meta = meta_from_json(&json);
        let ext = meta.format.clone().unwrap_or_else(|| "png".into());
        let row = if meta.tms { "{-y}" } else { "{y}" };
        let template = format!("{base}/{{z}}/{{x}}/{row}.{ext}");
        let scheme = parse_scheme(
            spec.scheme.as_deref(),
            meta.scheme.unwrap_or(TilingScheme::WebMercator),
        )?;
        (
            cached(Box::new(TemplateFetch::new(
                Arc::clone(client),
                &template,
                &[],
                scheme,
            )?))?,
            meta,
        )
    } else {
        let root = Path::new(url);
        let meta_path = root.join("metadata.json");
        let text = files::read_text_capped(&meta_path, files::MAX_TEXT_BYTES).map_err(|e| {
            OpenError::Unreadable(format!(
                "{}: {e} (a tile directory needs the metadata.json `globus tile` writes)",
                meta_path.display()
            ))
        })?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| OpenError::Invalid(format!("{}: {e}", meta_path.display())))?;
        let meta = meta_from_json(&json);
        let ext = meta.format.clone().unwrap_or_else(|| "png".into());
        let row = if meta.tms { "{-y}" } else { "{y}" };
        let scheme = meta.scheme.unwrap_or(TilingScheme::WebMercator);
        (
            Arc::new(DirectoryFetch::new(
                root,
                &format!("{{z}}/{{x}}/{row}.{ext}"),
                scheme,
            )?),
            meta,
        )
    };

    let quantized_mesh = quantized_mesh
        || (kind == LayerKind::Elevation
            && spec.encoding.is_none()
            && meta.encoding.as_deref() == Some(QUANTIZED_MESH));
    let scheme = parse_scheme(
        spec.scheme.as_deref(),
        meta.scheme.unwrap_or(template_scheme),
    )?;
    let min_level = spec.minzoom.or(meta.min).unwrap_or(0);
    let default_max = match kind {
        LayerKind::Elevation => 15,
        LayerKind::Imagery => 19,
    };
    let max_level = spec.maxzoom.or(meta.max).unwrap_or(default_max);
    if min_level > max_level {
        return Err(spec_error(format!(
            "{url}: minzoom {min_level} is above maxzoom {max_level}"
        )));
    }
    let mut tile_size = spec.tile_size.or(meta.tile_size).unwrap_or(256);
    let mut grid = match spec.grid.as_deref() {
        Some("corners") => SampleGrid::Corners,
        Some("cells") => SampleGrid::Cells,
        Some(g) => {
            return Err(spec_error(format!(
                "{url}: grid {g:?} (use corners or cells)"
            )));
        }
        None => meta.grid.unwrap_or(SampleGrid::Cells),
    };
    if quantized_mesh {
        tile_size = QUANTIZED_MESH_GRID;
        grid = SampleGrid::Corners;
    }
    if !(2..=4096).contains(&tile_size) {
        return Err(spec_error(format!(
            "{url}: tile size {tile_size} (2 to 4096 samples)"
        )));
    }
    let bounds = spec
        .bounds
        .or(meta.bounds)
        .map_or(GeoRect::WORLD, |[w, s, e, n]| {
            GeoRect::from_degrees(w, s, e, n)
        });
    let encoding = match kind {
        LayerKind::Imagery => None,
        LayerKind::Elevation if quantized_mesh => Some(ElevationFormat::QuantizedMesh),
        LayerKind::Elevation => {
            let name = spec.encoding.clone().or(meta.encoding).ok_or_else(|| {
                spec_error(format!("{url}: which elevation encoding? add #encoding=terrarium (or mapbox, centimetre, quantized-mesh)"))
            })?;
            Some(ElevationFormat::Rgb(ElevationEncoding::parse(&name).ok_or_else(|| {
                spec_error(format!(
                    "{url}: unknown elevation encoding {name:?} (terrarium, mapbox, centimetre, quantized-mesh)"
                ))
            })?))
        }
    };
    Ok(OpenedLayer {
        fetch,
        spec: PyramidSpec {
            scheme,
            min_level,
            max_level,
            tile_size,
            grid,
            bounds,
        },
        encoding,
    })
}

/// A served directory's `metadata.json`, kept in the disk cache (if any) so the layer opens
/// offline too.
fn served_metadata(
    client: &HttpClient,
    url: &str,
    disk_cache: Option<&DiskCacheOptions>,
) -> Result<serde_json::Value, OpenError> {
    let copy = disk_cache.map(|o| {
        o.dir.join(format!(
            "{:016x}.json",
            crate::fetch::disk_cache::origin_hash(url)
        ))
    });
    let fetched = client.get(url, None, &Cancel::new());
    let bytes = match (fetched, &copy) {
        (Ok(Some(body)), _) => {
            if let Some(path) = &copy {
                let _ = std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")));
                let _ = std::fs::write(path, &body.fetched.bytes);
            }
            body.fetched.bytes
        }
        (Ok(None), _) => {
            return Err(OpenError::Unreadable(format!(
                "{url}: not found (a served directory needs its metadata.json, or give a {{z}}/{{x}}/{{y}} template)"
            )));
        }
        (Err(e @ FetchError::Transient { .. }), Some(path)) => {
            files::read_capped(path, files::MAX_TEXT_BYTES).map_err(|_| {
                OpenError::Unreadable(format!("{url}: {e} (and no copy in the disk cache)"))
            })?
        }
        (Err(e), _) => return Err(OpenError::Unreadable(format!("{url}: {e}"))),
    };
    serde_json::from_slice(&bytes).map_err(|e| OpenError::Invalid(format!("{url}: {e}")))
}

fn pm_meta<R: crate::fetch::RangeRead>(p: &PmTilesFetch<R>) -> serde_json::Value {
    let mut j = p.metadata().clone();
    if !j.is_object() {
        j = serde_json::json!({});
    }
    let (min, max) = p.levels();
    j["minzoom"] = min.into();
    j["maxzoom"] = max.into();
    j["scheme"] = p.scheme().name().into();
    j
}

fn parse_scheme(text: Option<&str>, default: TilingScheme) -> Result<TilingScheme, OpenError> {
    text.map_or(Ok(default), |t| {
        t.parse()
            .map_err(|e: globus_tiling::ParseTileNameError| OpenError::Spec(e.0))
    })
}

fn spec_error(message: String) -> OpenError {
    OpenError::Spec(message)
}

/// Bytes of decoded source tiles a layer keeps by default (64 tiles of 256 x 256 samples):
/// engine tiles beside each other, and of other levels or schemes, share source tiles.
pub const DEFAULT_LAYER_CACHE_BYTES: usize = 16 << 20;

/// An elevation pyramid ready for [`crate::RasterTerrainSource`], keeping up to
/// `cache_bytes` of decoded tiles.
pub fn elevation_pyramid(
    layer: OpenedLayer,
    limits: DecodeLimits,
    cache_bytes: usize,
) -> Result<Arc<RasterPyramid<HeightImage>>, OpenError> {
    let encoding = layer.encoding.ok_or_else(|| {
        OpenError::Spec(format!("{}: not an elevation layer", layer.fetch.name()))
    })?;
    Ok(Arc::new(RasterPyramid::new(
        layer.fetch,
        layer.spec,
        match encoding {
            ElevationFormat::Rgb(e) => Box::new(move |b| decode_elevation(b, e, limits)),
            ElevationFormat::QuantizedMesh => {
                Box::new(|b| decode_quantized_mesh(b, QUANTIZED_MESH_GRID))
            }
        },
        cache_bytes,
    )))
}

/// An imagery pyramid ready for [`crate::RasterTerrainSource`], keeping up to `cache_bytes`
/// of decoded tiles.
pub fn imagery_pyramid(
    layer: OpenedLayer,
    limits: DecodeLimits,
    cache_bytes: usize,
) -> Arc<RasterPyramid<Rgba>> {
    Arc::new(RasterPyramid::new(
        layer.fetch,
        layer.spec,
        Box::new(move |b| decode_image(b, limits)),
        cache_bytes,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_fragments_and_refuses_nonsense() {
        let s = SourceSpec::parse(
            "https://t.example/{z}/{x}/{y}.png#encoding=terrarium&maxzoom=15&bounds=5,45,11,48",
        )
        .unwrap();
        assert_eq!(s.url, "https://t.example/{z}/{x}/{y}.png");
        assert_eq!(s.encoding.as_deref(), Some("terrarium"));
        assert_eq!(s.maxzoom, Some(15));
        assert_eq!(s.bounds, Some([5.0, 45.0, 11.0, 48.0]));
        for bad in ["x#maxzoom=99", "x#colour=red", "x#bounds=1,2", "x#minzoom"] {
            assert!(SourceSpec::parse(bad).is_err(), "{bad}");
        }
        let t: SourceSpec = toml::from_str("url = \"a.pmtiles\"\nmaxzoom = 3\n").unwrap();
        assert_eq!(t.maxzoom, Some(3));
    }
}
