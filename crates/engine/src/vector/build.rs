//! CPU geometry of the vector overlay: what each feature becomes (draped lon/lat geometry,
//! or ECEF geometry at altitude in chunks with their own origin), and the instances a drawn
//! tile gets from the draped part.

use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_terrain::{MorphVertex, TileMesh};
use globus_vector::shape::{self, Position, Straight};
use globus_vector::{Clamp, DrapeSurface, DrapedSegment, Feature, LineIndex, Rgba, Selection};

use super::gpu::{FillVertex, LineInstance, LineLook, RunEnd, push_run};

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

/// A line is drawn in a tile simplified to this fraction of the tile's height (a drawn tile
/// is at most a few hundred pixels tall once its colour texels meet the error bound, so
/// this is about a tenth of a pixel)...
const LINE_TOLERANCE_OF_TILE: f64 = 1.0 / 4096.0;
/// ...and to no more vertices near the tile than this (the tolerance is raised for the
/// lines that would have more: a million-vertex line over a tile draws in it as well as a
/// tile's few hundred pixels can show it, in a bounded number of instances).
const MAX_LINE_VERTICES_PER_TILE: usize = 4096;

/// Width of the outline drawn round point symbols, pixels.
const MARKER_OUTLINE_PX: f32 = 1.5;

/// Geometry draped on the terrain, in unwrapped longitude/latitude degrees.
#[derive(Clone, Debug, Default)]
pub(crate) struct Draped {
    pub lines: Vec<DrapedLine>,
    pub fills: Vec<DrapedFill>,
    pub points: Vec<DrapedPoint>,
}

/// A line to drape: its densified positions, metres along it at each, bounds and look.
#[derive(Clone, Debug)]
pub(crate) struct DrapedLine {
    pub pts: Vec<[f64; 2]>,
    pub along: Vec<f64>,
    pub bbox: Bbox,
    pub look: LineLook,
    /// A ring: it has no ends to cap.
    pub closed: bool,
    /// Its vertices ranked for simplification, and their blocks' bounds.
    pub index: LineIndex,
}

impl DrapedLine {
    /// The line through `pts` (degrees) on `ellipsoid`.
    fn new(pts: Vec<[f64; 2]>, ellipsoid: &Ellipsoid, look: LineLook, closed: bool) -> Self {
        let on = |p: &[f64; 2]| {
            ellipsoid.cartographic_to_ecef(Cartographic::new(
                p[0].to_radians(),
                p[1].to_radians(),
                0.0,
            ))
        };
        let world: Vec<DVec3> = pts.iter().map(on).collect();
        Self {
            bbox: Bbox::of(pts.iter().copied()),
            along: cumulative_length(&world),
            index: LineIndex::new(&pts),
            pts,
            look,
            closed,
        }
    }
}

/// Metres along a polyline at each of its points (chords: densified lines are within a
/// metre of their curves).
fn cumulative_length(pts: &[DVec3]) -> Vec<f64> {
    let mut total = 0.0;
    let mut out = Vec::with_capacity(pts.len());
    for (i, p) in pts.iter().enumerate() {
        if i > 0 {
            total += (*p - pts[i - 1]).length();
        }
        out.push(total);
    }
    out
}

/// A fill to drape: its tessellated triangles (or, for a polygon of more than
/// [`BIG_FILL_VERTICES`], its ranked rings, simplified, cut and tessellated per tile), bounds
/// and colour.
#[derive(Clone, Debug)]
pub(crate) struct DrapedFill {
    pub triangles: Vec<[[f64; 2]; 3]>,
    /// Closed rings (exterior first, holes beside it) and their rankings.
    pub rings: Vec<(Vec<[f64; 2]>, LineIndex)>,
    pub bbox: Bbox,
    pub colour: Rgba,
}

/// Polygons with more vertices than this are simplified and cut per tile like lines (at
/// most [`MAX_FILL_VERTICES_PER_TILE`] in a tile); smaller ones are tessellated once.
const BIG_FILL_VERTICES: usize = 4096;
const MAX_FILL_VERTICES_PER_TILE: usize = 16_384;

