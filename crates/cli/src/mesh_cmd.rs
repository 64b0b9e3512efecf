//! `globus mesh`: builds one tile's adaptive mesh from an encoded elevation tile, or describes
//! a quantized-mesh file.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use globus_geo::Ellipsoid;
use globus_terrain::adaptive::{AdaptiveMesh, HeightGrid, Rtin, RtinScratch, decimate};
use globus_terrain::encoding::ElevationEncoding;
use globus_terrain::quantized_mesh::{
    BorderRing, QuantizedMesh, QuantizedMeshOptions, TileProjection, WaterMask, from_adaptive_mesh,
};
use globus_tiling::{Direction, TileKey, TilingScheme};
use serde_json::{Value, json};

/// Options of `globus mesh`.
#[derive(Args, Clone, Debug)]
pub struct MeshArgs {
    /// An encoded elevation tile (PNG, 2^k + 1 or 2^k samples per side) or a quantized-mesh
    /// file (.terrain, gzip'd or not).
    #[arg(long = "in")]
    pub input: PathBuf,
    /// Elevation encoding of a PNG tile: terrarium, mapbox or centimetre.
    #[arg(long)]
    pub encoding: Option<String>,
    /// Largest vertical error allowed, metres.
    #[arg(long, allow_hyphen_values = true)]
    pub max_error: Option<f64>,
    /// rtin (fast, exact bound) or decimate (fewer triangles, slower).
    #[arg(long, default_value = "rtin")]
    pub method: String,
    /// Write the mesh as quantized-mesh 1.0 (gzip'd when the name ends in .gz).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print JSON (the default output is one line of text).
    #[arg(long)]
    pub json: bool,
    /// Where the tile lies, Z/X/Y (default: from the input path .../Z/X/Y.png).
    #[arg(long)]
    pub tile: Option<String>,
    /// Tiling scheme of --tile: geographic or webmercator.
    #[arg(long, default_value = "geographic")]
    pub scheme: String,
    /// Build this many times and report the median time.
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Also write the mesh in grid coordinates as JSON {"vertices": [[x, y], ...],
    /// "triangles": [[a, b, c], ...]} (for comparison scripts).
    #[arg(long)]
    pub dump: Option<PathBuf>,
}

/// Runs `globus mesh` and returns the report.
pub fn run(args: &MeshArgs) -> anyhow::Result<Value> {
    let bytes =
        globus_tiling::files::read_capped(&args.input, globus_tiling::files::MAX_TILE_BYTES)
            .with_context(|| format!("reading {}", args.input.display()))?;
    if !bytes.starts_with(b"\x89PNG") {
        return describe_quantized_mesh(&args.input, &bytes);
    }
    let parse = |name: &str| {
        ElevationEncoding::parse(name).with_context(|| {
            format!("unknown elevation encoding {name:?} (use terrarium, mapbox or centimetre)")
        })
    };
    let encoding = match (&args.encoding, pyramid_encoding(&args.input)?) {
        (Some(name), _) => parse(name)?,
        (None, Some((meta, name))) => {
            parse(&name).with_context(|| format!("the encoding of {}", meta.display()))?
        }
        (None, None) => bail!(
            "{}: pass --encoding to decode an elevation PNG (it is not in a pyramid whose metadata.json names one)",
            args.input.display()
        ),
    };
    let max_error = args
        .max_error
        .context("pass --max-error (metres) to build a mesh")?;
    if !(max_error.is_finite() && max_error >= 0.0) {
        bail!("--max-error must be a non-negative number of metres, not {max_error}");
    }
    let (grid, resampled_from) = read_elevation_png(&args.input, &bytes, encoding)?;
    let mut times = Vec::new();
    let mut mesh = AdaptiveMesh::default();
    // One scratch and one output for every repeat, as a tiler meshing tile after tile keeps
    // one of each per thread.
    let mut scratch = RtinScratch::default();
    let mut rtin = Rtin::default();
    for _ in 0..args.repeat.max(1) {
        let start = Instant::now();
        match args.method.as_str() {
            "rtin" => {
                rtin.rebuild_for(&grid, &mut scratch, max_error);
                rtin.mesh_into(max_error, u16::MAX, &mut scratch, &mut mesh);
            }
            "decimate" => mesh = decimate::decimate(&grid, max_error),
            other => bail!("unknown mesh method {other:?} (use rtin or decimate)"),
        };
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let measured = mesh.max_error(&grid);
    let (lo, hi) = grid
        .heights()
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)));
    let mut report = json!({
        "input": args.input.display().to_string(),
        "encoding": format!("{encoding:?}").to_lowercase(),
        "height_range_m": [lo, hi],
        "method": args.method,
        "grid": grid.side(),
        "resampled_from": resampled_from,
        "max_error_bound_m": max_error,
        "vertices": mesh.vertices.len(),
        "triangles": mesh.triangles.len(),
        "max_error_m": measured,
        "build_ms": times[times.len() / 2],
        "runs": times.len(),
    });
    if let Some(path) = &args.dump {
        let dump = json!({"vertices": mesh.vertices, "triangles": mesh.triangles});
        globus_tiling::files::write_atomic(path, dump.to_string().as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(out) = &args.out {
        let (qm, neighbours) = quantize(args, encoding, &grid, &mesh)?;
        report["normals_across_edges"] = json!(neighbours);
        let gzip = out.extension().is_some_and(|e| e == "gz");
        globus_tiling::files::write_atomic(out, &qm.encode(gzip))
            .with_context(|| format!("writing {}", out.display()))?;
        report["out"] = json!(out.display().to_string());
    }
    Ok(report)
}

/// The one-line text form of a report.
pub fn summary_line(report: &Value) -> String {
    if report.get("method").is_some() {
        format!(
            "{} vertices, {} triangles, max error {:.3} m (bound {} m), {:.2} ms",
            report["vertices"],
            report["triangles"],
            report["max_error_m"].as_f64().unwrap_or(f64::NAN),
            report["max_error_bound_m"],
            report["build_ms"].as_f64().unwrap_or(f64::NAN)
        )
    } else {
        format!(
            "quantized-mesh: {} vertices, {} triangles, heights {} .. {} m",
            report["vertices"], report["triangles"], report["min_height_m"], report["max_height_m"]
        )
    }
}

/// The quantized-mesh tile of `mesh`, and the edges whose normals use the neighbouring tile.
fn quantize(
    args: &MeshArgs,
    encoding: ElevationEncoding,
    grid: &HeightGrid,
    mesh: &AdaptiveMesh,
) -> anyhow::Result<(QuantizedMesh, Vec<&'static str>)> {
    let scheme = crate::tile_cmd::parse_scheme(&args.scheme)?;
    let key = match &args.tile {
        Some(name) => parse_tile(scheme, name)?,
        None => tile_from_path(scheme, &args.input).with_context(|| {
            format!(
                "{}: pass --tile Z/X/Y to place the mesh on the globe (the path does not end in Z/X/Y.png)",
                args.input.display()
            )
        })?,
    };
    let projection = match scheme {
        TilingScheme::Geographic | TilingScheme::GeographicReduced => TileProjection::Geographic,
        TilingScheme::WebMercator => TileProjection::WebMercator,
    };
    // In a pyramid (the input is .../Z/X/Y.png), the neighbours' samples next to the shared
    // edges make the edge normals central differences, as the neighbours' own are.
    let border = if tile_from_path(scheme, &args.input) == Some(key) {
        border_ring(&args.input, scheme, key, encoding, grid.side())?
    } else {
        BorderRing::default()
    };
    let neighbours = [
        ("north", &border.north),
        ("east", &border.east),
        ("south", &border.south),
        ("west", &border.west),
    ]
    .into_iter()
    .filter_map(|(name, side)| side.is_some().then_some(name))
    .collect();
    let options = QuantizedMeshOptions {
        normals: true,
        border,
        ..QuantizedMeshOptions::default()
    };
    let qm = from_adaptive_mesh(
        mesh,
        grid,
        &scheme.rect(key),
        projection,
        &Ellipsoid::WGS84,
        &options,
    );
    Ok((qm, neighbours))
}

/// The samples just outside `key`'s grid, from the neighbouring tiles beside `input` in its
/// `Z/X/Y` pyramid (same encoding, same grid size; they share the tile's edge samples, so
/// the sample next to the edge is their second row or column). Missing neighbours are left
/// out; a neighbour that is there but unreadable or of another size is an error naming it.
fn border_ring(
    input: &Path,
    scheme: TilingScheme,
    key: TileKey,
    encoding: ElevationEncoding,
    side: usize,
) -> anyhow::Result<BorderRing> {
    let (Some(level_dir), Some(ext)) = (
        input.parent().and_then(Path::parent),
        input.extension().and_then(|e| e.to_str()),
    ) else {
        return Ok(BorderRing::default());
    };
    let neighbour = |direction: Direction| -> anyhow::Result<Option<HeightGrid>> {
        let Some(n) = key.neighbor(scheme, direction) else {
            return Ok(None);
        };
        let path = level_dir
            .join(n.x().to_string())
            .join(format!("{}.{ext}", n.y()));
        let bytes =
            match globus_tiling::files::read_capped(&path, globus_tiling::files::MAX_TILE_BYTES) {
                Ok(bytes) => bytes,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
                Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
            };
        let (grid, _) = read_elevation_png(&path, &bytes, encoding)?;
        if grid.side() != side {
            bail!(
                "{}: neighbour of {} samples per side, the tile has {side}",
                path.display(),
                grid.side()
            );
        }
        Ok(Some(grid))
    };
    let last = side - 1;
    let row = |g: &HeightGrid, y: usize| (0..side).map(|x| g.at(x, y)).collect::<Vec<_>>();
    let column = |g: &HeightGrid, x: usize| (0..side).map(|y| g.at(x, y)).collect::<Vec<_>>();
    Ok(BorderRing {
        north: neighbour(Direction::North)?.map(|g| row(&g, last - 1)),
        south: neighbour(Direction::South)?.map(|g| row(&g, 1)),
        west: neighbour(Direction::West)?.map(|g| column(&g, last - 1)),
        east: neighbour(Direction::East)?.map(|g| column(&g, 1)),
    })
}

fn parse_tile(scheme: TilingScheme, name: &str) -> anyhow::Result<TileKey> {
    let parts: Vec<&str> = name.split('/').collect();
    let parsed = match parts.as_slice() {
        [z, x, y] => z
            .parse::<u8>()
            .ok()
            .zip(x.parse::<u32>().ok())
            .zip(y.parse::<u32>().ok())
            .and_then(|((z, x), y)| scheme.key(z, x, y)),
        _ => None,
    };
    parsed.with_context(|| format!("--tile {name:?} is not a Z/X/Y tile of the {scheme} scheme"))
}

fn tile_from_path(scheme: TilingScheme, path: &Path) -> Option<TileKey> {
    let y = path.file_stem()?.to_str()?;
    let x_dir = path.parent()?;
    let x = x_dir.file_name()?.to_str()?;
    let z = x_dir.parent()?.file_name()?.to_str()?;
    parse_tile(scheme, &format!("{z}/{x}/{y}")).ok()
}

/// Decodes an elevation PNG; a 2^k-sample corner grid (what `globus tile` writes) is
/// resampled bilinearly onto 2^k + 1 samples over the same extent.
/// The encoding the `metadata.json` of the pyramid holding `input` (`ROOT/Z/X/Y.png`) names,
/// with that file's path; `None` outside a pyramid.
fn pyramid_encoding(input: &Path) -> anyhow::Result<Option<(PathBuf, String)>> {
    let Some(root) = input.ancestors().nth(3) else {
        return Ok(None);
    };
    let meta = root.join("metadata.json");
    if !meta.is_file() {
        return Ok(None);
    }
    let text = globus_tiling::files::read_text_capped(&meta, globus_tiling::files::MAX_TEXT_BYTES)
        .with_context(|| format!("reading {}", meta.display()))?;
    let v: Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", meta.display()))?;
    Ok(v["encoding"]
        .as_str()
        .map(|e| (meta.clone(), e.to_string())))
}

/// Refuses a PNG whose pixels cannot hold an RGB elevation encoding: greyscale, 16-bit or
/// palette images (decoded as Terrarium before, without a word).
fn check_rgb_png(path: &Path, bytes: &[u8], encoding: ElevationEncoding) -> anyhow::Result<()> {
    // The IHDR chunk follows the 8-byte signature: length, "IHDR", width, height, bit depth,
    // colour type.
    let (Some(&depth), Some(&colour)) = (bytes.get(24), bytes.get(25)) else {
        bail!("{}: truncated PNG header", path.display());
    };
    let kind = match colour {
        0 => "greyscale",
        3 => "palette",
        4 => "greyscale with alpha",
        2 | 6 if depth == 8 => return Ok(()),
        2 | 6 => "16-bit colour",
        _ => "unknown colour type",
    };
    bail!(
        "{}: a {kind} PNG cannot hold {encoding:?} heights, which need 8-bit RGB(A) pixels (is it an image tile, or another encoding?)",
        path.display()
    )
}

fn read_elevation_png(
    path: &Path,
    bytes: &[u8],
    encoding: ElevationEncoding,
) -> anyhow::Result<(HeightGrid, Option<usize>)> {
    check_rgb_png(path, bytes, encoding)?;
    let mut reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(16385);
    limits.max_image_height = Some(16385);
    limits.max_alloc = Some(2 << 30);
    reader.limits(limits);
    let img = reader
        .decode()
        .with_context(|| format!("{}: not a readable PNG", path.display()))?
        .into_rgb8();
    let (w, h) = img.dimensions();
    if w != h {
        bail!("{}: elevation tile is {w}x{h}, not square", path.display());
    }
    let side = w as usize;
    let heights: Vec<f32> = img.pixels().map(|p| encoding.decode(p.0) as f32).collect();
    if let Some((i, h)) = heights
        .iter()
        .enumerate()
        .find(|(_, h)| h.is_nan() || h.abs() > globus_terrain::MAX_ABS_HEIGHT_M as f32)
    {
        bail!(
            "{}: pixel ({}, {}) decodes to {h} m as {encoding:?}, beyond any height on a planet (wrong --encoding?)",
            path.display(),
            i % side,
            i / side
        );
    }
    if let Ok(grid) = HeightGrid::new(side, heights.clone()) {
        return Ok((grid, None));
    }
    if side < 2 || !side.is_power_of_two() {
        bail!(
            "{}: a {side}x{side} tile cannot be meshed (need 2^k or 2^k + 1 samples per side)",
            path.display()
        );
    }
    let out = side + 1;
    let scale = (side - 1) as f64 / side as f64;
    let mut resampled = Vec::with_capacity(out * out);
    for j in 0..out {
        for i in 0..out {
            let (fx, fy) = (i as f64 * scale, j as f64 * scale);
            let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(side - 1), (y0 + 1).min(side - 1));
            let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
            let at = |x: usize, y: usize| f64::from(heights[y * side + x]);
            let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
            let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
            resampled.push((top * (1.0 - ty) + bottom * ty) as f32);
        }
    }
    let grid = HeightGrid::new(out, resampled)
        .with_context(|| format!("{}: resampled grid", path.display()))?;
    Ok((grid, Some(side)))
}

