//! `bronchosim view MODEL`: a self-contained browser viewer to fly through a built model, lit
//! as the bronchoscope lights it (issue 19).
//!
//! The folder holds `index.html`, the page's scripts and style, and `model-data.js` (the mesh,
//! the albedo atlas, the shading, the centre-line path and a coarse inside-distance field,
//! [`payload`]). Everything is loaded with plain `<script>` tags, so the page works from
//! file:// (a double click) and from any static server, with no network access.
//!
//! The page draws with WebGL2 exactly what `bronchosim render` computes per pixel: the
//! calibrated light `rho_c(gamma) s(theta) / z^2` of the camera's own light plus the new-view
//! ambient term, times the relative albedo (trilinear over the same mip chain, level from the
//! same footprint), then `kappa_c` times the view's own mean luminance (a reduction pass) on
//! every surface pixel, the gain (fixed, or the learnt auto-exposure), sRGB output. A model
//! shaded with the paper's Psi is drawn with the Psi of the k nearest fitted viewpoints,
//! blended with `render`'s weights (k = 4, or 1: the paper's nearest viewpoint).

pub mod field;
pub mod payload;

use std::path::{Path, PathBuf};

use crate::io::glb_import::read_glb;
use crate::io::output_dir::OutputDir;
use crate::io::png::{decode_png_bytes, read_png};
use crate::model::Model;
use crate::render::MipOptions;
use crate::shading::paper::PsiLookup;
use crate::workflow::flythrough::{read_lumen_mask, training_path_poses, FlythroughOptions};
use crate::{Error, Result};
use field::lumen_field;
use payload::{data_js, field_data, pack, row_major, Arrays, CameraData, Meta, ShadingData};

/// The page's files, written as they are (see `src/viewer/assets/`).
const ASSETS: [(&str, &str); 9] = [
    ("index.html", include_str!("assets/index.html")),
    ("viewer.css", include_str!("assets/viewer.css")),
    ("math.js", include_str!("assets/math.js")),
    ("decode.js", include_str!("assets/decode.js")),
    ("shaders.js", include_str!("assets/shaders.js")),
    ("renderer.js", include_str!("assets/renderer.js")),
    ("navigation.js", include_str!("assets/navigation.js")),
    ("ui.js", include_str!("assets/ui.js")),
    ("main.js", include_str!("assets/main.js")),
];

/// Options of [`write_viewer`].
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// Poses of the autopilot's path along the centre line.
    pub path_poses: usize,
    /// Sample spacing of the inside-distance field (mm; rounded down to whole voxels).
    pub field_spacing_mm: f64,
    /// How a model shaded with the paper's Psi picks its viewpoints (as `render --shading`).
    pub psi_lookup: PsiLookup,
    /// Replace an existing output folder.
    pub force: bool,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        ViewerOptions {
            path_poses: 400,
            field_spacing_mm: 1.0,
            psi_lookup: PsiLookup::default(),
            force: false,
        }
    }
}

/// What [`write_viewer`] wrote.
#[derive(Clone, Debug)]
pub struct ViewerSummary {
    /// The viewer folder.
    pub out: PathBuf,
    /// Total size of its files (bytes).
    pub bytes: u64,
    /// Mesh vertices and triangles.
    pub counts: [usize; 2],
    /// Length of the autopilot's path (mm; 0 when the centre line could not be traced).
    pub path_length_mm: f64,
    /// What the viewer could not do as usual.
    pub warnings: Vec<String>,
}

impl ViewerSummary {
    /// The command's summary.
    pub fn to_text(&self) -> String {
        let index = self.out.join("index.html");
        let mut s = format!(
            "viewer {} ({:.1} MB): {} triangles, autopilot path {:.0} mm\n\
             open {} in a browser (WebGL2; file:// or any static server)\n",
            self.out.display(),
            self.bytes as f64 / 1e6,
            self.counts[1],
            self.path_length_mm,
            index.display(),
        );
        for w in &self.warnings {
            s.push_str(&format!("warning: {w}\n"));
        }
        s
    }
}

/// The default output folder of `view MODEL`: `viewer` beside the model folder (where the
/// model's report links to).
pub fn default_viewer_dir(model_dir: &Path) -> PathBuf {
    let parent = model_dir
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    parent.join("viewer")
}

