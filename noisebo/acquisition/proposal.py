"""The acquire stage: from the posterior, the policy's proposal of the next point (x, t and
its shots) among the times and shot counts the instrument-time budget affords."""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from noisebo.acquisition import information
from noisebo.acquisition.method import Method
from noisebo.acquisition.policies import (
    Policy,
    acquisition_map,
    argmax_2d,
    point_scores,
)
from noisebo.acquisition.records import Decision
from noisebo.acquisition.search import STARTS, refine
from noisebo.config import (
    AcquisitionConfig,
    CampaignConfig,
    RewardConfig,
    ScheduleConfig,
    SpaceConfig,
)
from noisebo.keys import PROPOSE, jax_key
from noisebo.models import inference, primary
from noisebo.models.convergence import Convergence
from noisebo.models.fitting import Fitted, hyperparameters
from noisebo.models.noise_laws import NoiseLaw
from noisebo.models.grids import (
    Grids,
    grids,
    integration_points,
    reference_spacing,
    scaled,
    space_grids,
)
from noisebo.models.prediction import (
    NoiseRows,
    Posterior,
    Prediction,
    field_rows,
    spread,
)
from noisebo.programs import label, persisted
from noisebo.precision import float64


def shots_for(is_converged: bool, schedule: ScheduleConfig) -> int:
    """Shots the next point gets: ``shots_before`` until convergence, ``shots_after`` from then
    (in the budget mode, ``shots_after`` always)."""
    return schedule.rule.shots(is_converged, schedule.shots_before, schedule.shots_after)


def _propose_program(config: CampaignConfig, policy: Policy):
    return _propose_compiled(policy, config.acquisition, config.reward, config.space, config.schedule.point_overhead_s)


@lru_cache(maxsize=None)
def _propose_compiled(
    policy: Policy, acq: AcquisitionConfig, rew: RewardConfig, space: SpaceConfig, overhead_s: float = 0.0
):
    def propose(post: Posterior, shots, allowed):
        values = acquisition_map(policy, post, shots, acq, rew, overhead_s)
        i, j = argmax_2d(jnp.where(allowed[None, :], values, -jnp.inf))
        return values, i, j

    name = (
        f"propose/{label(policy)}/{acq.model_dump_json()}/{rew.model_dump_json()}/{space.model_dump_json()}/"
        f"{overhead_s!r}"
    )
    return persisted(name, propose, depends_on=(policy,))


