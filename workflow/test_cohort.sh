#!/usr/bin/env bash
# The cohort workflow end to end (issue 20): three small phantom cases, one broken (no CT), run
# with `--cores 2 --keep-going`; then: two models, the broken case failed with its error,
# cohort.csv with three rows; a second run has nothing to do; a scope light plans the builds
# again with it; a changed case (and the fixed broken one) and nothing else is planned again;
# the SLURM profile's dry run plans every job.
#
#   bash workflow/test_cohort.sh [BRONCHOSIM_BINARY]
#
# Without a binary it builds and uses the release one (cargo build --release). Snakemake comes
# from workflow/requirements.txt, installed into workflow/.venv (or $COHORT_VENV); the test
# fails when that venv holds anything but exactly those pinned packages.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)
started=$SECONDS
passed=0
pass() { passed=$((passed + 1)); echo "ok: $*"; }
fail() { echo "FAILED: $*" >&2; echo "cohort: $passed passed, 1 failed"; exit 1; }

# The binary.
if [ $# -ge 1 ]; then
  bin=$(realpath "$1")
else
  cargo build --release --quiet --bin bronchosim
  bin="$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')/release/bronchosim"
fi
[ -x "$bin" ] || fail "no bronchosim binary at $bin"
echo "binary: $bin ($("$bin" --version))"

# Snakemake, pinned.
venv=${COHORT_VENV:-$repo/workflow/.venv}
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r workflow/requirements.txt
norm() { tr 'A-Z' 'a-z' | sort; }
want=$(grep -v '^#' workflow/requirements.txt | grep -v '^$' | norm)
have=$("$venv/bin/python" -m pip freeze --disable-pip-version-check | norm)
if [ "$want" != "$have" ]; then
  diff <(echo "$want") <(echo "$have") >&2 || true
  fail "$venv does not hold exactly workflow/requirements.txt (< wanted, > installed)"
fi
"$venv/bin/python" -m pip check --disable-pip-version-check >/dev/null || fail "pip check: broken requirements in $venv"
pass "venv $venv holds exactly the pinned packages ($("$venv/bin/snakemake" --version))"
snakemake() { "$venv/bin/snakemake" "$@"; }

# The summary's arithmetic on hand-made case folders.
"$venv/bin/python" -m unittest discover -s workflow/tests -p 'test_*.py' 2>&1 | tail -n 3
"$venv/bin/python" -m unittest discover -s workflow/tests -p 'test_*.py' >/dev/null 2>&1 || fail "workflow/tests"
pass "workflow/tests (summary and case discovery)"

# Three cases: two phantoms (seeds 1 and 2) and a copy of the first without its CT.
work=$(mktemp -d "${TMPDIR:-/tmp}/bronchosim-cohort.XXXXXX")
trap 'rm -rf "$work"' EXIT
for seed in 1 2; do
  "$bin" phantom --out "$work/cases/p$seed" --frames 12 --size 96x96 --seed "$seed" --quiet
done
cp -r "$work/cases/p1" "$work/cases/broken"
rm "$work/cases/broken/ct.nii.gz"
echo "phantoms: $((SECONDS - started)) s"

# The light refits only improve the texture; off here to keep the test quick.
config=(cases="$work/cases" out="$work/out" bin="$bin" threads=2 flythrough_frames=8
        "build_args=--light-refits 0 --chroma-refits 0")
run() { snakemake -s workflow/Snakefile --cores 2 --keep-going --config "${config[@]}" "$@"; }

t=$SECONDS
if run >"$work/run1.log" 2>&1; then
  tail -n 20 "$work/run1.log"; fail "first run exited 0 although a case has no CT"
fi
echo "first run: $((SECONDS - t)) s"
grep -q "cohort summary: $work/out/cohort.csv (2 ok, not ok: broken)" "$work/run1.log" \
  || { tail -n 30 "$work/run1.log"; fail "first run did not write the summary after the failure"; }
pass "first run failed (one case broken) and still wrote the summary"
for c in p1 p2; do
  [ -f "$work/out/$c/model/model.json" ] || fail "$c: no model"
  [ -f "$work/out/$c/views/views/000000.png" ] || fail "$c: truth views not rendered"
  [ -f "$work/out/$c/flythrough/frame_0007.png" ] || fail "$c: no flythrough"
done
[ ! -e "$work/out/broken/model" ] || fail "broken: a model folder exists"
pass "two models with rendered views and flythroughs, none for the broken case"
partials=$(find "$work/out" -name '*.partial*' | wc -l)
[ "$partials" -eq 0 ] || fail "$partials half-written files left in out/"
pass "no half-written files"

# The table: three rows, values read back from the models and the benchmark records.
"$venv/bin/python" - "$work/out" <<'EOF' || fail "cohort.csv / cohort.html"
import csv, json, sys
from pathlib import Path
out = Path(sys.argv[1])
rows = {r["case"]: r for r in csv.DictReader(open(out / "cohort.csv"))}
assert sorted(rows) == ["broken", "p1", "p2"], sorted(rows)
b = rows["broken"]
assert b["status"] == "failed" and b["failed_stage"] == "inspect", b
assert "no CT: expected ct.nii.gz" in b["error"], b["error"]
for c in ["p1", "p2"]:
    r = rows[c]
    m = json.loads((out / c / "model" / "model.json").read_text())
    assert r["status"] == "ok", r
    assert r["ct_dims"] == "x".join(map(str, json.loads((out / c / "inspect.json").read_text())["ct"]["dims"])), r["ct_dims"]
    assert abs(float(r["airway_volume_ml"]) - m["counts"]["airway_volume_ml"]) < 1e-3, r
    assert int(r["branches"]) >= 7, r["branches"]  # the phantom tree, as tests/cli_segment.rs
    for model in ["paper", "calibrated"]:
        assert 15 < float(r[f"psnr_{model}_db"]) < 50, (model, r[f"psnr_{model}_db"])
    assert abs(float(r["build_total_s"]) - m["timings"]["total"]) < 1e-3, r
    assert 50 < float(r["build_peak_rss_mb"]) < 4000, r["build_peak_rss_mb"]
    assert float(r["peak_rss_mb"]) >= float(r["build_peak_rss_mb"]), r
    # Registration runs by default: the columns summarise the model's poses.json.
    frames = json.loads((out / c / "model" / "poses.json").read_text())["frames"]
    mean_mm = sum(f["correction_mm"] for f in frames) / len(frames)
    assert abs(float(r["pose_correction_mm_mean"]) - mean_mm) < 1e-3, (r["pose_correction_mm_mean"], mean_mm)
    assert r["pose_status"] and m["registration"]["kept"] in ("given", "refined"), r["pose_status"]
assert rows["p1"]["airway_volume_ml"] != rows["p2"]["airway_volume_ml"], "two seeds, one airway?"
page = (out / "cohort.html").read_text()
assert all(f"<b>{c}</b>" in page for c in rows) and "no CT: expected" in page
print("cohort.csv:", ", ".join(f"{c} {r['status']}" for c, r in sorted(rows.items())),
      "| build peak", rows["p1"]["build_peak_rss_mb"], "MB")
EOF
pass "cohort.csv: three rows (two ok with their numbers, broken failed with its error); cohort.html"

t=$SECONDS
run >"$work/run2.log" 2>&1 || { tail -n 20 "$work/run2.log"; fail "second run failed"; }
grep -q "Nothing to be done" "$work/run2.log" || { tail -n 30 "$work/run2.log"; fail "second run did something"; }
echo "second run: $((SECONDS - t)) s"
pass "second run: nothing to be done"

# The same bronchoscope's light for every build (a copy of p1's model standing for a calibrated
# scope): the builds are planned again with --scope-light; a scope light that is not there, or
# one under out/ (which the cohort rebuilds), is named before any job.
with_scope() { snakemake -s workflow/Snakefile --cores 2 --dry-run --printshellcmds --config "${config[@]}" scope_light="$1"; }
cp -r "$work/out/p1/model" "$work/scope"
with_scope "$work/scope" >"$work/scope.log" 2>&1 || { tail -n 20 "$work/scope.log"; fail "dry run with a scope light failed"; }
n=$(grep -c -- "--scope-light [^ ]*/scope/shading.json" "$work/scope.log" || true)
[ "$n" -ge 2 ] || { tail -n 30 "$work/scope.log"; fail "dry run with a scope light: $n build commands with --scope-light (want p1's and p2's)"; }
for bad in "$work/nowhere" "$work/out/p1/model"; do
  if with_scope "$bad" >"$work/scope_bad.log" 2>&1; then fail "scope_light=$bad was accepted"; fi
  grep -q "scope_light=$bad" "$work/scope_bad.log" || { tail -n 5 "$work/scope_bad.log"; fail "scope_light=$bad is not named"; }
done
pass "scope_light: the builds planned again with --scope-light; a missing one and one under out/ named"

# A changed frame of p2 (new content: Snakemake compares checksums of inputs under 1 MB, so a
# mere touch is no change) and a CT given to the broken case: only those two are planned again.
cp "$work/cases/p1/frames/000003.png" "$work/cases/p2/frames/000003.png"
cp "$work/cases/p1/ct.nii.gz" "$work/cases/broken/ct.nii.gz"
run --dry-run >"$work/run3.log" 2>&1 || { tail -n 20 "$work/run3.log"; fail "dry run after the change failed"; }
planned=$(grep -o 'case=[a-z0-9]*' "$work/run3.log" | sort -u | tr '\n' ' ')
[ "$planned" = "case=broken case=p2 " ] || fail "planned again: '$planned' (want broken and p2 only)"
pass "after a change only the changed case and the fixed one are planned"
rm "$work/cases/broken/ct.nii.gz"

# The cluster profile: a dry run plans every stage with its SLURM resources (a dry run caps
# threads at --cores, 1 by default; 64 stands for the cluster's nodes).
rm -rf "$work/out/p1"
snakemake -s workflow/Snakefile --profile workflow/profiles/slurm --dry-run --cores 64 \
  --config "${config[@]}" >"$work/slurm.log" 2>&1 || { tail -n 20 "$work/slurm.log"; fail "SLURM profile dry run"; }
for rule in inspect build render flythrough; do
  grep -q "rule $rule:" "$work/slurm.log" || fail "SLURM dry run has no $rule job"
done
grep -q "stage build .*--threads 8 " "$work/slurm.log" || fail "SLURM dry run: build without the profile's 8 threads"
grep -q "mem_mb=1500, .*runtime=30" "$work/slurm.log" || fail "SLURM dry run: flythrough without the profile's memory"
pass "SLURM profile dry run plans inspect, build, render and flythrough with the profile's threads and memory"

echo "cohort test: $((SECONDS - started)) s"
echo "cohort: $passed passed, 0 failed"