fn describe_quantized_mesh(path: &Path, bytes: &[u8]) -> anyhow::Result<Value> {
    let qm = QuantizedMesh::decode(bytes).with_context(|| {
        format!(
            "{}: not a PNG elevation tile nor a quantized-mesh tile",
            path.display()
        )
    })?;
    let h = &qm.header;
    Ok(json!({
        "input": path.display().to_string(),
        "format": "quantized-mesh-1.0",
        "gzip": bytes.starts_with(&[0x1f, 0x8b]),
        "vertices": qm.vertex_count(),
        "triangles": qm.triangle_count(),
        "min_height_m": h.min_height_m,
        "max_height_m": h.max_height_m,
        "centre": [h.centre.x, h.centre.y, h.centre.z],
        "bounding_sphere": {"centre": [h.sphere_centre.x, h.sphere_centre.y, h.sphere_centre.z], "radius_m": h.sphere_radius_m},
        "horizon_occlusion_point": [h.horizon_occlusion_point.x, h.horizon_occlusion_point.y, h.horizon_occlusion_point.z],
        "edges": {"west": qm.west.len(), "south": qm.south.len(), "east": qm.east.len(), "north": qm.north.len()},
        "normals": qm.normals.is_some(),
        "water_mask": match &qm.water_mask { None => Value::Null, Some(WaterMask::Uniform(b)) => json!(b), Some(WaterMask::Grid(_)) => json!("256x256") },
        "metadata": qm.metadata,
    }))
}
