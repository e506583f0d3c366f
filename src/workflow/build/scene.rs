//! The build's first stages — read the case, segment the airway, mesh its lumen, lay out the
//! texture atlas — and [`BuildScene`], what every later stage shares.

use std::time::Instant;

use super::frames::{CaseFrames, DepthCache, Resolution};
use super::options::BuildOptions;
use crate::camera::Camera;
use crate::image::reduce::{reduce_frame, reduce_mask};
use crate::image::Frame;
use crate::io::case::Case;
use crate::io::poses::FrameRef;
use crate::math::Affine;
use crate::model::manifest::BuildTimings;
use crate::raycast::{cast_depth_with, cast_frame_with, mask_out_depth, GBuffer, RayTable, Scene};
use crate::render::triangle_uvs;
use crate::shading::calibrated::cos_theta_of;
use crate::shading::FrameShaders;
use crate::texture::atlas::{build_atlas, rasterize_texels, Atlas};
use crate::texture::texels::TexelSet;
use crate::volume::segment::Segmentation;
use crate::workflow::progress::Progress;
use crate::workflow::segment::{segment_and_mesh, SegmentCommandOptions};
use crate::Result;

/// The case and the airway it is textured on: the plain inputs of every stage after the
/// atlas.
pub struct BuildScene {
    /// The case (CT, camera, poses, frames).
    pub case: Case,
    /// Camera → world of every frame as the build uses it (the case's poses).
    pub poses: Vec<Affine>,
    /// The airway mask on the CT grid.
    pub segmentation: Segmentation,
    /// The lumen mesh with its texture atlas.
    pub atlas: Atlas,
    /// The atlas texels on the surface.
    pub texels: TexelSet,
    /// UV corners of every triangle of the atlas mesh.
    pub tri_uv: Vec<[[f32; 2]; 3]>,
    /// The atlas mesh, ready for ray casting.
    pub scene: Scene,
    /// The working resolution of the fits, the light, the cross-validation and the
    /// registration: the frames reduced by `2^level` (the texture is fused from full-resolution
    /// pixels).
    pub level: usize,
    /// The camera at the working resolution.
    pub camera: Camera,
    /// The case's image mask at the working resolution.
    pub mask: Option<Vec<bool>>,
    /// The working camera's rays.
    pub rays: RayTable,
    /// The full-resolution camera's rays (the final fusion's visibility).
    pub full_rays: RayTable,
    /// cos theta (off the optical axis) of every working pixel's ray.
    pub cos_theta: Vec<f32>,
    /// Depth buffers (working resolution) kept from the first pass over the frames.
    pub cache: DepthCache,
    /// Linear intensity at which a channel is saturated (kept saturated by the reduction).
    pub saturation_level: f32,
    /// Each frame's position in the case's video (poses.json order): `0..n` until frames are
    /// left out by the selection or the registration.
    pub frame_numbers: Vec<usize>,
}

