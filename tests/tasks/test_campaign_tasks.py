"""The campaign's stages as tasks, each called through ``.fn`` on a hand-made state (no server)
and under Prefect: seed design, measure, fit SHO, fit noise model, fit GP, acquire, summarise."""

import numpy as np
import pytest
from prefect import flow

from noisebo.flows.campaign import start_campaign
from noisebo.instruments import build
from noisebo import sho
from noisebo.campaign import driver, engine, steps
from noisebo.events import Decided, DecisionDue, Request, ShotError, ShotFailed
from noisebo.failures import InstrumentError
from noisebo.keys import MEASURE, numpy_rng
from noisebo.models.fitting import NoiseFit, PrimaryFit
from noisebo.reduction import Reading
from noisebo.storage import journal
from noisebo.tasks import campaign as ops

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


def test_measure_commits_every_shot_as_it_is_taken(tiny_config):
    inst = build(tiny_config.instrument)
    commit, seen = commits()
    state = ops.measure.fn(inst, started(tiny_config), commit)
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
    state = ops.measure.fn(inst, started(tiny_config), commit)
    assert isinstance(seen[0][0], ShotFailed) and len(state.failures) == 1
    assert inst.calls == tiny_config.schedule.shots_before + 1 and len(state.points) == 1


def test_under_prefect_a_failed_shot_is_not_retried_by_prefect(tiny_config, prefect_harness):
    inst = Flaky(tiny_config, 1, InstrumentError("link dropped"))
    commit, seen = commits()

    @flow
    def one_point():
        return ops.measure(inst, started(tiny_config), commit)

    state = one_point()
    assert len(state.failures) == 1 and inst.calls == tiny_config.schedule.shots_before + 1


def test_other_errors_fail_the_task(tiny_config, prefect_harness):
    inst = Flaky(tiny_config, 1, ValueError("bad coordinate"))

    @flow
    def one_point():
        return ops.measure(inst, started(tiny_config), driver.in_memory)

    with pytest.raises(ValueError, match="bad coordinate"):
        one_point()
    assert inst.calls == 1


def test_the_recorder_journals_each_commit_with_its_clock_and_a_bad_event_writes_nothing(tiny_config, tmp_path):
    path = tmp_path / "c.h5"
    with start_campaign(path, tiny_config, 1) as recorder:
        request = engine.ask(recorder.state)
        reading = driver.take_shot(build(tiny_config.instrument), 1, request)
        events = engine.tell(recorder.state, request, {0: reading}).events
        state = recorder.commit(recorder.state, events)
        with pytest.raises(engine.EngineError, match="shot 0 of point 0 out of order"):
            recorder.commit(state, [events[0]])  # shot 0 again
        assert recorder.state is state
    found, _ = journal.read(path.with_suffix(".journal"))
    assert [r.type for r in found] == ["campaign", "shot", "clock"]
    assert state.n_shots == 1 and np.isclose(found[1].fields["value"], reading.value)
    assert state.wall_s == found[2].fields["wall_s"] > 0


def seeded(config, seed=3):
    """The engine state of a campaign whose seed points are measured, its first BO step due."""
    run = driver.run_campaign(config.with_overrides(schedule={"n_steps": 0}), build(config.instrument), seed)
    state = engine.start(engine.new_campaign(config, seed, run.final.driver, {}, "now"))
    for entry in run.final.points:
        state = driver.in_memory(state, [*entry.shots, entry.committed])
    return state


def test_seed_design_is_the_engines_seed_points(tiny_config):
    design = ops.seed_design.fn(tiny_config, 5)
    s = tiny_config.space
    assert design.shape == (tiny_config.schedule.n_seed, 2)
    assert np.all((design[:, 1] >= s.t_min) & (design[:, 1] <= s.t_max))
    assert np.array_equal(design, steps.seed_points(tiny_config, 5))
    first = engine.ask(started(tiny_config, 5))
    assert (first.x[0], first.t) == (design[0, 0], design[0, 1])


def test_measure_without_reduction_leaves_the_point_to_the_reduce_stage(tiny_config):
    inst = build(tiny_config.instrument)
    commit, seen = commits()
    state = ops.measure.fn(inst, started(tiny_config), commit, reduce=False)
    assert len(seen) == tiny_config.schedule.shots_before and not state.points
    due = engine.ask(state)
    assert isinstance(due, DecisionDue) and due.reduce
    reduced = driver.in_memory(state, engine.advance(state))
    at_once = ops.measure.fn(inst, started(tiny_config), driver.in_memory)
    assert reduced.points[0].committed == at_once.points[0].committed


