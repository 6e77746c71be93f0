"""Campaign quality figures, as plain functions of arrays."""

from __future__ import annotations

import numpy as np


def rmse(predicted: np.ndarray, truth: np.ndarray) -> float:
    """Root-mean-square difference of two equal-shape arrays."""
    predicted, truth = np.asarray(predicted, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if predicted.shape != truth.shape:
        raise ValueError(f"shape mismatch: {predicted.shape} vs {truth.shape}")
    return float(np.sqrt(np.mean((predicted - truth) ** 2)))


def relative_error(estimate: float, truth: float) -> float:
    """|estimate - truth| / |truth|."""
    return abs(estimate - truth) / abs(truth)


def median_iqr(values) -> tuple[float, float, float]:
    """(median, 25th percentile, 75th percentile) of the finite values; NaNs if there are none."""
    arr = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if arr.size == 0:
        return float("nan"), float("nan"), float("nan")
    q25, q50, q75 = np.percentile(arr, [25, 50, 75])
    return float(q50), float(q25), float(q75)
