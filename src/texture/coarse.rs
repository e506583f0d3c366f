//! A coarser sampling of an atlas's texels, for the passes over the video that need a
//! consensus of the frames rather than the texture's detail (the calibrated light's gain
//! corrections and refits). De-lighting is texel-driven, so a pass costs in proportion to the
//! texels each frame sees: keeping one texel of every `factor × factor` block makes those
//! passes about `factor²` times cheaper, at any frame resolution.
//!
//! The coarse set is the fine set's texels whose atlas column and row are multiples of
//! `factor` (same atlas, same charts); [`CoarseTexels::expand`] gives every fine texel the value
//! of its block's sample, so that lookups in the fine atlas (bilinear, by UV) keep working.

use super::atlas::TexelGeometry;
use super::fusion::FusedTexture;
use super::texels::TexelSet;
use crate::Result;

/// The texels of a [`TexelSet`] kept at one of every `factor × factor` atlas block.
#[derive(Clone, Debug)]
pub struct CoarseTexels {
    /// The kept texels, a texel set of the same atlas.
    pub texels: TexelSet,
    /// Block size (texels per side); 1 keeps every texel.
    pub factor: u32,
}

impl CoarseTexels {
    /// Keep the texels of `fine` whose column and row are multiples of `factor` (at least 1).
    pub fn new(fine: &TexelSet, factor: u32) -> Result<CoarseTexels> {
        let factor = factor.max(1);
        let w = fine.width;
        let keep: Vec<usize> = (0..fine.len())
            .filter(|&s| {
                let t = fine.texel[s];
                (t % w) % factor == 0 && (t / w) % factor == 0
            })
            .collect();
        let pick = |v: &[[f32; 3]]| keep.iter().map(|&s| v[s]).collect::<Vec<_>>();
        let geometry = TexelGeometry {
            width: fine.width,
            height: fine.height,
            texel: keep.iter().map(|&s| fine.texel[s]).collect(),
            // The texel set keeps neither triangles nor barycentrics.
            triangle: Vec::new(),
            bary: Vec::new(),
            point: pick(&fine.point),
            normal: pick(&fine.normal),
            chart: keep.iter().map(|&s| fine.chart[s]).collect(),
        };
        Ok(CoarseTexels {
            texels: TexelSet::new(&geometry)?,
            factor,
        })
    }

    /// The fusion `coarse` (over [`CoarseTexels::texels`]) as a fusion over `fine`: every fine
    /// texel takes the value, coverage and frame count of its block's sample when that sample
    /// is in the same chart; the others stay uncovered (filled by
    /// [`FusedTexture::filled`] from their chart's neighbours).
    pub fn expand(&self, coarse: &FusedTexture, fine: &TexelSet) -> FusedTexture {
        let mut out = FusedTexture {
            width: coarse.width,
            height: coarse.height,
            rgb: vec![0.0; coarse.rgb.len()],
            covered: vec![false; coarse.covered.len()],
            frames_seen: vec![0; coarse.frames_seen.len()],
            dominant_frame: vec![u32::MAX; coarse.dominant_frame.len()],
            stats: coarse.stats.clone(),
        };
        let (w, f) = (fine.width, self.factor);
        let mut covered = 0;
        for (s, &t) in fine.texel.iter().enumerate() {
            let (x, y) = (t % w, t / w);
            let anchor = (y - y % f) * w + (x - x % f);
            let a = self.texels.slot_of_texel[anchor as usize];
            if a == u32::MAX || self.texels.chart[a as usize] != fine.chart[s] {
                continue;
            }
            let (t, anchor) = (t as usize, anchor as usize);
            out.rgb[3 * t..3 * t + 3].copy_from_slice(&coarse.rgb[3 * anchor..3 * anchor + 3]);
            out.covered[t] = coarse.covered[anchor];
            out.frames_seen[t] = coarse.frames_seen[anchor];
            out.dominant_frame[t] = coarse.dominant_frame[anchor];
            covered += usize::from(coarse.covered[anchor]);
        }
        out.stats.chart_texels = fine.len();
        out.stats.covered_texels = covered;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6x4 atlas: chart 0 on columns 0..3, chart 1 on columns 3..6; points on a plane.
    fn fine_set() -> TexelSet {
        let (w, h) = (6u32, 4u32);
        let mut geo = TexelGeometry {
            width: w,
            height: h,
            texel: Vec::new(),
            triangle: Vec::new(),
            bary: Vec::new(),
            point: Vec::new(),
            normal: Vec::new(),
            chart: Vec::new(),
        };
        for chart in 0..2u32 {
            for y in 0..h {
                for x in 3 * chart..3 * chart + 3 {
                    geo.texel.push(y * w + x);
                    geo.point.push([x as f32, y as f32, 0.0]);
                    geo.normal.push([0.0, 0.0, 1.0]);
                    geo.chart.push(chart);
                }
            }
        }
        TexelSet::new(&geo).unwrap()
    }

    #[test]
    fn keeps_one_texel_per_block_and_expands_within_the_chart() {
        let fine = fine_set();
        let coarse = CoarseTexels::new(&fine, 2).unwrap();
        // Columns 0, 2 (chart 0) and 4 (chart 1), rows 0 and 2.
        let kept: Vec<u32> = coarse.texels.texel.clone();
        assert_eq!(kept, vec![0, 2, 12, 14, 4, 16]);
        let n = 24;
        let mut fused = FusedTexture {
            width: 6,
            height: 4,
            rgb: vec![0.0; 3 * n],
            covered: vec![false; n],
            frames_seen: vec![0; n],
            dominant_frame: vec![u32::MAX; n],
            stats: Default::default(),
        };
        for &t in &kept {
            let t = t as usize;
            fused.rgb[3 * t..3 * t + 3].copy_from_slice(&[t as f32, 1.0, 2.0]);
            fused.covered[t] = true;
            fused.frames_seen[t] = 5;
        }
        let out = coarse.expand(&fused, &fine);
        // Texel (1, 1) takes (0, 0)'s value; (5, 3) takes (4, 2)'s.
        assert_eq!(&out.rgb[3 * 7..3 * 7 + 3], &[0.0, 1.0, 2.0]);
        assert_eq!(&out.rgb[3 * 23..3 * 23 + 3], &[16.0, 1.0, 2.0]);
        // Column 3 is in chart 1 but its blocks' samples (column 2) are in chart 0: uncovered.
        assert!(!out.covered[3] && !out.covered[21]);
        assert_eq!(out.stats.covered_texels, 20);
        assert_eq!(out.frames_seen[23], 5);
    }
}
