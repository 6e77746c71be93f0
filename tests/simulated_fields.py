"""Noise-field measurements of known law and spread, for the tests of field profiles."""

import math

import numpy as np


def field_measurements(seed=0, positions=40, shots=10, a0=0.3, a1=2.0, amplitude=0.6, length=0.2):
    """Sample sds of ``shots`` shots at ``positions`` random x in [0, 1] ((n,)), t log-uniform over
    [0.2, 10] s, of the noise A1/sqrt(t) + A0 exp(g(x)), g a Matern 5/2 GP of sd ``amplitude`` and
    ``length``. Returns x, t, sample sds, shots (n,) each."""
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(0.0, 1.0, positions))
    r = np.abs(x[:, None] - x[None, :]) / length
    k = (1 + math.sqrt(5) * r + 5 / 3 * r**2) * np.exp(-math.sqrt(5) * r) + 1e-9 * np.eye(positions)
    g = amplitude * np.linalg.cholesky(k) @ rng.standard_normal(positions)
    t = np.exp(rng.uniform(math.log(0.2), math.log(10.0), positions))
    n = np.full(positions, float(shots))
    return x, t, (a1 / np.sqrt(t) + a0 * np.exp(g)) * np.sqrt(rng.chisquare(n - 1) / (n - 1)), n
