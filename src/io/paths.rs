//! Safe resolution of relative paths found inside input files (poses.json `"image"`,
//! views.json outputs): a path may only name something inside its base folder.

use std::path::{Component, Path, PathBuf};

use crate::{Error, Result};

/// Resolve `rel`, a path written in `file_for_errors`, against `base_dir` and refuse anything
/// that could reach outside `base_dir`.
///
/// Refused: an empty path, an absolute path (or one with a root or drive prefix), `..`
/// components that climb above `base_dir`, and — for the part of the path that already exists —
/// symbolic links whose canonical target lies outside the canonical `base_dir`. The file itself
/// need not exist (outputs are resolved before they are written): then its deepest existing
/// ancestor is checked. Returns `base_dir` joined with the lexically normalised `rel` (no `.` or
/// `..` left), not the canonical path, so messages show the names the user wrote.
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
    let joined = base_dir.join(&normal);

    // Symlinks: compare canonical forms. Without a canonical base (folder not created yet)
    // nothing inside it can be a link, so the lexical check above is complete.
    if let Ok(base_canonical) = base_dir.canonicalize() {
        let mut existing = joined.as_path();
        loop {
            if let Ok(canonical) = existing.canonicalize() {
                if !canonical.starts_with(&base_canonical) {
                    return Err(refuse(&format!(
                        "leads outside its folder through a symbolic link (to {})",
                        canonical.display()
                    )));
                }
                break;
            }
            // A dangling symlink cannot be canonicalised: refuse it rather than guess its target.
            if existing.symlink_metadata().is_ok() {
                return Err(refuse("is a dangling symbolic link"));
            }
            match existing.parent() {
                Some(parent) if parent.starts_with(base_dir) => existing = parent,
                _ => break,
            }
        }
    }
    Ok(joined)
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
