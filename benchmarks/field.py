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
  against the simulator's t maximising the x-averaged reward: campaigns within 10 %;
- the final RMSE of f over the reference points, the instrument time (shots x t) and the
  decision latency (median after the first decision).

``--set KEY=VALUE`` overrides an instrument setting, dotted keys reaching into nested ones, values
read as YAML: ``--set position_jitter_um=0.0025 --set profile='{source: synthetic, n_domains: 2}'``.
``--scan`` moves the campaign onto another scan (its whole area for a two-axis config).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from pfm2d import on_scan  # noqa: E402

from instruments import build  # noqa: E402
from instruments.registry import validated  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import ConfigError, load_config  # noqa: E402
from noisebo.metrics import median_iqr, rmse  # noqa: E402
from noisebo.models.grids import grids  # noqa: E402
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


def positions(config) -> np.ndarray:
    """The reference points (m, d) in x's units."""
    x = grids(config).x
    return x[:, None] if x.ndim == 1 else x


def truth_of(config, instrument) -> dict:
    """The simulator's optimal time at every reference point and for the whole sample (the t
    maximising the x-averaged reward), on a fine t grid."""
    s, rew = config.space, config.reward
    t = np.linspace(s.t_min, s.t_max, N_FINE)
    noise = instrument.noise_law_at(positions(config), t)
    per_x = t[np.argmax(np.asarray(reward(t[None, :], noise, rew.alpha, rew.beta)), axis=1)]
    whole = float(t[np.argmax(np.asarray(reward(t, noise.mean(axis=0), rew.alpha, rew.beta)))])
    return {"t_star_map": per_x, "t_star": whole, "f": instrument.truth(positions(config))}


def score(result, truth: dict) -> dict:
    summary = result.summary
    t_map = summary.t_opt_map if summary.t_opt_map.size else np.full(truth["t_star_map"].shape, summary.t_opt)
    err = np.abs(t_map - truth["t_star_map"]) / truth["t_star_map"]
    points = result.state.points
    return {
        "t_opt": float(summary.t_opt),
        "t_rel_error": abs(summary.t_opt - truth["t_star"]) / truth["t_star"],
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
    return {"x-independent": base.with_overrides(noise_model=noise | {"field": None}),
            "noise field": base.with_overrides(noise_model=noise | {"field": field})}


def fmt(values, scale: float = 1.0, digits: int = 1) -> str:
    m, lo, hi = median_iqr(values)
    return f"{scale * m:.{digits}f} [{scale * lo:.{digits}f}, {scale * hi:.{digits}f}]"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm.yaml"))
    parser.add_argument("--scan", default=None)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--law", choices=noise_law_names(), default=None)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    base = load_config(args.config)
    if args.scan:
        base = on_scan(base, args.scan)
    base = with_settings(base, args.set)
    if args.steps is not None:
        base = base.with_overrides(schedule={"n_steps": args.steps})
    base = validated(base)
    instrument = build(base.instrument)
    truth = truth_of(base, instrument)
    t_map = truth["t_star_map"]
    print(f"{base.name}: {base.space.dimensions} axis(es), law {base.noise_model.mean if args.law is None else args.law}, "
          f"{base.schedule.n_seed} seeds + {base.schedule.n_steps} steps; simulator t* for the whole sample "
          f"{truth['t_star']:.3f} s, t*(x) from {t_map.min():.3f} to {t_map.max():.3f} s "
          f"({100 * np.mean(np.abs(t_map / truth['t_star'] - 1) > 0.1):.0f} % of x more than 10 % away from it)",
          flush=True)
    records: dict[str, list] = {}
    for name, config in models(base, args.law).items():
        records[name] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            started = time.perf_counter()
            rec = score(run_campaign(config, instrument, seed), truth) | {"seed": seed}
            records[name].append(rec)
            print(f"{name:>13} seed {seed:3d}: t {rec['t_opt']:.3f} s ({100 * rec['t_rel_error']:.1f} %), t*(x) median "
                  f"error {100 * rec['map_median_error']:.1f} %, {100 * rec['map_within_10']:.0f} % of x within 10 %, "
                  f"RMSE {rec['rmse_f']:.3f}, {rec['time_s']:.0f} s, decision {rec['latency_s']:.3f} s, "
                  f"wall {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    print("\n| model | single t within 10 % | t*(x) error, median over x (%) | x with t*(x) within 10 % (%) "
          "| RMSE of f | instrument time (s) | decision (s) |")
    print("|---|---|---|---|---|---|---|")
    table = {}
    for name, recs in records.items():
        within = sum(r["t_rel_error"] <= 0.10 for r in recs)
        table[name] = {"single_t_within_10": within, "campaigns": len(recs),
                       **{k: median_iqr([r[k] for r in recs]) for k in
                          ("map_median_error", "map_within_10", "rmse_f", "time_s", "latency_s")}}
        print(f"| {name} | {within} of {len(recs)} | {fmt([r['map_median_error'] for r in recs], 100)} | "
              f"{fmt([r['map_within_10'] for r in recs], 100, 0)} | {fmt([r['rmse_f'] for r in recs], 1, 3)} | "
              f"{np.median([r['time_s'] for r in recs]):.0f} | {np.median([r['latency_s'] for r in recs]):.3f} |")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"config": base.model_dump(mode="json"), "t_star": truth["t_star"],
                                         "table": table, "records": records}, indent=1, default=float))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
