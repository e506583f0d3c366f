//! The sRGB transfer curve (IEC 61966-2-1): frames are decoded from sRGB to linear intensity
//! at load and encoded back at write (DESIGN.md, conventions); everything in between works in
//! linear light.

use std::sync::OnceLock;

/// sRGB-encoded value (0..=1) to linear light, the exact IEC 61966-2-1 piecewise curve.
#[inline]
pub fn srgb_to_linear(encoded: f32) -> f32 {
    srgb_to_linear_f64(encoded as f64) as f32
}

/// Linear light (0..=1) to an sRGB-encoded value, the exact IEC 61966-2-1 inverse curve.
/// Values outside 0..=1 are clamped.
#[inline]
pub fn linear_to_srgb(linear: f32) -> f32 {
    linear_to_srgb_f64(linear as f64) as f32
}

pub(crate) fn srgb_to_linear_f64(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

pub(crate) fn linear_to_srgb_f64(l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    if l <= 0.0031308 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value of every 8-bit sRGB code.
pub fn srgb8_to_linear_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|c| srgb_to_linear_f64(c as f64 / 255.0) as f32))
}

/// Linear value of every 16-bit sRGB code (65536 entries, 256 KiB, built once).
pub fn srgb16_to_linear_lut() -> &'static [f32] {
    static LUT: OnceLock<Vec<f32>> = OnceLock::new();
    LUT.get_or_init(|| {
        (0..=u16::MAX)
            .map(|c| srgb_to_linear_f64(c as f64 / 65535.0) as f32)
            .collect()
    })
}

/// Exact, fast linear → sRGB code quantiser for codes `0..=max`.
///
/// `thresholds[k]` is the linear value of the encoded code `k + 0.5`, so code `c` is the
/// answer exactly when `thresholds[c - 1] <= x < thresholds[c]`: rounding happens in the encoded
/// domain and every LUT value maps back to its own code. A 4096-bucket table of the encoded
/// curve, interpolated, gives a guess within about one code; a short walk fixes it (no `powf`).
struct Quantiser {
    max: usize,
    guess: Vec<f32>,
    thresholds: Vec<f32>,
}

const GUESS_BUCKETS: usize = 4096;

impl Quantiser {
    fn new(max: usize) -> Self {
        let guess = (0..=GUESS_BUCKETS)
            .map(|i| (linear_to_srgb_f64(i as f64 / GUESS_BUCKETS as f64) * max as f64) as f32)
            .collect();
        let thresholds = (0..max)
            .map(|k| srgb_to_linear_f64((k as f64 + 0.5) / max as f64) as f32)
            .collect();
        Quantiser {
            max,
            guess,
            thresholds,
        }
    }

    #[inline]
    fn code(&self, x: f32) -> usize {
        if x.is_nan() || x <= 0.0 {
            return 0;
        }
        if x >= 1.0 {
            return self.max;
        }
        let t = x * GUESS_BUCKETS as f32;
        let i = (t as usize).min(GUESS_BUCKETS - 1);
        let f = t - i as f32;
        let g = self.guess[i] + f * (self.guess[i + 1] - self.guess[i]);
        let mut c = ((g + 0.5) as usize).min(self.max);
        while c < self.max && x >= self.thresholds[c] {
            c += 1;
        }
        while c > 0 && x < self.thresholds[c - 1] {
            c -= 1;
        }
        c
    }
}

fn quantiser8() -> &'static Quantiser {
    static Q: OnceLock<Quantiser> = OnceLock::new();
    Q.get_or_init(|| Quantiser::new(255))
}

fn quantiser16() -> &'static Quantiser {
    static Q: OnceLock<Quantiser> = OnceLock::new();
    Q.get_or_init(|| Quantiser::new(65535))
}

/// Linear light to the nearest 8-bit sRGB code, rounding in the encoded domain (clamped; NaN
/// gives 0). Exact inverse of [`srgb8_to_linear_lut`].
#[inline]
pub fn linear_to_srgb8(linear: f32) -> u8 {
    quantiser8().code(linear) as u8
}

/// Linear light to the nearest 16-bit sRGB code, rounding in the encoded domain (clamped; NaN
/// gives 0). Exact inverse of [`srgb16_to_linear_lut`].
#[inline]
pub fn linear_to_srgb16(linear: f32) -> u16 {
    quantiser16().code(linear) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_exactly() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear_lut()[c as usize]), c);
        }
        let lut16 = srgb16_to_linear_lut();
        for c in 0..=u16::MAX {
            assert_eq!(linear_to_srgb16(lut16[c as usize]), c, "code {c}");
        }
        assert_eq!(linear_to_srgb8(-1.0), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb16(f32::NAN), 0);
        assert_eq!(linear_to_srgb16(1.5), 65535);
    }

    #[test]
    fn quantiser_matches_formula_rounding() {
        // Away from code boundaries (f32 thresholds hold a boundary to ~0.003 code) the fast
        // quantiser equals rounding the exact f64 curve.
        for i in 0..=200_000u32 {
            let x = i as f32 / 200_000.0;
            for (max, got) in [
                (255.0, linear_to_srgb8(x) as f64),
                (65535.0, linear_to_srgb16(x) as f64),
            ] {
                let exact = linear_to_srgb_f64(x as f64) * max;
                if (exact - exact.floor() - 0.5).abs() > 0.01 {
                    assert_eq!(got, exact.round(), "x = {x}, max {max}");
                }
            }
        }
    }
}
