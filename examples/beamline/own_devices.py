"""Your own ophyd-async devices over plain EPICS PVs in a noisebo campaign,
``python examples/beamline/own_devices.py [OUT.h5]``. The IOC (here a simulated one of that shape)
has an axis with a setpoint, a readback and a done-moving PV, and a detector with an exposure PV
and an acquire PV that returns to 0 once the value is in. Its puts complete at once, so set()
and trigger() wait for what the IOC says: the plan reads each shot when trigger() completes."""

import os
import sys
import time

os.environ.setdefault("EPICS_CA_ADDR_LIST", "127.0.0.1")  # Channel Access stays on this machine
os.environ.setdefault("EPICS_CA_AUTO_ADDR_LIST", "NO")
from bluesky import RunEngine  # noqa: E402
from bluesky.protocols import Movable, Triggerable  # noqa: E402
from ophyd_async.core import AsyncStatus, StandardReadable, init_devices, wait_for_value  # noqa: E402
from ophyd_async.core import StandardReadableFormat as Format  # noqa: E402
from ophyd_async.epics.core import epics_signal_r, epics_signal_rw  # noqa: E402

from noisebo.beamline.plan import DecisionLines, campaign_plan  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.config import load_config  # noqa: E402


class Stage(StandardReadable, Movable[float]):
    """PV (setpoint), PV:RBV (readback), PV:DMOV (1 once it stands): set(x) ends there."""

    def __init__(self, pv: str, name: str = "", tolerance: float = 1e-6, timeout_s: float = 60.0) -> None:
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback = epics_signal_r(float, f"{pv}:RBV")
        self.setpoint = epics_signal_rw(float, pv)
        self.done = epics_signal_r(bool, f"{pv}:DMOV")
        self.tolerance, self.timeout_s = tolerance, timeout_s
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        await self.setpoint.set(value)  # completes at once: the move has only begun
        # DMOV can still read 1 from before the move: first the readback at x, then DMOV
        await wait_for_value(self.readback, lambda at: abs(at - value) <= self.tolerance, self.timeout_s)
        await wait_for_value(self.done, True, self.timeout_s)


class Detector(StandardReadable, Triggerable):
    """PREFIX:EXPOSURE (s), PREFIX:ACQUIRE (1 while it acquires), PREFIX:VALUE (the shot's value)."""

    def __init__(self, prefix: str, name: str = "", timeout_s: float = 10.0) -> None:
        with self.add_children_as_readables(Format.HINTED_UNCACHED_SIGNAL):
            self.value = epics_signal_r(float, f"{prefix}VALUE")  # read afresh after each trigger
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.exposure = epics_signal_rw(float, f"{prefix}EXPOSURE")
        self.acquire = epics_signal_rw(bool, f"{prefix}ACQUIRE")
        self.timeout_s = timeout_s
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        exposure = await self.exposure.get_value()
        await self.acquire.set(True)  # completes at once; ACQUIRE reads 1 until the value is in
        await wait_for_value(self.acquire, False, exposure + self.timeout_s)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else time.strftime("data/runs/own-devices-%Y%m%d-%H%M%S.h5")
    config = load_config("data/configs/forrester.yaml").with_overrides(
        space={"t_min": 0.005, "t_max": 0.2}, reward={"alpha": 1800.0}, schedule={"n_steps": 6}
    )
    RE = RunEngine({}, call_returns_result=True)
    RE.subscribe(DecisionLines())
    with running_ioc("data/configs/forrester.yaml", plain=True) as ioc:  # at a beamline: your IOC
        with init_devices():
            stage, det = Stage(f"{ioc.prefix}M0"), Detector(ioc.prefix)
        result = RE(campaign_plan(config, [stage], det, det.value, exposure=det.exposure, path=out))
    print(f"{result.exit_status}: {out}")
