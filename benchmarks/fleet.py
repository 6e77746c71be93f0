"""Several instruments on one campaign: wall time to a target error against the number of
instruments, and against as many independent campaigns.

    python benchmarks/fleet.py [--config PATH] [--budget S] [--overhead S] [--shot-overhead S]
                               [--decision-s S] [--k 1,2,4] [--designs fleet,independent,botorch]
                               [--seeds 20] [--target R]
                               [--json PATH] [--figure PATH] [--report]

Every campaign spends the instrument-time budget --budget (all its instruments together; default
the config's ``schedule.budget_s``) in the budget mode (``schedule.mode: budget``: every point
takes ``shots_after`` shots and teaches the noise model; the config's policy), with no step
limit, on simulated instruments of the config's instrument, in simulated time
(``noisebo.campaign.fleet``): a shot lasts its t plus --shot-overhead (read-out), a point's first
shot also --overhead (``schedule.point_overhead_s``: moving the tip or stage), and a decision
--decision-s on the one decider, whichever instrument asked. The designs, for each k in --k:

- "fleet k=K": one campaign, K instruments; a decision takes the points in flight on the other
  instruments as pending (``noisebo.models.pending``: the kriging believer);
- "independent k=K" (K > 1): K campaigns of one instrument each, budget/K each, their seeds
  seed*1000 + j: what a lab runs today. Their points are pooled: at each checkpoint the error is
  that of one model fitted to every point all K campaigns have committed by then (the same
  final models a campaign gives, ``summarize``), which is more than any one of them knows;
- "botorch k=K": BoTorch's cost-aware design of the budget benchmark on one campaign of K
  instruments, the points in flight on the others as its pending points
  (``benchmarks/_botorch_fleet.py``; needs ``noisebo[peers]``).

A fleet campaign is scored after every decision (the GP mean it was made with, on the x grid
against the simulator's truth, 200 positions for one axis) at the wall time it was made and the
instrument time spent by then, and at the end its final model; an independent design at 24
evenly spaced wall times up to its end. The report gives per design the median wall time to first
reach --target (default 2 % of the range of the true f over the x grid) and its ratio to k=1's
(BoTorch's own k=1 for BoTorch's rows; a seed that never reaches it counts as never: "-" where
half of them do not), the median RMSE once the whole budget is spent (equal total instrument
time) and its ratio to k=1's, the median points, the median share of the wall time an
instrument is at work ("busy": measuring, moving or deciding; the rest it waits for the decider,
the seed points or the last points) and how many seeds reach the target at all. The clock is
simulated, so every figure but the decisions' own latency is independent of the machine and its
load.

    python benchmarks/fleet.py --latency [--n 100,1000] [--repeats 7] [--config PATH]

times a decision with 4 points in flight against one without, on campaign states of n points
(``benchmarks/scaling.py``'s, on the config's grids, past the noise model's convergence): after a
first call of each (it compiles), --repeats warm steps of each, alternated, and their medians and
ratio. The pending points are 4 (x, t) drawn on the grids with ``shots_after`` shots each.

Results go to --json after every seed; a run given the same --json measures only the seeds it
lacks, and one measured with other settings is refused.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _config import Parser, benchmark_config, refuse, same_settings  # noqa: E402
from budget import default_target, scorer  # noqa: E402

from noisebo.campaign.fleet import FleetTiming, run_fleet  # noqa: E402
from noisebo.campaign.steps import summarize  # noqa: E402
from noisebo.config import parse_config  # noqa: E402
from noisebo.state import CampaignState  # noqa: E402

INDEPENDENT_CHECKPOINTS = 24
SEED_STRIDE = 1000  # an independent design's campaign j of seed s has seed s * SEED_STRIDE + j


def fleet_config(base, k: int, budget_s: float):
    """``base`` in the budget mode with ``k`` named instruments of its instrument and the whole
    ``budget_s``."""
    data = base.with_overrides(schedule={"mode": "budget", "budget_s": budget_s, "n_steps": 100_000}).model_dump(
        mode="json"
    )
    one = data.pop("instrument")
    return parse_config({**data, "instruments": [{**one, "name": f"i{j}"} for j in range(k)]})


def run_fleet_design(config, instrument, seed: int, timing: FleetTiming, score) -> dict:
    """One fleet campaign's scores after every decision: wall time, instrument time, RMSE."""
    started = time.perf_counter()
    names = config.instrument_names
    spent = []

    def on_commit(state, events):
        if any(type(e).__name__ == "Decided" for e in events):
            spent.append(state.spent_s)

    run = run_fleet(config, {n: instrument for n in names}, seed, timing, on_commit)
    final = run.final
    errors = [score(d.f_mean) for d in final.decisions]
    summary = final.summary
    return {
        "seed": seed,
        "wall_s": [*run.decided_at, run.wall_s],
        "spent_s": [*spent, final.spent_s],
        "rmse": [*errors, score(summary.f_mean) if summary else float("nan")],
        "points": len(final.points),
        "status": final.status.value,
        "busy_s": dict(run.busy_s),
        "latency_s": float(np.median([d.latency_s for d in final.decisions[1:]])) if final.decisions else float("nan"),
        "cpu_s": time.perf_counter() - started,
    }


