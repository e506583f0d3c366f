#!/usr/bin/env python3
"""Write small CT DICOM test series into tests/data/dicom/ and SimpleITK reference values into
tests/data/dicom_reference.json (read by tests/dicom_series.rs).

Good series (read by SimpleITK's ImageSeriesReader, world points converted LPS -> RAS):
  axial         24x20x12 int16 signed, slope 1 / intercept -1024, file names shuffled relative to
                position, InstanceNumber scrambled
  oblique       24x20x12 uint16 with BitsStored 12, IOP rotated ~20 deg, feet-first (instance
                numbers run against the slice normal), slope 1 / intercept -1024
  axial_rle     axial re-encoded with RLE Lossless (must equal axial voxel for voxel)
  single_slice  one 8-bit slice, slope 2 / intercept -1000, SliceThickness 2.5 mm
  jpeg2000      genuine JPEG 2000 Lossless slices (encoded by GDCM via SimpleITK); its reference
                values are written by make_real_dicom_series.py
Bad series (each must fail with a message naming the folder/file and the problem):
  unknown_syntax  a transfer syntax UID no registry knows
  mixed_series  two SeriesInstanceUIDs
  mixed_size    one slice with different Rows/Columns
  localizer     axial slices plus a coronal 2-D localizer in the same series
  missing_slice one slice removed from the middle
  nonuniform    one slice shifted by 0.3 mm (> 1 % of the 2.5 mm step)
  huge_header   Rows = Columns = 60000 with 960 bytes of pixel data
  not_dicom     a DICOM slice plus a text file
  duplicate     two slices at the same position

Run: /work/venv/bin/python scripts/reference/make_dicom_series.py  (from the repository root)
"""

import json
import os
import shutil
import tempfile

import numpy as np
import pydicom
import SimpleITK as sitk
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import (
    CTImageStorage,
    ExplicitVRLittleEndian,
    ImplicitVRLittleEndian,
    JPEG2000Lossless,
    RLELossless,
    generate_uid,
)

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
OUT = os.path.join(ROOT, "tests", "data", "dicom")
REF = os.path.join(ROOT, "tests", "data", "dicom_reference.json")
NX, NY, NZ = 24, 20, 12  # columns, rows, slices
RNG = np.random.default_rng(20240611)


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def make_slice(raw, ipp, iop, spacing, series_uid, instance, *, signed=True, bits_stored=16,
               slope=1.0, intercept=-1024.0, thickness=2.5, study_uid=None, frame_uid=None,
               image_type="ORIGINAL\\PRIMARY\\AXIAL", ts=ExplicitVRLittleEndian):
    """One CT slice as a pydicom FileDataset; raw is a (rows, cols) integer array."""
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ts
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = study_uid or "1.2.826.0.1.3680043.8.498.1"
    ds.SeriesInstanceUID = series_uid
    ds.FrameOfReferenceUID = frame_uid or "1.2.826.0.1.3680043.8.498.2"
    ds.Modality = "CT"
    ds.ImageType = image_type
    ds.SeriesDescription = "bronchosim test " + series_uid.split(".")[-1]
    ds.PatientName = "Test^Phantom"
    ds.PatientID = "BRONCHOSIM"
    ds.InstanceNumber = int(instance)
    ds.ImagePositionPatient = [f"{v:.6f}" for v in ipp]
    ds.ImageOrientationPatient = [f"{v:.8f}" for v in iop]
    ds.PixelSpacing = [f"{spacing[0]:.6f}", f"{spacing[1]:.6f}"]  # row spacing, column spacing
    ds.SliceThickness = f"{thickness:.6f}"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows, ds.Columns = raw.shape
    bits = 8 if raw.dtype.itemsize == 1 else 16
    ds.BitsAllocated = bits
    ds.BitsStored = bits_stored
    ds.HighBit = bits_stored - 1
    ds.PixelRepresentation = 1 if signed else 0
    ds.RescaleSlope = f"{slope:g}"
    ds.RescaleIntercept = f"{intercept:g}"
    ds.RescaleType = "HU"
    ds.PixelData = np.ascontiguousarray(raw).tobytes()
    ds.is_little_endian = True
    ds.is_implicit_VR = ts == ImplicitVRLittleEndian
    return ds


def save(ds, folder, name):
    os.makedirs(folder, exist_ok=True)
    ds.save_as(os.path.join(folder, name), enforce_file_format=True)


def series_geometry(origin, rowcos, colcos, spacing, step, nz):
    n = np.cross(rowcos, colcos)
    return [np.asarray(origin) + k * step * n for k in range(nz)]


