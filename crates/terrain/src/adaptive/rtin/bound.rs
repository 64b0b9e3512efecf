//! The error passes for one bound ([`errors_for_bound`]): the same stored errors wherever a
//! mesh at that bound reads them, from far fewer samples.
//!
//! A mesh at bound `e` only asks whether each stored error exceeds `e`. Two facts let the
//! passes run from the coarsest level down and skip most of the grid:
//! * A scan may stop as soon as its triangle's error exceeds `e`: the value it has then is
//!   already beyond the bound, and so is every stored value it reaches.
//! * A triangle `T` whose samples, its legs included, all lie within `d` of its plane has no
//!   descendant with an error over `2 d`: a descendant's corners are samples of `T`, so its
//!   plane is within `d` of `T`'s over it, and its samples within `d` of `T`'s plane. Once
//!   `d <= e / 2`, nothing below `T` can split, and the passes leave its subtree at 0.
//!
//! So a coarse bound's build scans the coarse triangles until each one's first sample
//! beyond the bound, and the fine levels only where the terrain is rough: on the srtm window
//! of `tools/compare-meshers.py` at 30 m it touches a fraction of the samples the full build
//! does. Where most squares of a fine level are still open, that level and every finer one
//! run the full build's vectorised passes instead (cheaper per sample than one square at a
//! time), and their values are the full build's.
//!
//! Every mesh at `e` is the full build's: a stored value left at 0 stands only for
//! triangles within the bound, a scan stopped early only for values beyond it, and
//! everything else is computed exactly as the full build computes it (the rounding of
//! f32 is settled by the mesher in both; see [`super::MeshBuilder::exactly_beyond`]).

use super::levels::{
    self, ACROSS_SQUARES_UP_TO, EAST, LevelErrors, NORTH, Plane, SOUTH, Scratch, WEST, corners,
    half_planes, north_south_planes,
};
use crate::adaptive::rows::larger;

/// What a bound's build needs to know of the bound.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cut {
    /// A scan may stop once its triangle's error exceeds this (the bound plus the rounding
    /// of f32, rounded up): it is beyond the bound whatever the rest of its samples.
    pub(super) stop: f32,
    /// A triangle whose samples, legs included, lie within this of its plane (half the
    /// bound less the rounding, rounded down) has no descendant beyond the bound. Negative:
    /// nothing is skipped.
    pub(super) prune: f32,
}

/// Fine levels run the full passes once more than this share of their squares is open.
const FULL_PASSES_FROM_OPEN_SHARE: f64 = 0.7;

/// The stored errors of every midpoint, as [`levels::errors`] computes them wherever they
/// decide a mesh at the bound `cut` stands for; elsewhere any value on the same side of it.
pub(super) fn errors_for_bound(
    h: &[f32],
    side: usize,
    cut: Cut,
    scratch: &mut Scratch,
    errors: &mut Vec<f32>,
) {
    let n = side - 1;
    errors.clear();
    errors.resize(side * side, 0.0);
    scratch.transposed = false;
    scratch.phased_filled = false;
    // Levels from the whole tile (index 0) down to squares of 4.
    let count = if n >= 4 {
        n.trailing_zeros() as usize - 1
    } else {
        0
    };
    if scratch.per_level.len() < count {
        scratch.per_level.resize_with(count, LevelErrors::default);
    }
    let mut full = false;
    for i in 0..count {
        let s = n >> i;
        let squares = n / s;
        if full {
            if s > ACROSS_SQUARES_UP_TO {
                levels::along_rows(h, side, s, scratch);
            } else {
                levels::across_squares(h, side, s, scratch);
            }
            let level = &mut scratch.per_level[i];
            std::mem::swap(&mut level.a, &mut scratch.a);
            std::mem::swap(&mut level.b, &mut scratch.b);
            continue;
        }
        let (coarser, rest) = scratch.per_level.split_at_mut(i);
        let parent = coarser.last();
        let level = &mut rest[0];
        level.a.clear();
        level.a.resize(squares * squares, 0.0);
        level.b.clear();
        level.b.resize(squares * squares, [0.0; 4]);
        let mut open_below = 0usize;
        for row in 0..squares {
            for col in 0..squares {
                let open = match parent {
                    None => true,
                    Some(p) => {
                        // A quarter's halves are the children of the parent's B triangles on
                        // its two outer sides.
                        let pb = p.b[(row / 2) * (squares / 2) + col / 2];
                        let ns = if row % 2 == 0 { NORTH } else { SOUTH };
                        let we = if col % 2 == 0 { WEST } else { EAST };
                        !(pb[ns] <= cut.prune && pb[we] <= cut.prune)
                    }
                };
                if !open {
                    continue;
                }
                let (x, y) = (col * s, row * s);
                let k = row * squares + col;
                let nw_se = (row + col).is_multiple_of(2);
                let a = halves(h, side, (x, y), s, nw_se, cut.stop);
                level.a[k] = a;
                if a <= cut.prune {
                    continue;
                }
                let b = sides(h, side, (x, y), s, cut.stop);
                level.b[k] = b;
                // Children in each quarter whose two parent triangles are not both done.
                for (ns, we) in [(NORTH, WEST), (NORTH, EAST), (SOUTH, WEST), (SOUTH, EAST)] {
                    if !(b[ns] <= cut.prune && b[we] <= cut.prune) {
                        open_below += 1;
                    }
                }
            }
        }
        let next = s / 2;
        if (4..=ACROSS_SQUARES_UP_TO).contains(&next) {
            let total = (n / next) * (n / next);
            full = open_below as f64 > FULL_PASSES_FROM_OPEN_SHARE * total as f64;
        }
    }
    // Bottom-up, as the full build stores them.
    levels::level_two(h, side, errors);
    for i in (0..count).rev() {
        let level = &scratch.per_level[i];
        levels::combine(errors, &level.a, &level.b, side, n >> i);
    }
}

