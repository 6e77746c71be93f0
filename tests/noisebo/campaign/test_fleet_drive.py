"""Several instruments on one campaign in real time: a loop per instrument on its own thread,
every commit through one writer, one decision at a time."""

import threading
import time

import pytest

from noisebo.campaign import engine
from noisebo.campaign.driver import in_memory
from noisebo.campaign.engine import EngineError
from noisebo.campaign.fleet_drive import drive_fleet
from noisebo.events import Decided, PointIssued, ShotTaken, Status
from noisebo.failures import InstrumentTimeout, MeasurementStopped
from noisebo.instruments import build
from noisebo.storage.event_codec import rebuild
from noisebo.storage.journal import read
from noisebo.storage.record import read_record
from noisebo.storage.recorder import Recorder, journal_path
from tests.noisebo.campaign.test_fleet import FLEET, NAMES, fresh


class Paced:
    """A simulator whose shot takes ``pace`` s per s of exposure, so that shots overlap in time."""

    def __init__(self, pace=0.004, fail=None, dies_after=None):
        self.inner = build(FLEET.instruments[0].section)
        self.name, self.version, self.pace, self.fail = "paced", "1", pace, fail
        self.truth, self.noise_law = self.inner.truth, self.inner.noise_law
        self.shots, self.dies_after = 0, dies_after

    def simulate(self, x, t, rng):
        self.shots += 1
        if self.fail is not None and self.shots == self.fail[0]:
            raise self.fail[1]
        if self.dies_after is not None and self.shots > self.dies_after:
            time.sleep(0.1)  # waits out its timeout, then gives up
            raise InstrumentTimeout("no reading within 0.1 s")
        time.sleep(self.pace * t)
        return self.inner.simulate(x, t, rng)


class Watched:
    """Commits in memory and keeps, for each commit, how many points were in flight after it."""

    def __init__(self):
        self.in_flight = []

    def __call__(self, state, events):
        state = in_memory(state, events)
        self.in_flight.append(len(state.flights))
        return state


def shots_by_point(state):
    return {e.committed.index: [(s.shot, s.instrument) for s in e.shots] for e in state.points}


def test_three_instruments_measure_at_once_and_finish_the_campaign():
    watched = Watched()
    instruments = {name: Paced() for name in NAMES}
    final = drive_fleet(fresh(), instruments, watched)
    assert final.status is Status.COMPLETED and final.summary is not None
    assert len(final.points) == FLEET.schedule.n_seed + FLEET.schedule.n_steps
    assert max(watched.in_flight) >= 2  # points were measured at once
    assert all(i.shots >= 2 for i in instruments.values())  # every instrument took its share
    for entry in final.points:  # each point's shots by the instrument that finished it, in order
        assert [s.shot for s in entry.shots] == list(range(len(entry.shots)))
        assert {s.instrument for s in entry.shots} == {entry.instrument}
    assert sorted(e.committed.index for e in final.points) == list(range(len(final.points)))


def test_a_fleet_journaled_through_the_recorder_replays_to_its_file(tmp_path):
    path = tmp_path / "fleet.h5"
    state = fresh()
    from tests.noisebo.storage.test_fleet_file import _started

    with Recorder.create(path, _started(state)) as recorder:
        final = drive_fleet(recorder.state, {name: Paced() for name in NAMES}, recorder.commit)
    records, _ = read(journal_path(path))
    assert rebuild(records).points == final.points
    record = read_record(path)
    assert record.status == "completed" and set(record.shots.instrument) == set(NAMES)
    assert record.points.index.tolist() == [e.committed.index for e in final.points]


def test_a_stop_aborts_and_a_resume_finishes_every_shot_once():
    commits = []

    def stop_after_six():
        return "SIGTERM received" if len(commits) >= 6 else None

    def commit(state, events):
        commits.append(events)
        return in_memory(state, events)

    stopped = drive_fleet(fresh(), {name: Paced() for name in NAMES}, commit, stop_requested=stop_after_six)
    assert stopped.status is Status.ABORTED and stopped.reason == "SIGTERM received"
    resumed = in_memory(stopped, engine.resumed(stopped))
    final = drive_fleet(resumed, {name: Paced() for name in NAMES})
    assert final.status is Status.COMPLETED
    taken = [(e.point, e.shot) for batch in commits for e in batch if isinstance(e, ShotTaken)]
    before = {(s.point, s.shot) for e in stopped.points for s in e.shots} | {(s.point, s.shot) for s in stopped.taken}
    assert set(taken) == before and len(taken) == len(before)  # nothing taken twice before the stop
    kept = shots_by_point(final)
    for point, shot in before:  # what was in before the stop is kept, not measured again
        assert shot < len(kept[point])
    assert final.n_shots == sum(len(v) for v in kept.values())