def axial_raw():
    # HU in [-1024, 1975]; raw = HU + 1024 would be unsigned, so shift to exercise negative raw values
    hu = RNG.integers(-1024, 1976, size=(NZ, NY, NX)).astype(np.int16)
    return hu, (hu.astype(np.int32) + 1024 - 1500).astype(np.int16), -1024.0 + 1500.0  # raw signed, intercept


def write_axial(folder, raw, intercept, series_uid, *, nz=NZ, drop=(), shift=None, ts=ExplicitVRLittleEndian,
                prefix="IM", dup=None):
    rowcos, colcos = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    spacing = (0.75, 0.7)  # row spacing (along j), column spacing (along i)
    pos = series_geometry([-9.3, -20.1, -150.0], rowcos, colcos, spacing, 2.5, nz)
    order = RNG.permutation(nz)  # file name index of slice k
    inst = RNG.permutation(nz) + 1  # scrambled InstanceNumber
    for k in range(nz):
        if k in drop:
            continue
        p = pos[k].copy()
        if shift is not None and k == shift[0]:
            p[2] += shift[1]
        if dup is not None and k == dup:
            p = pos[k - 1].copy()
        ds = make_slice(raw[k], p, list(rowcos) + list(colcos), spacing, series_uid, inst[k],
                        intercept=intercept, ts=ts)
        save(ds, folder, f"{prefix}{order[k]:04d}.dcm")


def write_oblique(folder, series_uid):
    ang = np.deg2rad(20.0)
    # Rotate the axial frame by 20 deg about an axis tilted between x and z.
    axis = unit([1.0, 0.3, 0.5])
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K
    rowcos, colcos = R @ [1.0, 0, 0], R @ [0, 1.0, 0]
    spacing = (0.8, 0.65)
    step = 1.25
    pos = series_geometry([30.5, -12.25, 80.0], rowcos, colcos, spacing, step, NZ)
    raw = RNG.integers(0, 4096, size=(NZ, NY, NX)).astype(np.uint16)  # 12 bits stored
    order = RNG.permutation(NZ)
    for k in range(NZ):
        # Feet first: acquisition (instance numbers) runs against the slice normal.
        ds = make_slice(raw[k], pos[k], list(rowcos) + list(colcos), spacing, series_uid, NZ - k,
                        signed=False, bits_stored=12, thickness=step)
        ds.PatientPosition = "FFS"
        save(ds, folder, f"slice_{order[k]:02d}.dcm")


def write_single(folder, series_uid):
    raw = RNG.integers(0, 256, size=(NY, NX)).astype(np.uint8)
    ds = make_slice(raw, [12.0, -40.5, 33.25], [1, 0, 0, 0, 1, 0], (0.9, 0.9), series_uid, 1,
                    signed=False, bits_stored=8, slope=2.0, intercept=-1000.0, thickness=2.5)
    save(ds, folder, "only.dcm")


def sitk_reference(folder):
    """Affine-independent reference: world RAS points of chosen voxels and their HU, via SimpleITK."""
    reader = sitk.ImageSeriesReader()
    files = reader.GetGDCMSeriesFileNames(folder)
    reader.SetFileNames(files)
    img = reader.Execute()
    arr = sitk.GetArrayFromImage(img).astype(np.float64)  # (k, j, i)
    nz, ny, nx = arr.shape
    pts = [(0, 0, 0), (nx - 1, 0, 0), (0, ny - 1, 0), (0, 0, nz - 1), (nx - 1, ny - 1, nz - 1)]
    rng = np.random.default_rng(7)
    for _ in range(25):
        pts.append((int(rng.integers(nx)), int(rng.integers(ny)), int(rng.integers(nz))))
    voxels = []
    for i, j, k in pts:
        lps = img.TransformIndexToPhysicalPoint((i, j, k))
        voxels.append({"ras": [-lps[0], -lps[1], lps[2]], "hu": float(arr[k, j, i])})
    d = np.array(img.GetDirection()).reshape(3, 3) * np.array(img.GetSpacing())[None, :]
    aff = np.eye(4)
    aff[:3, :3] = d
    aff[:3, 3] = img.GetOrigin()
    aff = np.diag([-1.0, -1.0, 1.0, 1.0]) @ aff  # LPS -> RAS
    return {
        "dims": [nx, ny, nz],
        "affine_ras": aff.tolist(),
        "voxels": voxels,
        "hu_sum": float(arr.sum()),
        "hu_min": float(arr.min()),
        "hu_max": float(arr.max()),
    }


