"""The budget benchmark's targets, judged from medians over seeds.

Each function takes numbers (a design's median RMSE at each checkpoint, the bound it must meet
there, the seeds' final-t errors) and returns a verdict in words, so that ``budget.py --report``
prints the verdicts the docs state from the JSON it reads. The targets:

- ``budget warm`` at or below the best fixed t in hindsight at every checkpoint;
- ``budget cold`` within 10 % of it at every checkpoint;
- both at most 0.8 x the median fixed design (the median over the fixed designs of their medians);
- ``budget cold`` below gpCAM at every checkpoint;
- the final t within 5 % of t* in at least 95 % of seeds;
- the designs recommended for the best map of f within a budget, ``budget info_rate`` (cold) and
  ``budget warm info_rate`` (from a noise profile): below every peer at every checkpoint; the
  warm one at or below the best fixed t in hindsight and the cold one within 5 % of it at every
  checkpoint; stretch: both at most 0.9 x it.

A median of inf is a design with no model in half its seeds at that checkpoint (it misses any
bound); a bound of inf or NaN (no fixed design has a median there) judges nothing there.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence

WITHIN_BEST = 1.10  # budget cold: within 10 % of the best fixed t in hindsight
OF_MEDIAN_FIXED = 0.8  # both: at most 0.8 x the median fixed design
MAP_WITHIN_BEST = 1.05  # the cold mapping design: within 5 % of the best fixed t in hindsight
MAP_STRETCH = 0.9  # both mapping designs, stretch: at most 0.9 x the best fixed t in hindsight
T_WITHIN = 0.05  # final t within 5 % of t* ...
SHARE_WITHIN = 0.95  # ... in at least 95 % of seeds


def misses(values: Sequence[float], bounds: Sequence[float], strict: bool = False) -> list[int]:
    """Indices where ``values[i]`` is above ``bounds[i]`` (at or above it where ``strict``); a bound
    that is not finite judges nothing."""
    out = []
    for i, (v, b) in enumerate(zip(values, bounds, strict=True)):
        if not math.isfinite(b):
            continue
        if v > b or (strict and v >= b):
            out.append(i)
    return out


def verdict(values: Sequence[float], bounds: Sequence[float], at: Sequence[float], strict: bool = False) -> str:
    """ "met" or "missed at ..." naming each checkpoint (s) missed, the value, the bound and how far
    over it the value is."""
    judged = [i for i, b in enumerate(bounds) if math.isfinite(b)]
    if not judged:
        return "not judged (no bound at any checkpoint)"
    missed = misses(values, bounds, strict)
    if not missed:
        return "met"
    return "missed at " + "; ".join(_miss(at[i], values[i], bounds[i]) for i in missed)


def _miss(at: float, value: float, bound: float) -> str:
    if not math.isfinite(value):
        return f"{at:g} s (no model in half the seeds)"
    return f"{at:g} s ({value:.4g} against {bound:.4g}, {100 * (value / bound - 1):.1f} % over)"


def scaled(bounds: Sequence[float], factor: float) -> list[float]:
    return [factor * b for b in bounds]


def median_of_designs(medians: Sequence[Sequence[float]]) -> list[float]:
    """At each checkpoint the median over one or more designs of their medians (a design with no
    model there counts as inf)."""
    if not medians:
        raise ValueError("no designs to take the median of")
    return [statistics.median(column) for column in zip(*medians, strict=True)]


def needed(seeds: int) -> int:
    """The least number of seeds that is at least ``SHARE_WITHIN`` of ``seeds``."""
    return math.ceil(SHARE_WITHIN * seeds - 1e-9)


def t_verdict(errors: Sequence[float]) -> str:
    """ "k of n (needs m): met" or "...: missed" for final t errors relative to t* (a NaN error,
    no final model, is not within)."""
    within = sum(1 for e in errors if e <= T_WITHIN)
    need = needed(len(errors))
    return f"{within} of {len(errors)} (needs {need}): {'met' if within >= need else 'missed'}"


def ratios(values: Sequence[float], bounds: Sequence[float]) -> list[float]:
    """values / bounds at each checkpoint: inf where the value has no median, NaN where the bound
    is not finite."""
    return [
        math.nan if not math.isfinite(b) else (math.inf if not math.isfinite(v) else v / b)
        for v, b in zip(values, bounds, strict=True)
    ]