/// The largest distance of a sample of the s-square at `(x, y)` to the plane of the A(s)
/// half holding it, every sample included (sides and diagonal), row by row until one row
/// takes it beyond `stop`.
fn halves(h: &[f32], side: usize, (x, y): (usize, usize), s: usize, nw_se: bool, stop: f32) -> f32 {
    let [first, second] = half_planes(corners(h, side, (x, y), s), s, nw_se);
    let mut worst = 0.0f32;
    for k in 0..=s {
        let row = &h[(y + k) * side + x..=(y + k) * side + x + s];
        let cut = if nw_se { k } else { s - k };
        worst = larger(worst, first.deviation(row, k, (0, cut)));
        worst = larger(worst, second.deviation(row, k, (cut, s)));
        if worst > stop {
            break;
        }
    }
    worst
}

/// The errors of the four B(s) triangles of the s-square at `(x, y)` (north, south, west,
/// east of its centre), every sample included (legs and hypotenuse), each scan stopping at
/// the first row that takes it beyond `stop`. The west and east planes are the north and
/// south ones of the transposed grid, as the full build has them.
fn sides(h: &[f32], side: usize, (x, y): (usize, usize), s: usize, stop: f32) -> [f32; 4] {
    let [nw, ne, sw, se, c] = corners(h, side, (x, y), s);
    let [north, south] = north_south_planes([nw, ne, sw, se, c], s);
    // West and east: north and south of the transposed square, their slopes swapped back.
    let [west, east] = north_south_planes([nw, sw, ne, se, c], s).map(|p| Plane {
        p0: p.p0,
        gx: p.gy,
        gy: p.gx,
    });
    let half = s / 2;
    let row = |k: usize| &h[(y + k) * side + x..=(y + k) * side + x + s];
    let mut out = [0.0f32; 4];
    let (mut north_open, mut south_open, mut west_open, mut east_open) = (true, true, true, true);
    // North and south rows k and s - k run towards the centre row; west and east hold
    // rows 0..=s, each a run of columns from the square's side to the diagonals.
    for k in 0..=half {
        if north_open {
            out[NORTH] = larger(out[NORTH], north.deviation(row(k), k, (k, s - k)));
            north_open = out[NORTH] <= stop;
        }
        if south_open {
            let r = s - k;
            out[SOUTH] = larger(out[SOUTH], south.deviation(row(r), r, (k, s - k)));
            south_open = out[SOUTH] <= stop;
        }
        // West and east: rows k and s - k both reach `k` columns in from their side.
        for r in [k, s - k] {
            if west_open {
                out[WEST] = larger(out[WEST], west.deviation(row(r), r, (0, k)));
                west_open = out[WEST] <= stop;
            }
            if east_open {
                out[EAST] = larger(out[EAST], east.deviation(row(r), r, (s - k, s)));
                east_open = out[EAST] <= stop;
            }
        }
        if !(north_open || south_open || west_open || east_open) {
            break;
        }
    }
    out
}
