"""The noise field's part of a decision (``noise_model.field`` set): fit Noise(x, t) on a
campaign's points, and predict it where the policies look, with the optimal time t*(x).

The x-independent noise model gives one curve over the t grid for every x; the field gives one
curve per position. Everything here returns the field's predictions in the value's units
(``noise_field`` works over a data scale) and in the shapes the policies take: positions (m,)
by the t grid (n_t,), and per position t*(x) on the fine t grid with the noise there.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from noisebo.config import CampaignConfig
from noisebo.models import field_profile_check, inference, noise_field, noise_model
from noisebo.models.profile_check import ProfileCheck
from noisebo.models.inputs import capacity_for
from noisebo.models.noise_laws import NoiseLaw
from noisebo.models.reward import reward
from noisebo.state import CampaignState

# Prior draws of a multi-start field fit besides the data-driven guess: a draw of the field's
# hundreds of basis weights is a random field, a poor start, and each costs a whole L-BFGS run.
FIELD_RESTARTS = 2


class FieldRows(NamedTuple):
    """The noise at m positions, value units: ``mean``, ``var`` (m, n_t) on the t grid (the
    Laplace draws' spread in the variance); ``t_opt`` (m,) the fine-grid t maximising the reward
    R(t, Noise(x, t)) at each position (s); ``at_t_opt`` (m,) Noise there; ``fine`` (m, N_FINE)
    the MAP curve on the fine grid; ``draws`` (S, n_t) each posterior draw's curve on the t grid
    averaged over the positions."""

    mean: jnp.ndarray
    var: jnp.ndarray
    t_opt: jnp.ndarray
    at_t_opt: jnp.ndarray
    fine: jnp.ndarray
    draws: jnp.ndarray


def t_capacity(distinct: int) -> int:
    """The padded number of distinct t values of the field's data (``capacity_for``). Each
    evaluation of the field's likelihood factors a matrix of this size, so it grows with the
    campaign's distinct times rather than being fixed at the grid's: crossing a capacity (32,
    64, ...) compiles the decision's programs again, once."""
    return capacity_for(distinct)


def training_mask(config: CampaignConfig, state: CampaignState) -> np.ndarray:
    """(n,) bool: the points that train the noise law or field (``CampaignState.noise_training_mask``
    with the config's ``learn_after_convergence``, ``shots_after`` and ``intact_noise_shots``)."""
    sched = config.schedule
    return state.noise_training_mask(
        config.noise_model.learn_after_convergence, sched.shots_after, sched.intact_noise_shots
    )


def training_inputs(config: CampaignConfig, state: CampaignState, scaled_positions: np.ndarray):
    """The points that train the noise model (``training_mask``): scaled positions (k, d), t (k,)
    s, sample sd (k,) and shots (k,)."""
    train = training_mask(config, state)
    return (
        scaled_positions[train],
        state.column("t")[train],
        state.column("shot_std")[train],
        state.column("n_shots")[train],
    )


def groups_needed(config: CampaignConfig, state: CampaignState, scaled_positions: np.ndarray) -> int:
    """How many (x, t) groups the field's data will hold: one per distinct position and time."""
    x, t, _, _ = training_inputs(config, state, scaled_positions)
    if not t.size:
        return 0
    return int(np.unique(np.column_stack([x, t]), axis=0).shape[0])


def previous_field(previous: dict | None, data: noise_field.FieldData) -> dict | None:
    """The previous decision's field hyperparameters (``noise.g0_amplitude``, ...) if it has
    every one ``data`` needs, finite and positive; else None."""
    if not previous:
        return None
    wanted = noise_field.field_hyperparameters(data)
    found = {name: previous.get(f"noise.{name}") for name in wanted}
    if not all(v is not None and np.isfinite(v) and v > 0 for v in found.values()):
        return None
    return found


def previous_law(previous: dict | None, data: noise_field.FieldData, scale: float) -> dict | None:
    """The previous decision's law (a0, a1, p, the residual's amplitude and length) in ``data``'s
    scaled units, inside the prior's bounds, as a start for the next fit; None if it lacks one."""
    if not previous:
        return None
    names = [k.split(".", 1)[1] for k in previous if k.startswith("noise.") and not k.startswith("noise.g")]
    law = {name: previous[f"noise.{name}"] for name in names}
    if not {"a0", "a1", "amplitude", "length"} <= set(law) or not all(np.isfinite(v) and v > 0 for v in law.values()):
        return None
    bounds = np.asarray(data.bounds)
    for row, name in enumerate(("a0", "a1", "p")):
        if name in law:
            value = law[name] / scale if name in ("a0", "a1") else law[name]
            lo, hi = float(bounds[row, 0]), float(bounds[row, 1])
            law[name] = float(np.clip(value, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo)))
    return law


