"""The schedule section of a campaign config: seed points, shots, convergence, budgets and mode."""

from __future__ import annotations

from typing import Literal
from pydantic import (
    Field,
    model_validator,
)
from noisebo.schedule_modes import SCHEDULE_MODES, ScheduleMode
from noisebo.config.numbers import Count, Flag, FrozenModel, NonNegativeFloat, PositiveFloat, Rate


class ScheduleConfig(FrozenModel):
    """Seed points, BO steps, repeated shots and the noise-model convergence rule.

    Seed points are random: a Latin hypercube (or uniform draws) with t on a log or linear scale.

    ``convergence``: "variance" (the paper's): converged when the population variance of the
    predicted optimal t over the last ``window`` BO steps is below ``threshold`` (s^2);
    "posterior": converged when the 95 % interval of the optimal t over the noise model's
    posterior draws (Laplace or NUTS) reaches at most ``t_interval_rel`` of its median either
    side: a statement about how well t* is known rather than about how much it moved.

    ``adaptive_shots``: a point whose noise is measured (before convergence) takes the shots
    that make its noise estimate as precise as the noise model already is at its t (relative
    standard error 1/sqrt(2 (n - 1)) against the model's relative sd there), between
    max(2, shots_after) and shots_before, instead of always shots_before: cheap points while the
    model knows little, more as it knows more.

    ``noise_t``: where a noise-measuring point (before convergence) measures. "policy": at the
    t the acquisition policy chose (the paper's). "informative" (with the posterior rule, a
    noise model without a field): at the t whose measurement is expected to narrow the
    posterior of the optimal t most per second of instrument time (``information.t_opt_rate``),
    the point keeping the policy's x: the rule then converges by learning what it tests. In
    the budget mode every point measures the noise with its few shots, so every point whose
    step finds the interval wider than ``t_interval_rel`` is such a point: the rule is checked
    afresh each step there, since an interval that narrowed early can widen again.
    "valued" (the budget mode, where every point measures the noise; a policy whose t is the
    reward's, reward or double; no field, no fixed t): at the policy's t, or at the t whose
    noise measurement is worth more to the points still to come, through what it teaches about
    t*, than it costs in reward now (``information.t_information_value``): early excursions
    from the predicted t* that stop once t* is known or the budget nearly spent.

    ``clip_sd``: outlier-robust reduction of a point's shots. A shot farther than ``clip_sd``
    robust standard deviations (1.4826 x the median absolute deviation) from the median of the
    point's ok shots is rejected (recorded with its reason, like any rejected shot) and the point
    is the mean and sd of the rest. None: the plain mean of the ok shots.

    Failure budget: once at least ``min_failed`` shots have failed (instrument errors, timeouts,
    rejected readings), a campaign whose failed fraction of all attempts exceeds
    ``tolerated_rate`` stops with ``FailureBudgetExceeded`` and the status "failed". A dead
    instrument is noticed sooner, whatever the attempts before: ``max_failed_in_row`` failed
    attempts with no shot taken between them (10 by default), or ``max_silent_s`` of wall time
    without a shot taken (None by default: no limit), end the campaign as "failed" with the
    last failure's reason; both count from the (re)start, and the campaign continues once the
    instrument is back.

    Instrument-time budget: ``budget_s`` (None: none) is the instrument time the campaign may
    spend, each shot's t plus ``point_overhead_s`` per point (moving the tip or stage,
    settling). Each point is planned to fit what is left (a decision chooses only times, and
    if need be fewer shots, that fit); a point that cannot fit ends the campaign with the status
    "budget_spent" and its final models (``noisebo resume --budget-s`` continues it with more).
    ``n_steps`` still ends it first if it is reached first.

    Wall-time budget: ``wall_budget_s`` (None: none) is the wall time the campaign may run, as
    its recorder counts it at every commit (``Clocked``; the time between a stop and its resume
    is left out). A point is begun only when its instrument time fits the wall time left (with
    several instruments the points run side by side: each must fit on its own); a decision
    plans within it too, and once the cheapest point cannot fit, the campaign ends as
    "budget_spent". A point begun is finished. A campaign kept only in memory has no clock
    (the simulated fleet, ``noisebo.campaign.fleet``, keeps its simulated time).

    ``mode``: "paper" (default) is the paper's protocol: seed points and every point until the
    noise model converges take ``shots_before`` shots, whose sample sd is the point's measured
    noise, then ``shots_after``. "budget" spends no instrument time on dedicated noise
    measurements: every point, seeds included, takes ``shots_after`` (at least 2) shots, and the
    noise model learns Noise(t) from the replicate scatter of every point (the sampling variance
    of a few-shot sd is in its likelihood), while the GP for f uses the noise model's noise at
    each point's t (a seed point, before there is a model, its own sd). Use it when instrument
    time is short (a budget a few times what the paper's 30-shot seed points alone cost), or with
    an instrument's noise profile (``noise_model.profile``); use "paper" to learn t* with the
    paper's guarantees, or to reproduce its figures. It needs
    ``noise_model.learn_after_convergence``.
    """

    n_seed: Count = Field(3, ge=1, description="random seed points before the first BO step")
    seed_design: Literal["latin_hypercube", "uniform"] = Field(
        "latin_hypercube", description="how the seed points are drawn over x and t"
    )
    seed_t_scale: Literal["log", "linear", "log_span", "shortest"] = Field(
        "log",
        description="the scale of the seeds' t: log, "
        "linear, log_span (t_min, the geometric middle and "
        "t_max exactly), or shortest (every seed at t_min: for a noise profile that already "
        "gives the law)",
    )
    n_steps: Count = Field(15, ge=0, description="BO steps after the seed points")
    adaptive_shots: Flag = Field(
        False,
        description="a noise-measuring point takes the shots that make its noise "
        "estimate as precise as the noise model at its t, between max(2, shots_after) and "
        "shots_before",
    )
    convergence: Literal["variance", "posterior"] = Field(
        "variance",
        description="variance: the paper's rule (the "
        "predicted optimal t stopped moving); posterior: its 95 % "
        "interval is narrow enough",
    )
    t_interval_rel: PositiveFloat = Field(
        0.1,
        description="posterior rule: converged once the 95 % interval of t* "
        "lies within this fraction of its median either side",
    )
    noise_t: Literal["policy", "informative", "valued"] = Field(
        "policy",
        description="where a noise-measuring point measures: "
        "at the policy's t, (posterior rule) at the t that narrows "
        "t*'s interval most per second, or (budget mode) elsewhere than the policy's t where "
        "what it teaches about t* is worth more to the later points than the reward it loses now",
    )
    shots_before: Count = Field(
        30, ge=2, description="shots per point until the noise model converges (and per seed point, paper mode)"
    )
    shots_after: Count = Field(3, ge=1, description="shots per point after convergence (every point in budget mode)")
    window: Count = Field(
        3, ge=2, description="variance rule: BO steps over which the predicted optimal t's variance is taken"
    )
    threshold: PositiveFloat = Field(
        5e-4, description="variance rule: converged when that variance is below this (s^2)"
    )
    clip_sd: PositiveFloat | None = Field(
        None,
        description="reject shots farther than this many robust sd (1.4826 "
        "x MAD) from the median of the point's shots; null: no clipping",
    )
    min_failed: Count = Field(
        5, ge=1, description="failure budget: failed attempts before the failed fraction is judged"
    )
    tolerated_rate: Rate = Field(
        0.5,
        description="failure budget: the campaign stops as failed once the failed fraction of attempts exceeds this",
    )
    max_failed_in_row: Count = Field(
        10, ge=1, description="the campaign stops as failed after this many failed attempts with no shot taken between"
    )
    max_silent_s: PositiveFloat | None = Field(
        None,
        description="the campaign stops as failed after this much wall time (s) with failed attempts and no "
        "shot taken; null: no limit",
    )
    budget_s: PositiveFloat | None = Field(
        None,
        description="the instrument time the campaign may spend (s): every "
        "shot's t plus point_overhead_s per point; null: no budget",
    )
    wall_budget_s: PositiveFloat | None = Field(
        None,
        description="the wall time the campaign may run (s), counted at each commit, the time between a stop "
        "and its resume left out; a point is begun only when its instrument time fits what is left; "
        "null: no limit",
    )
    point_overhead_s: NonNegativeFloat = Field(
        0.0, description="instrument time per point besides its shots (s): moving the tip or stage, settling"
    )
    mode: Literal["paper", "budget"] = Field(
        "paper",
        description="paper: noise points of shots_before shots until "
        "convergence; budget: every point takes shots_after shots and the noise "
        "model learns from every point's replicate scatter",
    )

    @property
    def rule(self) -> ScheduleMode:
        """The mode as the object that says what it means (``noisebo.schedule_modes``)."""
        return SCHEDULE_MODES[self.mode]

    @property
    def seed_shots(self) -> int:
        """Shots a seed point takes: ``shots_before`` (paper), ``shots_after`` (budget)."""
        return self.rule.seed_shots(self.shots_before, self.shots_after)

    @property
    def intact_noise_shots(self) -> int | None:
        """In the budget mode, the shots (2) a point must keep, losing none to rejection, to
        inform the noise law through its replicate scatter, whatever it was planned with (a
        policy that chooses shots may plan fewer than ``shots_after``); None in the paper mode."""
        return self.rule.intact_noise_shots

    @property
    def draws_t_star(self) -> bool:
        """Whether a decision needs the noise model's draws of the optimal t: the posterior
        rule tests their interval and ``noise_t: valued`` weighs them (``informative``, which
        needs the posterior rule, narrows it)."""
        return self.convergence == "posterior" or self.noise_t == "valued"

    @model_validator(mode="after")
    def _mode_settings(self) -> ScheduleConfig:
        self.rule.check(self.shots_after, self.adaptive_shots)
        return self
