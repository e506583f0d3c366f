//! The exemplar: the square patches of the atlas whose texels (and a ring of one texel around
//! them) were all seen, with the 3-D
//! point of each patch's centre for choosing patches near a slot on the surface.

use crate::texture::texels::TexelSet;

/// Most exemplar positions kept (a stride thins dense atlases).
const MAX_POSITIONS: usize = 200_000;
/// Positions searched for the patches nearest a slot in 3-D.
const MAX_NEAR_SAMPLE: usize = 4096;
/// Smallest patch edge tried when no patch of the asked size is fully seen (texels).
const MIN_PATCH: usize = 8;

/// Fully seen patches of one size (see the module docs).
pub(super) struct Exemplar<'a> {
    /// Patch edge (texels).
    pub patch: usize,
    /// The atlas (linear RGB, interleaved) the patches are read from.
    pub rgb: &'a [f32],
    /// Atlas width (texels).
    pub width: usize,
    height: usize,
    /// Summed-area table of the coverage, `(width + 1) * (height + 1)`.
    integral: Vec<u32>,
    /// Top-left corners of the patches, atlas index `y * width + x`.
    positions: Vec<u32>,
    /// A spread subset of `positions` with the 3-D point of each patch's centre (world mm).
    near: Vec<(u32, [f32; 3])>,
}

impl<'a> Exemplar<'a> {
    /// The fully seen patches of edge `patch` (halved down to 8 texels while there are none);
    /// `None` when not even 8 x 8 seen texels lie together.
    pub fn find(
        rgb: &'a [f32],
        covered: &[bool],
        texels: &TexelSet,
        patch: usize,
    ) -> Option<Exemplar<'a>> {
        let (w, h) = (texels.width as usize, texels.height as usize);
        let mut integral = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                row += covered[y * w + x] as u32;
                integral[(y + 1) * (w + 1) + x + 1] = integral[y * (w + 1) + x + 1] + row;
            }
        }
        let mut b = patch;
        loop {
            let mut ex = Exemplar {
                patch: b,
                rgb,
                width: w,
                height: h,
                integral: std::mem::take(&mut integral),
                positions: Vec::new(),
                near: Vec::new(),
            };
            ex.collect_positions(texels);
            if !ex.positions.is_empty() {
                return Some(ex);
            }
            if b / 2 < MIN_PATCH {
                return None;
            }
            integral = ex.integral;
            b /= 2;
        }
    }

    /// Fill `positions` (on a stride keeping at most `MAX_POSITIONS`) and `near`.
    fn collect_positions(&mut self, texels: &TexelSet) {
        let (w, h, b) = (self.width, self.height, self.patch);
        if w < b || h < b {
            return;
        }
        let all = (w - b + 1) * (h - b + 1);
        let stride = (1..)
            .find(|s| all / (s * s) <= 4 * MAX_POSITIONS)
            .unwrap_or(1);
        for y in (0..=h - b).step_by(stride) {
            for x in (0..=w - b).step_by(stride) {
                if self.is_valid(x as i64, y as i64) {
                    self.positions.push((y * w + x) as u32);
                }
            }
        }
        if self.positions.len() > MAX_POSITIONS {
            let keep = self.positions.len().div_ceil(MAX_POSITIONS);
            self.positions = self.positions.iter().copied().step_by(keep).collect();
        }
        let step = self.positions.len().div_ceil(MAX_NEAR_SAMPLE).max(1);
        self.near = self
            .positions
            .iter()
            .step_by(step)
            .filter_map(|&p| {
                let (x, y) = (p as usize % w + b / 2, p as usize / w + b / 2);
                let s = texels.slot_of_texel[y * w + x];
                (s != u32::MAX).then(|| (p, texels.point[s as usize]))
            })
            .collect();
    }

    /// Number of patches.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Patch `i` (top-left atlas index).
    pub fn position(&self, i: usize) -> u32 {
        self.positions[i]
    }

    /// The patch with top-left corner (x, y) and a ring of one texel around it lie in the
    /// atlas and all their texels were seen (the ring gives the border its seen-side colours).
    pub fn is_valid(&self, x: i64, y: i64) -> bool {
        let (w, h, b) = (self.width as i64, self.height as i64, self.patch as i64);
        let (x0, y0, x1, y1) = (x - 1, y - 1, x + b + 1, y + b + 1);
        if x0 < 0 || y0 < 0 || x1 > w || y1 > h {
            return false;
        }
        let at = |x: i64, y: i64| self.integral[(y * (w + 1) + x) as usize] as i64;
        at(x1, y1) - at(x0, y1) - at(x1, y0) + at(x0, y0) == (b + 2) * (b + 2)
    }

    /// The (at most) `k` patches whose centres are nearest to `p` (world mm), from the spread
    /// subset, appended to `out`.
    pub fn nearest(
        &self,
        p: [f32; 3],
        k: usize,
        out: &mut Vec<u32>,
        scratch: &mut Vec<(f32, u32)>,
    ) {
        if k == 0 || self.near.is_empty() {
            return;
        }
        scratch.clear();
        scratch.extend(self.near.iter().map(|&(pos, q)| {
            let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2], pos)
        }));
        let k = k.min(scratch.len());
        if k < scratch.len() {
            scratch.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        }
        out.extend(scratch[..k].iter().map(|&(_, pos)| pos));
    }

    /// Colour of texel (dx, dy) of the patch at atlas index `pos` (-1..=patch: the ring too).
    #[inline]
    pub fn texel(&self, pos: u32, dx: i64, dy: i64) -> [f32; 3] {
        let i = 3 * (pos as i64 + dy * self.width as i64 + dx) as usize;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }
}
