"""A noisebo policy in a package of its own: pure exploration at the cheapest t.

Every point goes where the posterior variance of f is largest (uncertainty exploration, with no
reward and no noise model in the score), measured at the shortest exposure on the t grid. It is
a baseline: as many points as possible for the instrument time, each as noisy as it gets.

The class is the whole plug-in: ``noisebo.acquisition.policies.Policy``'s two methods, pure functions of
arrays that noisebo traces inside its compiled programs, and its entry point in pyproject.toml:

    [project.entry-points."noisebo.policies"]
    explore-cheapest = "noisebo_explore_cheapest:ExploreCheapest"
"""

from __future__ import annotations

import jax.numpy as jnp

from noisebo.acquisition.policies import Policy

__version__ = "0.1.0"


class ExploreCheapest(Policy):
    """Pure exploration: the posterior variance of f, at the cheapest t only."""

    def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
        """(n_x, n_t): Var[f(x)] in the column of the shortest t, 0 elsewhere."""
        cheapest = post.t == jnp.min(post.t)
        return jnp.where(cheapest[None, :], post.f_var[:, None], 0.0)

    def point_scores(self, post, mean, var, j, shots, acq, rew, noise=None, spread=None, overhead_s=0.0):
        """Var[f] at points off the grid (d > 1 axes), 0 unless paired with the shortest t."""
        return jnp.where(post.t[j] == jnp.min(post.t), var, 0.0)
