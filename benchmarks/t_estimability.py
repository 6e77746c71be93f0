"""How well can any campaign pin t*(law)? The ideal estimator's accuracy, by Monte Carlo.

    python benchmarks/t_estimability.py [--config PATH] [--trials N]

A campaign learns the noise law from sample standard deviations: its seed points and the BO
points before convergence (``shots_before`` shots each), then the few-shot points after it. This
script draws exactly such data from the instrument's true noise law (Gaussian shots; seed times
from the configured seed design, the other points at t*), fits the law's two amplitudes by exact
maximum likelihood (s^2 (n-1) / sigma^2 is chi-squared), and reports how far the optimum of the
fitted law lands from t*. No model, prior or acquisition is involved: this is the accuracy a
campaign of that design can reach at best, for the configured design and a few alternatives.
t* here is t*(law), the optimum with the simulator's x-independent noise law (``_tstar.py``): the
law is what is fitted. The config is validated as ``noisebo run`` validates it (``_config.py``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config  # noqa: E402
from _tstar import LAW, law_t_star  # noqa: E402

from noisebo.campaign.steps import seed_points  # noqa: E402

N_BEFORE_CONVERGENCE = 3  # BO points measured with shots_before: converged at step 2, the earliest


def law_amplitudes(noise_law, t_min: float, t_max: float) -> tuple[float, float]:
    """(A0, A1) of sqrt(A1^2/t + A0^2) fitted to the true law on a log grid (relative least squares)."""
    t = np.geomspace(t_min, t_max, 64)
    var = noise_law(t) ** 2
    design = np.column_stack([np.ones_like(t), 1.0 / t]) / var[:, None]
    (a0_sq, a1_sq), *_ = np.linalg.lstsq(design, np.ones_like(t), rcond=None)
    return float(np.sqrt(max(a0_sq, 0.0))), float(np.sqrt(max(a1_sq, 0.0)))


def fitted_t_opt(t, s, n, grid, alpha, beta) -> float:
    """Optimum of the reward along the chi-squared maximum-likelihood law for sample sds s."""

    def nll(log_params):
        a0_sq, a1_sq = np.exp(log_params)
        var = a1_sq / t + a0_sq
        return float(np.sum((n - 1) * (s**2 / var + np.log(var))))

    start = np.log([np.mean(s) ** 2 / 2, np.mean(s**2 * t) / 2])
    best = optimize.minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9}).x
    a0_sq, a1_sq = np.exp(best)
    return float(grid[np.argmax(-alpha * grid**2 - beta * np.sqrt(a1_sq / grid + a0_sq))])


def simulate(config, noise_law, t_star: float, trials: int) -> np.ndarray:
    """|t_opt - t*| / t* over ``trials`` campaigns of this design (seed design from the config)."""
    s, sched, rew = config.space, config.schedule, config.reward
    grid = np.linspace(s.t_min, s.t_max, 4001)
    rng = np.random.default_rng(0)
    n_after = max(sched.n_steps - N_BEFORE_CONVERGENCE, 0)
    errors = []
    for trial in range(trials):
        t = np.concatenate([seed_points(config, trial)[:, 1], np.full(N_BEFORE_CONVERGENCE + n_after, t_star)])
        n = np.array([sched.shots_before] * (sched.n_seed + N_BEFORE_CONVERGENCE) + [sched.shots_after] * n_after)
        true_sd = noise_law(t)
        sd = np.array([np.std(rng.normal(0.0, sigma, k), ddof=1) for sigma, k in zip(true_sd, n)])
        errors.append(abs(fitted_t_opt(t, sd, n, grid, rew.alpha, rew.beta) / t_star - 1.0))
    return np.asarray(errors)


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm.yaml"))
    parser.add_argument("--trials", type=int, default=400)
    args = parser.parse_args(argv)
    base, instrument = benchmark_config(parser, args.config)
    s = base.space
    t_star = law_t_star(base, instrument)
    a0, a1 = law_amplitudes(instrument.noise_law, s.t_min, s.t_max)
    print(
        f"{base.name}: t* = {LAW} = {t_star:.4f} s (the optimum with the x-independent noise law); true law ~ sqrt(A1^2/t + A0^2) with A1 = {a1:.3f}, A0 = {a0:.3f} "
        f"(A0 is {100 * a0**2 / (a1**2 / t_star + a0**2):.0f} % of the noise variance at t*); {args.trials} trials"
    )
    print("| seed times | shots before convergence | median abs(t_opt - t*)/t* | within 10 % |\n|---|---|---|---|")
    for scale in ("log", "log_span"):
        for shots in sorted({base.schedule.shots_before, 30, 50, 100}):
            config = base.with_overrides(schedule={"seed_t_scale": scale, "shots_before": shots})
            errors = simulate(config, instrument.noise_law, t_star, args.trials)
            mark = " (config)" if (scale, shots) == (base.schedule.seed_t_scale, base.schedule.shots_before) else ""
            print(
                f"| {scale}{mark} | {shots} | {100 * np.median(errors):.1f} % | {100 * np.mean(errors <= 0.10):.0f} % |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
