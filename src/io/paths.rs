//! Safe resolution of relative paths found inside input files (poses.json `"image"`,
//! views.json outputs): a path written in a file may only name something inside its base
//! folder.
//!
//! The rule is lexical: no absolute paths, no `..` climbing above the base folder. Symbolic
//! links that the user placed inside the folder are followed wherever they point (a case's
//! `frames/` linked to a data disk is common on clusters): the folder's owner chose them,
//! whereas a path in a poses.json may come from anywhere.

use std::path::{Component, Path, PathBuf};

use crate::{Error, Result};

/// Resolve `rel`, a path written in `file_for_errors`, against `base_dir` and refuse anything
/// that could reach outside `base_dir`.
///
/// Refused: an empty path, an absolute path (or one with a root or drive prefix), and `..`
/// components that climb above `base_dir`. The file need not exist (outputs are resolved before
/// they are written). Returns `base_dir` joined with the lexically normalised `rel` (no `.` or
/// `..` left), so messages show the names the user wrote.
pub fn resolve_inside(base_dir: &Path, rel: &str, file_for_errors: &Path) -> Result<PathBuf> {
    let refuse = |why: &str| Error::invalid(file_for_errors, format!("path {rel:?} {why}"));
    if rel.is_empty() {
        return Err(refuse("is empty"));
    }
    if rel.contains('\0') {
        return Err(refuse("contains a NUL byte"));
    }
    let mut normal = PathBuf::new();
    for component in Path::new(rel).components() {
        match component {
            Component::Prefix(_) | Component::RootDir => {
                return Err(refuse(
                    "is absolute; it must be relative to the case folder",
                ));
            }
            Component::CurDir => {}
            Component::ParentDir => {
                if !normal.pop() {
                    return Err(refuse("leads outside its folder (too many '..')"));
                }
            }
            Component::Normal(name) => normal.push(name),
        }
    }
    if normal.as_os_str().is_empty() {
        return Err(refuse("names the folder itself, not a file"));
    }
    Ok(base_dir.join(&normal))
}

/// [`resolve_inside`] for paths inside a case folder (CASE_FORMAT.md), e.g. poses.json images.
pub fn resolve_case_relative(
    case_dir: &Path,
    rel: &str,
    file_for_errors: &Path,
) -> Result<PathBuf> {
    resolve_inside(case_dir, rel, file_for_errors)
}

/// `path` relative to `base_dir` with `/` separators, for writing into JSON files; an error
/// names `file_for_errors` when `path` is not inside `base_dir`.
pub fn relative_slash_path(base_dir: &Path, path: &Path, file_for_errors: &Path) -> Result<String> {
    let rel = if path.is_absolute() || path.starts_with(base_dir) {
        path.strip_prefix(base_dir).map_err(|_| {
            Error::invalid(
                file_for_errors,
                format!("{} is not inside {}", path.display(), base_dir.display()),
            )
        })?
    } else {
        path
    };
    let mut parts = Vec::new();
    for component in rel.components() {
        match component {
            Component::Normal(name) => parts.push(name.to_str().ok_or_else(|| {
                Error::invalid(
                    file_for_errors,
                    format!("{} is not valid UTF-8", path.display()),
                )
            })?),
            Component::CurDir => {}
            _ => {
                return Err(Error::invalid(
                    file_for_errors,
                    format!("{} is not a plain relative path", path.display()),
                ))
            }
        }
    }
    if parts.is_empty() {
        return Err(Error::invalid(
            file_for_errors,
            format!("{} names the folder itself, not a file", path.display()),
        ));
    }
    Ok(parts.join("/"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lexical_rules() {
        let base = Path::new("/nonexistent-bronchosim-case");
        let f = Path::new("poses.json");
        assert_eq!(
            resolve_inside(base, "frames/./a/../000.png", f).unwrap(),
            base.join("frames/000.png")
        );
        assert!(resolve_inside(base, "/etc/passwd", f).is_err());
        assert!(resolve_inside(base, "../x.png", f).is_err());
        assert!(resolve_inside(base, "frames/../../x.png", f).is_err());
        assert!(resolve_inside(base, "", f).is_err());
        assert!(resolve_inside(base, ".", f).is_err());
        assert_eq!(
            relative_slash_path(base, &base.join("frames/000.png"), f).unwrap(),
            "frames/000.png"
        );
        assert!(relative_slash_path(base, Path::new("/elsewhere/x.png"), f).is_err());
    }
}
