//! Gaussian blur of a weight map over a rectangle of texels (the texture-domain smoothing of
//! the fusion's weight maps).

/// Normalised Gaussian taps of standard deviation `sigma` (texels), truncated at
/// `ceil(3 sigma)`: `2 * radius + 1` values. `sigma <= 0` gives the single tap 1.
pub(crate) fn gaussian_kernel(sigma: f32) -> Vec<f32> {
    if sigma.is_nan() || sigma <= 0.0 {
        return vec![1.0];
    }
    let radius = (3.0 * sigma).ceil() as i32;
    let k: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Separable convolution of the `w` x `h` row-major `map` with `kernel` in both directions,
/// zero outside the rectangle, in place (`tmp` is scratch of at least `w * h`).
pub(crate) fn blur_rect(map: &mut [f32], w: usize, h: usize, kernel: &[f32], tmp: &mut Vec<f32>) {
    let r = kernel.len() / 2;
    tmp.clear();
    tmp.resize(w * h, 0.0);
    // Rows. Only non-zero inputs scatter: the map is sparse (one frame's winning texels).
    for y in 0..h {
        let row = &map[y * w..(y + 1) * w];
        let out = &mut tmp[y * w..(y + 1) * w];
        for (x, &v) in row.iter().enumerate() {
            if v == 0.0 {
                continue;
            }
            let lo = x.saturating_sub(r);
            let hi = (x + r).min(w - 1);
            for (xo, o) in out.iter_mut().enumerate().take(hi + 1).skip(lo) {
                *o += v * kernel[xo + r - x];
            }
        }
    }
    // Columns.
    map.iter_mut().for_each(|v| *v = 0.0);
    for y in 0..h {
        let lo = y.saturating_sub(r);
        let hi = (y + r).min(h - 1);
        for yo in lo..=hi {
            let k = kernel[yo + r - y];
            let (src, dst) = (&tmp[y * w..(y + 1) * w], yo * w);
            for (x, &v) in src.iter().enumerate() {
                map[dst + x] += k * v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_matches_direct_2d_convolution() {
        let (w, h) = (9, 7);
        let mut map = vec![0.0f32; w * h];
        map[3 * w + 4] = 2.0;
        map[w + 1] = 1.0;
        let orig = map.clone();
        let k = gaussian_kernel(1.0);
        assert_eq!(k.len(), 7);
        assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let mut tmp = Vec::new();
        blur_rect(&mut map, w, h, &k, &mut tmp);
        let r = 3i64;
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let mut s = 0.0f32;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (sx, sy) = (x - dx, y - dy);
                        if sx >= 0 && sy >= 0 && sx < w as i64 && sy < h as i64 {
                            s += orig[(sy as usize) * w + sx as usize]
                                * k[(dx + r) as usize]
                                * k[(dy + r) as usize];
                        }
                    }
                }
                assert!((map[y as usize * w + x as usize] - s).abs() < 1e-6);
            }
        }
    }
}
