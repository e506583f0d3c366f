#!/usr/bin/env python3
"""DICOM test series made from real CT slices, and their reference values (read by
tests/dicom_j2k.rs, tests/cli_convert.rs and tests/cli_inspect_ct.rs).

Writes under tests/data/dicom_real/ (README.md and LICENSE there name the source):
  j2k_lossless/   5 consecutive real Siemens CT slices, copied byte for byte from
                  ../shared/data/real-dicom-j2k/ (transfer syntax 1.2.840.10008.1.2.4.90,
                  unsigned 12-bit, RescaleIntercept -1024, 2 mm apart)
  j2k_lossy/      the same slices decoded and re-encoded as JPEG 2000 lossy (.4.91: OpenJPEG via
                  pylibjpeg-openjpeg, 9/7 irreversible wavelet, compression ratio 12) as signed
                  HU (PixelRepresentation 1, intercept 0), a new series
  j2k_sign_mismatch/  3 slices of 40x32 HU cropped from the real slices, stored as an unsigned
                  12-bit codestream while the header says PixelRepresentation 1 (a known export
                  defect): decoders must sign-extend the 12 bits as pydicom does
  htj2k_lossless/, htj2k_lossy/  the same crops as signed HU, encoded as High-Throughput JPEG 2000
                  by OpenJPH (imagecodecs): .4.201 reversible, .4.203 irreversible
  deflated/       the same crops, native signed HU in Deflated Explicit VR Little Endian (.1.99)
and tests/data/dicom_real_reference.json with, per series (the three above and
tests/data/dicom/jpeg2000, small slices GDCM encoded, made by make_dicom_series.py), from
independent decoders:
  - pydicom 3 + pylibjpeg-openjpeg: every HU value, as one CRC-32 per slice over the HU values
    as little-endian int32 (slices sorted along the slice normal), plus sum, min and max;
  - SimpleITK (GDCM): the index -> RAS affine, chosen voxels' RAS points and HU, and its HU
    array, asserted here equal to pydicom's (GDCM 2.5.7 cannot decode HTJ2K: there the affine is
    computed from the headers by this script, "geometry_from" says which);
  - nibabel reading the NIfTI that SimpleITK writes from the series (what Slicer / ITK-SNAP users
    get): its affine and a CRC of its values, asserted equal to the above (not for HTJ2K).

Run from the repository root (needs ../shared/data/real-dicom-j2k):
  python -m venv /tmp/venv && /tmp/venv/bin/pip install pydicom pylibjpeg pylibjpeg-openjpeg \
      SimpleITK nibabel numpy
  /tmp/venv/bin/python scripts/reference/make_real_dicom_series.py
"""

import glob
import json
import os
import shutil
import tempfile
import zlib

import imagecodecs
import nibabel as nib
import numpy as np
import openjpeg
import openjpeg.utils
import pydicom
import SimpleITK as sitk
from pydicom.encaps import encapsulate
from pydicom.uid import (
    JPEG2000,
    DeflatedExplicitVRLittleEndian,
    JPEG2000Lossless,
    generate_uid,
)

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
SRC = os.path.join(ROOT, "..", "shared", "data", "real-dicom-j2k")
OUT = os.path.join(ROOT, "tests", "data", "dicom_real")
REF = os.path.join(ROOT, "tests", "data", "dicom_real_reference.json")
# Five consecutive slices from the middle of the 20 (instance numbers 274-278).
FIRST, COUNT = 7, 5
LOSSY_RATIO = 12.0
CROP = (200, 240, 150, 182)  # columns 200..239, rows 150..181 of each slice
SERIES = ("j2k_lossless", "j2k_lossy", "j2k_sign_mismatch", "htj2k_lossless", "htj2k_lossy", "deflated")


def uid_for(*names):
    """A UID derived from the names, so that re-running the script rewrites identical files."""
    return generate_uid(entropy_srcs=["bronchosim test data"] + [os.path.basename(n) for n in names])


