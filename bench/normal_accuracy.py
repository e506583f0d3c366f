#!/usr/bin/env python3
"""Issue 18 item 2: are normals from the CT's gradient closer to the true surface normals than
the lumen mesh's own? Measured on a phantom case, where the true surface is known.

    bronchosim phantom --out CASE
    bronchosim segment CASE --out SEG
    python3 bench/normal_accuracy.py CASE/ct.nii.gz SEG/lumen.ply CASE/truth/lumen.ply

At points spread over the CT mesh's faces (4 per face) it compares with the normal of the
nearest vertex of the true mesh: the mesh's interpolated vertex normals (what bronchosim shades
with), its face normals, and the CT's gradient after a Gaussian of 0.5 / 0.7 / 1.0 mm (trilinear
at the point, the direction a normal map baked from the CT at full resolution would hold).
Angles are unsigned (the gradient points into the wall, the mesh's normals into the lumen).
Needs numpy, scipy, nibabel, plyfile, trimesh.
"""
import sys
import numpy as np
import nibabel as nib
import plyfile
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree


def angle_deg(a, b):
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.abs((a * b).sum(1)), 0, 1)))


def main(ct_path, mesh_path, truth_path):
    ct = nib.load(ct_path)
    vol = ct.get_fdata().astype(np.float32)
    affine = ct.affine
    spacing = np.sqrt((affine[:3, :3] ** 2).sum(0))
    direction = affine[:3, :3] / spacing
    mesh = trimesh.load(mesh_path, process=False)
    tp = plyfile.PlyData.read(truth_path)["vertex"]
    true_pts = np.stack([tp["x"], tp["y"], tp["z"]], 1)
    true_nrm = np.stack([tp["nx"], tp["ny"], tp["nz"]], 1)

    rng = np.random.default_rng(0)
    faces = mesh.faces
    per_face = 4
    fi = np.repeat(np.arange(len(faces)), per_face)
    bary = rng.dirichlet([1, 1, 1], len(fi))
    pts = (mesh.vertices[faces[fi]] * bary[:, :, None]).sum(1)
    interp = (mesh.vertex_normals[faces[fi]] * bary[:, :, None]).sum(1)
    dist, nearest = cKDTree(true_pts).query(pts)
    truth = true_nrm[nearest]
    print(f"{len(pts)} points on {len(faces)} faces; mean distance to the nearest true vertex "
          f"{dist.mean():.3f} mm\n")
    print("| normals | mean angle to truth (deg) | median |\n|---|---|---|")
    for name, n in [("mesh, interpolated vertex normals", interp),
                    ("mesh, face normals", mesh.face_normals[fi])]:
        e = angle_deg(n, truth)
        print(f"| {name} | {e.mean():.2f} | {np.median(e):.2f} |")
    inv = np.linalg.inv(affine)
    vox = inv[:3, :3] @ pts.T + inv[:3, 3:4]
    for sigma_mm in [0.5, 0.7, 1.0]:
        grad = []
        for k in range(3):
            order = [int(i == k) for i in range(3)]
            g = ndimage.gaussian_filter(vol, sigma=sigma_mm / spacing, order=order) / spacing[k]
            grad.append(ndimage.map_coordinates(g, vox, order=1))
        world = (direction @ np.stack(grad, 0)).T
        e = angle_deg(world, truth)
        print(f"| CT gradient, Gaussian {sigma_mm} mm | {e.mean():.2f} | {np.median(e):.2f} |")


if __name__ == "__main__":
    main(*sys.argv[1:4])
