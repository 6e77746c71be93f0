"""An instrument PC serving a simulated instrument through the noisebo bridge: the simulator of a
campaign config (a file, or a shipped config by name; default pfm). Each shot is drawn from the
random stream keyed by (campaign seed, point, shot), as in an in-process campaign, so the
campaign it serves equals the in-process one of the same seed. A complete instrument-PC script
on ``noisebo.bridge.client``: ``noisebo client --out DIR`` writes a copy to start your own from.

    NOISEBO_BRIDGE_TOKEN=TOKEN python -m noisebo.bridge.serve_simulator URL [CONFIG] [PACE]

PACE (default 0): each shot takes PACE x its exposure t in seconds of real time (1: as long as
the exposure would), for an instrument PC that measures in time as a real one does.
"""

import os
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

from noisebo.bridge.client import Measure, Spectrum, serve_instrument
from noisebo.campaign.driver import simulates
from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.config import load_config
from noisebo.keys import MEASURE, numpy_rng


def main(url: str, config: str = "pfm", pace: str = "0") -> str:
    instrument = build(validated(load_config(_config_file(config))).instrument)
    seconds_per_s = float(pace)
    if not seconds_per_s >= 0:
        raise SystemExit(f"PACE is a number of seconds per second of exposure, 0 or more; got {pace!r}")
    return serve_instrument(url, os.environ["NOISEBO_BRIDGE_TOKEN"], measure_with(instrument, seconds_per_s))


def measure_with(instrument, pace: float = 0.0) -> Measure:
    """The bridge client's ``measure`` for a noisebo driver: a simulator's shot drawn from the
    stream keyed by (seed, point, shot) after pace x t seconds of real time, a device's
    ``measure(x, t)``; a reading with a spectrum handed in as its ``Spectrum``."""

    def measure(request):
        x = np.asarray(request.x, dtype=np.float64)
        if simulates(instrument):
            time.sleep(pace * request.t)
            reading = instrument.simulate(x, request.t, numpy_rng(request.seed, MEASURE, request.point, request.shot))
        else:
            reading = instrument.measure(x, request.t)
        return reading.value if reading.spectrum is None else Spectrum(reading.spectrum, reading.reduction)

    return measure


def _config_file(config: str):
    """The file ``config`` names: a path, else a shipped config's name (pfm, forrester, ...)."""
    path = Path(config)
    if path.exists():
        return path
    return Path(str(resources.files("noisebo.configs") / f"{path.name.removesuffix('.yaml')}.yaml"))


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
