//! The aircraft shapes Globus ships, made by code at start-up: a light aircraft (high wing,
//! straight), a narrow-body and a wide-body airliner (swept wings, twin engines), and a
//! helicopter (rotor disc, tail boom), at their real sizes (Cessna 172, Airbus A320,
//! Boeing 777-300ER, Airbus H135).
//!
//! A mesh is a list of triangles with flat normals (a faceted look reads well at a few dozen
//! pixels), in model metres: `x` forward (the nose), `y` left, `z` up, the origin at the
//! aircraft's reference point (centre of the fuselage, about the wing). Shapes are lofts
//! (fuselage, nacelles, boom: rings of points joined by quads) and slabs (wings, tails: a
//! trapezoid with a thickness), so each is a few hundred triangles: thousands of aircraft
//! drawn as models stay within a frame.

use glam::Vec3;
use globus_traffic::AircraftKind;

/// Cells across a model's extent in its coarse level of detail ([`ModelMesh::simplified`]):
/// at the switch to the full mesh ([`MODEL_LOD_FULL_PX`]) a cell is under 3 pixels.
pub const MODEL_LOD_CELLS: u32 = 24;
/// On-screen size (pixels, of the model's largest extent) from which the full mesh is drawn;
/// below it, the coarse level.
pub const MODEL_LOD_FULL_PX: f64 = 64.0;

/// One aircraft shape: triangles with flat normals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelMesh {
    /// The accent given to triangles being added.
    accent: u8,
    /// Three per triangle, metres (`x` forward, `y` left, `z` up).
    pub positions: Vec<[f32; 3]>,
    /// One per position (the triangle's), unit length.
    pub normals: Vec<[f32; 3]>,
    /// One per position: 0 for the airframe (drawn white), 1 for accents (tail fin,
    /// nacelles, rotor) drawn in the aircraft's colour, so the model matches its symbol and
    /// trail.
    pub accents: Vec<u8>,
}

impl ModelMesh {
    /// Triangles.
    pub fn triangles(&self) -> usize {
        self.positions.len() / 3
    }

