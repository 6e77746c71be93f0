"""Two-axis campaigns: the image a campaign reconstructs against the instrument time it spends.

    python benchmarks/pfm2d.py [--config data/configs/pfm2d.yaml] [--scan FILE.h5] [--seeds 10]
                               [--steps N] [--latency 200,500] [--figure PATH] [--json PATH]

For each seed it runs the configured campaign (t optimised) and two designs that keep every
sweep at a fixed time (0.1 s and 2 s) with the same number of points and the same shot schedule.
After every decision it scores the GP mean on the reference grid against the simulator's truth
(RMSE over the area) next to the instrument time spent so far, and prints, per design: the RMSE
once a given instrument time has been spent (median over seeds; the last decision made within
that time), the final RMSE and total time, and the final predicted optimal t against the
simulator's t*(law) (and t*(x-avg), the optimum of the x-averaged reward, where the two differ:
``_tstar.py``). The config is validated as ``noisebo run`` validates it before anything runs
(``_config.py``). ``--scan`` moves the campaign onto another scan (its whole area; the axes take
the scan's extent). ``--latency`` times decisions on states of that many points over the area
(``benchmarks/scaling.py`` in fresh processes: median warm decision, multi-start decision).
``--figure`` draws one campaign: truth, GP mean, GP sd, points coloured by t.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config  # noqa: E402
from _tstar import LAW, X_AVG, describe, differ, t_stars  # noqa: E402

from noisebo.instruments import build  # noqa: E402
from noisebo.instruments.registry import validated  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.metrics import median_iqr, relative_error, rmse  # noqa: E402
from noisebo.models.grids import grids  # noqa: E402

DESIGNS = {"t optimised": None, "fixed 0.1 s": 0.1, "fixed 2 s": 2.0}
BUDGETS_S = (30, 60, 120, 240, 480, 960)


def on_scan(config, scan: str):
    """The config moved onto another scan: its whole area, the axes spanning its extent."""
    settings = dict(config.instrument.settings)
    settings["profile"] = {k: v for k, v in settings["profile"].items() if k in ("source", "smooth_px")} | {
        "file": scan
    }
    moved = config.with_overrides(instrument={"settings": settings})
    extent = build(validated(moved).instrument).bounds_um
    axes = [a.model_dump() | {"low": lo, "high": hi} for a, (lo, hi) in zip(config.space.axes, extent)]
    return moved.with_overrides(space={"axes": axes})


def run_design(config, instrument, seed: int) -> dict:
    """One campaign: per decision, the instrument time spent before it and the RMSE of its GP
    mean over the reference grid; then the final model's."""
    started = time.perf_counter()
    result = run_campaign(config, instrument, seed)
    wall = time.perf_counter() - started
    g = grids(config)
    truth = instrument.truth(g.x)
    points, n_seed = result.state.points, config.schedule.n_seed
    spent = np.cumsum([p.t * p.n_shots for p in points])  # after each point
    times = [float(spent[n_seed + k - 1]) for k in range(len(result.decisions))]
    errors = [rmse(d.f_mean, truth) for d in result.decisions]
    times.append(float(spent[-1]))
    errors.append(rmse(result.summary.f_mean, truth))
    return {
        "seed": seed,
        "times_s": times,
        "rmse": errors,
        "t_opt": result.summary.t_opt,
        "points": len(points),
        "latency_s": [float(v) for v in result.latencies_s],
        "wall_s": wall,
        "result": result,
    }


def rmse_within(record: dict, budget: float) -> float:
    """The RMSE of the last model fitted within ``budget`` seconds of instrument time (NaN if none)."""
    inside = [e for t, e in zip(record["times_s"], record["rmse"]) if t <= budget]
    return inside[-1] if inside else float("nan")