@lru_cache(maxsize=None)
def _propose_nd_compiled(
    policy: Policy,
    acq: AcquisitionConfig,
    rew: RewardConfig,
    space: SpaceConfig,
    primary_first: bool,
    field_law: NoiseLaw | None = None,
    overhead_s: float = 0.0,
):
    """For d > 1: the policy's map on the reference points for each shot count, then
    ``search.refine`` from the best ``STARTS`` entries over all counts (each keeps its t), a
    candidate scored at its best count; with a noise field (its law ``field_law``) each
    candidate is scored with the noise predicted where it lies. Takes the counts ``shots``
    (n_s,) and the t each may use ``allowed`` (n_s, n_t) bool. Returns the maps' maximum over t
    and counts at each reference point (m,), the proposal's scaled x (d,), its t index, score,
    the noise there at that t and the index of its count. With one count it is that count's map
    and search alone."""
    g = space_grids(space)
    xs = jnp.asarray(scaled(space, g.x))
    xi = jnp.asarray(integration_points(space))
    spacing = reference_spacing(space)
    n_t = g.t.size
    uses_spread = policy.uses_spread

    def each_count(fn, shots, allowed):  # fn(count, its allowed t) for every count, stacked
        if shots.shape[0] == 1:
            return fn(shots[0], allowed[0])[None]
        return jax.vmap(fn)(shots, allowed)

    def propose(post: Posterior, shots, fitted: Fitted, key, allowed):
        def masked_map(n, ok):
            return jnp.where(ok[None, :], acquisition_map(policy, post, n, acq, rew, overhead_s), -jnp.inf)

        values = jnp.max(each_count(masked_map, shots, allowed), axis=0)
        _, flat = jax.lax.top_k(values.ravel(), STARTS)
        i, j = flat // n_t, flat % n_t
        std = fitted.standardisation

        def noise_rows(flat):  # (n, d) scaled -> NoiseRows (n, n_t)
            rows = field_rows(field_law, space, rew, fitted, flat)
            return NoiseRows(rows.mean, rows.var)

        def scores(candidates):  # (K, P, d) scaled -> (n_s, K, P), each count's
            k, p, d = candidates.shape
            flat = candidates.reshape(k * p, d)
            mean, var = inference.combine(
                *primary.predict_samples(fitted.primary.params, fitted.primary_data, flat),
                primary_first,
                fitted.primary.weights,
            )
            raw_mean, raw_var = std.mean + std.scale * mean, std.scale**2 * var
            noise = None
            if field_law is not None:
                rows = noise_rows(flat)
                noise = NoiseRows(rows.mean.reshape(k, p, n_t), rows.var.reshape(k, p, n_t))
            q = spread(fitted, flat, xi, primary_first).reshape(k, p) if uses_spread else None
            at = jnp.broadcast_to(j[:, None], (k, p))

            def of_count(n, ok):
                found = point_scores(
                    policy, post, raw_mean.reshape(k, p), raw_var.reshape(k, p), at, n, acq, rew, noise, q, overhead_s
                )
                return jnp.where(ok[at], found, -jnp.inf)

            return each_count(of_count, shots, allowed)

        best_x, best_s = refine(lambda c: jnp.max(scores(c), axis=0), xs[i], key, spacing)
        best = jnp.argmax(best_s)
        count = jnp.argmax(scores(best_x[:, None, :])[:, best, 0])
        if field_law is None:
            noise_at = post.noise_mean[j[best]]
        else:
            noise_at = noise_rows(best_x[best][None, :]).mean[0, j[best]]
        return jnp.max(values, axis=1), best_x[best], j[best], best_s[best], noise_at, count

    laws = () if field_law is None else (field_law,)
    name = (
        f"propose_nd/{label(policy)}/{acq.model_dump_json()}/{rew.model_dump_json()}/{space.model_dump_json()}/"
        f"{primary_first}/{'/'.join(map(label, laws))}/{overhead_s!r}"
    )
    return persisted(name, propose, depends_on=(policy, *laws))


def _allowed_t(acq: AcquisitionConfig, t_grid: np.ndarray) -> np.ndarray:
    """Which t-grid entries a proposal may use: all, or the one nearest ``fixed_t``. (n_t,) bool"""
    if acq.fixed_t is None:
        return np.ones(t_grid.size, dtype=bool)
    return np.arange(t_grid.size) == int(np.argmin(np.abs(t_grid - acq.fixed_t)))


def cheapest_point_s(config: CampaignConfig) -> float:
    """The instrument time (s) of the cheapest point a decision can propose: the overhead and
    ``shots_after`` shots at the shortest t it may use."""
    g, sched = grids(config), config.schedule
    return sched.point_overhead_s + sched.shots_after * float(g.t[_allowed_t(config.acquisition, g.t)].min())


def affordable(config: CampaignConfig, shots: int, left: float | None) -> tuple[np.ndarray, int]:
    """The t-grid entries (n_t,) bool a proposal may use and its shots, within ``left`` seconds
    of budget (None: no budget): the times at which ``shots`` shots and the point's overhead fit;
    if none does, as many shots as fit at the shortest time (at least ``shots_after``, which
    the engine checked fits: ``cheapest_point_s``)."""
    g, sched = grids(config), config.schedule
    allowed = _allowed_t(config.acquisition, g.t)
    if left is None:
        return allowed, shots
    room = left - sched.point_overhead_s + 1e-9
    fits = allowed & (shots * g.t <= room)
    if fits.any():
        return fits, shots
    shortest = float(g.t[allowed].min())
    fewer = int(max(sched.shots_after, min(shots, np.floor(room / shortest))))
    return allowed & (fewer * g.t <= room), fewer


