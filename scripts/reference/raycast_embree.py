#!/usr/bin/env python3
"""Reference closest hits from Embree (embreex, via trimesh's mesh tools) for tests/raycast.rs.

Mesh: a noisy icosphere (radius ~10 mm) with a cylinder and a box inside it, 1452 triangles.
Rays: 1000 from random points inside the sphere, 1000 from outside aimed at random points
near the centre; all directions unit. Embree's robust mode is on (no cracks at edges).
Writes tests/data/raycast_reference.json: vertices, faces, origins, dirs (float32 values),
and per ray the hit triangle (-1 = miss) and t (mm).

Usage: /work/venv/bin/python scripts/reference/raycast_embree.py
"""

import json
from pathlib import Path

import numpy as np
import trimesh
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

OUT = Path(__file__).resolve().parents[2] / "tests" / "data" / "raycast_reference.json"


def main():
    rng = np.random.default_rng(2004)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    sphere.vertices *= (1.0 + 0.05 * rng.standard_normal(len(sphere.vertices)))[:, None]
    cyl = trimesh.creation.cylinder(radius=2.0, height=8.0, sections=24)
    cyl.apply_translation([3.0, -1.0, 0.5])
    box = trimesh.creation.box(extents=[3.0, 2.0, 4.0])
    box.apply_translation([-3.5, 2.0, -1.0])
    mesh = trimesh.util.concatenate([sphere, cyl, box])
    v = mesh.vertices.astype(np.float32)
    f = mesh.faces.astype(np.int64)

    n = 1000
    inside = rng.uniform(-5.5, 5.5, (n, 3))
    d_in = rng.standard_normal((n, 3))
    outside_dir = rng.standard_normal((n, 3))
    outside = 25.0 * outside_dir / np.linalg.norm(outside_dir, axis=1, keepdims=True)
    target = rng.uniform(-9.0, 9.0, (n, 3))
    d_out = target - outside
    o = np.vstack([inside, outside]).astype(np.float32)
    d = np.vstack([d_in, d_out])
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)

    try:
        scene = rtcore_scene.EmbreeScene(robust=True)
    except TypeError:
        scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, v[f])
    r = scene.run(o, d, output=1)
    tri = np.asarray(r["primID"], dtype=np.int64)
    t = np.where(tri >= 0, np.asarray(r["tfar"], dtype=np.float64), -1.0)

    data = {
        "source": "embreex " + getattr(__import__("embreex"), "__version__", "?")
        + ", trimesh " + trimesh.__version__ + ", scripts/reference/raycast_embree.py",
        "vertices": [[float(c) for c in p] for p in v],
        "faces": f.tolist(),
        "origins": [[float(c) for c in p] for p in o],
        "dirs": [[float(c) for c in p] for p in d],
        "tri": tri.tolist(),
        "t": [float(np.float32(x)) for x in t],
    }
    OUT.write_text(json.dumps(data, separators=(",", ":")))
    print(f"{OUT}: {len(f)} triangles, {len(o)} rays, {int((tri >= 0).sum())} hits, "
          f"{OUT.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
