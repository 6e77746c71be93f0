"""The devices a campaign is given, checked before anything moves: the axes are a sequence of
movables, the detector is triggerable and readable, the exposure is movable, and the value (or
each signal of a ``plan.Spectrum``: ``signals``) is one the detector's reading holds. Each refusal is one line
(``DeviceMismatch``), raised before a bluesky document or a campaign file is written."""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any

from bluesky import plan_stubs as bps


class DeviceMismatch(ValueError):
    """A device that cannot play the part it was given, named."""


def _named(device: Any) -> str:
    name = getattr(device, "name", "")
    return repr(name) if isinstance(name, str) and name else type(device).__name__


def _movable(device: Any) -> bool:
    return callable(getattr(device, "set", None))


def check_parts(axes: Any, detector: Any, signals: Sequence, exposure: Any, dimensions: int | None) -> None:
    """Refuse devices whose kind is wrong for their part (no I/O): ``axes`` must be a list (or
    tuple) of ``dimensions`` movables (None: any number), ``detector`` triggerable and readable,
    ``exposure`` movable or None, and each of the value's ``signals`` named."""
    if isinstance(axes, (str, bytes)) or not isinstance(axes, Sequence):
        raise DeviceMismatch(f"axes: give a list of movables, one per axis of x (got {_named(axes)})")
    if dimensions is not None and len(axes) != dimensions:
        raise DeviceMismatch(f"the config has {dimensions} axes of x; {len(axes)} movables were given")
    for i, axis in enumerate(axes):
        if not _movable(axis):
            raise DeviceMismatch(f"axes[{i}]: {_named(axis)} is not movable (it has no set())")
    for part in ("trigger", "read", "describe"):
        if not callable(getattr(detector, part, None)):
            raise DeviceMismatch(f"detector: {_named(detector)} is not triggerable and readable (it has no {part}())")
    if exposure is not None and not _movable(exposure):
        raise DeviceMismatch(f"exposure: {_named(exposure)} is not movable (it has no set())")
    for signal in signals:
        if not isinstance(getattr(signal, "name", None), str) or not signal.name:
            raise DeviceMismatch(f"value: {_named(signal)} is not a named signal")


def check_read_by_detector(detector: Any, signals: Sequence):
    """A plan (no move, no document): refuse a value signal that the detector's reading does not
    hold (an axis's readback, another device's signal); its description is awaited in the
    RunEngine's loop for an ophyd-async device."""
    described: dict = {}

    async def describe() -> None:
        found = detector.describe()
        described.update(await found if inspect.isawaitable(found) else found)

    yield from bps.wait_for([describe])
    for signal in signals:
        if signal.name not in described:
            raise DeviceMismatch(
                f"value: {signal.name!r} is not in what {_named(detector)} reads "
                f"({', '.join(sorted(described)) or 'nothing'}): give a signal of the detector's reading"
            )
