#!/usr/bin/env python3
"""Checks of evaluate.py's analysis on synthetic views with known answers (no model, no
bronchosim): `python test_evaluate.py` exits non-zero when one fails."""

import numpy as np
from scipy.ndimage import gaussian_filter

import evaluate as ev


def synthetic(seed, field):
    """A textured truth view with depths in all three bands, and a render that is the truth
    times `field(depth, x, y)` (h, w)."""
    rng = np.random.default_rng(seed)
    h = w = 96
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 5.0 + 40.0 * x / (w - 1)  # 5 to 45 mm, left to right
    tex = gaussian_filter(rng.random((h, w, 3)), (1.0, 1.0, 0)) * 0.5 + 0.2
    truth = tex * np.array([0.9, 0.5, 0.4])
    render = truth * field(depth, x, y)[:, :, None]
    return {"name": f"v{seed}", "truth": truth, "render": render, "mask": np.ones((h, w), bool), "depth": depth}


def test_depth_bands_recover_a_known_darkening():
    # The model renders 15-30 mm 20 % too dark and beyond 30 mm 1.5x too bright, relative to
    # the near band; the global gain fit rescales everything, the band ratios keep the shape
    # (up to the per-channel gains differing by the texture's colour, < 0.2 %).
    def field(d, x, y):
        return np.where(d < 15, 1.0, np.where(d < 30, 0.8, 1.5)) * 0.5

    res = ev.evaluate([synthetic(1, field), synthetic(2, field)])
    b = [x["mean"] for x in res["depth_bands"]]
    assert abs(b[1] / b[0] - 0.8) < 2e-3 and abs(b[2] / b[0] - 1.5) < 2e-3, b


def test_local_gain_removes_low_frequency_error_only():
    # A brightness ramp across the view (0.7 to 1.3) is what a 16 px local gain corrects (a
    # Gaussian keeps a linear ramp but for the image border); PSNR must rise far above the
    # global-gain PSNR.
    def smooth(d, x, y):
        return 0.7 + 0.6 * x / 95.0 + 0.0 * y

    m = ev.evaluate([synthetic(3, smooth)])["mean"]
    assert m["psnr_db_local_gain_16px"] > m["psnr_db"] + 10.0, m
    # Pixel noise (high frequency) is not: the local gain gains less than 0.5 dB.
    rng = np.random.default_rng(4)
    noise = rng.normal(1.0, 0.1, (96, 96))
    m = ev.evaluate([synthetic(5, lambda d, x, y: noise)])["mean"]
    assert abs(m["psnr_db_local_gain_16px"] - m["psnr_db"]) < 0.5, m


def test_identical_views_score_the_cap():
    m = ev.evaluate([synthetic(6, lambda d, x, y: np.ones_like(d))])["mean"]
    assert m["psnr_db"] == 100.0 and abs(m["ssim"] - 1.0) < 1e-12, m


if __name__ == "__main__":
    tests = [f for name, f in sorted(globals().items()) if name.startswith("test_")]
    for t in tests:
        t()
        print(f"ok {t.__name__}")
