"""A campaign through the bluesky plan, for real: a softioc IOC in its own process serving the
Forrester simulator over Channel Access, ophyd-async devices, a RunEngine. The journal and the
HDF5 file are those of ``noisebo run``, and the decisions are the same, shot for shot, through a
pause, an abort and an IOC that dies mid-campaign."""

import re
import threading
import time
from functools import partial

import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")
pytest.importorskip("softioc")

from bluesky import RunEngine  # noqa: E402
from bluesky import plan_stubs as bps  # noqa: E402
from bluesky.utils import FailedStatus, RunEngineInterrupted  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.plan import (  # noqa: E402
    DECISIONS,
    BeyondLimits,
    CampaignNotCompleted,
    DeviceMismatch,
    campaign_plan,
)
from noisebo.beamline.sim_devices import SimAxis, SimDetector, SimPreparedDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.storage.record import read_record  # noqa: E402
from tests.noisebo.beamline.quick import FORRESTER, QUICK, same_as_alone  # noqa: E402


def connected(prefix: str, timeout_s: float = 10.0):
    """A RunEngine, the IOC's axis and detector connected to it, and the documents it emits."""
    engine = RunEngine({}, call_returns_result=True)
    with init_devices(timeout=10.0):
        x = SimAxis(prefix, 0, timeout_s=timeout_s, move_timeout_s=timeout_s)
        det = SimDetector(prefix, timeout_s=timeout_s)
    documents: list[tuple[str, dict]] = []
    engine.subscribe(lambda name, doc: documents.append((name, doc)))
    return engine, x, det, documents


@pytest.fixture
def forrester_ioc():
    # One IOC at a time: with Channel Access searches sent to 127.0.0.1 only, the last IOC to bind
    # the server port on this host answers them, so two at once would hide each other.
    with running_ioc(FORRESTER) as ioc:
        yield ioc


def primary(documents) -> list[dict]:
    descriptors = {doc["uid"]: doc["name"] for name, doc in documents if name == "descriptor"}
    return [doc["data"] for name, doc in documents if name == "event" and descriptors[doc["descriptor"]] == "primary"]


def at_event(engine, documents, count: int, then):
    """Call ``then()`` from another thread (as an operator would: the RunEngine's own thread
    emits the documents) once the ``count``-th primary event is out; returns the subscription."""

    def callback(name, doc):
        if name == "event" and len(primary(documents)) == count:
            threading.Thread(target=then).start()

    return engine.subscribe(callback)


def test_a_campaign_through_the_run_engine_decides_as_noisebo_run_does(forrester_ioc, tmp_path):
    engine, x, det, documents = connected(forrester_ioc.prefix)
    path = tmp_path / "forrester.h5"
    result = engine(campaign_plan(QUICK, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key))
    assert result.exit_status == "success"
    record = same_as_alone(path)

    names = [name for name, _ in documents]
    start = next(doc for name, doc in documents if name == "start")
    stop = next(doc for name, doc in documents if name == "stop")
    assert names[0] == "start" and names[-1] == "stop" and stop["exit_status"] == "success"
    assert start["noisebo"]["seed"] == 0 and start["noisebo"]["file"] == str(path)
    assert start["noisebo"]["config"]["name"] == QUICK.name and start["noisebo"]["resumed"] is False
    assert stop["num_events"] == {"primary": len(record.shots.t), DECISIONS: len(record.steps.step)}
    shots = primary(documents)
    assert [s[det.value.name] for s in shots] == list(record.shots.value)
    assert [s["noisebo_t"] for s in shots] == list(record.shots.t)
    assert [(s["noisebo_point"], s["noisebo_shot"]) for s in shots] == list(zip(record.shots.point, record.shots.shot))


