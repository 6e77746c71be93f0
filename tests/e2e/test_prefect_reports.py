"""End to end: a campaign run with `noisebo run` against a real Prefect server, read back through
Prefect's API as the UI reads it: the flow run's name and tags, a task run for each of the
method's stages (seed design, measure, fit SHO for sweeps, fit noise model, fit GP, acquire,
summarise) named by what it did, a log line per point, the progress, summary and points
artifacts, the status-change event; a failing campaign's event, state message and the Automation
that reacts to it.

Marked e2e: not in the default run (it starts servers), run by `.ci/run`."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from noisebo.flows.processes import wait_for

pytestmark = pytest.mark.e2e


def write_config(path: Path, config) -> Path:
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def noisebo_run(env, config: Path, out: Path, seed: int) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "noisebo.cli.main",
            "run",
            str(config),
            "--seed",
            str(seed),
            "--out",
            str(out),
            "--no-rrd",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=Path(__file__).resolve().parents[2],
    )


@pytest.fixture(scope="module")
def api(prefect_server):
    """A synchronous Prefect client of the session's server."""
    import prefect.settings as settings
    from prefect import get_client

    with settings.temporary_settings({settings.PREFECT_API_URL: prefect_server["PREFECT_API_URL"]}):
        with get_client(sync_client=True) as client:
            yield client


def flow_run_named(api, name: str):
    from prefect.client.schemas.filters import FlowRunFilter, FlowRunFilterName

    runs = api.read_flow_runs(flow_run_filter=FlowRunFilter(name=FlowRunFilterName(any_=[name])))
    assert len(runs) == 1, [r.name for r in runs]
    return runs[0]


def events_named(api, name: str, resource: str) -> list:
    from prefect.events.filters import EventFilter, EventNameFilter, EventResourceFilter

    page = api.read_events(
        EventFilter(event=EventNameFilter(name=[name]), resource=EventResourceFilter(id=[resource])), limit=50
    )
    return page.events


def logs_of(api, flow_run_id) -> list:
    from prefect.client.schemas.filters import LogFilter, LogFilterFlowRunId

    return api.read_logs(LogFilter(flow_run_id=LogFilterFlowRunId(any_=[flow_run_id])), limit=200)


def task_run_names(api, flow_run_id, expected: int) -> list[str]:
    """The names of the flow run's task runs, once the server has recorded ``expected`` of them
    in a final state (task runs reach it through events, a moment after the flow ends)."""
    from prefect.client.schemas.filters import FlowRunFilter, FlowRunFilterId

    def runs():
        return api.read_task_runs(flow_run_filter=FlowRunFilter(id=FlowRunFilterId(any_=[flow_run_id])), limit=200)

    wait_for(
        lambda: sum(r.state is not None and r.state.is_final() for r in runs()) >= expected, 60, f"{expected} task runs"
    )
    return sorted(r.name for r in runs())


def count(names: list[str], prefix: str) -> int:
    return sum(name.startswith(prefix) for name in names)


