#!/usr/bin/env python3
"""Render an independent, physically based bronchoscopy case with Mitsuba 3 from the geometry
and albedo of a `bronchosim phantom` case (issue 18, item 5).

    python render_case.py PHANTOM_CASE NEW_CASE [--spp 16] [--view-spp 128] [--seed 1]

Reads PHANTOM_CASE/truth/{albedo_vertices.ply, poses.json, views.json} and camera.json, writes
NEW_CASE in the case format (CASE_FORMAT.md): ct.nii.gz (and mask.png) linked from the input,
camera.json (the input's intrinsics without distortion: Mitsuba's `perspective` is a pinhole),
poses.json (the input case's poses, with whatever pose noise they carry), frames/ rendered at
the true poses, and truth/ with the new views in the layout `bronchosim build --truth` reads.

Light transport: path tracing (`path`, max_depth 4 = direct light plus two indirect bounces),
a `spot` emitter at the camera centre along the optical axis (40 degree beam, 70 degree cutoff,
Mitsuba's linear fall-off in angle between them), the `principled` BSDF (roughness 0.4,
specular 0.5, i.e. F0 = 0.04, not metallic) with the phantom's albedo per vertex.
Sensor: per-frame auto-gain putting the 99th percentile of the brightest channel at 0.9, then
Poisson-Gaussian noise, clipping at 1, 8-bit sRGB. Truth views: the same light at one reference
gain (the lowest of the views' own auto-gains), more paths a pixel, no sensor noise.
"""

import argparse
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np

import case_io as cio

LUMA = np.array([0.2126, 0.7152, 0.0722])


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("case", type=Path, help="a case written by `bronchosim phantom` (with truth/)")
    p.add_argument("out", type=Path, help="the new case folder to write")
    p.add_argument("--spp", type=int, default=16, help="paths per pixel of the video frames")
    p.add_argument("--view-spp", type=int, default=128, help="paths per pixel of the truth views")
    p.add_argument("--max-depth", type=int, default=4, help="Mitsuba max_depth (4: two indirect bounces)")
    p.add_argument("--frames", type=int, default=0, help="render only the first N frames (0: all)")
    p.add_argument("--seed", type=int, default=1, help="seed of the path sampler and the sensor noise")
    p.add_argument("--beam-deg", type=float, default=40.0, help="spot: full-intensity half angle (deg)")
    p.add_argument("--cutoff-deg", type=float, default=70.0, help="spot: zero-intensity half angle (deg)")
    p.add_argument("--roughness", type=float, default=0.4, help="principled roughness")
    p.add_argument("--specular", type=float, default=0.5, help="principled specular (F0 = 0.08 x this)")
    p.add_argument("--gain-percentile", type=float, default=99.0, help="auto-gain: this percentile of the brightest channel...")
    p.add_argument("--gain-target", type=float, default=0.9, help="...is scaled to this linear value")
    p.add_argument("--full-well", type=float, default=4000.0, help="electrons at signal 1 (shot noise)")
    p.add_argument("--read-noise", type=float, default=0.002, help="read noise std (linear full scale)")
    p.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (scalar_rgb needs no LLVM)")
    p.add_argument("--force", action="store_true", help="replace NEW_CASE if it exists")
    p.add_argument("--views-only", action="store_true",
                   help="re-render only the truth views of an existing NEW_CASE (same settings)")
    a = p.parse_args()
    a.intensity = 1000.0  # W/sr; any value: the auto-gain normalises it
    a.albedo_ply = a.case / "truth" / "albedo_vertices.ply"
    return a


def auto_gain(radiance, opts, mask=None):
    """Gain putting the `gain_percentile` of the brightest channel per pixel (over the image
    pixels of `mask`, default all) at `gain_target` (on luminance, the red mucosa would clip
    its red channel in half the frame)."""
    peak = radiance.max(axis=2)
    p = np.percentile(peak if mask is None else peak[mask], opts.gain_percentile)
    return opts.gain_target / p if p > 0 else 1.0


