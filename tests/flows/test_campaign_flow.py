"""The campaign and sweep flows under a real (temporary) Prefect server."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from noisebo.flows.campaign import campaign, campaign_path, resume, start_campaign
from noisebo.flows.sweep import sweep, task_runner
from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.storage.hdf5 import CampaignFileError
from noisebo.storage.recorder import Recorder


def points_of(path):
    with h5py.File(path, "r") as f:
        return {k: v[()] for k, v in f["points"].items()}, {k: v[()] for k, v in f["shots"].items()}, dict(f.attrs)


@pytest.fixture(scope="module")
def finished(tiny_config, prefect_harness, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    return campaign(tiny_config, seed=5, out_dir=str(out))


def test_flow_campaign_equals_the_pure_loop(tiny_config, finished):
    points, shots, attrs = points_of(finished)
    pure = run_campaign(tiny_config, build(tiny_config.instrument), 5)
    assert attrs["status"] == "completed" and attrs["n_points"] == 3 + 4
    np.testing.assert_array_equal(points["x"], [p.x[0] for p in pure.state.points])
    np.testing.assert_array_equal(points["t"], [p.t for p in pure.state.points])
    np.testing.assert_array_equal(points["value"], [p.value for p in pure.state.points])
    np.testing.assert_array_equal(points["n_shots"], [p.n_shots for p in pure.state.points])
    assert len(shots["value"]) == sum(p.n_shots for p in pure.state.points)
    assert json.loads(attrs["config_json"])["name"] == "tiny"


def test_each_step_records_the_inputs_its_models_saw(finished):
    with h5py.File(finished, "r") as f:
        x, t, step = f["points/x"][()], f["points/t"][()], f["points/step"][()]
        steps = {k: f["steps"][k][()] for k in ("primary_inputs", "noise_inputs", "binned")}
    for k in range(len(steps["binned"])):  # BO step k + 1 was fitted on the points of steps 0 (seed) to k
        before = step <= k
        assert steps["primary_inputs"][k] == np.unique(x[before]).size
        assert steps["noise_inputs"][k] == np.unique(t[before]).size  # 10 shots, then 3: all train it
    assert not steps["binned"].any()


def test_file_layout_is_readable_with_plain_h5py(finished):
    with h5py.File(finished, "r") as f:
        assert f.attrs["schema"] == "noisebo.campaign" and f.attrs["schema_version"] == 5
        assert json.loads(f.attrs["driver_json"]) == {
            "name": "forrester",
            "version": "0.1.0",
            "settings": {
                "a0": 0.1,
                "a1": 2.0,
                "law": "inv_sqrt",
                "patch_a0": 0.0,
                "patch_x": 0.5,
                "patch_width": 0.05,
                "seed": 0,
            },
        }
        assert f["steps/acq_map"].shape == (4, 40, 30)
        assert f["steps/t_opt"].attrs["units"] == "s"
        assert set(json.loads(f.attrs["versions_json"])) >= {"python", "jax", "numpyro", "h5py", "prefect"}
        assert f["summary/f_mean"].shape == (40,)
        for i in range(f.attrs["n_points"]):
            mine = f["shots/point"][()] == i
            assert f["shots/value"][mine].mean() == pytest.approx(f["points/value"][i])


def test_a_second_campaign_on_the_same_file_is_refused(tiny_config, finished):
    before = Path(finished).read_bytes()
    with pytest.raises(CampaignFileError, match="already exists"):
        start_campaign(finished, tiny_config, 5)
    assert Path(finished).read_bytes() == before


def test_a_running_campaign_locks_its_journal(tiny_config, tmp_path):
    path = campaign_path(tiny_config, 1, tmp_path)
    with start_campaign(path, tiny_config, 1):
        with pytest.raises(CampaignFileError, match="in use by another running campaign"):
            Recorder.resume(path)


def test_resuming_a_finished_campaign_changes_nothing(finished, prefect_harness):
    before = points_of(finished)
    resume(finished)
    after = points_of(finished)
    for a, b in zip(before[:2], after[:2]):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])


def test_sweep_runs_every_campaign_and_summarises(tiny_config, finished, prefect_harness, tmp_path):
    # Four campaigns at once writing into one folder: four distinct, intact files, each equal to
    # its seed run alone.
    four_at_once = sweep.with_options(task_runner=task_runner("threads", 4))
    table = four_at_once(tiny_config, seeds=[5, 6], policies=["reward", "double"], out_dir=str(tmp_path))
    files = sorted(p.name for p in tmp_path.glob("*.h5"))
    assert files == [f"tiny_{policy}_s000{seed}.h5" for policy in ("double", "reward") for seed in (5, 6)]
    text = Path(table).read_text()
    assert "| reward | 2 |" in text and "| double | 2 |" in text
    alone, _, _ = points_of(finished)
    swept, _, _ = points_of(tmp_path / "tiny_reward_s0005.h5")
    np.testing.assert_array_equal(alone["value"], swept["value"])
    for policy in ("reward", "double"):
        config = tiny_config.with_overrides(acquisition={"policy": policy})
        for seed in (5, 6):
            pure = run_campaign(config, build(config.instrument), seed)
            points, shots, attrs = points_of(tmp_path / f"tiny_{policy}_s{seed:04d}.h5")
            assert attrs["status"] == "completed" and attrs["seed"] == seed and attrs["policy"] == policy
            np.testing.assert_array_equal(points["value"], [p.value for p in pure.state.points])
            assert len(shots["value"]) == sum(p.n_shots for p in pure.state.points)
    summary = json.loads((tmp_path / "sweep_summary.json").read_text())
    assert len(summary["records"]) == 4
    from prefect import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey

    with get_client(sync_client=True) as client:  # the sweep's summary as an artifact of its flow run
        artifact = client.read_artifacts(
            artifact_filter=ArtifactFilter(key=ArtifactFilterKey(any_=["sweep-tiny-summary"]))
        )[-1]
        swept_by = client.read_flow_run(artifact.flow_run_id)
    assert swept_by.name == "sweep-tiny-s5-6"  # named from its parameters, not at random
    assert artifact.data.startswith(f"# sweep tiny\n\n4 of 4 campaigns finished; files in `{tmp_path}`\n")
    assert "| reward | 2 |" in artifact.data
    assert (tmp_path / "convergence_steps.png").stat().st_size > 10_000
    # `noisebo report DIR` redraws the same from the files alone
    from noisebo.view.report import report

    written = report(tmp_path, tmp_path / "report")
    assert [p.name for p in written] == ["convergence_steps.png", "sweep_summary.md"]
    assert written[1].read_text() == Path(table).read_text()


def test_the_flow_runs_a_campaign_of_three_instruments_each_on_its_loop(tiny_config, prefect_harness, tmp_path):
    from noisebo.config import parse_config
    from noisebo.storage.record import read_record

    dumped = tiny_config.model_dump(mode="json")
    one = dumped.pop("instrument")
    fleet = parse_config({**dumped, "instruments": [{**one, "name": n} for n in ("a", "b", "c")]})
    path = campaign(fleet, seed=5, out_dir=str(tmp_path), record_rrd=False)
    record = read_record(path)
    assert record.status == "completed" and len(record.points) == 3 + 4
    assert sorted(record.points.index.tolist()) == list(range(7))
    assert set(record.points.instrument) <= {"a", "b", "c"} and set(record.shots.instrument) == {"a", "b", "c"}
    for index, instrument in zip(record.points.index, record.points.instrument):
        assert {record.shots.instrument[k] for k in np.flatnonzero(record.shots.point == index)} == {instrument}
    assert record.driver["name"] == "fleet" and set(record.driver["settings"]["instruments"]) == {"a", "b", "c"}
    assert record.driver["settings"]["instruments"]["b"]["name"] == "forrester"
    loops, decided_in = instrument_flow_runs("tiny-reward-s5")
    assert sorted(loops) == ["tiny-reward-s5-a", "tiny-reward-s5-b", "tiny-reward-s5-c"]
    assert {run.state_name for run in loops.values()} == {"Completed"}
    parents = {run.parent_task_run_id for run in loops.values()}
    assert None not in parents and len(parents) == 3  # subflow runs of the campaign's, one each
    assert sum(decided_in.values()) == 4  # the 4 BO steps' "fit noise model" tasks, each in an instrument's run


def instrument_flow_runs(campaign_run: str):
    """The ``instrument`` flow runs named after ``campaign_run`` (name -> flow run), and how many
    ``fit noise model`` task runs each holds."""
    from prefect import get_client
    from prefect.client.schemas.filters import (
        FlowFilter,
        FlowFilterName,
        FlowRunFilter,
        FlowRunFilterId,
        TaskRunFilter,
        TaskRunFilterName,
    )

    with get_client(sync_client=True) as client:
        runs = client.read_flow_runs(flow_filter=FlowFilter(name=FlowFilterName(any_=["instrument"])))
        loops = {run.name: run for run in runs if run.name.startswith(f"{campaign_run}-")}
        decided_in = {}
        for name, run in loops.items():
            tasks = client.read_task_runs(
                flow_run_filter=FlowRunFilter(id=FlowRunFilterId(any_=[run.id])),
                task_run_filter=TaskRunFilter(name=TaskRunFilterName(like_="fit noise model")),
            )
            decided_in[name] = len(tasks)
    return loops, decided_in


def test_a_sweep_runs_campaigns_of_several_instruments(tiny_config, prefect_harness, tmp_path):
    from noisebo.config import parse_config
    from noisebo.storage.record import read_record

    dumped = tiny_config.model_dump(mode="json")
    one = dumped.pop("instrument")
    fleet = parse_config({**dumped, "instruments": [{**one, "name": n} for n in ("a", "b")]})
    table = sweep.with_options(task_runner=task_runner("threads", 2))(
        fleet, seeds=[1, 2], policies=["reward"], out_dir=str(tmp_path)
    )
    assert "| reward | 2 |" in Path(table).read_text()
    for seed in (1, 2):
        record = read_record(campaign_path(fleet, seed, tmp_path))
        assert record.status == "completed" and set(record.shots.instrument) == {"a", "b"}
