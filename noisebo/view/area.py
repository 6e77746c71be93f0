"""Pictures of x over two axes: values on the reference grid as images, points as markers.

For a two-axis space the reference points are the display grid, axis 0 varying slowest
(``noisebo.models.grids.reference_points``), so a per-point array (m,) reshapes to (n0, n1); images
are drawn with axis 0 across and axis 1 up.
"""

from __future__ import annotations

import numpy as np

from noisebo.config import CampaignConfig


def as_image(values, config: CampaignConfig) -> np.ndarray:
    """Values (m,) on a two-axis reference grid as an image (n1, n0): row = axis 1, column = axis 0."""
    n0, n1 = config.space.points_per_axis
    return np.asarray(values, dtype=np.float64).reshape(n0, n1).T


def extent(config: CampaignConfig) -> tuple[float, float, float, float]:
    """(left, right, bottom, top) of the images in axis units."""
    (lo0, lo1), (hi0, hi1) = config.space.lows, config.space.highs
    return lo0, hi0, lo1, hi1


def axis_labels(config: CampaignConfig) -> list[str]:
    """ "name (units)" per axis."""
    return [f"{a.name} ({a.units})" if a.units else a.name for a in config.space.axes]


def draw_image(
    ax,
    values,
    config: CampaignConfig,
    title: str,
    label: str,
    cmap: str = "viridis",
    points: np.ndarray | None = None,
    point_colours=None,
):
    """One area image on ``ax`` with its colour bar, and measured points (n, 2) on top."""
    image = ax.imshow(
        as_image(values, config),
        origin="lower",
        extent=extent(config),
        aspect="equal",
        cmap=cmap,
        interpolation="nearest",
    )
    ax.figure.colorbar(image, ax=ax, label=label, fraction=0.046, pad=0.02)
    if points is not None and len(points):
        ax.scatter(points[:, 0], points[:, 1], c=point_colours, s=16, edgecolor="w", linewidth=0.5, zorder=3)
    x_label, y_label = axis_labels(config)
    ax.set(xlabel=x_label, ylabel=y_label, title=title)
    return image
