"""The file of a campaign of several instruments: points in the order they were committed, each
with its index, every shot and point with the instrument that took it, spectra found by point
index; the running file, the finished one and the record of the state say the same."""

import json

import h5py
import numpy as np
import pytest

from noisebo.campaign.fleet import FleetTiming, run_fleet
from noisebo.config import load_config, parse_config
from noisebo.events import Clocked, PointCommitted
from noisebo.instruments import build
from noisebo.storage.hdf5 import read_campaign, spectra_reader
from noisebo.storage.record import from_state, read_record
from noisebo.storage.recorder import Recorder
from tests.noisebo.campaign.test_fleet import NAMES, fleet_config
from tests.noisebo.campaign.test_instrument_budget import budgeted
from tests.noisebo.storage.test_hdf5 import assert_reads_as_whole, assert_same


def recorded_fleet(config, path, seed, check=None):
    """A simulated fleet campaign committed through a recorder into ``path``; ``check(recorder)``
    after every point committed (the recorder brings the file up to date then). Returns the
    recorder's final state and the fleet run."""
    sims = {name: build(config.instruments[0].section) for name in config.instrument_names}
    recorder = None

    def on_commit(state, events):
        nonlocal recorder
        if recorder is None:
            recorder = Recorder.create(path, _started(state))
        recorder.commit(recorder.state, [e for e in events if not isinstance(e, Clocked)])  # it stamps its own
        if check is not None and any(isinstance(e, PointCommitted) for e in events):
            check(recorder)

    run = run_fleet(config, sims, seed, FleetTiming(0.05, 0.2), on_commit)
    recorder.close()
    return recorder.state, run


def _started(state):
    from noisebo.events import Started

    return Started(state.config, state.seed, state.driver, state.versions, state.created_utc)


@pytest.fixture(scope="module")
def forrester_fleet(tmp_path_factory):
    """Three instruments on a Forrester campaign of 9 points, recorded; the running file checked
    against the state at every commit. Returns the final state, the run, the file and what the
    checks saw."""
    folder = tmp_path_factory.mktemp("forrester_fleet")
    path = folder / "fleet.h5"
    seen = {"out_of_order": False, "in_flight": 0}

    def check(recorder):
        state = recorder.state
        record = read_record(path)  # the running file, appended in place
        assert record.points.index.tolist() == [e.committed.index for e in state.points]
        assert record.points.instrument == tuple(e.instrument for e in state.points)
        assert record.points.committed_after.tolist() == [e.after_decisions for e in state.points]
        assert record.steps.instrument == state.decided_for
        expected = from_state(state)
        assert record.shots.point.tolist() == expected.shots.point.tolist()
        assert record.shots.instrument == expected.shots.instrument
        seen["out_of_order"] |= record.points.index.tolist() != sorted(record.points.index.tolist())
        if len(state.flights) >= 2:
            seen["in_flight"] += 1
            assert_reads_as_whole(path, state, folder)

    config = budgeted({"b": 1e5}, n_steps=6)  # a budget of b's own, too large to end anything
    final, run = recorded_fleet(config, path, seed=3, check=check)
    return final, run, path, seen


def test_a_fleet_file_keeps_commit_order_indices_and_instruments(forrester_fleet, tmp_path):
    final, run, path, seen = forrester_fleet
    assert seen["out_of_order"] and seen["in_flight"] >= 3
    record = read_record(path)  # the finished file
    assert record.status == "completed" and len(record.points) == 9
    assert sorted(record.points.index.tolist()) == list(range(9))
    by_commit = [(c.point, c.instrument) for c in run.commits]
    assert list(zip(record.points.index.tolist(), record.points.instrument)) == by_commit
    for point, instrument in by_commit:  # every shot of a point by the instrument that finished it (no hand-over)
        mine = record.shots.point == point
        assert mine.sum() >= 1 and {record.shots.instrument[k] for k in np.flatnonzero(mine)} == {instrument}
    assert set(record.shots.instrument) == set(NAMES)
    assert record.points.committed_after.tolist() == [e.after_decisions for e in final.points]
    assert record.steps.instrument == final.decided_for and len(set(final.decided_for)) > 1
    bo = record.points.step >= 1
    assert np.all(record.points.committed_after[bo] >= record.points.step[bo])  # after the decision that made it
    assert np.any(record.points.committed_after[bo] > record.points.step[bo])  # and some while others decided
    assert_same(read_campaign(path)["points"], read_campaign(_rewritten(final, tmp_path))["points"])


