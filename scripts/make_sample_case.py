"""Write tests/data/case_small: a tiny but complete case (CASE_FORMAT.md) for `inspect` and the
CLI tests, until the phantom command exists. CT: an int16 NIfTI of a body with an air tube
(trachea-like) on a flipped (LPS-like) sform; camera.json with barrel distortion; 6 PNG
frames (8-bit sRGB, a vignetted disc like a bronchoscope image); poses along the tube axis.
Run: /work/venv/bin/python scripts/make_sample_case.py
"""
import json
import os
import zlib
import struct

import nibabel as nib
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "tests", "data", "case_small")
os.makedirs(os.path.join(OUT, "frames"), exist_ok=True)
rng = np.random.default_rng(3)

# CT: 48 x 48 x 40 voxels of 1.0 x 1.0 x 1.5 mm, axes flipped in x and y.
nx, ny, nz = 48, 48, 40
aff = np.array([[-1.0, 0, 0, 24.0], [0, -1.0, 0, 24.0], [0, 0, 1.5, -30.0], [0, 0, 0, 1]])
i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
wx, wy = -i + 24.0, -j + 24.0  # world x, y of each column
r_body = np.hypot(wx / 22.0, wy / 18.0)
r_tube = np.hypot(wx, wy - 2.0)
slab = np.where(r_body < 1.0, 40.0, -1000.0)
slab = np.where((r_body < 0.85) & (np.abs(wx) > 8), -850.0, slab)
slab = np.where(r_tube < 6.0, -1000.0, slab)
ct = np.repeat(slab[:, :, None], nz, axis=2) + rng.normal(0, 15, (nx, ny, nz))
nib.save(nib.Nifti1Image(np.clip(ct, -1024, 3000).astype(np.int16), aff), os.path.join(OUT, "ct.nii.gz"))

camera = {"width": 64, "height": 48, "fx": 40.0, "fy": 40.0, "cx": 31.5, "cy": 23.5,
          "k1": -0.3, "k2": 0.08, "p1": 0.001, "p2": -0.001, "k3": 0.0}
json.dump(camera, open(os.path.join(OUT, "camera.json"), "w"), indent=1)


def write_png(path, rgb):
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    open(path, "wb").write(png)


frames = []
yy, xx = np.mgrid[0:48, 0:64]
for f in range(6):
    rr = np.hypot(xx - 31.5, yy - 23.5) / 30.0
    base = np.clip(1.0 - rr**2, 0, 1)[:, :, None] * np.array([0.95, 0.55, 0.45])
    img = (255 * np.clip(base * (0.8 + 0.04 * f) + rng.normal(0, 0.01, base.shape), 0, 1)).astype(np.uint8)
    name = f"frames/{f:06d}.png"
    write_png(os.path.join(OUT, name), img)
    # Looking down the tube (world -z, i.e. inferior): camera z = world -z, x = world +x, y = world +y.
    z = 20.0 - 4.0 * f
    m = [1, 0, 0, 0.3 * f, 0, -1, 0, 2.0, 0, 0, -1, z, 0, 0, 0, 1]
    frames.append({"image": name, "camera_to_world": m})
json.dump({"frames": frames}, open(os.path.join(OUT, "poses.json"), "w"), indent=1)
print("wrote", OUT)
