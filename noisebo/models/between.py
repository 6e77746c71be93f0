"""A hierarchical prior between the noise laws of several instruments
(``noise_model.between_instruments``, with a law per instrument).

Instruments of one kind are alike but not equal: each instrument's law parameter theta_k (A0,
A1, p) is drawn about the fleet's mu, theta_k ~ N(mu, (tau mu)^2) for A0 and A1 (tau the
configured relative spread), N(mu, tau^2) for p. The decision made for instrument i learns its
law from its own points under the prior this hierarchy gives it from the other instruments:
each other instrument j's law is fitted on its own points alone (posterior mean m_j, sd s_j);
with mu flat and m the mean of the k values m_j,

    theta_i ~ N(m, spread^2 (1 + 1/k) + sum_j s_j^2 / k^2),   spread = tau |m| (tau for p),

the spread of one instrument about the fleet plus the uncertainty of the fleet's value. A
small tau all but shares the parameter; a parameter without one is the instrument's own. The
fleet's spread is the config's, not learned: two or three instruments cannot tell it.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import numpy as np

from noisebo.config import CampaignConfig
from noisebo.models.fitting import fit_noise_model, warm_step
from noisebo.models.noise_laws import NoiseLaw
from noisebo.models.profile import law_draws
from noisebo.state import CampaignState

PARAMETERS = ("a0", "a1", "p")


class Other(NamedTuple):
    """What the prior reads of another instrument: its own points and the hyperparameters of the
    last decision made for it (None before its first), the fit's start."""

    points: CampaignState
    previous: dict | None = None


def law_posterior(
    config: CampaignConfig, law: NoiseLaw, state: CampaignState, key: jax.Array, previous=None, warm=False
) -> dict:
    """The noise law fitted on ``state``'s points alone (no prior between instruments), from
    ``previous`` hyperparameters (alone when ``warm``, ``fit_noise_model``): each parameter's
    (mean, sd) over the fit's draws, A0 and A1 in value units."""
    fit = fit_noise_model(config, law, state, key, previous, warm)
    draws = law_draws(fit.samples.params, fit.scale)
    return {name: (float(np.mean(values)), float(np.std(values))) for name, values in draws.items()}


def fleet_prior(
    config: CampaignConfig, law: NoiseLaw, others: Sequence[Other], key: jax.Array, step: int = 0
) -> np.ndarray | None:
    """The prior of one instrument's law, for BO step ``step``, from the ``others`` (each other
    instrument with enough points of its own): (3, 3), rows a0, a1, p of (loc, sd, weight) in
    value units, weight 0 for a parameter the config does not pool (module docstring). None
    without others. Each other's fit draws from ``key`` folded with its index, and starts from
    the last decision made for it alone but on the steps that restart (``warm_step``): that
    decision's fit, of the same points under a prior, is a start near their own mode, and costs
    a few ms where a fresh search costs a few hundred."""
    pooled = config.noise_model.between_instruments
    if pooled is None or not others:
        return None
    fits = [
        law_posterior(
            config,
            law,
            other.points,
            jax.random.fold_in(key, k + 1),
            other.previous,
            warm_step(config, step, other.previous, True),
        )
        for k, other in enumerate(others)
    ]
    bounds = dict(
        zip(PARAMETERS, (config.noise_model.a0_prior, config.noise_model.a1_prior, config.noise_model.p_prior))
    )
    rows = np.array([[0.0, 1.0, 0.0]] * 3)
    for row, name in enumerate(PARAMETERS):
        tau = pooled.spreads.get(name)
        if tau is None or name not in fits[0]:
            continue
        means = np.array([fit[name][0] for fit in fits])
        sds = np.array([fit[name][1] for fit in fits])
        k, loc = len(fits), float(means.mean())
        spread = tau * (abs(loc) if name != "p" else 1.0)
        sd = np.sqrt(spread**2 * (1.0 + 1.0 / k) + np.sum(sds**2) / k**2)
        floor = 1e-6 * (bounds[name].high - bounds[name].low)  # a very narrow prior, never none
        rows[row] = [loc, max(float(sd), floor), 1.0]
    return rows