/// A point symbol on the ground.
#[derive(Clone, Debug)]
pub(crate) struct DrapedPoint {
    pub at: [f64; 2],
    pub colour: Rgba,
    pub outline: Rgba,
    pub size_px: f32,
    pub square: bool,
    /// Icon layer plus one (0: the symbol).
    pub icon: u32,
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

/// Builds a feature's geometry for a body and exaggeration; `ground_m(lon_deg, lat_deg)` is
/// the terrain's height (true metres) where heights are relative to it and walls end;
/// `icon_of(path)` the icon layer plus one of a PNG (0 if it cannot be drawn).
pub(crate) fn build(
    feature: &Feature,
    id: u32,
    ellipsoid: &Ellipsoid,
    exaggeration: f64,
    ground_m: &dyn Fn(f64, f64) -> f64,
    icon_of: &mut dyn FnMut(&str) -> u32,
) -> Built {
    let style = &feature.style;
    let mut out = Built::default();
    let relative = style.clamp == Clamp::Relative;
    // Heights above the ellipsoid (relative ones raised by the ground under them), drawn
    // raised by the exaggeration.
    let world = |p: Position| {
        let h = if relative {
            p[2] + ground_m(p[0], p[1])
        } else {
            p[2]
        };
        ellipsoid.cartographic_to_ecef(Cartographic::new(
            p[0].to_radians(),
            p[1].to_radians(),
            h * exaggeration,
        ))
    };
    let ground = style.clamp == Clamp::Ground;
    let mut chunks = ChunkWriter::default();
    let stroke = Stroke {
        look: LineLook::of(style),
        path: style.path,
        id,
    };
    for line in &feature.lines {
        if style.wall || style.corridor.is_some() {
            let tolerance = style
                .corridor
                .map_or(PATH_TOLERANCE_M, |(r, _)| (r / 100.0).max(PATH_TOLERANCE_M));
            let d = shape::densify(
                ellipsoid,
                line,
                false,
                style.path,
                Straight::Chord,
                tolerance,
            );
            if let Some((radius, half_height)) = style.corridor {
                corridor(
                    &d,
                    radius,
                    half_height * exaggeration,
                    style.fill,
                    id,
                    ellipsoid,
                    &world,
                    &mut chunks,
                );
            }
            if style.wall {
                wall(
                    &d,
                    style.fill,
                    id,
                    &world,
                    &|p| {
                        let h = ground_m(p[0], p[1]) - WALL_FOOT_M;
                        ellipsoid.cartographic_to_ecef(Cartographic::new(
                            p[0].to_radians(),
                            p[1].to_radians(),
                            h * exaggeration,
                        ))
                    },
                    &mut chunks,
                );
            }
        }
        if style.stroke_width_px <= 0.0 || style.stroke.0[3] == 0 {
            continue;
        }
        stroke.add(
            line,
            (ground, false),
            ellipsoid,
            &world,
            &mut chunks,
            &mut out.draped,
        );
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
            if ground && rings.iter().map(Vec::len).sum::<usize>() > BIG_FILL_VERTICES {
                let flat = shape::flatten_rings(&rings);
                let b = Bbox::of(flat.iter().flatten().copied());
                let ranked = flat
                    .into_iter()
                    .map(|mut r| {
                        r.push(r[0]);
                        let index = LineIndex::new(&r);
                        (r, index)
                    })
                    .collect();
                out.draped.fills.push(DrapedFill {
                    triangles: Vec::new(),
                    rings: ranked,
                    bbox: b,
                    colour: style.fill,
                });
            } else if ground {
                let tris = shape::tessellate(&rings, DRAPED_CELL_DEG);
                let b = Bbox::of(tris.iter().flatten().copied());
                out.draped.fills.push(DrapedFill {
                    triangles: tris,
                    rings: Vec::new(),
                    bbox: b,
                    colour: style.fill,
                });
            } else {
                let h = polygon[0][0][2];
                cap(&rings, h, style.fill, id, &world, &mut chunks);
            }
        }
        if style.stroke_width_px > 0.0 && style.stroke.0[3] > 0 {
            for r in polygon {
                let mut closed = r.clone();
                closed.push(r[0]);
                stroke.add(
                    &closed,
                    (ground, true),
                    ellipsoid,
                    &world,
                    &mut chunks,
                    &mut out.draped,
                );
            }
        }
    }
    let icon = style.marker_icon.as_deref().map_or(0, icon_of);
    // An icon fills the symbol's square.
    let square = style.marker_square || icon != 0;
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
                square,
                icon,
            });
        } else {
            chunks.point(world(p), id, colour, outline, size, square, icon);
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

/// How a line is stroked.
struct Stroke {
    look: LineLook,
    path: globus_vector::PathKind,
    id: u32,
}

impl Stroke {
    /// Adds a line (a ring if `closed`): draped (densified linear in longitude/latitude,
    /// cut along the tiles when drawn) or at altitude (densified in 3D chords, in chunks).
    fn add(
        &self,
        pts: &[Position],
        (ground, closed): (bool, bool),
        ellipsoid: &Ellipsoid,
        world: &dyn Fn(Position) -> DVec3,
        chunks: &mut ChunkWriter,
        draped: &mut Draped,
    ) {
        let straight = if ground {
            Straight::LonLat
        } else {
            Straight::Chord
        };
        let d = shape::densify(ellipsoid, pts, false, self.path, straight, PATH_TOLERANCE_M);
        if ground {
            let pts: Vec<[f64; 2]> = d.iter().map(|p| [p[0], p[1]]).collect();
            draped
                .lines
                .push(DrapedLine::new(pts, ellipsoid, self.look, closed));
        } else {
            let w: Vec<DVec3> = d.iter().map(|&p| world(p)).collect();
            chunks.line(&w, self.id, &self.look, closed);
        }
    }
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
    let look = LineLook {
        colour: edge,
        ..LineLook::of(style)
    };
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
            chunks.line(&[at(*c, lower), at(*c, upper)], id, &look, false);
        }
        for h in [lower, upper] {
            let mut pts: Vec<DVec3> = r.iter().map(|&p| at(p, h)).collect();
            pts.push(at(r[0], h));
            chunks.line(&pts, id, &look, true);
        }
        // Where it stands on the ground (from the surface up), its footprint on the terrain.
        if lower <= 0.0 && upper > 0.0 {
            let mut pts: Vec<[f64; 2]> = r.iter().map(|p| [p[0], p[1]]).collect();
            pts.push([r[0][0], r[0][1]]);
            draped
                .lines
                .push(DrapedLine::new(pts, ellipsoid, look, true));
        }
    }
    let world = |p: Position| at(p, p[2]);
    for h in [lower, upper] {
        cap(rings, h, fill, id, &world, chunks);
    }
}

