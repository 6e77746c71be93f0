"""What one decision of BoTorch's own acquisition code costs on a budget campaign's data, and why
the BoTorch peer designs (``benchmarks/_botorch.py``) compute qNIPV in closed form and do not use
the multi-fidelity tutorials' knowledge gradient.

    python benchmarks/botorch_kg.py [--points 50,200] [--config PATH]

For each number of points n: n points of the config's instrument at random (x, t) (3 shots each,
noisebo's shots), the peer's two models fitted to them, then the wall time of

- "qNIPV Monte Carlo, every grid candidate": ``qNegIntegratedPosteriorVariance`` over the
  integration points, less its current value, per second (``InverseCostWeightedUtility``), at
  every (x, t) of the grids (``optimize_acqf_discrete``, as the peer's ask is defined);
- "qNIPV closed form (the peer's)": the same values by ``_botorch.variance_removed``; the largest
  difference from the Monte Carlo values is printed (relative);
- "qMFKG, the tutorials' settings": ``qMultiFidelityKnowledgeGradient`` on the multi-fidelity
  model with the current value and optimisation of BoTorch's multi-fidelity tutorials (64
  fantasies, 5 restarts, 128 raw samples, 200 iterations, batch limit 5), one decision.

One thread (as the peers run); figures are one run each, on whatever the machine is doing.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads
import argparse
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import _botorch  # noqa: E402
from _config import validated_config  # noqa: E402
from _peer import PeerCampaign  # noqa: E402

from noisebo.instruments import build  # noqa: E402
from noisebo.models.grids import grids, integration_points  # noqa: E402

FANTASIES, RESTARTS, RAW_SAMPLES = 64, 5, 128  # the multi-fidelity tutorials' settings
OPTIONS = {"batch_limit": 5, "maxiter": 200}


def measured(config, n: int, seed: int = 0):
    """(x, t, value, variance of the mean) of n points at random (x, t), 3 shots each."""
    rng = np.random.default_rng(seed)
    s = config.space
    campaign = PeerCampaign(config, build(config.instrument), seed, "latency")
    xs = s.lows[0] + rng.random(n) * (s.highs[0] - s.lows[0])
    ts = np.exp(rng.uniform(np.log(s.t_min), np.log(s.t_max), n))
    values, variances = zip(*[campaign.measure([x], t, 3)[:2] for x, t in zip(xs, ts)])
    return xs, ts, np.asarray(values), np.asarray(variances)


def timed(f):
    tick = time.perf_counter()
    out = f()
    return out, time.perf_counter() - tick


def knowledge_gradient(model, enc, shots: int, overhead: float):
    import torch
    from botorch.acquisition import PosteriorMean, qMultiFidelityKnowledgeGradient
    from botorch.acquisition.cost_aware import InverseCostWeightedUtility
    from botorch.acquisition.fixed_feature import FixedFeatureAcquisitionFunction
    from botorch.acquisition.utils import project_to_target_fidelity
    from botorch.optim import optimize_acqf

    d = enc.d
    target = FixedFeatureAcquisitionFunction(PosteriorMean(model), d=d + 1, columns=[d], values=[1.0])
    unit = torch.stack([torch.zeros(d, dtype=torch.float64), torch.ones(d, dtype=torch.float64)])
    _, current = optimize_acqf(
        target, bounds=unit, q=1, num_restarts=RESTARTS, raw_samples=RAW_SAMPLES, options=OPTIONS
    )
    kg = qMultiFidelityKnowledgeGradient(
        model,
        num_fantasies=FANTASIES,
        current_value=current,
        cost_aware_utility=InverseCostWeightedUtility(_botorch.instrument_time_model(enc, shots, overhead)),
        project=partial(project_to_target_fidelity, target_fidelities={d: 1.0}, d=d + 1),
    )
    bounds = _botorch._tensor([[0.0] * d + [enc.t_min / enc.t_max], [1.0] * (d + 1)])
    return optimize_acqf(kg, bounds=bounds, q=1, num_restarts=RESTARTS, raw_samples=RAW_SAMPLES, options=OPTIONS)


def one(config, n: int) -> list[str]:
    import torch
    from botorch.acquisition import AcquisitionFunction, qNegIntegratedPosteriorVariance
    from botorch.acquisition.cost_aware import InverseCostWeightedUtility
    from botorch.optim import optimize_acqf_discrete

    s, shots, overhead = config.space, 3, float(config.schedule.point_overhead_s)
    g = grids(config)
    xs, ts, values, variances = measured(config, n)
    lines = []
    with _botorch._quiet_and_seeded(0):
        enc = _botorch._Encoding(config, fidelity=False)
        model = _botorch._fitted(_botorch._cost_aware_model, enc.inputs(xs, ts), values, variances, None)
        mc = _botorch._target_fidelity(enc, enc.inputs(np.asarray(integration_points(s)).reshape(-1, 1), s.t_min))
        choices = _botorch.grid_inputs(enc, np.asarray(g.x).reshape(-1, 1), g.t)
        per_second = InverseCostWeightedUtility(_botorch.instrument_time_model(enc, shots, overhead))
        nipv = qNegIntegratedPosteriorVariance(model, mc_points=mc)
        with torch.no_grad():
            now = -model.posterior(mc).variance.mean()

        class PerSecond(AcquisitionFunction):
            def forward(self, X):
                return per_second(X, deltas=nipv(X) - now)

        _, mc_s = timed(lambda: optimize_acqf_discrete(PerSecond(model), q=1, choices=choices, max_batch_size=256))
        closed, closed_s = timed(lambda: _botorch.variance_removed(model, mc, choices))
        sample = choices[:: max(1, len(choices) // 200)]
        with torch.no_grad():
            reference = nipv(sample.unsqueeze(-2)) - now
        gap = float(
            torch.max(torch.abs(_botorch.variance_removed(model, mc, sample) - reference) / reference.abs().max())
        )
        lines.append(f"n = {n}: qNIPV Monte Carlo, every grid candidate ({len(choices)}): {mc_s:.2f} s")
        lines.append(
            f"n = {n}: qNIPV closed form (the peer's): {closed_s:.3f} s (largest difference {gap:.1e} of the largest value)"
        )
        enc_f = _botorch._Encoding(config, fidelity=True)
        mf = _botorch._fitted(partial(_botorch._multi_fidelity_model, 1), enc_f.inputs(xs, ts), values, variances, None)
        _, kg_s = timed(lambda: knowledge_gradient(mf, enc_f, shots, overhead))
        lines.append(f"n = {n}: qMFKG, the tutorials' settings: {kg_s:.1f} s")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", default="50,200", help="numbers of points, comma-separated")
    parser.add_argument("--config", type=Path, default=ROOT / "data" / "configs" / "forrester.yaml")
    args = parser.parse_args(argv)
    missing = _botorch.available()
    if missing:
        parser.error(missing)
    config = validated_config(args.config, lambda c: c.with_overrides(schedule={"budget_s": None}))
    if config.space.dimensions != 1:
        parser.error("one axis only: the config's space has more")
    for n in (int(v) for v in args.points.split(",")):
        for line in one(config, n):
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
