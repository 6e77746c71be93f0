"""The pure helpers behind a flow run's Prefect reports (flows/reporting.py), on a hand-made
campaign: its name, tags, summary, points table, status event and log lines; and a report that
cannot be sent never stops the campaign."""

import logging

import numpy as np
import pytest

from noisebo.flows import reporting
from noisebo.campaign.engine import EngineState, PointEntry
from noisebo.events import (
    DriverInfo,
    PointCommitted,
    ShotFailed,
    ShotTaken,
    Status,
    StatusChanged,
    Summary,
)
from noisebo.reduction import Reading
from noisebo.state import CampaignState, Point

PATH = "/data/runs/tiny_reward_s0005.h5"


def entry(index: int, step: int, x: float, t: float, values: list[float], noise: float, measured: bool) -> PointEntry:
    point = Point(
        x=x,
        t=t,
        value=float(np.mean(values)),
        shot_std=noise,
        n_shots=len(values),
        noise=noise,
        noise_measured=measured,
    )
    shots = tuple(ShotTaken(index, k, (x,), t, Reading(v)) for k, v in enumerate(values))
    return PointEntry(PointCommitted(index, step, point, ()), shots)


@pytest.fixture
def state(tiny_config) -> EngineState:
    """Two seed points and one BO step of the tiny config (3 seed + 4 steps planned), converged at
    BO step 1 (0-based 0), finished with a summary at t_opt = 2.5 s."""
    entries = (
        entry(0, -1, 0.25, 1.0, [1.0, 2.0, 3.0], 0.5, True),
        entry(1, -1, 0.5, 2.0, [4.0, 6.0], 1.25, True),
        entry(2, 0, 0.125, 0.5, [-1.0], 0.75, False),
    )
    data = CampaignState(points=tuple(e.committed.point for e in entries), t_opt_history=(2.25,), converged_step=0)
    summary = Summary(f_mean=np.zeros(3), f_var=np.zeros(3), noise_fine=np.zeros(3), t_opt=2.5, hyperparameters={})
    return EngineState(
        config=tiny_config,
        seed=5,
        driver=DriverInfo("forrester", "0.1.0"),
        versions={},
        created_utc="2026-11-25T00:00:00Z",
        data=data,
        points=entries,
        summary=summary,
        status=Status.COMPLETED,
    )


def test_the_run_is_named_config_policy_seed_and_says_when_resumed(state):
    assert reporting.run_name("forrester", "double", 12) == "forrester-double-s12"
    assert reporting.run_name_of(state) == "tiny-reward-s5"
    assert reporting.run_name_of(state, resumed=True) == "tiny-reward-s5-resumed"


def test_the_tags_name_config_policy_seed_and_driver(state):
    assert reporting.run_tags(state) == ["noisebo", "config:tiny", "policy:reward", "seed:5", "driver:forrester"]
    assert reporting.run_tags(state, resumed=True)[-1] == "resumed"


def test_artifact_keys_are_what_prefect_accepts():
    assert reporting.artifact_key("tiny-reward-s5", "summary") == "tiny-reward-s5-summary"
    assert reporting.artifact_key("PFM_2d-info_rate-s0", "points") == "pfm-2d-info-rate-s0-points"


def test_the_summary_markdown(state):
    assert (
        reporting.summary_markdown(state, PATH)
        == """# tiny-reward-s5

| | |
|---|---|
| status | completed |
| points | 3 of 7 (2 seed, 1 BO) |
| shots | 6 |
| instrument time | 7.5 s |
| predicted optimal t | 2.5 s |
| noise model converged | at BO step 1 |
| file | `/data/runs/tiny_reward_s0005.h5` |

Look at it:

```bash
noisebo inspect /data/runs/tiny_reward_s0005.h5
noisebo report /data/runs/tiny_reward_s0005.h5
noisebo replay /data/runs/tiny_reward_s0005.h5
```
"""
    )


def test_the_summary_of_a_failed_budgeted_campaign_before_any_decision(state):
    from dataclasses import replace

    failed = replace(
        state,
        status=Status.FAILED,
        reason="failure budget exceeded: 5 of 5 shots failed",
        summary=None,
        data=replace(state.data, t_opt_history=(), converged_step=None),
        budget_s=100.0,
        spent_s=9.5,
    )
    text = reporting.summary_markdown(failed, PATH, resumed=True)
    assert text.startswith("# tiny-reward-s5-resumed\n")
    assert "| status | failed (failure budget exceeded: 5 of 5 shots failed) |" in text
    assert "| instrument time | 7.5 s (9.5 of 100 s budget spent) |" in text
    assert "| predicted optimal t | none yet |" in text
    assert "| noise model converged | not yet |" in text


def test_the_points_table(state):
    assert reporting.points_table(state) == [
        {
            "point": 0,
            "step": 0,
            "x": 0.25,
            "t_s": 1.0,
            "shots": 3,
            "value": 2.0,
            "noise": 0.5,
            "noise_measured": True,
        },
        {
            "point": 1,
            "step": 0,
            "x": 0.5,
            "t_s": 2.0,
            "shots": 2,
            "value": 5.0,
            "noise": 1.25,
            "noise_measured": True,
        },
        {
            "point": 2,
            "step": 1,
            "x": 0.125,
            "t_s": 0.5,
            "shots": 1,
            "value": -1.0,
            "noise": 0.75,
            "noise_measured": False,
        },
    ]


