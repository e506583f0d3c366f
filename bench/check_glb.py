#!/usr/bin/env python3
"""Check a model's airway.glb the way its users' tools will load it (issue 7):

1. the Khronos glTF validator (npm `gltf-validator`, installed into bench/glb_check on first use)
   must report 0 errors and 0 warnings;
2. trimesh must load it as one textured mesh whose vertex and triangle counts match model.json
   and the validator, with UVs in [0, 1] and the embedded albedo of the atlas size.

usage: bench/check_glb.py MODEL_DIR      (e.g. bronchosim-demo/model after `bronchosim demo`)
exit status 0 when both pass.
"""
import json
import pathlib
import subprocess
import sys

import numpy as np
import trimesh

here = pathlib.Path(__file__).resolve().parent / "glb_check"


def main():
    model = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "bronchosim-demo/model")
    glb = model / "airway.glb"
    manifest = json.loads((model / "model.json").read_text())
    if not (here / "node_modules" / "gltf-validator").exists():
        subprocess.run(["npm", "install", "--silent", "--no-audit", "--no-fund"], cwd=here, check=True)
    v = subprocess.run(["node", str(here / "validate.mjs"), str(glb)], capture_output=True, text=True)
    report = json.loads(v.stdout)
    print("gltf-validator:", json.dumps(report))
    ok = v.returncode == 0 and report["errors"] == 0 and report["warnings"] == 0

    scene = trimesh.load(glb, force="scene")
    meshes = list(scene.geometry.values())
    m = meshes[0]
    tex = m.visual.material.baseColorTexture
    uv = np.asarray(m.visual.uv)
    print(
        f"trimesh: {len(meshes)} mesh, {len(m.vertices)} vertices, {len(m.faces)} triangles, "
        f"texture {tex.size if tex is not None else None}, UV range [{uv.min():.4f}, {uv.max():.4f}], "
        f"bounds (mm) {np.round(m.bounds, 1).tolist()}"
    )
    ok &= len(meshes) == 1
    ok &= len(m.faces) == manifest["counts"]["triangles"] == report["triangles"]
    ok &= tex is not None and list(tex.size) == manifest["counts"]["atlas_size"]
    ok &= uv.shape == (len(m.vertices), 2) and uv.min() >= 0.0 and uv.max() <= 1.0
    print("PASS" if ok else "FAIL")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
