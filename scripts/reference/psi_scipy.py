"""Reference fit of the paper's Psi with scipy.optimize.least_squares.

Draws 2500 samples (gamma, z, R, G, B) from a shading that is NOT Psi (Lambert-like rho with a
specular bump, 1/z^2-like falloff, a non-separable cone term, noise), over a skewed (gamma, z)
distribution, with density weights from a 2-D histogram computed here (numpy, independently
of bronchosim). All stored numbers are rounded to float32 first, so bronchosim (which keeps
samples and weights as f32) solves exactly the same problem. For each channel, minimises the
residuals sqrt(w_i) (Psi(gamma_i, z_i) - P_i) with method='lm' from several starts and keeps
the best; cost = sum w (Psi - P)^2 (= 2 x scipy's cost).
Writes tests/data/psi_scipy_reference.json. Run: /work/venv/bin/python scripts/reference/psi_scipy.py
"""
import json
import os
import numpy as np
from scipy.optimize import least_squares

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "..", "tests", "data", "psi_scipy_reference.json")
rng = np.random.default_rng(2004)
N = 2500
Z_MIN, Z_MAX = 6.0, 40.0

f32 = lambda a: np.asarray(a, dtype=np.float32).astype(np.float64)

# Skewed domain: mostly far and grazing (gamma ~ R / z), a thin uniform background.
bg = rng.random(N) < 0.05
r = np.where(bg, rng.random(N), 1.0 - rng.random(N) ** 2)
z = Z_MIN + (Z_MAX - Z_MIN) * r
gamma = np.where(bg, 0.05 + 0.95 * rng.random(N), np.clip(7.0 / z + 0.07 * rng.normal(size=N), 0.05, 1.0))
gamma, z = f32(gamma), f32(z)
r = np.clip((z - Z_MIN) / (Z_MAX - Z_MIN), 0.0, 1.0)

albedo = np.array([0.8, 0.42, 0.35])
cone = (1.0 - 0.3 * (1.0 - gamma) * r)  # non-separable
shade = (gamma / np.pi + 0.02 * gamma ** 8) * 40.0 / (z + 4.0) ** 2 * cone * 9.0
P = f32(np.clip(albedo[None, :] * shade[:, None] * (1.0 + 0.03 * rng.normal(size=(N, 3))), 0.0, 1.0))

# Density weights: 11 x 11 histogram over the samples' gamma range and r in [0, 1].
nb = int(round(np.sqrt(N / 20.0)))
gi = np.minimum(((gamma - gamma.min()) / (gamma.max() - gamma.min()) * nb).astype(int), nb - 1)
ri = np.minimum((r * nb).astype(int), nb - 1)
counts = np.zeros((nb, nb))
np.add.at(counts, (gi, ri), 1)
w = 1.0 / counts[gi, ri]
w = f32(w * N / (counts > 0).sum())


def B(t):
    s = 1.0 - t
    return np.stack([s ** 3, 3 * s * s * t, 3 * s * t * t, t ** 3], axis=1)


Bg, Br = B(gamma), B(r)
sw = np.sqrt(w)


def resid(p, ch):
    rho = Bg @ p[:4]
    varrho = Br @ np.concatenate([[1.0], p[4:]])
    return sw * (rho * varrho - P[:, ch])


channels = []
for ch in range(3):
    best = None
    for start in ([0.1, 0.1, 0.1, 0.1, 1, 1, 1], [0, 0.2, 0.4, 0.6, 0.7, 0.5, 0.3], [0.5, 0.5, 0.5, 0.5, 0.2, 0.2, 0.2]):
        res = least_squares(resid, np.array(start, float), args=(ch,), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
        if best is None or res.cost < best.cost:
            best = res
    channels.append({"cost": 2.0 * best.cost, "c": best.x[:4].tolist(), "d": best.x[4:].tolist()})
    print(f"channel {ch}: cost {2 * best.cost:.9e} params {np.round(best.x, 5)}")

ref = {
    "note": "scripts/reference/psi_scipy.py: scipy.optimize.least_squares (lm) on sqrt(w)(Psi - P)",
    "z_min": Z_MIN,
    "z_max": Z_MAX,
    "gamma": [float(x) for x in gamma],
    "z": [float(x) for x in z],
    "rgb": [[float(x) for x in P[:, ch]] for ch in range(3)],
    "w": [float(x) for x in w],
    "channels": channels,
}
with open(OUT, "w") as f:
    json.dump(ref, f, separators=(",", ":"))
print("wrote", OUT, os.path.getsize(OUT), "bytes")
