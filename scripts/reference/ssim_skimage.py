"""Reference SSIM and PSNR values from scikit-image for tests/render.rs.

Writes tests/data/ssim_reference.json: a small sRGB-encoded image pair (24x20 RGB, values in
[0, 1], quantised to 1/255 so the JSON holds them exactly) and
skimage.metrics.structural_similarity(gaussian_weights=True, sigma=1.5,
use_sample_covariance=False, data_range=1, channel_axis=2), plus
peak_signal_noise_ratio(data_range=1). Run: /work/venv/bin/python scripts/reference/ssim_skimage.py
"""
import json
import pathlib

import numpy as np
import skimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

rng = np.random.default_rng(7)
h, w = 20, 24
yy, xx = np.mgrid[0:h, 0:w]
base = 0.5 + 0.3 * np.sin(xx / 3.0)[..., None] * np.cos(yy / 4.0)[..., None] * np.array([1.0, 0.7, 0.4])
a = np.clip(base + 0.05 * rng.standard_normal((h, w, 3)), 0, 1)
b = np.clip(0.9 * a + 0.04 + 0.06 * rng.standard_normal((h, w, 3)), 0, 1)
a = np.round(a * 255) / 255
b = np.round(b * 255) / 255

ssim = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                             data_range=1.0, channel_axis=2)
psnr = peak_signal_noise_ratio(a, b, data_range=1.0)
out = {
    "generator": f"scripts/reference/ssim_skimage.py, scikit-image {skimage.__version__}",
    "width": w,
    "height": h,
    "a_srgb_codes": (a * 255).round().astype(int).ravel().tolist(),
    "b_srgb_codes": (b * 255).round().astype(int).ravel().tolist(),
    "ssim": float(ssim),
    "psnr_db": float(psnr),
}
p = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "ssim_reference.json"
p.write_text(json.dumps(out) + "\n")
print(p, ssim, psnr)