def test_a_detector_prepared_with_its_livetime_takes_the_same_campaign(forrester_ioc, tmp_path):
    engine = RunEngine({}, call_returns_result=True)
    with init_devices(timeout=10.0):
        x = SimAxis(forrester_ioc.prefix, 0)
        det = SimPreparedDetector(forrester_ioc.prefix)
    path = tmp_path / "forrester.h5"
    plan = campaign_plan(QUICK, [x], det, det.value, path=path, shot_key=det.key, rerun="record")
    assert engine(plan).exit_status == "success"
    same_as_alone(path)
    assert path.with_suffix(".rrd").stat().st_size > 10_000  # the campaign's Rerun recording beside it


def test_a_paused_run_resumes_and_an_aborted_one_continues_in_a_new_run_each_shot_once(forrester_ioc, tmp_path):
    engine, x, det, documents = connected(forrester_ioc.prefix)
    path = tmp_path / "forrester.h5"
    plan = partial(campaign_plan, QUICK, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key)

    token = at_event(engine, documents, 12, engine.request_pause)  # as Ctrl-C: at the next checkpoint
    with pytest.raises(RunEngineInterrupted):
        engine(plan())
    engine.unsubscribe(token)
    token = at_event(engine, documents, 30, engine.request_pause)
    with pytest.raises(RunEngineInterrupted):
        engine.resume()
    engine.unsubscribe(token)
    aborted = engine.abort("the operator stopped it")
    assert aborted.exit_status == "abort"
    first = read_record(path)
    assert first.status == "aborted" and "RequestAbort" in first.status_reason
    assert len(first.shots.t) == len(primary(documents)) == 30  # every event a journaled shot, none twice

    assert engine(plan()).exit_status == "success"
    record = same_as_alone(path)
    starts = [doc["noisebo"] for name, doc in documents if name == "start"]
    documented = {"config", "seed", "version", "file", "resumed", "points_before", "previous_runs"}  # the docs' table
    assert all(set(s) == documented for s in starts)
    assert [s["resumed"] for s in starts] == [False, True] and starts[1]["points_before"] == len(first.points)
    uids = [doc["uid"] for name, doc in documents if name == "start"]
    assert [s["previous_runs"] for s in starts] == [[], uids[:1]]  # the new run names the one it continues
    shots = primary(documents)
    assert [s[det.value.name] for s in shots] == list(record.shots.value)  # each shot once, over both runs


def test_an_ioc_that_dies_fails_the_campaign_within_its_budget_and_it_continues_once_back(tmp_path):
    config = QUICK.with_overrides(schedule={"min_failed": 3, "tolerated_rate": 0.05})
    path = tmp_path / "forrester.h5"
    with running_ioc(FORRESTER) as ioc:
        engine, x, det, documents = connected(ioc.prefix, timeout_s=1.0)
        at_event(engine, documents, 20, ioc.process.kill)
        plan = partial(campaign_plan, config, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key)
        with pytest.raises(CampaignNotCompleted, match="the campaign failed: failure budget exceeded"):
            engine(plan())
    stop = next(doc for name, doc in documents if name == "stop")
    assert stop["exit_status"] == "fail" and "failure budget exceeded" in stop["reason"]
    failed = read_record(path)
    assert failed.status == "failed" and "failure budget exceeded" in failed.status_reason
    assert len(failed.shots.t) == 20 and len(failed.failures.reason) == 3
    reasons = failed.failures.reason  # each names what failed (a ConnectionError, aioca's CANothing, ...)
    assert all(re.fullmatch(r"(?!FailedStatus)\w+: \S.*", reason) for reason in reasons), reasons

    with running_ioc(FORRESTER, prefix=ioc.prefix):
        deadline = time.monotonic() + 30
        while True:  # Channel Access finds the server again within seconds
            try:
                engine(bps.rd(det.exposure))
                break
            except Exception:
                assert time.monotonic() < deadline, "the devices did not reconnect"
        assert engine(plan()).exit_status == "success"
    record = same_as_alone(path, config)
    assert len(record.failures.reason) == 3