def expose(radiance, gain, opts, rng):
    """Linear sensor values: gain, Poisson-Gaussian noise when `rng` is given, clip to [0, 1]."""
    s = radiance * gain
    if rng is not None:
        s = s + np.sqrt(np.maximum(s, 0.0) / opts.full_well) * rng.standard_normal(s.shape)
        s = s + opts.read_noise * rng.standard_normal(s.shape)
    return np.clip(s, 0.0, 1.0)


def finite(radiance, what, stats):
    """Replace non-finite pixels (a path sample that failed) by the median of their finite
    3x3 neighbours, and count them."""
    bad = ~np.isfinite(radiance).all(axis=2)
    if bad.any():
        stats["nonfinite_pixels"] = stats.get("nonfinite_pixels", 0) + int(bad.sum())
        print(f"note: {what}: {int(bad.sum())} non-finite pixels filled from their neighbours", file=sys.stderr)
        radiance = radiance.copy()
        h, w = bad.shape
        for y, x in zip(*np.nonzero(bad)):
            nb = radiance[max(y - 1, 0) : y + 2, max(x - 1, 0) : x + 2].reshape(-1, 3)
            nb = nb[np.isfinite(nb).all(axis=1)]
            radiance[y, x] = np.median(nb, axis=0) if len(nb) else 0.0
    return radiance


def prepare_output(opts, cam_in):
    """Create NEW_CASE with the CT (and mask) linked, camera.json and poses.json."""
    src = opts.case
    for f in ("truth/poses.json", "truth/views.json", "poses.json"):
        if not (src / f).exists():
            cio.fail(src / f, "missing (the input must be a `bronchosim phantom` case)")
    if not (src / "ct.nii.gz").exists():
        cio.fail(src / "ct.nii.gz", "missing (only NIfTI CTs are linked)")
    if opts.out.exists():
        if not opts.force:
            cio.fail(opts.out, "exists (use --force to replace it)")
        shutil.rmtree(opts.out)
    (opts.out / "frames").mkdir(parents=True)
    (opts.out / "truth" / "views").mkdir(parents=True)
    cio.link_or_copy(src / "ct.nii.gz", opts.out / "ct.nii.gz")
    mask = None
    if (src / "mask.png").exists():
        cio.link_or_copy(src / "mask.png", opts.out / "mask.png")
        mask = cio.read_png_raw(src / "mask.png")
        mask = (mask if mask.ndim == 2 else mask[:, :, 0]) > 127
        if mask.shape != (cam_in["height"], cam_in["width"]):
            cio.fail(src / "mask.png", f"is {mask.shape[1]}x{mask.shape[0]}, the camera {cam_in['width']}x{cam_in['height']}")
    cam = cio.pinhole_camera(cam_in)
    cio.write_camera(opts.out / "camera.json", cam)
    cio.write_camera(opts.out / "truth" / "camera.json", cam)
    for f in ("albedo_vertices.ply", "lumen.ply"):
        cio.link_or_copy(src / "truth" / f, opts.out / "truth" / f)
    return cam, mask


def render_frames(ctx, truth_poses, case_poses, opts, mask, stats):
    """Render the video frames at the true poses; returns the per-frame gain records."""
    sc, scene, params = ctx
    records, entries, times = [], [], []
    n = len(truth_poses) if opts.frames <= 0 else min(opts.frames, len(truth_poses))
    for i in range(n):
        t0 = time.perf_counter()
        rad = finite(sc.render(scene, params, truth_poses[i][1], opts.spp, opts.seed * 100003 + i), f"frame {i}", stats)
        gain = auto_gain(rad, opts, mask)
        img = expose(rad, gain, opts, np.random.default_rng([opts.seed, 1, i]))
        if mask is not None:
            img[~mask] = 0.0
        name = f"frames/{i:06d}.png"
        cio.write_srgb8(opts.out / name, img)
        times.append(time.perf_counter() - t0)
        clipped = float((rad * gain >= 1.0).any(axis=2).mean())
        records.append({"image": name, "gain": gain, "mean_linear": float((img @ LUMA).mean()),
                        "saturated_fraction": clipped})
        entries.append((name, case_poses[i][1]))
        print(f"frame {i + 1}/{n}: {times[-1]:.1f} s, gain {gain:.4g}", flush=True)
    cio.write_poses(opts.out / "poses.json", entries)
    cio.write_poses(opts.out / "truth" / "poses.json", [(name, truth_poses[i][1]) for i, (name, _) in enumerate(entries)])
    stats["seconds_per_frame"] = float(np.mean(times))
    return records


