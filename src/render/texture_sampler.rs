//! The albedo atlas as a mip-mapped texture with coverage-aware trilinear sampling.
//!
//! Each level stores premultiplied `(w·r, w·g, w·b, w)` where `w` is the fraction of the level's
//! texel covered by chart data (1 on chart texels, 0 in the gutter). Box filtering the
//! premultiplied values and dividing after interpolation means the empty gutter never darkens a
//! chart border, at any level.
//!
//! Charts still bleed into each other at coarse levels: a level-L texel spans 2^L base texels,
//! more than the gutter (2 texels by default) from level 2 on. Rather than building mips per
//! chart, the chain is capped at [`MipOptions::max_level`] (default 4: 16 texels, 2.4 mm at the
//! default 0.15 mm texels). Beyond that footprint the remaining aliasing is left to the
//! renderer's supersampling option; on the airway wall neighbouring charts carry similar mucosa,
//! so the bleed of the capped levels is a slight blur, not a visible seam.

use crate::image::Frame;
use crate::image::ImageError;
use crate::Result;

/// Options of [`MipTexture::new`].
#[derive(Clone, Debug)]
pub struct MipOptions {
    /// Coarsest level built (level 0 = the atlas itself; level L has texels 2^L times larger).
    pub max_level: u32,
}

impl Default for MipOptions {
    fn default() -> Self {
        MipOptions { max_level: 4 }
    }
}

/// One level: premultiplied RGBA (A = coverage), row-major, `4 * width * height` values.
#[derive(Clone, Debug)]
struct Level {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

/// A linear-RGB texture atlas with its mip chain (built once, read by every rendered view).
#[derive(Clone, Debug)]
pub struct MipTexture {
    /// Texel edge length of level 0 on the surface (mm).
    pub texel_mm: f64,
    /// Level-0 width (texels).
    pub width: u32,
    /// Level-0 height (texels).
    pub height: u32,
    levels: Vec<Level>,
}

impl MipTexture {
    /// Build the chain from a linear-RGB atlas image. `coverage` (one flag per texel, row-major)
    /// marks texels that carry chart data; `None` treats every texel as covered.
    /// UV convention of [`crate::texture::atlas::Atlas`]: texel (x, y) has its centre at
    /// ((x + 0.5) / width, (y + 0.5) / height), row 0 first.
    pub fn new(
        image: &Frame,
        coverage: Option<&[bool]>,
        texel_mm: f64,
        opts: &MipOptions,
    ) -> Result<MipTexture> {
        let (w, h) = (image.width as usize, image.height as usize);
        if w == 0 || h == 0 || image.rgb.len() != 3 * w * h {
            return Err(ImageError::BufferSize {
                stage: "texture",
                what: "the atlas image (a non-empty RGB image)",
                got: image.rgb.len(),
                expected: (3 * w * h).max(3),
            }
            .into());
        }
        if let Some(c) = coverage {
            if c.len() != w * h {
                return Err(ImageError::BufferSize {
                    stage: "texture",
                    what: "the coverage flags",
                    got: c.len(),
                    expected: w * h,
                }
                .into());
            }
        }
        if !(texel_mm.is_finite() && texel_mm > 0.0) {
            return Err(ImageError::Inconsistent {
                stage: "texture",
                message: format!("texel_mm must be positive, got {texel_mm}"),
            }
            .into());
        }
        let mut data = vec![0.0f32; 4 * w * h];
        for i in 0..w * h {
            let a = coverage.map_or(1.0, |c| if c[i] { 1.0 } else { 0.0 });
            data[4 * i] = a * image.rgb[3 * i];
            data[4 * i + 1] = a * image.rgb[3 * i + 1];
            data[4 * i + 2] = a * image.rgb[3 * i + 2];
            data[4 * i + 3] = a;
        }
        let mut levels = vec![Level {
            width: w,
            height: h,
            data,
        }];
        while levels.len() <= opts.max_level as usize {
            let prev = levels.last().expect("level 0 exists");
            if prev.width == 1 && prev.height == 1 {
                break;
            }
            levels.push(downsample(prev));
        }
        Ok(MipTexture {
            texel_mm,
            width: image.width,
            height: image.height,
            levels,
        })
    }

    /// Number of levels built (level 0 included).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Bilinear sample of level 0 at UV (no mip-mapping).
    #[inline]
    pub fn sample_bilinear(&self, u: f32, v: f32) -> [f32; 3] {
        unpremultiply(self.bilinear(0, u, v))
    }

    /// Trilinear sample at UV with level-of-detail `lod` (log2 of the footprint in level-0
    /// texels; clamped to the built levels).
    #[inline]
    pub fn sample(&self, u: f32, v: f32, lod: f32) -> [f32; 3] {
        let top = (self.levels.len() - 1) as f32;
        let lod = if lod.is_nan() {
            0.0
        } else {
            lod.clamp(0.0, top)
        };
        // lod >= 0: truncation is floor.
        let l0 = lod as usize;
        let f = lod - l0 as f32;
        let a = self.bilinear(l0, u, v);
        if f <= 0.0 || l0 + 1 >= self.levels.len() {
            return unpremultiply(a);
        }
        let b = self.bilinear(l0 + 1, u, v);
        unpremultiply(std::array::from_fn(|k| a[k] + f * (b[k] - a[k])))
    }

