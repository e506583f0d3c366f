//! The bronchoscope's light in `airway.glb`, for simulators and engines (Unity, Unreal,
//! three.js): a glTF `KHR_lights_punctual` spot light on a node that also carries a glTF
//! camera, placed at the reference frame's pose, with the full calibrated light in the node's
//! `extras`.
//!
//! A punctual spot light can only approximate the calibrated light: its angular falloff is the
//! extension's recommended one (`a = clamp((cos theta - cos outer) / (cos inner - cos outer),
//! 0, 1)^2`, fitted here to s(theta) by least squares), its surface response is the engine's
//! (Lambert for a rough, non-metallic material: `albedo / pi x I cos(gamma) / z^2`, so the
//! intensity per channel is fitted as `rho_c(gamma) ~ pi K_c gamma` over gamma in [0, 1]), and
//! the inter-reflection and ambient terms are left out. Distances are in the file's units (mm),
//! so the intensity is in candela per mm² of the usual metre-based scale; engines that apply
//! inverse-square falloff in scene units reproduce `rho / z²` as written.

use std::path::Path;

use serde_json::{json, Value};

use crate::camera::Camera;
use crate::shading::{CalibratedModel, FittedShading, ShadingKind};
use crate::{Error, Result};

/// The spot light fitted to a calibrated light.
#[derive(Clone, Debug, PartialEq)]
pub struct SpotFit {
    /// Linear RGB colour, largest channel 1.
    pub color: [f64; 3],
    /// Intensity (candela in the file's distance unit, mm), times `color`.
    pub intensity: f64,
    /// Inner cone angle (radians): full intensity inside it.
    pub inner: f64,
    /// Outer cone angle (radians): no light beyond it.
    pub outer: f64,
    /// RMS of `s(theta) - falloff(theta)` over the fitted angles (unitless; s = 1 on the axis).
    pub falloff_rms: f64,
}

/// The extension's recommended angular falloff.
pub fn spot_falloff(cos_theta: f64, inner: f64, outer: f64) -> f64 {
    let (ci, co) = (inner.cos(), outer.cos());
    let a = ((cos_theta - co) / (ci - co).max(1e-3)).clamp(0.0, 1.0);
    a * a
}

/// Fit the spot light to `light`, whose texture was encoded at `albedo_scale` x
/// `colour_balance` (model.json): the engine multiplies the base colour texture, so the
/// intensity divides them back out.
pub fn fit_spot(light: &CalibratedModel, albedo_scale: f32, colour_balance: [f32; 3]) -> SpotFit {
    // s beyond the fit's edge is held constant (as new views hold it), up to 89 degrees.
    let edge = light.theta_edge_deg().min(89.0).to_radians();
    let thetas: Vec<f64> = (0..=90)
        .map(|i| 89f64.to_radians() * i as f64 / 90.0)
        .collect();
    let s: Vec<f64> = thetas.iter().map(|t| light.s(t.cos())).collect();
    let rms = |inner: f64, outer: f64| {
        let e: f64 = thetas
            .iter()
            .zip(&s)
            .map(|(t, s)| (s - spot_falloff(t.cos(), inner, outer)).powi(2))
            .sum();
        (e / thetas.len() as f64).sqrt()
    };
    let mut best = (f64::INFINITY, 0.0, edge);
    let step = 0.25f64.to_radians();
    let n = (89f64.to_radians() / step) as usize;
    for i in 0..=n {
        for j in (i + 1)..=n.max(i + 1) {
            let (inner, outer) = (i as f64 * step, j as f64 * step);
            let e = rms(inner, outer);
            if e < best.0 {
                best = (e, inner, outer);
            }
        }
    }
    // Least squares of rho_c(gamma) = pi K_c gamma on a uniform grid of gamma in [0, 1].
    let gammas: Vec<f64> = (1..=100).map(|i| i as f64 / 100.0).collect();
    let gg: f64 = gammas.iter().map(|g| g * g).sum();
    let per_channel: [f64; 3] = std::array::from_fn(|c| {
        let k = gammas.iter().map(|&g| light.rho(c, g) * g).sum::<f64>() / gg;
        std::f64::consts::PI * k / f64::from(albedo_scale * colour_balance[c]).max(1e-12)
    });
    let intensity = per_channel.iter().copied().fold(0.0, f64::max).max(1e-12);
    SpotFit {
        color: per_channel.map(|v| (v / intensity).max(0.0)),
        intensity,
        inner: best.1,
        outer: best.2,
        falloff_rms: best.0,
    }
}