    /// The largest extent (length or span), metres: what the minimum on-screen size applies
    /// to.
    pub fn extent_m(&self) -> f32 {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f32::max)
    }

    /// The same shape with fewer triangles, for when it is small on screen: vertex
    /// clustering (Rossignac and Borrel 1993) on a grid of `cells` cells across the largest
    /// extent. Every corner moves to the mean of the corners in its cell; triangles whose
    /// corners share a cell, or that repeat one already kept (a thin slab's two faces), go.
    /// Written here rather than taken from meshoptimizer: the shapes are flat-shaded
    /// triangle soups of a few hundred triangles (for which clustering is all a level of
    /// detail needs), and its edge collapse would want them welded first and a C++ build.
    pub fn simplified(&self, cells: u32) -> ModelMesh {
        let extent = self.extent_m();
        if self.positions.is_empty() || extent <= 0.0 || cells == 0 {
            return self.clone();
        }
        let mut lo = [f32::INFINITY; 3];
        for p in &self.positions {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
            }
        }
        let cell = extent / cells as f32;
        let key = |p: &[f32; 3]| -> [i32; 3] {
            [0, 1, 2].map(|i| ((p[i] - lo[i]) / cell).floor() as i32)
        };
        let mut means: rustc_hash::FxHashMap<[i32; 3], (Vec3, u32)> = Default::default();
        for p in &self.positions {
            let m = means.entry(key(p)).or_insert((Vec3::ZERO, 0));
            m.0 += Vec3::from(*p);
            m.1 += 1;
        }
        let mean = |k: &[i32; 3]| {
            means
                .get(k)
                .map_or([0.0; 3], |(sum, n)| (*sum / *n as f32).to_array())
        };
        let mut kept: rustc_hash::FxHashSet<[[i32; 3]; 3]> = Default::default();
        let mut out = ModelMesh::default();
        for (t, accents) in self
            .positions
            .chunks_exact(3)
            .zip(self.accents.chunks_exact(3))
        {
            let keys = [key(&t[0]), key(&t[1]), key(&t[2])];
            if keys[0] == keys[1] || keys[1] == keys[2] || keys[0] == keys[2] {
                continue;
            }
            let mut sorted = keys;
            sorted.sort_unstable();
            if !kept.insert(sorted) {
                continue;
            }
            let [a, b, c] = keys.map(|k| mean(&k));
            out.push_triangle(a, b, c, accents[0] != 0);
        }
        out
    }

    /// A mesh of triangles (three positions each, model metres) with flat normals; those
    /// flagged `true` are accents. Degenerate triangles are left out.
    pub fn from_triangles(triangles: impl IntoIterator<Item = ([[f32; 3]; 3], bool)>) -> Self {
        let mut m = Self::default();
        for ([a, b, c], accent) in triangles {
            m.push_triangle(a, b, c, accent);
        }
        m
    }

    pub(crate) fn push_triangle(&mut self, a: [f32; 3], b: [f32; 3], c: [f32; 3], accent: bool) {
        self.accent = u8::from(accent);
        self.triangle(a, b, c);
        self.accent = 0;
    }

    /// Paints what is added next as an accent (or not).
    fn accent(&mut self, on: bool) -> &mut Self {
        self.accent = u8::from(on);
        self
    }

    fn triangle(&mut self, a: [f32; 3], b: [f32; 3], c: [f32; 3]) {
        let (va, vb, vc) = (Vec3::from(a), Vec3::from(b), Vec3::from(c));
        let n = (vb - va).cross(vc - va);
        if n.length() <= 1e-9 {
            return;
        }
        let n = n.normalize().to_array();
        self.positions.extend([a, b, c]);
        self.normals.extend([n; 3]);
        self.accents.extend([self.accent; 3]);
    }

    fn quad(&mut self, a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3]) {
        self.triangle(a, b, c);
        self.triangle(a, c, d);
    }

    /// A loft along `x`: each station is (x, centre z, half width, half height), joined by
    /// rings of `sides` points; ends closed.
    fn loft(&mut self, stations: &[[f32; 4]], sides: usize, y_offset: f32) {
        let ring = |s: &[f32; 4]| -> Vec<[f32; 3]> {
            (0..sides)
                .map(|k| {
                    let a = k as f32 / sides as f32 * std::f32::consts::TAU;
                    [s[0], y_offset + s[2] * a.cos(), s[1] + s[3] * a.sin()]
                })
                .collect()
        };
        let rings: Vec<Vec<[f32; 3]>> = stations.iter().map(ring).collect();
        for w in rings.windows(2) {
            for k in 0..sides {
                let k1 = (k + 1) % sides;
                self.quad(w[0][k], w[0][k1], w[1][k1], w[1][k]);
            }
        }
        for (r, s) in [
            (&rings[0], &stations[0]),
            (&rings[rings.len() - 1], &stations[stations.len() - 1]),
        ] {
            let centre = [s[0], y_offset, s[1]];
            for k in 0..sides {
                self.triangle(centre, r[(k + 1) % sides], r[k]);
            }
        }
    }

    /// A slab: the quadrilateral `root_front, root_back, tip_back, tip_front` given as its
    /// mid-surface, thickened by `half_thick` along `thick_axis` (2: z for wings, 1: y for
    /// fins).
    fn slab(&mut self, outline: [[f32; 3]; 4], half_thick: f32, thick_axis: usize) {
        let off = |p: [f32; 3], s: f32| {
            let mut q = p;
            q[thick_axis] += s * half_thick;
            q
        };
        let top: Vec<[f32; 3]> = outline.iter().map(|&p| off(p, 1.0)).collect();
        let bottom: Vec<[f32; 3]> = outline.iter().map(|&p| off(p, -1.0)).collect();
        self.quad(top[0], top[1], top[2], top[3]);
        self.quad(bottom[3], bottom[2], bottom[1], bottom[0]);
        for k in 0..4 {
            let k1 = (k + 1) % 4;
            self.quad(bottom[k], bottom[k1], top[k1], top[k]);
        }
    }

    /// A wing pair (or tailplane) mirrored about `y = 0`: root chord from `x_root` back by
    /// `root_chord`, tip at `half_span`, swept back by `sweep` metres at the tip's leading
    /// edge, at height `z` rising by `dihedral` metres at the tip.
    #[allow(clippy::too_many_arguments)]
    fn wings(
        &mut self,
        x_root: f32,
        root_chord: f32,
        tip_chord: f32,
        half_span: f32,
        sweep: f32,
        z: f32,
        dihedral: f32,
        half_thick: f32,
    ) {
        for side in [1.0f32, -1.0] {
            let tip_front = [x_root - sweep, side * half_span, z + dihedral];
            self.slab(
                [
                    [x_root, side * 0.3, z],
                    [x_root - root_chord, side * 0.3, z],
                    [tip_front[0] - tip_chord, tip_front[1], tip_front[2]],
                    tip_front,
                ],
                half_thick,
                2,
            );
        }
    }

    /// A vertical fin on the centre line: root from `x_root` back by `root_chord` at height
    /// `z`, tip `height` above, swept by `sweep`.
    fn fin(
        &mut self,
        x_root: f32,
        root_chord: f32,
        tip_chord: f32,
        z: f32,
        height: f32,
        sweep: f32,
    ) {
        let tip_front = [x_root - sweep, 0.0, z + height];
        self.slab(
            [
                [x_root, 0.0, z],
                [x_root - root_chord, 0.0, z],
                [tip_front[0] - tip_chord, 0.0, tip_front[2]],
                tip_front,
            ],
            (root_chord * 0.04).max(0.05),
            1,
        );
    }
}

