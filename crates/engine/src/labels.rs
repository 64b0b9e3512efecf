//! Label placement: which labels are drawn and where, so that no two overlap, greedy by
//! priority, with anchors that stay put from frame to frame and fades instead of flicker.
//!
//! This is MapLibre's collision approach (its `CollisionIndex` and `Placement`, as in the
//! symbol placement of mapbox-gl-js), sized for moving objects: each label may sit at one of
//! four corners round its object (north-east first, as ATC data blocks do), clear of the
//! object's symbol. Every frame, labels are taken in priority order (the caller's: Globus
//! uses selected first, then nearer, then larger) and each takes the first free corner,
//! trying the corner it had last frame before the others, so a label only jumps when its old
//! place is taken. A grid of cells indexes the boxes already placed, so a frame costs
//! O(labels · boxes per cell).
//!
//! Labels keep off obstacles too (the objects' symbols), held in a summed-area table so that
//! thousands of them cost four lookups per test.
//!
//! Hidden labels beyond the first few in the order are tried every other frame (every frame
//! when the time since the last is unknown: a first, or a still, picture), which halves the
//! cost of a crowd (most of whose labels have no room) at the price of a frame's delay.
//!
//! A label that finds a place fades in over `fade_s`; one that loses its place fades out at
//! its old corner if that corner is still free once every placed label is in, or vanishes at
//! once if it is not, so drawn labels never overlap, even while fading. Labels that were not
//! asked for this frame (their object left the screen) are forgotten.

use rustc_hash::FxHashMap;

pub(crate) mod gpu;

/// The label shader (leaders and glyphs), for validation.
pub use gpu::SHADER;

/// Labels at the head of the priority order tried every frame even when hidden.
const ALWAYS_TRIED: usize = 64;

/// A label wanted this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LabelRequest {
    /// Stable identity (an object id).
    pub id: u64,
    /// The object's position on screen, pixels (`x` right, `y` down).
    pub anchor_px: [f32; 2],
    /// How far from the anchor the box keeps (the symbol's half size and a gap), pixels.
    pub clearance_px: f32,
    /// The box's width and height, pixels.
    pub size_px: [f32; 2],
    /// Placement order: higher first.
    pub priority: f32,
}

/// Where a label sits round its anchor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Corner {
    /// Above and to the right.
    NorthEast,
    /// Below and to the right.
    SouthEast,
    /// Above and to the left.
    NorthWest,
    /// Below and to the left.
    SouthWest,
}

impl Corner {
    /// In the order they are tried (after last frame's).
    pub const ALL: [Corner; 4] = [
        Corner::NorthEast,
        Corner::SouthEast,
        Corner::NorthWest,
        Corner::SouthWest,
    ];

    /// The box (min x, min y, max x, max y) of a label at this corner.
    pub fn place(self, anchor: [f32; 2], clearance: f32, size: [f32; 2]) -> [f32; 4] {
        let [ax, ay] = anchor;
        let [w, h] = size;
        let x = match self {
            Corner::NorthEast | Corner::SouthEast => ax + clearance,
            Corner::NorthWest | Corner::SouthWest => ax - clearance - w,
        };
        let y = match self {
            Corner::NorthEast | Corner::NorthWest => ay - clearance - h,
            Corner::SouthEast | Corner::SouthWest => ay + clearance,
        };
        [x, y, x + w, y + h]
    }
}

/// A label to draw this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedLabel {
    /// Its request's id.
    pub id: u64,
    /// Index of its request in this frame's requests.
    pub request: usize,
    /// Its box: min x, min y, max x, max y (pixels).
    pub bounds: [f32; 4],
    /// Where it sits.
    pub corner: Corner,
    /// 0..1: fading in or out.
    pub opacity: f32,
}

#[derive(Clone, Copy, Debug)]
struct State {
    corner: Corner,
    opacity: f32,
    /// The frame it was last asked for.
    seen: u64,
}

/// Boxes on a grid of square cells, for overlap queries.
#[derive(Debug, Default)]
struct Grid {
    cell_px: f32,
    columns: usize,
    rows: usize,
    cells: Vec<Vec<u32>>,
    boxes: Vec<[f32; 4]>,
    /// What each box belongs to (the caller's index).
    tags: Vec<u32>,
}

