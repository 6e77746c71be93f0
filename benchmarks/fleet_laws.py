"""Two instruments whose noise laws differ on one campaign: does each end at its own optimal t?

    python benchmarks/fleet_laws.py [--config PATH] [--ratio 2] [--seeds 20]
                                    [--designs own,shared,alone,pooled] [--between a0=0.05]
                                    [--steps 30] [--n-seed 4] [--wall-budget-s S]
                                    [--json PATH] [--report]

One campaign of the config (its schedule, with --steps BO steps and --n-seed seed points) on two
simulated instruments of its instrument: "good" with the config's settings and "bad" with its A1
(``settings.a1``) --ratio times higher, in simulated time (``noisebo.campaign.fleet``: 0.1 s of
read-out per shot, 1 s per decision). The designs:

- "own": ``noise_model.per_instrument: true``, each instrument's law learned from its own points
  (``noisebo.campaign.own_noise``);
- "pooled": a law each under a hierarchical prior between them (``noise_model.between_instruments``
  set to --between, each parameter's spread: "a0=0.05", the default, all but shares A0 and
  leaves each its own A1; ``noisebo.models.between``), reported as "pooled a0=0.05";
- "shared": one law learned from every point, as with one instrument;
- "alone": the yardstick, each instrument on a campaign of its own with half the seed points
  and half the steps (about the points each instrument measures in the designs above), seeds
  seed*1000 + 0 and + 1; its final t is its last decision's optimal t, its RMSE the mean of
  the two campaigns' final models'.

--wall-budget-s S ends every campaign by its simulated wall time (``schedule.wall_budget_s``)
instead of its steps (--steps then defaults to 100 000): the two instruments run side by side for
S seconds whatever their points cost, as a lab's would, where a step count lets the instrument
with the cheaper points take most of the steps. Each "alone" campaign then runs on a simulated
instrument of its own for the same S seconds.

Each instrument's t* (``t*(law)``, ``benchmarks/_tstar.py``) maximises the config's reward with
that instrument's own noise law. A campaign's final t for an instrument is the optimal t
predicted by the last decision made for it. The report gives per design and instrument the
median final t, the median of |final t / t* - 1| and the share of seeds within 5 % of t* (the
target: 90 %), the share of seeds whose last decision for the instrument had converged, and the
median RMSE of f's final model (the summary's, on the x grid against the simulator's truth).

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
from _tstar import law_t_star  # noqa: E402
from budget import scorer  # noqa: E402

from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.campaign.fleet import FleetTiming, run_fleet  # noqa: E402
from noisebo.config import parse_config  # noqa: E402
from noisebo.instruments import build  # noqa: E402

NAMES = ("good", "bad")
WITHIN = 0.05
SEED_STRIDE = 1000
TIMING = FleetTiming(shot_overhead_s=0.1, decision_s=1.0)


def two_instrument_config(base, ratio: float, per_instrument: bool, between: dict | None = None):
    """``base`` on the instruments "good" (its settings) and "bad" (A1 ``ratio`` times higher);
    ``between``: the spreads of a prior between their laws (with ``per_instrument``)."""
    data = base.model_dump(mode="json")
    one = data.pop("instrument")
    bad = {**one, "name": "bad", "settings": {**one["settings"], "a1": one["settings"]["a1"] * ratio}}
    data["noise_model"] |= {"per_instrument": per_instrument, "between_instruments": between}
    return parse_config({**data, "instruments": [{**one, "name": "good"}, bad]})


def run_design(config, seed: int, score) -> dict:
    """One campaign: each instrument's final optimal t and convergence, f's final error."""
    started = time.perf_counter()
    instruments = {i.name: build(i.section) for i in config.instruments}
    final = run_fleet(config, instruments, seed, TIMING).final
    last = {who: d for d, who in zip(final.decisions, final.decided_for)}
    return {
        "seed": seed,
        "t_final": {n: float(last[n].t_opt) if n in last else float("nan") for n in NAMES},
        "converged": {n: bool(last[n].converged) if n in last else False for n in NAMES},
        "points": {n: sum(1 for p in final.points if p.instrument == n) for n in NAMES},
        "rmse": score(final.summary.f_mean) if final.summary else float("nan"),
        "cpu_s": time.perf_counter() - started,
    }


def run_alone(config, seed: int, score) -> dict:
    """Each instrument of ``config`` on a campaign of its own (half the seed points and steps;
    with a wall-time budget, the same wall time on a simulated clock of its own)."""
    started = time.perf_counter()
    sched = config.schedule
    finals, rmse = {}, []
    for j, named in enumerate(config.instruments):
        data = config.model_dump(mode="json")
        one = data.pop("instruments")[j]
        data["noise_model"] |= {"per_instrument": False, "between_instruments": None}
        data["schedule"] |= {"n_seed": max(sched.n_seed // 2, 2), "n_steps": max(sched.n_steps // 2, 1)}
        if sched.wall_budget_s is None:
            alone = parse_config({**data, "instrument": named.section.model_dump(mode="json")})
            final = run_campaign(alone, build(alone.instrument), seed * SEED_STRIDE + j).final
        else:
            alone = parse_config({**data, "instruments": [one]})
            final = run_fleet(alone, {named.name: build(named.section)}, seed * SEED_STRIDE + j, TIMING).final
        finals[named.name] = final
        rmse.append(score(final.summary.f_mean) if final.summary else float("nan"))
    return {
        "seed": seed,
        "t_final": {n: float(f.decisions[-1].t_opt) if f.decisions else float("nan") for n, f in finals.items()},
        "converged": {n: bool(f.decisions[-1].converged) if f.decisions else False for n, f in finals.items()},
        "points": {n: len(f.points) for n, f in finals.items()},
        "rmse": float(np.mean(rmse)),
        "cpu_s": time.perf_counter() - started,
    }


def report(records: dict, t_star: dict) -> list[str]:
    lines = [
        "| design | instrument | t* (s) | final t (median) | abs(t/t* - 1) (median) | within 5 % | converged "
        "| points (median) | RMSE of f (median) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for design, recs in records.items():
        for n in NAMES:
            t = np.asarray([r["t_final"][n] for r in recs])
            err = np.abs(t / t_star[n] - 1)
            lines.append(
                f"| {design} | {n} | {t_star[n]:.3f} | {np.median(t):.3f} | {np.median(err):.1%} | "
                f"{np.mean(err <= WITHIN):.0%} of {len(recs)} | {np.mean([r['converged'][n] for r in recs]):.0%} | "
                f"{np.median([r['points'][n] for r in recs]):.0f} | {np.median([r['rmse'] for r in recs]):.3g} |"
            )
    return lines


def parse_between(parser: Parser, text: str) -> dict[str, float]:
    """--between "a0=0.05,a1=0.5" as the config's ``between_instruments``; refused in one line."""
    spreads = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, _, value = item.partition("=")
        try:
            spreads[name.strip()] = float(value)
        except ValueError:
            refuse(parser, f"--between: NAME=SD pairs of a0, a1, p, got {item!r}")
        if name.strip() not in ("a0", "a1", "p") or not spreads[name.strip()] > 0:
            refuse(parser, f"--between: a positive spread of a0, a1 or p, got {item!r}")
    if not spreads:
        refuse(parser, f"--between: at least one NAME=SD, got {text!r}")
    return spreads


