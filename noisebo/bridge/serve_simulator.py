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

from noisebo.bridge.client import Spectrum, serve_instrument
from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.config import load_config
from noisebo.keys import MEASURE, numpy_rng


def main(url: str, config: str = "pfm", pace: str = "0") -> str:
    instrument = build(validated(load_config(_config_file(config))).instrument)
    seconds_per_s = float(pace)
    if not seconds_per_s >= 0:
        raise SystemExit(f"PACE is a number of seconds per second of exposure, 0 or more; got {pace!r}")

    def measure(request):
        time.sleep(seconds_per_s * request.t)
        rng = numpy_rng(request.seed, MEASURE, request.point, request.shot)
        reading = instrument.simulate(np.asarray(request.x), request.t, rng)
        return reading.value if reading.spectrum is None else Spectrum(reading.spectrum, reading.reduction)

    return serve_instrument(url, os.environ["NOISEBO_BRIDGE_TOKEN"], measure)


def _config_file(config: str):
    """The file ``config`` names: a path, else a shipped config's name (pfm, forrester, ...)."""
    path = Path(config)
    if path.exists():
        return path
    return Path(str(resources.files("noisebo.configs") / f"{path.name.removesuffix('.yaml')}.yaml"))


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