impl Grid {
    fn reset(&mut self, viewport: [f32; 2], cell_px: f32) {
        self.cell_px = cell_px;
        self.columns = (viewport[0] / cell_px).ceil().max(1.0) as usize;
        self.rows = (viewport[1] / cell_px).ceil().max(1.0) as usize;
        let n = self.columns * self.rows;
        self.cells.resize_with(n, Vec::new);
        self.cells.truncate(n);
        for c in &mut self.cells {
            c.clear();
        }
        self.boxes.clear();
        self.tags.clear();
    }

    fn cell_range(&self, b: &[f32; 4]) -> (usize, usize, usize, usize) {
        // `as` truncates towards zero and saturates at 0: the floor of non-negative cells.
        let inv = 1.0 / self.cell_px;
        let clamp_x = |v: f32| ((v * inv) as usize).min(self.columns - 1);
        let clamp_y = |v: f32| ((v * inv) as usize).min(self.rows - 1);
        (clamp_x(b[0]), clamp_y(b[1]), clamp_x(b[2]), clamp_y(b[3]))
    }

    fn is_free(&self, b: &[f32; 4]) -> bool {
        let mut free = true;
        self.overlapping(b, |_| free = false);
        free
    }

    /// Calls `f` with the tag of every box overlapping `b` (a box in several cells may be
    /// reported more than once).
    fn overlapping(&self, b: &[f32; 4], mut f: impl FnMut(u32)) {
        let (x0, y0, x1, y1) = self.cell_range(b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                for &i in &self.cells[y * self.columns + x] {
                    if overlaps(&self.boxes[i as usize], b) {
                        f(self.tags[i as usize]);
                    }
                }
            }
        }
    }

    fn insert(&mut self, b: [f32; 4], tag: u32) {
        let i = self.boxes.len() as u32;
        self.boxes.push(b);
        self.tags.push(tag);
        let (x0, y0, x1, y1) = self.cell_range(&b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.cells[y * self.columns + x].push(i);
            }
        }
    }
}

/// Boxes that are always drawn (symbols), as a summed-area table of the cells they touch:
/// whether a box meets any of them is four lookups, however many there are. Cells are
/// [`OBSTACLE_CELL_PX`] square, so a box may be refused up to that close to an obstacle.
#[derive(Debug, Default)]
struct ObstacleMap {
    /// Few obstacles: kept in a grid of boxes instead (building the table costs a pass over
    /// every cell of the screen, about a quarter of a millisecond at 1920x1080).
    few: Grid,
    dense: bool,
    columns: usize,
    rows: usize,
    /// (columns + 1) x (rows + 1): `sums[y][x]` counts occupied cells above and left of
    /// (x, y).
    sums: Vec<u32>,
}

/// Up to this many obstacles go in a grid of boxes rather than the table.
const FEW_OBSTACLES: usize = 256;

/// Side of an obstacle cell, pixels.
const OBSTACLE_CELL_PX: f32 = 4.0;

impl ObstacleMap {
    fn build(&mut self, obstacles: &[[f32; 4]], viewport: [f32; 2]) {
        self.dense = obstacles.len() > FEW_OBSTACLES;
        if !self.dense {
            self.few.reset(viewport, 64.0);
            for o in obstacles {
                self.few.insert(*o, 0);
            }
            return;
        }
        self.columns = (viewport[0] / OBSTACLE_CELL_PX).ceil().max(1.0) as usize;
        self.rows = (viewport[1] / OBSTACLE_CELL_PX).ceil().max(1.0) as usize;
        let (c, r) = (self.columns, self.rows);
        let stride = c + 1;
        self.sums.clear();
        self.sums.resize(stride * (r + 1), 0);
        if obstacles.is_empty() {
            return;
        }
        // A difference array of coverage counts, one corner pair per obstacle...
        let mut diff = vec![0i32; stride * (r + 1)];
        for o in obstacles {
            let Some((x0, y0, x1, y1)) = self.cells(o) else {
                continue;
            };
            diff[y0 * stride + x0] += 1;
            diff[y0 * stride + x1 + 1] -= 1;
            diff[(y1 + 1) * stride + x0] -= 1;
            diff[(y1 + 1) * stride + x1 + 1] += 1;
        }
        // ... summed into counts, then occupancy summed into the table.
        for y in 0..r {
            let mut run = 0i32;
            for x in 0..c {
                run += diff[y * stride + x];
                let above = if y > 0 { diff[(y - 1) * stride + x] } else { 0 };
                diff[y * stride + x] = run + above;
                let occupied = u32::from(diff[y * stride + x] > 0);
                let i = (y + 1) * stride + x + 1;
                self.sums[i] =
                    occupied + self.sums[i - 1] + self.sums[i - stride] - self.sums[i - stride - 1];
            }
        }
    }

