//! Void filling by push-pull: voids (`NaN`) take values interpolated from a pyramid of
//! averages of the valid samples around them, so a hole in a DEM becomes a smooth surface
//! that meets its rim, never a spike to -32768 m.

/// Fills every `NaN` in a `width` x `height` grid. Returns the number of samples filled, or
/// `None` if the grid has no valid sample at all (nothing to fill from).
pub fn fill_voids(data: &mut [f32], width: usize, height: usize) -> Option<usize> {
    let voids = data.iter().filter(|v| v.is_nan()).count();
    if voids == 0 {
        return Some(0);
    }
    if voids == data.len() {
        return None;
    }
    fill_level(data, width, height);
    Some(voids)
}

/// Fills the voids of one level from the next coarser one, built and filled recursively.
fn fill_level(data: &mut [f32], width: usize, height: usize) {
    if !data.iter().any(|v| v.is_nan()) {
        return;
    }
    // Push: average the valid samples of each 2x2 block.
    let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
    let mut coarse = vec![f32::NAN; cw * ch];
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut sum, mut n) = (0.0f64, 0u32);
            for y in (2 * cy)..(2 * cy + 2).min(height) {
                for x in (2 * cx)..(2 * cx + 2).min(width) {
                    let v = data[y * width + x];
                    if !v.is_nan() {
                        sum += f64::from(v);
                        n += 1;
                    }
                }
            }
            if n > 0 {
                coarse[cy * cw + cx] = (sum / f64::from(n)) as f32;
            }
        }
    }
    if cw * ch < data.len() {
        fill_level(&mut coarse, cw, ch);
    } else {
        // A 1x1 grid that is still void cannot happen: the caller checked for a valid sample.
        return;
    }
    // Pull: voids take the coarse level, interpolated bilinearly at their position.
    let sample = |x: f64, y: f64| {
        let x = x.clamp(0.0, (cw - 1) as f64);
        let y = y.clamp(0.0, (ch - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(cw - 1), (y0 + 1).min(ch - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let c = |xx: usize, yy: usize| f64::from(coarse[yy * cw + xx]);
        let top = c(x0, y0) * (1.0 - fx) + c(x1, y0) * fx;
        let bottom = c(x0, y1) * (1.0 - fx) + c(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    };
    for y in 0..height {
        for x in 0..width {
            let v = &mut data[y * width + x];
            if v.is_nan() {
                *v = sample((x as f64 - 0.5) * 0.5, (y as f64 - 0.5) * 0.5) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hole_in_a_slope_is_filled_between_its_rim_values() {
        let (w, h) = (40, 30);
        let mut data: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 * 10.0).collect();
        for y in 10..20 {
            for x in 12..25 {
                data[y * w + x] = f32::NAN;
            }
        }
        assert_eq!(fill_voids(&mut data, w, h), Some(130));
        for y in 10..20 {
            for x in 12..25 {
                let v = data[y * w + x];
                assert!((110.0..=250.0).contains(&v), "({x},{y}) = {v}");
            }
        }
        // Valid samples are untouched.
        assert_eq!(data[5 * w + 7], 70.0);
    }

    #[test]
    fn all_void_is_reported() {
        let mut data = vec![f32::NAN; 12];
        assert_eq!(fill_voids(&mut data, 4, 3), None);
        let mut one = vec![f32::NAN, 5.0, f32::NAN];
        assert_eq!(fill_voids(&mut one, 3, 1), Some(2));
        assert_eq!(one, vec![5.0, 5.0, 5.0]);
    }
}
