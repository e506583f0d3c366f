"""Reference for region growing: SimpleITK ConnectedThreshold on a small random volume.

Writes tests/data/region_grow_reference.json: the int16 volume (x fastest), the seed, the
threshold and SimpleITK's mask as run lengths (alternating 0-runs and 1-runs, x fastest).
ConnectedThreshold's default connectivity is FaceConnectivity (6-connected); it is set
explicitly here and checked against the full-connectivity result, which must differ.
"""
import json
import pathlib

import numpy as np
import SimpleITK as sitk

rng = np.random.default_rng(2024)
nx, ny, nz = 40, 36, 30
# Smooth random field so the region has tunnels, pockets and diagonal-only contacts.
field = rng.normal(size=(nz, ny, nx))
img = sitk.GetImageFromArray(field)
img = sitk.SmoothingRecursiveGaussian(img, 1.2)
arr = sitk.GetArrayFromImage(img)
arr = (arr / arr.std() * 300).round().astype(np.int16)
seed = (20, 18, 15)
# Make sure the seed passes.
arr[seed[2], seed[1], seed[0]] = -400
upper = -100
lower = -32768
img16 = sitk.GetImageFromArray(arr)
f = sitk.ConnectedThresholdImageFilter()
f.SetLower(lower)
f.SetUpper(upper)
f.SetSeedList([seed])
f.SetReplaceValue(1)
assert f.GetConnectivity() == f.FaceConnectivity, "default connectivity is not face (6)"
mask = sitk.GetArrayFromImage(f.Execute(img16)).astype(np.uint8)
f.SetConnectivity(f.FullConnectivity)
full = sitk.GetArrayFromImage(f.Execute(img16))
assert (full != mask).any(), "6- and 26-connectivity agree: the reference would not pin connectivity"
flat = mask.reshape(-1)  # (z, y, x) C-order == x fastest
runs = []
cur, n = 0, 0
for v in flat:
    if v == cur:
        n += 1
    else:
        runs.append(n)
        cur, n = v, 1
runs.append(n)
out = {
    "dims": [nx, ny, nz],
    "seed": list(seed),
    "lower": lower,
    "upper": upper,
    "values": arr.reshape(-1).tolist(),
    "mask_runs": runs,
    "mask_voxels": int(flat.sum()),
    "mask_voxels_26": int(full.sum()),
    "simpleitk": sitk.Version.VersionString(),
}
p = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "region_grow_reference.json"
p.write_text(json.dumps(out, separators=(",", ":")))
print(p, "voxels", out["mask_voxels"], "(26-connected:", out["mask_voxels_26"], ")")
