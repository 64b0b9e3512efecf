//! Distances of a grid row from a plane, in SIMD lanes: the inner loop of both meshers.

/// Lanes of [`row_deviation`]: eight f32, one AVX register or two SSE ones.
const LANES: usize = 8;
const OFFSETS: [f32; LANES] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];

/// The larger of two finite values: compare-and-select, cheaper than `f32::max` and its NaN
/// rules.
#[inline(always)]
pub(super) fn larger(a: f32, b: f32) -> f32 {
    if b > a { b } else { a }
}

/// max |row[k] - (start + step * k)|, in lanes the compiler vectorises (compare-and-select
/// instead of `f32::max`, whose NaN rules keep it scalar; heights are finite).
#[inline(always)]
pub(super) fn row_deviation(row: &[f32], start: f32, step: f32) -> f32 {
    if row.len() < LANES {
        // Short rows (small triangles): the lanes' final reduction would cost more than the
        // row.
        let mut worst = 0.0f32;
        for (k, &v) in row.iter().enumerate() {
            worst = larger(worst, (v - (start + step * k as f32)).abs());
        }
        return worst;
    }
    let mut acc = [0.0f32; LANES];
    let chunks = row.chunks_exact(LANES);
    let tail = chunks.remainder();
    let mut base = start;
    let mut done = 0usize;
    for chunk in chunks {
        for k in 0..LANES {
            let d = (chunk[k] - (base + step * OFFSETS[k])).abs();
            acc[k] = larger(acc[k], d);
        }
        done += LANES;
        base = start + step * done as f32;
    }
    let mut worst = 0.0f32;
    for (k, &v) in tail.iter().enumerate() {
        let d = (v - (base + step * k as f32)).abs();
        worst = larger(worst, d);
    }
    for a in acc {
        worst = larger(worst, a);
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_find_the_largest_distance() {
        for len in [1usize, 5, 8, 9, 23, 64, 70] {
            let row: Vec<f32> = (0..len)
                .map(|k| ((k * 37 % 11) as f32) * 0.7 + 1000.0 + k as f32 * 0.3)
                .collect();
            let (start, step) = (1000.5f32, 0.31f32);
            let worst = row_deviation(&row, start, step);
            let brute = row
                .iter()
                .enumerate()
                .map(|(k, &v)| (v - (start + step * k as f32)).abs())
                .fold(0.0f32, f32::max);
            assert!((worst - brute).abs() < 1e-3, "{len}: {worst} vs {brute}");
        }
    }
}
