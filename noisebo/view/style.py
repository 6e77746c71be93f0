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


def instrument_colours(names, order) -> np.ndarray:
    """RGBA in [0, 1], (n, 4): each point's instrument ``names`` (n,) by its place in the
    campaign's instruments ``order`` along tab10, so an instrument keeps its colour in every
    frame and view (grey for a name not in ``order``)."""
    from matplotlib import colormaps

    place = {name: k for k, name in enumerate(order)}
    rgba = np.asarray([colormaps["tab10"](place[str(n)] % 10) if str(n) in place else SEED_GREY for n in names])
    return rgba.reshape(len(rgba), 4)