/// A fuselage of length `length` and radius `r`: rounded nose, straight barrel, tail cone
/// rising to the fin.
fn fuselage(m: &mut ModelMesh, length: f32, r: f32, sides: usize) {
    let nose = length * 0.5;
    let tail = -length * 0.5;
    let stations = [
        [nose, -0.1 * r, 0.05 * r, 0.05 * r],
        [nose - 0.4 * r, -0.05 * r, 0.55 * r, 0.5 * r],
        [nose - 1.2 * r, 0.0, 0.9 * r, 0.88 * r],
        [nose - 2.5 * r, 0.0, r, r],
        [tail + length * 0.3, 0.0, r, r],
        [tail + length * 0.12, 0.35 * r, 0.6 * r, 0.55 * r],
        [tail, 0.7 * r, 0.12 * r, 0.2 * r],
    ];
    m.loft(&stations, sides, 0.0);
}

fn nacelle(m: &mut ModelMesh, x: f32, y: f32, z: f32, length: f32, r: f32) {
    let stations = [
        [x, z, 0.9 * r, 0.9 * r],
        [x - 0.2 * length, z, r, r],
        [x - length, z, 0.7 * r, 0.7 * r],
    ];
    m.loft(&stations, 8, y);
}

/// An airliner's dimensions, metres (see [`ModelMesh::wings`] and [`ModelMesh::fin`] for the
/// order of each part's numbers).
struct Airliner {
    /// Length, radius, sides.
    fuselage: [f32; 3],
    wing: [f32; 8],
    tailplane: [f32; 8],
    fin: [f32; 6],
    /// Front x, |y|, z, length, radius of each of the two engines.
    nacelle: [f32; 5],
}

fn airliner(m: &mut ModelMesh, a: &Airliner) {
    let [length, radius, sides] = a.fuselage;
    fuselage(m, length, radius, sides as usize);
    for w in [a.wing, a.tailplane] {
        m.wings(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]);
    }
    let f = a.fin;
    m.accent(true).fin(f[0], f[1], f[2], f[3], f[4], f[5]);
    let [x, y, z, l, r] = a.nacelle;
    for side in [1.0, -1.0] {
        nacelle(m, x, side * y, z, l, r);
    }
}

