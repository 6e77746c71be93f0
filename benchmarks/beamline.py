"""What the bluesky path costs: a campaign through a RunEngine, ophyd-async devices and a softioc
IOC over Channel Access on loopback (the bluesky plan), the same devices driven by ``noisebo run``'s
loop (the instrument kind ``bluesky``), against the same campaign driven as ``noisebo run`` drives
it with the simulator called directly (each shot sleeping its t there too, as an instrument
would); all three journal every shot and keep the HDF5 file.

    python benchmarks/beamline.py [--instrument forrester|pfm] [--t 0.1] [--steps 8] [--repeats 3]
                                  [--velocity 1e6] [--json FILE]

The campaign is the Forrester one (or the PFM line's: each shot a resonance sweep of t seconds,
served by the IOC as waveforms and fitted with the SHO model) with every BO point at t
(``acquisition.fixed_t``; the seed points spread over [t/2, 2t]), 10 shots per noise-measuring
point, 3 per point after. Figures, medians over ``--repeats`` campaigns each way:
the wall time, the time outside the decisions (each decision's ``latency_s`` taken off), the
overhead per shot (that time, less the shots' exposure, per shot), its share of the campaign's wall
time, the documents emitted per point and their size as JSON, and whether the two ways took the same
points with the same values (the IOC draws each shot from the same random stream, keyed by the
plan). The IOC's axes move at ``--velocity`` (default: at once), so the overhead is the software's,
not the motion's. Targets: at most 20 ms per shot and 10 % of the wall time at t = 0.1 s. Run it on
an idle machine.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401  (one OpenBLAS thread, as the command line has)

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

for name, value in {"EPICS_CA_ADDR_LIST": "127.0.0.1", "EPICS_CA_AUTO_ADDR_LIST": "NO"}.items():
    os.environ.setdefault(name, value)  # Channel Access stays on this machine

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from noisebo.campaign import engine  # noqa: E402
from noisebo.campaign.driver import drive, now_utc  # noqa: E402
from noisebo.events import DriverInfo  # noqa: E402
from noisebo.storage.recorder import Recorder  # noqa: E402
from noisebo.config import load_config  # noqa: E402
from noisebo.instruments import build  # noqa: E402
from noisebo.storage.record import read_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = {name: ROOT / "data" / "configs" / f"{name}.yaml" for name in ("forrester", "pfm")}
TARGET_MS, TARGET_SHARE = 20.0, 0.10


class Sleeping:
    """The simulator, each shot taking its t of wall time as an instrument's does."""

    def __init__(self, simulator) -> None:
        self._simulator = simulator
        self.name = simulator.name

    def simulate(self, x, t, rng):
        time.sleep(t)
        return self._simulator.simulate(x, t, rng)

    def truth(self, x):
        return self._simulator.truth(x)

    def noise_law(self, t):
        return self._simulator.noise_law(t)


def campaign_config(instrument: str, t: float, steps: int):
    return load_config(CONFIGS[instrument]).with_overrides(
        space={"t_min": t / 2, "t_max": 2 * t},
        acquisition={"fixed_t": t},
        schedule={"n_steps": steps, "shots_before": 10, "shots_after": 3},
    )


def direct(config, instrument=None) -> dict:
    """The campaign as ``noisebo run`` drives it in its process: the same engine loop, the journal
    and the HDF5 file written as the plan writes them, the simulator called for each shot (or
    ``instrument``'s ``measure``)."""
    instrument = instrument or Sleeping(build(config.instrument))
    with tempfile.TemporaryDirectory() as folder:
        started_at = engine.new_campaign(config, 0, DriverInfo(instrument.name, "", {}), {}, now_utc())
        with Recorder.create(Path(folder) / "campaign.h5", started_at) as recorder:
            started = time.perf_counter()
            final = drive(recorder.state, instrument, recorder.commit)
            wall = time.perf_counter() - started
    latencies = [d.latency_s for d in final.decisions]
    exposure = sum(shot.t for point in final.points for shot in point.shots)
    return figures(wall, latencies, final.data.column("n_shots").sum(), exposure) | {
        "values": final.data.column("value").tolist()
    }


def on_devices(config, prefix: str) -> dict:
    """The campaign as ``noisebo run`` drives it on the IOC's devices (the ``bluesky`` driver)."""
    from noisebo.beamline.driver import BlueskyInstrument

    settings = {"devices": "noisebo.beamline.sim_devices:sim_ioc_devices", "arguments": devices_of(config, prefix)}
    instrument = BlueskyInstrument(BlueskyInstrument.Settings(**settings))
    instrument.open()
    try:
        return direct(config, instrument)
    finally:
        instrument.close()


def devices_of(config, prefix: str) -> dict:
    return {"prefix": prefix, "spectra": config.instrument.kind == "pfm"}