def main():
    if os.path.isdir(OUT):
        shutil.rmtree(OUT)
    os.makedirs(OUT)
    base = "1.2.826.0.1.3680043.8.498.10"
    hu, raw, intercept = axial_raw()
    write_axial(os.path.join(OUT, "axial"), raw, intercept, base + ".1")
    write_oblique(os.path.join(OUT, "oblique"), base + ".2")
    write_single(os.path.join(OUT, "single_slice"), base + ".3")
    # RLE copy of axial: same files, re-encoded.
    os.makedirs(os.path.join(OUT, "axial_rle"))
    for name in sorted(os.listdir(os.path.join(OUT, "axial"))):
        ds = pydicom.dcmread(os.path.join(OUT, "axial", name))
        ds.compress(RLELossless)
        save(ds, os.path.join(OUT, "axial_rle"), name)

    # --- bad series (fewer slices to keep the data small) ---
    small = raw[:5]
    # JPEG 2000: let GDCM encode each slice, then carry the codestream into our headers.
    tmp = tempfile.mkdtemp()
    folder = os.path.join(OUT, "jpeg2000")
    for k in range(3):
        img = sitk.GetImageFromArray(small[k][None])
        w = sitk.ImageFileWriter()
        w.SetImageIO("GDCMImageIO")
        w.SetFileName(os.path.join(tmp, "j.dcm"))
        w.UseCompressionOn()
        w.SetCompressor("JPEG2000")
        w.Execute(img)
        j2k = pydicom.dcmread(os.path.join(tmp, "j.dcm"))
        assert j2k.file_meta.TransferSyntaxUID == JPEG2000Lossless
        ds = make_slice(small[k], [0, 0, 2.5 * k], [1, 0, 0, 0, 1, 0], (0.7, 0.7), base + ".4", k + 1)
        ds.file_meta.TransferSyntaxUID = JPEG2000Lossless
        ds.PixelData = j2k.PixelData
        ds["PixelData"].VR = "OB"
        ds["PixelData"].is_undefined_length = True
        save(ds, folder, f"j{k}.dcm")
    shutil.rmtree(tmp)

    folder = os.path.join(OUT, "unknown_syntax")
    for k in range(2):
        ds = make_slice(small[k], [0, 0, 2.5 * k], [1, 0, 0, 0, 1, 0], (0.7, 0.7), base + ".5", k + 1)
        ds.file_meta.TransferSyntaxUID = "1.2.826.0.1.3680043.8.498.999.1"  # private, undecodable
        save(ds, folder, f"u{k}.dcm")

    write_axial(os.path.join(OUT, "mixed_series"), small, intercept, base + ".6", nz=3, prefix="A")
    write_axial(os.path.join(OUT, "mixed_series"), small[2:], intercept, base + ".7", nz=2, prefix="B")

    folder = os.path.join(OUT, "mixed_size")
    write_axial(folder, small, intercept, base + ".8", nz=3)
    ds = make_slice(np.zeros((16, 24), np.int16), [0, 0, 7.5], [1, 0, 0, 0, 1, 0], (0.75, 0.7), base + ".8", 9)
    save(ds, folder, "odd.dcm")

    folder = os.path.join(OUT, "localizer")
    write_axial(folder, small, intercept, base + ".9", nz=4)
    ds = make_slice(np.zeros((20, 24), np.int16), [-9.3, 0.0, -100.0], [1, 0, 0, 0, 0, -1], (2.0, 2.0),
                    base + ".9", 99, image_type="ORIGINAL\\PRIMARY\\LOCALIZER")
    save(ds, folder, "scout.dcm")

    write_axial(os.path.join(OUT, "missing_slice"), small, intercept, base + ".11", nz=5, drop=(2,))
    write_axial(os.path.join(OUT, "nonuniform"), small, intercept, base + ".12", nz=5, shift=(3, 0.3))
    write_axial(os.path.join(OUT, "duplicate"), small, intercept, base + ".13", nz=4, dup=2)

    folder = os.path.join(OUT, "huge_header")
    for k in range(2):
        ds = make_slice(small[k], [0, 0, 2.5 * k], [1, 0, 0, 0, 1, 0], (0.7, 0.7), base + ".14", k + 1)
        ds.Rows, ds.Columns = 60000, 60000  # claims 7.2 GB per slice
        save(ds, folder, f"h{k}.dcm")

    folder = os.path.join(OUT, "not_dicom")
    write_axial(folder, small, intercept, base + ".15", nz=2)
    with open(os.path.join(folder, "notes.txt"), "w") as f:
        f.write("not a DICOM file\n")

    ref = {
        "comment": "SimpleITK ImageSeriesReader reference; world points in RAS mm (LPS x, y negated)",
        "simpleitk": sitk.Version.VersionString(),
        "series": {name: sitk_reference(os.path.join(OUT, name))
                   for name in ["axial", "oblique", "axial_rle", "single_slice"]},
    }
    with open(REF, "w") as f:
        json.dump(ref, f, indent=1)
    total = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(OUT) for f in fs)
    print(f"wrote {OUT} ({total / 1024:.0f} KB) and {REF} ({os.path.getsize(REF) / 1024:.0f} KB)")


if __name__ == "__main__":
    main()