def test_a_campaign_is_named_tagged_logged_summarised_and_announced(prefect_server, api, tiny_config, tmp_path):
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterFlowRunId

    run = noisebo_run(prefect_server, write_config(tmp_path / "tiny.yaml", tiny_config), tmp_path / "runs", 4)
    assert run.returncode == 0, run.stdout + run.stderr
    path = tmp_path / "runs" / "tiny_reward_s0004.h5"
    assert [line.split(":")[0] for line in run.stdout.splitlines() if line.startswith(("seed point", "step "))] == [
        "seed point"
    ] * 3 + [f"step {k}/4" for k in range(1, 5)]  # the terminal's lines as before

    flow_run = flow_run_named(api, "tiny-reward-s4")
    assert flow_run.state.is_completed()
    assert set(flow_run.tags) >= {"noisebo", "config:tiny", "policy:reward", "seed:4", "driver:forrester"}

    names = task_run_names(api, flow_run.id, 1 + 7 + 3 * 4 + 1)
    assert count(names, "seed design: 3 points") == 1 and count(names, "summarise n=7") == 1
    assert count(names, "measure x=") == 7 and sum("(seed point " in name for name in names) == 3
    assert [name for name in names if name.startswith("fit GP")] == [f"fit GP n={n}" for n in range(3, 7)]
    assert count(names, "fit noise model n=") == 4 and count(names, "fit SHO") == 0  # scalar readings
    assert sorted(name.split(" -> ")[0] for name in names if name.startswith("acquire")) == [
        f"acquire step {k}/4" for k in range(1, 5)
    ]
    assert all(" -> x=" in name for name in names if name.startswith("acquire"))  # renamed by what it chose

    wanted = lambda: len([log for log in logs_of(api, flow_run.id) if log.name == "noisebo.campaign"]) >= 9  # noqa: E731
    wait_for(wanted, 60, "the run's log lines")
    lines = [log.message for log in logs_of(api, flow_run.id) if log.name == "noisebo.campaign"]
    assert sum(line.startswith("seed point: ") for line in lines) == 3
    assert sum(line.startswith("step ") for line in lines) == 4  # one line per point
    assert "campaign completed" in lines
    assert sum("the first decision in a process compiles the models" in line for line in lines) == 1

    artifacts = api.read_artifacts(
        artifact_filter=ArtifactFilter(flow_run_id=ArtifactFilterFlowRunId(any_=[flow_run.id]))
    )
    by_key = {a.key: a for a in artifacts if a.key}
    assert set(by_key) == {"tiny-reward-s4-progress", "tiny-reward-s4-summary", "tiny-reward-s4-points"}
    assert by_key["tiny-reward-s4-progress"].type == "progress" and float(by_key["tiny-reward-s4-progress"].data) == 100
    summary = by_key["tiny-reward-s4-summary"].data
    assert "| status | completed |" in summary and "| points | 7 of 7 (3 seed, 4 BO) |" in summary
    assert f"noisebo inspect {path}" in summary and f"`{path}`" in summary
    assert by_key["tiny-reward-s4-points"].type == "table"
    table = str(by_key["tiny-reward-s4-points"].data)
    assert '"point": 0, "step": 0,' in table  # seed points are step 0
    assert re.search(r'"step": 0, "x": \d\.\d+, "t_s": \d', table)  # numbers, x among them

    announced = lambda: events_named(api, "noisebo.campaign.completed", "noisebo.campaign.tiny-reward-s4")  # noqa: E731
    wait_for(lambda: bool(announced()), 60, "the completed event")
    event = announced()[0]
    assert event.resource["noisebo.seed"] == "4" and event.resource["noisebo.file"] == str(path)
    assert event.payload["points"] == 7 and event.payload["status"] == "completed"
    assert any(r.id == f"prefect.flow-run.{flow_run.id}" for r in event.related)


def test_a_spectra_campaign_fits_each_points_sweeps_in_a_task(prefect_server, api, tmp_path):
    from noisebo.config import load_config

    root = Path(__file__).resolve().parents[2]
    config = load_config(root / "data" / "configs" / "pfm.yaml").with_overrides(
        name="pfm_small", space={"n_x": 40, "n_t": 30}, schedule={"n_seed": 3, "n_steps": 1, "shots_before": 4}
    )
    run = noisebo_run(prefect_server, write_config(tmp_path / "pfm_small.yaml", config), tmp_path / "runs", 0)
    assert run.returncode == 0, run.stdout + run.stderr
    flow_run = flow_run_named(api, "pfm_small-double-s0")
    names = task_run_names(api, flow_run.id, 1 + 4 + 4 + 3 + 1)
    sho = [name for name in names if name.startswith("fit SHO")]
    assert len(sho) == 4 and all(name.startswith("fit SHO: 4 sweeps -> ") for name in sho), sho
    assert all(" of 4 fitted, value " in name for name in sho)


def test_a_failed_campaign_says_why_and_an_automation_reacts(prefect_server, api, tiny_config, tmp_path):
    from prefect.automations import Automation
    from prefect.events.actions import DoNothing
    from prefect.events.filters import EventFilter, EventNameFilter

    from noisebo.flows.reporting import failed_campaign_trigger

    automation = Automation(
        name="tiny campaign failed", trigger=failed_campaign_trigger("tiny"), actions=[DoNothing()]
    ).create()
    failing = tiny_config.with_overrides(instrument={"kind": "forrester", "faults": {"exception": 1.0}})
    run = noisebo_run(prefect_server, write_config(tmp_path / "tiny.yaml", failing), tmp_path / "runs", 6)
    assert run.returncode == 3, run.stdout + run.stderr

    flow_run = flow_run_named(api, "tiny-reward-s6")
    assert flow_run.state.is_failed()
    assert "failure budget exceeded" in flow_run.state.message
    failed = lambda: events_named(api, "noisebo.campaign.failed", "noisebo.campaign.tiny-reward-s6")  # noqa: E731
    wait_for(lambda: bool(failed()), 60, "the failed event")
    assert "failure budget exceeded" in failed()[0].payload["reason"]

    def triggered() -> bool:
        page = api.read_events(EventFilter(event=EventNameFilter(prefix=["prefect.automation.triggered"])), limit=50)
        return any(e.resource.id == f"prefect.automation.{automation.id}" for e in page.events)

    wait_for(triggered, 90, "the automation to fire")
