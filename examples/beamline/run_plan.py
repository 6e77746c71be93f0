"""A noisebo campaign in a bluesky RunEngine, over EPICS Channel Access on this machine: a simulated
IOC (noisebo's Forrester simulator behind a motor and a detector) stands in for the beamline.

    python examples/beamline/run_plan.py [OUT.h5]    (an unfinished OUT.h5 is continued)

At a beamline, drop the IOC and the Sim* devices: hand the plan your own movable, detector, the
detector's value signal and its exposure-time signal (or a StandardDetector, prepared with t).
"""

import os
import sys
import time

os.environ.setdefault("EPICS_CA_ADDR_LIST", "127.0.0.1")  # Channel Access stays on this machine
os.environ.setdefault("EPICS_CA_AUTO_ADDR_LIST", "NO")

from bluesky import RunEngine  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.plan import campaign_plan  # noqa: E402
from noisebo.beamline.sim_devices import SimAxis, SimDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.config import load_config  # noqa: E402

CONFIG = "data/configs/forrester.yaml"
# exposures of milliseconds, and a time cost (reward alpha) that puts the best t near 50 ms
config = load_config(CONFIG).with_overrides(
    space={"t_min": 0.005, "t_max": 0.2}, reward={"alpha": 1800.0}, schedule={"n_steps": 6}
)
out = sys.argv[1] if len(sys.argv) > 1 else time.strftime("data/runs/bluesky-forrester-%Y%m%d-%H%M%S.h5")

streams: dict[str, str] = {}


def show(name: str, doc: dict) -> None:  # one line per decision, from the "decisions" stream
    if name == "descriptor":
        streams[doc["uid"]] = doc["name"]
    elif name == "event" and streams[doc["descriptor"]] == "decisions":
        d = doc["data"]
        print(
            f"step {d['decision_step']}: x {d['decision_x'][0]:.3f}, t {d['decision_t']:.3f} s, {d['decision_shots']} shots"
        )


with running_ioc(CONFIG) as ioc:
    RE = RunEngine({}, call_returns_result=True)
    RE.subscribe(show)
    with init_devices():
        stage = SimAxis(ioc.prefix, 0)
        det = SimDetector(ioc.prefix)
    plan = campaign_plan(config, [stage], det, det.value, exposure=det.exposure, path=out, shot_key=det.key)
    result = RE(plan)
    print(f"{result.exit_status}: {out}")
