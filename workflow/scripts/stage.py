#!/usr/bin/env python3
"""Run one bronchosim stage of one case for the cohort workflow (workflow/Snakefile).

    stage.py --stage NAME --case-out DIR --log FILE --fingerprint TEXT [--threads N]
             [--stdout FILE] [--output-dir DIR] -- COMMAND [ARGS...]

The command's stderr goes to the log. On success its stdout (with --stdout) is moved into
place atomically and any failure record of the case is removed. On failure the case's
failure record DIR/failed.json is written atomically (stage, the one-line error, exit status,
fingerprint) and the command's exit status is returned, so Snakemake sees the job fail, keeps
the log, deletes nothing that looks done, and the cohort summary finds the error. A command
stopped from outside (SIGINT, SIGTERM, SIGHUP) leaves no record: that is not the case's failure.

The failure record is not a rule output: Snakemake never takes a failed case for done. The
Snakefile reads it only to leave an unchanged failed case alone on the next run.
"""
import argparse
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FAILURE_RECORD = "failed.json"
INTERRUPTS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}


def write_atomic(path: Path, text: str) -> None:
    """Write `text` to a temporary file beside `path` and rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def error_line(log: Path, returncode: int) -> str:
    """The command's one-line error: its last `error:` line, else its last line, else the exit."""
    lines = []
    if log.exists():
        lines = [l.strip() for l in log.read_text(errors="replace").splitlines() if l.strip()]
    errors = [l for l in lines if l.startswith("error:")]
    if errors:
        return errors[-1][len("error:"):].strip()
    if returncode < 0:
        return f"killed by signal {signal.Signals(-returncode).name}"
    if lines:
        return lines[-1]
    return f"exit status {returncode} with no message"


def remove_partials(output_dir: Path) -> None:
    """Remove staging folders a killed earlier attempt left beside `output_dir`.

    bronchosim writes `.NAME.partial-XXXX` and renames it to NAME when complete; a SIGKILL
    (out of memory, wall-time limit) leaves it behind. Snakemake runs one job per output, so no
    other process is writing there now.
    """
    parent = output_dir.parent
    if parent.is_dir():
        for p in parent.glob(f".{output_dir.name}.partial-*"):
            shutil.rmtree(p, ignore_errors=True)


def write_usage(path: Path, wall_s: float, rc: int) -> None:
    """The command's wall time and the kernel's exact peak resident memory of it (Snakemake's
    benchmark samples memory every 0.5 s, then every 30 s, and can miss a short peak)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    record = {
        "exit_status": rc,
        "wall_s": wall_s,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        # ru_maxrss: KiB on Linux; the largest process among the waited-for descendants.
        "peak_rss_mb": usage.ru_maxrss / 1024.0,
    }
    write_atomic(path, json.dumps(record, indent=2) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stage", required=True)
    ap.add_argument("--case-out", required=True, type=Path, help="out/<case>")
    ap.add_argument("--log", required=True, type=Path)
    ap.add_argument("--fingerprint", required=True, help="what the failure is valid for")
    ap.add_argument("--threads", type=int, default=0, help="RAYON_NUM_THREADS (0: leave)")
    ap.add_argument("--stdout", type=Path, help="file to receive the command's stdout")
    ap.add_argument("--output-dir", type=Path, help="the folder bronchosim writes atomically")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        ap.error("no command after --")

    env = dict(os.environ)
    if args.threads > 0:
        env["RAYON_NUM_THREADS"] = str(args.threads)
    if args.output_dir is not None:
        remove_partials(args.output_dir)
    args.log.parent.mkdir(parents=True, exist_ok=True)
    record = args.case_out / FAILURE_RECORD

    stdout_tmp = None
    with open(args.log, "w") as log:
        if args.stdout is not None:
            args.stdout.parent.mkdir(parents=True, exist_ok=True)
            fd, stdout_tmp = tempfile.mkstemp(
                prefix=f".{args.stdout.name}.", suffix=".partial", dir=args.stdout.parent
            )
            out = os.fdopen(fd, "w")
        else:
            out = log
        start = time.monotonic()
        try:
            rc = subprocess.run(command, stdout=out, stderr=log, env=env).returncode
        except OSError as e:  # the binary itself could not be started
            log.write(f"error: {command[0]}: {e.strerror}\n")
            rc = 127
        finally:
            if out is not log:
                out.close()

    write_usage(args.log.with_suffix(".usage.json"), time.monotonic() - start, rc)
    if rc == 0:
        if stdout_tmp is not None:
            os.replace(stdout_tmp, args.stdout)
        record.unlink(missing_ok=True)
        return 0

    if stdout_tmp is not None:
        Path(stdout_tmp).unlink(missing_ok=True)
    if -rc in INTERRUPTS:
        # Stopped from outside (Ctrl-C, Snakemake or the scheduler cancelling): not the case's
        # failure, so no record; the next run tries again.
        print(f"{args.case_out.name}: {args.stage} interrupted", file=sys.stderr)
        return 128 - rc
    failure = {
        "stage": args.stage,
        "error": error_line(args.log, rc),
        "exit_status": rc,
        "log": os.path.relpath(args.log, args.case_out),
        "fingerprint": args.fingerprint,
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    write_atomic(record, json.dumps(failure, indent=2) + "\n")
    print(f"{args.case_out.name}: {args.stage} failed: {failure['error']}", file=sys.stderr)
    return rc if rc > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
