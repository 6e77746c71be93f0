"""``noisebo run`` on ophyd-async devices: the instrument driver ``kind: bluesky``.

    instrument:
      kind: bluesky
      settings:
        devices: my_beamline.devices:noisebo_devices   # module:function, returns Devices
        arguments: {prefix: "BL01:"}                     # its keyword arguments

The function (a beamline's own, or ``noisebo.beamline.sim_devices:sim_ioc_devices`` for the
simulated IOC) builds the devices and returns them as ``Devices``; the driver connects them when
the campaign opens (a PV that does not answer is refused then, named, before anything moves) and
takes each shot as the bluesky plan does, in a RunEngine of its own: move the axes and set the
exposure once per point, trigger, read the value.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from pydantic import Field

import noisebo
from noisebo.campaign import engine
from noisebo.config import ConfigError
from noisebo.config.numbers import FrozenModel, PositiveFloat
from noisebo.events import Request
from noisebo.failures import InstrumentError
from noisebo.instruments.base import Reading

FACTORY = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


@dataclass(frozen=True)
class Devices:
    """What a campaign runs on, as a device factory returns it: ``axes``, one bluesky ``Movable``
    per axis of x in the config's order; ``detector``, a ``Triggerable`` and ``Readable``;
    ``value``, the signal of its reading that is a shot's value, or a ``plan.Spectrum``;
    ``exposure``, the ``Movable`` that takes a shot's t (s), or None for a detector prepared with
    ``TriggerInfo(livetime=t)``; ``shot_key``, a simulated detector's (seed, point, shot) signals
    (``sim_devices.ShotKey``), None for real hardware."""

    axes: Sequence[Any]
    detector: Any
    value: Any
    exposure: Any = None
    shot_key: Any = None

    def all(self) -> list:
        key = [] if self.shot_key is None else [self.shot_key]
        exposure = [] if self.exposure is None else [self.exposure]
        return [*self.axes, self.detector, *exposure, *key]


class BlueskySettings(FrozenModel):
    """``devices``: the function that builds the devices (``module:function``, importable where
    the campaign runs), returning ``Devices``; ``arguments``: its keyword arguments;
    ``connect_timeout_s``: how long connecting them may take before the campaign is refused."""

    devices: str = Field(
        pattern=FACTORY.pattern,
        description="module:function that builds the devices and returns noisebo.beamline.driver.Devices",
    )
    arguments: dict[str, Any] = Field(default_factory=dict, description="keyword arguments of that function")
    connect_timeout_s: PositiveFloat = Field(default=10.0, description="how long connecting may take (s)")


class DevicesNotConnected(ConfigError):
    """A device the factory built did not connect: its PVs are named."""


def load_factory(path: str):
    """The function ``module:function`` names, or a ``ConfigError`` saying why not."""
    module_name, _, attribute = path.partition(":")
    try:
        target: Any = importlib.import_module(module_name)
        for part in attribute.split("."):
            target = getattr(target, part)
    except ImportError as error:
        raise ConfigError(
            f"instrument.settings.devices: cannot load {path!r}: {error} (install its package, or put its "
            "folder on PYTHONPATH)"
        ) from None
    except AttributeError as error:
        raise ConfigError(f"instrument.settings.devices: cannot load {path!r}: {error}") from None
    if not callable(target):
        raise ConfigError(f"instrument.settings.devices: {path!r} is not a function")
    return target


class BlueskyInstrument:
    """Shots on ophyd-async (or other bluesky) devices that a factory named in the settings builds,
    through a RunEngine of its own; needs noisebo[bluesky] (see the module's docstring). It follows the campaign (``committed``): a simulated
    detector's shot key is the campaign's (seed, point, shot), so a campaign on the simulated
    IOC decides as ``noisebo run`` on the simulator does."""

    Settings = BlueskySettings
    name = "bluesky"
    version = noisebo.__version__

    def __init__(self, settings: BlueskySettings) -> None:
        self.settings = settings
        self._engine: Any = None
        self._rig: Any = None
        self._next: tuple[int, Request] | None = None

    def open(self) -> None:
        try:
            from bluesky import RunEngine
        except ImportError:
            raise ConfigError(
                "instrument 'bluesky' needs the bluesky packages: pip install 'noisebo[bluesky]'"
            ) from None

        # no signal handlers: the campaign's own handle Ctrl-C, and shots run on worker threads
        self._engine = RunEngine({}, call_returns_result=True, context_managers=[])
        devices = load_factory(self.settings.devices)(**self.settings.arguments)
        if not isinstance(devices, Devices):
            raise ConfigError(
                f"instrument.settings.devices: {self.settings.devices} returned {type(devices).__name__}, not Devices"
            )
        from noisebo.beamline.checks import DeviceMismatch, check_parts, check_read_by_detector
        from noisebo.beamline.plan import Rig, value_signals

        signals = value_signals(devices.value)
        try:
            check_parts(devices.axes, devices.detector, signals, devices.exposure, None)
            self._connect(devices)
            self._engine(check_read_by_detector(devices.detector, signals))
        except DeviceMismatch as error:
            raise ConfigError(f"instrument.settings.devices: {self.settings.devices}: {error}") from None

        self._rig = Rig(tuple(devices.axes), devices.detector, devices.value, devices.exposure, devices.shot_key)

    def _connect(self, devices: Devices) -> None:
        from ophyd_async.core import NotConnectedError
        from ophyd_async.plan_stubs import ensure_connected

        for i, axis in enumerate(devices.axes):
            _name(axis, f"axis{i}")
        _name(devices.detector, "detector")
        try:
            self._engine(ensure_connected(*devices.all(), timeout=self.settings.connect_timeout_s))
        except NotConnectedError as error:
            missing = sorted(set(re.findall(r"ca://([^\s:]+:[^\s]+)", str(error)))) or [str(error).strip()]
            raise DevicesNotConnected(
                f"instrument: the devices did not connect within {self.settings.connect_timeout_s:g} s: "
                f"no answer from {', '.join(missing)}"
            ) from None

    def committed(self, state) -> None:
        step = engine.ask(state)
        self._next = (state.seed, step) if isinstance(step, Request) else None

    def measure(self, x: np.ndarray, t: float) -> Reading:
        from bluesky.utils import FailedStatus

        from noisebo.beamline.plan import device_failure, shot_plan

        if self._engine is None:
            raise RuntimeError("the bluesky driver is not open: open() connects its devices")
        seed, step = self._wanted(x, t)
        try:
            return self._engine(shot_plan(seed, step, self._rig)).plan_result
        except (FailedStatus, TimeoutError, ConnectionError, OSError) as error:
            self._rig.placed = None
            cause = device_failure(error)
            raise InstrumentError(f"{type(cause).__name__}: {cause}".rstrip(": ")) from error

    def _wanted(self, x: np.ndarray, t: float) -> tuple[int, Request]:
        """The request this shot answers: the campaign's next (followed), or, for a caller that
        does not share its state, one at x and t of its own."""
        if self._next is not None:
            seed, step = self._next
            if np.allclose(step.x, x) and np.isclose(step.t, t):
                return seed, step
        where = tuple(float(v) for v in np.ravel(x))
        return 0, Request(point=-1, step=-1, x=where, t=float(t), wanted=1, taken=0, model_noise=None)

    def close(self) -> None:
        self._engine = None


def _name(device, name: str) -> None:
    if not getattr(device, "name", ""):
        device.set_name(name)