/// The shape of a kind.
pub fn aircraft_mesh(kind: AircraftKind) -> ModelMesh {
    let mut m = ModelMesh::default();
    match kind {
        // Airbus A320: 37.6 m long, 35.8 m span, fuselage 3.95 m.
        AircraftKind::NarrowBody => airliner(
            &mut m,
            &Airliner {
                fuselage: [37.6, 1.98, 12.0],
                wing: [3.5, 6.0, 1.5, 17.9, 7.5, -1.0, 1.2, 0.25],
                tailplane: [-14.0, 3.6, 1.4, 6.2, 3.5, 0.6, 0.3, 0.12],
                fin: [-12.5, 5.5, 2.0, 1.2, 6.0, 4.5],
                nacelle: [5.0, 5.8, -2.2, 4.5, 1.0],
            },
        ),
        // Boeing 777-300ER: 73.9 m long, 64.8 m span, fuselage 6.2 m.
        AircraftKind::WideBody => airliner(
            &mut m,
            &Airliner {
                fuselage: [73.9, 3.1, 14.0],
                wing: [8.0, 12.0, 3.0, 32.4, 14.0, -1.8, 2.0, 0.45],
                tailplane: [-29.0, 7.0, 2.5, 10.6, 6.5, 1.0, 0.5, 0.2],
                fin: [-26.0, 10.0, 3.5, 2.0, 10.5, 8.5],
                nacelle: [11.5, 9.7, -3.4, 7.5, 1.7],
            },
        ),
        AircraftKind::Light => {
            // Cessna 172: 8.3 m long, 11.0 m span, high straight wing.
            fuselage(&mut m, 8.3, 0.6, 10);
            m.wings(1.3, 1.6, 1.1, 5.5, 0.2, 0.75, 0.15, 0.08);
            m.wings(-3.1, 1.0, 0.7, 1.7, 0.3, 0.1, 0.0, 0.05);
            m.accent(true).fin(-2.8, 1.3, 0.6, 0.3, 1.3, 0.9);
        }
        AircraftKind::Helicopter => {
            // Airbus H135: 10.2 m rotor, 12.2 m long overall.
            let body = [
                [2.6, -0.3, 0.1, 0.1],
                [2.2, -0.1, 0.7, 0.75],
                [0.8, 0.1, 0.8, 0.95],
                [-1.2, 0.3, 0.75, 0.85],
                [-2.0, 0.5, 0.35, 0.4],
            ];
            m.accent(true).loft(&body, 12, 0.0);
            m.accent(false);
            let boom = [
                [-1.9, 0.5, 0.25, 0.25],
                [-6.5, 0.6, 0.12, 0.15],
                [-7.1, 0.6, 0.05, 0.05],
            ];
            m.loft(&boom, 8, 0.0);
            m.fin(-6.2, 0.9, 0.5, 0.4, 1.4, 0.6);
            m.wings(-5.6, 0.6, 0.4, 1.0, 0.1, 0.6, 0.0, 0.04);
            // Rotor disc (blades blurred by their speed) on its mast.
            m.fin(0.45, 0.3, 0.3, 0.9, 0.6, 0.0);
            m.rotor(0.3, 1.5, 5.1);
        }
    }
    m
}

