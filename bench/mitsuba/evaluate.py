#!/usr/bin/env python3
"""Score a bronchosim model's new views against a case's truth views, with the split of issue 18:

    python evaluate.py MODEL CASE [--bronchosim PATH] [--rendered DIR] [--json OUT]

MODEL is a `bronchosim build` folder, CASE a case with truth/ (a `bronchosim phantom` case or
one written by render_case.py). The new views are rendered with `bronchosim render` (or read
from --rendered). Reported, per view and as means:
- PSNR / SSIM after one least-squares gain per channel over all views (linear light, covered
  pixels that neither image saturates; `bronchosim build --truth` fits unclipped renders),
  on the sRGB-encoded images;
- on the pixels that neither image saturates (a clipped channel hides any gain): PSNR / SSIM
  with the global gain, and after a local brightness gain at 16 and 8 px: the render times the
  Gaussian-smoothed (sigma = the scale, normalised convolution over unsaturated pixels) ratio of
  the truth's and the render's luminance, G*(m Y_truth) / G*(m Y_render). What this lifts is
  low-frequency brightness error (light model); what remains is texture and fine geometry;
- per depth band (distance along the pixel-centre ray from truth/views/*_depth.png: 0-15, 15-30,
  >30 mm) the ratio render / truth of the summed luminance (after the global gain);
  the local gain and the bands use only pixels that neither image saturates;
- the held-out cross-validation of MODEL/model.json and the build's own scores
  (MODEL/evaluation.json) when present.
SSIM: scikit-image's structural_similarity (Gaussian window sigma 1.5, population covariances,
data range 1) with pixels outside the covered mask set to the truth in both images, averaged
over covered pixels at least 5 px from the border; bronchosim's masked SSIM uses normalised
convolution instead, so the two agree only where the mask is (nearly) full.
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

import case_io as cio

LUMA = np.array([0.2126, 0.7152, 0.0722])
BANDS_MM = [(0.0, 15.0), (15.0, 30.0), (30.0, np.inf)]
SCALES_PX = [16.0, 8.0]
MIN_BAND_PIXELS = 200
SATURATED = 0.99  # linear; 8-bit code 254.5 decodes to 0.996


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("model", type=Path, help="a `bronchosim build` model folder")
    p.add_argument("case", type=Path, help="the case with truth/ (views.json, camera.json, views/)")
    p.add_argument("--bronchosim", default="bronchosim", help="the bronchosim binary")
    p.add_argument("--rendered", type=Path, help="already rendered new views (skip `bronchosim render`)")
    p.add_argument("--json", type=Path, help="also write the results here")
    return p.parse_args()


def render_views(opts, out_dir):
    truth = opts.case / "truth"
    cmd = [opts.bronchosim, "render", str(opts.model), "--views", str(truth / "views.json"),
           "--camera", str(truth / "camera.json"), "--out", str(out_dir), "--quiet", "--force"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        cio.fail(opts.model, f"`{' '.join(cmd)}` failed: {r.stderr.strip()}")


def read_mask(path, shape, default):
    if not path.exists():
        return default
    m = cio.read_png_raw(path)
    m = m if m.ndim == 2 else m[:, :, 0]
    if m.shape != shape:
        cio.fail(path, f"mask is {m.shape[1]}x{m.shape[0]}, its image {shape[1]}x{shape[0]}")
    return m > 127


def load_views(case, rendered_dir):
    """Per view: truth linear RGB, render linear RGB, common mask, depth (mm, nan = unknown)."""
    truth = case / "truth"
    views = cio.read_poses(truth / "views.json")
    out = []
    for name, _ in views:
        tp = truth / name
        stem = tp.with_suffix("")
        lin = Path(f"{stem}_linear.png")
        t = cio.read_png_raw(lin)[:, :, :3] / 65535.0 if lin.exists() else cio.read_srgb8_linear(tp)
        shape = t.shape[:2]
        tm = read_mask(Path(f"{stem}_mask.png"), shape, np.ones(shape, bool))
        rp = rendered_dir / name
        r = cio.read_srgb8_linear(rp)
        if r.shape != t.shape:
            cio.fail(rp, f"is {r.shape[1]}x{r.shape[0]}, the truth view {t.shape[1]}x{t.shape[0]}")
        rm = read_mask(Path(f"{rp.with_suffix('')}_mask.png"), shape, (r > 0).any(axis=2))
        dp = Path(f"{stem}_depth.png")
        depth = np.full(shape, np.nan)
        if dp.exists():
            d = cio.read_png_raw(dp).astype(np.float64)
            depth = np.where(d > 0, d / 100.0, np.nan)
        out.append({"name": name, "truth": t, "render": r, "mask": tm & rm, "depth": depth})
    return out


def fit_gains(views):
    """One least-squares gain per channel over the covered pixels of all views (linear), leaving
    out pixels saturated in either image: `bronchosim render` writes 8-bit images clipped at the
    model's reference gain, so a clipped pixel says nothing about the gain (with them the fit
    is biased dark; on the phantom, 29.3 instead of 33.3 dB)."""
    num, den = np.zeros(3), np.zeros(3)
    for v in views:
        m = unsaturated(v["render"], v["truth"], v["mask"])
        r, t = v["render"][m], v["truth"][m]
        num += (r * t).sum(axis=0)
        den += (r * r).sum(axis=0)
    return np.where(den > 0, num / np.maximum(den, 1e-30), 1.0)


def psnr(a, b, mask):
    mse = ((a[mask] - b[mask]) ** 2).mean()
    return float(10.0 * np.log10(1.0 / mse)) if mse > 0 else 100.0


def ssim(a, b, mask):
    a = np.where(mask[:, :, None], a, b)
    _, smap = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                    data_range=1.0, channel_axis=2, full=True)
    m = mask.copy()
    m[:5, :], m[-5:, :], m[:, :5], m[:, -5:] = False, False, False, False
    return float(smap.mean(axis=2)[m].mean())


def scores(render, truth, mask):
    a, b = cio.srgb_encode(render), cio.srgb_encode(truth)
    return psnr(a, b, mask), ssim(a, b, mask)


def unsaturated(raw_render, truth, mask):
    """Covered pixels that neither image saturates (their ratio says something). The render is
    judged before the gain: `bronchosim render` clips at the model's own reference gain."""
    return mask & (raw_render.max(axis=2) < SATURATED) & (truth.max(axis=2) < SATURATED)