/// Write the viewer of the model folder `model_dir` into `out` (atomically; an existing `out`
/// is replaced only with `opts.force`).
pub fn write_viewer(model_dir: &Path, out: &Path, opts: &ViewerOptions) -> Result<ViewerSummary> {
    let model = Model::load(model_dir)?;
    refuse_to_replace_the_model(model_dir, out)?;
    // Before the slow part: an existing `out` is kept unless forced.
    let dir = OutputDir::create(out, opts.force)?;
    let gpath = model_dir.join("airway.glb");
    let glb = read_glb(&gpath)?;
    let (welded, map) = glb.mesh.welded();
    if welded.positions.len() != model.scene.normals.len() {
        return Err(Error::invalid(&gpath, "the mesh changed while it was read"));
    }
    let uvs = glb
        .uvs
        .ok_or_else(|| Error::invalid(&gpath, "no TEXCOORD_0"))?;
    let png = glb
        .texture_png
        .ok_or_else(|| Error::invalid(&gpath, "no embedded base colour texture"))?;
    let texture = decode_png_bytes(&png, &gpath)?;
    // Which walls a frame saw (absent in hand-made model folders: then nothing is marked).
    let cov_path = model_dir.join("coverage.png");
    let coverage = match cov_path.is_file() {
        true => Some(read_png(&cov_path)?),
        false => None,
    };
    if let Some(c) = &coverage {
        if (c.width, c.height) != (texture.width, texture.height) {
            return Err(Error::invalid(
                &cov_path,
                "not the size of the model's texture",
            ));
        }
    }
    let positions: Vec<[f32; 3]> = glb.mesh.positions.iter().map(|p| [p.x, p.y, p.z]).collect();
    let normals: Vec<[f32; 3]> = map
        .iter()
        .map(|&w| model.scene.normals[w as usize])
        .collect();

    let seg_path = model_dir.join("segmentation.nii.gz");
    let mask = read_lumen_mask(&seg_path)?;
    let field = lumen_field(&mask, opts.field_spacing_mm)
        .ok_or_else(|| Error::invalid(&seg_path, "the airway mask is empty"))?;
    let mut warnings = Vec::new();
    let fly = FlythroughOptions {
        frames: opts.path_poses.max(2),
        ..Default::default()
    };
    let (path, path_length_mm) = match training_path_poses(&model, &mask, &seg_path, &fly) {
        Ok((poses, len, _)) => (poses.iter().map(row_major).collect(), len),
        Err(e) => {
            warnings.push(format!(
                "no centre-line path ({e}); the autopilot follows the training viewpoints"
            ));
            let vps = model.shading.viewpoints.iter().map(|v| v.camera_to_world);
            (vps.collect(), 0.0)
        }
    };
    let shading = ShadingData::of(&model.shading, opts.psi_lookup).ok_or_else(|| {
        Error::invalid(
            model_dir.join("shading.json"),
            "the model's shading is missing",
        )
    })?;
    let (bin, sections) = pack(&Arrays {
        positions: &positions,
        normals: &normals,
        uvs: &uvs,
        indices: &glb.mesh.triangles,
        texture: &texture,
        field: &field,
        coverage: coverage.as_ref(),
    });
    let m = &model.manifest;
    let meta = Meta {
        format: 1,
        generator: format!("bronchosim {}", env!("CARGO_PKG_VERSION")),
        model_name: model_name(model_dir),
        shading,
        texture: payload::TextureData {
            width: texture.width,
            height: texture.height,
            texel_mm: m.texel_mm,
            albedo_scale: m.albedo_scale,
            colour_balance: m.colour_balance,
            max_level: MipOptions::default().max_level,
        },
        camera: CameraData::from(&m.camera),
        counts: [positions.len(), glb.mesh.triangles.len()],
        path,
        path_length_mm,
        field: field_data(&field),
        sections,
    };
    let js = data_js(&meta, &bin)?;
    let mut bytes = 0u64;
    for (name, text) in ASSETS
        .iter()
        .copied()
        .chain([("model-data.js", js.as_str())])
    {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| Error::io(&p, e))?;
        bytes += text.len() as u64;
    }
    let out = dir.commit()?;
    Ok(ViewerSummary {
        out,
        bytes,
        counts: meta.counts,
        path_length_mm,
        warnings,
    })
}

/// `out` must not be the model folder or hold it (`--force` would replace the model).
fn refuse_to_replace_the_model(model_dir: &Path, out: &Path) -> Result<()> {
    // A folder that does not exist yet cannot hold the model.
    let (Ok(model), Ok(out_abs)) = (model_dir.canonicalize(), out.canonicalize()) else {
        return Ok(());
    };
    if model.starts_with(&out_abs) {
        return Err(Error::invalid(
            out,
            "is (or holds) the model folder; choose another --out for the viewer",
        ));
    }
    Ok(())
}

/// The model folder's own name ("model" for "bronchosim-demo/model/").
fn model_name(dir: &Path) -> String {
    std::path::absolute(dir)
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "model".into())
}

/// Open `index` in the desktop's browser (xdg-open, open or start); the message says why not.
pub fn open_in_browser(index: &Path) -> std::result::Result<(), String> {
    let (program, args): (&str, Vec<&std::ffi::OsStr>) = if cfg!(target_os = "macos") {
        ("open", vec![index.as_os_str()])
    } else if cfg!(target_os = "windows") {
        (
            "cmd",
            vec![
                "/C".as_ref(),
                "start".as_ref(),
                "".as_ref(),
                index.as_os_str(),
            ],
        )
    } else {
        ("xdg-open", vec![index.as_os_str()])
    };
    std::process::Command::new(program)
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map(|_| ())
        .map_err(|e| {
            format!(
                "could not start {program} ({e}): open {} yourself",
                index.display()
            )
        })
}
