"""How a decision scales with the number of points a campaign holds.

    python benchmarks/scaling.py [--n 20,100,...,5000] [--repeats 5] [--mode map|nuts]
                                 [--design grid|distinct] [--config PATH] [--json PATH]

For each n, a fresh process builds a campaign state of n Forrester points (30 shots each, noise
drawn from the simulator's law) and calls ``noisebo.campaign.decision.decide`` on it: the first call (it
compiles; a multi-start fit), then ``--repeats`` warm calls (steps that start from the previous
fit, as 7 steps in 8 do once the noise model has converged; the state says it has) and one
multi-start call (every ``inference.restart_every``-th step, and every step before convergence). It prints the first call's time, the median warm call, the multi-start call, the XLA
compilations of the first call and of all later ones, the distinct inputs (or bins) each GP was
fitted on, and the process's peak memory (resident set). Each n runs alone, so one size's memory
and caches do not reach the next.

Designs: "grid" puts x and t on the config's candidate grids, where a campaign's proposals lie
(its 3 random seed points aside); "distinct" draws x uniformly and t log-uniformly, every point
at an input of its own: the worst case, where beyond ``inference.max_inputs`` the GPs bin.

    python benchmarks/scaling.py --crossing

measures what crossing a padding capacity costs instead: a decision on 32 distinct inputs, then
one on 33 (both GPs: capacity 32 -> 64), in line and after ``decision.compile_ahead``.

    python benchmarks/scaling.py --cold

times `noisebo run` from its start to its first BO point, on an empty compilation cache and
again with the cache the first run left, with Prefect's temporary server and with a running one.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

SHOTS = 30


def state_of(config, n: int, design: str = "grid", seed: int = 0):
    """A campaign state of n points measured on the config's simulator (noise from its law;
    value: mean of 30 Gaussian shots about its truth, which for PFM skips the sweeps' SHO fits)."""
    import numpy as np

    from noisebo.instruments import build
    from noisebo.instruments.registry import validated
    from noisebo.models.grids import grids
    from noisebo.state import CampaignState, Point

    simulator = build(validated(config).instrument)
    rng = np.random.default_rng(seed)
    s = config.space
    g = grids(config)
    if design == "grid" and s.dimensions == 1:
        x, t = rng.choice(g.x, n)[:, None], rng.choice(g.t, n)
    elif design == "grid":  # proposals lie off the reference points in d > 1: draw x anywhere, t on its grid
        x, t = rng.uniform(s.lows, s.highs, (n, s.dimensions)), rng.choice(g.t, n)
    else:
        x = rng.uniform(s.lows, s.highs, (n, s.dimensions))
        t = np.exp(rng.uniform(np.log(s.t_min), np.log(s.t_max), n))
    sd = simulator.noise_law(t)
    truth = simulator.truth(x)
    points = []
    for i in range(n):
        shots = truth[i] + sd[i] * rng.standard_normal(SHOTS)
        std = float(shots.std(ddof=1))
        points.append(Point(tuple(x[i]), float(t[i]), float(shots.mean()), std, SHOTS, std, True))
    # A long campaign is past its noise model's convergence (its warm steps start from the
    # previous fit; before convergence every step multi-starts).
    return CampaignState(points=tuple(points), t_opt_history=(2.5, 2.5, 2.5), converged_step=2)


def _compile_counter():
    import jax

    compiles = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, duration, **kw: compiles.append(duration) if event.endswith("backend_compile_duration") else None
    )
    return compiles


def _timed(fn, *args):
    started = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - started


def one_size(config_path: str, n: int, repeats: int, mode: str, design: str) -> dict:
    """The figures of one n, in this process."""
    from noisebo.campaign.decision import decide
    from noisebo.config import load_config

    compiles = _compile_counter()
    config = load_config(config_path).with_overrides(inference={"mode": mode})
    state = state_of(config, n, design)
    (first, _), first_s = _timed(decide, config, state, 0, 0)
    first_compiles = len(compiles)
    every = config.inference.restart_every
    warm_steps = [step for step in range(1, repeats + every) if step % every][:repeats]
    times = [_timed(decide, config, state, 0, step, first.hyperparameters)[1] for step in warm_steps]
    (_, _), restart_s = _timed(decide, config, state, 0, every, first.hyperparameters)
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "n": n,
        "mode": mode,
        "design": design,
        "first_s": first_s,
        "median_s": statistics.median(times),
        "times_s": times,
        "restart_s": restart_s,
        "compiles_first": first_compiles,
        "compiles_later": len(compiles) - first_compiles,
        "primary_inputs": first.primary_inputs,
        "noise_inputs": first.noise_inputs,
        "binned": first.binned,
        "peak_gb": peak_kib / 2**20,
    }


def crossing(config_path: str) -> dict:
    """Seconds of the decision that crosses capacity 32 -> 64, in line and compiled ahead."""
    from noisebo.campaign.compile_ahead import capacities_ahead, compile_ahead
    from noisebo.campaign.decision import decide
    from noisebo.config import load_config

    compiles = _compile_counter()
    out = {}
    for name, lengths in (("in_line", 0.2), ("compiled_ahead", 0.3)):
        # Each variant its own priors, so neither finds the other's programs compiled.
        config = load_config(config_path).with_overrides(primary_model={"length_loc": float(np.log(lengths))})
        state = state_of(config, 60, "distinct", seed=1)
        before = type(state)(points=state.points[:32])
        first, _ = decide(config, before, 0, 0)
        if name == "compiled_ahead":
            (_, ahead_s) = _timed(compile_ahead, config, before, first.hyperparameters, capacities_ahead(config, first))
            out["compile_ahead_s"] = ahead_s
        count = len(compiles)
        (crossed, _), seconds = _timed(
            decide, config, type(state)(points=state.points[:33]), 0, 1, first.hyperparameters
        )
        assert capacities_ahead(config, first) == (64, 64) and crossed.primary_inputs == crossed.noise_inputs == 33
        out[name] = {"seconds": seconds, "compiles": len(compiles) - count}
    return out


