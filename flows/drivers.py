"""The instrument driver a campaign file was made with: light (no Prefect), so that `noisebo
resume` can refuse a file whose driver is missing before it starts anything."""

from __future__ import annotations

from pathlib import Path

from noisebo.instruments import build, registry
from noisebo.storage.recorder import read_started


def driver_of(path: Path):
    """The driver a campaign file was made with, built from the settings its journal recorded
    (with several instruments, their drivers by name); ``DriverNotInstalled`` says which driver
    and version the file needs."""
    started = read_started(path)
    try:
        if started.config.instruments is not None:
            return registry.build_fleet(started.config)
        return build(started.config.instrument)
    except registry.DriverNotInstalled as error:
        d = started.driver
        raise registry.DriverNotInstalled(
            f"{path} was made with the instrument driver {d.name!r} {d.version}, which is not installed here: {error}"
        ) from None
