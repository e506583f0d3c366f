//! Reading a scope's calibrated light from a model folder built with the same bronchoscope
//! (`build --scope-light`, `register --scope-light`).

use std::path::Path;

use crate::shading::calibrated::ScopeLight;
use crate::shading::FittedShading;
use crate::{Error, Result};

/// The calibrated light of the model at `path`: a model folder (its shading.json) or a
/// shading.json itself. Errors name the file and what is wrong with it.
pub fn read_scope_light(path: &Path) -> Result<ScopeLight> {
    let file = match path.is_dir() {
        true => path.join("shading.json"),
        false => path.to_path_buf(),
    };
    let text = std::fs::read_to_string(&file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => {
            Error::missing(&file, "the scope light: a model folder or its shading.json")
        }
        _ => Error::io(&file, e),
    })?;
    let shading: FittedShading = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(&file, format!("not a model's shading.json: {e}")))?;
    let light = shading.calibrated.ok_or_else(|| {
        Error::invalid(
            &file,
            "no calibrated light (the model was built with --shading paper)",
        )
    })?;
    light
        .validate()
        .map_err(|m| Error::invalid(&file, format!("calibrated light: {m}")))?;
    Ok(ScopeLight {
        source: file,
        light,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(path: &Path) -> String {
        read_scope_light(path).unwrap_err().to_string()
    }

    #[test]
    fn bad_scope_lights_name_the_file_and_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let m = message(dir.path());
        assert!(
            m.contains("shading.json") && m.contains("scope light"),
            "{m}"
        );
        let file = dir.path().join("shading.json");
        std::fs::write(&file, "{\"model\": \"calibrated\"").unwrap();
        let m = message(&file);
        assert!(
            m.contains("shading.json") && m.contains("not a model's"),
            "{m}"
        );
        std::fs::write(&file, r#"{"model": "paper", "viewpoints": []}"#).unwrap();
        let m = message(dir.path());
        assert!(m.contains("no calibrated light"), "{m}");
    }
}