/// Column-major glTF node matrix of an OpenCV camera → world pose (glTF cameras and spot
/// lights look down -Z with +Y up: the OpenCV y and z axes flipped).
fn gltf_matrix(camera_to_world: &[f64; 16]) -> Vec<f64> {
    let m = |r: usize, c: usize| camera_to_world[4 * r + c];
    let mut out = Vec::with_capacity(16);
    for c in 0..4 {
        let sign = if c == 1 || c == 2 { -1.0 } else { 1.0 };
        for r in 0..4 {
            out.push(sign * m(r, c));
        }
    }
    out
}

/// Add the scope's light and camera to the GLB at `path` (rewritten atomically). Nothing is
/// added when the model's shading is not the calibrated light (the paper's Psi has no single
/// light to export).
pub fn add_scope_light(
    path: &Path,
    shading: &FittedShading,
    camera: &Camera,
    albedo_scale: f32,
    colour_balance: [f32; 3],
) -> Result<()> {
    let (ShadingKind::Calibrated, Some(light)) = (shading.model, &shading.calibrated) else {
        return Ok(());
    };
    let pose = shading
        .viewpoints
        .get(light.reference_frame)
        .or(shading.viewpoints.first())
        .map(|v| v.camera_to_world)
        .ok_or_else(|| Error::invalid(path, "no viewpoint to place the scope's light at"))?;
    let spot = fit_spot(light, albedo_scale, colour_balance);
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (mut root, bin) = split_glb(&bytes).map_err(|m| Error::invalid(path, m))?;
    let obj = root
        .as_object_mut()
        .ok_or_else(|| Error::invalid(path, "the glTF JSON is not an object"))?;
    let used = obj.entry("extensionsUsed").or_insert_with(|| json!([]));
    if let Some(a) = used.as_array_mut() {
        a.push(json!("KHR_lights_punctual"));
    }
    obj.insert(
        "extensions".into(),
        json!({"KHR_lights_punctual": {"lights": [{
            "name": "bronchoscope light",
            "type": "spot",
            "color": spot.color,
            "intensity": spot.intensity,
            "spot": {"innerConeAngle": spot.inner, "outerConeAngle": spot.outer},
        }]}}),
    );
    obj.insert(
        "cameras".into(),
        json!([{
            "name": "bronchoscope",
            "type": "perspective",
            "perspective": {
                "yfov": 2.0 * (f64::from(camera.height) / (2.0 * camera.fy)).atan(),
                "aspectRatio": f64::from(camera.width) * camera.fy / (f64::from(camera.height) * camera.fx),
                "znear": 0.1,
                "zfar": 2000.0,
            },
        }]),
    );
    let nodes = obj.entry("nodes").or_insert_with(|| json!([]));
    let node_index = nodes.as_array().map_or(0, Vec::len);
    if let Some(a) = nodes.as_array_mut() {
        a.push(json!({
            "name": "bronchoscope",
            "camera": 0,
            "matrix": gltf_matrix(&pose),
            "extensions": {"KHR_lights_punctual": {"light": 0}},
            "extras": {"bronchosim_light": light_extras(light, &spot, albedo_scale, colour_balance)},
        }));
    }
    if let Some(scene) = obj
        .get_mut("scenes")
        .and_then(|s| s.get_mut(0))
        .and_then(|s| s.get_mut("nodes"))
        .and_then(Value::as_array_mut)
    {
        scene.push(json!(node_index));
    }
    let js =
        serde_json::to_vec(&root).map_err(|e| Error::invalid(path, format!("glTF JSON: {e}")))?;
    crate::io::atomic::write_bytes_atomic(path, &join_glb(js, bin))
}

