#!/usr/bin/env bash
# Every comparison of bronchosim with the reference tools (BENCHMARKS.md), from a fresh clone:
#
#   bash bench/run_all.sh [NAME ...]        (NAME: a script below without .py; default all)
#
# 1. the system tools: .ci/install-deps (ffmpeg, g++, pkg-config), node and npm for check_glb;
# 2. a Python venv holding exactly bench/requirements.txt (bench/.venv, or $BENCH_VENV);
# 3. bronchosim and the examples in release, in the repository's target folder (or
#    $CARGO_TARGET_DIR); each script builds what it runs, so this only makes the cost visible;
# 4. each comparison in turn; its output also goes to bench/results/NAME.txt (or $BENCH_OUT);
# 5. check_glb: `bronchosim demo` and the Khronos glTF validator (npm, into bench/glb_check) and
#    trimesh on its airway.glb.
# Large inputs are generated under /tmp once (about 2 GB). Exit status: 0 when every script ran.
set -euo pipefail
cd "$(dirname "$0")/.."
started=$SECONDS

bash .ci/install-deps
if ! command -v npm >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends nodejs npm
fi

venv=${BENCH_VENV:-$(pwd)/bench/.venv}
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r bench/requirements.txt
norm() { grep -v '^#' | grep -v '^$' | tr 'A-Z' 'a-z' | sort; }
if ! diff <(norm <bench/requirements.txt) <("$venv/bin/python" -m pip freeze --disable-pip-version-check | norm) >&2; then
  echo "error: $venv does not hold exactly bench/requirements.txt (< wanted, > installed)" >&2
  exit 1
fi
py="$venv/bin/python"

t=$SECONDS
cargo build --release --bin bronchosim --examples
target=$(cargo metadata --format-version 1 --no-deps | "$py" -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')
echo "release build: $((SECONDS - t)) s (target folder $target)"

results=${BENCH_OUT:-$(pwd)/bench/results}
mkdir -p "$results"
all=(nifti_vs_nibabel dicom_read undistort_vs_opencv frames marching_cubes_vs_vtk
     region_grow_vs_sitk raycast_vs_embree check_glb)
if [ $# -gt 0 ]; then names=("$@"); else names=("${all[@]}"); fi
failed=()
for name in "${names[@]}"; do
  [ -f "bench/$name.py" ] || { echo "error: no bench/$name.py" >&2; exit 2; }
  echo "=== $name"
  t=$SECONDS
  if [ "$name" = check_glb ]; then
    demo=$(mktemp -d "${TMPDIR:-/tmp}/bronchosim-bench-demo.XXXXXX")
    cmd=(sh -c "'$target/release/bronchosim' --quiet demo --out '$demo/demo' && '$py' bench/check_glb.py '$demo/demo/model'")
  else
    cmd=("$py" "bench/$name.py")
  fi
  if "${cmd[@]}" 2>&1 | tee "$results/$name.txt"; then
    echo "--- $name: $((SECONDS - t)) s"
  else
    echo "--- $name: FAILED after $((SECONDS - t)) s" >&2
    failed+=("$name")
  fi
  [ "$name" != check_glb ] || rm -rf "$demo"
done
echo "bench/run_all.sh: $((SECONDS - started)) s; outputs in $results"
if [ "${#failed[@]}" -gt 0 ]; then
  echo "error: failed: ${failed[*]}" >&2
  exit 1
fi