def through_bluesky(config, prefix: str) -> dict:
    from bluesky import RunEngine

    from noisebo.beamline.plan import campaign_plan
    from noisebo.beamline.sim_devices import sim_ioc_devices

    engine = RunEngine({}, call_returns_result=True)
    devices = sim_ioc_devices(**devices_of(config, prefix))
    from ophyd_async.plan_stubs import ensure_connected

    engine(ensure_connected(*devices.all()))
    documents: list[tuple[str, dict]] = []
    engine.subscribe(lambda name, doc: documents.append((name, doc)))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "campaign.h5"
        started = time.perf_counter()
        d = devices
        engine(campaign_plan(config, d.axes, d.detector, d.value, exposure=d.exposure, path=path, shot_key=d.shot_key))
        wall = time.perf_counter() - started
        record = read_record(path)
    latencies = [float(v) for v in record.steps.latency_s]
    shots = len(record.shots.t)
    size = sum(len(json.dumps(doc, default=_plain)) for _, doc in documents)
    return figures(wall, latencies, shots, float(np.sum(record.shots.t))) | {
        "values": record.points.value.tolist(),
        "documents_per_point": len(documents) / len(record.points),
        "bytes_per_point": size / len(record.points),
    }


def _plain(value):
    return value.tolist() if isinstance(value, np.ndarray) else str(value)


def figures(wall: float, latencies, shots: int, exposure_s: float) -> dict:
    outside = wall - float(np.sum(latencies))
    overhead = outside - exposure_s
    return {
        "wall_s": wall,
        "outside_decisions_s": outside,
        "shots": int(shots),
        "overhead_ms_per_shot": 1000 * overhead / shots,
        "overhead_share": overhead / wall,
    }


def median(runs: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--instrument", choices=sorted(CONFIGS), default="forrester", help="default forrester")
    parser.add_argument("--t", type=float, default=0.1, help="every shot's exposure (s), default 0.1")
    parser.add_argument("--steps", type=int, default=8, help="BO steps per campaign, default 8")
    parser.add_argument("--repeats", type=int, default=3, help="campaigns each way, default 3")
    parser.add_argument(
        "--velocity",
        type=float,
        default=1e6,
        help="the IOC's axis speed, x units per s (default 1e6: motion costs nothing)",
    )
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)
    from noisebo.beamline.sim_ioc import running_ioc

    config = campaign_config(args.instrument, args.t, args.steps)
    direct(config)  # compiles the decision programs, outside the timing
    mine, driven, theirs = [], [], []
    with tempfile.TemporaryDirectory() as folder:
        served = Path(folder) / "served.yaml"  # the IOC's sweeps are as long as this config's longest
        served.write_text(yaml.safe_dump(config.model_dump(mode="json")))
        with running_ioc(served, velocity=args.velocity) as ioc:
            for _ in range(args.repeats):
                mine.append(through_bluesky(config, ioc.prefix))
                driven.append(on_devices(config, ioc.prefix))
                theirs.append(direct(config))
    same = all(m["values"] == d["values"] == o["values"] for m, o, d in zip(mine, driven, theirs))
    rows = [
        ("bluesky plan, IOC over CA", mine),
        ("noisebo's loop, IOC over CA", driven),
        ("noisebo's loop, simulator", theirs),
    ]
    print(f"{args.instrument}, BO points at t = {args.t:g} s, {args.steps} BO steps, median of {args.repeats}")
    print(f"{'way':28} {'wall s':>8} {'outside decisions s':>20} {'shots':>6} {'overhead ms/shot':>17} {'share':>7}")
    for label, runs in rows:
        print(
            f"{label:28} {median(runs, 'wall_s'):8.2f} {median(runs, 'outside_decisions_s'):20.2f} "
            f"{median(runs, 'shots'):6.0f} {median(runs, 'overhead_ms_per_shot'):17.1f} "
            f"{100 * median(runs, 'overhead_share'):6.1f}%"
        )
    per_shot = median(mine, "overhead_ms_per_shot") - median(theirs, "overhead_ms_per_shot")
    share = median(mine, "overhead_share") - median(theirs, "overhead_share")
    print(
        f"the bluesky path adds {per_shot:.1f} ms per shot (target <= {TARGET_MS:g}), "
        f"{100 * share:.1f} % of the wall time (target <= {100 * TARGET_SHARE:g} %)"
    )
    per_shot = median(driven, "overhead_ms_per_shot") - median(theirs, "overhead_ms_per_shot")
    share = median(driven, "overhead_share") - median(theirs, "overhead_share")
    print(f"noisebo's loop on the devices adds {per_shot:.1f} ms per shot, {100 * share:.1f} % of the wall time")
    print(
        f"documents per point {median(mine, 'documents_per_point'):.1f}, "
        f"{median(mine, 'bytes_per_point') / 1024:.1f} KiB of JSON per point"
    )
    print(f"the same points and values all three ways: {'yes' if same else 'NO'}")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "instrument": args.instrument,
                    "t": args.t,
                    "steps": args.steps,
                    "bluesky": mine,
                    "driver": driven,
                    "direct": theirs,
                    "same": same,
                },
                indent=1,
            )
        )
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
