"""The noise laws: the mean of the noise model, Noise(t) = law(t; A0, A1[, p]) (``noise_model.mean``).

One class per law, each registered in the entry-point group ``noisebo.noise_laws`` under the name
a config uses (``noisebo.registry``); a package adds a law the same way. A law has two sources:
a time-independent one, A0, and a shot-noise one, A1 t^-p (p = 0.5 unless the law infers it).

Members (``NoiseLaw``), all pure functions of arrays (they run inside jitted programs, and on
numpy arrays):

- ``mean(t, a0, a1, p)``: Noise(t), broadcasting its arguments.
- ``combine(shot, a0)``: Noise from the two sources' values, shot = A1 t^-p.
- ``share(part, m)``: the fraction of d log Noise / d log(part) at Noise m, for part either source
  (``noise_field``'s Fisher scoring).
- ``infers_exponent``: True when p is a parameter of the model (a site ``p`` with the prior
  ``noise_model.p_prior``); otherwise p = 0.5.
- ``sources_power``: k in Noise^k = A0^k + shot^k, for the least-squares starting points
  (1: the sources add, 2: their variances add).
"""

from __future__ import annotations

import jax.numpy as jnp


class NoiseLaw:
    """Base of the built-in laws: two sources that add, p = 0.5."""

    infers_exponent: bool = False
    sources_power: float = 1.0

    def mean(self, t, a0, a1, p=0.5):
        raise NotImplementedError

    def combine(self, shot, a0):
        return shot + a0

    def share(self, part, m):
        return part / m


class InverseSqrt(NoiseLaw):
    """The paper's A1/sqrt(t) + A0."""

    def mean(self, t, a0, a1, p=0.5):
        return a1 / jnp.sqrt(t) + a0


class Power(NoiseLaw):
    """A1/t^p + A0 with the exponent p inferred."""

    infers_exponent = True

    def mean(self, t, a0, a1, p=0.5):
        return a1 * t ** (-p) + a0


class Quadrature(NoiseLaw):
    """sqrt(A1^2/t + A0^2): two independent sources whose variances add.

    A shot-noise source and a time-independent one."""

    sources_power = 2.0

    def mean(self, t, a0, a1, p=0.5):
        return jnp.sqrt(a1**2 / t + a0**2)

    def combine(self, shot, a0):
        return jnp.sqrt(shot**2 + a0**2)

    def share(self, part, m):
        return part**2 / m**2
