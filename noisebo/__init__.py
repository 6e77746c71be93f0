"""noisebo: Bayesian optimisation of where (x) and how long (t) to measure.

Importing noisebo changes nothing in the process: the core computes in float64 whatever JAX's
default there is (``noisebo.precision``), and the command line sets what its own process needs.
"""

__version__ = "0.1.0"