def test_an_instrument_that_stops_waiting_ends_the_campaign_as_aborted():
    instruments = {name: Paced() for name in NAMES}
    instruments["b"] = Paced(fail=(2, MeasurementStopped("SIGINT received")))
    final = drive_fleet(fresh(), instruments)
    assert final.status is Status.ABORTED and final.reason == "SIGINT received"


def test_an_unexpected_error_in_one_loop_stops_all_and_is_raised_with_the_commits_kept():
    commits = []

    def commit(state, events):
        commits.extend(events)
        return in_memory(state, events)

    instruments = {name: Paced() for name in NAMES}
    instruments["c"] = Paced(fail=(3, RuntimeError("the stage lost its home position")))
    with pytest.raises(RuntimeError, match="lost its home position"):
        drive_fleet(fresh(), instruments, commit)
    assert sum(1 for e in commits if isinstance(e, ShotTaken) and e.instrument == "c") == 2  # c's shots before it
    replayed = engine.replay([engine.new_campaign(FLEET, 4, fresh().driver, {}, "now"), *commits])
    assert replayed.status is Status.RUNNING  # resumable: nothing said it ended


def test_an_instrument_that_dies_has_its_points_taken_over_and_the_campaign_completes():
    events = []

    def commit(state, new):
        events.extend(new)
        return in_memory(state, new)

    # b dies on its first point (every point takes at least shots_before = 3 shots), so that
    # point is always taken over, however the threads are scheduled
    instruments = {"a": Paced(), "b": Paced(dies_after=2), "c": Paced()}
    final = drive_fleet(fresh(), instruments, commit)
    assert final.status is Status.COMPLETED and len(final.points) == 7
    over = [e for e in events if isinstance(e, PointIssued) and e.reason]
    assert over and all(e.reason.startswith("b timed out") and e.instrument in ("a", "c") for e in over)
    assert {e.committed.index for e in final.points} == set(range(7))
    assert sum(1 for e in final.points for s in e.shots if s.instrument == "b") == 2  # all it took, kept


def test_the_fleet_must_be_the_configs_instruments():
    with pytest.raises(EngineError, match=r"names the instruments \['a', 'b', 'c'\]; the fleet has \['a', 'b'\]"):
        drive_fleet(fresh(), {"a": Paced(), "b": Paced()})


def test_a_decision_under_way_when_the_campaign_is_stopped_is_dropped():
    # while step 1 is decided, step 0's point is measured: a stop comes in with one of its shots
    commits, deciding = [], threading.Event()

    def decide(state, name):
        if len(state.decisions) == 1:
            deciding.set()
            seen = len(commits)
            deadline = time.monotonic() + 10
            while len(commits) == seen and time.monotonic() < deadline:
                time.sleep(0.01)
        return engine.advance(state, instrument=name)

    def commit(state, events):
        commits.extend(events)
        return in_memory(state, events)

    def stop_requested():
        return "SIGTERM received" if deciding.is_set() else None

    final = drive_fleet(fresh(), {name: Paced(pace=0.02) for name in NAMES}, commit, decide, stop_requested)
    assert final.status is Status.ABORTED and final.reason == "SIGTERM received"
    assert [d.step for d in final.decisions] == [0]  # step 1's decision was dropped
    assert [e.decision.step for e in commits if isinstance(e, Decided)] == [0]


def test_decisions_made_while_every_point_is_in_flight_do_not_converge_the_noise_model():
    from tests.noisebo.campaign.test_fleet import fleet_config

    config = fleet_config(threshold=1e3, n_steps=6)
    instruments = {name: Paced() for name in NAMES}
    final = drive_fleet(fresh(config), instruments, in_memory)
    assert final.status is Status.COMPLETED
    counts = [d.n_points for d in final.decisions]
    assert counts[0] == config.schedule.n_seed and counts == sorted(counts)
    converged_at = next(k for k, d in enumerate(final.decisions) if d.converged)
    assert len(set(counts[: converged_at + 1])) == config.schedule.window  # one step per set of data