impl BuildScene {
    /// Read the case in `case_dir`, segment its CT, mesh the lumen and lay out the atlas;
    /// records each stage's seconds in `timings`.
    pub fn prepare(
        case_dir: &std::path::Path,
        opts: &BuildOptions,
        timings: &mut BuildTimings,
    ) -> Result<BuildScene> {
        let t = Instant::now();
        let case = if opts.poses == super::options::PosesMode::First {
            Case::open_untracked(case_dir)?
        } else {
            Case::open(case_dir)?
        };
        timings.read_case = t.elapsed().as_secs_f64();

        let seg_opts = SegmentCommandOptions {
            force: false,
            ..opts.segment.clone()
        };
        let (segmentation, mesh, _mesh_report, [t_seg, t_mesh]) =
            segment_and_mesh(&case.ct, &seg_opts)?;
        timings.segment = t_seg;
        timings.mesh = t_mesh;

        let t = Instant::now();
        let atlas = build_atlas(&mesh, &opts.atlas)?;
        let texels = TexelSet::new(&rasterize_texels(&atlas, &mesh)?)?;
        timings.atlas = t.elapsed().as_secs_f64();

        let scene = Scene::new(&atlas.mesh)?;
        let full_rays = RayTable::new(&case.camera);
        let level = match opts.working_level {
            Some(level) => level,
            None => working_level(&case, &scene, opts.atlas.texel_mm),
        }
        .min(max_level(&case.camera));
        let camera = case.camera.at_level(level);
        let rays = if level == 0 {
            full_rays.clone()
        } else {
            RayTable::new(&camera)
        };
        let mask = case.mask.as_ref().map(|m| {
            reduce_mask(
                &m.image,
                case.camera.width as usize,
                case.camera.height as usize,
                level,
            )
        });
        let n = case.frame_count();
        Ok(BuildScene {
            poses: case.poses.iter().map(|p| p.pose.camera_to_world).collect(),
            segmentation,
            tri_uv: triangle_uvs(&atlas),
            texels,
            atlas,
            scene,
            level,
            camera,
            mask,
            cos_theta: cos_theta_of(&rays),
            rays,
            full_rays,
            cache: DepthCache::new(n, opts.depth_cache_bytes, level),
            saturation_level: opts.samples.saturation_level,
            frame_numbers: (0..n).collect(),
            case,
        })
    }

    /// Ray cast frame `i` from its pose at the working resolution; pixels outside the case's
    /// image mask see nothing.
    pub fn cast(&self, i: usize) -> GBuffer {
        let mut g = cast_frame_with(&self.scene, &self.rays, &self.poses[i]);
        if let Some(mask) = &self.mask {
            g.mask_out(mask);
        }
        g
    }

    /// Ray cast frame `i` at full resolution.
    pub fn cast_full(&self, i: usize) -> GBuffer {
        if self.level == 0 {
            return self.cast(i);
        }
        let mut g = cast_frame_with(&self.scene, &self.full_rays, &self.poses[i]);
        if let Some(mask) = &self.case.mask {
            g.mask_out(&mask.image);
        }
        g
    }

    /// The depth plane of [`BuildScene::cast`] alone (the same values).
    pub fn cast_depth(&self, i: usize) -> Vec<f32> {
        let mut z = cast_depth_with(&self.scene, &self.rays, &self.poses[i]);
        if let Some(mask) = &self.mask {
            mask_out_depth(&mut z, mask);
        }
        z
    }

    /// The depth plane of [`BuildScene::cast_full`] alone (the same values).
    pub fn cast_full_depth(&self, i: usize) -> Vec<f32> {
        if self.level == 0 {
            return self.cast_depth(i);
        }
        let mut z = cast_depth_with(&self.scene, &self.full_rays, &self.poses[i]);
        if let Some(mask) = &self.case.mask {
            mask_out_depth(&mut z, &mask.image);
        }
        z
    }

    /// A decoded frame at the working resolution.
    pub fn working_frame(&self, frame: Frame) -> Frame {
        if self.level == 0 {
            frame
        } else {
            reduce_frame(&frame, self.level, self.saturation_level)
        }
    }

    /// Keep only the frames `keep` (increasing indices into the current ones), e.g. those the
    /// registration could trust; the depth cache starts empty.
    pub fn keep_frames(&mut self, keep: &[usize], cache_bytes: usize) {
        self.case.poses = keep.iter().map(|&i| self.case.poses[i].clone()).collect();
        self.poses = keep.iter().map(|&i| self.poses[i]).collect();
        self.frame_numbers = keep.iter().map(|&i| self.frame_numbers[i]).collect();
        self.cache = DepthCache::new(self.poses.len(), cache_bytes, self.level);
    }

