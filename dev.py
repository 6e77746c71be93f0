#!/usr/bin/env python3
"""Set up and use noisebo with nothing but Python 3.11+.

    python3 dev.py run [ARGS...]   # a default Forrester campaign through the Prefect flow, into
                                   # data/runs/<time>/ (extra ARGS go to `noisebo run`)
    python3 dev.py test [ARGS...]  # the test suite, on up to 4 cores (extra ARGS go to pytest; -n 0: one process)
    python3 dev.py bench [ARGS...] # the Forrester benchmark (extra ARGS go to benchmarks/forrester.py)
    python3 dev.py peers           # adds the budget benchmark's peers (gpCAM, BoTorch on PyTorch
                                   # 2.13.0) to .venv/, so that their tests run too (see docs/versions.md)

The first call creates .venv/ beside this file and installs the package with its pinned
dependencies; later calls reuse it, and reinstall only when pyproject.toml changes.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
STAMP = VENV / ".noisebo-installed"


def _say(message: str) -> None:
    print(f"[dev] {message}", file=sys.stderr, flush=True)


def ensure_environment() -> None:
    if sys.version_info < (3, 11):
        sys.exit(f"noisebo needs Python 3.11 or newer; this is {sys.version.split()[0]}")
    wanted = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if STAMP.exists() and STAMP.read_text() == wanted:
        return
    if not (BIN / "python").exists():
        _say(f"creating {VENV}")
        venv.EnvBuilder(with_pip=True).create(VENV)
    _say("installing noisebo and its dependencies (first run: a few minutes)")
    pip = [str(BIN / "python"), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["--upgrade", "pip"], check=True)
    subprocess.run(pip + ["-e", f"{ROOT}[test,docs]"], check=True, cwd=ROOT)
    STAMP.write_text(wanted)


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("TQDM_DISABLE", "1")
    env.setdefault("DO_NOT_TRACK", "1")
    return env


def parallel(pytest_args: list[str]) -> list[str]:
    """pytest-xdist options: one worker per core up to 4 (each test file stays on one worker, so
    module fixtures run once; the files in the order tests/conftest.py gives them, the longest
    first), unless the arguments choose (-n, --numprocesses, -p no:xdist)."""
    chosen = any(a == "-n" or a.startswith(("-n", "--numprocesses")) or a == "no:xdist" for a in pytest_args)
    workers = str(max(1, min(4, os.cpu_count() or 1)))
    return [] if chosen else ["-n", workers, "--dist", "loadfile", "--no-loadscope-reorder"]


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in {"run", "test", "bench", "peers"}:
        print(__doc__, file=sys.stderr)
        return 2
    command, rest = argv[0], argv[1:]
    ensure_environment()
    python = str(BIN / "python")
    if command == "run":
        args = [str(BIN / "noisebo"), "run", str(ROOT / "data" / "configs" / "forrester.yaml"), *rest]
        if "--out" not in rest:  # a fresh folder per call, so the command can be repeated
            stamp = time.strftime("%Y%m%d-%H%M%S")
            args += ["--out", str(ROOT / "data" / "runs" / stamp)]
    elif command == "peers":
        _say("installing the peers: gpCAM, BoTorch and PyTorch (see docs/versions.md for its size)")
        args = [python, "-m", "pip", "install", "--disable-pip-version-check", "-q", "-e", f"{ROOT}[peers]", *rest]
    elif command == "test":
        args = [python, "-m", "pytest", *parallel(rest), *rest]
    else:
        args = [python, str(ROOT / "benchmarks" / "forrester.py"), *rest]
    return subprocess.run(args, cwd=ROOT, env=environment()).returncode


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