def cold_starts(config_path: str) -> list[dict]:
    """Seconds from starting `noisebo run` to its first BO point (the first decision made and
    its point measured), twice on an empty compilation cache (the second run loads what the
    first compiled), with Prefect's temporary server and with a running Prefect server."""
    import tempfile

    import yaml

    from noisebo.flows.processes import local_server
    from noisebo.config import load_config

    work = Path(tempfile.mkdtemp(prefix="noisebo-cold-"))
    config = load_config(config_path).with_overrides(name="cold", schedule={"n_steps": 1})
    path = work / "cold.yaml"
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    rows = []

    def run_twice(server: str, env: dict) -> None:
        env = {**env, "NOISEBO_JAX_CACHE": str(work / f"jax-{server}"), "PYTHONUNBUFFERED": "1"}
        for run in ("first run", "cache warm"):
            started = time.perf_counter()
            process = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "noisebo.cli.main",
                    "run",
                    str(path),
                    "--out",
                    str(work / f"{server}-{run}"),
                    "--no-rrd",
                ],
                cwd=ROOT,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            first = next((time.perf_counter() - started for line in process.stdout if line.startswith("step 1/")), None)
            process.wait()
            rows.append({"server": server, "run": run, "first_point_s": first, "exit": process.returncode})

    base = {k: v for k, v in os.environ.items() if k != "PREFECT_API_URL"}
    run_twice("temporary", base)
    with local_server(work / "prefect") as env:
        run_twice("running", {**base, **env})
    return rows


def _run_alone(args, *extra) -> dict | str:
    done = subprocess.run(
        [sys.executable, __file__, "--config", args.config, *extra],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    if done.returncode != 0:
        return done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"exit {done.returncode}"
    return json.loads(done.stdout.strip().splitlines()[-1])


def _inputs(row: dict) -> str:
    return f"{row['primary_inputs']}/{row['noise_inputs']}{' bins' if row['binned'] else ''}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", default="20,100,200,500,1000,2000,5000", help="comma-separated numbers of points")
    parser.add_argument("--repeats", type=int, default=5, help="warm calls per n")
    parser.add_argument("--mode", choices=["map", "nuts"], default="map")
    parser.add_argument("--design", choices=["grid", "distinct"], default="grid")
    parser.add_argument("--config", default=str(ROOT / "data/configs/forrester.yaml"))
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--crossing", action="store_true", help="measure crossing a padding capacity instead")
    parser.add_argument("--cold", action="store_true", help="measure `noisebo run` to its first decision instead")
    parser.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--crossing-one", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(one_size(args.config, args.one, args.repeats, args.mode, args.design)))
        return 0
    if args.crossing_one:
        print(json.dumps(crossing(args.config)))
        return 0
    if args.cold:
        print("seconds from `noisebo run` to its first BO point (forrester, map, simulated shots):")
        rows = cold_starts(args.config)
        for row in rows:
            first = "failed" if row["first_point_s"] is None else f"{row['first_point_s']:6.1f} s"
            print(f"  Prefect server {row['server']:<10} {row['run']:<11} {first}")
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        return 0
    if args.crossing:
        out = _run_alone(args, "--crossing-one")
        if isinstance(out, str):
            print(f"failed: {out}")
            return 1
        print("the decision that crosses capacity 32 -> 64 (both GPs), forrester, map:")
        for name in ("in_line", "compiled_ahead"):
            print(f"  {name:<15} {out[name]['seconds']:6.2f} s  {out[name]['compiles']:3} compilations")
        print(
            f"  compiling ahead took {out['compile_ahead_s']:.2f} s (a background thread, while the instrument measures)"
        )
        if args.json:
            args.json.write_text(json.dumps(out, indent=1))
        return 0
    print(
        f"decide() on a state of n points ({args.mode}, {args.design} design, {Path(args.config).name}); warm: "
        f"median of {args.repeats} steps from the previous fit; multi-start: one step of restarts",
        flush=True,
    )
    print(
        f"{'n':>6} {'warm':>9} {'vs first n':>10} {'multi-start':>11} {'first call':>10} {'compiles':>9} "
        f"{'later':>6} {'inputs x/t':>14} {'peak':>7}",
        flush=True,
    )
    rows, base = [], None
    for n in (int(v) for v in args.n.split(",")):
        row = _run_alone(
            args, "--one", str(n), "--repeats", str(args.repeats), "--mode", args.mode, "--design", args.design
        )
        if isinstance(row, str):
            print(f"{n:>6} failed: {row}", flush=True)
            continue
        rows.append(row)
        base = base or row["median_s"]
        print(
            f"{n:>6} {row['median_s']:>8.3f}s {row['median_s'] / base:>10.1f} {row['restart_s']:>10.2f}s "
            f"{row['first_s']:>9.1f}s {row['compiles_first']:>9} {row['compiles_later']:>6} {_inputs(row):>14} "
            f"{row['peak_gb']:>5.2f}GB",
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