def render_views(ctx, lumen, cam, views, opts, stats):
    """Clean truth views with their pixel-centre buffers, all at one reference gain: the lowest
    of the views' own auto-gains, so that no view clips more than its auto-gain would (at frame
    0's gain, as the phantom does, the views of the default phantom clip 5-80 % of their
    pixels: frame 0 looks down the trachea, the views are nearer the walls). Returns
    (reference gain, the views' own auto-gains)."""
    sc, scene, params = ctx
    vdir = opts.out / "truth" / "views"
    entries, times, radiances = [], [], []
    for k, (_, pose) in enumerate(views):
        t0 = time.perf_counter()
        seed = opts.seed * 100003 + 50000 + k
        radiances.append(finite(sc.render(scene, params, pose, opts.view_spp, seed), f"view {k}", stats))
        times.append(time.perf_counter() - t0)
        print(f"view {k + 1}/{len(views)}: {times[-1]:.1f} s", flush=True)
    own = [auto_gain(r, opts) for r in radiances]
    gain = min(own)
    for k, ((_, pose), rad) in enumerate(zip(views, radiances)):
        img = expose(rad, gain, opts, None)
        hit, dist, alb = sc.pixel_centre_buffers(scene, lumen, cam, pose)
        stem = f"{k:06d}"
        cio.write_srgb8(vdir / f"{stem}.png", img)
        cio.write_linear16(vdir / f"{stem}_linear.png", img)
        cio.write_gray8(vdir / f"{stem}_mask.png", np.where(hit, 255, 0))
        depth = np.where(hit, np.clip(np.round(np.where(hit, dist, 0.0) * 100.0), 1, 65535), 0)
        cio.write_png16(vdir / f"{stem}_depth.png", depth)
        cio.write_linear16(vdir / f"{stem}_albedo.png", alb)
        entries.append((f"views/{stem}.png", pose))
    cio.write_poses(opts.out / "truth" / "views.json", entries)
    stats["seconds_per_view"] = float(np.mean(times))
    return gain, own


FILES = {
    "lumen.ply": "true lumen mesh, world mm (RAS+), normals into the lumen (from the input case)",
    "albedo_vertices.ply": "the same mesh with float red, green, blue: linear albedo per vertex",
    "poses.json": "the true pose of every frame (frames were rendered there); the case's poses.json is the input case's",
    "views.json": "novel view poses (camera_to_world), images relative to truth/",
    "camera.json": "pinhole camera of the frames and views (no distortion)",
    "views/NNNNNN.png": "sRGB 8-bit, no sensor noise, reference_gain (Monte Carlo noise of spp_views paths remains)",
    "views/NNNNNN_linear.png": "linear 16-bit RGB: value = code / 65535",
    "views/NNNNNN_mask.png": "8-bit: 255 where the pixel-centre ray hits the mesh",
    "views/NNNNNN_depth.png": "16-bit: distance camera centre to surface along the pixel-centre ray, code / 100 mm (0 = miss)",
    "views/NNNNNN_albedo.png": "linear 16-bit RGB albedo at the pixel-centre hit (barycentric from the vertices)",
}


