//! The case's frames as the build's passes see them: decoded one at a time from the frame
//! source (never all in memory), each with its depth buffer (cached from the fit pass while
//! the cache fits its memory budget, else ray cast again) and its fitted shading.

use super::error::BuildError;
use super::scene::BuildScene;
use crate::image::Frame;
use crate::io::frame_source::FrameSource;
use crate::shading::FrameShaders;
use crate::texture::delight::Observation;
use crate::texture::fusion::FrameStream;
use crate::workflow::progress::Progress;
use crate::Result;

/// Depth buffers kept between passes over the frames, up to a memory budget: the working
/// resolution's from the fit pass, or the full resolution's for the final fusions.
pub struct DepthCache {
    depth: Vec<Option<Vec<f32>>>,
    budget_bytes: usize,
    used_bytes: usize,
    /// The buffers are of the frames reduced by `2^level` ([`BuildScene::level`] or 0).
    pub level: usize,
}

impl DepthCache {
    /// A cache for `frames` frames at the working resolution `level` holding at most
    /// `budget_bytes` of depth.
    pub fn new(frames: usize, budget_bytes: usize, level: usize) -> DepthCache {
        DepthCache {
            depth: vec![None; frames],
            budget_bytes,
            used_bytes: 0,
            level,
        }
    }

    /// Every frame of `scene` cast at full resolution, as far as `budget_bytes` allows (the
    /// final fusions read each frame once or twice).
    pub fn full_resolution(scene: &BuildScene, budget_bytes: usize) -> DepthCache {
        let n = scene.frame_count();
        let mut cache = DepthCache::new(n, budget_bytes, 0);
        let frame_bytes = 4 * scene.case.camera.width as usize * scene.case.camera.height as usize;
        for i in 0..n.min(budget_bytes / frame_bytes.max(1)) {
            cache.offer(i, &scene.cast_full_depth(i));
        }
        cache
    }

    /// Keep frame `i`'s depth when it fits the budget.
    pub fn offer(&mut self, i: usize, depth: &[f32]) {
        let bytes = std::mem::size_of_val(depth);
        if i < self.depth.len() && self.used_bytes + bytes <= self.budget_bytes {
            self.depth[i] = Some(depth.to_vec());
            self.used_bytes += bytes;
        }
    }

    /// Frame `i`'s depth, if kept.
    pub fn get(&self, i: usize) -> Option<&[f32]> {
        self.depth.get(i).and_then(|d| d.as_deref())
    }
}

/// The resolution a stream of frames is read at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resolution {
    /// The build's working resolution ([`BuildScene::level`]).
    Working,
    /// The frames as recorded.
    Full,
}

/// The frames of a case (a subset of them, in increasing order) for the fusion passes.
pub struct CaseFrames<'a> {
    scene: &'a BuildScene,
    resolution: Resolution,
    shading: &'a dyn FrameShaders,
    /// Frame indices (into the case) of the stream's frames, increasing.
    subset: Vec<usize>,
    source: Option<FrameSource>,
    next: usize,
    frame: Frame,
    depth: Vec<f32>,
    /// Advanced once per observation.
    pub progress: Progress,
}

impl<'a> CaseFrames<'a> {
    /// Stream the frames `subset` (case indices, increasing) of `scene`'s case at `resolution`.
    pub fn new(
        scene: &'a BuildScene,
        shading: &'a dyn FrameShaders,
        subset: Vec<usize>,
        resolution: Resolution,
        progress: Progress,
    ) -> CaseFrames<'a> {
        CaseFrames {
            scene,
            resolution,
            shading,
            subset,
            source: None,
            next: 0,
            frame: Frame::new(1, 1),
            depth: Vec::new(),
            progress,
        }
    }
}

impl FrameStream for CaseFrames<'_> {
    fn frame_count(&self) -> usize {
        self.subset.len()
    }

    fn observation(&mut self, k: usize) -> Result<Observation<'_>> {
        let index = *self.subset.get(k).ok_or(BuildError::FrameMissing {
            frame: k,
            frames: self.subset.len(),
        })?;
        if self.source.is_none() || index < self.next {
            self.source = Some(self.scene.case.frame_source()?);
            self.next = 0;
        }
        let src = self.source.as_mut().expect("opened above");
        // The frames between are passed over, not decoded.
        let f = src
            .nth(index - self.next)
            .ok_or(BuildError::FrameMissing {
                frame: index,
                frames: self.next,
            })??;
        self.frame = match self.resolution {
            Resolution::Working => self.scene.working_frame(f),
            Resolution::Full => f,
        };
        self.next = index + 1;
        let pose = &self.scene.poses[index];
        let working = self.resolution == Resolution::Working || self.scene.level == 0;
        let level = if working { self.scene.level } else { 0 };
        let depth: &[f32] = match self.scene.cache.get(index) {
            Some(d) if self.scene.cache.level == level => d,
            _ => {
                self.depth = if working {
                    self.scene.cast_depth(index)
                } else {
                    self.scene.cast_full_depth(index)
                };
                &self.depth
            }
        };
        self.progress.inc();
        Ok(Observation {
            frame: &self.frame,
            camera: if working {
                &self.scene.camera
            } else {
                &self.scene.case.camera
            },
            camera_to_world: pose,
            shading: self.shading.frame_shading(index),
            depth,
        })
    }
}
