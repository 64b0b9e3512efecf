//! Signed distance fields from coverage rasters: the exact Euclidean distance transform of
//! Felzenszwalb and Huttenlocher ("Distance Transforms of Sampled Functions", Theory of
//! Computing 8, 2012), applied to a glyph's anti-aliased coverage as Mapbox's TinySDF does
//! (each partly covered texel starts at its sub-pixel distance from the edge, so the field is
//! smooth along curves).
//!
//! Written here because the crates that make SDF glyphs either rasterise fonts themselves
//! with their own text stack (msdfgen bindings need a C++ build) or take an image crate's
//! raster API; the transform is sixty lines and exact, and the glyph outlines come from
//! `ab_glyph`.

/// Stands for "infinitely far" in squared distances (TinySDF's choice: finite, so the
/// parabola intersections below stay finite).
const FAR: f64 = 1.0e20;

/// The signed distance (texels, positive outside, negative inside) of every texel of a
/// `width` x `height` coverage raster (`coverage[y * width + x]` in 0..1) to the shape's
/// edge, where coverage crosses 0.5.
pub fn signed_distance(coverage: &[f32], width: usize, height: usize) -> Vec<f32> {
    let n = width * height;
    let mut outer = vec![FAR; n];
    let mut inner = vec![FAR; n];
    for (i, &a) in coverage.iter().enumerate().take(n) {
        let a = f64::from(a.clamp(0.0, 1.0));
        if a >= 1.0 {
            outer[i] = 0.0;
        } else if a <= 0.0 {
            inner[i] = 0.0;
        } else {
            // A partly covered texel: the edge runs through it, about (a - 0.5) from its
            // centre.
            let d = 0.5 - a;
            outer[i] = if d > 0.0 { d * d } else { 0.0 };
            inner[i] = if d < 0.0 { d * d } else { 0.0 };
        }
    }
    transform_2d(&mut outer, width, height);
    transform_2d(&mut inner, width, height);
    outer
        .iter()
        .zip(&inner)
        .map(|(&o, &i)| (o.sqrt() - i.sqrt()) as f32)
        .collect()
}

/// Squared Euclidean distance transform of a 2-D grid in place: columns, then rows.
fn transform_2d(grid: &mut [f64], width: usize, height: usize) {
    let longest = width.max(height);
    let mut f = vec![0.0; longest];
    let mut d = vec![0.0; longest];
    let mut v = vec![0usize; longest];
    let mut z = vec![0.0; longest + 1];
    for x in 0..width {
        for y in 0..height {
            f[y] = grid[y * width + x];
        }
        transform_1d(&f[..height], &mut d, &mut v, &mut z);
        for y in 0..height {
            grid[y * width + x] = d[y];
        }
    }
    for y in 0..height {
        f[..width].copy_from_slice(&grid[y * width..(y + 1) * width]);
        transform_1d(&f[..width], &mut d, &mut v, &mut z);
        grid[y * width..(y + 1) * width].copy_from_slice(&d[..width]);
    }
}

/// One-dimensional squared distance transform: `d[q] = min_p (q - p)^2 + f[p]`, by the lower
/// envelope of the parabolas rooted at each `p`.
fn transform_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let fq = f[q] + (q * q) as f64;
        loop {
            let r = v[k];
            let s = (fq - f[r] - (r * r) as f64) / (2.0 * (q - r) as f64);
            if s <= z[k] && k > 0 {
                k -= 1;
                continue;
            }
            if s <= z[k] {
                // Replaces the first parabola.
                v[0] = q;
                z[0] = f64::NEG_INFINITY;
                z[1] = f64::INFINITY;
                break;
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
            break;
        }
    }
    k = 0;
    for (q, out) in d.iter_mut().enumerate().take(n) {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let r = v[k];
        let dq = q as f64 - r as f64;
        *out = dq * dq + f[r];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc's coverage, by 16x16 supersampling.
    fn disc(size: usize, cx: f64, cy: f64, r: f64) -> Vec<f32> {
        let mut out = vec![0.0f32; size * size];
        for y in 0..size {
            for x in 0..size {
                let mut hits = 0;
                for sy in 0..16 {
                    for sx in 0..16 {
                        let px = x as f64 + (sx as f64 + 0.5) / 16.0;
                        let py = y as f64 + (sy as f64 + 0.5) / 16.0;
                        if (px - cx).hypot(py - cy) <= r {
                            hits += 1;
                        }
                    }
                }
                out[y * size + x] = hits as f32 / 256.0;
            }
        }
        out
    }

    #[test]
    fn a_discs_field_is_its_distance_from_the_circle_to_within_a_texel() {
        let (size, cx, cy, r) = (48usize, 23.3, 24.6, 11.2);
        let field = signed_distance(&disc(size, cx, cy, r), size, size);
        let (mut worst, mut sum, mut count): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for y in 0..size {
            for x in 0..size {
                let truth = (x as f64 + 0.5 - cx).hypot(y as f64 + 0.5 - cy) - r;
                if truth.abs() < 8.0 {
                    let e = (f64::from(field[y * size + x]) - truth).abs();
                    worst = worst.max(e);
                    sum += e;
                    count += 1.0;
                }
            }
        }
        // The edge texels' sub-pixel estimate (0.5 - coverage) is exact only where the edge
        // runs along the grid: on a circle it is off by at most about half a texel.
        assert!(worst < 0.7, "worst error {worst} texels");
        assert!(sum / count < 0.25, "mean error {} texels", sum / count);
    }

    #[test]
    fn empty_and_full_rasters_have_no_edge_to_measure() {
        let empty = signed_distance(&[0.0; 9], 3, 3);
        assert!(empty.iter().all(|&d| d > 1.0e9));
        let full = signed_distance(&[1.0; 9], 3, 3);
        assert!(full.iter().all(|&d| d < -1.0e9));
        // One covered texel: 1 texel (centre to centre) beside it, -1 at its own centre.
        let mut one = [0.0; 9];
        one[4] = 1.0;
        let d = signed_distance(&one, 3, 3);
        assert!(
            (d[3] - 1.0).abs() < 1e-6 && (d[1] - 1.0).abs() < 1e-6,
            "{d:?}"
        );
        assert!((d[0] - 2f32.sqrt()).abs() < 1e-6 && (d[4] + 1.0).abs() < 1e-6);
    }
}