@float64
def acquire(
    config: CampaignConfig,
    method: Method,
    fitted: Fitted,
    prediction: Prediction,
    convergence: Convergence,
    step: int,
    key: jax.Array | None = None,
    budget_left: float | None = None,
) -> Decision:
    """The acquire stage: ``method``'s policy's proposal of BO step ``step`` from the posterior
    (``prediction``) and where the noise model stands (``convergence``), among the times (and
    shot counts) that fit ``budget_left`` seconds (``affordable``; None: no budget); with d > 1
    axes the local refinement draws from ``key`` (default ``propose_key(0, step)``)."""
    post = prediction.posterior
    sched = config.schedule
    t_opt, t_map, spread_t, now_converged = (
        convergence.t_opt,
        convergence.t_opt_map,
        convergence.t_interval,
        convergence.converged,
    )
    key = propose_key(0, step) if key is None else key
    choices = shot_choices(config, method.policy, now_converged, budget_left)
    if config.space.dimensions == 1:  # each count's map maximised exactly; the best count kept
        best = None
        for shots, allowed in choices:
            if allowed.any():
                found = _propose(config, method.policy, post, shots, jnp.asarray(allowed))
                if best is None or found[2] > best[2]:
                    best = found + (shots,)
        assert best is not None  # some count fits: the engine checked the cheapest point does
        x, j, acq_value, acq_map, noise_at_t, shots = best
    else:  # one search over x, t and the counts together
        x, j, acq_value, acq_map, noise_at_t, k = _propose_nd(config, method, fitted, post, key, choices)
        shots = choices[k][0]
    g = grids(config)
    rule = method.noise_t
    if rule.applies(method.policy, sched, convergence, shots):
        j = rule.choose(prediction, j, shots, affordable(config, shots, budget_left)[0], config, budget_left, step)
        noise_at_t = float(np.asarray(post.noise_mean)[j])
    if sched.adaptive_shots and not now_converged:
        shots = min(shots, noise_point_shots(post, j, x, g, sched))
    decision = Decision(
        step=step,
        x=x,
        t=float(g.t[j]),
        acq_value=acq_value,
        shots=shots,
        measure_noise=method.schedule.measures_noise(now_converged, shots),
        noise_at_t=noise_at_t,
        t_opt=t_opt,
        converged=now_converged,
        hyperparameters=hyperparameters(fitted),
        acq_map=np.asarray(acq_map, dtype=np.float32),
        f_mean=np.asarray(post.f_mean, dtype=np.float64),
        f_var=np.asarray(post.f_var, dtype=np.float64),
        noise_mean=_over_x(post.noise_mean),
        noise_var=_over_x(post.noise_var),
        primary_inputs=int(fitted.primary_inputs),
        noise_inputs=int(fitted.noise_inputs),
        binned=bool(fitted.binned),
        t_opt_map=t_map,
        t_opt_interval=spread_t,
        profile_p=float(fitted.profile.p_value),
        profile_in_use=bool(fitted.profile.in_use),
        n_points=convergence.n_points,
    )
    return decision


def shot_choices(
    config: CampaignConfig, policy: Policy, now_converged: bool, budget_left: float | None
) -> list[tuple[int, np.ndarray]]:
    """The shot counts ``policy``'s proposal chooses among, each with the t-grid entries (n_t,) bool it may
    use within ``budget_left`` (``affordable``): the schedule's count, or, for a policy that
    chooses shots once the noise model has converged, each of ``information.shot_options`` (from
    2 in the budget mode, where every point's replicate scatter informs the noise law). A
    count the budget cuts to another of the options allows no t (that one is tried as itself),
    so the list keeps its length as the budget runs out."""
    sched = config.schedule
    options = [shots_for(now_converged, sched)]
    if policy.chooses_shots and now_converged:
        least = sched.intact_noise_shots or 1  # the budget mode: every point informs the noise law
        options = list(information.shot_options(sched.shots_before, sched.shots_after, least))
    choices = []
    for wanted in options:
        allowed, shots = affordable(config, wanted, budget_left)
        if shots != wanted and len(options) > 1 and shots in options:
            allowed = np.zeros_like(allowed)
        choices.append((shots, allowed))
    return choices