def test_the_status_event_carries_the_campaigns_labels(state):
    event = reporting.status_event(state, PATH, {"id": "f00", "name": "tiny-reward-s5"})
    assert event == {
        "event": "noisebo.campaign.completed",
        "resource": {
            "prefect.resource.id": "noisebo.campaign.tiny-reward-s5",
            "prefect.resource.name": "tiny-reward-s5",
            "noisebo.config": "tiny",
            "noisebo.policy": "reward",
            "noisebo.seed": "5",
            "noisebo.driver": "forrester",
            "noisebo.file": PATH,
        },
        "payload": {
            "status": "completed",
            "reason": "",
            "points": 3,
            "shots": 6,
            "instrument_time_s": 7.5,
            "t_opt_s": 2.5,
        },
        "related": [
            {
                "prefect.resource.id": "prefect.flow-run.f00",
                "prefect.resource.role": "flow-run",
                "prefect.resource.name": "tiny-reward-s5",
            }
        ],
    }


def test_the_failed_campaign_trigger_matches_the_failed_event(state):
    from dataclasses import replace

    from prefect.events.schemas.events import Resource

    trigger = reporting.failed_campaign_trigger("tiny")
    event = reporting.status_event(replace(state, status=Status.FAILED), PATH)
    assert event["event"] in trigger.expect
    assert trigger.match.matches(Resource(event["resource"]))
    other = dict(event["resource"], **{"noisebo.config": "forrester"})
    assert not trigger.match.matches(Resource(other))


def test_the_log_records_add_failed_shots_and_status_changes(state):
    events = [
        ShotFailed(3, 0, (0.5,), 2.0, "timeout", "no answer in 5 s"),
        StatusChanged(Status.FAILED, "failure budget exceeded"),
    ]
    assert reporting.log_records(state, events, ["step 2/4: ..."]) == [
        (logging.INFO, "step 2/4: ..."),
        (logging.WARNING, "point 3 shot 0 at t=2 s failed (timeout): no answer in 5 s"),
        (logging.ERROR, "campaign failed: failure budget exceeded"),
    ]


def test_progress_is_the_share_of_planned_points_until_the_end(state):
    from dataclasses import replace

    assert reporting.progress_percent(replace(state, status=Status.RUNNING)) == pytest.approx(300 / 7)
    assert reporting.progress_percent(state) == 100.0


def test_a_report_that_cannot_be_sent_is_said_once_and_the_campaign_goes_on(state):
    said = []
    report = reporting.RunReport(state, PATH, warn=said.append)
    report.on = True

    def broken():
        raise ConnectionError("server gone")

    assert report._safely("event", broken) is None
    assert report._safely("event", broken) is None  # not tried again
    assert (
        len(said) == 1
        and "the Prefect event of tiny-reward-s5 could not be sent (ConnectionError: server gone)" in said[0]
    )


def test_outside_a_flow_run_or_when_turned_off_nothing_is_sent(state, monkeypatch):
    assert not reporting.RunReport(state, PATH).on  # no flow run here
    monkeypatch.setenv("NOISEBO_PREFECT_REPORTS", "0")
    assert not reporting.enabled()


def test_progress_is_updated_at_most_once_a_second(state, monkeypatch):
    from dataclasses import replace

    now = [100.0]
    report = reporting.RunReport(state, PATH, clock=lambda: now[0])
    report.on, report.progress_id, report.last_progress = True, "id", 100.0
    sent = []
    monkeypatch.setattr(
        report, "update_progress", lambda s: (sent.append(len(s.points)), setattr(report, "last_progress", now[0]))
    )
    running = replace(state, status=Status.RUNNING)
    fewer = replace(running, points=running.points[:2])
    for t in (100.2, 100.5, 100.9, 101.0, 101.4, 102.1):
        now[0] = t
        report.committed(fewer, running, [], [])
    assert sent == [3, 3]  # at 101.0 and 102.1


def test_the_sweep_markdown():
    text = reporting.sweep_markdown(
        "tiny", "Median [IQR] over campaigns.\n\n| policy |\n|---|\n", "/runs/sweep", 4, ["RuntimeError: seed 3 failed"]
    )
    assert (
        text
        == """# sweep tiny

3 of 4 campaigns finished; files in `/runs/sweep`

Median [IQR] over campaigns.

| policy |
|---|

Failed:

- RuntimeError: seed 3 failed

Figures again from the files:

```bash
noisebo report /runs/sweep
```
"""
    )


@pytest.mark.parametrize(
    ("parameters", "name"),
    [
        ({"seed": 3}, "forrester-reward-s3"),
        ({"config": "data/configs/pfm.yaml", "policy": "info_rate"}, "pfm-info_rate-s0"),
        ({"config": "no/such.yaml", "seed": 2}, "campaign-s2"),
    ],
    ids=["default config", "policy given", "unreadable config"],
)
def test_a_campaign_run_is_named_from_its_parameters(parameters, name):
    assert reporting.campaign_run_name(parameters, "data/configs/forrester.yaml") == name


@pytest.mark.parametrize(
    ("seeds", "name"),
    [([0, 1, 2, 3], "sweep-forrester-s0-3"), ([5], "sweep-forrester-s5"), ([0, 2, 5], "sweep-forrester-s0,2,5")],
)
def test_a_sweep_run_is_named_from_its_parameters(seeds, name):
    assert reporting.sweep_run_name({"seeds": seeds}, "data/configs/forrester.yaml") == name


@pytest.mark.parametrize(
    ("path", "name"),
    [
        ("runs/pfm_info_rate_s0007.h5", "pfm-info_rate-s7-resumed"),
        ("runs/forrester_5shots_reward_s0000.h5", "forrester_5shots-reward-s0-resumed"),
        ("runs/elsewhere.h5", "elsewhere-resumed"),
    ],
)
def test_a_resume_run_is_named_from_its_file(path, name):
    assert reporting.resumed_run_name(path, ["reward", "double", "info_rate", "rate"]) == name