def test_axes_whose_limits_leave_out_part_of_x_are_refused_before_anything_moves(tmp_path):
    with running_ioc(FORRESTER, limits=(0.0, 0.5)) as ioc:
        engine, x, det, documents = connected(ioc.prefix)
        path = tmp_path / "forrester.h5"
        plan = campaign_plan(QUICK, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key)
        with pytest.raises(
            BeyondLimits, match=r"^x: its travel limits \[0, 0.5\] do not hold the config's x in \[0, 1\]"
        ):
            engine(plan)
        assert documents == [] and not path.exists()
        with pytest.raises(FailedStatus, match="stopped at 0.5, short of 0.7 \\(a travel limit\\)"):
            engine(bps.mv(x, 0.7))  # a move past a limit fails, as a shot's would


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (
            lambda x, det, path: campaign_plan(QUICK, [x, x], det, det.value, exposure=det.exposure, path=path),
            ValueError,
            "the config has 1 axes of x; 2 movables were given",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], det, det.value, path=path),
            ValueError,
            "cannot be prepared with an exposure .* give exposure=",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], det, det.value, exposure=det.exposure, path=path, seed=1),
            ValueError,
            "holds another campaign",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], det, det.acquire, exposure=det.exposure, path=path),
            DeviceMismatch,
            "^value: 'det-acquire' is not in what 'det' reads \\(det-value\\): give a signal of the detector's reading$",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], det, x.readback, exposure=det.exposure, path=path),
            DeviceMismatch,
            "^value: 'x-readback' is not in what 'det' reads \\(det-value\\)",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], x, det.value, exposure=det.exposure, path=path),
            DeviceMismatch,
            "^detector: 'x' is not triggerable and readable \\(it has no trigger\\(\\)\\)$",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [det], det, det.value, exposure=det.exposure, path=path),
            DeviceMismatch,
            "^axes\\[0\\]: 'det' is not movable \\(it has no set\\(\\)\\)$",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, x, det, det.value, exposure=det.exposure, path=path),
            DeviceMismatch,
            "^axes: give a list of movables, one per axis of x \\(got 'x'\\)$",
        ),
        (
            lambda x, det, path: campaign_plan(QUICK, [x], det, det.value, exposure=det.value, path=path),
            DeviceMismatch,
            "^exposure: 'det-value' is not movable",
        ),
    ],
    ids=[
        "axes",
        "no exposure",
        "another campaign",
        "value not read",
        "axis readback as the value",
        "axis as the detector",
        "detector as an axis",
        "an axis not in a list",
        "exposure not movable",
    ],
)
def test_a_plan_called_wrongly_says_what_is_wrong(forrester_ioc, tmp_path, call, error, message):
    engine, x, det, _ = connected(forrester_ioc.prefix)
    path = tmp_path / "forrester.h5"
    if "another" in message:  # a campaign of seed 0 is there already
        engine(
            campaign_plan(
                QUICK.with_overrides(schedule={"n_steps": 1}),
                [x],
                det,
                det.value,
                exposure=det.exposure,
                path=path,
                shot_key=det.key,
            )
        )
    documents = []
    engine.subscribe(lambda name, doc: documents.append(name))
    there = path.exists()
    with pytest.raises(error, match=message):
        engine(call(x, det, path))
    assert documents == [] and path.exists() == there  # no run opened, no file begun


def test_a_finished_campaigns_path_is_said_and_no_run_is_opened(forrester_ioc, tmp_path):
    engine, x, det, documents = connected(forrester_ioc.prefix)
    path = tmp_path / "forrester.h5"
    config = QUICK.with_overrides(schedule={"n_steps": 1})
    plan = partial(campaign_plan, config, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key)
    engine(plan())
    before, journal = len(documents), path.with_suffix(".journal").read_bytes()
    lines = []
    again = engine(plan(write=lines.append))
    assert documents[before:] == [] and path.with_suffix(".journal").read_bytes() == journal
    assert again.plan_result.status.value == "completed" and len(again.plan_result.points) == 4
    assert re.fullmatch(
        rf"{re.escape(str(path))}: the campaign completed before \(4 points, \d+ shots; final predicted optimal t "
        r"[0-9.]+ s\); nothing was run: give a new path for a new campaign",
        lines[0],
    ), lines
