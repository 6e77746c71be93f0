"""How long `noisebo run` takes to its first measured point, and where the time goes.

    python benchmarks/startup.py [--repeats 5] [--config PATH] [--json FILE]

Runs the default campaign (``noisebo run data/configs/forrester.yaml --no-rrd``, Prefect's
temporary server) ``--repeats`` times in fresh processes, twice over: with a Prefect home used
before (its database made and migrated by a first run outside the timing), and with a new, empty
one each time (as on a new machine or a new checkout: the server makes its database first). JAX's
compilation cache is the checkout's in both. For each run it times, from the command's start,
the lines the command prints: the campaign line (the config checked), the first seed point, the
first BO step (the first decision, which compiles or loads the models) and the exit; the table
gives the median and range of each. A third series, with the Prefect home used before, starts the
server only when the flow needs it (``flows.server_launch.launched`` made a no-op in the command's
process), as `noisebo run` did before it started the server early: what starting it early saves.
Run it on an idle machine: whole processes move with the load.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOISEBO = str(Path(sys.executable).with_name("noisebo"))
MARKS = {  # what is timed: the first line that starts with this
    "config checked": "campaign ",
    "first point": "seed point:",
    "first decision": "step 1/",
}
TARGET_FIRST_POINT_S = 5.0


LATE_SERVER = """
import contextlib, sys
from noisebo.flows import server_launch
server_launch.launched = contextlib.nullcontext
from noisebo.cli.main import main
sys.argv[0] = "noisebo"
raise SystemExit(main())
"""


def timed_run(config: Path, out: Path, env: dict, late_server: bool = False) -> dict[str, float]:
    """Seconds from the start of one `noisebo run` to each of ``MARKS`` and to its exit; with
    ``late_server`` the temporary server starts only when the flow needs it."""
    start = time.perf_counter()
    command = [sys.executable, "-c", LATE_SERVER] if late_server else [NOISEBO]
    process = subprocess.Popen(
        [*command, "run", str(config), "--no-rrd", "--out", str(out)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    seen: dict[str, float] = {}
    assert process.stdout is not None
    for line in process.stdout:
        for name, prefix in MARKS.items():
            if name not in seen and line.startswith(prefix):
                seen[name] = time.perf_counter() - start
    errors = process.stderr.read() if process.stderr else ""
    if process.wait() != 0:
        raise SystemExit(f"noisebo run failed (exit {process.returncode}):\n{errors[-3000:]}")
    seen["exit"] = time.perf_counter() - start
    missing = [name for name in MARKS if name not in seen]
    if missing:
        raise SystemExit(f"noisebo run printed no line for: {', '.join(missing)}")
    return seen


def series(config: Path, repeats: int, fresh_home: bool, folder: Path, late_server: bool = False) -> list:
    runs = []
    home = folder / "prefect-home-used"
    if not fresh_home and not home.exists():  # made and migrated once, outside the timing
        timed_run(config, folder / "warm-up", {**os.environ, "PREFECT_HOME": str(home)})
    for i in range(repeats):
        if fresh_home:
            home = folder / f"prefect-home-new-{i}"
        out = folder / f"run-{fresh_home}-{late_server}-{i}"
        runs.append(timed_run(config, out, {**os.environ, "PREFECT_HOME": str(home)}, late_server))
        print(f"  {'new' if fresh_home else 'used'} Prefect home, run {i + 1}: {runs[-1]}", file=sys.stderr)
    return runs


def table(results: dict[str, list[dict[str, float]]], repeats: int) -> str:
    names = [*MARKS, "exit"]
    lines = [
        f"`noisebo run` of the default campaign, {repeats} runs each (fresh processes); seconds from the "
        "command's start, median [range]:",
        "",
        "| Prefect home | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for home, runs in results.items():
        cells = []
        for name in names:
            values = [run[name] for run in runs]
            cells.append(f"{statistics.median(values):.1f} [{min(values):.1f}-{max(values):.1f}]")
        lines.append(f"| {home} | " + " | ".join(cells) + " |")
    used = statistics.median(run["first point"] for run in results["used before"])
    verdict = "met" if used <= TARGET_FIRST_POINT_S else "missed"
    lines += ["", f"target: first point within {TARGET_FIRST_POINT_S:g} s with a Prefect home used before: {verdict}"]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--config", type=Path, default=ROOT / "data" / "configs" / "forrester.yaml")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="noisebo-startup-") as folder:
        results = {
            "used before": series(args.config, args.repeats, False, Path(folder)),
            "new": series(args.config, args.repeats, True, Path(folder)),
            "used before, server started late": series(args.config, args.repeats, False, Path(folder), True),
        }
    print(table(results, args.repeats))
    if args.json:
        args.json.write_text(json.dumps({"repeats": args.repeats, "runs": results}, indent=1))


if __name__ == "__main__":
    main()
