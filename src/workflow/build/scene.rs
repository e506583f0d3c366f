//! The build's first stages — read the case, segment the airway, mesh its lumen, lay out the
//! texture atlas — and [`BuildScene`], what every later stage shares.

use std::time::Instant;

use super::frames::{CaseFrames, DepthCache};
use super::options::BuildOptions;
use crate::io::case::Case;
use crate::io::poses::FrameRef;
use crate::math::Affine;
use crate::model::manifest::BuildTimings;
use crate::raycast::{cast_frame_with, GBuffer, RayTable, Scene};
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
    /// The training camera's rays.
    pub rays: RayTable,
    /// cos theta (off the optical axis) of every pixel's ray.
    pub cos_theta: Vec<f32>,
    /// Depth buffers kept from the first pass over the frames.
    pub cache: DepthCache,
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
        let rays = RayTable::new(&case.camera);
        let n = case.frame_count();
        Ok(BuildScene {
            poses: case.poses.iter().map(|p| p.pose.camera_to_world).collect(),
            segmentation,
            tri_uv: triangle_uvs(&atlas),
            texels,
            atlas,
            scene,
            cos_theta: cos_theta_of(&rays),
            rays,
            cache: DepthCache::new(n, opts.depth_cache_bytes),
            case,
        })
    }

    /// Ray cast frame `i` from its pose; pixels outside the case's image mask see nothing.
    pub fn cast(&self, i: usize) -> GBuffer {
        let mut g = cast_frame_with(&self.scene, &self.rays, &self.poses[i]);
        if let Some(mask) = &self.case.mask {
            g.mask_out(&mask.image);
        }
        g
    }

    /// Keep only the frames `keep` (increasing indices into the current ones), e.g. those the
    /// registration could trust; the depth cache starts empty.
    pub fn keep_frames(&mut self, keep: &[usize], cache_bytes: usize) {
        self.case.poses = keep.iter().map(|&i| self.case.poses[i].clone()).collect();
        self.poses = keep.iter().map(|&i| self.poses[i]).collect();
        self.cache = DepthCache::new(self.poses.len(), cache_bytes);
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.poses.len()
    }

    /// Stream the frames `subset` (increasing indices) shaded by `shading`, with a progress bar
    /// of `passes` passes labelled `label`.
    pub fn frames<'a>(
        &'a self,
        shading: &'a dyn FrameShaders,
        subset: Vec<usize>,
        label: &str,
        passes: usize,
        quiet: bool,
    ) -> CaseFrames<'a> {
        let progress = Progress::new(label, (passes * subset.len()) as u64, quiet);
        CaseFrames::new(self, shading, subset, progress)
    }

    /// Frame `i`'s file name (PNG) or index (video), for messages.
    pub fn frame_name(&self, i: usize) -> String {
        match &self.case.poses[i].frame {
            FrameRef::Image(p) => p.display().to_string(),
            FrameRef::VideoIndex(k) => format!("video frame {k}"),
        }
    }
}
