//! What the phantom's truth folder gives the examples that compare a model with it: its linear
//! 16-bit images and its true surface, ready to be shaded by a model's light.

use std::path::Path;

use bronchosim::camera::Camera;
use bronchosim::image::Frame;
use bronchosim::io::mesh_export::read_ply;
use bronchosim::math::Affine;
use bronchosim::phantom::truth_io::read_png16;
use bronchosim::raycast::Scene;
use bronchosim::registration::photometric::{ModelParts, ModelView, PhotometricModel, RayGrid};
use bronchosim::render::views_io::View;

/// A linear 16-bit RGB truth image (`code / 65535`: `_linear.png`, `_albedo.png`) of
/// `width` x `height` pixels.
pub fn read_linear(path: &Path, width: u32, height: u32) -> bronchosim::Result<Frame> {
    let codes = read_png16(path, 3)?;
    let mut f = Frame::new(width, height);
    if codes.len() != f.rgb.len() {
        return Err(bronchosim::Error::invalid(
            path,
            format!("expected {width}x{height} pixels"),
        ));
    }
    for (v, c) in f.rgb.iter_mut().zip(codes) {
        *v = f32::from(c) / 65535.0;
    }
    Ok(f)
}

/// The phantom's true lumen (truth/lumen.ply), without a texture.
pub struct TrueSurface {
    scene: Scene,
    tri_uv: Vec<[[f32; 2]; 3]>,
}

impl TrueSurface {
    pub fn read(truth: &Path) -> bronchosim::Result<TrueSurface> {
        let scene = Scene::new(&read_ply(&truth.join("lumen.ply"))?)?;
        let tri_uv = vec![[[0.0f32; 2]; 3]; scene.triangle_count()];
        Ok(TrueSurface { scene, tri_uv })
    }

    /// The true surface lit by the light (and seen by the camera) of `parts`.
    pub fn model<'a>(&'a self, parts: ModelParts<'a>) -> bronchosim::Result<PhotometricModel<'a>> {
        PhotometricModel::new(ModelParts {
            scene: &self.scene,
            tri_uv: &self.tri_uv,
            texture: None,
            ..parts
        })
    }
}

/// A truth view's linear image `NNNNNN_<suffix>.png` (`linear` or `albedo`).
pub fn read_view_image(view: &View, suffix: &str, camera: &Camera) -> bronchosim::Result<Frame> {
    let stem = view.path.with_extension("");
    let path = format!("{}_{suffix}.png", stem.to_string_lossy());
    read_linear(Path::new(&path), camera.width, camera.height)
}

/// The surface points of `model` and of `truth` seen from `pose` on `grid`, and for each ray
/// the index of the true surface's point on it.
pub fn both_views(
    model: &PhotometricModel,
    truth: &PhotometricModel,
    grid: &RayGrid,
    pose: &Affine,
) -> (ModelView, ModelView, Vec<Option<usize>>) {
    let mv = model.view(grid, pose, 0.0);
    let tv = truth.view(grid, pose, 0.0);
    let mut on_true = vec![None; grid.rays.dirs.len()];
    for (k, q) in tv.points.iter().enumerate() {
        on_true[q.ray as usize] = Some(k);
    }
    (mv, tv, on_true)
}
