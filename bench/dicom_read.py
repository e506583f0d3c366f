#!/usr/bin/env python3
"""Time reading a 512x512x160 int16 CT DICOM series (raw and RLE): SimpleITK's ImageSeriesReader
against bronchosim's read_dicom_series (criterion bench `dicom_read`), in one run; prints ratios.

The series is written once into /tmp/bronchosim_bench_dicom (about 80 MB raw + RLE).
Run: bench/.venv/bin/python bench/dicom_read.py (all comparisons, venv included: bash bench/run_all.sh)
"""

import json
import os
import subprocess
import time

import numpy as np
import pydicom
import SimpleITK as sitk
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, RLELossless, generate_uid

import cargo_target

ROOT = "/tmp/bronchosim_bench_dicom"
N, NZ = 512, 160


def write_series(folder, rle):
    os.makedirs(folder, exist_ok=True)
    if len(os.listdir(folder)) == NZ:
        return
    rng = np.random.default_rng(1)
    series = generate_uid()
    yy, xx = np.mgrid[0:N, 0:N]
    body = ((xx - N / 2) ** 2 / (0.45 * N) ** 2 + (yy - N / 2) ** 2 / (0.35 * N) ** 2) < 1
    for k in range(NZ):
        # CT-like: air outside, soft tissue with noise inside, a dark airway disc.
        img = np.where(body, 40 + rng.normal(0, 20, (N, N)), -1000).astype(np.int16)
        img[(xx - N / 2) ** 2 + (yy - N / 2 + 40) ** 2 < 15 ** 2] = -950
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
        ds.SeriesInstanceUID, ds.Modality, ds.InstanceNumber = series, "CT", k + 1
        ds.ImagePositionPatient = [-180.0, -180.0, -300.0 + 1.25 * k]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [0.703125, 0.703125]
        ds.SliceThickness = 1.25
        ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
        ds.Rows = ds.Columns = N
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
        ds.RescaleSlope, ds.RescaleIntercept = 1, 0
        ds.PixelData = img.tobytes()
        if rle:
            ds.compress(RLELossless)
        ds.save_as(os.path.join(folder, f"{k:04d}.dcm"), enforce_file_format=True)


def time_sitk(folder, repeat=3):
    best = 1e9
    for _ in range(repeat):
        t = time.perf_counter()
        r = sitk.ImageSeriesReader()
        r.SetFileNames(r.GetGDCMSeriesFileNames(folder))
        img = r.Execute()
        sitk.Cast(img, sitk.sitkFloat32)  # we return f32 HU; count the conversion too
        best = min(best, time.perf_counter() - t)
    return best


def main():
    raw, rle = os.path.join(ROOT, "raw"), os.path.join(ROOT, "rle")
    write_series(raw, False)
    write_series(rle, True)
    env = dict(os.environ, BRONCHOSIM_DICOM_BENCH_DIR=raw, BRONCHOSIM_DICOM_BENCH_RLE_DIR=rle)
    subprocess.run(["cargo", "bench", "--bench", "dicom_read", "--", "--noplot"], check=True, env=env,
                   cwd=cargo_target.ROOT)
    target = cargo_target.target_dir()
    for label, folder in [("raw", raw), ("rle", rle)]:
        est = json.load(open(os.path.join(target, "criterion", "dicom_read", label, "new", "estimates.json")))
        ours = est["median"]["point_estimate"] / 1e9
        theirs = time_sitk(folder)
        print(f"{label}: 512x512x{NZ}  SimpleITK {theirs:.3f} s  bronchosim {ours:.3f} s  "
              f"ratio (SimpleITK / bronchosim) {theirs / ours:.2f}")


if __name__ == "__main__":
    main()