/// The full light model for engines that implement it (DESIGN.md, "one calibrated light").
fn light_extras(light: &CalibratedModel, spot: &SpotFit, scale: f32, balance: [f32; 3]) -> Value {
    json!({
        "model": "I_c = gain * (albedo_c * rho_c(gamma) + k_c * spec(gamma)) * s(theta) / z^2 + ambient_c + kappa_c * L",
        "specular": light.specular,
        "specular_lobe": "spec(gamma) = D G1^2 / (4 gamma) of GGX with roughness alpha, n.h = gamma (light at the lens), scaled to 1 at gamma = 1; absent: k = 0",
        "albedo_c": "base colour texture (linear) / (albedo_scale * colour_balance_c)",
        "rho": light.rho,
        "rho_basis": "Bernstein in gamma = |cos| between the view ray and the normal, over [0, 1]",
        "s": light.s,
        "s_basis": "Bernstein in t = (1 - cos theta) / (1 - cos_theta_edge), clamped to [0, 1]",
        "cos_theta_edge": light.cos_theta_edge,
        "z_unit": "mm",
        "ambient": light.new_view_ambient(),
        "interreflection_kappa": light.interreflection,
        "L": "the view's mean luminance (Rec. 709) over its surface pixels, inter-reflection included",
        "auto_exposure": light.auto_exposure,
        "albedo_scale": scale,
        "colour_balance": balance,
        "spot_falloff_rms": spot.falloff_rms,
    })
}

/// The JSON and BIN chunks of a GLB.
fn split_glb(b: &[u8]) -> std::result::Result<(Value, Vec<u8>), String> {
    let u32_at = |at: usize| -> std::result::Result<usize, String> {
        b.get(at..at + 4)
            .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
            .ok_or_else(|| "truncated GLB".to_string())
    };
    if b.get(0..4) != Some(b"glTF") {
        return Err("not a binary glTF file".into());
    }
    let (mut js, mut bin) = (None, Vec::new());
    let mut at = 12;
    while at + 8 <= b.len() {
        let len = u32_at(at)?;
        let data = b
            .get(at + 8..at + 8 + len)
            .ok_or("a GLB chunk runs past the end")?;
        match &b[at + 4..at + 8] {
            b"JSON" => {
                js = Some(serde_json::from_slice(data).map_err(|e| format!("glTF JSON: {e}"))?)
            }
            b"BIN\0" => bin = data.to_vec(),
            _ => {}
        }
        at += 8 + len;
    }
    Ok((js.ok_or("no JSON chunk")?, bin))
}

/// A GLB from its JSON and BIN chunks (padded to 4 bytes).
fn join_glb(mut js: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + js.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light(s: Vec<f64>) -> CalibratedModel {
        CalibratedModel::new(
            [vec![0.0, 2.0], vec![0.0, 1.0], vec![0.0, 0.5]],
            s,
            60f64.to_radians().cos(),
        )
    }

    #[test]
    fn a_light_that_is_a_spot_is_fitted_exactly() {
        // s = (1 - t)^2 with t = (1 - cos theta) / (1 - cos 60deg) is the extension's falloff
        // with inner 0 and outer 60 degrees; rho linear in gamma (Lambert): rho_R = 2 gamma.
        // The engine shades texture / pi x I cos(gamma) / z^2 with texture = albedo x
        // albedo_scale, so I = pi x 2 / albedo_scale = 4 pi.
        let l = light(vec![1.0, 0.0, 0.0]);
        let fit = fit_spot(&l, 0.5, [1.0, 1.0, 1.0]);
        let want = 4.0 * std::f64::consts::PI;
        assert!((fit.intensity - want).abs() < 1e-9, "{fit:?}");
        assert!((fit.color[1] - 0.5).abs() < 1e-9 && (fit.color[2] - 0.25).abs() < 1e-9);
        assert!(fit.inner.abs() < 1e-9, "{fit:?}");
        assert!((fit.outer.to_degrees() - 60.0).abs() < 0.01, "{fit:?}");
        assert!(fit.falloff_rms < 1e-9, "{fit:?}");
        // A wider, flat-topped profile moves the cone out and opens an inner angle.
        let wide = fit_spot(&light(vec![1.0, 1.0, 1.0, 0.2]), 0.5, [1.0; 3]);
        assert!(
            wide.inner > 5f64.to_radians() && wide.outer > fit.outer,
            "{wide:?}"
        );
    }

    #[test]
    fn opencv_to_gltf_axes() {
        // Identity pose: the glTF node looks down -Z = the OpenCV camera's +Z flipped.
        let mut id = [0.0; 16];
        for k in 0..4 {
            id[5 * k] = 1.0;
        }
        id[3] = 7.0;
        let g = gltf_matrix(&id);
        assert_eq!(&g[0..4], &[1.0, 0.0, 0.0, 0.0]);
        assert_eq!(&g[4..8], &[0.0, -1.0, 0.0, 0.0]);
        assert_eq!(&g[8..12], &[0.0, 0.0, -1.0, 0.0]);
        assert_eq!(&g[12..16], &[7.0, 0.0, 0.0, 1.0]);
    }
}