/// How far below the ground a wall reaches (hidden there), metres: no gap where the drawn
/// terrain is a little lower than the loaded heights say.
const WALL_FOOT_M: f64 = 50.0;

/// Sides of a corridor's cross-section.
const CORRIDOR_SIDES: usize = 16;

/// Largest turn, radians, between two rings of a corridor's joint.
const CORRIDOR_JOINT_STEP_RAD: f64 = 0.26;

/// A curtain from a line down to the ground (`foot` gives each vertex's bottom).
fn wall(
    pts: &[Position],
    colour: Rgba,
    id: u32,
    world: &dyn Fn(Position) -> DVec3,
    foot: &dyn Fn(Position) -> DVec3,
    chunks: &mut ChunkWriter,
) {
    let mut tris = Vec::with_capacity(pts.len() * 6);
    for w in pts.windows(2) {
        let (a, b) = (world(w[0]), world(w[1]));
        let (fa, fb) = (foot(w[0]), foot(w[1]));
        tris.extend_from_slice(&[fa, fb, b, fa, b, a]);
    }
    chunks.triangles(&tris, id, colour);
}

/// A tube of elliptic cross-section (`radius` across, `half_height` up) along a line, its
/// rings swept round every turn in steps of at most [`CORRIDOR_JOINT_STEP_RAD`], so it stays
/// round through sharp turns (where mitred rings would fold), closed at both ends.
#[allow(clippy::too_many_arguments)]
fn corridor(
    pts: &[Position],
    radius: f64,
    half_height: f64,
    colour: Rgba,
    id: u32,
    ellipsoid: &Ellipsoid,
    world: &dyn Fn(Position) -> DVec3,
    chunks: &mut ChunkWriter,
) {
    let centres: Vec<DVec3> = pts.iter().map(|&p| world(p)).collect();
    let dirs: Vec<DVec3> = centres
        .windows(2)
        .filter_map(|w| (w[1] - w[0]).try_normalize())
        .collect();
    if dirs.is_empty() || centres.len() != dirs.len() + 1 {
        return;
    }
    // Rings: (centre, direction) in order along the tube.
    let mut rings: Vec<(DVec3, DVec3)> = Vec::new();
    for (i, &c) in centres.iter().enumerate() {
        let d_in = if i == 0 { dirs[0] } else { dirs[i - 1] };
        let d_out = if i == dirs.len() { d_in } else { dirs[i] };
        let turn = d_in.angle_between(d_out);
        let steps = (turn / CORRIDOR_JOINT_STEP_RAD).ceil().max(1.0) as usize;
        if turn < 1e-6 {
            rings.push((c, d_in));
            continue;
        }
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let d = slerp(d_in, d_out, t);
            rings.push((c, d));
        }
    }
    let ring_points = |(c, d): (DVec3, DVec3)| -> Vec<DVec3> {
        let up = ellipsoid.geodetic_normal(c).unwrap_or(DVec3::Z);
        let side = d
            .cross(up)
            .try_normalize()
            .unwrap_or_else(|| d.any_orthonormal_vector());
        let vup = side.cross(d);
        (0..CORRIDOR_SIDES)
            .map(|k| {
                let phi = std::f64::consts::TAU * k as f64 / CORRIDOR_SIDES as f64;
                c + side * (radius * phi.cos()) + vup * (half_height * phi.sin())
            })
            .collect()
    };
    let all: Vec<Vec<DVec3>> = rings.iter().map(|&r| ring_points(r)).collect();
    let mut tris = Vec::new();
    for w in all.windows(2) {
        for k in 0..CORRIDOR_SIDES {
            let k2 = (k + 1) % CORRIDOR_SIDES;
            let (a, b, c, d) = (w[0][k], w[0][k2], w[1][k2], w[1][k]);
            tris.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    for (ring, (c, _)) in [
        (&all[0], rings[0]),
        (&all[all.len() - 1], rings[rings.len() - 1]),
    ] {
        for k in 0..CORRIDOR_SIDES {
            tris.extend_from_slice(&[c, ring[k], ring[(k + 1) % CORRIDOR_SIDES]]);
        }
    }
    chunks.triangles(&tris, id, colour);
}

/// Spherical interpolation between unit vectors.
fn slerp(a: DVec3, b: DVec3, t: f64) -> DVec3 {
    let angle = a.angle_between(b);
    if angle < 1e-9 {
        return a;
    }
    let s = angle.sin();
    (a * ((1.0 - t) * angle).sin() / s + b * (t * angle).sin() / s).normalize_or(a)
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

    /// A polyline (a ring if `closed`), in runs of joined segments, one per chunk it
    /// passes through.
    fn line(&mut self, pts: &[DVec3], id: u32, look: &LineLook, closed: bool) {
        let along = cumulative_length(pts);
        let mut local = Vec::new();
        let mut i = 0;
        while i + 1 < pts.len() {
            let c = self.chunk_for(pts[i]);
            let origin = c.origin;
            // The run goes on while its segments start inside this chunk.
            let mut j = i + 1;
            while j + 1 < pts.len() && (pts[j] - origin).abs().max_element() < CHUNK_EXTENT_M {
                j += 1;
            }
            local.clear();
            local.extend(pts[i..=j].iter().map(|&p| p - origin));
            let end = |line_end: bool| {
                if line_end {
                    RunEnd::Line
                } else {
                    RunEnd::Break
                }
            };
            let ends = (end(i == 0 && !closed), end(j + 1 == pts.len() && !closed));
            push_run(&mut c.lines, &local, &along[i..=j], &[], id, look, ends);
            i = j;
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn point(
        &mut self,
        p: DVec3,
        id: u32,
        colour: Rgba,
        outline: Rgba,
        size: f32,
        square: bool,
        icon: u32,
    ) {
        let c = self.chunk_for(p);
        c.lines.push(
            LineInstance::point(
                p - c.origin,
                id,
                colour,
                outline,
                size,
                MARKER_OUTLINE_PX,
                square,
            )
            .with_icon(icon),
        );
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

/// The drape surface of a tile's mesh: its surface triangles and skirt walls, positions
/// relative to its centre, and its vertices' morph heights (`morph`, one per vertex, else
/// none: see [`globus_terrain::MorphVertex`]).
pub(crate) fn surface(mesh: &TileMesh, rect_deg: [f64; 4], morph: &[MorphVertex]) -> DrapeSurface {
    let surface_count = mesh.surface_triangles as usize;
    let surface_vertices = mesh
        .indices
        .iter()
        .take(surface_count * 3)
        .copied()
        .max()
        .map_or(0, |m| m as usize + 1);
    let uv = mesh
        .vertices
        .iter()
        .map(|v| {
            let (u, w) = (v.uv & 0xffff, v.uv >> 16);
            [f64::from(u) / 65535.0, f64::from(w) / 65535.0]
        })
        .collect();
    let positions = mesh
        .vertices
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
        .take(surface_count)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    // Skirt walls are pairs of triangles over two edge vertices and the two skirt vertices
    // under them (same uv).
    let is_top = |i: u32| (i as usize) < surface_vertices;
    let edge_skirts = mesh.quadrants.edge_skirts();
    let skirts = mesh
        .indices
        .get(edge_skirts.start as usize..edge_skirts.end as usize)
        .unwrap_or_default()
        .chunks_exact(6)
        .filter_map(|q| {
            let mut top: Vec<u32> = q.iter().copied().filter(|&i| is_top(i)).collect();
            let mut bottom: Vec<u32> = q.iter().copied().filter(|&i| !is_top(i)).collect();
            top.sort_unstable();
            top.dedup();
            bottom.sort_unstable();
            bottom.dedup();
            let [a, b] = top[..] else { return None };
            let [s0, s1] = bottom[..] else { return None };
            let uv_of = |i: u32| mesh.vertices.get(i as usize).map(|v| v.uv);
            let under = |t: u32| {
                if uv_of(s0) == uv_of(t) {
                    Some(s0)
                } else if uv_of(s1) == uv_of(t) {
                    Some(s1)
                } else {
                    None
                }
            };
            Some([a, b, under(a)?, under(b)?])
        })
        .collect();
    DrapeSurface::new(rect_deg, uv, positions, triangles)
        .with_skirts(skirts)
        .with_lifts(morph.iter().map(|m| f64::from(m.dh_m)).collect())
}

/// A big fill's triangles over a tile (`rect`, at a whole-turn `shift` of the fill): its
/// rings simplified as lines are, cut to the tile (a hair beyond it) and tessellated.
fn cut_fill(f: &DrapedFill, rect: [f64; 4], shift: f64) -> Vec<[[f64; 2]; 3]> {
    let [w, s, e, n] = rect;
    let (mx, my) = ((e - w) * 0.01, (n - s) * 0.01);
    let clip = [w - shift - mx, s - my, e - shift + mx, n + my];
    let mut tolerance = (n - s) * LINE_TOLERANCE_OF_TILE;
    loop {
        let kept: Vec<Vec<[f64; 2]>> = f
            .rings
            .iter()
            .map(|(r, index)| {
                // Without the closing vertex (a ring's last is its first).
                (0..r.len() - 1)
                    .filter(|&i| f64::from(index.rank(i)) > tolerance)
                    .map(|i| r[i])
                    .collect()
            })
            .collect();
        let cut = shape::clip_rings(&kept, clip);
        let count: usize = cut.iter().map(Vec::len).sum();
        if count <= MAX_FILL_VERTICES_PER_TILE || tolerance > 360.0 {
            return shape::tessellate_flat(&cut, DRAPED_CELL_DEG);
        }
        tolerance *= 2.0;
    }
}

/// Buffers reused while a tile drapes its lines.
#[derive(Default)]
struct LineScratch {
    pts: Vec<[f64; 2]>,
    segs: Vec<DrapedSegment>,
    run: Vec<DVec3>,
    lifts: Vec<f64>,
    metres: Vec<f64>,
}

/// Instances one tile draws for the draped geometry of `features` (id, draped part), at
/// anchor 0 (the caller sets the tile's anchor), kept apart by the quadrant of the tile they
/// lie in (bit order of [`globus_tiling::Quadrants`]): a tile drawn over only some of its
/// quadrants, beside finer children, draws only those quadrants' pieces, so a line is not
/// drawn twice, on the parent and on the child.
#[derive(Clone, Debug, Default)]
pub(crate) struct TileDrape {
    pub quadrants: [QuadrantDrape; 4],
}

/// The draped instances of one quadrant of a tile.
#[derive(Clone, Debug, Default)]
pub(crate) struct QuadrantDrape {
    pub lines: Vec<LineInstance>,
    pub fills: Vec<FillVertex>,
    pub points: Vec<LineInstance>,
}

impl QuadrantDrape {
    /// Its line instances, then its points'.
    pub(crate) fn line_instances(&self) -> impl Iterator<Item = &LineInstance> {
        self.lines.iter().chain(&self.points)
    }
}

impl TileDrape {
    pub(crate) fn add(&mut self, surface: &DrapeSurface, id: u32, d: &Draped) {
        let rect = surface.rect_deg();
        let tolerance = (rect[3] - rect[1]) * LINE_TOLERANCE_OF_TILE;
        let (mut selection, mut scratch) = (Selection::default(), LineScratch::default());
        for l in &d.lines {
            if !l.bbox.overlaps(rect) {
                continue;
            }
            for shift in surface.shifts(l.bbox.lon[0], l.bbox.lon[1]) {
                let [w, s, e, n] = rect;
                l.index.select(
                    [w - shift, s, e - shift, n],
                    tolerance,
                    MAX_LINE_VERTICES_PER_TILE,
                    &mut selection,
                );
                for run in &selection.runs {
                    let kept = &selection.vertices[run.clone()];
                    self.add_run(surface, id, l, kept, shift, &mut scratch);
                }
            }
        }
        let mut tris = Vec::new();
        for f in &d.fills {
            if !f.bbox.overlaps(rect) {
                continue;
            }
            let colour = f.colour;
            for shift in surface.shifts(f.bbox.lon[0], f.bbox.lon[1]) {
                let cut;
                let triangles = if f.rings.is_empty() {
                    &f.triangles
                } else {
                    cut = cut_fill(f, rect, shift);
                    &cut
                };
                for t in triangles {
                    let tb = Bbox::of(t.iter().map(|p| [p[0] + shift, p[1]]));
                    if !tb.overlaps(rect) {
                        continue;
                    }
                    tris.clear();
                    surface.drape_triangle(*t, shift, &mut tris);
                    for tri in &tris {
                        let fills = &mut self.quadrants[usize::from(tri.quadrant)].fills;
                        for &p in &tri.at {
                            fills.push(FillVertex::new(p.at, 0, colour, id, true).lifted(p.lift_m));
                        }
                    }
                }
            }
        }
        for p in &d.points {
            let [lon, lat] = p.at;
            for shift in surface.shifts(lon, lon) {
                if let Some(at) = surface.point(lon, lat, shift) {
                    let q = usize::from(surface.quadrant(lon, lat, shift));
                    self.quadrants[q].points.push(
                        LineInstance::point(
                            at.at,
                            id,
                            p.colour,
                            p.outline,
                            p.size_px,
                            MARKER_OUTLINE_PX,
                            p.square,
                        )
                        .with_icon(p.icon)
                        .lifted(at.lift_m),
                    );
                }
            }
        }
    }

    /// Drapes one run of a line's kept vertices (indices into `l.pts`).
    fn add_run(
        &mut self,
        surface: &DrapeSurface,
        id: u32,
        l: &DrapedLine,
        kept: &[u32],
        shift: f64,
        scratch: &mut LineScratch,
    ) {
        let LineScratch {
            pts,
            segs,
            run,
            lifts,
            metres,
        } = scratch;
        pts.clear();
        pts.extend(kept.iter().map(|&i| l.pts[i as usize]));
        segs.clear();
        surface.drape_line(pts, shift, segs);
        // Metres along the whole line at a fractional index into `kept`.
        let at = |f: f64| {
            let i = (f.floor().max(0.0) as usize).min(kept.len().saturating_sub(2));
            let t = f - i as f64;
            let (a, b) = (kept[i] as usize, kept[(i + 1).min(kept.len() - 1)] as usize);
            l.along[a] + (l.along[b] - l.along[a]) * t
        };
        let last_vertex = (l.pts.len() - 1) as u32;
        let (starts, ends) = (
            !l.closed && kept[0] == 0,
            !l.closed && kept[kept.len() - 1] == last_vertex,
        );
        let last = (kept.len() - 1) as f64;
        // Runs of pieces that meet end to end within one quadrant. Where a line crosses a
        // midline its run breaks into the next quadrant's, the two ends cut square and
        // abutting (a seam), and so where it crosses the tile's border, abutting the
        // neighbour's run; where pieces do not meet inside the tile (a gap in the kept
        // vertices), the ends are drawn round.
        let meets = |x: &DrapedSegment, y: &DrapedSegment| x.along[1] == y.along[0];
        let mut first = 0usize;
        for piece in segs.chunk_by(|x: &DrapedSegment, y| meets(x, y) && x.quadrant == y.quadrant) {
            let (before, after) = (
                first.checked_sub(1).and_then(|i| segs.get(i)),
                segs.get(first + piece.len()),
            );
            first += piece.len();
            run.clear();
            lifts.clear();
            metres.clear();
            run.push(piece[0].a);
            run.extend(piece.iter().map(|s| s.b));
            lifts.push(piece[0].lift_m[0]);
            lifts.extend(piece.iter().map(|s| s.lift_m[1]));
            metres.push(at(piece[0].along[0]));
            metres.extend(piece.iter().map(|s| at(s.along[1])));
            let (head, tail) = (&piece[0], &piece[piece.len() - 1]);
            let run_ends = (
                if starts && head.along[0] == 0.0 {
                    RunEnd::Line
                } else if head.on_border[0] || before.is_some_and(|b| meets(b, head)) {
                    RunEnd::Seam
                } else {
                    RunEnd::Break
                },
                if ends && tail.along[1] == last {
                    RunEnd::Line
                } else if tail.on_border[1] || after.is_some_and(|a| meets(tail, a)) {
                    RunEnd::Seam
                } else {
                    RunEnd::Break
                },
            );
            let lines = &mut self.quadrants[usize::from(head.quadrant)].lines;
            push_run(lines, run, metres, lifts, id, &l.look, run_ends);
        }
    }

    /// Drops the pieces of the features with these pick ids.
    pub(crate) fn retain_not(&mut self, picks: &[u32]) {
        for q in &mut self.quadrants {
            q.lines.retain(|l| !picks.contains(&l.id));
            q.points.retain(|l| !picks.contains(&l.id));
            q.fills.retain(|f| !picks.contains(&f.id));
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.quadrants
            .iter()
            .all(|q| q.lines.is_empty() && q.fills.is_empty() && q.points.is_empty())
    }

    /// Bytes of its instances.
    pub(crate) fn bytes(&self) -> usize {
        self.quadrants
            .iter()
            .map(|q| {
                (q.lines.len() + q.points.len()) * std::mem::size_of::<LineInstance>()
                    + q.fills.len() * std::mem::size_of::<FillVertex>()
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance from `p` to the polyline `path`.
    fn distance_to(path: &[DVec3], p: DVec3) -> f64 {
        path.windows(2)
            .map(|w| {
                let d = w[1] - w[0];
                let t = ((p - w[0]).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                (w[0] + d * t - p).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn a_corridor_keeps_its_radius_through_a_hairpin() {
        let e = Ellipsoid::WGS84;
        let world = |p: Position| {
            e.cartographic_to_ecef(Cartographic::new(
                p[0].to_radians(),
                p[1].to_radians(),
                p[2],
            ))
        };
        // Out east, then back west-north-west: a 160 degree turn.
        let pts = [
            [7.0, 46.0, 3000.0],
            [7.5, 46.0, 3000.0],
            [7.0, 46.09, 3000.0],
        ];
        let radius = 5.0 * globus_vector::style::NAUTICAL_MILE_M;
        let mut chunks = ChunkWriter::default();
        corridor(
            &pts,
            radius,
            radius,
            Rgba([0, 255, 0, 100]),
            1,
            &e,
            &world,
            &mut chunks,
        );
        let path: Vec<DVec3> = pts.iter().map(|&p| world(p)).collect();
        let chunks = chunks.finish();
        let (mut n, mut outside_at_turn) = (0, 0.0f64);
        for c in &chunks {
            for v in &c.fills {
                let p = c.origin
                    + DVec3::new(
                        f64::from(v.position[0]),
                        f64::from(v.position[1]),
                        f64::from(v.position[2]),
                    );
                let d = distance_to(&path, p);
                // Never beyond the radius (a mitred joint would spike to r / cos(80 deg)).
                assert!(
                    d <= radius * 1.001,
                    "a vertex {d:.0} m from the path, radius {radius:.0}"
                );
                if (p - path[1]).length() < radius * 1.5 {
                    outside_at_turn = outside_at_turn.max(d);
                }
                n += 1;
            }
        }
        // Round on the outside of the turn: the swept rings reach the full radius there.
        assert!(
            outside_at_turn > radius * 0.99,
            "{outside_at_turn:.0} m round the turn"
        );
        assert!(n > 16 * 6 * 4, "{n} vertices");
    }

    #[test]
    fn a_wall_reaches_from_the_line_to_the_ground() {
        let e = Ellipsoid::WGS84;
        let at = |p: Position, h: f64| {
            e.cartographic_to_ecef(Cartographic::new(p[0].to_radians(), p[1].to_radians(), h))
        };
        let pts = [[7.0, 46.0, 3000.0], [7.1, 46.0, 3000.0]];
        let mut chunks = ChunkWriter::default();
        wall(
            &pts,
            Rgba([255, 0, 0, 100]),
            1,
            &|p| at(p, p[2]),
            &|p| at(p, 500.0),
            &mut chunks,
        );
        let chunks = chunks.finish();
        let heights: Vec<f64> = chunks
            .iter()
            .flat_map(|c| {
                c.fills.iter().map(move |v| {
                    let p = c.origin
                        + DVec3::new(
                            f64::from(v.position[0]),
                            f64::from(v.position[1]),
                            f64::from(v.position[2]),
                        );
                    e.ecef_to_cartographic(p).map_or(f64::NAN, |c| c.height_m)
                })
            })
            .collect();
        assert_eq!(heights.len(), 6);
        assert!(
            heights
                .iter()
                .all(|h| (h - 3000.0).abs() < 0.1 || (h - 500.0).abs() < 0.1),
            "{heights:?}"
        );
    }
}
