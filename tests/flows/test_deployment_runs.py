"""A campaign deployment's runs (flows/deployments.py): each in a folder of its own, so the same
seed twice gives two campaigns; the file's path is the flow run's (stored) result and is in its
summary artifact. Under the session's temporary Prefect server."""

from pathlib import Path

import h5py
import numpy as np

from noisebo.flows.campaign import campaign
from noisebo.flows.deployments import deployments_for


def test_the_same_seed_twice_through_the_deployment_gets_two_folders(tiny_yaml, prefect_harness, tmp_path):
    from prefect import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterFlowRunId

    deployment = deployments_for(tiny_yaml, tmp_path / "runs", [0], ["reward"])[0]
    assert deployment.parameters["per_run_dir"] is True
    parameters = {**deployment.parameters, "record_rrd": False, "show_progress": False}
    states = [campaign(**parameters, seed=1, return_state=True) for _ in range(2)]
    paths = [Path(state.result()) for state in states]
    assert all(state.is_completed() for state in states)
    assert paths[0] != paths[1] and paths[0].name == paths[1].name == "tiny_reward_s0001.h5"
    assert [p.parent.parent for p in paths] == [tmp_path / "runs"] * 2
    assert all(p.parent.name.startswith("tiny-reward-s1-") for p in paths)
    with h5py.File(paths[0], "r") as a, h5py.File(paths[1], "r") as b:
        np.testing.assert_array_equal(a["points/value"][()], b["points/value"][()])
    with get_client(sync_client=True) as client:
        for state, path in zip(states, paths):
            flow_run = client.read_flow_run(state.state_details.flow_run_id)
            assert flow_run.name == "tiny-reward-s1"
            artifacts = client.read_artifacts(
                artifact_filter=ArtifactFilter(flow_run_id=ArtifactFilterFlowRunId(any_=[flow_run.id]))
            )
            summary = next(a for a in artifacts if a.key == "tiny-reward-s1-summary")
            assert f"| file | `{path}` |" in summary.data