    /// The cells a box touches, clamped to the map (`None` if it is off the map).
    fn cells(&self, b: &[f32; 4]) -> Option<(usize, usize, usize, usize)> {
        if b[2] <= 0.0 || b[3] <= 0.0 {
            return None;
        }
        let inv = 1.0 / OBSTACLE_CELL_PX;
        let x0 = ((b[0] * inv) as usize).min(self.columns - 1);
        let y0 = ((b[1] * inv) as usize).min(self.rows - 1);
        let x1 = ((b[2] * inv) as usize).min(self.columns - 1);
        let y1 = ((b[3] * inv) as usize).min(self.rows - 1);
        (x0 <= x1 && y0 <= y1).then_some((x0, y0, x1, y1))
    }

    fn meets(&self, b: &[f32; 4]) -> bool {
        if !self.dense {
            return !self.few.is_free(b);
        }
        if self.sums.is_empty() {
            return false;
        }
        let Some((x0, y0, x1, y1)) = self.cells(b) else {
            return false;
        };
        let stride = self.columns + 1;
        let at = |x: usize, y: usize| i64::from(self.sums[y * stride + x]);
        at(x1 + 1, y1 + 1) - at(x0, y1 + 1) - at(x1 + 1, y0) + at(x0, y0) > 0
    }
}

