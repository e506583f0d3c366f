//! Novel views (paper §2.4, Fig. 4) and their evaluation against reference images (issue 7).
//!
//! ```text
//! Scene + triangle UVs + MipTexture + Psi models ─ render_view(camera, pose) ─► Frame + hit mask
//! rendered / baseline frames + reference frames ─ evaluate_methods ─► PSNR, SSIM per view
//! ```

pub mod baselines;
pub mod evaluate;
mod novel_view;
pub mod texture_sampler;
pub mod views_io;

pub use baselines::{flat_albedo_view, reproject_nearest_frame, TrainingView};
pub use evaluate::{evaluate_methods, MaskedImage, MethodScore, ViewScore};
pub use novel_view::{
    render_view, render_view_with, triangle_uvs, RenderInputs, RenderOptions, ViewRays,
};
pub use texture_sampler::{MipOptions, MipTexture};
pub use views_io::{evaluate_folders, read_views, render_views, View};