def run_independent(config, instrument, seed: int, timing: FleetTiming, score, k: int) -> dict:
    """``k`` one-instrument campaigns of budget/k each, pooled at evenly spaced wall times."""
    started = time.perf_counter()
    one = fleet_config(config, 1, config.schedule.budget_s / k)
    runs = [run_fleet(one, {"i0": instrument}, seed * SEED_STRIDE + j, timing) for j in range(k)]
    end = max(r.wall_s for r in runs)
    walls = np.linspace(end / INDEPENDENT_CHECKPOINTS, end, INDEPENDENT_CHECKPOINTS)
    errors, spent = [], []
    for wall in walls:
        pooled = CampaignState()
        used = 0.0
        for run in runs:
            done = [c.point for c in run.commits if c.wall_s <= wall + 1e-9]
            for entry in run.final.points:
                if entry.committed.index in done:
                    pooled = pooled.with_point(entry.committed.point)
                    used += sum(s.t for s in entry.shots) + one.schedule.point_overhead_s
        spent.append(used)
        errors.append(score(summarize(one, pooled, seed).f_mean) if len(pooled.points) >= 2 else float("nan"))
    return {
        "seed": seed,
        "wall_s": [float(w) for w in walls],
        "spent_s": spent,
        "rmse": [float(e) for e in errors],
        "points": sum(len(r.final.points) for r in runs),
        "status": ",".join(r.final.status.value for r in runs),
        "cpu_s": time.perf_counter() - started,
    }


def time_to(record: dict, target: float) -> float:
    return next((w for w, e in zip(record["wall_s"], record["rmse"]) if e <= target), float("nan"))


def final_rmse(record: dict) -> float:
    return record["rmse"][-1]


def median_or_dash(values, fmt="{:.4g}") -> str:
    v = np.asarray(values, dtype=np.float64)
    if np.isnan(v).sum() * 2 >= len(v):
        return "-"
    return fmt.format(float(np.median(np.nan_to_num(v, nan=np.inf))))


def busy(recs: list) -> str:
    """The median share of the wall time an instrument is at work (measuring or deciding), "-"
    for independent campaigns (each instrument is always at work)."""
    shares = [sum(r["busy_s"].values()) / len(r["busy_s"]) / r["wall_s"][-1] for r in recs if "busy_s" in r]
    return f"{np.median(shares):.0%}" if shares else "-"


def reference(design: str) -> str:
    """The design a row's "x k=1" ratios are taken against: BoTorch's own on one instrument for
    BoTorch's, noisebo's on one instrument for the others."""
    return "botorch k=1" if design.startswith("botorch") else "fleet k=1"


def report(records: dict, target: float) -> list[str]:
    lines = [
        f"{'design':<18} {'seeds':>5} {'wall to target (s)':>19} {'x k=1':>7} {'final RMSE':>11} {'x k=1':>7} {'points':>7} {'busy':>5} {'reached':>8}"
    ]
    for name, recs in records.items():
        ref_by_seed = {r["seed"]: r for r in records.get(reference(name), [])}
        times = [time_to(r, target) for r in recs]
        finals = [final_rmse(r) for r in recs]
        ratio_t = [
            time_to(r, target) / time_to(ref_by_seed[r["seed"]], target) for r in recs if r["seed"] in ref_by_seed
        ]
        ratio_e = [final_rmse(r) / final_rmse(ref_by_seed[r["seed"]]) for r in recs if r["seed"] in ref_by_seed]
        lines.append(
            f"{name:<18} {len(recs):>5} {median_or_dash(times):>19} {median_or_dash(ratio_t, '{:.3f}'):>7} "
            f"{median_or_dash(finals):>11} {median_or_dash(ratio_e, '{:.3f}'):>7} "
            f"{int(np.median([r['points'] for r in recs])):>7} {busy(recs):>5} "
            f"{sum(np.isfinite(times)):>5}/{len(recs):<2}"
        )
    return lines


def latency(config, n: int, repeats: int) -> dict:
    """Median warm decision times (s) on n points without and with 4 points in flight."""
    from scaling import state_of

    from noisebo.campaign.decision import decide
    from noisebo.models.grids import grids
    from noisebo.models.pending import Pending

    state = state_of(config, n)
    rng = np.random.default_rng(1)
    g = grids(config)
    pending = tuple(
        Pending((float(rng.choice(g.x)),), float(rng.choice(g.t)), config.schedule.shots_after) for _ in range(4)
    )
    first, _ = decide(config, state, 0, 0)
    decide(config, state, 0, 0, first.hyperparameters, pending=pending)
    every = config.inference.restart_every
    steps = [step for step in range(1, repeats + every) if step % every][:repeats]
    alone, with_pending = [], []
    for step in steps:
        for times, wanted in ((alone, ()), (with_pending, pending)):
            started = time.perf_counter()
            decide(config, state, 0, step, first.hyperparameters, pending=wanted)
            times.append(time.perf_counter() - started)
    a, p = float(np.median(alone)), float(np.median(with_pending))
    return {"n": n, "alone_s": a, "pending_s": p, "ratio": p / a, "alone": alone, "pending": with_pending}