def local_gain(render, truth, ok, sigma):
    """The render times the smoothed luminance ratio truth / render at scale `sigma` (px),
    estimated from the pixels `ok` (1 where there are none nearby)."""
    m = ok.astype(np.float64)
    yt = gaussian_filter(m * (truth @ LUMA), sigma, mode="reflect")
    yr = gaussian_filter(m * (render @ LUMA), sigma, mode="reflect")
    ratio = np.where(yr > 1e-9, yt / np.maximum(yr, 1e-9), 1.0)
    return render * ratio[:, :, None]


def band_ratios(render, truth, ok, depth):
    """Per depth band: summed luminance render / truth over the pixels `ok` (None with too few)."""
    out = []
    for lo, hi in BANDS_MM:
        m = ok & (depth >= lo) & (depth < hi)
        st = (truth[m] @ LUMA).sum()
        out.append(float((render[m] @ LUMA).sum() / st) if m.sum() >= MIN_BAND_PIXELS and st > 0 else None)
    return out


def evaluate(views):
    gain = fit_gains(views)
    rows = []
    for v in views:
        # Clipped like a displayed image: the local gain and the bands see what PSNR sees.
        r, t, m = np.minimum(v["render"] * gain, 1.0), v["truth"], v["mask"]
        u = unsaturated(v["render"], t, m)
        row = {"view": v["name"], "pixels": int(m.sum()), "unsaturated_pixels": int(u.sum()),
               "render_saturated_pixels": int((m & (v["render"].max(axis=2) >= SATURATED)).sum())}
        row["psnr_db"], row["ssim"] = scores(r, t, m)
        # The split on unsaturated pixels only: where a channel clips, neither gain is observable.
        row["psnr_db_unsaturated"], row["ssim_unsaturated"] = scores(r, t, u)
        for s in SCALES_PX:
            c = np.minimum(local_gain(r, t, u, s), 1.0)
            row[f"psnr_db_local_gain_{s:g}px"], row[f"ssim_local_gain_{s:g}px"] = scores(c, t, u)
        row["depth_band_ratio"] = band_ratios(r, t, u, v["depth"])
        rows.append(row)
    pooled = []
    for k in range(len(BANDS_MM)):
        vals = [row["depth_band_ratio"][k] for row in rows if row["depth_band_ratio"][k] is not None]
        pooled.append({"views": len(vals), "mean": float(np.mean(vals)) if vals else None,
                       "min": float(np.min(vals)) if vals else None, "max": float(np.max(vals)) if vals else None})
    keys = [k for k in rows[0] if k.startswith(("psnr", "ssim"))]
    means = {k: float(np.mean([row[k] for row in rows])) for k in keys}
    return {"gain": gain.tolist(), "views": rows, "mean": means, "depth_bands": pooled}