    /// Run `f` on the scene reduced to the frames `keep` (increasing indices), then restore
    /// every frame: the kept frames at the poses `f` left them at, the others where they were.
    /// The depth cache starts empty after it, unless `keep` is every frame (then `f` runs on
    /// the scene as it is, and what it cached stays).
    pub fn on_frames<T>(
        &mut self,
        keep: &[usize],
        cache_bytes: usize,
        f: impl FnOnce(&mut BuildScene) -> T,
    ) -> T {
        if keep.len() == self.frame_count() {
            return f(self);
        }
        let (case_poses, mut poses) = (self.case.poses.clone(), self.poses.clone());
        let numbers = self.frame_numbers.clone();
        self.keep_frames(keep, cache_bytes);
        let out = f(self);
        for (&i, p) in keep.iter().zip(&self.poses) {
            poses[i] = *p;
        }
        self.case.poses = case_poses;
        self.poses = poses;
        self.frame_numbers = numbers;
        self.cache = DepthCache::new(self.poses.len(), cache_bytes, self.level);
        out
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.poses.len()
    }

    /// Stream the frames `subset` (increasing indices) at `resolution` shaded by `shading`,
    /// with a progress bar of `passes` passes labelled `label`.
    pub fn frames<'a>(
        &'a self,
        resolution: Resolution,
        shading: &'a dyn FrameShaders,
        subset: Vec<usize>,
        label: &str,
        passes: usize,
        quiet: bool,
    ) -> CaseFrames<'a> {
        let progress = Progress::new(label, (passes * subset.len()) as u64, quiet);
        CaseFrames::new(self, shading, subset, resolution, progress)
    }

    /// Frame `i`'s file name (PNG) or index (video), for messages.
    pub fn frame_name(&self, i: usize) -> String {
        match &self.case.poses[i].frame {
            FrameRef::Image(p) => p.display().to_string(),
            FrameRef::VideoIndex(k) => format!("video frame {k}"),
        }
    }
}

/// Most reductions of the working resolution: the short side keeps at least 256 pixels (the
/// 320-pixel demo is fitted and registered at full resolution; its pixel-bound stages are a
/// small share of its build, so reducing it saves nothing measurable).
fn max_level(camera: &Camera) -> usize {
    coarsest_level(camera, 256, 3)
}

/// The coarsest level up to `most` at which the camera's short side keeps `min_side` pixels.
pub(super) fn coarsest_level(camera: &Camera, min_side: u32, most: usize) -> usize {
    (0..=most)
        .rev()
        .find(|&l| camera.width.min(camera.height) >> l >= min_side)
        .unwrap_or(0)
}

/// The working level chosen from the texel size and the camera: the coarsest at which a
/// pixel still covers no more than one texel at the median depth the video sees (sampled on
/// three frames by a coarse ray cast). Finer pixels would only resolve detail the texture's
/// fit does not use, at a cost that grows with the pixels.
fn working_level(case: &Case, scene: &Scene, texel_mm: f64) -> usize {
    let n = case.poses.len();
    if n == 0 {
        return 0;
    }
    // A coarse probe (~64 pixels across) is enough for a median.
    let probe = case.camera.at_level(coarsest_level(&case.camera, 64, 4));
    let rays = RayTable::new(&probe);
    let mut depths: Vec<f32> = [0, n / 2, n - 1]
        .iter()
        .flat_map(|&i| {
            cast_frame_with(scene, &rays, &case.poses[i].pose.camera_to_world)
                .z
                .into_iter()
                .filter(|z| z.is_finite() && *z > 0.0)
        })
        .collect();
    if depths.is_empty() {
        return 0;
    }
    let mid = depths.len() / 2;
    let (_, median, _) = depths.select_nth_unstable_by(mid, f32::total_cmp);
    let focal = case.camera.fx.min(case.camera.fy);
    // Pixel footprint at level L: 2^L * z / f (mm).
    let ratio = texel_mm * focal / f64::from(*median);
    if ratio >= 2.0 {
        ratio.log2().floor() as usize
    } else {
        0
    }
}