def normal_position(ds):
    iop = np.array(ds.ImageOrientationPatient, dtype=float)
    n = np.cross(iop[:3], iop[3:])
    return float(np.dot(n, np.array(ds.ImagePositionPatient, dtype=float)))


def hu_of(ds):
    """HU of one slice by pydicom (+ pylibjpeg-openjpeg for JPEG 2000), float64 (rows, cols)."""
    arr = ds.pixel_array.astype(np.float64)
    return arr * float(getattr(ds, "RescaleSlope", 1.0)) + float(getattr(ds, "RescaleIntercept", 0.0))


def crc_i32(a):
    a = np.asarray(a)
    assert np.all(a == np.round(a)), "HU values must be integers for the int32 checksum"
    return zlib.crc32(a.astype("<i4").tobytes())


def write_lossy(files, folder):
    series_uid = uid_for(folder)
    for f in files:
        ds = pydicom.dcmread(f)
        hu = hu_of(ds).astype(np.int16)
        cs = openjpeg.utils.encode_array(hu, bits_stored=12, compression_ratios=[LOSSY_RATIO])
        ds.PixelRepresentation = 1
        ds.BitsStored, ds.HighBit = 12, 11
        ds.RescaleIntercept, ds.RescaleSlope = "0", "1"
        ds.PixelData = encapsulate([cs])
        ds["PixelData"].VR = "OB"
        ds.file_meta.TransferSyntaxUID = JPEG2000
        ds.LossyImageCompression = "01"
        ds.LossyImageCompressionRatio = f"{hu.nbytes / len(cs):.2f}"
        ds.LossyImageCompressionMethod = "ISO_15444_1"
        ds.SeriesInstanceUID = series_uid
        ds.SeriesDescription = "bronchosim: JPEG 2000 lossy re-encoding"
        ds.SOPInstanceUID = uid_for(folder, f)
        ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
        ds.save_as(os.path.join(folder, os.path.basename(f)), enforce_file_format=True)


def sign_mismatch_codestream(hu):
    """Two's complement in 12 bits, encoded as an unsigned 12-bit codestream."""
    bits = (hu.astype(np.int32) & 0xFFF).astype(np.uint16)
    return openjpeg.utils.encode_array(bits, bits_stored=12)


def write_crops(files, folder, ts, encode, description):
    """3 slices of the CROP of `files` as signed 12-bit HU; encode(hu) gives the one fragment of
    an encapsulated syntax, or None for native pixel data."""
    series_uid = uid_for(folder)
    c0, c1, r0, r1 = CROP
    for f in files[:3]:
        ds = pydicom.dcmread(f)
        hu = hu_of(ds)[r0:r1, c0:c1].astype(np.int16)
        cs = encode(hu)
        iop = np.array(ds.ImageOrientationPatient, dtype=float)
        dr, dc = (float(v) for v in ds.PixelSpacing)
        ipp = np.array(ds.ImagePositionPatient, dtype=float) + c0 * dc * iop[:3] + r0 * dr * iop[3:]
        ds.ImagePositionPatient = [f"{v:.6f}" for v in ipp]
        ds.Rows, ds.Columns = r1 - r0, c1 - c0
        ds.PixelRepresentation = 1
        ds.BitsStored, ds.HighBit = 12, 11
        ds.RescaleIntercept, ds.RescaleSlope = "0", "1"
        if cs is None:
            ds.PixelData = hu.astype("<i2").tobytes()
            ds["PixelData"].VR = "OW"
        else:
            ds.PixelData = encapsulate([cs])
            ds["PixelData"].VR = "OB"
        ds.file_meta.TransferSyntaxUID = ts
        ds.SeriesInstanceUID = series_uid
        ds.SeriesDescription = "bronchosim: " + description
        ds.SOPInstanceUID = uid_for(folder, f)
        ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
        ds.save_as(os.path.join(folder, os.path.basename(f)), enforce_file_format=True)


