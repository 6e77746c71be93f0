"""Colours shared by the live view and the report."""

from __future__ import annotations

import numpy as np

SEED_GREY = (0.55, 0.55, 0.55, 1.0)


def step_colours(steps: np.ndarray, n_steps: int) -> np.ndarray:
    """RGBA in [0, 1], (n, 4): seed points (step 0) grey, BO steps 1..n_steps along viridis."""
    from matplotlib import colormaps

    steps = np.asarray(steps)
    rgba = colormaps["viridis"](np.clip(steps - 1, 0, None) / max(n_steps - 1, 1))
    rgba[steps == 0] = SEED_GREY
    return rgba
