//! The phantom case's truth folder (CASE_FORMAT.md): the lumen mesh and its albedo, the
//! gains and the light, the novel views with their pixel-centre buffers, and truth.json.

use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;

use super::{FrameGain, PhantomOptions, PhantomSummary, Stage};
use crate::camera::{Camera, Pose};
use crate::image::Frame;
use crate::io::atomic::write_json_atomic;
use crate::io::camera_file::write_camera_json;
use crate::io::mesh_export::write_ply;
use crate::io::png::write_png_srgb8;
use crate::io::poses::{write_poses, FrameRef, PoseEntry};
use crate::math::{Affine, Point3};
use crate::mesh::TriMesh;
use crate::phantom::baked_albedo::PhantomAlbedo;
use crate::phantom::render::{expose, render_radiance, LightModel, SensorModel, SubpixelRays};
use crate::phantom::truth_io::{
    write_albedo_ply, write_gray16_png, write_gray8_png, write_linear16_png,
};
use crate::raycast::{cast_frame, Scene};
use crate::{Error, Result};

#[derive(Serialize)]
struct GainsFile<'a> {
    description: &'static str,
    light: &'a LightModel,
    cone_exponent: f64,
    sensor: &'a SensorModel,
    reference_gain: f64,
    frames: Vec<FrameGain>,
}

/// Write the truth folder `truth` but its manifest: the lumen mesh, its albedo per vertex,
/// the gains and the light, and the novel views (rendered through the pinhole version of
/// `camera` at frame 0's gain). Returns the number of views.
pub(super) fn write_truth(
    truth: &Path,
    stage: &Stage,
    mesh: &TriMesh,
    camera: &Camera,
    views: &[Affine],
    gains: Vec<FrameGain>,
) -> Result<usize> {
    let opts = stage.opts;
    let vdir = truth.join("views");
    std::fs::create_dir_all(&vdir).map_err(|e| Error::io(&vdir, e))?;
    write_ply(&truth.join("lumen.ply"), mesh)?;
    let vertex_albedo: Vec<[f32; 3]> = mesh
        .positions
        .par_iter()
        .enumerate()
        .map(|(v, p)| {
            let p = Point3::new(p.x as f64, p.y as f64, p.z as f64);
            stage.albedo.at_vertex(v, p)
        })
        .collect();
    write_albedo_ply(&truth.join("albedo_vertices.ply"), mesh, &vertex_albedo)?;
    let reference_gain = gains[0].gain;
    let gfile = GainsFile {
        description:
            "linear frame = clip(gain * radiance + noise); radiance per render.rs with the \
                      light below; truth views use reference_gain (frame 0) and no noise",
        light: &opts.light,
        cone_exponent: opts.light.cone_exponent(),
        sensor: &opts.sensor,
        reference_gain,
        frames: gains,
    };
    write_json_atomic(&truth.join("gains.json"), &gfile)?;
    let pinhole = camera.pinhole();
    write_camera_json(&truth.join("camera.json"), &pinhole)?;
    let vrays = SubpixelRays::new(&pinhole, opts.supersample);
    let mut ventries = Vec::new();
    for (k, v) in views.iter().enumerate() {
        write_view(
            truth,
            k,
            v,
            &stage.scene,
            &pinhole,
            &vrays,
            &stage.albedo,
            opts,
            reference_gain,
        )?;
        ventries.push(PoseEntry {
            frame: FrameRef::Image(vdir.join(format!("{k:06}.png"))),
            pose: Pose::new(*v),
        });
    }
    write_poses(&truth.join("views.json"), &ventries, truth)?;
    Ok(ventries.len())
}

