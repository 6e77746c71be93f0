"""How long the commands an operator types take, from start to exit, in fresh processes.

    python benchmarks/cli.py [--repeats 5] [--json FILE]

Each command runs ``--repeats`` times as the installed ``noisebo`` script (a new interpreter each
time, as at the instrument's keyboard); the table gives the median and the range, and the target
of each. ``inspect`` reads a finished campaign made here first (``noisebo run``, Forrester);
``ask`` reads a campaign measured by hand (``noisebo start``) whose point is already decided;
``tell (decides)`` records the last shot of the last seed point, so the command also makes the
campaign's first decision, with the JAX compilation cache and the kept programs
(``noisebo.programs``) warm from the campaigns before it (each repeat is a fresh campaign brought
to that shot first, outside the timing); ``tell (decides, nothing kept)`` is the same with an empty
folder of kept programs, as on the first decision of its kind on a machine: it traces the programs
and keeps them. The refusals (exit 2, one line): ``inspect`` and ``report`` of the finished file
with a byte of its metadata flipped, ``report`` of an empty folder. Run it on an idle machine:
timings of whole processes move with the load.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOISEBO = str(Path(sys.executable).with_name("noisebo"))
FORRESTER = ROOT / "data" / "configs" / "forrester.yaml"
MANUAL = ROOT / "data" / "configs" / "forrester_manual.yaml"
TARGETS_S = {
    "--help": 0.3,
    "--version": 0.3,
    "instruments": None,
    "inspect": 1.0,
    "ask": 1.0,
    "tell (decides)": 2.0,
    "tell (decides, nothing kept)": None,
    "inspect (damaged file)": 1.0,
    "report (damaged file)": 1.0,
    "report (empty folder)": 1.0,
}


def noisebo(*args: str, cwd: Path, env: dict | None = None, code: int = 0) -> tuple[float, str]:
    """(seconds from start to exit, stdout) of one `noisebo ARGS` that must exit with ``code``, with
    ``env`` added to the environment."""
    start = time.perf_counter()
    done = subprocess.run(
        [NOISEBO, *args], cwd=cwd, capture_output=True, text=True, check=False, env={**os.environ, **(env or {})}
    )
    elapsed = time.perf_counter() - start
    if done.returncode != code:
        raise SystemExit(f"cli.py: `noisebo {' '.join(args)}` exited {done.returncode}: {done.stderr.strip()[-400:]}")
    return elapsed, done.stdout


def started(work: Path, name: str) -> Path:
    """A campaign measured by hand, created in work/name; its file."""
    noisebo("start", str(MANUAL), "--out", str(work / name), cwd=work)
    return next((work / name).glob("*.h5"))


def answer(path: Path, work: Path, keep_last: bool) -> None:
    """Tell the campaign every wanted shot of every seed point, all but the very last when
    ``keep_last``: the readings are the Forrester function's value plus a fixed offset."""
    while True:
        _, out = noisebo("ask", "--json", str(path), cwd=work)
        request = json.loads(out)
        if request.get("step", 0) > 0 or request["kind"] != "shot":
            return
        wanted = request["wanted"]
        last_seed_point = request["point"] == _seed_points() - 1
        n = wanted - 1 if keep_last and last_seed_point else wanted
        if n == 0:
            return
        x = request["x"][0]
        values = [f"{(6 * x - 2) ** 2 * math.sin(12 * x - 4) + 0.01 * k:.6f}" for k in range(n)]
        noisebo("tell", str(path), "--point", str(request["point"]), *values, cwd=work)
        if keep_last and last_seed_point:
            return


def damaged_copy(finished: Path, work: Path) -> Path:
    """A copy of ``finished`` with one byte of its root group's object header flipped."""
    import struct

    data = bytearray(finished.read_bytes())
    root = struct.unpack_from("<Q", data, 12 + 3 * 8)[0]  # superblock version 2/3, 8-byte addresses
    data[root + 24] ^= 0xFF
    (work / "damaged").mkdir()
    path = work / "damaged" / finished.name
    path.write_bytes(bytes(data))
    return path


def _seed_points() -> int:
    import yaml

    return int(yaml.safe_load(MANUAL.read_text())["schedule"]["n_seed"])


def timings(repeats: int) -> dict[str, list[float]]:
    work = Path(tempfile.mkdtemp(prefix="noisebo-cli-"))
    try:
        noisebo("run", str(FORRESTER), "--out", str(work / "runs"), "--no-rrd", cwd=work)  # also warms the JAX cache
        finished = next((work / "runs").glob("*.h5"))
        asked = started(work, "asked")
        damaged, empty = damaged_copy(finished, work), work / "empty"
        empty.mkdir()
        found: dict[str, list[float]] = {name: [] for name in TARGETS_S}
        for _ in range(repeats):
            found["--help"].append(noisebo("--help", cwd=work)[0])
            found["--version"].append(noisebo("--version", cwd=work)[0])
            found["instruments"].append(noisebo("instruments", cwd=work)[0])
            found["inspect"].append(noisebo("inspect", str(finished), cwd=work)[0])
            found["ask"].append(noisebo("ask", str(asked), cwd=work)[0])
            found["inspect (damaged file)"].append(noisebo("inspect", str(damaged), cwd=work, code=2)[0])
            found["report (damaged file)"].append(noisebo("report", str(damaged), cwd=work, code=2)[0])
            found["report (empty folder)"].append(noisebo("report", str(empty), cwd=work, code=2)[0])
        for i in range(repeats):
            for name, env in (
                ("tell (decides)", None),
                ("tell (decides, nothing kept)", {"NOISEBO_PROGRAM_CACHE": str(work / f"nothing-kept-{i}")}),
            ):
                path = started(work, f"told{i}-{len(found[name])}-{env is None}")
                answer(path, work, keep_last=True)
                request = json.loads(noisebo("ask", "--json", str(path), cwd=work)[1])
                found[name].append(
                    noisebo("tell", str(path), "--point", str(request["point"]), "1.0", cwd=work, env=env)[0]
                )
        return found
    finally:
        shutil.rmtree(work, ignore_errors=True)


def table(found: dict[str, list[float]]) -> str:
    lines = ["| command | median (s) | range (s) | target (s) | |", "|---|---|---|---|---|"]
    for name, values in found.items():
        median, target = statistics.median(values), TARGETS_S[name]
        verdict = "" if target is None else ("met" if median <= target else "missed")
        lines.append(
            f"| `{name}` | {median:.2f} | {min(values):.2f}-{max(values):.2f} | "
            f"{'-' if target is None else f'{target:g}'} | {verdict} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None, help="also write the timings here")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    if not Path(NOISEBO).exists():
        parser.error(f"no noisebo script beside {sys.executable}: install the package first")
    found = timings(args.repeats)
    print(f"noisebo commands, {args.repeats} runs each (fresh processes):\n")
    print(table(found))
    if args.json:
        args.json.write_text(json.dumps(found, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
