//! CPU geometry of the vector overlay: what each feature becomes (draped lon/lat geometry,
//! or ECEF geometry at altitude in chunks with their own origin), and the instances a drawn
//! tile gets from the draped part.

use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_terrain::TileMesh;
use globus_vector::shape::{self, Position, Straight};
use globus_vector::{Clamp, DrapeSurface, Feature, Rgba};

use super::gpu::{FillVertex, LineInstance};

/// Densification tolerance: drawn lines pass within this of their true path, metres.
pub(crate) const PATH_TOLERANCE_M: f64 = 1.0;

/// Longest side of a chunk of geometry at altitude sharing one origin: f32 offsets within
/// it resolve 6 cm at worst (invisible on geometry at altitude, which is never nearer than
/// its own size allows), and a continent's routes need a few hundred anchors, each one
/// subtraction per frame.
const CHUNK_EXTENT_M: f64 = 1_000_000.0;

/// Largest step, degrees, between vertices of a fill or volume cap at altitude (so its
/// triangles follow the curvature of the body: the chord of 0.5 degree sags about 60 m).
const CAP_STEP_DEG: f64 = 0.5;

/// Cell size, degrees, draped fills are tessellated to before draping (see
/// [`shape::tessellate`]): small enough that a fill triangle meets few terrain triangles,
/// large enough that a continent is a few thousand.
const DRAPED_CELL_DEG: f64 = 1.0;

/// Width of the outline drawn round point symbols, pixels.
const MARKER_OUTLINE_PX: f32 = 1.5;

/// Geometry draped on the terrain, in unwrapped longitude/latitude degrees.
#[derive(Clone, Debug, Default)]
pub(crate) struct Draped {
    pub lines: Vec<DrapedLine>,
    pub fills: Vec<DrapedFill>,
    pub points: Vec<DrapedPoint>,
}

/// A line to drape: its densified positions, bounds, colour and width in pixels.
#[derive(Clone, Debug)]
pub(crate) struct DrapedLine {
    pub pts: Vec<[f64; 2]>,
    pub bbox: Bbox,
    pub colour: Rgba,
    pub width_px: f32,
}

/// A fill to drape: its tessellated triangles, bounds and colour.
#[derive(Clone, Debug)]
pub(crate) struct DrapedFill {
    pub triangles: Vec<[[f64; 2]; 3]>,
    pub bbox: Bbox,
    pub colour: Rgba,
}

/// A point symbol on the ground.
#[derive(Clone, Debug)]
pub(crate) struct DrapedPoint {
    pub at: [f64; 2],
    pub colour: Rgba,
    pub outline: Rgba,
    pub size_px: f32,
    pub square: bool,
}

/// Longitude/latitude bounds, degrees (longitudes unwrapped).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bbox {
    pub lon: [f64; 2],
    pub lat: [f64; 2],
}

impl Bbox {
    fn of(points: impl Iterator<Item = [f64; 2]>) -> Self {
        let mut b = Bbox {
            lon: [f64::INFINITY, f64::NEG_INFINITY],
            lat: [f64::INFINITY, f64::NEG_INFINITY],
        };
        for p in points {
            b.lon = [b.lon[0].min(p[0]), b.lon[1].max(p[0])];
            b.lat = [b.lat[0].min(p[1]), b.lat[1].max(p[1])];
        }
        b
    }

    fn union(self, o: Bbox) -> Bbox {
        Bbox {
            lon: [self.lon[0].min(o.lon[0]), self.lon[1].max(o.lon[1])],
            lat: [self.lat[0].min(o.lat[0]), self.lat[1].max(o.lat[1])],
        }
    }

    /// Whether it overlaps `rect` (west, south, east, north) at some whole-turn shift.
    pub fn overlaps(&self, rect: [f64; 4]) -> bool {
        let [w, s, e, n] = rect;
        if self.lat[1] < s || self.lat[0] > n {
            return false;
        }
        (-2..=2).any(|k| {
            let shift = f64::from(k) * 360.0;
            self.lon[1] + shift >= w && self.lon[0] + shift <= e
        })
    }
}

/// Geometry at altitude sharing one origin.
#[derive(Clone, Debug, Default)]
pub(crate) struct Chunk {
    pub origin: DVec3,
    pub lines: Vec<LineInstance>,
    pub fills: Vec<FillVertex>,
}

