"""noisebo: Bayesian optimisation of where (x) and how long (t) to measure.

The numerical core works in float64: GP covariance diagonals span several orders of magnitude.
"""

import os
import sys

# OpenBLAS's threads spin over the tiny matrices of a decision's fits (L-BFGS-B, least squares):
# one thread made a decision 1.9x faster on 2 cores (benchmarks/scaling.py). Set before numpy
# loads OpenBLAS; a value already in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# JAX reads JAX_ENABLE_X64 when it is first imported. Only the modules that compute import it,
# so a command that needs no model (`noisebo --help`, `inspect`, `ask`) does not wait for it.
if "jax" in sys.modules:
    sys.modules["jax"].config.update("jax_enable_x64", True)
else:
    os.environ["JAX_ENABLE_X64"] = "1"

__version__ = "0.1.0"