def _propose(config: CampaignConfig, policy: Policy, post: Posterior, shots: int, allowed) -> tuple:
    """One axis: the policy's proposal for points of ``shots`` shots at the allowed t: x (a
    tuple), its t index, acquisition value, the acquisition map, and the noise model's sd there."""
    g = grids(config)
    noise_grid = np.asarray(post.noise_mean)
    values, i, j = _propose_program(config, policy)(post, float(shots), allowed)
    i, j, acq_map = int(i), int(j), np.asarray(values)  # index on the host: no program per index
    noise_at_t = float(noise_grid[j] if noise_grid.ndim == 1 else noise_grid[i, j])
    return (float(g.x[i]),), j, float(acq_map[i, j]), acq_map, noise_at_t


def _propose_nd(config: CampaignConfig, method: Method, fitted: Fitted, post: Posterior, key, choices) -> tuple:
    """d > 1 axes: the policy's proposal over x, t and the shot counts of ``choices``
    (``shot_choices``) in one search: x (a tuple), its t index, acquisition value, the map (the
    best over t and counts at each reference point), the noise model's sd there, and the index
    of the chosen count in ``choices``."""
    assert any(allowed.any() for _, allowed in choices)  # the engine checked the cheapest point fits
    s = config.space
    shots = jnp.asarray([float(n) for n, _ in choices])
    allowed = jnp.asarray(np.stack([a for _, a in choices]))
    acq_map, x_scaled, j, acq_value, noise_at, k = _propose_nd_program(config, method, fitted)(
        post, shots, fitted, key, allowed
    )
    lows, highs = np.asarray(s.lows), np.asarray(s.highs)
    x = tuple(float(v) for v in np.clip(lows + np.asarray(x_scaled) * (highs - lows), lows, highs))
    return x, int(j), float(acq_value), acq_map, float(noise_at), int(k)


def noise_point_shots(post: Posterior, j: int, x: tuple, g: Grids, sched) -> int:
    """``schedule.adaptive_shots``: the shots of a point whose noise is measured, as many as
    make its noise estimate as precise as the noise model already is at its t: the sample sd
    of n shots has a relative standard error of about 1/sqrt(2 (n - 1)), so n = 1 + 1 / (2 r^2)
    for the model's relative sd r = sd(Noise) / Noise there (a field: at the proposal's nearest
    reference point); at least max(2, shots_after), at most shots_before."""
    mean, var = np.asarray(post.noise_mean), np.asarray(post.noise_var)
    if mean.ndim == 2:
        i = int(np.argmin(np.sum((np.asarray(g.x).reshape(len(mean), -1) - np.asarray(x)) ** 2, axis=1)))
        mean, var = mean[i], var[i]
    r = float(np.sqrt(max(var[j], 0.0)) / max(mean[j], 1e-300))
    wanted = 1 + int(np.ceil(1.0 / (2.0 * max(r, 1e-6) ** 2)))
    return int(np.clip(wanted, max(2, sched.shots_after), sched.shots_before))


def _over_x(curves) -> np.ndarray:
    """A noise curve (n_t,) as it is; curves per position (m, n_t) averaged over the positions."""
    curves = np.asarray(curves, dtype=np.float64)
    return curves if curves.ndim == 1 else curves.mean(axis=0)


def _propose_nd_program(config: CampaignConfig, method: Method, fitted: Fitted):
    return _propose_nd_compiled(
        method.policy,
        config.acquisition,
        config.reward,
        config.space,
        fitted.primary.map_first,
        None if config.noise_model.field is None else method.noise_law,
        config.schedule.point_overhead_s,
    )


def propose_key(seed: int, step: int) -> jax.Array:
    """The key of BO step ``step``'s local refinement (d > 1 axes)."""
    return jax_key(seed, PROPOSE, step)