def build_parser() -> Parser:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--ratio", type=float, default=2.0, help="the bad instrument's A1 over the good one's")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--designs", default="own,shared,alone", help="own, shared, alone and/or pooled")
    parser.add_argument(
        "--between", default="a0=0.05", help="the pooled design's spreads, NAME=SD,... of a0, a1, p (default a0=0.05)"
    )
    parser.add_argument("--steps", type=int, default=None, help="BO steps (default 30; 100 000 with --wall-budget-s)")
    parser.add_argument("--n-seed", type=int, default=4, help="seed points (default 4)")
    parser.add_argument(
        "--wall-budget-s", type=float, default=None, help="each campaign's simulated wall time (s) instead of steps"
    )
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--report", action="store_true", help="print the report of --json only")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    designs = [v.strip() for v in args.designs.split(",")]
    if not set(designs) <= {"own", "shared", "alone", "pooled"}:
        refuse(parser, f"--designs: own, shared, alone and/or pooled, got {args.designs!r}")
    between = parse_between(parser, args.between)
    if not args.ratio > 0:
        refuse(parser, f"--ratio: a positive number, got {args.ratio:g}")

    if args.wall_budget_s is not None and not args.wall_budget_s > 0:
        refuse(parser, f"--wall-budget-s: a positive number of seconds, got {args.wall_budget_s:g}")
    steps = args.steps if args.steps is not None else 30 if args.wall_budget_s is None else 100_000

    def edit(config):
        schedule = {"n_steps": steps, "n_seed": args.n_seed, "wall_budget_s": args.wall_budget_s}
        return config.with_overrides(schedule=schedule)

    base, instrument = benchmark_config(parser, args.config, edit)
    if "a1" not in base.instrument.settings:
        refuse(parser, f"{args.config}: its instrument has no a1 setting to make a noisier one of")
    label = {d: f"pooled {args.between}" if d == "pooled" else d for d in designs}
    configs = {
        label[d]: two_instrument_config(base, args.ratio, d in ("own", "pooled"), between if d == "pooled" else None)
        for d in designs
    }
    laws = {i.name: build(i.section) for i in next(iter(configs.values())).instruments}
    t_star = {n: law_t_star(base, laws[n]) for n in NAMES}
    settings = {"config": base.model_dump(mode="json"), "ratio": args.ratio}
    kept = json.loads(args.json.read_text()) if args.json is not None and args.json.exists() else None
    if kept is not None and not same_settings(kept["settings"], settings):
        refuse(parser, f"{args.json} was measured with other settings; give another --json")
    records: dict[str, list] = kept["records"] if kept else {}
    print("t*: " + ", ".join(f"{n} {t_star[n]:.4g} s" for n in NAMES), flush=True)
    if not args.report:
        score = scorer(base, instrument)
        for design in map(label.get, designs):
            done = {r["seed"] for r in records.get(design, [])}
            for seed in (s for s in range(args.seeds) if s not in done):
                run = run_alone if design == "alone" else run_design
                record = run(configs[design], seed, score)
                records.setdefault(design, []).append(record)
                finals = ", ".join(f"{n} {record['t_final'][n]:.3f} s" for n in NAMES)
                print(f"{design} seed {seed}: final t {finals} ({record['cpu_s']:.0f} s)", flush=True)
                if args.json is not None:
                    args.json.write_text(json.dumps({"settings": settings, "records": records}))
    for line in report({label[d]: records[label[d]] for d in designs if label[d] in records}, t_star):
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
