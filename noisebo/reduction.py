"""From raw readings to shot values: a scalar reading is its own value; a resonance sweep is
fitted with the SHO model and its value is the signed fitted amplitude. A shot that yields no
trustworthy value is kept with ok False and the reason, and never reaches a model."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Sequence

import numpy as np

from noisebo.config import ReductionConfig, SHOReductionConfig
from noisebo.sho import SHOFit, fit_sho


@dataclass(frozen=True, eq=False)
class Reading:
    """One shot as an instrument returns it: a scalar ``value`` (value units), or a raw
    ``spectrum`` with value None that the named ``reduction`` turns into one ("sho", the
    default for spectra: rows frequency Hz, amplitude pm, phase deg)."""

    value: float | None
    spectrum: np.ndarray | None = None
    reduction: str | None = None

    def __eq__(self, other) -> bool:
        if not isinstance(other, Reading):
            return NotImplemented
        same_spectrum = (self.spectrum is None and other.spectrum is None) or (
            self.spectrum is not None
            and other.spectrum is not None
            and np.array_equal(self.spectrum, other.spectrum, equal_nan=True)
        )
        same_value = self.value == other.value or (
            self.value is not None and other.value is not None and np.isnan(self.value) and np.isnan(other.value)
        )
        return same_value and self.reduction == other.reduction and same_spectrum

    __hash__ = None  # type: ignore[assignment]  # compared by value, with arrays: not hashable


class ShotValue(NamedTuple):
    """value: the shot's number (NaN when not ok); fit: the SHO fit behind it, if any."""

    value: float
    ok: bool
    reason: str
    fit: SHOFit | None


class NoUsableShots(ValueError):
    """A point none (or too few) of whose shots gave a value: ``missing`` more ok shots are
    needed, ``rejected`` of its shots were not ok."""

    def __init__(self, message: str, missing: int = 1, rejected: int = 0):
        super().__init__(message)
        self.missing, self.rejected = missing, rejected


def sho_value(spectrum: np.ndarray, config: SHOReductionConfig) -> ShotValue:
    """The "sho" reduction: the signed amplitude of Eq. 8 fitted to a sweep (2 or 3, N): rows
    frequency (Hz), amplitude (value units) and optionally phase (deg) for the sign."""
    if spectrum.ndim != 2 or spectrum.shape[0] not in (2, 3):
        return ShotValue(float("nan"), False, f"spectrum of shape {spectrum.shape}, expected (2 or 3, N)", None)
    phase = spectrum[2] if spectrum.shape[0] == 3 else None
    nominal = None
    if config.nominal_resonance_hz is not None and config.nominal_q is not None:
        nominal = (config.nominal_resonance_hz, config.nominal_q)
    fit = fit_sho(spectrum[0], spectrum[1], phase, (config.q_bounds[0], config.q_bounds[1]), 0.0, nominal)
    return ShotValue(fit.value if fit.ok else float("nan"), fit.ok, fit.reason if not fit.ok else "", fit)


REDUCTIONS = {"sho": lambda spectrum, config: sho_value(spectrum, config.sho)}
DEFAULT_REDUCTION = "sho"


def register_reduction(name: str, reduce: Callable[[np.ndarray], float]) -> None:
    """Make the reduction ``name`` available to readings that name it: ``reduce(spectrum)``
    returns the shot's value; a non-finite value or a ``ValueError`` rejects the shot with its
    reason. Drivers declare theirs as a ``reductions`` mapping (see ``instruments.registry``).
    The built-in "sho" cannot be replaced; registering the same function again changes nothing."""
    if name in REDUCTIONS and getattr(REDUCTIONS[name], "user_function", None) is not reduce:
        raise ValueError(f"a reduction named {name!r} is registered already")

    def reduction(spectrum: np.ndarray, config: ReductionConfig) -> ShotValue:
        try:
            value = float(reduce(spectrum))
        except ValueError as error:
            return ShotValue(float("nan"), False, f"{name}: {error}", None)
        if not np.isfinite(value):
            return ShotValue(float("nan"), False, f"{name}: non-finite value", None)
        return ShotValue(value, True, "", None)

    reduction.user_function = reduce  # type: ignore[attr-defined]  # what the registry wraps, for its name
    REDUCTIONS[name] = reduction


def shot_value(reading: Reading, config: ReductionConfig) -> ShotValue:
    """The value of one reading: a scalar is its own value; a spectrum goes through the
    reduction it names (default "sho"), configured by ``config``."""
    if reading.spectrum is None:
        value = float(reading.value) if reading.value is not None else float("nan")
        ok = bool(np.isfinite(value))
        return ShotValue(value if ok else float("nan"), ok, "" if ok else "non-finite reading", None)
    name = reading.reduction or DEFAULT_REDUCTION
    if name not in REDUCTIONS:
        return ShotValue(
            float("nan"), False, f"unknown reduction {name!r} (known: {', '.join(sorted(REDUCTIONS))})", None
        )
    return REDUCTIONS[name](np.asarray(reading.spectrum), config)


def shot_values(readings: Sequence[Reading], config: ReductionConfig) -> list[ShotValue]:
    return [shot_value(r, config) for r in readings]


ROBUST_SD = 1.4826  # median absolute deviation -> standard deviation, for Gaussian data


def clip_outliers(values: Sequence[ShotValue], clip_sd: float | None) -> list[ShotValue]:
    """The shots with those of the ok ones farther than ``clip_sd`` robust sd (ROBUST_SD x MAD)
    from their median turned into rejected shots; unchanged with ``clip_sd`` None, fewer than
    three ok shots or a zero MAD."""
    values = list(values)
    good = np.asarray([v.value for v in values if v.ok], dtype=np.float64)
    if clip_sd is None or good.size < 3:
        return values
    centre = float(np.median(good))
    spread = ROBUST_SD * float(np.median(np.abs(good - centre)))
    if spread <= 0:
        return values
    limit = clip_sd * spread
    return [
        v._replace(ok=False, reason=f"outlier: {abs(v.value - centre):.4g} from the median, limit {limit:.4g}")
        if v.ok and abs(v.value - centre) > limit
        else v
        for v in values
    ]


def usable(values: Sequence[ShotValue], needed: int) -> np.ndarray:
    """The finite values of the ok shots; raise ``NoUsableShots`` with fewer than ``needed``."""
    good = np.asarray([v.value for v in values if v.ok], dtype=np.float64)
    if good.size < needed:
        reasons = sorted({v.reason for v in values if not v.ok})
        raise NoUsableShots(
            f"{good.size} of {len(values)} shots usable, {needed} needed ({'; '.join(reasons)})",
            needed - good.size,
            len(values) - good.size,
        )
    return good


class Reduced(NamedTuple):
    """A point from its shots: value = mean; shot_std = sample sd (ddof=1; NaN below 2 shots)."""

    value: float
    shot_std: float
    n_shots: int


def reduce_shots(values: Sequence[float] | np.ndarray) -> Reduced:
    """Mean and sample standard deviation of one point's repeated shots."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"need a non-empty 1-D sequence of shot values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("shot values must be finite")
    std = float(arr.std(ddof=1)) if arr.size > 1 else float("nan")
    return Reduced(float(arr.mean()), std, int(arr.size))
