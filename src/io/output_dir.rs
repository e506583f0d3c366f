//! Output folders written atomically: everything goes into a temporary folder beside the
//! target, which replaces the target only when complete. A failed or interrupted run never
//! leaves a half-written result that looks whole, and an existing result is replaced only
//! with `force`.

use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// A folder being written; [`OutputDir::commit`] moves it into place.
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: Option<tempfile::TempDir>,
    force: bool,
}

impl OutputDir {
    /// Start writing `target`. Fails when `target` exists and `force` is false, or when its
    /// parent folder cannot hold a temporary folder.
    pub fn create(target: &Path, force: bool) -> Result<OutputDir> {
        if target.exists() && !force {
            return Err(Error::invalid(
                target,
                "already exists; use --force to replace it (or choose another --out)",
            ));
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let staging = tempfile::Builder::new()
            .prefix(&format!(".{name}.partial-"))
            .tempdir_in(&parent)
            .map_err(|e| Error::io(&parent, e))?;
        Ok(OutputDir {
            target: target.to_path_buf(),
            staging: Some(staging),
            force,
        })
    }

    /// The temporary folder to write into.
    pub fn path(&self) -> &Path {
        self.staging.as_ref().expect("not yet committed").path()
    }

    /// A path inside the temporary folder.
    pub fn join(&self, rel: impl AsRef<Path>) -> PathBuf {
        self.path().join(rel)
    }

    /// The final location.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Move the finished folder into place (replacing an existing one when forced).
    pub fn commit(mut self) -> Result<PathBuf> {
        let staging = self.staging.take().expect("committed once").keep();
        // tempfile creates 0700 folders; a result folder is ordinary (0755).
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&staging, std::fs::Permissions::from_mode(0o755));
        }
        if self.target.exists() {
            if !self.force {
                return Err(Error::invalid(
                    &self.target,
                    "appeared while writing; not replaced (use --force)",
                ));
            }
            // Move the old result aside first so the swap leaves either the old or the new one.
            let old = staging.with_extension("old");
            std::fs::rename(&self.target, &old).map_err(|e| Error::io(&self.target, e))?;
            std::fs::rename(&staging, &self.target).map_err(|e| Error::io(&self.target, e))?;
            let removed = if old.is_dir() {
                std::fs::remove_dir_all(&old)
            } else {
                std::fs::remove_file(&old)
            };
            removed.map_err(|e| Error::io(&old, e))?;
        } else {
            std::fs::rename(&staging, &self.target).map_err(|e| Error::io(&self.target, e))?;
        }
        Ok(self.target.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commit_replaces_only_with_force_and_failure_leaves_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let target = tmp.path().join("model");
        {
            let out = OutputDir::create(&target, false).unwrap();
            std::fs::write(out.join("a.txt"), "one").unwrap();
            // Dropped without commit: a failed run leaves no target and no temporary folder.
        }
        assert!(!target.exists());
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
        let out = OutputDir::create(&target, false).unwrap();
        std::fs::write(out.join("a.txt"), "one").unwrap();
        out.commit().unwrap();
        let err = OutputDir::create(&target, false).unwrap_err().to_string();
        assert!(
            err.contains("already exists") && err.contains("--force"),
            "{err}"
        );
        let out = OutputDir::create(&target, true).unwrap();
        std::fs::write(out.join("b.txt"), "two").unwrap();
        out.commit().unwrap();
        assert!(!target.join("a.txt").exists());
        assert_eq!(
            std::fs::read_to_string(target.join("b.txt")).unwrap(),
            "two"
        );
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
    }
}
