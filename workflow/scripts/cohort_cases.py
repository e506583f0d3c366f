"""The cases of a cohort and what each stage reads: used by workflow/Snakefile at parse time
and by the summary (cohort_summary.py).

A case is every sub-folder of the `cases` folder whose name does not start with a dot; a
folder that is not a valid case (no CT, say) is still a case, so it gets its row (failed).
"""
import json
import os
from pathlib import Path

# The files of a case that `inspect` and `build` read (shared/CASE_FORMAT.md). Anything else
# in the folder (truth/, notes) changes nothing and triggers no rebuild.
CASE_FILES = ["ct.nii.gz", "ct.nii", "camera.json", "camera.yml", "camera.yaml",
              "camera.xml", "poses.json", "video.mp4", "mask.png"]
CASE_FOLDERS = ["ct", "frames"]
# Where a case's novel views are looked for, in order: the case format's own views.json, then
# the phantom's truth views (bronchosim phantom writes truth/views.json and truth/camera.json).
VIEWS_FILES = ["views.json", "truth/views.json"]
FAILURE_RECORD = "failed.json"


def discover(cases_dir: Path) -> list:
    """Names of the case folders under `cases_dir`, sorted."""
    if not cases_dir.is_dir():
        raise ValueError(f"cases={cases_dir}: not a folder")
    return sorted(p.name for p in cases_dir.iterdir() if p.is_dir() and not p.name.startswith("."))


def input_files(case_dir: Path) -> list:
    """The files `inspect` and `build` read, as paths (frames/ and ct/ listed file by file so
    that a changed frame is seen: a folder's own time changes only when entries come or go)."""
    files = [case_dir / n for n in CASE_FILES if (case_dir / n).is_file()]
    for folder in CASE_FOLDERS:
        root = case_dir / folder
        if root.is_dir():
            for dirpath, _dirs, names in os.walk(root):
                files.extend(Path(dirpath) / n for n in sorted(names) if not n.startswith("."))
    return files


def views(case_dir: Path):
    """(views.json, camera.json or None) of the case's novel views, or None when it has none.

    The camera is the camera.json beside the views file (the phantom's truth views are
    rendered with an undistorted camera); without one the model's training camera is used.
    """
    for name in VIEWS_FILES:
        v = case_dir / name
        if v.is_file():
            cam = v.parent / "camera.json"
            return v, (cam if cam.is_file() else None)
    return None


def newest_mtime(paths) -> float:
    """Latest modification time among `paths` (0 for none)."""
    return max((p.stat().st_mtime for p in paths if p.exists()), default=0.0)


def current_failure(case_dir: Path, case_out: Path, fingerprint: str):
    """The case's failure record when it still holds: written by the same binary version and
    settings, and newer than every file the case's stages read. Then the case is left alone
    (it would fail the same way); otherwise None and the case is run again."""
    record = case_out / FAILURE_RECORD
    if not record.is_file():
        return None
    try:
        failure = json.loads(record.read_text())
    except (OSError, ValueError):
        return None
    if failure.get("fingerprint") != fingerprint:
        return None
    inputs = input_files(case_dir)
    v = views(case_dir)
    if v is not None:
        inputs.extend(p for p in v if p is not None)
    # The folder itself too: a CT added after the failure is a new entry.
    inputs.append(case_dir)
    if newest_mtime(inputs) > record.stat().st_mtime:
        return None
    return record
