"""noisebo: Bayesian optimisation of where (x) and how long (t) to measure.

The numerical core works in float64: GP covariance diagonals span several orders of magnitude.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"
