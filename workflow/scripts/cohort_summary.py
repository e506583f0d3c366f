"""The cohort table: one row per case from what the workflow left in out/<case>/, written as
out/cohort.csv and out/cohort.html (atomically).

Read per case: failed.json (stage.py's failure record), inspect.json (`bronchosim inspect
--json`), model/model.json, model/poses.json (when registration ran: per frame
`correction_mm`, `correction_deg`, `status`), benchmarks/<stage>.tsv (Snakemake's
`benchmark:` files: wall seconds `s`), logs/<stage>.usage.json (stage.py: the kernel's peak
resident memory of the job, MB; Snakemake's sampled `max_rss` when it is missing).

Status: `ok` (every stage's output is there), `failed` (a stage failed: its one-line error; or
a stage's log exists without its output or an error, i.e. the job was killed), `pending`
(not run yet, e.g. the run was stopped before reaching the case).
"""
import csv
import html
import io
import json
import math
import os
import tempfile
from collections import Counter
from pathlib import Path

import cohort_cases as cc

STAGES = ["inspect", "build", "render", "flythrough"]
# The file each stage leaves when it is complete (bronchosim writes its folders atomically).
STAGE_RESULT = {
    "inspect": "inspect.json",
    "build": "model/model.json",
    "render": "views/render.json",
    "flythrough": "flythrough/path.json",
}
MAIN_COLUMNS = [
    "case", "status", "failed_stage", "error", "ct_dims", "ct_spacing_mm", "frames",
    "airway_volume_ml", "branches", "triangles", "shading_model",
    "pose_correction_mm_mean", "pose_correction_mm_max", "pose_correction_deg_mean",
    "pose_correction_deg_max", "pose_status",
]


def read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def read_benchmark(path: Path):
    """(wall seconds, peak RSS in MB) from a Snakemake benchmark TSV, or None."""
    try:
        rows = list(csv.DictReader(path.read_text().splitlines(), delimiter="\t"))
    except OSError:
        return None
    if not rows:
        return None
    def number(key):
        try:
            v = float(rows[-1][key])
        except (KeyError, TypeError, ValueError):
            return None
        return v if math.isfinite(v) else None
    return number("s"), number("max_rss")


def stage_usage(case_out: Path, stage: str):
    """(wall seconds, peak RSS in MB) of a stage's job: the wall time from Snakemake's
    benchmark, the peak from the kernel (stage.py's logs/<stage>.usage.json, exact) or else
    from the benchmark (sampled every 0.5 s, later every 30 s: it can miss a short peak)."""
    wall, rss = read_benchmark(case_out / "benchmarks" / f"{stage}.tsv") or (None, None)
    usage = read_json(case_out / "logs" / f"{stage}.usage.json") or {}
    if wall is None:
        wall = usage.get("wall_s")
    return wall, usage.get("peak_rss_mb", rss)


def pose_columns(poses):
    """Mean and max correction (mm, degrees) and the count of each frame status."""
    frames = (poses or {}).get("frames") or []
    mm = [f["correction_mm"] for f in frames if isinstance(f.get("correction_mm"), (int, float))]
    deg = [f["correction_deg"] for f in frames if isinstance(f.get("correction_deg"), (int, float))]
    statuses = Counter(str(f["status"]) for f in frames if "status" in f)
    out = {}
    if mm:
        out["pose_correction_mm_mean"] = sum(mm) / len(mm)
        out["pose_correction_mm_max"] = max(mm)
    if deg:
        out["pose_correction_deg_mean"] = sum(deg) / len(deg)
        out["pose_correction_deg_max"] = max(deg)
    if statuses:
        out["pose_status"] = " ".join(f"{k}:{n}" for k, n in sorted(statuses.items(), key=lambda kv: (-kv[1], kv[0])))
    return out


def status_of(case_dir: Path, case_out: Path):
    """(status, failed stage, error) of one case."""
    failure = read_json(case_out / cc.FAILURE_RECORD)
    if failure is not None:
        return "failed", failure.get("stage", ""), failure.get("error", "")
    stages = [s for s in STAGES if s != "render" or cc.views(case_dir) is not None]
    for stage in stages:
        if not (case_out / STAGE_RESULT[stage]).exists():
            log = case_out / "logs" / f"{stage}.log"
            if log.exists():
                return ("failed", stage,
                        f"no result and no error recorded: the job was interrupted (see logs/{stage}.log)")
            return "pending", stage, "not run yet"
    return "ok", "", ""


