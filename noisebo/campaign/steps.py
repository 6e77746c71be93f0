"""The campaign's steps as pure functions: seed points, a point from its shots, and the final
summary. The engine (``noisebo.campaign.engine``) sequences them; every random draw is keyed by
(campaign seed, point, shot), so one seed always gives one campaign."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from noisebo.config import CampaignConfig, ReductionConfig
from noisebo.events import Summary
from noisebo.keys import SEED_POINTS, numpy_rng
from noisebo.models.grids import grids
from noisebo.reduction import (
    ShotValue,
    clip_outliers,
    reduce_shots,
    shot_values,
    usable,
)
from noisebo.state import CampaignState, Point, as_position
from noisebo.precision import float64


def seed_points(config: CampaignConfig, seed: int) -> np.ndarray:
    """(n_seed, d + 1) random seed locations: the d coordinates of x, then t.

    "latin_hypercube" (default) stratifies every axis, t on a log scale: the seeds then span the
    exposure range, from a short, cheap shot to a long one, which separates A0 from A1 in the
    noise model from the start. "uniform" draws each coordinate uniformly. ``seed_t_scale``
    "log_span" replaces the random t by n values evenly spaced on a log scale from t_min to t_max
    inclusive (in random order): the ends of the range are where the two terms of the noise law
    differ most, so they pin A0 and A1 best; "shortest" puts every seed at t_min, the cheapest
    point, for a campaign whose noise profile already gives the law (seeds spread over t would
    pay for knowledge it has). With a noise field (``noise_model.field``) the seeds come in pairs
    at one position (``paired_positions``)."""
    s, sched = config.space, config.schedule
    n, d = sched.n_seed, s.dimensions
    rng = numpy_rng(seed, SEED_POINTS)
    if sched.seed_design == "latin_hypercube":
        strata = np.column_stack([rng.permutation(n) for _ in range(d + 1)])
        u = (strata + rng.random((n, d + 1))) / n
    else:
        u = rng.random((n, d + 1))
    lows, highs = np.asarray(s.lows), np.asarray(s.highs)
    x = lows + u[:, :d] * (highs - lows)
    if sched.seed_t_scale == "log":
        t = s.t_min * (s.t_max / s.t_min) ** u[:, d]
    elif sched.seed_t_scale == "log_span":
        t = s.t_min * (s.t_max / s.t_min) ** (rng.permutation(n) / max(n - 1, 1))
    elif sched.seed_t_scale == "shortest":
        t = np.full(n, s.t_min)
    else:
        t = s.t_min + u[:, d] * (s.t_max - s.t_min)
    if config.acquisition.fixed_t is not None:
        t_grid = grids(config).t
        t = np.full(n, t_grid[np.argmin(np.abs(t_grid - config.acquisition.fixed_t))])
    elif config.noise_model.field is not None:
        x = paired_positions(x, t)
    return np.column_stack([x, t])


def paired_positions(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Seed positions x (n, d) for a noise field: the seed with the k-th longest t moves to the
    position of the seed with the k-th shortest, so floor(n/2) positions are each measured at a
    short and a long t. A field can explain any one noise per position by where it is; only
    two times at one position tell the time-dependent part from the position-dependent one."""
    order = np.argsort(t, kind="stable")
    paired = x.copy()
    for k in range(x.shape[0] // 2):
        paired[order[-1 - k]] = x[order[k]]
    return paired


def make_point(
    x,
    t: float,
    readings: Sequence,
    model_noise: float | None,
    reduction: ReductionConfig,
    clip_sd: float | None = None,
) -> tuple[Point, list[ShotValue]]:
    """A point from its readings (spectra are fitted here) and each shot's value. The point uses
    the ok shots only (after outlier clipping with ``clip_sd``, see ``ScheduleConfig``). With
    ``model_noise`` None the noise is measured (the sample sd of the ok shots, at least two
    needed), otherwise it is the given noise-model prediction."""
    shots = clip_outliers(shot_values(readings, reduction), clip_sd)
    measured = model_noise is None
    reduced = reduce_shots(usable(shots, 2 if measured else 1))
    return Point(
        x=as_position(x),
        t=float(t),
        value=reduced.value,
        shot_std=reduced.shot_std,
        n_shots=reduced.n_shots,
        noise=reduced.shot_std if model_noise is None else float(model_noise),
        noise_measured=measured,
    ), shots


@float64
def summarize(config: CampaignConfig, state: CampaignState, seed: int) -> Summary:
    """Fit both models on every point (key for the step after the last decision: ``n_steps``
    unless the instrument-time budget ended the campaign sooner) and summarise them."""
    from noisebo.acquisition.method import Method  # the models load with the first fit, not to ask
    from noisebo.models.fitting import fit_key, fit_models, hyperparameters
    from noisebo.models.prediction import predict

    method = Method.of(config)
    fitted = fit_models(config, method.noise_law, state, fit_key(seed, len(state.t_opt_history)))
    pred = predict(config, method.noise_law, fitted, state, method.policy.uses_spread)
    return Summary(
        f_mean=np.asarray(pred.posterior.f_mean, dtype=np.float64),
        f_var=np.asarray(pred.posterior.f_var, dtype=np.float64),
        noise_fine=np.asarray(pred.noise_fine, dtype=np.float64),
        t_opt=float(pred.posterior.t_opt),
        hyperparameters=hyperparameters(fitted),
        **(
            {}
            if pred.posterior.t_opt_map is None
            else {
                "t_opt_map": np.asarray(pred.posterior.t_opt_map, dtype=np.float64),
                "noise_map": np.asarray(pred.posterior.noise_at_t_opt, dtype=np.float64),
            }
        ),
    )
