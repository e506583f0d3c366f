//! A copy of a phantom case with other poses, for the examples that build models from
//! another run's poses.

use bronchosim::io::poses::{write_poses, FrameRef, PoseEntry};
use std::path::Path;

/// A copy of the case at `to` with its own poses.json (everything else hard-linked).
pub fn case_copy(from: &Path, to: &Path, poses: &[PoseEntry]) -> anyhow::Result<()> {
    std::fs::create_dir_all(to.join("frames"))?;
    for e in std::fs::read_dir(from)? {
        let p = e?.path();
        let name = p.file_name().unwrap();
        if name == "poses.json" || name == "truth" {
            continue;
        }
        if p.is_dir() {
            for f in std::fs::read_dir(&p)? {
                let f = f?.path();
                std::fs::hard_link(&f, to.join(name).join(f.file_name().unwrap()))?;
            }
        } else {
            std::fs::hard_link(&p, to.join(name))?;
        }
    }
    let entries: Vec<PoseEntry> = poses
        .iter()
        .map(|p| PoseEntry {
            frame: match &p.frame {
                FrameRef::Image(i) => FrameRef::Image(to.join(i.strip_prefix(from).unwrap_or(i))),
                other => other.clone(),
            },
            pose: p.pose,
        })
        .collect();
    write_poses(&to.join("poses.json"), &entries, to)?;
    Ok(())
}
