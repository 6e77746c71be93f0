"""Where the BoTorch cost-aware peer's map goes wrong: one campaign of ``benchmarks/_botorch.py``
on a budget setting, then its final model's map of f read at several t (the benchmark reads it at
t_max), scored as the budget benchmark scores, and the model's fitted length scales.

    python benchmarks/botorch_map_at_t.py [--config PATH] [--budget S] [--overhead S] [--seed N]

A model that takes the scatter of short-exposure points for changes of f with t has a short
length scale on u (ln t scaled to [0, 1]) and a map that differs with the t it is read at; f
itself does not depend on t.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import _botorch  # noqa: E402
import budget  # noqa: E402
from _config import Parser, benchmark_config  # noqa: E402
from _tstar import LAW, t_stars  # noqa: E402

from noisebo.models.grids import grids  # noqa: E402


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm.yaml"))
    parser.add_argument("--budget", type=float, default=300.0)
    parser.add_argument("--overhead", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=2)
    args = parser.parse_args(argv)
    if (missing := _botorch.available()) is not None:
        parser.error(missing)
    config, instrument = benchmark_config(
        parser,
        args.config,
        lambda c: c.with_overrides(
            schedule={"budget_s": args.budget, "point_overhead_s": args.overhead, "n_steps": budget.NO_STEP_LIMIT}
        ),
    )
    if config.space.dimensions != 1:
        parser.error("one axis only: the config's space has more")
    score = budget.scorer(config, instrument)
    fitted = []
    fit = _botorch._fitted

    def keeping(*a, **k):
        model = fit(*a, **k)
        fitted.append(model)
        return model

    _botorch._fitted = keeping
    record = _botorch.run_cost_aware(config, instrument, args.seed, score, t_stars(config, instrument)[LAW])
    model, enc, s = fitted[-1], _botorch._Encoding(config, fidelity=False), config.space
    x = np.asarray(grids(config).x).reshape(-1, 1)
    print(f"{config.name}, seed {args.seed}: {record['points']} points, {record['spent_s']:.0f} s")
    for t in np.geomspace(s.t_min, s.t_max, 5):
        print(f"map read at t = {t:.3g} s: RMSE {score(_botorch._mean_at(model, enc.inputs(x, t))):.3g}")
    scales = model.covar_module.lengthscale.detach().reshape(-1).numpy()
    print(f"fitted length scales (unit box): x {scales[0]:.3g}, u = scaled ln t {scales[1]:.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
