//! One streaming pass of the fusion over the frames: every texel of the blocks a frame can see
//! de-lit and handed to the method's per-texel update, and what every pass keeps per texel.

use rayon::prelude::*;

use super::delight::{max_ray_angle, FrameCtx};
use super::texels::{TexelSet, BLOCK};
use crate::camera::Camera;

/// Running sum of one texel: weighted value and weight.
#[derive(Clone, Copy, Default)]
pub(crate) struct Acc {
    pub(crate) rgb: [f32; 3],
    pub(crate) w: f32,
}

/// What the first pass over the frames learns of one texel whatever the method: how many
/// frames gave it a value and which one with the largest weight (the paper's max-weight
/// choice, and the frame that dominates the texel for the seam measure).
#[derive(Clone, Copy)]
pub(crate) struct Seen {
    pub(crate) count: u32,
    pub(crate) best_w: f32,
    /// `u32::MAX` while no frame saw the texel.
    pub(crate) best_frame: u32,
}

impl Default for Seen {
    fn default() -> Self {
        Seen {
            count: 0,
            best_w: 0.0,
            best_frame: u32::MAX,
        }
    }
}

/// `w` raised to `exponent` (the common exponents without `powf`).
#[inline]
pub(crate) fn weight_power(w: f32, exponent: f32) -> f32 {
    match exponent {
        1.0 => w,
        2.0 => w * w,
        e => w.powf(e),
    }
}

/// The view-cone angle of the last camera (cameras rarely change within a video).
#[derive(Default)]
pub(crate) struct CameraCache {
    last: Option<(Camera, f64)>,
}

impl CameraCache {
    pub(crate) fn angle(&mut self, cam: &Camera) -> f64 {
        match self.last {
            Some((c, a)) if c == *cam => a,
            _ => {
                let a = max_ray_angle(cam);
                self.last = Some((*cam, a));
                a
            }
        }
    }
}

/// De-light every texel of the blocks the frame can see (parallel over blocks) and hand each
/// valid `(value, weight)` to `update` with the texel's state; with `seen = Some((seen, f))`
/// also count the observation and keep frame `f` where its weight is the texel's largest.
pub(crate) fn for_visible_blocks<T: Send>(
    texels: &TexelSet,
    ctx: &FrameCtx,
    state: &mut [T],
    seen: Option<(&mut [Seen], u32)>,
    update: impl Fn(&mut T, [f32; 3], f32) + Sync,
) {
    let (seen, frame, count) = match seen {
        Some((s, f)) => (s, f, true),
        None => (&mut [][..], u32::MAX, false),
    };
    let visit = |b: usize, st: &mut [T], mut sn: Option<&mut [Seen]>| {
        if !ctx.block_visible(&texels.blocks[b]) {
            return;
        }
        let s0 = b * BLOCK;
        for k in 0..st.len() {
            if let Some((v, w)) = ctx.texel(texels.point[s0 + k], texels.normal[s0 + k]) {
                update(&mut st[k], v, w);
                if let Some(sn) = sn.as_deref_mut() {
                    let s = &mut sn[k];
                    s.count += 1;
                    if w > s.best_w {
                        s.best_w = w;
                        s.best_frame = frame;
                    }
                }
            }
        }
    };
    if count {
        state
            .par_chunks_mut(BLOCK)
            .zip(seen.par_chunks_mut(BLOCK))
            .enumerate()
            .for_each(|(b, (st, sn))| visit(b, st, Some(sn)));
    } else {
        state
            .par_chunks_mut(BLOCK)
            .enumerate()
            .for_each(|(b, st)| visit(b, st, None));
    }
}
