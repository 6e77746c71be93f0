"""The instrument PC killed at random moments and restarted: the campaign equals the
uninterrupted one, every shot once. (The campaign's side: tests/e2e/test_bridge_kills.py.)"""

import signal

import numpy as np

from tests.noisebo.bridge.conftest import remote_config, served
from tests.noisebo.bridge.kills import (
    OVERRIDES,
    SOURCE,
    assert_same_campaign,
    reference,
    start_client,
    wait_for_length,
)

SEED = 11


def test_the_instrument_pc_killed_at_random_moments_and_restarted(tmp_path):
    moments = sorted(np.random.default_rng(SEED).choice(np.arange(3, 30), size=3, replace=False))
    config = remote_config(SOURCE, OVERRIDES)
    with served(config, tmp_path / "c.h5", seed=SEED) as running:
        for moment in moments:
            client = start_client(running.url)
            wait_for_length(running.path, moment, lambda process=client: process.poll() is None)
            client.send_signal(signal.SIGKILL)
            client.wait()
        client = start_client(running.url, capture=True)
        _, err = client.communicate(timeout=240)
        assert client.returncode == 0, err
        final = running.final()
    assert not final.failures
    assert_same_campaign(running.path, reference(SEED))
