"""The record of one BO decision, as the journal and the file keep it: numpy arrays and plain
numbers only (no JAX), so whatever reads a campaign can name it without loading the models."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from noisebo.state import as_position


@dataclass(frozen=True)
class Decision:
    """The outcome of one BO step (0-based ``step``): the proposal (x, one float per axis, and
    t), how to measure it, and what the models said. ``noise_at_t`` is the noise model's
    single-shot sd at the proposed t (and x, for a noise field). ``t_opt``: the predicted
    optimal t; for a noise field the one t that maximises the reward averaged over x, with
    ``t_opt_map`` (m,) t*(x) on the reference points (empty (0,) without a field);
    ``t_opt_interval``: for the posterior convergence rule, half the width of the 95 % interval
    of the optimal t over the noise model's draws relative to its median (NaN otherwise). Arrays:
    ``acq_map`` (n_x, n_t) float32 for one axis, for d > 1 its maximum over t at each of the m
    reference points, (m,); ``f_mean``, ``f_var`` (m,) on the reference points (the x grid for
    one axis); ``noise_mean``, ``noise_var`` (n_t,) on the t grid (for a noise field, their
    averages over the reference points). ``latency_s``: the decision's time (s).
    ``primary_inputs``, ``noise_inputs``: the distinct inputs (or bins) each GP was fitted on;
    ``binned``: True when they were bins, an approximation (see ``noisebo.models.inputs``).
    ``profile_p``: the noise profile's posterior predictive p-value on the noise model's training
    points (NaN: no profile, or nothing to check yet); ``profile_in_use``: whether the profile
    was this step's prior (``noisebo.models.profile_check``). ``n_points``: how many committed
    points the noise model was fitted on (the instrument's own, for a law per instrument); two
    decisions with the same count saw the same data (-1: not known, a record from before it was
    kept)."""

    step: int
    x: tuple[float, ...]
    t: float
    acq_value: float
    shots: int
    measure_noise: bool
    noise_at_t: float
    t_opt: float
    converged: bool
    hyperparameters: dict
    acq_map: np.ndarray
    f_mean: np.ndarray
    f_var: np.ndarray
    noise_mean: np.ndarray
    noise_var: np.ndarray
    latency_s: float = 0.0
    primary_inputs: int = 0
    noise_inputs: int = 0
    binned: bool = False
    t_opt_map: np.ndarray = field(default_factory=lambda: np.zeros(0))
    t_opt_interval: float = float("nan")
    profile_p: float = float("nan")
    profile_in_use: bool = False
    n_points: int = -1

    def __post_init__(self) -> None:  # one number is one axis; a list (from a record) a tuple
        object.__setattr__(self, "x", as_position(self.x))
