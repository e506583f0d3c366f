#!/usr/bin/env python3
"""Which DICOM transfer syntaxes `bronchosim convert` reads, and whether it reads them right.

For every transfer syntax below, a 3-slice CT series (64 x 48 pixels cut from a real slice of
tests/data/dicom_real/j2k_lossless) is written with pydicom, the pixel data encoded by pydicom
itself (native, deflate, big endian, RLE) or by imagecodecs (libjpeg-turbo, CharLS, OpenJPEG,
OpenJPH, libjxl). The series is converted with `bronchosim convert`, the NIfTI read with nibabel
and compared voxel for voxel with the HU an independent decoder gives: pydicom with its pylibjpeg
/ pyjpegls plugins, or imagecodecs where pydicom has no decoder (JPEG XL). One line per syntax:
OK (every HU equal), DIFF (max |difference|), or FAIL with bronchosim's error.

usage: bench/dicom_transfer_syntaxes.py [path/to/bronchosim]   (default target/release/bronchosim)
needs: pip install pydicom pylibjpeg pylibjpeg-openjpeg pylibjpeg-libjpeg pyjpegls imagecodecs nibabel numpy
"""

import glob
import os
import subprocess
import sys
import tempfile

import imagecodecs as ic
import nibabel as nib
import numpy as np
import pydicom
import pydicom.filewriter
from pydicom.encaps import encapsulate
from pydicom.uid import generate_uid

ROOT = os.path.join(os.path.dirname(__file__), "..")
SRC = sorted(glob.glob(os.path.join(ROOT, "tests", "data", "dicom_real", "j2k_lossless", "*")))[0]
R0, C0, NY, NX = 200, 180, 48, 64


def base_slices():
    """Three (dataset, HU int16 array) pairs 2 mm apart, cut from one real slice."""
    ds0 = pydicom.dcmread(SRC)
    hu = (ds0.pixel_array.astype(np.int32) - 1024)[R0:R0 + NY, C0:C0 + NX]
    out = []
    for k in range(3):
        ds = pydicom.dcmread(SRC)
        ds.Rows, ds.Columns = NY, NX
        ipp = np.array(ds.ImagePositionPatient, dtype=float)
        sp = float(ds.PixelSpacing[0])
        ds.ImagePositionPatient = [f"{ipp[0] + C0 * sp:.6f}", f"{ipp[1] + R0 * sp:.6f}", f"{ipp[2] + 2 * k:.6f}"]
        ds.InstanceNumber = k + 1
        out.append((ds, (hu + 7 * k).astype(np.int16)))
    return out


def set_pixels(ds, raw, ts, *, encapsulated_frame=None, signed=True, bits=16, stored=None):
    ds.file_meta.TransferSyntaxUID = ts
    ds.BitsAllocated, ds.BitsStored = bits, stored or bits
    ds.HighBit = ds.BitsStored - 1
    ds.PixelRepresentation = 1 if signed else 0
    ds.RescaleIntercept, ds.RescaleSlope = "0", "1"
    if encapsulated_frame is not None:
        ds.PixelData = encapsulate([encapsulated_frame])
        ds["PixelData"].VR = "OB"
    else:
        ds.PixelData = raw.tobytes()
        ds["PixelData"].VR = "OW" if bits == 16 else "OB"


