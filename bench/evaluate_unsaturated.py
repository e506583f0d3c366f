"""New views scored as `bronchosim evaluate` scores them, and again without the pixels where
the truth is saturated.

    python3 bench/evaluate_unsaturated.py RENDERED TRUTH

RENDERED is a folder written by `bronchosim render` for TRUTH/views.json; TRUTH a phantom's
truth folder (views/NNNNNN.png, sRGB 8-bit, and NNNNNN_mask.png). As `evaluate` does: the
images are linearised, one gain per channel is fitted over every view's covered pixels that
neither image saturates, and the PSNR of each view is taken in sRGB on the pixels the truth's
mask and the render cover. The second line scores only the pixels where no channel of the
truth is saturated: there the truth says what the wall looks like; where it is saturated it
says only that the wall is brighter than the exposure holds, and the score follows the
render's exposure instead of the model.
"""
import json
import sys

import numpy as np
from PIL import Image


def linear(code):
    a = code / 255.0
    return np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)


def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def read(path):
    return np.asarray(Image.open(path).convert("RGB")).astype(float)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    rendered, truth = sys.argv[1], sys.argv[2]
    names = [f["image"] for f in json.load(open(f"{truth}/views.json"))["frames"]]
    renders, truths, masks = [], [], []
    for name in names:
        t = read(f"{truth}/{name}")
        r = read(f"{rendered}/{name}")
        mask = np.asarray(Image.open(f"{truth}/{name[:-4]}_mask.png").convert("L")) > 127
        masks.append(mask & (r.sum(2) > 0))
        renders.append(linear(r))
        truths.append(linear(t))
    num, den = np.zeros(3), np.zeros(3)
    for r, t, m in zip(renders, truths, masks):
        ok = (r < 1.0) & (t < 1.0) & m[..., None]
        num += (r * t * ok).sum((0, 1))
        den += (r * r * ok).sum((0, 1))
    gain = num / den
    for label, unsaturated_only in [("every pixel", False), ("truth unsaturated", True)]:
        scores, shares = [], []
        for r, t, m in zip(renders, truths, masks):
            keep = m & (t.max(2) < 1.0) if unsaturated_only else m
            d = srgb(r * gain) - srgb(t)
            scores.append(10 * np.log10(1 / (d[keep] ** 2).mean()))
            shares.append(keep.sum() / max(m.sum(), 1))
        print(f"{label:18s} mean {np.mean(scores):.2f} dB  per view "
              + " ".join(f"{p:.2f}" for p in scores)
              + (f"  (pixels kept {min(shares):.0%}-{max(shares):.0%})" if unsaturated_only else ""))


if __name__ == "__main__":
    main()