def manifest(opts, cam_in, records, lumen, stats, camera_check, view_gains):
    import mitsuba as mi

    return {
        "generator": "bench/mitsuba/render_case.py (Mitsuba 3 path tracing)",
        "input_case": str(opts.case.resolve()),
        "mitsuba": {"version": mi.__version__, "variant": opts.variant, "python": platform.python_version()},
        "seed": opts.seed,
        "frames": len(records),
        "size": [cam_in["width"], cam_in["height"]],
        "input_camera_distortion": {k: cam_in[k] for k in ("k1", "k2", "p1", "p2", "k3")},
        "integrator": {"type": "path", "max_depth": opts.max_depth, "spp_frames": opts.spp, "spp_views": opts.view_spp,
                       "pixel_filter": "box", "sampler": "independent"},
        "light": {"type": "spot", "position": "camera centre", "direction": "optical axis (+z)",
                  "beam_width_deg": opts.beam_deg, "cutoff_angle_deg": opts.cutoff_deg,
                  "falloff": "1 inside the beam, linear in angle to 0 at the cutoff", "intensity_w_per_sr": opts.intensity},
        "bsdf": {"type": "principled", "base_color": "per-vertex albedo (linear RGB)", "roughness": opts.roughness,
                 "specular": opts.specular, "metallic": 0.0},
        "sensor": {"auto_gain": f"gain = {opts.gain_target} / percentile {opts.gain_percentile} of each pixel's brightest linear channel",
                   "noise": "Poisson-Gaussian: s + sqrt(s / full_well) N + read_noise N, then clip to [0, 1]",
                   "full_well_electrons": opts.full_well, "read_noise": opts.read_noise, "encoding": "8-bit sRGB PNG"},
        "reference_gain": view_gains[0],
        "reference_gain_rule": "the lowest of the views' own auto-gains (the views share one gain; frame 0's would clip them)",
        "view_auto_gains": view_gains[1],
        "frame_gains": records,
        "mesh": {"vertices": len(lumen.positions), "triangles": len(lumen.faces), **lumen.info},
        "camera_check_median_relative_depth_error": camera_check,
        "timing": stats,
        "files": FILES,
    }


def main():
    opts = parse_args()
    import scene as sc

    sc.set_variant(opts.variant)
    import mitsuba as mi

    cam_in = cio.read_camera(opts.case / "camera.json")
    truth_poses = cio.read_poses(opts.case / "truth" / "poses.json")
    case_poses = cio.read_poses(opts.case / "poses.json")
    if len(truth_poses) != len(case_poses):
        cio.fail(opts.case / "poses.json", f"{len(case_poses)} frames, truth/poses.json {len(truth_poses)}")
    views = cio.read_poses(opts.case / "truth" / "views.json")
    if opts.views_only:
        old = cio.read_json(opts.out / "truth" / "truth.json")
        cam, records, stats = cio.read_camera(opts.out / "camera.json"), old["frame_gains"], old["timing"]
    else:
        cam, mask = prepare_output(opts, cam_in)
        stats = {}
    verts, faces = cio.read_ply(opts.albedo_ply)
    lumen = sc.lumen_mesh(verts, faces, opts)
    check = sc.check_camera(lumen, cam, opts, views[0][1])
    if not check < 0.01:
        cio.fail(opts.out / "camera.json", f"Mitsuba's sensor disagrees with the ray cast (median depth error {check:.3g})")
    scene = sc.build_scene(lumen.mesh, cam, opts)
    ctx = (sc, scene, mi.traverse(scene))
    t0 = time.perf_counter()
    if not opts.views_only:
        records = render_frames(ctx, truth_poses, case_poses, opts, mask, stats)
        stats["frames_seconds"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    view_gains = render_views(ctx, lumen, cam, views, opts, stats)
    stats["views_seconds"] = time.perf_counter() - t1
    cio.write_json(opts.out / "truth" / "truth.json", manifest(opts, cam_in, records, lumen, stats, check, view_gains))
    print(f"wrote {opts.out}: {len(records)} frames ({stats['seconds_per_frame']:.1f} s each), "
          f"{len(views)} views ({stats['seconds_per_view']:.1f} s each)")


if __name__ == "__main__":
    cio.main_guard(main)
