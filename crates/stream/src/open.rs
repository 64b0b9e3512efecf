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

/// Reads a container's metadata (`metadata.json`, the MBTiles `metadata` table, a PMTiles
/// header), refusing every field that is present but makes no sense with an error naming
/// `origin` and the field: a nonsense value used to become a default without a word
/// (`"scheme": "mars"` gave Web Mercator and the terrain vanished). `strings` accepts numbers
/// written as text (MBTiles keeps every value as text).
fn meta_from_json(origin: &str, j: &serde_json::Value, strings: bool) -> Result<Meta, OpenError> {
    use serde_json::Value;
    let bad =
        |field: &str, why: String| OpenError::Invalid(format!("{origin}: metadata {field}: {why}"));
    let text = |k: &str| -> Result<Option<&str>, OpenError> {
        match &j[k] {
            Value::Null => Ok(None),
            Value::String(s) => Ok(Some(s.as_str())),
            other => Err(bad(k, format!("{other} is not text"))),
        }
    };
    let whole = |k: &str, lo: u64, hi: u64| -> Result<Option<u64>, OpenError> {
        let v = match &j[k] {
            Value::Null => return Ok(None),
            Value::Number(n) => n.as_u64(),
            Value::String(s) if strings => s.trim().parse::<u64>().ok(),
            _ => None,
        };
        match v {
            Some(v) if (lo..=hi).contains(&v) => Ok(Some(v)),
            _ => Err(bad(
                k,
                format!("{} is not a whole number from {lo} to {hi}", j[k]),
            )),
        }
    };
    let max_level = u64::from(globus_tiling::TileKey::MAX_LEVEL);
    let scheme = match text("scheme")? {
        None => None,
        Some(s) => TilingScheme::parse_container(s).map_err(|e| bad("scheme", e.0))?,
    };
    let grid = match text("sample_grid")? {
        None => None,
        Some("corners") => Some(SampleGrid::Corners),
        Some("cells") => Some(SampleGrid::Cells),
        Some(g) => return Err(bad("sample_grid", format!("{g:?} (corners or cells)"))),
    };
    let format = match text("format")? {
        None => None,
        Some(f @ ("png" | "jpg" | "jpeg" | "webp" | "terrain")) => Some(f.to_string()),
        Some(f) => {
            return Err(bad(
                "format",
                format!("{f:?} is not a raster tile format Globus reads (png, jpg, webp, terrain)"),
            ));
        }
    };
    let tms = match text("layout")? {
        None | Some("xyz") => false,
        Some("tms") => true,
        Some(l) => return Err(bad("layout", format!("{l:?} (xyz or tms)"))),
    };
    let bounds = match &j["bounds"] {
        Value::Null => None,
        b => {
            let v: Option<Vec<f64>> = match b {
                Value::Array(a) => a.iter().map(Value::as_f64).collect(),
                Value::String(s) => s.split(',').map(|x| x.trim().parse().ok()).collect(),
                _ => None,
            };
            let Some([w, s, e, n]) = v.and_then(|v| <[f64; 4]>::try_from(v).ok()) else {
                return Err(bad(
                    "bounds",
                    format!("{b} is not four numbers west, south, east, north"),
                ));
            };
            if !(w < e && s < n && w >= -180.0 && e <= 180.0 && s >= -90.0 && n <= 90.0) {
                return Err(bad(
                    "bounds",
                    format!(
                        "[{w}, {s}, {e}, {n}] is not west < east within +-180 and south < north within +-90"
                    ),
                ));
            }
            Some([w, s, e, n])
        }
    };
    let min = whole("minzoom", 0, max_level)?.map(|v| v as u8);
    let max = whole("maxzoom", 0, max_level)?.map(|v| v as u8);
    if let (Some(lo), Some(hi)) = (min, max)
        && lo > hi
    {
        return Err(bad("minzoom", format!("{lo} is above maxzoom {hi}")));
    }
    let tile_size = whole("tile_size", 2, 4096)?.map(|v| v as u32);
    Ok(Meta {
        scheme,
        min,
        max,
        tile_size,
        grid,
        encoding: text("encoding")?.map(str::to_string),
        bounds,
        format,
        tms,
    })
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
        (fetch, meta_from_json(url, &json, false)?)
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
        let mut meta = meta_from_json(url, &j, true)?;
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
        let meta = meta_from_json(&meta_url, &json, false)?;
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
        let meta = meta_from_json(&meta_path.display().to_string(), &json, false)?;
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

    /// Nonsense in a container's metadata became a default without a word ("scheme": "mars"
    /// gave Web Mercator and the terrain vanished): each is one error naming the file and field.
    #[test]
    fn nonsense_metadata_names_the_file_and_the_field() {
        let good = serde_json::json!({
            "scheme": "geographic", "minzoom": 0, "maxzoom": 12, "tile_size": 256,
            "sample_grid": "corners", "format": "png", "encoding": "terrarium",
            "bounds": [11.0, 57.0, 12.0, 58.0], "layout": "xyz"
        });
        let m = meta_from_json("p/metadata.json", &good, false).unwrap();
        assert_eq!(m.scheme, Some(TilingScheme::Geographic));
        assert_eq!((m.min, m.max, m.tile_size), (Some(0), Some(12), Some(256)));
        // MBTiles keeps numbers as text.
        let mb = serde_json::json!({"minzoom": "2", "maxzoom": "9", "bounds": "-180,-85,180,85"});
        assert_eq!(meta_from_json("a.mbtiles", &mb, true).unwrap().max, Some(9));
        for (field, value) in [
            ("scheme", serde_json::json!("mars")),
            ("sample_grid", serde_json::json!("hexagons")),
            ("format", serde_json::json!("gif")),
            ("minzoom", serde_json::json!(99)),
            ("maxzoom", serde_json::json!(-1)),
            ("bounds", serde_json::json!([12.0, 57.0, 11.0, 58.0])),
            ("bounds", serde_json::json!([11.0, 58.0, 12.0, 57.0])),
            ("bounds", serde_json::json!([11.0, 57.0, 12.0])),
            ("tile_size", serde_json::json!(-256)),
            ("tile_size", serde_json::json!("256")),
            ("tile_size", serde_json::json!(256.5)),
            ("layout", serde_json::json!("spiral")),
        ] {
            let mut j = good.clone();
            j[field] = value.clone();
            let e = match meta_from_json("p/metadata.json", &j, false) {
                Ok(_) => panic!("{field} = {value} was accepted"),
                Err(e) => e.to_string(),
            };
            assert!(e.contains("p/metadata.json") && e.contains(field), "{e}");
        }
        let mut j = good.clone();
        j["minzoom"] = serde_json::json!(13);
        let e = meta_from_json("p/metadata.json", &j, false)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("above maxzoom 12"), "{e}");
    }

    /// Mutations of the metadata.json files `globus tile` writes, read as a directory's and
    /// as MBTiles' (text numbers): every one parses or is refused, none panics.
    #[test]
    fn fuzz_metadata() {
        let r = globus_test_support::fuzz::run("metadata", |b| {
            let Ok(j) = serde_json::from_slice::<serde_json::Value>(b) else {
                return false;
            };
            let dir = meta_from_json("metadata.json", &j, false).is_ok();
            let mb = meta_from_json("a.mbtiles", &j, true).is_ok();
            dir || mb
        });
        assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
    }
}
