"""The paper's Forrester protocol over many seeds: convergence, accuracy, cost and latency.

    python benchmarks/forrester.py [--config PATH] [--policy reward|double|both] [--seeds N]
                                   [--first-seed S] [--set SECTION.KEY=VALUE ...] [--json PATH]

Prints one table row per policy. Convergence is the paper's rule (variance of the predicted
optimal t over the last `window` BO steps below `threshold`); steps count from 1 (step 1 is the
first BO step) and "converged by step 10" counts campaigns whose first converged BO step is at most 10. t* is t*(law), computed numerically from the instrument's
true noise law and the configured reward (the output names it, and t*(x-avg) where the noise
depends on x: ``_tstar.py``). The config, with ``--set`` applied, is validated as ``noisebo run``
validates it before anything runs (``_config.py``). Latency is the decision time per BO step (both fits,
prediction and acquisition). "recompiles" counts XLA compilations after each campaign's first BO
step: with fixed-capacity padding it must be 0. ``--set`` overrides config keys (values read as
YAML), e.g. the paper's other protocols: ``--set acquisition.f_acquisition=ei`` (its Fig. S2) and
``--set schedule.shots_after=5`` (Fig. S3).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config  # noqa: E402
from _tstar import LAW, X_AVG, describe, differ, t_stars  # noqa: E402

from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import ConfigError  # noqa: E402
from noisebo.diagnostics import compile_count  # noqa: E402
from noisebo.metrics import campaign_figures, relative_error, summarise_campaigns  # noqa: E402
from noisebo.models.grids import grids  # noqa: E402
from noisebo.registry import chosen_policies, policy_names  # noqa: E402
from noisebo.storage.steps import shown as shown_step  # noqa: E402
from noisebo.view.report import benchmark_table  # noqa: E402


def with_overrides(config, assignments: list[str]):
    """The config with SECTION.KEY=VALUE overrides (values read as YAML)."""
    import yaml

    for item in assignments:
        key, sep, text = item.partition("=")
        section, dot, name = key.partition(".")
        if not sep or not dot or not name:
            raise ConfigError(f"--set {item!r}: expected SECTION.KEY=VALUE")
        config = config.with_overrides(**{section: {name: yaml.safe_load(text)}})
    return config


def regret(config, instrument, f_mean) -> float:
    """How far the final model's best point is from the best of f (EI and UCB look for it):
    |f(x_hat) - f*|, x_hat the grid point with the best predicted mean, f* the best of the truth
    on the grid."""
    x = grids(config).x
    x = x[:, None] if x.ndim == 1 else x
    truth = np.asarray(instrument.truth(x), dtype=np.float64)
    pick = np.argmax if config.acquisition.maximize else np.argmin
    return float(abs(truth[int(pick(f_mean))] - truth[int(pick(truth))]))


def run_one(config, instrument, seed: int) -> dict:
    compiles = {"after_first": None}
    before = compile_count()

    def on_commit(state, events):
        if len(state.decisions) == 1 and compiles["after_first"] is None:
            compiles["after_first"] = compile_count()

    started = time.perf_counter()
    result = run_campaign(config, instrument, seed, on_commit=on_commit)
    wall = time.perf_counter() - started
    points = result.state.points
    record = campaign_figures(
        config,
        instrument,
        result.state.t_opt_history,
        result.summary.t_opt,
        grids(config).x,
        result.summary.f_mean,
        [p.t for p in points for _ in range(p.n_shots)],
        result.latencies_s,
        shown_step(result.state.converged_step),
    )
    after_first = compiles["after_first"]
    record["regret"] = regret(config, instrument, result.summary.f_mean)
    record.update(
        seed=seed,
        recompiles_after_first_step=None if after_first is None else compile_count() - after_first,
        compiles_total=compile_count() - before,
        hyperparameters=result.summary.hyperparameters,
        wall_s=wall,
    )
    return record


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--policy", choices=[*policy_names(), "both", "all"], default="both")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--inference", choices=["map", "nuts"], default=None, help="override the config's mode")
    parser.add_argument(
        "--quadrature",
        type=int,
        default=None,
        help="override inference.primary_quadrature (nodes per dimension, 0 = MAP)",
    )
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    def edit(config):
        config = with_overrides(config, args.set)
        if args.inference:
            config = config.with_overrides(inference={"mode": args.inference})
        if args.quadrature is not None:
            config = config.with_overrides(inference={"primary_quadrature": args.quadrature})
        return config

    base, instrument = benchmark_config(parser, args.config, edit)
    policies = chosen_policies(args.policy)
    stars = t_stars(base, instrument)  # the records' t error is against t*(law) (noisebo.metrics.campaign_figures)
    records, rows = [], {}
    for policy in policies:
        config = base.with_overrides(acquisition={"policy": policy})
        mine = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rec = run_one(config, instrument, seed)
            mine.append(rec)
            print(
                f"{policy:>6} seed {seed:3d}: converged step {rec['converged_step']}, "
                f"t_opt {rec['t_opt_pred'][-1]:.3f} s ({100 * rec['t_opt_rel_error']:.1f} %), "
                f"RMSE {rec['rmse_f']:.3f}, time {rec['total_measurement_time']:.0f} s, "
                f"decision {np.median(rec['step_latency_s'][1:]) if len(rec['step_latency_s']) > 1 else float('nan'):.3f} s",
                file=sys.stderr,
                flush=True,
            )
        records += mine
        rows[policy] = summarise_campaigns(mine)
        rows[policy]["regret"] = float(np.median([r["regret"] for r in mine]))
        rows[policy]["recompiles_after_first"] = sum(r["recompiles_after_first_step"] or 0 for r in mine)
    print(
        f"\n{describe(stars, LAW)} (the table's t*)\ninference = {base.inference.mode}   "
        f"primary quadrature = {base.inference.primary_quadrature}   f acquisition = {base.acquisition.f_acquisition}   "
        f"shots {base.schedule.shots_before} / {base.schedule.shots_after}   (median [IQR])"
    )
    print(benchmark_table(rows))
    if base.acquisition.f_acquisition != "ue":  # EI and UCB look for the optimum; UE explores
        best = "maximum" if base.acquisition.maximize else "minimum"
        print(
            f"regret of the final model's {best} (|f(x_hat) - f*| on the grid), median: "
            + ", ".join(f"{p} {r['regret']:.3g}" for p, r in rows.items())
        )
    if differ(stars):
        print(
            f"final t within 10 % of {X_AVG}: "
            + ", ".join(
                f"{p} {sum(relative_error(r['t_opt_pred'][-1], stars[X_AVG]) <= 0.10 for r in records if r['policy'] == p)}"
                f" of {sum(r['policy'] == p for r in records)}"
                for p in rows
            )
        )
    print(
        "XLA recompilations after the first BO step, all campaigns: "
        + ", ".join(f"{p} {r['recompiles_after_first']}" for p, r in rows.items())
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps({"records": records, "summary": rows, "t_star_definition": LAW, "t_stars": stars}, indent=1)
        )
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
