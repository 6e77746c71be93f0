import math

import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.acquisition.functions import (
    expected_improvement,
    f_acquisition,
    uncertainty,
    upper_confidence_bound,
)


def phi(z):
    return math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)


def Phi(z):
    return 0.5 * (1 + math.erf(z / math.sqrt(2)))


def test_ei_matches_closed_form():
    mean, var, best = 1.0, 0.25, 0.8
    z = (1.0 - 0.8) / 0.5
    expected = 0.2 * Phi(z) + 0.5 * phi(z)
    assert float(expected_improvement(jnp.asarray(mean), jnp.asarray(var), best)) == pytest.approx(expected, rel=1e-10)


def test_ei_minimisation_mirrors_maximisation():
    up = expected_improvement(jnp.asarray(1.2), jnp.asarray(0.3), 1.0, 0.0, True)
    down = expected_improvement(jnp.asarray(-1.2), jnp.asarray(0.3), -1.0, 0.0, False)
    assert float(up) == pytest.approx(float(down))


def test_ei_with_zero_variance_is_the_plain_improvement():
    out = expected_improvement(jnp.array([2.0, 0.5]), jnp.array([0.0, 0.0]), 1.0)
    np.testing.assert_allclose(np.asarray(out), [1.0, 0.0])


def test_ucb_and_ue():
    assert float(upper_confidence_bound(jnp.asarray(1.0), jnp.asarray(4.0), 2.0)) == 5.0
    assert float(upper_confidence_bound(jnp.asarray(1.0), jnp.asarray(4.0), 2.0, maximize=False)) == 3.0
    assert float(uncertainty(jnp.asarray(7.0), jnp.asarray(0.3))) == pytest.approx(0.3)


def test_unknown_acquisition_is_an_error():
    with pytest.raises(ValueError, match="unknown acquisition"):
        f_acquisition("pi", 0.0, 1.0, 0.0, xi=0.0, kappa=1.0, maximize=True)
