"""Fits from several threads at once (as in a sweep on a thread-pool task runner)."""

import threading

import numpy as np

from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.config import CampaignConfig

# Grid sizes no other test uses, and one config per thread (models are built per config): the
# threads trace and compile different programs at the same moment, as the campaigns of a sweep do.
CONFIGS = {
    seed: CampaignConfig().with_overrides(
        name=f"thread{seed}", space={"n_x": 23, "n_t": 17}, schedule={"n_steps": 2, "shots_before": 6}
    )
    for seed in (1, 2)
}


def test_concurrent_campaigns_equal_sequential_ones():
    results, errors = {}, []
    start = threading.Barrier(len(CONFIGS))

    def work(seed):
        try:
            start.wait()
            results[seed] = run_campaign(CONFIGS[seed], build(CONFIGS[seed].instrument), seed)
        except BaseException as error:  # noqa: BLE001 - reported below
            errors.append(error)

    threads = [threading.Thread(target=work, args=(s,)) for s in CONFIGS]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    for seed in CONFIGS:
        alone = run_campaign(CONFIGS[seed], build(CONFIGS[seed].instrument), seed)
        np.testing.assert_array_equal(alone.state.column("value"), results[seed].state.column("value"))
        assert alone.state.t_opt_history == results[seed].state.t_opt_history
