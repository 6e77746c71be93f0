"""ophyd-async devices over Channel Access for the simulated IOC (``noisebo.beamline.sim_ioc``):
an axis per dimension of x and a detector whose exposure is the shot's t. They are the devices a
test, the example and the benchmark hand to the plan; a beamline hands it its own."""

from __future__ import annotations

import time

import numpy as np
from bluesky.protocols import Movable, Preparable, Triggerable
from ophyd_async.core import Array1D, AsyncStatus, StandardReadable, StandardReadableFormat, TriggerInfo
from ophyd_async.epics.core import epics_signal_r, epics_signal_rw

TIMEOUT_S = 10.0  # how long a put or a read may wait on the IOC beyond what it should take


class SimAxis(StandardReadable, Movable[float]):
    """Axis ``index`` of the IOC: ``set(x)`` puts the setpoint and completes when the readback
    has arrived (the IOC's put completes then), or fails after ``move_timeout_s``, or when the
    axis stopped short of x (held at a travel limit). ``low_limit_travel``, ``high_limit_travel``:
    its limits, read as an ophyd-async ``Motor``'s are."""

    def __init__(
        self, prefix: str, index: int, name: str = "", timeout_s: float = TIMEOUT_S, move_timeout_s: float = 60.0
    ) -> None:
        with self.add_children_as_readables(StandardReadableFormat.HINTED_SIGNAL):
            self.readback = epics_signal_r(float, f"{prefix}M{index}:RBV", timeout=timeout_s)
        self.setpoint = epics_signal_rw(float, f"{prefix}M{index}", timeout=timeout_s)
        self.low_limit_travel = epics_signal_r(float, f"{prefix}M{index}.DRVL", timeout=timeout_s)
        self.high_limit_travel = epics_signal_r(float, f"{prefix}M{index}.DRVH", timeout=timeout_s)
        self._move_timeout_s = move_timeout_s
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        await self.setpoint.set(float(value), timeout=self._move_timeout_s)
        at = await self.readback.get_value()
        if abs(at - value) > 1e-9 * max(1.0, abs(value)):
            raise ValueError(f"{self.name}: stopped at {at:g}, short of {value:g} (a travel limit)")


class ShotKey(StandardReadable):
    """The simulated detector's random stream of a shot: (seed, point, shot)."""

    def __init__(self, prefix: str, name: str = "", timeout_s: float = TIMEOUT_S) -> None:
        self.seed = epics_signal_rw(int, f"{prefix}SEED", timeout=timeout_s)
        self.point = epics_signal_rw(int, f"{prefix}POINT", timeout=timeout_s)
        self.shot = epics_signal_rw(int, f"{prefix}SHOT", timeout=timeout_s)
        super().__init__(name=name)


class SimDetector(StandardReadable, Triggerable):
    """The IOC's detector: ``exposure`` (s) is set before a shot, ``trigger()`` exposes and
    completes when ``value`` holds the shot's value. A put that completes sooner than the exposure
    means the IOC went away (Channel Access completes a put whose server vanished): the trigger
    fails then, rather than read a stale value. ``timeout_s``: how long a put or read may wait
    on the IOC beyond what it should take."""

    def __init__(self, prefix: str, name: str = "", timeout_s: float = TIMEOUT_S) -> None:
        with self.add_children_as_readables(StandardReadableFormat.HINTED_UNCACHED_SIGNAL):
            self.value = epics_signal_r(float, f"{prefix}VALUE", timeout=timeout_s)
        with self.add_children_as_readables(StandardReadableFormat.CONFIG_SIGNAL):
            self.exposure = epics_signal_rw(float, f"{prefix}EXPOSURE", timeout=timeout_s)
        self.acquire = epics_signal_rw(bool, f"{prefix}ACQUIRE", timeout=timeout_s)
        self.key = ShotKey(prefix, timeout_s=timeout_s)
        self._timeout_s = timeout_s
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        exposure = await self.exposure.get_value()
        started = time.monotonic()
        await self.acquire.set(True, timeout=exposure + self._timeout_s)
        took = time.monotonic() - started
        if took < 0.95 * exposure:
            raise ConnectionError(
                f"{self.name}: the exposure of {exposure:g} s ended after {took:.3f} s: the IOC went away"
            )


class SimPreparedDetector(SimDetector, Preparable):
    """The IOC's detector as a detector that is prepared for its exposures, as an ophyd-async
    ``StandardDetector`` is: ``prepare(TriggerInfo(livetime=t))`` sets the exposure (the plan's
    path when no exposure signal is given)."""

    @AsyncStatus.wrap
    async def prepare(self, value: TriggerInfo) -> None:
        if value.livetime is None:
            raise ValueError(f"{self.name}: prepared without a livetime: no exposure to set")
        await self.exposure.set(float(value.livetime))


class SimSpectrumDetector(SimDetector):
    """The IOC's detector where a shot is a resonance sweep (the PFM simulators): its reading holds
    the sweep's ``frequency`` (Hz), ``amplitude`` (pm) and ``phase`` (deg), arrays as long as the
    longest sweep, NaN past this one's end; the plan is given them as
    ``Spectrum(det.frequency, det.amplitude, det.phase)``."""

    def __init__(self, prefix: str, name: str = "", timeout_s: float = TIMEOUT_S) -> None:
        with self.add_children_as_readables(StandardReadableFormat.UNCACHED_SIGNAL):
            self.frequency = epics_signal_r(Array1D[np.float32], f"{prefix}FREQUENCY", timeout=timeout_s)
            self.amplitude = epics_signal_r(Array1D[np.float32], f"{prefix}AMPLITUDE", timeout=timeout_s)
            self.phase = epics_signal_r(Array1D[np.float32], f"{prefix}PHASE", timeout=timeout_s)
        super().__init__(prefix, name=name, timeout_s=timeout_s)


def sim_ioc_devices(prefix: str, dimensions: int = 1, spectra: bool = False, timeout_s: float = TIMEOUT_S):
    """The simulated IOC's devices as the ``bluesky`` driver takes them (its ``devices`` factory,
    ``noisebo.beamline.sim_devices:sim_ioc_devices``): ``dimensions`` axes and the detector, a
    ``SimSpectrumDetector`` read as a ``Spectrum`` where ``spectra`` (the PFM simulators)."""
    from noisebo.beamline.driver import Devices
    from noisebo.beamline.plan import Spectrum

    axes = [SimAxis(prefix, i, name=f"m{i}", timeout_s=timeout_s) for i in range(dimensions)]
    det: SimDetector
    value: object
    if spectra:
        det = SimSpectrumDetector(prefix, name="det", timeout_s=timeout_s)
        value = Spectrum(det.frequency, det.amplitude, det.phase)
    else:
        det = SimDetector(prefix, name="det", timeout_s=timeout_s)
        value = det.value
    return Devices(axes, det, value, exposure=det.exposure, shot_key=det.key)