def _rewritten(state, folder):
    from noisebo.storage.hdf5 import write_snapshot

    write_snapshot(folder / "again.h5", state)
    return folder / "again.h5"


def test_inspect_lists_a_fleets_points_with_their_index_and_instrument(forrester_fleet, capsys):
    from noisebo.cli.main import main

    _, run, path, _ = forrester_fleet
    assert main(["inspect", str(path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["points"]
    assert [(r["point"], r["instrument"]) for r in rows] == [(c.point, c.instrument) for c in run.commits]
    assert main(["inspect", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(k for k, line in enumerate(lines) if line.split()[:2] == ["point", "instrument"])
    table = [line.split()[:2] for line in lines[header + 1 : header + 10]]
    assert table == [[str(c.point), c.instrument] for c in run.commits]


def test_the_report_of_a_fleet_file_draws_it(forrester_fleet, tmp_path):
    from noisebo.view.report import campaign_report

    _, _, path, _ = forrester_fleet
    written = campaign_report(path, tmp_path)
    assert [p.name for p in written] == ["fleet_report.png"] and written[0].stat().st_size > 50_000


def test_the_recording_of_a_fleet_file_names_each_points_instrument(forrester_fleet, tmp_path):
    import rerun.chunk

    from noisebo.view.recording import replay
    from tests.flows.test_campaign_view import labels

    _, run, path, _ = forrester_fleet
    rrd = replay(path, tmp_path / "fleet.rrd", warn=lambda line: None)
    last = labels(rrd, "/acquisition/points")[-1]
    assert [label.rsplit(" on ", 1)[1] for label in last] == [c.instrument for c in run.commits]
    logged = [
        chunk.to_record_batch().column("instrument").to_pylist()
        for chunk in rerun.chunk.RrdReader(rrd).stream()
        if str(chunk.entity_path) == "/campaign/points"
    ]
    assert logged[-1][-1] == [c.instrument for c in run.commits]
    colours = [
        row
        for chunk in rerun.chunk.RrdReader(rrd).stream()
        if str(chunk.entity_path) == "/acquisition/points"
        for row in chunk.to_record_batch().column("Points2D:colors").to_pylist()
        if row is not None
    ][-1]
    by_instrument = {}
    for colour, commit in zip(colours, run.commits):  # one colour per instrument, a different one each
        assert by_instrument.setdefault(commit.instrument, colour) == colour
    assert len(set(by_instrument.values())) == len(by_instrument) == len({c.instrument for c in run.commits}) > 1
    logged = [
        chunk.to_record_batch()
        for chunk in rerun.chunk.RrdReader(rrd).stream()
        if str(chunk.entity_path) == "/acquisition/in_flight"
    ]
    flying = [
        row
        for batch in logged
        if "Points2D:labels" in batch.schema.names
        for row in batch.column("Points2D:labels").to_pylist()
        if row
    ]
    assert flying and all(label.startswith("in flight: point ") for row in flying for label in row)
    assert {int(label.split()[3].rstrip(",")) for row in flying for label in row} <= {c.point for c in run.commits}
    assert len(flying) < sum(batch.num_rows for batch in logged)  # and cleared where nothing was in flight


def test_the_live_recording_of_a_fleet_shows_what_its_replay_shows(tmp_path):
    import rerun.chunk

    from noisebo.view.recording import CampaignRecording, replay
    from noisebo.view.rerun_view import RerunView

    config = fleet_config(n_steps=6)
    view = RerunView(config, "live", rrd=tmp_path / "live.rrd", warn=lambda line: None, wall_clock=False)
    live = CampaignRecording(view, config)
    final, _ = recorded_fleet(config, tmp_path / "fleet.h5", seed=3, check=lambda recorder: live.update(recorder.state))
    live.update(final)
    live.close()
    replay(tmp_path / "fleet.h5", tmp_path / "replay.rrd", warn=lambda line: None)

    def shown(rrd, entity):
        rows = []
        for chunk in rerun.chunk.RrdReader(rrd).stream():
            if str(chunk.entity_path) == entity:
                batch = chunk.to_record_batch()
                steps = batch.column("step").to_pylist()
                labels = batch.column("Points2D:labels").to_pylist() if "Points2D:labels" in batch.schema.names else []
                rows += list(zip(steps, labels or [None] * len(steps)))
        return sorted(rows, key=lambda row: row[0])

    for entity in ("/acquisition/points", "/acquisition/in_flight"):
        assert shown(tmp_path / "live.rrd", entity) == shown(tmp_path / "replay.rrd", entity), entity
    assert any(labels for _, labels in shown(tmp_path / "live.rrd", "/acquisition/in_flight"))


def test_a_one_instrument_file_has_no_instrument_columns_and_rows_are_indices(tmp_path):
    from tests.noisebo.storage.test_hdf5 import SMALL, commit_points
    from benchmarks.storage import started

    path = tmp_path / "one.h5"
    with Recorder.create(path, started(SMALL)) as recorder:
        commit_points(recorder, SMALL, range(4), spectra=False)
    with h5py.File(path, "r", swmr=True) as f:
        assert "index" in f["points"] and all("instrument" not in f[t] for t in ("points", "shots", "failures"))
    record = read_record(path)
    assert record.points.index.tolist() == [0, 1, 2, 3]
    assert record.points.instrument == ("",) * 4 and set(record.shots.instrument) == {""}


@pytest.fixture(scope="module")
def pfm_fleet(tmp_path_factory):
    """A short PFM-line campaign on two instruments (sweeps as shots), recorded; the state and a
    copy of the running file at the first commit with another point's sweeps in flight, and the
    final state and file."""
    base = load_config("data/configs/pfm.yaml").with_overrides(
        space={"n_x": 60, "n_t": 40}, schedule={"n_seed": 2, "n_steps": 3}
    )
    dumped = base.model_dump(mode="json")
    one = dumped.pop("instrument")
    config = parse_config({**dumped, "instruments": [{**one, "name": n} for n in ("left", "right")]})
    folder = tmp_path_factory.mktemp("pfm_fleet")
    path = folder / "pfm.h5"
    kept = {}

    def check(recorder):
        if any(f.taken for f in recorder.state.flights) and "running" not in kept:
            kept["running"] = (recorder.state, folder / "running.h5")
            with open(path, "rb") as f, open(folder / "running.h5", "wb") as copy:
                copy.write(f.read())

    final, _ = recorded_fleet(config, path, seed=1, check=check)
    return kept["running"], (final, path), folder


def test_spectra_of_a_fleet_are_found_by_point_index(pfm_fleet):
    (running, running_path), (final, path), folder = pfm_fleet
    for state, file in ((running, running_path), (final, path)):
        with spectra_reader(file) as spectra:
            for entry in state.points:
                stacked = spectra(entry.committed.index)
                want = np.stack([s.reading.spectrum for s in entry.shots])
                np.testing.assert_array_equal(stacked, want)
    assert_reads_as_whole(running_path, running, folder)  # points in flight, their sweeps included


def test_each_instruments_time_is_its_shots_attempts_and_the_points_it_began(forrester_fleet, capsys):
    from dataclasses import replace

    from noisebo.cli.main import main

    final, run, path, _ = forrester_fleet
    record = read_record(path)
    by_instrument = record.spent_by_instrument
    assert set(by_instrument) == set(NAMES) and sum(by_instrument.values()) == pytest.approx(record.spent_s)
    assert by_instrument == pytest.approx(dict(final.spent_by))  # the file counts as the engine does
    for name in NAMES:
        assert by_instrument[name] == pytest.approx(
            sum(t for t, n in zip(record.shots.t, record.shots.instrument) if n == name)
        )
    # point 1 begun by b's failed attempt, then taken over by c; point 2 only attempted, by c
    shots = replace(record.shots, point=np.array([0, 0, 1, 1]), shot=np.array([0, 1, 0, 1]),
                    t=np.array([1.0, 1.0, 2.0, 2.0]), instrument=("a", "a", "b", "c"))  # fmt: skip
    failures = replace(record.failures, point=np.array([1, 2]), shot=np.array([0, 0]), t=np.array([2.0, 3.0]),
                       instrument=("b", "c"))  # fmt: skip
    config = {**record.config, "schedule": {**record.config["schedule"], "point_overhead_s": 0.5}}
    handmade = replace(record, shots=shots, failures=failures, config=config)
    assert handmade.spent_by_instrument == {"a": 2.5, "b": 4.5, "c": 5.5}
    unnamed = replace(
        handmade, shots=replace(shots, instrument=("",) * 4), failures=replace(failures, instrument=("", ""))
    )
    assert unnamed.spent_by_instrument == {}  # one instrument: no shares
    assert handmade.spent_s == pytest.approx(12.5)
    assert main(["inspect", str(path)]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if "instrument time:" in line)
    assert line.startswith("  instrument time: a ") and ", c " in line
    assert f", b {by_instrument['b']:.4g} s of 1e+05 s, " in line
