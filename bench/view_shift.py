"""Where two renders of the same views differ by a local shift, and where by something else.

    python3 bench/view_shift.py RENDERED_A RENDERED_B [VIEW ...]

RENDERED_A and RENDERED_B are folders written by `bronchosim render` (views/NNNNNN.png) for the
same views, e.g. a model built from registered poses and one built from the true poses. Each
view is cut into 40 x 40 pixel tiles; for each tile the sub-pixel shift of A (cubic
interpolation, +-4 px in quarter pixels) that best matches B is printed as `dy,dx` when it
lowers the tile's squared difference by more than 1 dB, `~0` when no shift does, and `.` for a
tile under 90 % lit. Coherent shifts over many tiles mean the texture sits in a different place
(a pose error the frames share); `~0` everywhere with a large difference would mean blur or
colour. Also prints the PSNR of A against B and the high-frequency energy of each (a blurred
texture has less).
"""
import sys

import numpy as np
from PIL import Image
from scipy import ndimage

TILE = 40
SHIFTS = np.arange(-4, 4.01, 0.25)
PAD = 6


def grey(path):
    return (np.asarray(Image.open(path).convert("RGB")).astype(float) / 255).mean(2)


def high_frequency(a, lit):
    return np.sqrt(((a - ndimage.gaussian_filter(a, 1.5)) ** 2)[lit].mean())


def tile_shift(a, b, y0, x0):
    tb = b[y0:y0 + TILE, x0:x0 + TILE]
    base = ((a[y0:y0 + TILE, x0:x0 + TILE] - tb) ** 2).mean()
    best = (base, 0.0, 0.0)
    # The tile with a margin (edge pixels repeated at the image border), shifted and cut back.
    padded = np.pad(a, PAD, mode="edge")[y0:y0 + TILE + 2 * PAD, x0:x0 + TILE + 2 * PAD]
    for dy in SHIFTS:
        for dx in SHIFTS:
            s = ndimage.shift(padded, (dy, dx), order=3)[PAD:PAD + TILE, PAD:PAD + TILE]
            err = ((s - tb) ** 2).mean()
            if err < best[0]:
                best = (err, dy, dx)
    gain = 10 * np.log10(base / best[0]) if best[0] > 0 else 0.0
    return best[1], best[2], gain


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    a_dir, b_dir = sys.argv[1], sys.argv[2]
    views = [int(v) for v in sys.argv[3:]] or range(8)
    for v in views:
        a = grey(f"{a_dir}/views/{v:06d}.png")
        b = grey(f"{b_dir}/views/{v:06d}.png")
        lit = b > 0.02
        psnr = -10 * np.log10(((a - b) ** 2)[lit].mean())
        print(f"view {v}: A against B {psnr:.2f} dB, high frequencies A {high_frequency(a, lit):.4f}"
              f" B {high_frequency(b, lit):.4f}")
        for y0 in range(0, a.shape[0] - TILE + 1, TILE):
            row = []
            for x0 in range(0, a.shape[1] - TILE + 1, TILE):
                if lit[y0:y0 + TILE, x0:x0 + TILE].mean() < 0.9:
                    row.append(f"{'.':>9}")
                    continue
                dy, dx, gain = tile_shift(a, b, y0, x0)
                row.append(f"{dy:+.2f},{dx:+.2f}" if gain > 1 else f"{'~0':>9}")
            print("  " + " ".join(row))


if __name__ == "__main__":
    main()
