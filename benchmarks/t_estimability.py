"""How well can any campaign pin t*(law)? The ideal estimator's accuracy, by Monte Carlo.

    python benchmarks/t_estimability.py [--config PATH] [--trials N]

A campaign learns the noise law from sample standard deviations: its seed points and the BO
points before convergence (``shots_before`` shots each), then the few-shot points after it. This
script draws exactly such data from the instrument's true noise law (Gaussian shots; seed times
from the configured seed design, the other points at t*), fits the law's two amplitudes by exact
maximum likelihood (s^2 (n-1) / sigma^2 is chi-squared), and reports how far the optimum of the
fitted law lands from t*. No model, prior or acquisition is involved: this is the accuracy a
campaign of that design can reach at best, for the configured design and a few alternatives.
The fitted family is the installed two-source law (``noisebo.models.noise_laws`` with p = 0.5:
A1/sqrt(t) + A0, sqrt(A1^2/t + A0^2), ...) closest to the simulator's noise law over
[t_min, t_max]; the header names it.

A second table does the same for a noise profile (``noisebo noise-profile``): the noise points of
K campaigns of the config (seed points and the BO points before convergence, no few-shot points:
the ones a profile pools) fitted together, the best any profile of K campaigns can know t* from.
t* here is t*(law), the optimum with the simulator's x-independent noise law (``_tstar.py``): the
law is what is fitted. The config is validated as ``noisebo run`` validates it (``_config.py``).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import sys
from pathlib import Path

import numpy as np
from scipy import optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config  # noqa: E402
from _tstar import LAW, law_t_star  # noqa: E402

from noisebo import registry  # noqa: E402
from noisebo.campaign.steps import seed_points  # noqa: E402

N_BEFORE_CONVERGENCE = 3  # BO points measured with shots_before: converged at step 2, the earliest


PROFILE_CAMPAIGNS = (1, 3, 5, 10, 20)  # campaigns pooled in a profile, the second table's rows


def _two_source_laws() -> tuple[str, ...]:
    """The installed noise laws with a fixed exponent (p = 0.5), the ones fitted here."""
    return tuple(n for n in registry.noise_law_names() if not registry.noise_law(n).infers_exponent)


def law_amplitudes(noise_law, t_min: float, t_max: float) -> tuple[str, float, float]:
    """The installed two-source law closest to ``noise_law`` on a log grid over [t_min, t_max]
    (relative least squares; Noise^k = A0^k + (A1 t^-1/2)^k is linear in A0^k, A1^k for the law's
    ``sources_power`` k): its name (e.g. "inv_sqrt", "quadrature"), A0 and A1 (noise units)."""
    t = np.geomspace(t_min, t_max, 64)
    noise = noise_law(t)
    best = None
    for law in _two_source_laws():
        power = registry.noise_law(law).sources_power
        design = np.column_stack([np.ones_like(t), t ** (-0.5 * power)]) / noise[:, None] ** power
        coef, *_ = np.linalg.lstsq(design, np.ones_like(t), rcond=None)
        amplitudes = np.maximum(coef, 0.0) ** (1.0 / power)
        error = float(np.sum((law_noise(law, t, *amplitudes) / noise - 1.0) ** 2))
        if best is None or error < best[0]:
            best = (error, law, float(amplitudes[0]), float(amplitudes[1]))
    assert best is not None
    return best[1], best[2], best[3]


def law_noise(law: str, t: np.ndarray, a0: float, a1: float) -> np.ndarray:
    """Noise(t) (numpy) of the installed noise law ``law`` with amplitudes A0, A1."""
    return np.asarray(registry.noise_law(law).mean(t, a0, a1), dtype=np.float64)


def fitted_t_opt(t, s, n, grid, alpha, beta, law: str) -> float:
    """Optimum of the reward along ``law`` fitted to sample sds s (n shots each) by chi-squared
    maximum likelihood."""

    def nll(log_params):
        var = law_noise(law, t, *np.exp(log_params)) ** 2
        return float(np.sum((n - 1) * (s**2 / var + np.log(var))))

    power = registry.noise_law(law).sources_power
    start = np.log([np.mean(s**power) / 2, np.mean(s**power * t ** (power / 2)) / 2]) / power
    best = optimize.minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9}).x
    return float(grid[np.argmax(-alpha * grid**2 - beta * law_noise(law, grid, *np.exp(best)))])


def _noise_points(config, seed: int, t_star: float, after: bool) -> tuple[np.ndarray, np.ndarray]:
    """One campaign's noise points: t (s) and shots. Its seed points and the BO points before
    convergence at t*, ``shots_before`` each; with ``after``, the few-shot points after it too."""
    sched = config.schedule
    n_after = max(sched.n_steps - N_BEFORE_CONVERGENCE, 0) if after else 0
    t = np.concatenate([seed_points(config, seed)[:, 1], np.full(N_BEFORE_CONVERGENCE + n_after, t_star)])
    n = np.array([sched.shots_before] * (sched.n_seed + N_BEFORE_CONVERGENCE) + [sched.shots_after] * n_after)
    return t, n


def simulate(config, noise_law, t_star: float, trials: int, law: str, campaigns: int = 0) -> np.ndarray:
    """|t_opt - t*| / t* over ``trials`` campaigns of this design (seed design from the config),
    or, with ``campaigns`` K > 0, over ``trials`` profiles, each pooling K campaigns' noise points."""
    s, rew = config.space, config.reward
    grid = np.linspace(s.t_min, s.t_max, 4001)
    rng = np.random.default_rng(0)
    errors = []
    for trial in range(trials):
        if campaigns:
            pieces = [_noise_points(config, trial * campaigns + c, t_star, after=False) for c in range(campaigns)]
            t, n = (np.concatenate(part) for part in zip(*pieces))
        else:
            t, n = _noise_points(config, trial, t_star, after=True)
        true_sd = noise_law(t)
        sd = np.array([np.std(rng.normal(0.0, sigma, k), ddof=1) for sigma, k in zip(true_sd, n)])
        errors.append(abs(fitted_t_opt(t, sd, n, grid, rew.alpha, rew.beta, law) / t_star - 1.0))
    return np.asarray(errors)