def model_records(model):
    """The build's cross-validation and its own new-view scores, when the model has them."""
    out = {}
    mj = cio.read_json(model / "model.json")
    out["shading_model"] = mj.get("shading_model")
    cv = mj.get("cross_validation")
    if cv:
        out["cross_validation"] = {"every": cv.get("every"), "held_out": len(cv.get("held_out", [])),
                                   "models": [{k: m.get(k) for k in ("model", "mean_psnr_db", "mean_ssim")}
                                              for m in cv.get("models", [])]}
    ev = model / "evaluation.json"
    if ev.exists():
        out["build_evaluation"] = [{k: m.get(k) for k in ("method", "mean_psnr_db", "mean_ssim")}
                                   for m in cio.read_json(ev)]
    return out


def band_label(lo, hi):
    return f"{lo:g}-{hi:g} mm" if np.isfinite(hi) else f">{lo:g} mm"


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def print_report(res):
    print(f"global gain per channel: {', '.join(f'{g:.4f}' for g in res['gain'])}")
    head = ["view", "PSNR", "SSIM", "unsat", "PSNR unsat", "PSNR@16", "PSNR@8"] + [band_label(*b) for b in BANDS_MM]
    print("  ".join(f"{h:>12}" for h in head))
    for row in res["views"]:
        cells = [row["view"][-12:], fmt(row["psnr_db"], ".2f"), fmt(row["ssim"], ".4f"),
                 fmt(row["unsaturated_pixels"] / max(row["pixels"], 1), ".3f"), fmt(row["psnr_db_unsaturated"], ".2f"),
                 fmt(row["psnr_db_local_gain_16px"], ".2f"), fmt(row["psnr_db_local_gain_8px"], ".2f")]
        cells += [fmt(x, ".3f") for x in row["depth_band_ratio"]]
        print("  ".join(f"{c:>12}" for c in cells))
    clipped = sum(r["render_saturated_pixels"] for r in res["views"]) / max(sum(r["pixels"] for r in res["views"]), 1)
    if clipped > 0.01:
        print(f"note: the rendered PNGs clip {100 * clipped:.1f} % of the covered pixels at the model's reference "
              "gain, which the PSNR / SSIM of all pixels count; `bronchosim build --truth` and "
              "`bronchosim evaluate --baselines` score unclipped renders")
    m = res["mean"]
    print(f"mean: PSNR {m['psnr_db']:.2f} dB, SSIM {m['ssim']:.4f}; unsaturated pixels: "
          f"{m['psnr_db_unsaturated']:.2f} dB / {m['ssim_unsaturated']:.4f}, local gain 16 px: "
          f"{m['psnr_db_local_gain_16px']:.2f} dB / {m['ssim_local_gain_16px']:.4f}; 8 px: "
          f"{m['psnr_db_local_gain_8px']:.2f} dB / {m['ssim_local_gain_8px']:.4f}")
    for (lo, hi), b in zip(BANDS_MM, res["depth_bands"]):
        print(f"depth {band_label(lo, hi)}: render/truth luminance mean {fmt(b['mean'], '.3f')} "
              f"(min {fmt(b['min'], '.3f')}, max {fmt(b['max'], '.3f')}, {b['views']} views)")
    for m in res.get("cross_validation", {}).get("models", []):
        print(f"cross-validation ({res['cross_validation']['held_out']} held-out frames) {m['model']}: "
              f"PSNR {fmt(m['mean_psnr_db'], '.2f')} dB, SSIM {fmt(m['mean_ssim'], '.4f')}")
    for m in res.get("build_evaluation", []):
        print(f"build --truth {m['method']}: PSNR {fmt(m['mean_psnr_db'], '.2f')} dB, SSIM {fmt(m['mean_ssim'], '.4f')}")


def main():
    opts = parse_args()
    for p in (opts.model / "model.json", opts.case / "truth" / "views.json"):
        if not p.exists():
            cio.fail(p, "missing")
    with tempfile.TemporaryDirectory() as tmp:
        rendered = opts.rendered
        if rendered is None:
            rendered = Path(tmp) / "views"
            render_views(opts, rendered)
        res = evaluate(load_views(opts.case, rendered))
    res.update(model_records(opts.model))
    res["model"], res["case"] = str(opts.model), str(opts.case)
    print_report(res)
    if opts.json:
        cio.write_json(opts.json, res)


if __name__ == "__main__":
    cio.main_guard(main)