def _median_of_finite(values) -> float:
    """The median of the campaigns that had a model within the budget; NaN when none had."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.median(finite)) if finite else float("nan")


def latency(config_path: str, sizes: list[int]) -> list[dict]:
    rows = []
    for n in sizes:
        code = (
            "import json, sys; sys.path.insert(0, 'benchmarks'); from scaling import one_size; "
            f"print(json.dumps(one_size({config_path!r}, {n}, 5, 'map', 'grid')))"
        )
        out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        print(
            f"latency at {n} points: warm {r['median_s']:.3f} s, multi-start {r['restart_s']:.3f} s, first "
            f"{r['first_s']:.1f} s, peak {r['peak_gb']:.2f} GB",
            file=sys.stderr,
            flush=True,
        )
    return rows


def figure(record: dict, config, instrument, path: Path) -> None:
    from matplotlib.figure import Figure

    from noisebo.view.area import draw_image

    result = record["result"]
    g = grids(config)
    xy = np.asarray([p.x for p in result.state.points])
    t = np.asarray([p.t for p in result.state.points])
    fig = Figure(figsize=(15, 4.4), layout="constrained")
    axes = fig.subplots(1, 3)
    draw_image(axes[0], instrument.truth(g.x), config, "truth: signed response of the scan", "pm")
    draw_image(
        axes[1],
        result.summary.f_mean,
        config,
        f"GP mean after {len(t)} points ({record['times_s'][-1]:.0f} s of sweeps)",
        "pm",
        points=xy,
        point_colours=np.log10(t),
    )
    draw_image(
        axes[2],
        np.sqrt(result.summary.f_var),
        config,
        "GP sd; points coloured by log10 t",
        "pm",
        cmap="magma",
        points=xy,
        point_colours=np.log10(t),
    )
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm2d.yaml"))
    parser.add_argument("--scan", default=None)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--latency", default="200,500", help="comma-separated sizes, '' to skip")
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    def edit(config):
        if args.scan:
            config = on_scan(config, args.scan)
        return config if args.steps is None else config.with_overrides(schedule={"n_steps": args.steps})

    base, instrument = benchmark_config(parser, args.config, edit)
    s = base.space
    stars = t_stars(base, instrument)
    t_star = stars[LAW]
    against = [LAW, X_AVG] if differ(stars) else [LAW]
    records: dict[str, list] = {}
    for name, fixed in DESIGNS.items():
        config = base if fixed is None else base.with_overrides(acquisition={"fixed_t": fixed})
        records[name] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rec = run_design(config, instrument, seed)
            records[name].append(rec)
            print(
                f"{name:>12} seed {seed:3d}: {rec['points']} points, {rec['times_s'][-1]:.0f} s of sweeps, final "
                f"RMSE {rec['rmse'][-1]:.2f} pm, t_opt {rec['t_opt']:.3f} s, median decision "
                f"{np.median(rec['latency_s']):.3f} s, wall {rec['wall_s']:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    print(
        f"\n{base.name}: {s.dimensions} axes {[a.name for a in s.axes]}, {base.schedule.n_seed} seed points + "
        f"{base.schedule.n_steps} steps, {len(records['t optimised'])} seeds; {describe(stars, ' and '.join(against))}"
    )
    print("\nRMSE of the GP mean over the area (pm) once this much instrument time is spent (median over seeds):\n")
    print("| design | " + " | ".join(f"{b} s" for b in BUDGETS_S) + " | final RMSE | total time (s) |")
    print("|---" * (len(BUDGETS_S) + 3) + "|")
    table = {}
    for name, recs in records.items():
        at = [_median_of_finite([rmse_within(r, b) for r in recs]) for b in BUDGETS_S]
        final = median_iqr([r["rmse"][-1] for r in recs])
        total = median_iqr([r["times_s"][-1] for r in recs])
        table[name] = {"rmse_at_budget": dict(zip(BUDGETS_S, at)), "final_rmse": final, "total_time_s": total}
        cells = " | ".join("-" if np.isnan(v) else f"{v:.2f}" for v in at)
        print(f"| {name} | {cells} | {final[0]:.2f} [{final[1]:.2f}, {final[2]:.2f}] | {total[0]:.0f} |")
    within = []
    for star in against:
        errors = [relative_error(r["t_opt"], stars[star]) for r in records["t optimised"]]
        within.append(f"within 10 % of {star} in {sum(e <= 0.10 for e in errors)} of {len(errors)} campaigns")
    print(
        f"\nfinal predicted optimal t (t optimised): median {np.median([r['t_opt'] for r in records['t optimised']]):.3f} s, "
        + ", ".join(within)
    )
    lat = [v for r in records["t optimised"] for v in r["latency_s"][1:]]
    print(f"decision latency in these campaigns: median {np.median(lat):.3f} s (first decision aside)")
    sizes = [int(v) for v in args.latency.split(",") if v.strip()]
    latencies = latency(args.config, sizes) if sizes else []
    for r in latencies:
        print(
            f"decision latency at {r['n']} points over the area: warm {r['median_s']:.3f} s, multi-start "
            f"{r['restart_s']:.3f} s, peak memory {r['peak_gb']:.2f} GB"
        )
    if args.figure:
        figure(records["t optimised"][0], base, instrument, args.figure)
        print(f"\nwrote {args.figure}")
    if args.json:
        out = {
            "t_star": t_star,
            "t_star_definition": LAW,
            "t_stars": stars,
            "table": table,
            "latency": latencies,
            "records": {k: [{kk: vv for kk, vv in r.items() if kk != "result"} for r in v] for k, v in records.items()},
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1, default=float))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
