"""The cohort workflow's Python parts on hand-made folders: the failure records stage.py writes,
when a failure still holds, and the numbers the summary reads back.

Run: workflow/.venv/bin/python -m unittest discover -s workflow/tests (from workflow/test_cohort.sh).
"""
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
sys.path.insert(0, str(SCRIPTS))
import cohort_cases as cc  # noqa: E402
import cohort_resources as cr  # noqa: E402
import cohort_summary as cs  # noqa: E402


def write(path: Path, text: str, mtime=None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    if mtime is not None:
        os.utime(path, (mtime, mtime))
    return path


def stage(case_out: Path, *command, stdout=None):
    args = [sys.executable, str(SCRIPTS / "stage.py"), "--stage", "build", "--case-out",
            str(case_out), "--log", str(case_out / "logs" / "build.log"), "--fingerprint", "fp"]
    if stdout is not None:
        args += ["--stdout", str(stdout)]
    return subprocess.run(args + ["--", *command], capture_output=True, text=True)


class StageWrapper(unittest.TestCase):
    def test_failure_is_recorded_with_its_error_line_and_cleared_by_a_success(self):
        with tempfile.TemporaryDirectory() as tmp:
            case_out = Path(tmp) / "c"
            r = stage(case_out, "sh", "-c", "echo progress >&2; echo 'error: ct.nii.gz: bad header' >&2; exit 3")
            self.assertEqual(r.returncode, 3)
            rec = json.loads((case_out / "failed.json").read_text())
            self.assertEqual((rec["stage"], rec["error"], rec["exit_status"]), ("build", "ct.nii.gz: bad header", 3))
            self.assertEqual(rec["fingerprint"], "fp")
            self.assertEqual(json.loads((case_out / "logs" / "build.usage.json").read_text())["exit_status"], 3)
            out = case_out / "inspect.json"
            r = stage(case_out, "sh", "-c", "echo '{\"ok\": 1}'", stdout=out)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertFalse((case_out / "failed.json").exists())
            self.assertEqual(json.loads(out.read_text()), {"ok": 1})
            self.assertEqual([p.name for p in case_out.iterdir() if "partial" in p.name], [])

    def test_a_failed_command_leaves_no_stdout_file(self):
        with tempfile.TemporaryDirectory() as tmp:
            case_out = Path(tmp) / "c"
            out = case_out / "inspect.json"
            r = stage(case_out, "sh", "-c", "echo '{\"half\"'; exit 1", stdout=out)
            self.assertEqual(r.returncode, 1)
            self.assertFalse(out.exists())
            self.assertEqual(sorted(p.name for p in case_out.iterdir()), ["failed.json", "logs"])
            # No `error:` line: the last line stands for the error.
            self.assertEqual(json.loads((case_out / "failed.json").read_text())["error"], "exit status 1 with no message")

    def test_a_killed_command_is_named_by_its_signal(self):
        with tempfile.TemporaryDirectory() as tmp:
            case_out = Path(tmp) / "c"
            r = stage(case_out, "sh", "-c", "kill -9 $$")
            self.assertEqual(r.returncode, 1)
            self.assertEqual(json.loads((case_out / "failed.json").read_text())["error"], "killed by signal SIGKILL")

    def test_an_interrupted_command_leaves_no_failure_record(self):
        with tempfile.TemporaryDirectory() as tmp:
            case_out = Path(tmp) / "c"
            r = stage(case_out, "sh", "-c", "kill -TERM $$")
            self.assertEqual(r.returncode, 128 + 15)
            self.assertFalse((case_out / "failed.json").exists())


class FailureRecord(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        root = Path(self.tmp.name)
        self.case = root / "cases" / "a"
        self.out = root / "out" / "a"
        old = time.time() - 100
        write(self.case / "poses.json", "{}", old)
        write(self.case / "frames" / "000000.png", "", old)
        write(self.case / "notes.txt", "", old)
        os.utime(self.case, (old, old))
        self.record = write(self.out / "failed.json", json.dumps({"fingerprint": "v1"}), old + 50)

    def tearDown(self):
        self.tmp.cleanup()

    def test_an_unchanged_case_keeps_its_failure(self):
        self.assertEqual(cc.current_failure(self.case, self.out, "v1"), self.record)

    def test_another_binary_or_settings_retry_it(self):
        self.assertIsNone(cc.current_failure(self.case, self.out, "v2"))

    def test_a_newer_frame_or_a_new_ct_retries_it(self):
        os.utime(self.case / "frames" / "000000.png")
        self.assertIsNone(cc.current_failure(self.case, self.out, "v1"))

    def test_a_new_file_in_the_case_folder_retries_it(self):
        write(self.case / "ct.nii.gz", "")
        self.assertIsNone(cc.current_failure(self.case, self.out, "v1"))

    def test_inputs_are_the_case_format_files_only(self):
        names = sorted(p.relative_to(self.case).as_posix() for p in cc.input_files(self.case))
        self.assertEqual(names, ["frames/000000.png", "poses.json"])


class BuildMemory(unittest.TestCase):
    def inspection(self, dims, frames, size):
        return {"ct": {"dims": dims}, "video": {"frames": frames}, "camera": {"size": size}}

    def test_the_fit_reproduces_the_measured_peaks(self):
        for dims, frames, size, peak in [([225, 169, 181], 12, [96, 96], 193),
                                         ([225, 169, 181], 80, [320, 320], 410),
                                         ([352, 287, 312], 80, [320, 320], 965)]:
            got = cr.build_peak_mb(self.inspection(dims, frames, size))
            self.assertLess(abs(got - peak), 2.0, (dims, frames, got))

    def test_the_request_has_headroom_a_floor_and_grows_with_the_attempt(self):
        with tempfile.TemporaryDirectory() as tmp:
            small = write(Path(tmp) / "s.json", json.dumps(self.inspection([225, 169, 181], 80, [320, 320])))
            atm = write(Path(tmp) / "a.json", json.dumps(self.inspection([352, 287, 312], 80, [320, 320])))
            self.assertEqual(cr.build_mem_mb(small), 1000)  # 1.5 x 410 MB, under the 1 GB floor
            self.assertEqual(cr.build_mem_mb(atm), 1500)  # 1.5 x 965 MB = 1447, rounded up
            self.assertEqual(cr.build_mem_mb(atm, attempt=2), 3000)
            self.assertEqual(cr.build_mem_mb(Path(tmp) / "missing.json"), cr.UNKNOWN_MB)


class Summary(unittest.TestCase):
    def test_rows_of_an_ok_a_failed_an_interrupted_and_a_pending_case(self):
        with tempfile.TemporaryDirectory() as tmp:
            cases, out = Path(tmp) / "cases", Path(tmp) / "out"
            for c in ["ok", "failed", "killed", "waiting"]:
                (cases / c).mkdir(parents=True)
            write(cases / "ok" / "views.json", "{}")
            write(out / "ok" / "inspect.json", json.dumps({"ct": {"dims": [10, 20, 30], "spacing_mm": [0.5, 0.5, 1.25]}, "video": {"frames": 3}}))
            write(out / "ok" / "model" / "model.json", json.dumps({
                "generator": "bronchosim 9.9.9",
                "counts": {"frames": 3, "airway_volume_ml": 12.5, "branches": 9, "triangles": 1000},
                "shading_model": "calibrated",
                "cross_validation": {"models": [{"model": "paper", "mean_psnr_db": 25.25},
                                                {"model": "calibrated", "mean_psnr_db": 27.5}]},
                "timings": {"segment": 1.5, "total": 4.0}}))
            write(out / "ok" / "model" / "poses.json", json.dumps({"frames": [
                {"correction_mm": 1.0, "correction_deg": 0.5, "status": "ok"},
                {"correction_mm": 3.0, "correction_deg": 2.5, "status": "ok"},
                {"correction_mm": 2.0, "correction_deg": 1.0, "status": "rejected"}]}))
            write(out / "ok" / "views" / "render.json", "{}")
            write(out / "ok" / "flythrough" / "path.json", "{}")
            bench = "s\th:m:s\tmax_rss\tmax_vms\n2.50\t0:00:02\t100.0\t200.0\n"
            write(out / "ok" / "benchmarks" / "build.tsv", bench)
            write(out / "ok" / "benchmarks" / "render.tsv", bench.replace("100.0", "80.0"))
            write(out / "ok" / "logs" / "build.usage.json", json.dumps({"peak_rss_mb": 150.0, "wall_s": 2.4}))
            write(out / "failed" / "failed.json", json.dumps({"stage": "inspect", "error": "no CT"}))
            write(out / "killed" / "inspect.json", "{}")
            write(out / "killed" / "logs" / "build.log", "")

            rows = cs.summarise(cases, ["failed", "killed", "ok", "waiting"], out)
            self.assertEqual([r["status"] for r in rows], ["failed", "failed", "ok", "pending"])
            with open(out / "cohort.csv") as f:
                table = {r["case"]: r for r in csv.DictReader(f)}
            ok = table["ok"]
            self.assertEqual((ok["ct_dims"], ok["ct_spacing_mm"], ok["frames"]), ("10x20x30", "0.5x0.5x1.25", "3"))
            self.assertEqual((ok["airway_volume_ml"], ok["branches"]), ("12.5", "9"))
            self.assertEqual((ok["psnr_paper_db"], ok["psnr_calibrated_db"]), ("25.25", "27.5"))
            self.assertEqual((ok["pose_correction_mm_mean"], ok["pose_correction_mm_max"]), ("2", "3"))
            self.assertEqual((ok["pose_correction_deg_mean"], ok["pose_correction_deg_max"]), ("1.333", "2.5"))
            self.assertEqual(ok["pose_status"], "ok:2 rejected:1")
            self.assertEqual((ok["build_segment_s"], ok["build_total_s"]), ("1.5", "4"))
            # Wall time from the benchmark; peak from the kernel's record, else the benchmark's.
            self.assertEqual((ok["build_wall_s"], ok["build_peak_rss_mb"]), ("2.5", "150"))
            self.assertEqual(ok["render_peak_rss_mb"], "80")
            self.assertEqual(ok["peak_rss_mb"], "150")
            self.assertEqual((table["failed"]["failed_stage"], table["failed"]["error"]), ("inspect", "no CT"))
            self.assertEqual(table["killed"]["failed_stage"], "build")
            self.assertIn("interrupted", table["killed"]["error"])
            self.assertEqual((table["waiting"]["status"], table["waiting"]["failed_stage"]), ("pending", "inspect"))
            self.assertEqual(table["failed"]["pose_status"], "")
            page = (out / "cohort.html").read_text()
            self.assertIn("4 cases: 2 failed, 1 ok, 1 pending", page)
            self.assertEqual([p.name for p in out.iterdir() if "partial" in p.name], [])


if __name__ == "__main__":
    unittest.main()
