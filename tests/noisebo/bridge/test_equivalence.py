"""A simulator behind the bridge, in another process, gives the campaign it gives in-process."""

import os
import subprocess
import sys

import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.campaign.driver import run_campaign
from noisebo.config import load_config
from tests.noisebo.bridge.conftest import remote_config, served

CASES = {
    "forrester": {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_steps": 3, "shots_before": 10}},
    "pfm": {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_steps": 2, "shots_before": 6}},
}


def shots_of(final):
    return [[(s.point, s.shot, s.x, s.t, s.reading) for s in p.shots] for p in final.points]


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_simulator_served_from_another_process_gives_the_in_process_campaign(tmp_path, name):
    source = f"data/configs/{name}.yaml"
    config = remote_config(source, CASES[name])
    with served(config, tmp_path / f"{name}.h5", seed=5) as running:
        client = subprocess.run(
            [sys.executable, "-m", "noisebo.bridge.serve_simulator", running.url, source],
            capture_output=True,
            text=True,
            timeout=300,
            env=os.environ,
        )
        remote = running.final()
    assert client.returncode == 0, client.stderr
    assert client.stdout.strip() == "completed"
    local_config = validated(load_config(source)).with_overrides(**CASES[name])
    local = run_campaign(local_config, build(local_config.instrument), 5).final
    assert remote.status.value == "completed" and not remote.failures
    assert shots_of(remote) == shots_of(local)
    assert [p.committed for p in remote.points] == [p.committed for p in local.points]
    assert [(d.x, d.t) for d in remote.decisions] == [(d.x, d.t) for d in local.decisions]
    assert np.array_equal(remote.summary.f_mean, local.summary.f_mean)