    /// Level of detail for a pixel footprint of `footprint_mm` on the surface.
    #[inline]
    pub fn lod(&self, footprint_mm: f32) -> f32 {
        (footprint_mm / self.texel_mm as f32).max(1.0).log2()
    }

    /// Premultiplied bilinear lookup of level `l`, edge texels clamped. Level-L coordinates are
    /// level-0 coordinates divided by 2^L so odd sizes stay aligned with level 0.
    #[inline]
    fn bilinear(&self, l: usize, u: f32, v: f32) -> [f32; 4] {
        let lev = &self.levels[l];
        let s = 1.0 / (1u32 << l) as f32;
        let x = (u * self.width as f32 * s - 0.5).clamp(0.0, (lev.width - 1) as f32);
        let y = (v * self.height as f32 * s - 0.5).clamp(0.0, (lev.height - 1) as f32);
        if !(x.is_finite() && y.is_finite()) {
            return [0.0; 4];
        }
        let (x0, y0) = (x as usize, y as usize);
        let x1 = (x0 + 1).min(lev.width - 1);
        let y1 = (y0 + 1).min(lev.height - 1);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let d = &lev.data;
        let i00 = 4 * (y0 * lev.width + x0);
        let i10 = 4 * (y0 * lev.width + x1);
        let i01 = 4 * (y1 * lev.width + x0);
        let i11 = 4 * (y1 * lev.width + x1);
        std::array::from_fn(|k| {
            let top = d[i00 + k] + fx * (d[i10 + k] - d[i00 + k]);
            let bot = d[i01 + k] + fx * (d[i11 + k] - d[i01 + k]);
            top + fy * (bot - top)
        })
    }
}

#[inline]
fn unpremultiply(p: [f32; 4]) -> [f32; 3] {
    // A footprint entirely in the gutter has no data: black (never reached on chart triangles).
    if p[3] <= 1e-6 {
        return [0.0; 3];
    }
    let inv = 1.0 / p[3];
    [p[0] * inv, p[1] * inv, p[2] * inv]
}

/// 2x2 box filter of premultiplied RGBA; texels beyond an odd edge count as empty.
fn downsample(prev: &Level) -> Level {
    let w = prev.width.div_ceil(2);
    let h = prev.height.div_ceil(2);
    let mut data = vec![0.0f32; 4 * w * h];
    for y in 0..h {
        for x in 0..w {
            let o = &mut data[4 * (y * w + x)..4 * (y * w + x) + 4];
            for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                let (sx, sy) = (2 * x + dx, 2 * y + dy);
                if sx < prev.width && sy < prev.height {
                    let i = 4 * (sy * prev.width + sx);
                    for (k, ov) in o.iter_mut().enumerate() {
                        *ov += 0.25 * prev.data[i + k];
                    }
                }
            }
        }
    }
    Level {
        width: w,
        height: h,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_average_and_the_gutter_does_not_darken() {
        // 4x4 atlas: left half a chart of value 0.8, right half gutter (value 0, uncovered).
        let mut img = Frame::new(4, 4);
        let mut cov = vec![false; 16];
        for y in 0..4 {
            for x in 0..2 {
                img.set(x, y, [0.8, 0.4, 0.2]);
                cov[(y * 4 + x) as usize] = true;
            }
        }
        let t = MipTexture::new(&img, Some(&cov), 0.15, &MipOptions { max_level: 8 }).unwrap();
        assert_eq!(t.level_count(), 3);
        // Level 2 is one texel mixing chart and gutter: the chart colour, not half of it.
        let c = t.sample(0.5, 0.5, 2.0);
        assert!(
            (c[0] - 0.8).abs() < 1e-6 && (c[2] - 0.2).abs() < 1e-6,
            "{c:?}"
        );
        // Level 0 at a texel centre returns the texel.
        let c = t.sample(0.125, 0.375, 0.0);
        assert!((c[1] - 0.4).abs() < 1e-6);
        // The lod of a footprint of 4 texels is 2.
        assert!((t.lod(0.6) - 2.0).abs() < 1e-5);
    }

    #[test]
    fn trilinear_blends_levels() {
        // Checkerboard 0/1: level 0 at a texel centre is 0 or 1, level 1 is 0.5 everywhere.
        let mut img = Frame::new(8, 8);
        for y in 0..8 {
            for x in 0..8 {
                let v = ((x + y) % 2) as f32;
                img.set(x, y, [v; 3]);
            }
        }
        let t = MipTexture::new(&img, None, 1.0, &MipOptions::default()).unwrap();
        let (u, v) = (1.5 / 8.0, 0.5 / 8.0); // texel (1, 0) = 1
        assert!((t.sample(u, v, 0.0)[0] - 1.0).abs() < 1e-6);
        assert!((t.sample(u, v, 1.0)[0] - 0.5).abs() < 1e-6);
        assert!((t.sample(u, v, 0.5)[0] - 0.75).abs() < 1e-6);
    }
}
