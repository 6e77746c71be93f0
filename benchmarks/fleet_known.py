"""A fleet against one instrument: how long until each instrument's optimal t is known?

    python benchmarks/fleet_known.py [--config data/configs/forrester_fleet.yaml] [--seeds 20]
                                     [--wall-limit-s 3000] [--json PATH] [--report]

The config names several simulated instruments with a noise law each (``noise_model.
per_instrument``). Each seed runs it as a fleet in simulated time (``noisebo.campaign.fleet``:
0.1 s of read-out per shot, 1 s per decision) until every instrument's law has converged, and
each instrument on a campaign of its own (one law, the same schedule, seed seed*1000 + j) until
its law has converged; a campaign not converged by --wall-limit-s of simulated time counts as
never. Per seed: the wall time (s) at which each law converged, its predicted optimal t then,
and the instrument time (s: exposures and read-out, every instrument's) spent by then.

The report: each instrument's t* (``benchmarks/_tstar.py``), the share of seeds whose t at
convergence is within 5 % of it, fleet and alone; the fleet's wall time until every law is known
over the mean of the instruments' own times alone, and its instrument time over theirs (medians
over the seeds). Results go to --json after every seed; a run given the same --json measures only
the seeds it lacks, and one measured with other settings is refused.
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

from _config import Parser, refuse, same_settings  # noqa: E402
from _tstar import law_t_star  # noqa: E402

from noisebo.campaign.fleet import FleetTiming, run_fleet  # noqa: E402
from noisebo.campaign.own_noise import state_standings  # noqa: E402
from noisebo.config import ConfigError, load_config, parse_config  # noqa: E402
from noisebo.events import ShotTaken  # noqa: E402
from noisebo.instruments import build  # noqa: E402

WITHIN = 0.05
SEED_STRIDE = 1000
TIMING = FleetTiming(shot_overhead_s=0.1, decision_s=1.0)


class _AllKnown(Exception):
    """Every law has converged: the campaign has what this benchmark measures."""


def until_known(config, seed: int) -> dict:
    """One campaign of ``config`` until each instrument's law has converged: per instrument the
    wall time (s) it converged at, its optimal t then (s) and the instrument time (s) spent by
    then (None where it did not converge)."""
    names = config.instrument_names
    spent = [0.0]
    known: dict[str, dict] = {}

    def on_commit(state, events) -> None:
        spent[0] += sum(e.t + TIMING.shot_overhead_s for e in events if isinstance(e, ShotTaken))
        if config.noise_model.per_instrument:
            standing = {s.instrument: (s.converged_step is not None, s.t_opt) for s in state_standings(state)}
        else:
            last = state.decisions[-1] if state.decisions else None
            standing = {names[0]: (bool(last and last.converged), last and float(last.t_opt))}
        for name, (converged, t_opt) in standing.items():
            if converged and name not in known:
                known[name] = {"wall_s": events[-1].wall_s, "t": t_opt, "spent_s": spent[0]}
        if len(known) == len(names):
            raise _AllKnown

    started = time.perf_counter()
    try:
        run_fleet(config, {i.name: build(i.section) for i in config.instruments}, seed, TIMING, on_commit)
    except _AllKnown:
        pass
    return {"seed": seed, "known": {n: known.get(n) for n in names}, "cpu_s": time.perf_counter() - started}


def alone_configs(config) -> list:
    """Each instrument of ``config`` on a campaign of its own, with one law."""
    data = config.model_dump(mode="json")
    named = data.pop("instruments")
    data["noise_model"] |= {"per_instrument": False, "between_instruments": None}
    return [parse_config({**data, "instruments": [one]}) for one in named]


def report(records: dict, t_star: dict) -> list[str]:
    lines = ["| instrument | t* (s) | fleet: within 5 % at convergence | alone: within 5 % |", "|---|---|---|---|"]

    def within(rec, n):
        k = rec["known"][n]
        return k is not None and abs(k["t"] / t_star[n] - 1) <= WITHIN

    fleet, alone = records.get("fleet", []), records.get("alone", [])
    for n in t_star:
        lines.append(
            f"| {n} | {t_star[n]:.3f} | {np.mean([within(r, n) for r in fleet]):.0%} of {len(fleet)} "
            f"| {np.mean([within(r, n) for r in alone if n in r['known']]):.0%} |"
        )
    wall, spent = [], []
    for f in fleet:
        mine = [a for a in alone if a["seed"] // SEED_STRIDE == f["seed"]]
        ends = [f["known"][n] for n in t_star]
        own = [a["known"][n] for a in mine for n in a["known"]]
        if len(own) < len(t_star):
            continue
        if None in ends:  # a law the fleet never knew: the fleet never got there
            wall.append(np.inf), spent.append(np.inf)
            continue
        last = max(ends, key=lambda k: k["wall_s"])
        never = {"wall_s": np.inf, "spent_s": np.inf}  # alone, never known: the fleet's time over infinity
        wall.append(last["wall_s"] / np.mean([(k or never)["wall_s"] for k in own]))
        spent.append(last["spent_s"] / np.mean([(k or never)["spent_s"] for k in own]))
    lines.append("")
    lines.append(
        f"fleet until every law known, over one instrument alone until its own (median of {len(wall)} seeds): "
        f"wall time {np.median(wall):.2f}x, instrument time {np.median(spent):.2f}x"
    )
    return lines


def main(argv=None) -> int:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester_fleet.yaml"))
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--wall-limit-s", type=float, default=3000.0, help="simulated wall time before giving up")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--report", action="store_true", help="print the report of --json only")
    args = parser.parse_args(argv)
    if not args.wall_limit_s > 0:
        refuse(parser, f"--wall-limit-s: a positive number of seconds, got {args.wall_limit_s:g}")
    try:
        config = load_config(args.config)
    except ConfigError as error:
        refuse(parser, error)
    if config.instruments is None or len(config.instruments) < 2 or not config.noise_model.per_instrument:
        refuse(parser, f"{args.config}: give a config with several instruments and noise_model.per_instrument: true")
    config = config.with_overrides(schedule={"n_steps": 1_000_000, "wall_budget_s": args.wall_limit_s})
    t_star = {i.name: law_t_star(config, build(i.section)) for i in config.instruments}
    settings = {"config": config.model_dump(mode="json")}
    kept = json.loads(args.json.read_text()) if args.json is not None and args.json.exists() else None
    if kept is not None and not same_settings(kept["settings"], settings):
        refuse(parser, f"{args.json} was measured with other settings; give another --json")
    records: dict[str, list] = kept["records"] if kept else {"fleet": [], "alone": []}
    print("t*: " + ", ".join(f"{n} {t:.4g} s" for n, t in t_star.items()), flush=True)
    alone = alone_configs(config)
    for seed in range(0 if args.report else args.seeds):
        if seed in {r["seed"] for r in records["fleet"]}:
            continue
        records["fleet"].append(until_known(config, seed))
        records["alone"].extend(until_known(one, seed * SEED_STRIDE + j) for j, one in enumerate(alone))
        fleet = records["fleet"][-1]["known"]
        print(f"seed {seed}: " + ", ".join(f"{n} {k['wall_s']:.0f} s" if k else f"{n} never" for n, k in fleet.items()))
        if args.json is not None:
            args.json.write_text(json.dumps({"settings": settings, "records": records}))
    for line in report(records, t_star):
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
