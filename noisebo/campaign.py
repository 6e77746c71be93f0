"""The campaign loop as pure functions over an explicit state: seed points, then
propose -> measure -> update for ``n_steps`` BO steps. Every random draw is keyed by
(campaign seed, point, shot), so one seed always gives one campaign."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from noisebo.config import CampaignConfig
from noisebo.decision import Decision, decide, fit_key, fit_models, grids, hyperparameters, predict
from noisebo.failures import InstrumentError
from noisebo.keys import MEASURE, SEED_POINTS, numpy_rng
from noisebo.reduction import NoUsableShots, ShotValue, clip_outliers, shot_values, usable
from noisebo.schedule import reduce_shots
from noisebo.state import CampaignState, Point


def seed_points(config: CampaignConfig, seed: int) -> np.ndarray:
    """(n_seed, 2) random (x, t) seed locations.

    "latin_hypercube" (default) stratifies both axes, t on a log scale: the seeds then span the
    exposure range, from a short, cheap shot to a long one, which separates A0 from A1 in the
    noise model from the start. "uniform" draws each coordinate uniformly. ``seed_t_scale``
    "log_span" replaces the random t by n values evenly spaced on a log scale from t_min to t_max
    inclusive (in random order): the ends of the range are where the two terms of the noise law
    differ most, so they pin A0 and A1 best."""
    s, sched = config.space, config.schedule
    n = sched.n_seed
    rng = numpy_rng(seed, SEED_POINTS)
    if sched.seed_design == "latin_hypercube":
        strata = np.column_stack([rng.permutation(n), rng.permutation(n)])
        u = (strata + rng.random((n, 2))) / n
    else:
        u = rng.random((n, 2))
    x = s.x_min + u[:, 0] * (s.x_max - s.x_min)
    if sched.seed_t_scale == "log":
        t = s.t_min * (s.t_max / s.t_min) ** u[:, 1]
    elif sched.seed_t_scale == "log_span":
        t = s.t_min * (s.t_max / s.t_min) ** (rng.permutation(n) / max(n - 1, 1))
    else:
        t = s.t_min + u[:, 1] * (s.t_max - s.t_min)
    if config.acquisition.fixed_t is not None:
        t_grid = grids(config).t
        t = np.full(n, t_grid[np.argmin(np.abs(t_grid - config.acquisition.fixed_t))])
    return np.column_stack([x, t])


def shot_readings(
    instrument, x: float, t: float, shots: int, seed: int, point: int,
    done: Sequence = (), on_shot: Callable[[int, object], None] | None = None,
    on_failure: Callable[[int, InstrumentError], None] | None = None,
) -> list:
    """Readings ``len(done)..shots-1`` of a point appended to ``done``; shot k draws from key
    (seed, point, k), and each new reading goes to ``on_shot(k, reading)`` as soon as it is taken.
    With ``on_failure``, an ``InstrumentError`` goes to ``on_failure(k, error)`` (which records
    it and may stop the campaign) and shot k is tried again with the same key; without, it is
    raised."""
    readings = list(done)
    for k in range(len(readings), shots):
        while True:
            try:
                reading = instrument.measure(x, t, numpy_rng(seed, MEASURE, point, k))
                break
            except InstrumentError as error:
                if on_failure is None:
                    raise
                on_failure(k, error)
        if on_shot is not None:
            on_shot(k, reading)
        readings.append(reading)
    return readings


def make_point(
    x: float, t: float, readings: Sequence, model_noise: float | None, instrument_config, clip_sd: float | None = None
) -> tuple[Point, list[ShotValue]]:
    """A point from its readings (spectra are fitted here) and each shot's value. The point uses
    the ok shots only (after outlier clipping with ``clip_sd``, see ``ScheduleConfig``). With
    ``model_noise`` None the noise is measured (the sample sd of the ok shots, at least two
    needed), otherwise it is the given noise-model prediction."""
    shots = clip_outliers(shot_values(readings, instrument_config), clip_sd)
    measured = model_noise is None
    reduced = reduce_shots(usable(shots, 2 if measured else 1))
    return Point(
        x=float(x),
        t=float(t),
        value=reduced.value,
        shot_std=reduced.shot_std,
        n_shots=reduced.n_shots,
        noise=reduced.shot_std if measured else float(model_noise),
        noise_measured=measured,
    ), shots


@dataclass(frozen=True)
class Summary:
    """Final models after the last measurement: f mean and variance on the x grid, the noise
    curve on the fine t grid, the final predicted optimal t and hyperparameters."""

    x: np.ndarray
    f_mean: np.ndarray
    f_var: np.ndarray
    t_fine: np.ndarray
    noise_fine: np.ndarray
    t_opt: float
    hyperparameters: dict


def summarize(config: CampaignConfig, state: CampaignState, seed: int) -> Summary:
    """Fit both models on every point (key for step ``n_steps``) and summarise them."""
    fitted = fit_models(config, state, fit_key(seed, config.schedule.n_steps))
    pred = predict(config, fitted, state)
    g = grids(config)
    return Summary(
        x=g.x,
        f_mean=np.asarray(pred.posterior.f_mean),
        f_var=np.asarray(pred.posterior.f_var),
        t_fine=g.t_fine,
        noise_fine=np.asarray(pred.noise_fine),
        t_opt=float(pred.posterior.t_opt),
        hyperparameters=hyperparameters(fitted),
    )


def _measure_pure(config: CampaignConfig, instrument, x, t, shots: int, seed: int, index: int, model_noise) -> Point:
    """A point measured in this process: its shots, then extra shots while too few are usable."""
    readings: list = []
    while True:
        readings = shot_readings(instrument, x, t, shots, seed, index, readings)
        try:
            return make_point(x, t, readings, model_noise, config.instrument, config.schedule.clip_sd)[0]
        except NoUsableShots as short:
            shots = len(readings) + short.missing


@dataclass(frozen=True)
class CampaignResult:
    state: CampaignState
    decisions: tuple[Decision, ...]
    latencies_s: tuple[float, ...]
    summary: Summary

    @property
    def total_measurement_time(self) -> float:
        """Sum over all shots of t (s), seed points included."""
        return float(sum(p.t * p.n_shots for p in self.state.points))


def run_campaign(
    config: CampaignConfig, instrument, seed: int, on_step: Callable[[Decision, CampaignState], None] | None = None
) -> CampaignResult:
    """Run a whole campaign in this process and return its state, decisions and summary."""
    state = CampaignState()
    shots = config.schedule.shots_before
    for i, (x, t) in enumerate(seed_points(config, seed)):
        state = state.with_point(_measure_pure(config, instrument, x, t, shots, seed, i, None))
    decisions, latencies = [], []
    for step in range(config.schedule.n_steps):
        started = time.perf_counter()
        decision, state = decide(config, state, seed, step)
        latencies.append(time.perf_counter() - started)
        model_noise = None if decision.measure_noise else decision.noise_at_t
        state = state.with_point(
            _measure_pure(config, instrument, decision.x, decision.t, decision.shots, seed, len(state.points), model_noise)
        )
        decisions.append(decision)
        if on_step is not None:
            on_step(decision, state)
    return CampaignResult(state, tuple(decisions), tuple(latencies), summarize(config, state, seed))
