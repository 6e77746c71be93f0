"""The campaign's tasks through ``.fn`` (no server) and under Prefect: one point's shots, one
decision, no retries."""

import numpy as np
import pytest
from prefect import flow

from flows.campaign import start_campaign
from instruments import build
from noisebo.campaign import driver, engine
from noisebo.events import Decided, Request, ShotError, ShotFailed
from noisebo.failures import InstrumentError
from noisebo.keys import MEASURE, numpy_rng
from noisebo.reduction import Reading
from storage import journal
from tasks import campaign as ops

REQUEST = Request(point=2, step=-1, x=(0.3,), t=2.0, wanted=5, taken=1, model_noise=None)


def started(config, seed=7):
    """A fresh campaign's engine state (its first wanted shot: seed point 0, shot 0)."""
    return engine.start(engine.new_campaign(config, seed, engine.DriverInfo("x", "1", {}), {}, "now"))


def commits():
    """An in-memory commit that also records each commit's events."""
    seen = []

    def commit(state, events):
        seen.append(list(events))
        return driver.in_memory(state, events)

    return commit, seen


class Flaky:
    """Fails the first ``failures`` calls with ``error``, then measures like Forrester."""

    name = "flaky"

    def __init__(self, config, failures, error):
        self.inner, self.failures, self.error, self.calls = build(config.instrument), failures, error, 0

    def measure(self, x, t):
        self.calls += 1
        if self.calls <= self.failures:
            raise self.error
        return self.inner.measure(x, t)


def test_measure_takes_the_next_shot_with_its_own_key(tiny_config):
    inst = build(tiny_config.instrument)
    reading = driver.take_shot(inst, 7, REQUEST)
    expected = inst.simulate(np.array([0.3]), 2.0, numpy_rng(7, MEASURE, 2, 1))
    assert reading == expected


def test_measure_point_commits_every_shot_as_it_is_taken(tiny_config):
    inst = build(tiny_config.instrument)
    commit, seen = commits()
    state = ops.measure_point.fn(inst, started(tiny_config), commit)
    wanted = tiny_config.schedule.shots_before
    assert len(seen) == wanted and len(state.points) == 1  # one commit per shot, the last reduces
    point = state.points[0].committed.point
    expected = [inst.simulate(np.array(point.x), point.t, numpy_rng(7, MEASURE, 0, k)).value for k in range(wanted)]
    np.testing.assert_allclose([s.reading.value for s in state.points[0].shots], expected)
    assert isinstance(engine.ask(state), Request) and engine.ask(state).point == 1  # stops at the next point


class Device:
    """A device: measure(x, t) only, no simulate."""

    name, version = "device", "1"

    def __init__(self):
        self.calls = []

    def measure(self, x, t):
        self.calls.append((x.tolist(), t))
        return Reading(1.0)


def test_a_device_is_asked_to_measure_at_the_coordinate_vector():
    device = Device()
    assert driver.take_shot(device, 7, REQUEST) == Reading(1.0) and device.calls == [([0.3], 2.0)]


def test_an_instrument_error_is_a_shot_error_not_an_exception(tiny_config):
    outcome = driver.take_shot(Flaky(tiny_config, 1, InstrumentError("link dropped")), 7, REQUEST)
    assert outcome == ShotError("instrument error", "link dropped")


def test_a_failed_shot_is_committed_and_taken_again_within_the_point(tiny_config):
    inst = Flaky(tiny_config, 1, InstrumentError("link dropped"))
    commit, seen = commits()
    state = ops.measure_point.fn(inst, started(tiny_config), commit)
    assert isinstance(seen[0][0], ShotFailed) and len(state.failures) == 1
    assert inst.calls == tiny_config.schedule.shots_before + 1 and len(state.points) == 1


def test_decide_is_the_engines_next_decision(tiny_config):
    seeded = driver.run_campaign(tiny_config.with_overrides(schedule={"n_steps": 0}), build(tiny_config.instrument), 3)
    state = engine.start(engine.new_campaign(tiny_config, 3, seeded.final.driver, {}, "now"))
    for entry in seeded.final.points:
        state = driver.in_memory(state, [*entry.shots, entry.committed])
    events = ops.decide.fn(state)
    assert len(events) == 1 and isinstance(events[0], Decided) and events[0].decision.step == 0
    assert events[0].decision.x == engine.advance(state)[0].decision.x


def test_under_prefect_a_failed_shot_is_not_retried_by_prefect(tiny_config, prefect_harness):
    inst = Flaky(tiny_config, 1, InstrumentError("link dropped"))
    commit, seen = commits()

    @flow
    def one_point():
        return ops.measure_point(inst, started(tiny_config), commit)

    state = one_point()
    assert len(state.failures) == 1 and inst.calls == tiny_config.schedule.shots_before + 1


def test_other_errors_fail_the_task(tiny_config, prefect_harness):
    inst = Flaky(tiny_config, 1, ValueError("bad coordinate"))

    @flow
    def one_point():
        return ops.measure_point(inst, started(tiny_config), driver.in_memory)

    with pytest.raises(ValueError, match="bad coordinate"):
        one_point()
    assert inst.calls == 1


def test_the_recorder_journals_each_event_before_applying_it(tiny_config, tmp_path):
    path = tmp_path / "c.h5"
    with start_campaign(path, tiny_config, 1) as recorder:
        request = engine.ask(recorder.state)
        reading = driver.take_shot(build(tiny_config.instrument), 1, request)
        state = recorder.commit(recorder.state, engine.tell(recorder.state, request, {0: reading}).events)
    found, _ = journal.read(path.with_suffix(".journal"))
    assert [r.type for r in found] == ["campaign", "shot"]
    assert state.n_shots == 1 and np.isclose(found[1].fields["value"], reading.value)