/// truth/truth.json: how the case was made and what each truth file holds.
pub(super) fn write_manifest(
    truth: &Path,
    opts: &PhantomOptions,
    sm: &PhantomSummary,
) -> Result<()> {
    let manifest = serde_json::json!({
        "generator": "bronchosim phantom",
        "seed": opts.seed,
        "anatomy": opts.anatomy.as_ref().map(|p| p.display().to_string()),
        "trachea_posterior_wall": opts.ct.tree.trachea_posterior_wall,
        "frames": sm.frames,
        "size": [opts.width, opts.height],
        "supersample": opts.supersample,
        "truth_grid_mm": opts.truth_grid_mm,
        "albedo": sm.albedo,
        "pose_noise": &opts.pose_noise,
        "motion_blur": {
            "share": opts.motion_blur.share,
            "length_share": opts.motion_blur.length_share,
            "sub_renders": opts.motion_blur.sub_renders(opts.width),
            "frames": &sm.blurred_frames,
        },
        "files": {
            "lumen.ply": "true lumen mesh, world mm (RAS+), normals into the lumen",
            "albedo": "how the frames, the views and albedo_vertices.ply evaluate the mucosa albedo: procedural at every hit, or baked on lumen.ply (a barycentric lattice per triangle, spacing_mm apart at most, interpolated linearly)",
            "albedo_vertices.ply": "the same mesh with float red, green, blue: linear albedo per vertex",
            "gains.json": "per-frame auto-gain, light and sensor model",
            "motion_blur.frames": "frames averaged over sub-renders along the exposure's motion (a fast turn plus the path's travel, symmetric about the frame's pose in poses.json)",
            "poses.json": "the true pose of every frame, images relative to the case folder (the case's poses.json has pose_noise added)",
            "views.json": "novel view poses (camera_to_world), images relative to truth/",
            "camera.json": "pinhole camera of the views (no distortion)",
            "views/NNNNNN.png": "sRGB 8-bit, clean (no noise), reference gain",
            "views/NNNNNN_linear.png": "linear 16-bit RGB: value = code / 65535",
            "views/NNNNNN_mask.png": "8-bit: 255 where the pixel-centre ray hits the mesh",
            "views/NNNNNN_depth.png": "16-bit: distance camera centre to surface along the pixel-centre ray, code / 100 mm (0 = miss)",
            "views/NNNNNN_albedo.png": "linear 16-bit RGB albedo at the pixel-centre hit"
        },
        "mesh": { "vertices": sm.mesh_vertices, "triangles": sm.mesh_triangles },
    });
    write_json_atomic(&truth.join("truth.json"), &manifest)
}

/// Render one truth view: clean image at the reference gain and pixel-centre buffers.
#[allow(clippy::too_many_arguments)]
fn write_view(
    truth: &Path,
    k: usize,
    pose: &Affine,
    scene: &Scene,
    pinhole: &Camera,
    rays: &SubpixelRays,
    albedo: &PhantomAlbedo,
    opts: &PhantomOptions,
    gain: f64,
) -> Result<()> {
    let rad = render_radiance(scene, rays, pose, albedo, &opts.light);
    let img = expose(&rad.frame, gain, &opts.sensor, false, 0, 0);
    let base = truth.join("views");
    write_png_srgb8(&base.join(format!("{k:06}.png")), &img)?;
    write_linear16_png(&base.join(format!("{k:06}_linear.png")), &img)?;
    let gb = cast_frame(scene, pinhole, pose);
    let (w, h) = (pinhole.width, pinhole.height);
    let mask: Vec<u8> = (0..gb.tri.len())
        .map(|i| if gb.hit(i) { 255 } else { 0 })
        .collect();
    let depth: Vec<u16> =
        gb.z.iter()
            .map(|&z| {
                if z.is_finite() {
                    (z as f64 * 100.0).round().clamp(1.0, 65535.0) as u16
                } else {
                    0
                }
            })
            .collect();
    let mut alb = Frame::new(w, h);
    for i in 0..gb.tri.len() {
        if gb.hit(i) {
            let a = albedo.at(gb.tri[i], gb.bary[i], gb.point[i]);
            alb.rgb[3 * i..3 * i + 3].copy_from_slice(&a);
        }
    }
    write_gray8_png(&base.join(format!("{k:06}_mask.png")), w, h, &mask)?;
    write_gray16_png(&base.join(format!("{k:06}_depth.png")), w, h, &depth)?;
    write_linear16_png(&base.join(format!("{k:06}_albedo.png")), &alb)
}
