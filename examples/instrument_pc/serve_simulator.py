"""An instrument PC serving a simulated instrument through the noisebo bridge: the PFM of
data/configs/pfm.yaml unless another campaign config is named. Each shot is drawn from the
random stream keyed by (campaign seed, point, shot), as in an in-process campaign, so the
campaign it serves equals the in-process one of the same seed.

    NOISEBO_BRIDGE_TOKEN=TOKEN python examples/instrument_pc/serve_simulator.py URL [CONFIG]
"""

import os
import sys

import numpy as np

from noisebo.bridge.client import Spectrum, serve_instrument
from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.config import load_config
from noisebo.keys import MEASURE, numpy_rng


def main(url: str, config: str = "data/configs/pfm.yaml") -> str:
    instrument = build(validated(load_config(config)).instrument)

    def measure(request):
        rng = numpy_rng(request.seed, MEASURE, request.point, request.shot)
        reading = instrument.simulate(np.asarray(request.x), request.t, rng)
        return reading.value if reading.spectrum is None else Spectrum(reading.spectrum, reading.reduction)

    return serve_instrument(url, os.environ["NOISEBO_BRIDGE_TOKEN"], measure)


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
