"""A long campaign through `noisebo run`: decision, orchestration and storage time per point as
it grows.

    python benchmarks/long_campaign.py [--points 1000] [--config PATH] [--window 100] [--no-rrd] [--json PATH]
                                       [--reports on|off|both]

Runs `noisebo run` (the Prefect flow with its temporary server, the journal, the HDF5 file and
the Rerun recording, exactly as a user runs it) on the config with as many BO steps as make
``--points`` points, and timestamps each progress line as it arrives. Per BO point, the time
between its line and the previous one is the decision (its ``latency_s`` in the file) plus the
instrument (the simulator's shots, measured here on their own) plus everything else: Prefect's
tasks, the engine, the journal (one fsync per shot), the HDF5 append and the live recording.
The table gives, per window of points, the median and maximum of that last part and the median
decision, and the file's bytes per point. ``--reports both`` runs the campaign twice, back to
back: without the flow run's Prefect reports (NOISEBO_PREFECT_REPORTS=0: no run name, tags, log
lines, artifacts or events) and with them, and prints a table for each.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]

STEP_LINE = re.compile(r"^step (\d+)/\d+:")


def timed_lines(command: list[str], env: dict) -> tuple[list[tuple[float, str]], int]:
    """Each stdout line of ``command`` with the time (s, from start) it arrived, and the exit code."""
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env, cwd=ROOT)
    lines = [(time.perf_counter() - started, line.rstrip("\n")) for line in process.stdout]
    return lines, process.wait()


def shot_seconds(config, file) -> np.ndarray:
    """What the simulated instrument itself took for each BO point's shots (s), re-run here."""
    from noisebo.instruments import build
    from noisebo.keys import MEASURE, numpy_rng

    instrument = build(config.instrument)
    shots, points = file.shots, file.points
    out = []
    for i in np.flatnonzero(points.step >= 1):  # BO points (seed points: step 0)
        started = time.perf_counter()
        for k in range(int(np.sum(shots.point == i))):
            instrument.simulate(np.array([points.x[i]]), float(points.t[i]), numpy_rng(0, MEASURE, int(i), k))
        out.append(time.perf_counter() - started)
    return np.asarray(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1000)
    parser.add_argument("--config", default=str(ROOT / "data/configs/forrester.yaml"))
    parser.add_argument("--window", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-rrd", action="store_true", help="without the Rerun recording")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument(
        "--reports",
        choices=["on", "off", "both"],
        default="on",
        help="the flow run's Prefect reports (names, logs, artifacts, events)",
    )
    args = parser.parse_args(argv)
    results = {}
    for mode in ["off", "on"] if args.reports == "both" else [args.reports]:
        print(f"\nPrefect reports {mode}:")
        results[mode] = one_run(args, mode)
        if results[mode] is None:
            return 1
    if args.json:
        args.json.write_text(json.dumps(results if args.reports == "both" else results[args.reports], indent=1))
    return 0


def one_run(args, reports: str) -> dict | None:

    from noisebo.config import load_config
    from noisebo.storage.record import read_record

    base = load_config(args.config)
    config = base.with_overrides(name="long", schedule={"n_steps": args.points - base.schedule.n_seed})
    work = Path(tempfile.mkdtemp(prefix="noisebo-long-"))
    config_path = work / "long.yaml"
    config_path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "NOISEBO_PREFECT_REPORTS": "1" if reports == "on" else "0"}
    env.pop("PREFECT_API_URL", None)
    lines, code = timed_lines(
        [
            sys.executable,
            "-m",
            "noisebo.cli.main",
            "run",
            str(config_path),
            "--seed",
            str(args.seed),
            "--out",
            str(work),
            *(["--no-rrd"] if args.no_rrd else []),
        ],
        env,
    )
    if code != 0:
        print(f"noisebo run failed (exit {code}); last lines:\n" + "\n".join(line for _, line in lines[-5:]))
        return None
    path = next(work.glob("*.h5"))
    file = read_record(path)
    at = {int(m.group(1)): t for t, line in lines if (m := STEP_LINE.match(line))}
    latency = file.steps.latency_s
    instrument = shot_seconds(config, file)
    rows = []
    for step in sorted(at):
        if step - 1 not in at:
            continue
        gap = at[step] - at[step - 1]
        k = step - 1  # 0-based BO step of this point
        rows.append(
            {
                "n": base.schedule.n_seed + k,
                "gap_s": gap,
                "decision_s": float(latency[k]),
                "instrument_s": float(instrument[k]),
                "rest_s": gap - float(latency[k]) - float(instrument[k]),
            }
        )
    size = path.stat().st_size
    print(
        f"noisebo run{' --no-rrd' if args.no_rrd else ''} on {Path(args.config).name} to {args.points} points "
        f"({path.name}: {size / 2**20:.1f} MiB, {size / args.points / 1024:.1f} KiB per point, finished layout)"
    )
    print(f"{'points':>11} {'decision':>9} {'other, median':>14} {'other, max':>11} {'gap, median':>12}")
    summary = []
    for lo in range(0, args.points, args.window):
        window = [r for r in rows if lo < r["n"] + 1 <= lo + args.window]
        if not window:
            continue
        row = {
            "points": f"{lo + 1}-{lo + args.window}",
            "decision_s": statistics.median(r["decision_s"] for r in window),
            "other_median_s": statistics.median(r["rest_s"] for r in window),
            "other_max_s": max(r["rest_s"] for r in window),
            "gap_median_s": statistics.median(r["gap_s"] for r in window),
        }
        summary.append(row)
        print(
            f"{row['points']:>11} {row['decision_s']:>8.3f}s {1e3 * row['other_median_s']:>12.1f}ms "
            f"{1e3 * row['other_max_s']:>9.1f}ms {row['gap_median_s']:>11.3f}s"
        )
    os.environ.get("KEEP") or __import__("shutil").rmtree(work, ignore_errors=True)
    return {"summary": summary, "points": rows}


if __name__ == "__main__":
    raise SystemExit(main())