def reference(folder):
    paths = sorted(glob.glob(os.path.join(folder, "*")))
    slices = sorted((pydicom.dcmread(p) for p in paths), key=normal_position)
    hu = np.stack([hu_of(ds) for ds in slices])  # (k, j, i)
    nz, ny, nx = hu.shape

    reader = sitk.ImageSeriesReader()
    reader.SetFileNames(reader.GetGDCMSeriesFileNames(folder))
    try:
        img = reader.Execute()
    except RuntimeError:  # GDCM has no decoder for this syntax (HTJ2K)
        img = None
    if img is not None:
        sitk_hu = sitk.GetArrayFromImage(img).astype(np.float64)
        assert sitk_hu.shape == hu.shape, (sitk_hu.shape, hu.shape)
        sitk_diff = float(np.abs(sitk_hu - hu).max())
        d = np.array(img.GetDirection()).reshape(3, 3) * np.array(img.GetSpacing())[None, :]
        origin = np.array(img.GetOrigin())
        geometry_from = "SimpleITK"
    else:
        # PS3.3 C.7.6.2.1.1 with the slice step from the sorted positions (axial, no tilt).
        iop = np.array(slices[0].ImageOrientationPatient, dtype=float)
        dr, dc = (float(v) for v in slices[0].PixelSpacing)
        p0 = np.array(slices[0].ImagePositionPatient, dtype=float)
        step = (np.array(slices[-1].ImagePositionPatient, dtype=float) - p0) / max(nz - 1, 1)
        d = np.stack([iop[:3] * dc, iop[3:] * dr, step], axis=1)
        origin = p0
        geometry_from = "headers (this script)"
    aff = np.eye(4)
    aff[:3, :3] = d
    aff[:3, 3] = origin
    aff = np.diag([-1.0, -1.0, 1.0, 1.0]) @ aff  # LPS -> RAS
    lps_of = lambda ijk: (np.diag([-1.0, -1.0, 1.0, 1.0]) @ aff @ np.array([*ijk, 1.0]))[:3]

    pts = [(0, 0, 0), (nx - 1, 0, 0), (0, ny - 1, 0), (0, 0, nz - 1), (nx - 1, ny - 1, nz - 1)]
    rng = np.random.default_rng(17)
    pts += [(int(rng.integers(nx)), int(rng.integers(ny)), int(rng.integers(nz))) for _ in range(35)]
    voxels = []
    for i, j, k in pts:
        lps = img.TransformIndexToPhysicalPoint((i, j, k)) if img is not None else lps_of((i, j, k))
        voxels.append({"ijk": [i, j, k], "ras": [-lps[0], -lps[1], lps[2]], "hu": float(hu[k, j, i])})

    result = {
        "files": [os.path.basename(p) for p in paths],
        "transfer_syntax": str(slices[0].file_meta.TransferSyntaxUID),
        "geometry_from": geometry_from,
        "dims": [nx, ny, nz],
        "affine_ras": aff.tolist(),
        "slice_crc32_hu_i32le": [crc_i32(hu[k]) for k in range(nz)],
        "hu_sum": float(hu.sum()),
        "hu_min": float(hu.min()),
        "hu_max": float(hu.max()),
        "voxels": voxels,
    }
    if img is None:
        return result
    result["simpleitk_max_abs_diff_hu"] = sitk_diff
    with tempfile.TemporaryDirectory() as tmp:
        nii = os.path.join(tmp, "ct.nii.gz")
        sitk.WriteImage(img, nii)
        ni = nib.load(nii)
        nib_hu = np.asarray(ni.dataobj, dtype=np.float64)  # (i, j, k)
        assert nib_hu.shape == (nx, ny, nz)
        nib_affine = ni.affine.tolist()
        nib_crc = [crc_i32(nib_hu[:, :, k].T) for k in range(nz)]
    result["nibabel_from_simpleitk_nifti"] = {"affine": nib_affine, "slice_crc32_hu_i32le": nib_crc}
    return result