def encoders():
    """(name, uid, encode(ds, hu) -> None) for each syntax; encode fills ds's pixel data."""
    def native(ts, order="<"):
        def f(ds, hu):
            set_pixels(ds, hu.astype(order + "i2"), ts)
        return f

    def rle(ds, hu):
        set_pixels(ds, hu, pydicom.uid.ExplicitVRLittleEndian)
        ds.compress(pydicom.uid.RLELossless, encoding_plugin="pydicom")

    def enc(ts, fn, *, unsigned12=False, eight=False, **kw):
        def f(ds, hu):
            if eight:  # 8-bit baseline: window -1024..1016 HU into 0..255
                raw = np.clip((hu.astype(np.int32) + 1024) // 8, 0, 255).astype(np.uint8)
                set_pixels(ds, raw, ts, encapsulated_frame=fn(raw, **kw), signed=False, bits=8)
                ds.RescaleIntercept, ds.RescaleSlope = "-1024", "8"
            elif unsigned12:  # 12-bit unsigned with intercept -1024, as scanners store it
                raw = (hu.astype(np.int32) + 1024).clip(0, 4095).astype(np.uint16)
                set_pixels(ds, raw, ts, encapsulated_frame=fn(raw, **kw), signed=False, stored=12)
                ds.RescaleIntercept = "-1024"
            else:
                set_pixels(ds, hu, ts, encapsulated_frame=fn(hu, **kw))
        return f

    u = pydicom.uid
    return [
        ("Implicit VR Little Endian", u.ImplicitVRLittleEndian, native(u.ImplicitVRLittleEndian)),
        ("Explicit VR Little Endian", u.ExplicitVRLittleEndian, native(u.ExplicitVRLittleEndian)),
        ("Deflated Explicit VR Little Endian", u.DeflatedExplicitVRLittleEndian,
         native(u.DeflatedExplicitVRLittleEndian)),
        ("Explicit VR Big Endian", u.ExplicitVRBigEndian, native(u.ExplicitVRBigEndian, ">")),
        ("RLE Lossless", u.RLELossless, rle),
        ("JPEG Baseline (8-bit)", u.JPEGBaseline8Bit, enc(u.JPEGBaseline8Bit, ic.jpeg8_encode, eight=True, level=95)),
        ("JPEG Extended (12-bit)", u.JPEGExtended12Bit,
         enc(u.JPEGExtended12Bit, ic.jpeg8_encode, unsigned12=True, level=95, bitspersample=12)),
        ("JPEG Lossless P14 (predictor 6)", u.JPEGLossless,
         enc(u.JPEGLossless, ic.jpeg8_encode, unsigned12=True, lossless=True, predictor=6, bitspersample=12)),
        ("JPEG Lossless SV1", u.JPEGLosslessSV1,
         enc(u.JPEGLosslessSV1, ic.jpeg8_encode, unsigned12=True, lossless=True, predictor=1, bitspersample=12)),
        ("JPEG-LS Lossless", u.JPEGLSLossless, enc(u.JPEGLSLossless, ic.jpegls_encode, unsigned12=True)),
        ("JPEG-LS Near-Lossless", u.JPEGLSNearLossless,
         enc(u.JPEGLSNearLossless, ic.jpegls_encode, unsigned12=True, level=2)),
        ("JPEG 2000 Lossless", u.JPEG2000Lossless,
         enc(u.JPEG2000Lossless, ic.jpeg2k_encode, codecformat="J2K", reversible=True)),
        ("JPEG 2000 (lossy)", u.JPEG2000, enc(u.JPEG2000, ic.jpeg2k_encode, codecformat="J2K", level=80, reversible=False)),
        ("HTJ2K Lossless", "1.2.840.10008.1.2.4.201", enc("1.2.840.10008.1.2.4.201", ic.htj2k_encode, reversible=True)),
        ("HTJ2K (lossy)", "1.2.840.10008.1.2.4.203", enc("1.2.840.10008.1.2.4.203", ic.htj2k_encode, level=0.001)),
        ("JPEG XL Lossless", "1.2.840.10008.1.2.4.110",
         enc("1.2.840.10008.1.2.4.110", ic.jpegxl_encode, unsigned12=True, lossless=True)),
    ]


def reference_hu(paths):
    """HU by pydicom (with plugins), or by imagecodecs when pydicom cannot decode."""
    out = []
    for p in paths:
        ds = pydicom.dcmread(p)
        try:
            arr = ds.pixel_array
        except Exception:  # no pydicom decoder (JPEG XL): decode the one fragment with imagecodecs
            frame = next(pydicom.encaps.generate_frames(ds.PixelData, number_of_frames=1))
            arr = ic.imread(frame)
        out.append(arr.astype(np.float64) * float(ds.RescaleSlope) + float(ds.RescaleIntercept))
    return np.stack(out)


def main():
    exe = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "target", "release", "bronchosim")
    for name, uid, encode in encoders():
        with tempfile.TemporaryDirectory() as tmp:
            folder = os.path.join(tmp, "series")
            os.makedirs(folder)
            series = generate_uid()
            try:
                for k, (ds, hu) in enumerate(base_slices()):
                    ds.SeriesInstanceUID = series
                    encode(ds, hu)
                    path = os.path.join(folder, f"s{k}.dcm")
                    if uid == pydicom.uid.ExplicitVRBigEndian:  # pixel bytes already big endian
                        pydicom.filewriter.dcmwrite(path, ds, implicit_vr=False, little_endian=False,
                                                    force_encoding=True)
                    else:
                        ds.save_as(path, enforce_file_format=True)
                want = reference_hu(sorted(glob.glob(os.path.join(folder, "*"))))
            except Exception as e:  # the encoder or the reference decoder is missing
                print(f"{name:38s} {uid:26s} SKIP (cannot make or decode: {e})")
                continue
            nii = os.path.join(tmp, "ct.nii")
            r = subprocess.run([exe, "--quiet", "convert", folder, "--out", nii], capture_output=True, text=True)
            if r.returncode != 0:
                print(f"{name:38s} {uid:26s} FAIL {r.stderr.strip().split(': ', 2)[-1][:150]}")
                continue
            got = np.asarray(nib.load(nii).dataobj, dtype=np.float64).transpose(2, 1, 0)  # (k, j, i)
            d = np.abs(got - want).max()
            print(f"{name:38s} {uid:26s} {'OK' if d == 0 else f'DIFF max {d:g} HU'}")


if __name__ == "__main__":
    main()