def case_row(case_dir: Path, case_out: Path) -> dict:
    """Every column of one case that its files give (missing ones are left out)."""
    status, stage, error = status_of(case_dir, case_out)
    row = {"case": case_out.name, "status": status, "failed_stage": stage, "error": error}
    inspection = read_json(case_out / "inspect.json") or {}
    ct = inspection.get("ct") or {}
    if ct.get("dims"):
        row["ct_dims"] = "x".join(str(d) for d in ct["dims"])
    if ct.get("spacing_mm"):
        row["ct_spacing_mm"] = "x".join(f"{s:.3g}" for s in ct["spacing_mm"])
    if (inspection.get("video") or {}).get("frames") is not None:
        row["frames"] = inspection["video"]["frames"]
    model = read_json(case_out / "model" / "model.json") or {}
    counts = model.get("counts") or {}
    for key, column in [("frames", "frames"), ("airway_volume_ml", "airway_volume_ml"),
                        ("branches", "branches"), ("triangles", "triangles")]:
        if key in counts:
            row[column] = counts[key]
    if "shading_model" in model:
        row["shading_model"] = model["shading_model"]
    for m in (model.get("cross_validation") or {}).get("models") or []:
        row[f"psnr_{m['model']}_db"] = m.get("mean_psnr_db")
    row.update(pose_columns(read_json(case_out / "model" / "poses.json")))
    for key, seconds in (model.get("timings") or {}).items():
        row[f"build_{key}_s"] = seconds
    peaks = []
    for stage in STAGES:
        wall, rss = stage_usage(case_out, stage)
        if wall is not None:
            row[f"{stage}_wall_s"] = wall
        if rss is not None:
            row[f"{stage}_peak_rss_mb"] = rss
            peaks.append(rss)
    if peaks:
        row["peak_rss_mb"] = max(peaks)
    if "generator" in model:
        row["bronchosim"] = model["generator"]
    return row


def columns(rows) -> list:
    """The main columns, then every other column in the order first seen."""
    cols = list(MAIN_COLUMNS)
    for row in rows:
        cols.extend(k for k in row if k not in cols)
    return cols


def cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.3f}".rstrip("0").rstrip(".") if abs(value) < 1e6 else f"{value:.0f}"
    return str(value)


def write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        with os.fdopen(fd, "w", newline="") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def to_csv(rows, cols) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in rows:
        w.writerow([cell(row.get(c)) for c in cols])
    return buf.getvalue()


def to_html(rows, cols, out: Path) -> str:
    counts = Counter(r["status"] for r in rows)
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = []
    for row in rows:
        cells = []
        for c in cols:
            text = html.escape(cell(row.get(c)))
            if c == "case":
                links = [f"<b>{text}</b>"]
                for label, rel in [("report", "model/report.html"), ("flythrough", "flythrough/flythrough.mp4")]:
                    if (out / row["case"] / rel).exists():
                        links.append(f'<a href="{html.escape(row["case"])}/{rel}">{label}</a>')
                text = " ".join(links)
            cells.append(f"<td>{text}</td>")
        body.append(f'<tr class="{html.escape(row["status"])}">{"".join(cells)}</tr>')
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>bronchosim cohort</title>
<style>
body {{ font: 14px sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
th, td {{ border: 1px solid #ccc; padding: 3px 6px; text-align: left; white-space: nowrap; }}
th {{ background: #eee; position: sticky; top: 0; }}
tr.failed td {{ background: #fde2e2; }}
tr.pending td {{ background: #fff6d5; }}
td:nth-child(4) {{ white-space: normal; min-width: 20em; }}
</style></head><body>
<h1>bronchosim cohort</h1>
<p>{len(rows)} cases: {html.escape(summary)}. Times in seconds, memory in MB (peak resident set
of each job, from Snakemake's benchmark files); PSNR of each shading model on held-out frames
(cross-validation in <code>bronchosim build</code>). The same table: <a href="cohort.csv">cohort.csv</a>.</p>
<table><thead><tr>{head}</tr></thead><tbody>
{chr(10).join(body)}
</tbody></table></body></html>
"""


def summarise(cases_dir, cases, out) -> list:
    """Write out/cohort.csv and out/cohort.html for `cases` (names under `cases_dir`); return
    the rows."""
    cases_dir, out = Path(cases_dir), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = [case_row(cases_dir / c, out / c) for c in cases]
    cols = columns(rows)
    write_atomic(out / "cohort.csv", to_csv(rows, cols))
    write_atomic(out / "cohort.html", to_html(rows, cols, out))
    return rows