def main():
    if os.path.isdir(OUT):
        for sub in SERIES:
            shutil.rmtree(os.path.join(OUT, sub), ignore_errors=True)
    src = sorted(glob.glob(os.path.join(SRC, "CT.*")))
    assert len(src) == 20, f"expected the 20 slices of {SRC}"
    chosen = src[FIRST:FIRST + COUNT]
    dirs = {s: os.path.join(OUT, s) for s in SERIES}
    for d in dirs.values():
        os.makedirs(d)
    for f in chosen:
        shutil.copyfile(f, os.path.join(dirs["j2k_lossless"], os.path.basename(f)))
    shutil.copyfile(os.path.join(SRC, "LICENSE"), os.path.join(OUT, "LICENSE"))
    write_lossy(chosen, dirs["j2k_lossy"])
    write_crops(chosen, dirs["j2k_sign_mismatch"], JPEG2000Lossless, sign_mismatch_codestream,
                "JPEG 2000 sign mismatch")
    write_crops(chosen, dirs["htj2k_lossless"], "1.2.840.10008.1.2.4.201",
                lambda hu: imagecodecs.htj2k_encode(hu, reversible=True), "HTJ2K lossless")
    write_crops(chosen, dirs["htj2k_lossy"], "1.2.840.10008.1.2.4.203",
                lambda hu: imagecodecs.htj2k_encode(hu, level=0.001), "HTJ2K lossy")
    write_crops(chosen, dirs["deflated"], DeflatedExplicitVRLittleEndian, lambda hu: None,
                "deflated")

    ref = {
        "comment": "HU per slice as CRC-32 of little-endian int32, slices sorted along the normal; "
        "pydicom + pylibjpeg-openjpeg values, SimpleITK (GDCM) geometry, nibabel on SimpleITK's NIfTI",
        "versions": {
            "pydicom": pydicom.__version__,
            "pylibjpeg-openjpeg": openjpeg.__version__,
            "simpleitk": sitk.Version_VersionString(),
            "nibabel": nib.__version__,
            "imagecodecs": imagecodecs.__version__,
        },
        "series": {},
    }
    dirs["gdcm_small"] = os.path.join(ROOT, "tests", "data", "dicom", "jpeg2000")
    for name, d in dirs.items():
        r = reference(d)
        if "simpleitk_max_abs_diff_hu" in r:
            assert r["simpleitk_max_abs_diff_hu"] == 0.0, (name, r["simpleitk_max_abs_diff_hu"])
            nib_crc = r["nibabel_from_simpleitk_nifti"]["slice_crc32_hu_i32le"]
            assert nib_crc == r["slice_crc32_hu_i32le"], name
        ref["series"][name] = r
        print(name, r["dims"], r["transfer_syntax"], "HU", r["hu_min"], r["hu_max"], "geometry", r["geometry_from"])
    # How far the lossy re-encoding is from the lossless original (for the README).
    lossless = np.stack([hu_of(pydicom.dcmread(p)) for p in sorted(glob.glob(os.path.join(dirs["j2k_lossless"], "*")))])
    lossy = np.stack([hu_of(pydicom.dcmread(p)) for p in sorted(glob.glob(os.path.join(dirs["j2k_lossy"], "*")))])
    a = lossy - lossless
    ref["series"]["j2k_lossy"]["error_vs_lossless_hu"] = {
        "max_abs": float(np.abs(a).max()),
        "rms": float(np.sqrt((a**2).mean())),
    }
    print("lossy vs lossless: max |error| %.0f HU, rms %.2f HU" % (np.abs(a).max(), np.sqrt((a**2).mean())))
    with open(REF, "w") as f:
        json.dump(ref, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
