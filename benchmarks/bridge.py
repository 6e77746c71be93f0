"""Per-shot overhead of the network bridge against an in-process instrument, on loopback.

    python benchmarks/bridge.py [--shots N]

Both campaigns take the same prerecorded readings, one point of N shots, through the same loop
and recorder (journal fsynced per commit): in-process from a driver that replays them, through
the bridge from a client process (``bridge.client``) that posts them. The time between
consecutive shots journaled is measured on the campaign's side; the overhead is the median
interval through the bridge minus the median in-process. Two kinds of shot: a scalar, and a
0.5-s simulated PFM sweep (3 rows × 5 000 samples, sent as JSON and SHO-fitted on arrival).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from noisebo.bridge.client import Spectrum, serve_instrument
from noisebo.instruments import build
from noisebo.instruments.registry import driver_info, validated
from noisebo.campaign.driver import drive, now_utc
from noisebo.campaign.engine import new_campaign
from noisebo.config import load_config
from noisebo.events import DriverInfo, ShotTaken
from noisebo.keys import MEASURE, numpy_rng
from noisebo.reduction import Reading
from noisebo.storage.recorder import Recorder

ROOT = Path(__file__).resolve().parents[1]
TOKEN = "benchmark-token"
DISTINCT = 16  # distinct prerecorded readings, cycled


def readings(kind: str, path: Path) -> None:
    """Prerecorded readings: scalars, or 0.5-s PFM sweeps from the simulator."""
    if kind == "scalar":
        np.save(path, np.random.default_rng(0).normal(1.0, 0.3, DISTINCT))
        return
    pfm = build(validated(load_config(ROOT / "data/configs/pfm.yaml")).instrument)
    sweeps = [pfm.simulate(np.array([0.4]), 0.5, numpy_rng(0, MEASURE, 0, k)).spectrum for k in range(DISTINCT)]
    np.save(path, np.stack(sweeps))


def as_reading(item: np.ndarray) -> Reading:
    return Reading(float(item)) if item.ndim == 0 else Reading(None, item, "sho")


class Replay:
    """An in-process driver that returns the prerecorded readings in turn."""

    name, version = "replay", "1"

    def __init__(self, items: np.ndarray):
        self.items, self.n = items, 0

    def measure(self, x, t: float) -> Reading:
        self.n += 1
        return as_reading(self.items[(self.n - 1) % len(self.items)])


def config_for(kind: str, shots: int, remote: bool):
    base = "pfm.yaml" if kind == "spectrum" else "forrester.yaml"
    config = validated(load_config(ROOT / "data/configs" / base)).with_overrides(
        schedule={"n_seed": 1, "n_steps": 0, "shots_before": shots}, space={"n_x": 40, "n_t": 30}
    )
    if remote:
        config = validated(
            config.with_overrides(instrument={"kind": "remote", "settings": {"port": 0, "shape": {"reading": kind}}})
        )
    return config


def shot_intervals(config, instrument, path: Path, client=None) -> np.ndarray:
    """Seconds between consecutive shots journaled, for one point of shots."""
    stamps: list[float] = []
    info = driver_info(config.instrument) if client is not None else DriverInfo("replay", "1", {})
    with Recorder.create(path, new_campaign(config, 0, info, {}, now_utc())) as recorder:

        def commit(state, events):
            new = recorder.commit(state, events)
            if any(isinstance(e, ShotTaken) for e in events):
                stamps.append(time.perf_counter())
            return new

        runner = threading.Thread(target=lambda: drive(recorder.state, instrument, commit))
        runner.start()
        if client is not None:
            client()
        runner.join()
    return np.diff(stamps)


def measure(kind: str, shots: int, workdir: Path) -> tuple[float, float]:
    items = workdir / f"{kind}.npy"
    readings(kind, items)
    local = shot_intervals(config_for(kind, shots, False), Replay(np.load(items)), workdir / f"{kind}_local.h5")
    remote_config = config_for(kind, shots, True)
    instrument = build(remote_config.instrument)
    instrument.open()
    try:

        def client():
            subprocess.run(
                [sys.executable, __file__, "--client", instrument.url, str(items)],
                check=True,
                env={**os.environ, "NOISEBO_BRIDGE_TOKEN": TOKEN},
            )

        remote = shot_intervals(remote_config, instrument, workdir / f"{kind}_remote.h5", client)
    finally:
        instrument.close()
    return float(np.median(local)), float(np.median(remote))


def run_client(url: str, items_path: str) -> None:
    items = np.load(items_path)

    def measure(request):
        item = items[request.shot % len(items)]
        return float(item) if item.ndim == 0 else Spectrum(item, "sho")

    serve_instrument(url, TOKEN, measure, log=lambda line: None)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shots", type=int, default=200, help="shots per kind")
    parser.add_argument("--client", nargs=2, metavar=("URL", "READINGS"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.client:
        run_client(*args.client)
        return 0
    os.environ["NOISEBO_BRIDGE_TOKEN"] = TOKEN
    targets = {"scalar": 5.0, "spectrum": 20.0}
    print(f"per-shot time, median of {args.shots - 1} intervals between shots journaled (ms)")
    print(f"{'shot':<16} {'in-process':>11} {'bridge':>9} {'overhead':>9} {'target':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for kind, target in targets.items():
            local, remote = measure(kind, args.shots, Path(tmp))
            overhead = (remote - local) * 1e3
            label = "0.5-s PFM sweep" if kind == "spectrum" else kind
            print(
                f"{label:<16} {local * 1e3:>11.2f} {remote * 1e3:>9.2f} {overhead:>9.2f} {target:>7.0f}"
                f"  {'ok' if overhead <= target else 'OVER'}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