/// What one feature becomes.
#[derive(Clone, Debug, Default)]
pub(crate) struct Built {
    pub draped: Draped,
    pub bbox: Option<Bbox>,
    pub chunks: Vec<Chunk>,
}

/// Builds a feature's geometry for a body and exaggeration.
pub(crate) fn build(feature: &Feature, id: u32, ellipsoid: &Ellipsoid, exaggeration: f64) -> Built {
    let style = &feature.style;
    let mut out = Built::default();
    let world = |p: Position| {
        ellipsoid.cartographic_to_ecef(Cartographic::new(
            p[0].to_radians(),
            p[1].to_radians(),
            p[2] * exaggeration,
        ))
    };
    let ground = matches!(style.clamp, Clamp::Ground | Clamp::Relative);
    let mut chunks = ChunkWriter::default();
    let lonlat = |pts: &[Position]| pts.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>();
    for line in &feature.lines {
        if style.stroke_width_px <= 0.0 || style.stroke.0[3] == 0 {
            continue;
        }
        if ground {
            let d = shape::densify(
                ellipsoid,
                line,
                false,
                style.path,
                Straight::LonLat,
                PATH_TOLERANCE_M,
            );
            let pts = lonlat(&d);
            let b = Bbox::of(pts.iter().copied());
            out.draped.lines.push(DrapedLine {
                pts,
                bbox: b,
                colour: style.stroke,
                width_px: style.stroke_width_px,
            });
        } else {
            let d = shape::densify(
                ellipsoid,
                line,
                false,
                style.path,
                Straight::Chord,
                PATH_TOLERANCE_M,
            );
            let pts: Vec<DVec3> = d.iter().map(|&p| world(p)).collect();
            chunks.line(&pts, id, style.stroke, style.stroke_width_px);
        }
    }
    for polygon in &feature.polygons {
        let rings: Vec<Vec<Position>> = polygon
            .iter()
            .map(|r| {
                shape::densify(
                    ellipsoid,
                    r,
                    true,
                    style.path,
                    Straight::LonLat,
                    PATH_TOLERANCE_M,
                )
            })
            .collect();
        if let Some((lower, upper)) = style.extrude {
            volume(
                &rings,
                polygon,
                (lower, upper),
                style,
                id,
                ellipsoid,
                exaggeration,
                &mut chunks,
                &mut out.draped,
            );
            continue;
        }
        if style.fill.0[3] > 0 {
            if ground {
                let tris = shape::tessellate(&rings, DRAPED_CELL_DEG);
                let b = Bbox::of(tris.iter().flatten().copied());
                out.draped.fills.push(DrapedFill {
                    triangles: tris,
                    bbox: b,
                    colour: style.fill,
                });
            } else {
                let h = polygon[0][0][2];
                cap(&rings, h, style.fill, id, &world, &mut chunks);
            }
        }
        if style.stroke_width_px > 0.0 && style.stroke.0[3] > 0 {
            for r in &rings {
                let mut pts = r.clone();
                pts.push(r[0]);
                if ground {
                    let pts = lonlat(&pts);
                    let b = Bbox::of(pts.iter().copied());
                    out.draped.lines.push(DrapedLine {
                        pts,
                        bbox: b,
                        colour: style.stroke,
                        width_px: style.stroke_width_px,
                    });
                } else {
                    let d = shape::densify(
                        ellipsoid,
                        &pts,
                        false,
                        style.path,
                        Straight::Chord,
                        PATH_TOLERANCE_M,
                    );
                    let w: Vec<DVec3> = d.iter().map(|&p| world(p)).collect();
                    chunks.line(&w, id, style.stroke, style.stroke_width_px);
                }
            }
        }
    }
    for &p in &feature.points {
        let (colour, outline, size) = (
            style.marker_color,
            style.marker_outline,
            style.marker_size_px,
        );
        if ground {
            out.draped.points.push(DrapedPoint {
                at: [p[0], p[1]],
                colour,
                outline,
                size_px: size,
                square: style.marker_square,
            });
        } else {
            chunks.point(world(p), id, colour, outline, size, style.marker_square);
        }
    }
    let d = &out.draped;
    out.bbox = d
        .lines
        .iter()
        .map(|l| l.bbox)
        .chain(d.fills.iter().map(|f| f.bbox))
        .chain(d.points.iter().map(|p| Bbox::of(std::iter::once(p.at))))
        .reduce(Bbox::union);
    out.chunks = chunks.finish();
    out
}

