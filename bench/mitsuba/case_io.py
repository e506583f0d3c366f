"""Reading and writing bronchosim's case format (CASE_FORMAT.md) and its phantom's truth folder.

Conventions that matter for the numbers:
- camera.json is OpenCV's pinhole (+ Brown-Conrady) with pixel centres at integer coordinates;
  camera axes +x right, +y down, +z the viewing direction; poses are camera-to-world, row-major
  4x4, millimetres.
- Frames and views are 8-bit sRGB PNG; `_linear.png` is linear RGB, value = code / 65535;
  `_depth.png` is the distance camera centre to surface along the pixel-centre ray, code / 100 mm
  (0 = miss); `_mask.png` is 255 where the pixel-centre ray hits the mesh.
16-bit PNGs go through Mitsuba's Bitmap (Pillow reads 16-bit RGB PNGs as 8-bit).
"""

import json
import os
import shutil
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np


class CaseError(Exception):
    """Bad input: the message names the file and the problem."""


def fail(path, problem):
    raise CaseError(f"{path}: {problem}")


def read_json(path):
    path = Path(path)
    if not path.exists():
        fail(path, "missing")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        fail(path, f"not valid JSON ({e})")


def write_json(path, value):
    """Write JSON atomically (temporary file, then rename) so that nothing half-written stays."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(value, indent=2) + "\n")
    os.replace(tmp, path)


def read_camera(path):
    """camera.json as a dict of floats (missing distortion keys are 0)."""
    cam = read_json(path)
    for k in ("width", "height", "fx", "fy", "cx", "cy"):
        if k not in cam:
            fail(path, f'no "{k}"')
    out = {k: float(cam.get(k, 0.0)) for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")}
    out["width"], out["height"] = int(cam["width"]), int(cam["height"])
    return out


def is_pinhole(cam):
    return all(cam[k] == 0.0 for k in ("k1", "k2", "p1", "p2", "k3"))


def pinhole_camera(cam):
    """The same intrinsics without lens distortion."""
    out = dict(cam)
    for k in ("k1", "k2", "p1", "p2", "k3"):
        out[k] = 0.0
    return out


def write_camera(path, cam):
    keys = ("width", "height", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    write_json(path, {k: cam[k] for k in keys})


def read_poses(path):
    """poses.json / views.json: list of (image name relative to the file's folder, 4x4 array)."""
    doc = read_json(path)
    frames = doc.get("frames") if isinstance(doc, dict) else None
    if not isinstance(frames, list) or not frames:
        fail(path, 'no "frames" list')
    out = []
    for i, f in enumerate(frames):
        m = f.get("camera_to_world")
        if "image" not in f:
            fail(path, f'frame {i}: no "image" (video cases are not supported here)')
        if not isinstance(m, list) or len(m) != 16:
            fail(path, f'frame {i}: "camera_to_world" must hold 16 numbers')
        out.append((f["image"], np.array(m, dtype=np.float64).reshape(4, 4)))
    return out


def write_poses(path, entries):
    """Write poses.json / views.json from (image name, 4x4 array) pairs."""
    frames = [{"image": name, "camera_to_world": [float(v) for v in m.ravel()]} for name, m in entries]
    write_json(path, {"frames": frames})


def read_ply(path):
    """A binary little-endian triangle PLY: (dict of float vertex properties, faces (n, 3) uint32)."""
    path = Path(path)
    if not path.exists():
        fail(path, "missing")
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        fail(path, "not a PLY file")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        fail(path, "only binary little-endian PLY is supported")
    elements, current = [], None
    for line in header:
        w = line.split()
        if w[0] == "element":
            current = (w[1], int(w[2]), [])
            elements.append(current)
        elif w[0] == "property":
            current[2].append(w[1:])
    names = [e[0] for e in elements]
    if names != ["vertex", "face"]:
        fail(path, f"expected elements vertex, face; found {names}")
    _, nv, vprops = elements[0]
    if any(p[0] != "float" for p in vprops):
        fail(path, "vertex properties must all be float")
    vdt = np.dtype([(p[1], "<f4") for p in vprops])
    off = end + len(b"end_header\n")
    verts = np.frombuffer(data, vdt, nv, off)
    off += nv * vdt.itemsize
    _, nf, fprops = elements[1]
    if fprops != [["list", "uchar", "uint", "vertex_indices"]]:
        fail(path, f"face property must be 'list uchar uint vertex_indices', found {fprops}")
    fdt = np.dtype([("n", "u1"), ("i", "<u4", (3,))])
    if len(data) < off + nf * fdt.itemsize:
        fail(path, "truncated (or faces that are not triangles)")
    faces = np.frombuffer(data, fdt, nf, off)
    if np.any(faces["n"] != 3):
        fail(path, "only triangle faces are supported")
    if faces["i"].size and faces["i"].max() >= nv:
        fail(path, "a face indexes a vertex that does not exist")
    return {p[1]: verts[p[1]].astype(np.float64) for p in vprops}, faces["i"].astype(np.uint32)


def srgb_encode(linear):
    """Linear [0, 1] to sRGB [0, 1] (IEC 61966-2-1)."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_decode(encoded):
    """sRGB [0, 1] to linear [0, 1]."""
    x = np.clip(encoded, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def write_srgb8(path, linear):
    """Linear RGB (h, w, 3), clipped to [0, 1], as an 8-bit sRGB PNG."""
    iio.imwrite(path, np.round(srgb_encode(linear) * 255.0).astype(np.uint8))


def read_srgb8_linear(path):
    """An 8- or 16-bit sRGB PNG as linear RGB float64 (h, w, 3)."""
    path = Path(path)
    if not path.exists():
        fail(path, "missing")
    a = read_png_raw(path)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    scale = 65535.0 if a.dtype == np.uint16 else 255.0
    return srgb_decode(a[:, :, :3].astype(np.float64) / scale)


def _mitsuba():
    """Mitsuba with some variant set (Bitmap needs one; render_case.py sets its own first)."""
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return mi


def read_png_raw(path):
    """A PNG's stored codes (uint8 or uint16), 16-bit through Mitsuba's Bitmap."""
    mi = _mitsuba()
    try:
        return np.array(mi.Bitmap(str(path)))
    except RuntimeError as e:
        fail(path, f"not a readable PNG ({e})")


def write_png16(path, codes):
    """uint16 codes, (h, w) grey or (h, w, 3) RGB, as a 16-bit PNG."""
    mi = _mitsuba()
    fmt = mi.Bitmap.PixelFormat.RGB if codes.ndim == 3 else mi.Bitmap.PixelFormat.Y
    mi.Bitmap(np.ascontiguousarray(codes.astype(np.uint16)), fmt).write(str(path))


def write_linear16(path, linear):
    write_png16(path, np.round(np.clip(linear, 0.0, 1.0) * 65535.0))


def write_gray8(path, values):
    iio.imwrite(path, values.astype(np.uint8))


def link_or_copy(src, dst):
    """Hard-link `src` to `dst` (same file system), else copy it."""
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def main_guard(main):
    """Run `main`; a CaseError becomes one line on stderr and exit status 2."""
    try:
        main()
    except CaseError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
