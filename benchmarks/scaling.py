"""How a decision scales with the number of points a campaign holds.

    python benchmarks/scaling.py [--n 20,100,200,500,1000] [--repeats 3] [--mode map|nuts] [--config PATH]

For each n, a fresh process builds a campaign state of n Forrester points (x uniform, t
log-uniform over the config's range, 30 shots each, noise drawn from the simulator's law) and
calls ``noisebo.decision.decide`` on it: the first call (it compiles), then ``--repeats`` more
(other steps, so other keys). It prints the first call's time, the median of the others, the
XLA compilations of the first call and of the later ones, and the process's peak memory
(resident set). Each n runs alone, so one size's memory and caches do not reach the next.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SHOTS = 30


def state_of(config, n: int, seed: int = 0):
    """A campaign state of n measured Forrester points (noise from the simulator's law)."""
    import numpy as np

    from instruments import build
    from instruments.registry import validated
    from noisebo.state import CampaignState, Point

    simulator = build(validated(config).instrument)
    rng = np.random.default_rng(seed)
    s = config.space
    x = rng.uniform(s.x_min, s.x_max, n)
    t = np.exp(rng.uniform(np.log(s.t_min), np.log(s.t_max), n))
    sd = simulator.noise_law(t)
    truth = simulator.truth(x[:, None])
    state = CampaignState()
    for i in range(n):
        shots = truth[i] + sd[i] * rng.standard_normal(SHOTS)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(float(x[i]), float(t[i]), float(shots.mean()), std, SHOTS, std, True))
    return state


def one_size(config_path: str, n: int, repeats: int, mode: str) -> dict:
    """The figures of one n, in this process."""
    import jax

    from noisebo.config import load_config
    from noisebo.decision import decide

    compiles = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, duration, **kw: compiles.append(duration) if event.endswith("backend_compile_duration") else None)
    config = load_config(config_path).with_overrides(inference={"mode": mode})
    state = state_of(config, n)
    started = time.perf_counter()
    decide(config, state, 0, 0)
    first, first_compiles = time.perf_counter() - started, len(compiles)
    times = []
    for step in range(1, repeats + 1):
        started = time.perf_counter()
        decide(config, state, 0, step)
        times.append(time.perf_counter() - started)
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"n": n, "mode": mode, "first_s": first, "median_s": statistics.median(times), "times_s": times,
            "compiles_first": first_compiles, "compiles_later": len(compiles) - first_compiles,
            "peak_gb": peak_kib / 2**20}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", default="20,100,200,500,1000", help="comma-separated numbers of points")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mode", choices=["map", "nuts"], default="map")
    parser.add_argument("--config", default=str(ROOT / "data/configs/forrester.yaml"))
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(one_size(args.config, args.one, args.repeats, args.mode)))
        return 0
    print(f"decide() on a state of n points ({args.mode}, {Path(args.config).name}); median of {args.repeats} calls "
          "after the first", flush=True)
    print(f"{'n':>6} {'decision':>10} {'vs first n':>10} {'first call':>11} {'compiles':>9} {'later':>6} {'peak':>8}",
          flush=True)
    rows, base = [], None
    for n in (int(v) for v in args.n.split(",")):
        done = subprocess.run([sys.executable, __file__, "--one", str(n), "--repeats", str(args.repeats), "--mode",
                               args.mode, "--config", args.config], capture_output=True, text=True, check=False,
                              env={**os.environ, "PYTHONWARNINGS": "ignore"})
        if done.returncode != 0:
            print(f"{n:>6} failed: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}")
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1])
        rows.append(row)
        base = base or row["median_s"]
        print(f"{n:>6} {row['median_s']:>9.3f}s {row['median_s'] / base:>10.1f} {row['first_s']:>10.1f}s "
              f"{row['compiles_first']:>9} {row['compiles_later']:>6} {row['peak_gb']:>6.2f}GB", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