/// A polygon between two altitudes: translucent walls, top and bottom, its rings as lines at
/// both limits with vertical edges at the input vertices, and where it stands on the ground,
/// its footprint draped.
#[allow(clippy::too_many_arguments)]
fn volume(
    rings: &[Vec<Position>],
    corners: &[Vec<Position>],
    (lower, upper): (f64, f64),
    style: &globus_vector::Style,
    id: u32,
    ellipsoid: &Ellipsoid,
    exaggeration: f64,
    chunks: &mut ChunkWriter,
    draped: &mut Draped,
) {
    let at = |p: Position, h: f64| {
        ellipsoid.cartographic_to_ecef(Cartographic::new(
            p[0].to_radians(),
            p[1].to_radians(),
            h * exaggeration,
        ))
    };
    let fill = style.fill;
    let edge = Rgba([
        style.stroke.0[0],
        style.stroke.0[1],
        style.stroke.0[2],
        style.stroke.0[3].max(200),
    ]);
    // Edges unless asked for none (stroke-width 0).
    let width = style.stroke_width_px;
    for r in rings {
        let n = r.len();
        for i in 0..n {
            let (a, b) = (r[i], r[(i + 1) % n]);
            let quad = [at(a, lower), at(b, lower), at(b, upper), at(a, upper)];
            chunks.triangles(
                &[quad[0], quad[1], quad[2], quad[0], quad[2], quad[3]],
                id,
                fill,
            );
        }
        if width <= 0.0 {
            continue;
        }
        // Vertical edges at the polygon's own vertices (not the densified ones).
        for c in corners.iter().flatten() {
            chunks.line(&[at(*c, lower), at(*c, upper)], id, edge, width);
        }
        for h in [lower, upper] {
            let mut pts: Vec<DVec3> = r.iter().map(|&p| at(p, h)).collect();
            pts.push(at(r[0], h));
            chunks.line(&pts, id, edge, width);
        }
        // Where it stands on the ground (from the surface up), its footprint on the terrain.
        if lower <= 0.0 && upper > 0.0 {
            let mut pts: Vec<[f64; 2]> = r.iter().map(|p| [p[0], p[1]]).collect();
            pts.push([r[0][0], r[0][1]]);
            let b = Bbox::of(pts.iter().copied());
            draped.lines.push(DrapedLine {
                pts,
                bbox: b,
                colour: edge,
                width_px: width,
            });
        }
    }
    let world = |p: Position| at(p, p[2]);
    for h in [lower, upper] {
        cap(rings, h, fill, id, &world, chunks);
    }
}

/// A polygon at height `h`, in triangles of at most [`CAP_STEP_DEG`] a side.
fn cap(
    rings: &[Vec<Position>],
    h: f64,
    colour: Rgba,
    id: u32,
    world: &dyn Fn(Position) -> DVec3,
    chunks: &mut ChunkWriter,
) {
    let out: Vec<DVec3> = shape::tessellate(rings, CAP_STEP_DEG)
        .iter()
        .flat_map(|t| t.map(|p| world([p[0], p[1], h])))
        .collect();
    chunks.triangles(&out, id, colour);
}

/// Splits geometry at altitude into chunks of at most [`CHUNK_EXTENT_M`].
#[derive(Default)]
struct ChunkWriter {
    done: Vec<Chunk>,
    current: Option<Chunk>,
}

impl ChunkWriter {
    fn chunk_for(&mut self, p: DVec3) -> &mut Chunk {
        let fits = self
            .current
            .as_ref()
            .is_some_and(|c| (p - c.origin).abs().max_element() < CHUNK_EXTENT_M);
        if !fits {
            if let Some(c) = self.current.take() {
                self.done.push(c);
            }
            self.current = Some(Chunk {
                origin: p,
                ..Chunk::default()
            });
        }
        self.current.get_or_insert_with(Chunk::default)
    }

