"""Noise that depends on x: the x-independent noise model against the noise field, one setting.

    python benchmarks/field.py [--config PATH] [--scan FILE] [--set KEY=VALUE ...] [--law LAW]
                               [--seeds N] [--first-seed S] [--steps N] [--json PATH]

For each seed the configuration runs twice, with the x-independent noise model and with the
noise field (``noise_model.field: {varies: a0}``, or the config's own field), the same noise law
(the config's, or ``--law``) and everything else equal. Scored against the simulator's own noise
at every position (``noise_law_at``), it prints per model (medians over seeds, [IQR]):

- the optimal time per position: |t_opt(x) - t*(x)| / t*(x) over the reference points, its median
  over x and the share of x within 10 % (the x-independent model has one t for every x);
- the single t of each campaign (for the field, the t maximising the reward averaged over x)
  against t*(x-avg), the simulator's t maximising the x-averaged reward, and against t*(law), the
  optimum with the simulator's x-independent noise law (the t* ``pfm.py`` and ``budget.py`` score
  against; see ``_tstar.py``): campaigns within 10 % of each;
- the final RMSE of f over the reference points, the instrument time (shots x t) and the
  decision latency (median after the first decision).

``--set KEY=VALUE`` overrides an instrument setting, dotted keys reaching into nested ones, values
read as YAML: ``--set position_jitter_um=0.0025 --set profile='{source: synthetic, n_domains: 2}'``.
``--scan`` moves the campaign onto another scan (its whole area for a two-axis config). The
config, with these changes, is validated as ``noisebo run`` validates it before anything runs
(``_config.py``).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import json
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config, refuse  # noqa: E402
from _tstar import LAW, X_AVG, law_t_star, reference_positions, x_averaged_t_star  # noqa: E402
from pfm2d import on_scan  # noqa: E402

from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import ConfigError  # noqa: E402
from noisebo.metrics import median_iqr, relative_error, rmse  # noqa: E402
from noisebo.models.reward import reward  # noqa: E402
from noisebo.registry import noise_law_names  # noqa: E402

N_FINE = 2049
DEFAULT_FIELD = {"varies": "a0"}


def with_settings(config, assignments: list[str]):
    """The config with instrument settings overridden by KEY=VALUE strings (dotted keys nest)."""
    settings = json.loads(json.dumps(config.instrument.settings))
    for item in assignments:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        target, *path = key.split(".")
        node = settings
        for part in [target, *path][:-1]:
            node = node.setdefault(part, {})
        node[[target, *path][-1]] = yaml.safe_load(text)
    return config.with_overrides(instrument={"settings": settings})


def truth_of(config, instrument) -> dict:
    """The simulator's optimal time at every reference point (t*(x), on a fine t grid) and for the
    whole sample: t*(x-avg), the t maximising the x-averaged reward (what the single t is scored
    against), and t*(law), with the x-independent noise law."""
    s, rew = config.space, config.reward
    x = reference_positions(config)
    t = np.linspace(s.t_min, s.t_max, N_FINE)
    noise = instrument.noise_law_at(x, t)
    per_x = t[np.argmax(np.asarray(reward(t[None, :], noise, rew.alpha, rew.beta)), axis=1)]
    return {
        "t_star_map": per_x,
        "t_star": x_averaged_t_star(config, instrument),
        "t_star_law": law_t_star(config, instrument),
        "f": instrument.truth(x),
    }


def score(result, truth: dict) -> dict:
    summary = result.summary
    t_map = summary.t_opt_map if summary.t_opt_map.size else np.full(truth["t_star_map"].shape, summary.t_opt)
    err = np.abs(t_map - truth["t_star_map"]) / truth["t_star_map"]
    points = result.state.points
    return {
        "t_opt": float(summary.t_opt),
        "t_rel_error": relative_error(summary.t_opt, truth["t_star"]),  # against t*(x-avg)
        "t_rel_error_law": relative_error(summary.t_opt, truth["t_star_law"]),
        "map_median_error": float(np.median(err)),
        "map_within_10": float(np.mean(err <= 0.10)),
        "map_p90_error": float(np.quantile(err, 0.9)),
        "rmse_f": rmse(summary.f_mean, truth["f"]),
        "time_s": float(sum(p.t * p.n_shots for p in points)),
        "latency_s": float(np.median(result.latencies_s[1:])) if len(result.latencies_s) > 1 else float("nan"),
        "converged_step": result.state.converged_step,
        "points": len(points),
    }


def models(base, law: str | None) -> dict:
    noise = {} if law is None else {"mean": law}
    field = base.noise_model.field.model_dump() if base.noise_model.field is not None else DEFAULT_FIELD
    return {
        "x-independent": base.with_overrides(noise_model=noise | {"field": None}),
        "noise field": base.with_overrides(noise_model=noise | {"field": field}),
    }


def fmt(values, scale: float = 1.0, digits: int = 1) -> str:
    m, lo, hi = median_iqr(values)
    return f"{scale * m:.{digits}f} [{scale * lo:.{digits}f}, {scale * hi:.{digits}f}]"


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm.yaml"))
    parser.add_argument("--scan", default=None)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--law", choices=noise_law_names(), default=None)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    def edit(config):
        if args.scan:
            config = on_scan(config, args.scan)
        config = with_settings(config, args.set)
        return config if args.steps is None else config.with_overrides(schedule={"n_steps": args.steps})

    base, instrument = benchmark_config(parser, args.config, edit)
    if not callable(getattr(instrument, "noise_law_at", None)):
        refuse(
            parser,
            f"{args.config}: the {base.instrument.kind} simulator has no noise at each position "
            "(noise_law_at) to score a noise field against",
        )
    truth = truth_of(base, instrument)
    t_map = truth["t_star_map"]
    print(
        f"{base.name}: {base.space.dimensions} axis(es), law {base.noise_model.mean if args.law is None else args.law}, "
        f"{base.schedule.n_seed} seeds + {base.schedule.n_steps} steps; simulator {X_AVG} for the whole sample "
        f"(the optimum of the x-averaged reward, what the single t is scored against) {truth['t_star']:.3f} s, "
        f"{LAW} (with the x-independent noise law, as in pfm.py and budget.py) {truth['t_star_law']:.3f} s "
        f"({100 * (truth['t_star_law'] / truth['t_star'] - 1):+.1f} %); t*(x) from {t_map.min():.3f} to "
        f"{t_map.max():.3f} s ({100 * np.mean(np.abs(t_map / truth['t_star'] - 1) > 0.1):.0f} % of x more than "
        f"10 % away from {X_AVG})",
        flush=True,
    )
    records: dict[str, list] = {}
    for name, config in models(base, args.law).items():
        records[name] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            started = time.perf_counter()
            rec = score(run_campaign(config, instrument, seed), truth) | {"seed": seed}
            records[name].append(rec)
            print(
                f"{name:>13} seed {seed:3d}: t {rec['t_opt']:.3f} s ({100 * rec['t_rel_error']:.1f} % from {X_AVG}, "
                f"{100 * rec['t_rel_error_law']:.1f} % from {LAW}), t*(x) median "
                f"error {100 * rec['map_median_error']:.1f} %, {100 * rec['map_within_10']:.0f} % of x within 10 %, "
                f"RMSE {rec['rmse_f']:.3f}, {rec['time_s']:.0f} s, decision {rec['latency_s']:.3f} s, "
                f"wall {time.perf_counter() - started:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    print(
        f"\n| model | single t within 10 % of {X_AVG} | single t within 10 % of {LAW} | t*(x) error, median over x (%) "
        "| x with t*(x) within 10 % (%) | RMSE of f | instrument time (s) | decision (s) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    table = {}
    for name, recs in records.items():
        within = sum(r["t_rel_error"] <= 0.10 for r in recs)
        within_law = sum(r["t_rel_error_law"] <= 0.10 for r in recs)
        table[name] = {
            "single_t_within_10": within,
            "single_t_within_10_law": within_law,
            "campaigns": len(recs),
            **{
                k: median_iqr([r[k] for r in recs])
                for k in ("map_median_error", "map_within_10", "rmse_f", "time_s", "latency_s")
            },
        }
        print(
            f"| {name} | {within} of {len(recs)} | {within_law} of {len(recs)} | {fmt([r['map_median_error'] for r in recs], 100)} | "
            f"{fmt([r['map_within_10'] for r in recs], 100, 0)} | {fmt([r['rmse_f'] for r in recs], 1, 3)} | "
            f"{np.median([r['time_s'] for r in recs]):.0f} | {np.median([r['latency_s'] for r in recs]):.3f} |"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps(
                {
                    "config": base.model_dump(mode="json"),
                    "t_star": truth["t_star"],
                    "t_star_definition": X_AVG,
                    "t_star_law": truth["t_star_law"],
                    "table": table,
                    "records": records,
                },
                indent=1,
                default=float,
            )
        )
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
