"""The first BO decision after the seed points, under the bluesky plan and under `noisebo run`, in
fresh processes: the example of docs/instruments/beamline.md (``examples/beamline/run_plan.py``:
a Forrester campaign through a RunEngine and the simulated IOC) against `noisebo run` of the same
config on the simulator.

    python benchmarks/first_decision.py [--repeats 3] [--json FILE]

Each way runs ``--repeats`` times with the compilation cache another process filled (a machine
that has run a campaign before: one run each way first, untimed), and ``--repeats`` times with a
new, empty cache (a first campaign on a new machine). The figure is the first decision's own time
(``/steps/latency_s`` of step 1: its fits, prediction and acquisition, with whatever compiling
they waited for), median and range. Target: the plan's first decision no slower than `noisebo
run`'s (within 25 % or 0.5 s, whichever is larger). Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
NOISEBO = str(Path(sys.executable).with_name("noisebo"))
EXAMPLE = ROOT / "examples" / "beamline" / "run_plan.py"


def example_config() -> dict:
    """The example's config, as it builds it (docs/instruments/beamline.md)."""
    from noisebo.config import load_config

    config = load_config(ROOT / "data" / "configs" / "forrester.yaml").with_overrides(
        space={"t_min": 0.005, "t_max": 0.2}, reward={"alpha": 1800.0}, schedule={"n_steps": 6}
    )
    return config.model_dump(mode="json")


def first_latency(path: Path) -> float:
    from noisebo.storage.record import read_record

    return float(read_record(path).steps.latency_s[0])


def under_plan(folder: Path, env: dict) -> float:
    out = folder / "plan.h5"
    subprocess.run([sys.executable, str(EXAMPLE), str(out)], cwd=ROOT, env=env, check=True, capture_output=True)
    return first_latency(out)


def under_run(folder: Path, env: dict, config: Path) -> float:
    subprocess.run(
        [NOISEBO, "run", str(config), "--no-rrd", "--out", str(folder)],
        cwd=ROOT,
        env=env,
        check=True,
        capture_output=True,
    )
    (path,) = folder.glob("*.h5")
    return first_latency(path)


def once(way: str, cache: Path, config: Path) -> float:
    env = dict(os.environ, NOISEBO_JAX_CACHE=str(cache))
    with tempfile.TemporaryDirectory() as folder:
        return under_plan(Path(folder), env) if way == "plan" else under_run(Path(folder), env, config)


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs each way and cache, default 3")
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)
    found: dict[str, dict[str, list[float]]] = {"filled": {}, "empty": {}}
    with tempfile.TemporaryDirectory() as work:
        work = Path(work)
        config = work / "example.yaml"
        config.write_text(yaml.safe_dump(example_config()))
        shared = work / "shared-cache"
        for way in ("plan", "run"):
            once(way, shared, config)  # fills the cache, untimed
        for way in ("plan", "run"):
            found["filled"][way] = [once(way, shared, config) for _ in range(args.repeats)]
            found["empty"][way] = [once(way, work / f"new-{way}-{k}", config) for k in range(args.repeats)]
    print(f"first decision's own time (s), median [range] of {args.repeats} fresh processes each:")
    print("| compilation cache | bluesky plan | `noisebo run` |\n|---|---|---|")
    for cache, label in (("filled", "filled by an earlier process"), ("empty", "new, empty")):
        print(f"| {label} | {spread(found[cache]['plan'])} | {spread(found[cache]['run'])} |")
    met = all(
        statistics.median(found[c]["plan"])
        <= max(1.25 * statistics.median(found[c]["run"]), statistics.median(found[c]["run"]) + 0.5)
        for c in found
    )
    print(f"target: the plan's first decision no slower than noisebo run's: {'met' if met else 'missed'}")
    if args.json:
        args.json.write_text(json.dumps(found, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
