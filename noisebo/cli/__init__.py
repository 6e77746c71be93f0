"""The ``noisebo`` command line: an adapter over the flows, storage and views.

The command line is its own process, so it sets what that process computes best with: one
OpenBLAS thread (its threads spin over the tiny matrices of a decision's fits, L-BFGS-B and least
squares: one thread made a decision 1.9x faster on 2 cores, benchmarks/scaling.py), set before
numpy loads OpenBLAS; a value already in the environment wins. ``import noisebo`` sets nothing.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