def fit_field(
    config: CampaignConfig,
    law: NoiseLaw,
    state: CampaignState,
    scaled_positions: np.ndarray,
    key: jax.Array,
    previous: dict | None,
    warm: bool,
    capacity: int | None,
) -> tuple[inference.Samples, noise_field.FieldData, float, int, bool, ProfileCheck]:
    """Fit the noise field on the campaign's noise-training points.

    The field's amplitude and lengths are re-estimated every step (``noise_field.estimate_field``)
    from the previous step's values when there are any. The MAP fit starts from the data-driven
    guess and from the previous step's law (its fields refitted to the data): with few
    noise-measured points the guess alone can fall into a basin where the fields explain the
    t-dependence and A1 goes to 0. A warm step (``decision.warm_step``) stops there; the other
    steps also scan the field's shapes and add ``FIELD_RESTARTS`` prior draws. Returns the samples (the MAP point then the
    Laplace draws), the data holding the hyperparameters used, the data scale (noise units), the
    number of (x, t) groups, whether t was binned and the noise profile's check
    (``field_profile_check``; while the profile is in use its means are one more start)."""
    nm, s, inf = config.noise_model, config.space, config.inference
    x, t, std, shots = training_inputs(config, state, scaled_positions)
    distinct = min(int(np.unique(t).size), inf.max_inputs_for(1))
    field = nm.field
    assert field is not None  # fit_field runs for a noise field only
    spans = np.asarray(s.highs) - np.asarray(s.lows)
    check = field_profile_check.verdict(nm, law, state.profile_dropped_step is not None, x, spans, t, std, shots)
    data, scale, groups = noise_field.prepare(
        x,
        t,
        std,
        shots,
        nm,
        field,
        s.t_min,
        s.t_max,
        inf.max_inputs_for(1),
        capacity,
        t_capacity(distinct),
        check.in_use,
    )
    hyper = previous_field(previous, data)
    if hyper is not None:
        data = noise_field.set_field(data, hyper)
    before = previous_law(previous, data, scale)
    starts = ([before] if before else []) + ([] if warm else noise_model.profile_guess(data, nm, law))
    samples, data = noise_field.fit(
        data,
        nm,
        law,
        field,
        key,
        FIELD_RESTARTS,
        inf.laplace_samples,
        guesses=starts,
        draws=not warm,
        scan=not (warm and hyper is not None),
    )
    return samples, data, scale, groups.count.size, groups.binned, check


def rows(
    law: NoiseLaw,
    samples: inference.Samples,
    data: noise_field.FieldData,
    scale,
    xs: jnp.ndarray,
    t: jnp.ndarray,
    ts: jnp.ndarray,
    t_fine: jnp.ndarray,
    ts_fine: jnp.ndarray,
    alpha: float,
    beta: float,
) -> FieldRows:
    """The field at scaled positions xs (m, d) over the t grid t (n_t,) s / ts scaled, and its
    t*(x) on the fine grid t_fine / ts_fine (k,): value units. The mean is the MAP point's, the
    variance adds the Laplace draws' spread (``inference.combine``); t*(x) maximises R on the
    MAP curve, which is linear in Noise, so the posterior mean gives the expected reward's best."""
    means, variances = noise_field.predict_samples(law, samples.params, data, xs, t, ts)
    mean, var = inference.combine(means, variances, True)
    first = {name: value[:1] for name, value in samples.params.items()}
    fine = noise_field.predict_samples(law, first, data, xs, t_fine, ts_fine)[0][0] * scale
    best = jnp.argmax(reward(t_fine[None, :], fine, alpha, beta), axis=-1)
    at = jnp.take_along_axis(fine, best[:, None], axis=-1)[:, 0]
    return FieldRows(mean * scale, var * scale**2, t_fine[best], at, fine, jnp.mean(means, axis=1) * scale)


def best_training_reward(
    law: NoiseLaw,
    samples: inference.Samples,
    data: noise_field.FieldData,
    scale,
    t: jnp.ndarray,
    t_min: float,
    t_max: float,
    alpha: float,
    beta: float,
) -> jnp.ndarray:
    """The incumbent of the time acquisition: the largest normalised reward of a training group,
    each normalised over the t grid t (n_t,) at its own position (as the policies normalise the
    reward per position), from the MAP curve. A scalar."""
    first = {name: value[0] for name, value in samples.params.items()}
    t_nodes = t_min + data.t_nodes * (t_max - t_min)
    t_all = jnp.concatenate([t, t_nodes])
    ts_all = (t_all - t_min) / (t_max - t_min)
    mean, _ = noise_field.predict_one(law, first, data, data.x, t_all, ts_all)
    r = reward(t_all[None, :], mean * scale, alpha, beta)
    n_t = t.shape[0]
    lo, hi = jnp.min(r[:, :n_t], axis=1), jnp.max(r[:, :n_t], axis=1)
    span = hi - lo
    own = jnp.take_along_axis(r[:, n_t:], data.tid[:, None], axis=1)[:, 0]
    normalised = (own - lo) / jnp.where(span > 0, span, 1.0)
    return jnp.max(jnp.where(data.mask, normalised, -jnp.inf))


def hyperparameters(samples: inference.Samples, data: noise_field.FieldData, scale: float) -> dict[str, float]:
    """The field's point summaries as ``decision.hyperparameters`` names them (without the
    "noise." prefix): the law's levels a0, a1 in value units (A0(x) = a0 exp(g0(x))), p, the
    residual's amplitude and length, and the fields' amplitudes and lengths; not the basis
    weights (hundreds per field)."""
    out = {}
    for name, values in samples.params.items():
        v = np.asarray(values)
        if v.ndim > 1:
            continue
        out[name] = float(v[0]) * (scale if name in ("a0", "a1") else 1.0)
    return out | noise_field.field_hyperparameters(data)