    fn line(&mut self, pts: &[DVec3], id: u32, colour: Rgba, width: f32) {
        for w in pts.windows(2) {
            let c = self.chunk_for(w[0]);
            let (a, b) = (w[0] - c.origin, w[1] - c.origin);
            c.lines.push(LineInstance::segment(a, b, id, colour, width));
        }
    }

    fn point(&mut self, p: DVec3, id: u32, colour: Rgba, outline: Rgba, size: f32, square: bool) {
        let c = self.chunk_for(p);
        c.lines.push(LineInstance::point(
            p - c.origin,
            id,
            colour,
            outline,
            size,
            MARKER_OUTLINE_PX,
            square,
        ));
    }

    fn triangles(&mut self, pts: &[DVec3], id: u32, colour: Rgba) {
        for t in pts.chunks_exact(3) {
            let c = self.chunk_for(t[0]);
            for &p in t {
                c.fills
                    .push(FillVertex::new(p - c.origin, 0, colour, id, false));
            }
        }
    }

    fn finish(mut self) -> Vec<Chunk> {
        self.done.extend(self.current.take());
        self.done
    }
}

/// The drape surface of a tile's mesh (its surface triangles, positions relative to its
/// centre).
pub(crate) fn surface(mesh: &TileMesh, rect_deg: [f64; 4]) -> DrapeSurface {
    let surface_vertices = mesh
        .indices
        .iter()
        .take(mesh.surface_triangles as usize * 3)
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let verts = &mesh.vertices[..surface_vertices.min(mesh.vertices.len())];
    let uv = verts
        .iter()
        .map(|v| {
            let (u, w) = (v.uv & 0xffff, v.uv >> 16);
            [f64::from(u) / 65535.0, f64::from(w) / 65535.0]
        })
        .collect();
    let positions = verts
        .iter()
        .map(|v| {
            DVec3::new(
                f64::from(v.position[0]),
                f64::from(v.position[1]),
                f64::from(v.position[2]),
            )
        })
        .collect();
    let triangles = mesh
        .indices
        .chunks_exact(3)
        .take(mesh.surface_triangles as usize)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    DrapeSurface::new(rect_deg, uv, positions, triangles)
}

/// Instances one tile draws for the draped geometry of `features` (id, draped part), at
/// anchor 0 (the caller sets the tile's anchor).
#[derive(Clone, Debug, Default)]
pub(crate) struct TileDrape {
    pub lines: Vec<LineInstance>,
    pub fills: Vec<FillVertex>,
    pub points: Vec<LineInstance>,
}

impl TileDrape {
    pub(crate) fn add(&mut self, surface: &DrapeSurface, id: u32, d: &Draped) {
        let rect = surface.rect_deg();
        let mut segs = Vec::new();
        for l in &d.lines {
            if !l.bbox.overlaps(rect) {
                continue;
            }
            for shift in surface.shifts(l.bbox.lon[0], l.bbox.lon[1]) {
                segs.clear();
                surface.drape_line(&l.pts, shift, &mut segs);
                self.lines.extend(
                    segs.iter()
                        .map(|s| LineInstance::segment(s[0], s[1], id, l.colour, l.width_px)),
                );
            }
        }
        let mut tris = Vec::new();
        for f in &d.fills {
            if !f.bbox.overlaps(rect) {
                continue;
            }
            let colour = f.colour;
            for shift in surface.shifts(f.bbox.lon[0], f.bbox.lon[1]) {
                for t in &f.triangles {
                    let tb = Bbox::of(t.iter().map(|p| [p[0] + shift, p[1]]));
                    if !tb.overlaps(rect) {
                        continue;
                    }
                    tris.clear();
                    surface.drape_triangle(*t, shift, &mut tris);
                    for tri in &tris {
                        for &p in tri {
                            self.fills.push(FillVertex::new(p, 0, colour, id, true));
                        }
                    }
                }
            }
        }
        for p in &d.points {
            let [lon, lat] = p.at;
            for shift in surface.shifts(lon, lon) {
                if let Some(at) = surface.point(lon, lat, shift) {
                    self.points.push(LineInstance::point(
                        at,
                        id,
                        p.colour,
                        p.outline,
                        p.size_px,
                        MARKER_OUTLINE_PX,
                        p.square,
                    ));
                }
            }
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.lines.is_empty() && self.fills.is_empty() && self.points.is_empty()
    }
}
