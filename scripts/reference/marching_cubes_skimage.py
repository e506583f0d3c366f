"""Reference for tests/marching_cubes.rs: skimage's classic marching cubes on a small volume.

Writes tests/data/mc_reference.json with the volume (x fastest, values exact multiples of 1/64 so
the decimal text is the exact float32), the level, the spacing, and skimage's
marching_cubes(method='lorensen') vertices (converted to x, y, z voxel indices) and faces.
Run: /work/venv/bin/python scripts/reference/marching_cubes_skimage.py
"""
import json
import pathlib

import numpy as np
import skimage
from skimage.measure import marching_cubes

NX, NY, NZ = 24, 20, 18
SPACING_XYZ = (0.7, 0.9, 1.6)  # mm, anisotropic
LEVEL = -500.0

rng = np.random.default_rng(20240521)
z, y, x = np.meshgrid(np.arange(NZ), np.arange(NY), np.arange(NX), indexing="ij")
# Physical coordinates (mm) so the shapes are round in world space, not in voxels.
px, py, pz = x * SPACING_XYZ[0], y * SPACING_XYZ[1], z * SPACING_XYZ[2]
air = np.zeros((NZ, NY, NX))
# A blob, and a tilted tube through the volume (it leaves through the grid's faces: open there).
air = np.maximum(air, np.exp(-((px - 6) ** 2 + (py - 7) ** 2 + (pz - 9) ** 2) / (2 * 2.5**2)))
d = np.array([0.6, 0.3, 0.74])
d /= np.linalg.norm(d)
rel = np.stack([px - 9, py - 9, pz - 14], -1)
along = rel @ d
perp = np.linalg.norm(rel - along[..., None] * d, axis=-1)
air = np.maximum(air, np.exp(-(perp**2) / (2 * 1.8**2)))
hu = 40.0 - 1040.0 * air + rng.normal(0, 60, air.shape)
vol = (np.round(hu * 64) / 64).astype(np.float32)  # exact in decimal and float32

verts, faces, _, _ = marching_cubes(vol, LEVEL, method="lorensen")
# skimage returns (axis0, axis1, axis2) = (z, y, x) voxel indices: reorder to x, y, z.
verts_xyz = verts[:, ::-1]

out = {
    "skimage_version": skimage.__version__,
    "method": "lorensen",
    "dims_xyz": [NX, NY, NZ],
    "spacing_xyz": list(SPACING_XYZ),
    "level": LEVEL,
    "volume_x_fastest": [float(v) for v in vol.ravel()],  # C order of (z, y, x) = x fastest
    "verts_xyz_voxel": np.round(verts_xyz, 6).tolist(),
    "faces": faces.tolist(),
}
path = pathlib.Path(__file__).resolve().parents[2] / "tests/data/mc_reference.json"
path.write_text(json.dumps(out, separators=(",", ":")))
print(f"wrote {path}: {len(verts)} vertices, {len(faces)} faces, {path.stat().st_size} bytes")
