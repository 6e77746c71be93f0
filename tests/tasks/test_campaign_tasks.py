"""Every task through ``.fn`` (no server), and the measure task's retry policy under Prefect."""

import numpy as np
import pytest
from prefect import flow

from instruments import build
from instruments.guard import InstrumentError
from noisebo import campaign as core
from noisebo.decision import decide
from noisebo.reduction import Reading
from noisebo.state import CampaignState
from noisebo.storage import journal, records
from noisebo.storage.recorder import Recorder
from tasks import campaign as ops


def seeded_state(config, seed=3):
    inst = build(config.instrument)
    state = CampaignState()
    for i, (x, t) in enumerate(core.seed_points(config, seed)):
        readings = core.shot_readings(inst, x, t, config.schedule.shots_before, seed, i)
        state = state.with_point(core.make_point(x, t, readings, None, config.instrument)[0])
    return state


def test_seed_points_task_is_the_core_function(tiny_config):
    np.testing.assert_array_equal(ops.seed_points.fn(tiny_config, 4), core.seed_points(tiny_config, 4))


class ListLog:
    def __init__(self, done=()):
        self.rows = [(0, k, v) for k, v in enumerate(done)]
        self.failures = []

    def taken(self, point):
        return [v for p, _, v in self.rows if p == point]

    def add(self, point, shot, x, t, value):
        assert shot == len(self.taken(point)), "a shot recorded twice or out of order"
        self.rows.append((point, shot, value))

    def failed(self, point, shot, x, t, error):
        self.failures.append((point, shot, type(error).__name__))

    def failure_counts(self):
        return len(self.failures), len(self.failures) + len(self.rows)


def test_measure_continues_after_the_shots_already_taken(tiny_config):
    inst = build(tiny_config.instrument)
    full = ops.measure.fn(inst, 0.3, 2.0, 6, 1, 0, ListLog())
    log = ListLog(full[:4])
    assert ops.measure.fn(inst, 0.3, 2.0, 6, 1, 0, log) == full
    assert [(k, v) for _, k, v in log.rows[4:]] == [(4, full[4]), (5, full[5])]


def test_reduce_task(tiny_config):
    point, shots = ops.reduce.fn(0.5, 1.0, [Reading(1.0), Reading(3.0)], None, tiny_config.instrument)
    assert [s.value for s in shots] == [1.0, 3.0]
    assert point.value == 2.0 and point.shot_std == pytest.approx(np.sqrt(2.0)) and point.noise_measured


def test_update_models_and_acquire_equal_the_core_decision(tiny_config):
    state = seeded_state(tiny_config)
    fitted, fit_s = ops.update_models.fn(tiny_config, state, 3, 0)
    decision, acq_s = ops.acquire.fn(tiny_config, fitted, state, 0)
    expected, _ = decide(tiny_config, state, 3, 0)
    assert (decision.x, decision.t, decision.t_opt, decision.shots) == (expected.x, expected.t, expected.t_opt, expected.shots)
    assert fit_s > 0 and acq_s > 0


def test_record_task_journals_then_snapshots(tiny_config, tmp_path):
    path = tmp_path / "c.h5"
    with Recorder.create(path, tiny_config, 1) as recorder:
        ops.record.fn(recorder, records.shot_record(0, 0, 0.1, 1.0, Reading(2.0)))
    found, _ = journal.read(path.with_suffix(".journal"))
    assert [r.type for r in found] == ["campaign", "shot"]
    import h5py

    with h5py.File(path, "r") as f:
        assert f["shots/value"][()].tolist() == [2.0]


def test_summarize_task(tiny_config):
    state = seeded_state(tiny_config)
    summary = ops.summarize.fn(tiny_config, state, 3)
    assert summary.f_mean.shape == (tiny_config.space.n_x,) and tiny_config.space.t_min <= summary.t_opt


class Flaky:
    """Fails the first ``failures`` calls with ``error``, then measures like Forrester."""

    name = "flaky"

    def __init__(self, config, failures, error):
        self.inner, self.failures, self.error, self.calls = build(config.instrument), failures, error, 0

    def measure(self, x, t, rng):
        self.calls += 1
        if self.calls <= self.failures:
            raise self.error
        return self.inner.measure(x, t, rng)


class FailsMidway(Flaky):
    """Measures ``after`` shots, then fails ``failures`` times, then measures again."""

    def __init__(self, config, after, failures):
        super().__init__(config, 0, None)
        self.after, self.failures_left = after, failures

    def measure(self, x, t, rng):
        self.calls += 1
        if self.calls > self.after and self.failures_left:
            self.failures_left -= 1
            raise InstrumentError("link dropped")
        return self.inner.measure(x, t, rng)


def test_measure_retries_instrument_errors_and_keeps_the_shots_it_took(tiny_config, prefect_harness):
    inst = FailsMidway(tiny_config, after=2, failures=2)
    log = ListLog()

    @flow
    def one_point():
        return ops.measure(inst, 0.3, 2.0, 5, 1, 0, log)

    values = one_point()
    reference = core.shot_readings(build(tiny_config.instrument), 0.3, 2.0, 5, 1, 0)
    assert values == reference
    assert [k for _, k, _ in log.rows] == [0, 1, 2, 3, 4]
    assert inst.calls == 7
    assert log.failures == [(0, 2, "InstrumentError"), (0, 2, "InstrumentError")]  # both logged, then retried


def test_measure_stops_past_the_failure_budget(tiny_config):
    from noisebo.failures import FailureBudgetExceeded

    inst = FailsMidway(tiny_config, after=1, failures=100)
    log = ListLog()
    with pytest.raises(FailureBudgetExceeded, match="3 of 4 shot attempts failed"):
        ops.measure.fn(inst, 0.3, 2.0, 5, 1, 0, log, (3, 0.5))
    assert len(log.rows) == 1 and len(log.failures) == 3


def test_measure_does_not_retry_other_errors(tiny_config, prefect_harness):
    inst = Flaky(tiny_config, 1, ValueError("bad coordinate"))

    @flow
    def one_point():
        return ops.measure(inst, 0.3, 2.0, 4, 1, 0, ListLog())

    with pytest.raises(ValueError, match="bad coordinate"):
        one_point()
    assert inst.calls == 1