def _shares(errors: np.ndarray) -> str:
    return f"{100 * np.median(errors):.1f} % | {100 * np.mean(errors <= 0.05):.0f} % | {100 * np.mean(errors <= 0.10):.0f} %"


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "pfm.yaml"))
    parser.add_argument("--trials", type=int, default=400)
    args = parser.parse_args(argv)
    base, instrument = benchmark_config(parser, args.config)
    s = base.space
    t_star = law_t_star(base, instrument)
    law, a0, a1 = law_amplitudes(instrument.noise_law, s.t_min, s.t_max)
    floor = a0**2 / law_noise(law, np.array([t_star]), a0, a1)[0] ** 2
    print(
        f"{base.name}: t* = {LAW} = {t_star:.4f} s (the optimum with the x-independent noise law); true law ~ {law} (the installed law fitted here) with A1 = {a1:.3f}, A0 = {a0:.3f} "
        f"(A0 is {100 * floor:.0f} % of the noise variance at t*); {args.trials} trials"
    )
    print(
        "| seed times | shots before convergence | median abs(t_opt - t*)/t* | within 5 % | within 10 % |\n|---|---|---|---|---|"
    )
    for scale in ("log", "log_span"):
        for shots in sorted({base.schedule.shots_before, 30, 50, 100}):
            config = base.with_overrides(schedule={"seed_t_scale": scale, "shots_before": shots})
            errors = simulate(config, instrument.noise_law, t_star, args.trials, law)
            mark = " (config)" if (scale, shots) == (base.schedule.seed_t_scale, base.schedule.shots_before) else ""
            print(f"| {scale}{mark} | {shots} | {_shares(errors)} |", flush=True)
    sched = base.schedule
    print(
        f"\nA profile of K campaigns of the config ({sched.n_seed} seed points ({sched.seed_t_scale}) and "
        f"{N_BEFORE_CONVERGENCE} at t*, {sched.shots_before} shots each, per campaign), fitted together:"
    )
    print("| campaigns | noise points | median abs(t_opt - t*)/t* | within 5 % | within 10 % |\n|---|---|---|---|---|")
    for k in PROFILE_CAMPAIGNS:
        errors = simulate(base, instrument.noise_law, t_star, args.trials, law, campaigns=k)
        print(f"| {k} | {k * (sched.n_seed + N_BEFORE_CONVERGENCE)} | {_shares(errors)} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