impl ModelMesh {
    /// A thin disc of radius `r` in the `x`-`y` plane, centred at (`centre_x`, 0, `z`).
    fn rotor(&mut self, centre_x: f32, z: f32, r: f32) {
        let sides = 20;
        let h = 0.05;
        for k in 0..sides {
            let a0 = k as f32 / sides as f32 * std::f32::consts::TAU;
            let a1 = (k + 1) as f32 / sides as f32 * std::f32::consts::TAU;
            let p = |a: f32, dz: f32| [centre_x + r * a.cos(), r * a.sin(), z + dz];
            let c = |dz: f32| [centre_x, 0.0, z + dz];
            self.triangle(c(h), p(a0, h), p(a1, h));
            self.triangle(c(-h), p(a1, -h), p(a0, -h));
            self.quad(p(a0, -h), p(a1, -h), p(a1, h), p(a0, h));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds(m: &ModelMesh) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &m.positions {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        (lo, hi)
    }

    #[test]
    fn shapes_have_their_aircrafts_sizes_and_are_symmetric() {
        // (kind, length, span) of the type each stands for, metres.
        for (kind, length, span) in [
            (AircraftKind::NarrowBody, 37.6, 35.8),
            (AircraftKind::WideBody, 73.9, 64.8),
            (AircraftKind::Light, 8.3, 11.0),
            (AircraftKind::Helicopter, 12.2, 10.2),
        ] {
            let m = aircraft_mesh(kind);
            let (lo, hi) = bounds(&m);
            let (l, s) = (hi[0] - lo[0], hi[1] - lo[1]);
            assert!((l - length).abs() < length * 0.08, "{kind:?} length {l}");
            assert!((s - span).abs() < span * 0.08, "{kind:?} span {s}");
            assert!((lo[1] + hi[1]).abs() < 0.01, "{kind:?} not symmetric");
            assert!(
                m.triangles() > 100 && m.triangles() < 1500,
                "{kind:?} {}",
                m.triangles()
            );
            assert!((m.extent_m() - length.max(span)).abs() < length.max(span) * 0.08);
            // Flat normals: unit length, perpendicular to their triangle.
            for (t, n) in m.positions.chunks(3).zip(m.normals.chunks(3)) {
                let n = Vec3::from(n[0]);
                assert!((n.length() - 1.0).abs() < 1e-4);
                for e in [
                    Vec3::from(t[1]) - Vec3::from(t[0]),
                    Vec3::from(t[2]) - Vec3::from(t[0]),
                ] {
                    let dot = e.dot(n);
                    assert!(dot.abs() <= 1e-3 * e.length().max(1.0), "{kind:?}: {dot}");
                }
            }
        }
    }

    #[test]
    fn the_coarse_level_keeps_the_outline_with_a_fraction_of_the_triangles() {
        let (mut fine, mut coarse) = (0, 0);
        for kind in AircraftKind::ALL {
            let m = aircraft_mesh(kind);
            let c = m.simplified(MODEL_LOD_CELLS);
            assert!(
                c.triangles() * 4 < m.triangles() * 3 && c.triangles() > 20,
                "{kind:?}: {} of {} triangles",
                c.triangles(),
                m.triangles()
            );
            // Same length and span within a cell (corners move to their cell's mean).
            let cell = m.extent_m() / MODEL_LOD_CELLS as f32;
            let ((lo, hi), (clo, chi)) = (bounds(&m), bounds(&c));
            for i in 0..2 {
                assert!(
                    (lo[i] - clo[i]).abs() <= cell,
                    "{kind:?} axis {i}: {lo:?} {clo:?}"
                );
                assert!(
                    (hi[i] - chi[i]).abs() <= cell,
                    "{kind:?} axis {i}: {hi:?} {chi:?}"
                );
            }
            fine += m.triangles();
            coarse += c.triangles();
            // Still painted: accents survive.
            assert!(c.accents.contains(&1), "{kind:?}");
            assert_eq!(c.positions.len(), c.normals.len());
            // Flat normals of non-degenerate triangles.
            assert!(
                c.normals
                    .iter()
                    .all(|n| (Vec3::from(*n).length() - 1.0).abs() < 1e-4)
            );
        }
        // Over the four shapes, well under half.
        assert!(coarse * 2 < fine, "{coarse} of {fine} triangles");
        // Nothing to simplify: the same.
        let empty = ModelMesh::default();
        assert_eq!(empty.simplified(8), empty);
    }

    #[test]
    fn the_nose_points_forward() {
        for kind in AircraftKind::ALL {
            let m = aircraft_mesh(kind);
            // More of the fuselage's cross-section is behind the reference point than the
            // nose's tip: the tip (largest x) lies on the centre line.
            let tip = m
                .positions
                .iter()
                .filter(|p| p[2] < 0.9)
                .max_by(|a, b| a[0].total_cmp(&b[0]))
                .copied()
                .unwrap_or_default();
            assert!(tip[1].abs() < 0.2, "{kind:?} nose tip at {tip:?}");
        }
    }
}
