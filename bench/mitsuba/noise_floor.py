#!/usr/bin/env python3
"""The Monte Carlo noise left in a Mitsuba case's truth views: re-render one view with the
settings recorded in truth.json and another seed, and compare the two renders.

    python noise_floor.py NEW_CASE [--view 0] [--seed 2]

Two independent renders differ by twice the variance each has around the converged image, so
one view's PSNR against the converged image is the PSNR between the two plus 3.01 dB: the
highest score any model can reach on that view (up to 8-bit quantisation).
"""

import argparse
import types
from pathlib import Path

import numpy as np

import case_io as cio


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("case", type=Path, help="a case written by render_case.py")
    p.add_argument("--view", type=int, default=0, help="the view to re-render (index in views.json)")
    p.add_argument("--seed", type=int, default=2, help="the second render's sampler seed")
    a = p.parse_args()
    truth = a.case / "truth"
    man = cio.read_json(truth / "truth.json")
    if "integrator" not in man or "light" not in man:
        cio.fail(truth / "truth.json", "not written by render_case.py")
    import scene as sc

    sc.set_variant(man["mitsuba"]["variant"])
    import mitsuba as mi

    opts = types.SimpleNamespace(
        albedo_ply=truth / "albedo_vertices.ply",
        roughness=man["bsdf"]["roughness"], specular=man["bsdf"]["specular"],
        max_depth=man["integrator"]["max_depth"], spp=man["integrator"]["spp_views"],
        intensity=man["light"]["intensity_w_per_sr"], beam_deg=man["light"]["beam_width_deg"],
        cutoff_deg=man["light"]["cutoff_angle_deg"],
    )
    views = cio.read_poses(truth / "views.json")
    if not 0 <= a.view < len(views):
        cio.fail(truth / "views.json", f"has no view {a.view}")
    name, pose = views[a.view]
    cam = cio.read_camera(truth / "camera.json")
    lumen = sc.lumen_mesh(*cio.read_ply(opts.albedo_ply), opts)
    scene = sc.build_scene(lumen.mesh, cam, opts)
    rad = sc.render(scene, mi.traverse(scene), pose, opts.spp, a.seed * 100003 + 50000 + a.view)
    second = np.clip(rad * man["reference_gain"], 0.0, 1.0)
    stem = (truth / name).with_suffix("")
    first = cio.read_png_raw(Path(f"{stem}_linear.png"))[:, :, :3] / 65535.0
    mask = cio.read_png_raw(Path(f"{stem}_mask.png")) > 127
    ok = np.isfinite(second).all(axis=2) & mask
    mse = ((cio.srgb_encode(first) - cio.srgb_encode(second))[ok] ** 2).mean()
    between = 10.0 * np.log10(1.0 / mse)
    print(f"{name}: {opts.spp} paths a pixel, PSNR between two seeds {between:.2f} dB, "
          f"one render vs converged ~{between + 10 * np.log10(2):.2f} dB")


if __name__ == "__main__":
    cio.main_guard(main)
