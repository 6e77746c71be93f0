"""noisebo computes in float64 whatever the process's JAX default is, and changes no default.

GP covariance diagonals and the noise model's likelihood span several orders of magnitude, so
every JAX computation of the core needs 64-bit floats. JAX makes them a process-wide switch
(``jax_enable_x64``), which a library imported into a lab's own process (a notebook, a beamline's
RunEngine process) must leave alone: that process's other JAX code keeps computing in its own
default. So the core's computing functions (the decision's stages, the keys, the summary, the
noise profile's fits and checks) are wrapped in ``float64``: JAX's 64-bit types on
for the calling thread while they run (``jax.enable_x64``, a thread-local setting), off again
after. Arrays they return are float64 and stay so; arithmetic on them outside such a function
follows the process's default.

JAX keys its compiled programs by the setting, so a process may run noisebo's float64 programs and
its own float32 ones side by side.
"""

from __future__ import annotations

import functools
from typing import Callable, TypeVar

F = TypeVar("F", bound=Callable)


def float64(fn: F) -> F:
    """``fn`` with JAX's 64-bit types on for the calling thread while it runs."""

    @functools.wraps(fn)
    def in_float64(*args, **kwargs):
        import jax  # here, not at import: a command that computes nothing does not load JAX

        with jax.enable_x64(True):
            return fn(*args, **kwargs)

    return in_float64  # type: ignore[return-value]
