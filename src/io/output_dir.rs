//! Output folders written atomically: everything goes into a temporary folder beside the
//! target, which replaces the target only when complete. A failed or interrupted run never
//! leaves a half-written result that looks whole, and an existing result is replaced only
//! with `force`. A temporary folder left by a run that was killed is removed by the next run
//! for the same target (its name carries the writing process's id).

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
        let prefix = format!(".{name}.partial-");
        for stale in remove_stale_partials(&parent, &prefix) {
            eprintln!(
                "note: removed {}, left by an interrupted run",
                stale.display()
            );
        }
        let staging = tempfile::Builder::new()
            .prefix(&format!("{prefix}{}-", std::process::id()))
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

/// Remove the folders `parent/<prefix><pid>-*` whose process `pid` no longer runs (and those
/// without a process id, from older versions); returns what was removed. A folder that cannot
/// be read or removed is left alone: it is only a leftover.
fn remove_stale_partials(parent: &Path, prefix: &str) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(prefix) else {
            continue;
        };
        let owner = rest.split('-').next().and_then(|p| p.parse::<u32>().ok());
        if owner.is_some_and(process_runs) {
            continue;
        }
        let path = entry.path();
        if path.is_dir() && std::fs::remove_dir_all(&path).is_ok() {
            removed.push(path);
        }
    }
    removed
}

/// True when process `pid` exists (on Linux, its /proc entry); elsewhere every process is
/// assumed to run, so nothing another run may still be writing is removed.
fn process_runs(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new(&format!("/proc/{pid}")).exists()
    } else {
        true
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

    #[test]
    fn a_killed_runs_partial_folder_is_removed_and_a_running_ones_kept() {
        let tmp = tempfile::tempdir().unwrap();
        let target = tmp.path().join("model");
        // pid 0 never names a user process: its folder is a leftover. Ours is alive.
        let dead = tmp.path().join(".model.partial-0-abc");
        let alive = tmp
            .path()
            .join(format!(".model.partial-{}-xyz", std::process::id()));
        let other = tmp.path().join(".other.partial-0-abc");
        for d in [&dead, &alive, &other] {
            std::fs::create_dir_all(d.join("sub")).unwrap();
        }
        let out = OutputDir::create(&target, false).unwrap();
        assert!(!dead.exists(), "a dead run's folder is removed");
        assert!(
            alive.exists() && other.exists(),
            "live and unrelated folders stay"
        );
        out.commit().unwrap();
    }
}
