"""The paper's Forrester protocol over many seeds: convergence, accuracy, cost and latency.

    python benchmarks/forrester.py [--config PATH] [--policy reward|double|both] [--seeds N]
                                   [--first-seed S] [--json PATH]

Prints one table row per policy. Convergence is the paper's rule (variance of the predicted
optimal t over the last `window` BO steps below `threshold`); "within 10" counts campaigns whose
first converged BO step (0-based) is at most 9. t* is computed numerically from the instrument's
true noise law and the configured reward. Latency is the decision time per BO step (both fits,
prediction and acquisition). "recompiles" counts XLA compilations after each campaign's first BO
step: with fixed-capacity padding it must be 0.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from instruments import build  # noqa: E402
from noisebo.campaign import run_campaign  # noqa: E402
from noisebo.config import load_config  # noqa: E402
from noisebo.diagnostics import compile_count  # noqa: E402
from noisebo.metrics import median_iqr, relative_error, rmse  # noqa: E402
from noisebo.reward import true_optimal_t  # noqa: E402
from noisebo.schedule import first_converged_step  # noqa: E402

RMSE_POINTS = 200


def run_one(config, instrument, seed: int, t_star: float) -> dict:
    compiles = {"after_first": None}
    before = compile_count()

    def on_step(decision, state):
        if decision.step == 0:
            compiles["after_first"] = compile_count()

    started = time.perf_counter()
    result = run_campaign(config, instrument, seed, on_step=on_step)
    wall = time.perf_counter() - started
    s = config.space
    x_eval = np.linspace(s.x_min, s.x_max, RMSE_POINTS)
    f_pred = np.interp(x_eval, result.summary.x, result.summary.f_mean)
    sched = config.schedule
    history = list(result.state.t_opt_history)
    after_first = compiles["after_first"]
    return {
        "policy": config.acquisition.policy,
        "seed": seed,
        "converged_step": first_converged_step(history, sched.window, sched.threshold),
        "t_opt_pred": history + [result.summary.t_opt],
        "t_star": t_star,
        "t_opt_rel_error": relative_error(result.summary.t_opt, t_star),
        "rmse_f": rmse(f_pred, instrument.truth(x_eval)),
        "total_measurement_time": result.total_measurement_time,
        "step_latency_s": list(result.latencies_s),
        "recompiles_after_first_step": None if after_first is None else compile_count() - after_first,
        "compiles_total": compile_count() - before,
        "hyperparameters": result.summary.hyperparameters,
        "wall_s": wall,
    }


def summarise(records: list[dict]) -> dict:
    conv = [r["converged_step"] for r in records]
    within = sum(1 for c in conv if c is not None and c <= 9)
    first = [r["step_latency_s"][0] for r in records if r["step_latency_s"]]
    rest = [v for r in records for v in r["step_latency_s"][1:]]
    return {
        "campaigns": len(records),
        "converged_within_10": within / len(records),
        "converged_step": median_iqr([c for c in conv if c is not None]),
        "t_rel_error": median_iqr([r["t_opt_rel_error"] for r in records]),
        "rmse_f": median_iqr([r["rmse_f"] for r in records]),
        "measurement_time_s": median_iqr([r["total_measurement_time"] for r in records]),
        "latency_first_s": median_iqr(first)[0],
        "latency_rest_s": median_iqr(rest)[0],
        "recompiles_after_first": sum(r["recompiles_after_first_step"] or 0 for r in records),
    }


def fmt(m: tuple[float, float, float], digits: int = 3) -> str:
    return f"{m[0]:.{digits}f} [{m[1]:.{digits}f}, {m[2]:.{digits}f}]"


def print_table(rows: dict[str, dict], t_star: float, mode: str) -> None:
    print(f"\nt* = {t_star:.4f} s   inference = {mode}   (median [IQR])")
    header = (
        "| policy | campaigns | converged <= step 9 | first converged step | final abs(t_opt - t*)/t* "
        "| final RMSE f | measurement time (s) | latency step 0 (s) | latency median rest (s) | recompiles |"
    )
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for policy, s in rows.items():
        print(
            f"| {policy} | {s['campaigns']} | {100 * s['converged_within_10']:.0f} % | {fmt(s['converged_step'], 1)} "
            f"| {fmt(s['t_rel_error'])} | {fmt(s['rmse_f'])} | {fmt(s['measurement_time_s'], 0)} "
            f"| {s['latency_first_s']:.2f} | {s['latency_rest_s']:.3f} | {s['recompiles_after_first']} |"
        )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--policy", choices=["reward", "double", "both"], default="both")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--inference", choices=["map", "nuts"], default=None, help="override the config's mode")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    base = load_config(args.config)
    if args.inference:
        base = base.with_overrides(inference={"mode": args.inference})
    policies = ["reward", "double"] if args.policy == "both" else [args.policy]
    instrument = build(base.instrument)
    s, rew = base.space, base.reward
    t_star = true_optimal_t(instrument.noise_law, s.t_min, s.t_max, rew.alpha, rew.beta)
    records, rows = [], {}
    for policy in policies:
        config = base.with_overrides(acquisition={"policy": policy})
        mine = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rec = run_one(config, instrument, seed, t_star)
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
        rows[policy] = summarise(mine)
    print_table(rows, t_star, base.inference.mode)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"records": records, "summary": rows}, indent=1))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