@pytest.mark.parametrize(
    ("step", "model_noise", "taken", "expected"),
    [
        (-1, None, 0, "measure x=0.3 t=2 s 5 shots (seed point 3/3)"),
        (4, None, 0, "measure x=0.3 t=2 s 5 shots (noise model not converged: noise measured)"),
        (4, 0.2, 2, "measure x=0.3 t=2 s 5 shots (noise model converged, from shot 3)"),
    ],
)
def test_a_measure_task_is_named_by_where_how_long_and_why(
    tiny_config, monkeypatch, step, model_noise, taken, expected
):
    request = Request(point=2, step=step, x=(0.3,), t=2.0, wanted=5, taken=taken, model_noise=model_noise)
    monkeypatch.setattr(engine, "ask", lambda state: request)
    assert ops.measure_name(started(tiny_config)) == expected


def sweep(amplitude: float, resonance: float = 300e3, q: float = 100.0, n: int = 64, noise: float = 0.0, seed=0):
    freq = np.linspace(resonance * 0.97, resonance * 1.03, n)
    amp = sho.sho_amplitude(freq, amplitude, resonance, q) + np.random.default_rng(seed).normal(0, noise, n)
    return np.vstack([freq, amp, sho.sho_phase(freq, resonance, q)])


def test_fit_sho_turns_sweeps_into_a_point_with_their_spread(tiny_config):
    amplitudes = [10.0, 12.0, 14.0]
    readings = [Reading(None, sweep(a)) for a in amplitudes]
    point, values = ops.fit_sho.fn((0.4,), 1.5, readings, None, tiny_config.reduction, None)
    assert [v.ok for v in values] == [True] * 3
    np.testing.assert_allclose([abs(v.value) for v in values], amplitudes, rtol=1e-6)
    assert abs(point.value) == pytest.approx(12.0, rel=1e-6)
    assert point.shot_std == pytest.approx(2.0, rel=1e-5) and point.noise == point.shot_std  # sd of 10, 12, 14
    assert point.n_shots == 3 and point.t == 1.5 and point.x == (0.4,)


def test_fit_sho_keeps_a_failed_sweep_as_rejected_with_its_reason(tiny_config):
    readings = [Reading(None, sweep(10.0)), Reading(None, sweep(12.0)), Reading(None, np.zeros((3, 2)))]
    point, values = ops.fit_sho.fn((0.4,), 1.5, readings, None, tiny_config.reduction, None)
    assert [v.ok for v in values] == [True, True, False] and values[2].reason
    assert abs(point.value) == pytest.approx(11.0, rel=1e-6) and point.n_shots == 2


def test_scalar_readings_are_reduced_without_a_task(tiny_config):
    point, values = ops.reduce_point((0.4,), 1.5, [Reading(1.0), Reading(3.0)], None, tiny_config.reduction, None)
    assert point.value == 2.0 and point.shot_std == pytest.approx(np.sqrt(2.0)) and len(values) == 2


def test_the_fit_stages_give_the_engines_decision(tiny_config):
    state = seeded(tiny_config)
    step = engine.step_inputs(state)
    assert (step.step, step.previous, step.budget_left) == (0, None, None)
    noise = ops.fit_noise_model.fn(step)
    n_seed = tiny_config.schedule.n_seed
    assert isinstance(noise, NoiseFit) and not noise.warm and noise.inputs == n_seed  # three distinct t
    gp = ops.fit_gp.fn(step, noise)
    assert isinstance(gp, PrimaryFit) and gp.inputs == n_seed
    made = ops.acquire.fn(step, gp, noise)
    expected = engine.advance(state)[0].decision
    assert made.step == 0 and (made.x, made.t, made.shots) == (expected.x, expected.t, expected.shots)
    assert made.acq_value == expected.acq_value and made.t_opt == expected.t_opt


def test_summarise_is_the_engines_summary(tiny_config):
    state = seeded(tiny_config)
    summary = ops.summarise.fn(tiny_config, state.data, state.seed)
    assert summary.t_opt == steps.summarize(tiny_config, state.data, state.seed).t_opt
    assert tiny_config.space.t_min <= summary.t_opt <= tiny_config.space.t_max


def test_under_prefect_the_staged_decision_equals_the_plain_one(tiny_config, prefect_harness):
    state = seeded(tiny_config)

    @flow
    def one_step():
        return engine.advance(state, ops.TASKS)

    (decided,) = one_step()
    plain = engine.advance(state)[0].decision
    assert isinstance(decided, Decided)
    assert (decided.decision.x, decided.decision.t, decided.decision.acq_value) == (plain.x, plain.t, plain.acq_value)