def build_parser() -> Parser:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--budget", type=float, default=None, help="total instrument time (s); default the config's")
    parser.add_argument("--overhead", type=float, default=None, help="per point (s); default the config's")
    parser.add_argument("--shot-overhead", type=float, default=0.1, help="per shot besides its t (s; default 0.1)")
    parser.add_argument("--decision-s", type=float, default=1.0, help="simulated time of a decision (s; default 1)")
    parser.add_argument("--k", default="1,2,4", help="numbers of instruments (default 1,2,4)")
    parser.add_argument(
        "--designs", default="fleet,independent", help="fleet, independent and/or botorch (default fleet,independent)"
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--target", type=float, default=None)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--report", action="store_true", help="print the report of --json only")
    parser.add_argument("--latency", action="store_true", help="time decisions with 4 points in flight instead")
    parser.add_argument("--n", default="100,1000", help="with --latency: the campaign sizes (default 100,1000)")
    parser.add_argument("--repeats", type=int, default=7, help="with --latency: warm steps of each (default 7)")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        ks = sorted({int(v) for v in args.k.split(",")})
    except ValueError:
        refuse(parser, f"--k: expected whole numbers separated by commas, got {args.k!r}")
    if ks[0] < 1:
        refuse(parser, f"--k: at least one instrument, got {ks[0]}")
    kinds = {v.strip() for v in args.designs.split(",")}
    if not kinds <= {"fleet", "independent", "botorch"}:
        refuse(parser, f"--designs: fleet, independent and/or botorch, got {args.designs!r}")
    if "botorch" in kinds and not args.report:
        from _botorch import available

        if (reason := available()) is not None:
            refuse(parser, reason)

    def edit(config):
        schedule = {}
        if args.budget is not None:
            schedule["budget_s"] = args.budget
        if args.overhead is not None:
            schedule["point_overhead_s"] = args.overhead
        return config.with_overrides(schedule=schedule) if schedule else config

    base, instrument = benchmark_config(parser, args.config, edit)
    if args.latency:
        for n in (int(v) for v in args.n.split(",")):
            row = latency(base, n, args.repeats)
            print(
                f"{n} points: a decision {row['alone_s'] * 1e3:.0f} ms alone, {row['pending_s'] * 1e3:.0f} ms with 4 "
                f"points in flight ({row['ratio']:.2f}x; medians of {args.repeats})",
                flush=True,
            )
        return 0
    if base.schedule.budget_s is None:
        refuse(parser, f"{args.config}: no schedule.budget_s; give --budget")
    timing = FleetTiming(args.shot_overhead, args.decision_s)
    target, said = default_target(base, instrument, args.target)
    settings = {
        "config": base.model_dump(mode="json"),
        "shot_overhead_s": args.shot_overhead,
        "decision_s": args.decision_s,
        "target": target,
    }
    kept = json.loads(args.json.read_text()) if args.json is not None and args.json.exists() else None
    if kept is not None and not same_settings(kept["settings"], settings):
        refuse(parser, f"{args.json} was measured with other settings; give another --json")
    records: dict[str, list] = kept["records"] if kept else {}
    print(said)
    if not args.report:
        score = scorer(base, instrument)
        designs = [(f"fleet k={k}", k, "fleet") for k in ks if "fleet" in kinds]
        designs += [(f"independent k={k}", k, "independent") for k in ks if k > 1 and "independent" in kinds]
        designs += [(f"botorch k={k}", k, "botorch") for k in ks if "botorch" in kinds]
        for name, k, kind in designs:
            config = fleet_config(base, k, base.schedule.budget_s)
            done = {r["seed"] for r in records.get(name, [])}
            for seed in range(args.seeds):
                if seed in done:
                    continue
                if kind == "fleet":
                    record = run_fleet_design(config, instrument, seed, timing, score)
                elif kind == "botorch":
                    from _botorch_fleet import run_botorch_fleet

                    record = run_botorch_fleet(config, instrument, seed, timing, score, k)
                else:
                    record = run_independent(base, instrument, seed, timing, score, k)
                records.setdefault(name, []).append(record)
                print(
                    f"{name} seed {seed}: wall {record['wall_s'][-1]:.1f} s, {record['points']} points, final RMSE "
                    f"{record['rmse'][-1]:.4g} ({record['cpu_s']:.0f} s)",
                    flush=True,
                )
                if args.json is not None:
                    args.json.write_text(json.dumps({"settings": settings, "records": records}))
    for line in report(records, target):
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
