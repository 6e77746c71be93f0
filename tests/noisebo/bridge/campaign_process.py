"""A bridged campaign in a process of its own, driven as `noisebo run` drives it (the journal and
HDF5 recorder, the campaign loop, SIGINT/SIGTERM asking it to stop) but without Prefect:

    python -m tests.noisebo.bridge.campaign_process CONFIG.yaml FILE.h5

It prints the bridge's lines, then the final status and reason."""

import sys
from pathlib import Path

from noisebo.flows import abort
from noisebo.instruments import build
from noisebo.instruments.registry import driver_info, validated
from noisebo.campaign.driver import drive, now_utc
from noisebo.campaign.engine import new_campaign
from noisebo.config import load_config
from noisebo.storage.recorder import Recorder


def main(config_path: str, path: str) -> None:
    config = validated(load_config(config_path))
    instrument = build(config.instrument)
    with abort.AbortFlag().installed():
        instrument.open()
        try:
            started = new_campaign(config, 0, driver_info(config.instrument), {}, now_utc())
            with Recorder.create(Path(path), started) as recorder:
                stop = lambda: None if abort.requested() is None else f"{abort.requested()} received"  # noqa: E731
                final = drive(recorder.state, instrument, recorder.commit, stop_requested=stop)
        finally:
            instrument.close()
    print(final.status.value, final.reason, flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
