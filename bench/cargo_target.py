"""Where the comparison scripts find bronchosim's release examples: the repository's own target
folder, or $CARGO_TARGET_DIR, as cargo itself resolves it (`cargo metadata`), never a fixed path."""
import functools
import json
import pathlib
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[1]


@functools.lru_cache(maxsize=None)
def target_dir() -> pathlib.Path:
    """Cargo's target folder for this repository (honours CARGO_TARGET_DIR and .cargo/config)."""
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=ROOT,
                          capture_output=True, text=True, check=True).stdout
    return pathlib.Path(json.loads(meta)["target_directory"])


def example(*names: str) -> list:
    """Build the named examples in release (a no-op when up to date); their executables."""
    args = ["cargo", "build", "--release", "--quiet"]
    for n in names:
        args += ["--example", n]
    subprocess.run(args, cwd=ROOT, check=True)
    return [target_dir() / "release" / "examples" / n for n in names]
