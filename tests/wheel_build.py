"""The wheel of the checkout as it stands, built outside it (tests/test_wheel.py, tests/e2e)."""

from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_wheel(out: Path) -> Path:
    """The wheel of the checkout's files as git tracks them (and new files not ignored), built in a
    copy under ``out`` so the build leaves nothing (no build/ folder) in the checkout; its path."""
    import subprocess
    import sys

    listed = (
        subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        .stdout.decode()
        .split("\0")
    )
    source = out / "source"
    for name in filter(None, listed):
        path = ROOT / name
        if path.is_symlink():  # noisebo/flows -> ../flows: the link itself, as git keeps it
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            (source / name).symlink_to(path.readlink())
        elif path.is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, source / name)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--disable-pip-version-check",
            str(source),
            "-w",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=600,
        cwd=out,
    )
    shutil.rmtree(source)
    (wheel,) = out.glob("noisebo-*.whl")
    return wheel
