"""Reference geometry and values for the NIfTI reader, computed with nibabel.

Writes small NIfTI files of every supported datatype and affine source into tests/data/nifti/,
and tests/data/nifti_reference.json with, for chosen voxels, the world coordinates nibabel
computes (apply_affine with img.affine, which follows sform > qform > pixdim like bronchosim)
and the scaled voxel values (get_fdata). Run: /work/venv/bin/python scripts/reference/nifti_nibabel.py
"""
import json
import os
import numpy as np
import nibabel as nib

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "..", "tests", "data")
NDIR = os.path.join(OUT, "nifti")
os.makedirs(NDIR, exist_ok=True)
rng = np.random.default_rng(7)


def rot(axis, deg):
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    m = np.eye(3)
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def affine(R, spacing, origin):
    A = np.eye(4)
    A[:3, :3] = R @ np.diag(spacing)
    A[:3, 3] = origin
    return A


shape = (7, 6, 5)
flipped = affine(np.diag([-1.0, -1.0, 1.0]), [0.7, 0.7, 1.25], [120.0, 95.0, -210.0])
oblique = affine(rot(2, 17) @ rot(0, -9) @ np.diag([-1.0, 1.0, 1.0]), [0.6, 0.8, 1.5], [-30.0, 44.0, 12.5])
cases = []


def add(name, data, aff, sform=True, qform=True, slope=None, inter=None, endian="<", pixdim_only=False):
    img = nib.Nifti1Image(data, None if pixdim_only else aff)
    hdr = img.header
    if pixdim_only:
        hdr.set_zooms((0.9, 1.1, 2.0))
        hdr.set_sform(None, code=0)
        hdr.set_qform(None, code=0)
    else:
        if not sform:
            img.set_qform(aff, code=1)
            img.set_sform(None, code=0)
        if not qform:
            img.set_qform(None, code=0)
    if slope is not None:
        hdr.set_slope_inter(slope, inter)
    if endian == ">":
        hdr = hdr.as_byteswapped(">")
        img = nib.Nifti1Image(data.astype(data.dtype.newbyteorder(">")), None, header=hdr)
    path = os.path.join(NDIR, name)
    nib.save(img, path)
    back = nib.load(path)
    assert (back.header["sform_code"] > 0) == (sform and not pixdim_only), name
    A = back.affine
    if pixdim_only:
        # NIfTI-1 "method 1" (what bronchosim and ITK use): plain pixdim scaling, origin 0.
        # nibabel's own fallback (Analyze's centred, x-flipped base affine) differs on purpose.
        assert back.header["sform_code"] == 0 and back.header["qform_code"] == 0
        A = np.diag([0.9, 1.1, 2.0, 1.0])
    vals = back.get_fdata(dtype=np.float64)
    picks = [(0, 0, 0), (6, 5, 4), (3, 2, 1), (1, 4, 3), (5, 0, 2)]
    cases.append({
        "file": name,
        "dims": list(back.shape),
        "affine": A.tolist(),
        "voxels": [
            {"ijk": list(p), "world": nib.affines.apply_affine(A, p).tolist(), "value": float(vals[p])}
            for p in picks
        ],
        "mean": float(vals.mean()),
    })


ct = rng.integers(-1024, 1500, size=shape).astype(np.int16)
add("int16_flipped_sform.nii.gz", ct, flipped)
add("int16_scaled_oblique.nii.gz", (ct // 2).astype(np.int16), oblique, slope=2.0, inter=-24.5)
add("uint8_qform_only.nii", rng.integers(0, 255, size=shape).astype(np.uint8), oblique, sform=False)
add("uint16_bigendian.nii.gz", rng.integers(0, 4000, size=shape).astype(np.uint16), flipped, endian=">")
add("int32.nii.gz", rng.integers(-100000, 100000, size=shape).astype(np.int32), oblique)
add("float32.nii.gz", rng.normal(-500, 300, size=shape).astype(np.float32), flipped)
add("float64.nii", rng.normal(-500, 300, size=shape).astype(np.float64), oblique)
add("int8_mask.nii.gz", (rng.random(shape) > 0.7).astype(np.int8), flipped)
add("pixdim_only.nii.gz", ct, flipped, pixdim_only=True)

with open(os.path.join(OUT, "nifti_reference.json"), "w") as f:
    json.dump({"generator": f"nibabel {nib.__version__}", "cases": cases}, f, indent=1)
print(f"wrote {len(cases)} cases")