/// Whether two boxes share any area (touching edges do not count).
pub fn overlaps(a: &[f32; 4], b: &[f32; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// Places labels frame after frame; see the module documentation.
#[derive(Debug)]
pub struct LabelPlacer {
    fade_s: f32,
    states: FxHashMap<u64, State>,
    grid: Grid,
    /// Boxes of labels fading out this frame.
    fading_grid: Grid,
    obstacles: ObstacleMap,
    order: Vec<usize>,
    fading: Vec<(usize, u64)>,
    /// Per placed label: its opacity last frame.
    was: Vec<f32>,
    frame: u64,
}

impl LabelPlacer {
    /// A placer whose labels fade in and out over `fade_s` seconds.
    pub fn new(fade_s: f32) -> Self {
        Self {
            fade_s: fade_s.max(1e-3),
            states: FxHashMap::default(),
            grid: Grid::default(),
            fading_grid: Grid::default(),
            obstacles: ObstacleMap::default(),
            order: Vec::new(),
            fading: Vec::new(),
            was: Vec::new(),
            frame: 0,
        }
    }

    /// Places this frame's `requests` in a `viewport` (pixels), `dt_s` after the last frame,
    /// keeping clear of `obstacles` (boxes always drawn, such as symbols: min x, min y, max x,
    /// max y), and writes the labels to draw into `out` (cleared first).
    pub fn place(
        &mut self,
        requests: &[LabelRequest],
        obstacles: &[[f32; 4]],
        viewport: [f32; 2],
        dt_s: f32,
        out: &mut Vec<PlacedLabel>,
    ) {
        out.clear();
        let step = (dt_s.max(0.0) / self.fade_s).min(1.0);
        // Whole steps land exactly on 0 and 1 (no label left at 1e-8 opacity).
        let settle = |o: f32| {
            if o < 1e-4 {
                0.0
            } else if o > 1.0 - 1e-4 {
                1.0
            } else {
                o
            }
        };
        // Cells about the size of a label.
        let typical = requests
            .first()
            .map_or(64.0, |r| r.size_px[0].max(r.size_px[1]));
        let cell_px = typical.clamp(16.0, 256.0);
        self.grid.reset(viewport, cell_px);
        self.fading_grid.reset(viewport, cell_px);
        self.obstacles.build(obstacles, viewport);
        self.order.clear();
        self.order.extend(0..requests.len());
        self.order.sort_unstable_by(|&a, &b| {
            let (ra, rb) = (&requests[a], &requests[b]);
            rb.priority.total_cmp(&ra.priority).then(ra.id.cmp(&rb.id))
        });
        let on_screen =
            |b: &[f32; 4]| b[0] >= 0.0 && b[1] >= 0.0 && b[2] <= viewport[0] && b[3] <= viewport[1];
        self.fading.clear();
        self.was.clear();
        self.frame += 1;
        let frame = self.frame;
        // Greedy by priority: each takes the first free corner, last frame's first.
        for k in 0..self.order.len() {
            let i = self.order[k];
            let r = &requests[i];
            let previous = self.states.get(&r.id).copied();
            let hidden = previous.is_none_or(|s| s.opacity == 0.0);
            if hidden && dt_s.is_finite() && k >= ALWAYS_TRIED && (r.id ^ frame) & 1 == 1 {
                // A hidden label far down the order is tried every other frame (it stays
                // hidden in between): most of a crowd's labels are hidden, and this halves
                // their cost; one that finds room shows a frame later, fading in anyway.
                let corner = previous.map_or(Corner::NorthEast, |s| s.corner);
                self.states.insert(
                    r.id,
                    State {
                        corner,
                        opacity: 0.0,
                        seen: frame,
                    },
                );
                continue;
            }
            let first = previous.map(|s| s.corner);
            let tries = first
                .into_iter()
                .chain(Corner::ALL.into_iter().filter(|&c| Some(c) != first));
            let mut found = None;
            for corner in tries {
                let b = corner.place(r.anchor_px, r.clearance_px, r.size_px);
                if on_screen(&b) && !self.obstacles.meets(&b) && self.grid.is_free(&b) {
                    found = Some((corner, b));
                    break;
                }
            }
            let opacity = previous.map_or(0.0, |s| s.opacity);
            let corner = found.map_or(first.unwrap_or(Corner::NorthEast), |f| f.0);
            self.states.insert(
                r.id,
                State {
                    corner,
                    opacity,
                    seen: frame,
                },
            );
            match found {
                Some((corner, bounds)) => {
                    self.grid.insert(bounds, out.len() as u32);
                    self.was.push(opacity);
                    out.push(PlacedLabel {
                        id: r.id,
                        request: i,
                        bounds,
                        corner,
                        opacity: settle(opacity + step),
                    });
                }
                None if opacity > 0.0 => self.fading.push((i, r.id)),
                None => {}
            }
        }
        // Labels that lost their place fade out where they were, unless a label shown last
        // frame is there now (then they go at once); labels newly placed over them wait,
        // unshown, until they are gone.
        let placed = out.len();
        for k in 0..self.fading.len() {
            let (i, id) = self.fading[k];
            let r = &requests[i];
            let Some(s) = self.states.get(&id).copied() else {
                continue;
            };
            let b = s.corner.place(r.anchor_px, r.clearance_px, r.size_px);
            let mut blocked =
                !on_screen(&b) || self.obstacles.meets(&b) || !self.fading_grid.is_free(&b);
            self.grid
                .overlapping(&b, |tag| blocked |= self.was[tag as usize] > 0.0);
            let opacity = if blocked {
                0.0
            } else {
                settle(s.opacity - step)
            };
            if let Some(st) = self.states.get_mut(&id) {
                st.opacity = opacity;
            }
            if opacity > 0.0 {
                self.fading_grid.insert(b, 0);
                self.grid
                    .overlapping(&b, |tag| out[tag as usize].opacity = 0.0);
                out.push(PlacedLabel {
                    id,
                    request: i,
                    bounds: b,
                    corner: s.corner,
                    opacity,
                });
            }
        }
        for p in &out[..placed] {
            if let Some(st) = self.states.get_mut(&p.id) {
                st.opacity = p.opacity;
            }
        }
        out.retain(|p| p.opacity > 0.0);
        // Forget labels not asked for this frame.
        self.states.retain(|_, s| s.seen == frame);
    }
}

#[cfg(test)]
mod tests;
