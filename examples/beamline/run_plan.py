"""A noisebo campaign in a bluesky RunEngine over EPICS Channel Access, its documents in Tiled,
``python examples/beamline/run_plan.py [OUT.h5] [--tiled URI]`` (an unfinished OUT.h5 continues).
A simulated IOC stands in for the beamline: at yours, build your own devices in its place."""

import argparse
import os
import time

os.environ.setdefault("EPICS_CA_ADDR_LIST", "127.0.0.1")  # Channel Access stays on this machine
os.environ.setdefault("EPICS_CA_AUTO_ADDR_LIST", "NO")
from bluesky import RunEngine  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.plan import DecisionLines, campaign_plan  # noqa: E402
from noisebo.beamline.sim_devices import SimAxis, SimDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.config import load_config  # noqa: E402

parser = argparse.ArgumentParser()
parser.add_argument("out", nargs="?", default=time.strftime("data/runs/bluesky-%Y%m%d-%H%M%S.h5"))
parser.add_argument("--tiled", help="a Tiled server's URI to write the run to (its key: TILED_API_KEY)")
args = parser.parse_args()
# exposures of milliseconds, and a time cost (reward alpha) that puts the best t near 50 ms
config = load_config("data/configs/forrester.yaml").with_overrides(
    space={"t_min": 0.005, "t_max": 0.2}, reward={"alpha": 1800.0}, schedule={"n_steps": 6}
)
RE = RunEngine({}, call_returns_result=True)
RE.subscribe(DecisionLines())  # a line per decision
if args.tiled:
    from bluesky_tiled_plugins import TiledWriter
    from tiled.client import from_uri

    RE.subscribe(TiledWriter(from_uri(args.tiled, api_key=os.environ.get("TILED_API_KEY")), batch_size=1))
with running_ioc("data/configs/forrester.yaml") as ioc:  # at a beamline: your IOCs are running
    with init_devices():  # your devices
        stage, det = SimAxis(ioc.prefix, 0), SimDetector(ioc.prefix)
    plan = campaign_plan(config, [stage], det, det.value, exposure=det.exposure, shot_key=det.key, path=args.out)
    result = RE(plan)
print(f"{result.exit_status}: {args.out}" + "".join(f" (run {uid})" for uid in result.run_start_uids))
