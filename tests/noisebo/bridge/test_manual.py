"""A campaign measured by hand with `noisebo ask` / `noisebo tell` is the in-process campaign."""

import json

import numpy as np
import pytest
import yaml

from noisebo.cli.main import main
from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.campaign.driver import run_campaign
from noisebo.config import load_config
from noisebo.keys import MEASURE, numpy_rng
from noisebo.storage.recorder import Recorder

SMALL = {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_steps": 2, "shots_before": 4, "shots_after": 2}}


def config_file(tmp_path, base="data/configs/forrester.yaml", **overrides):
    config = validated(load_config(base)).with_overrides(**{**SMALL, **overrides})
    path = tmp_path / "campaign.yaml"
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return config, path


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_a_campaign_told_by_hand_equals_the_in_process_one(tmp_path, capsys):
    config, path = config_file(tmp_path)
    code, out, _ = cli(capsys, "start", path, "--seed", 7, "--out", tmp_path)
    assert code == 0
    campaign = tmp_path / "forrester_reward_s0007.h5"
    assert out.splitlines()[0] == f"created {campaign}"
    simulator = build(config.instrument)
    steps = {}  # point: its step, as ask --json and ask's text give it
    while True:
        _, out, _ = cli(capsys, "ask", campaign, "--json")
        request = json.loads(out)
        if request["kind"] == "done":
            break
        text = cli(capsys, "ask", campaign)[1]
        steps[request["point"]] = (request["step"], text.split("(")[1].split(")")[0])
        values = [
            repr(
                simulator.simulate(
                    np.asarray(request["x"]), request["t"], numpy_rng(request["seed"], MEASURE, request["point"], shot)
                ).value
            )
            for shot in range(request["shot"], request["wanted"])
        ]
        assert cli(capsys, "tell", campaign, "--point", request["point"], *values)[0] == 0
    assert request["status"] == "completed"
    # 3 seed points (step 0), then BO steps 1 and 2 of 2
    assert steps == {
        0: (0, "seed point"),
        1: (0, "seed point"),
        2: (0, "seed point"),
        3: (1, "BO step 1/2"),
        4: (2, "BO step 2/2"),
    }
    local = run_campaign(config, simulator, 7).final
    with Recorder.attach(campaign) as recorder:
        told = recorder.state
    assert [[s.reading for s in p.shots] for p in told.points] == [[s.reading for s in p.shots] for p in local.points]
    assert [p.committed for p in told.points] == [p.committed for p in local.points]
    assert [(d.x, d.t) for d in told.decisions] == [(d.x, d.t) for d in local.decisions]


@pytest.fixture
def started(tmp_path, capsys):
    _, path = config_file(tmp_path)
    cli(capsys, "start", path, "--out", tmp_path)
    return tmp_path / "forrester_reward_s0000.h5"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--point", "3", "1.0"], "--point 3: point 3 has not been asked for yet; the point being measured is 0"),
        (["--point", "0", "--", "--", "-1.0"], "'--' is not a number"),  # only the first ends the options
        (["1", "2", "3", "4", "5"], "point 0 wants 4 more shots (shots 0-3); got 5"),
        (["1.0", "nan"], "'nan' is not a finite number"),
        (["1.0", "high"], "'high' is not a number"),
        ([], "give the shots' readings as VALUE..., or --spectrum FILE..., or one --error REASON"),
        (["1.0", "--error", "x"], "give the shots' readings"),
        (["--spectrum", "s.npy"], "this campaign's readings are numbers"),
    ],
)
def test_a_tell_that_does_not_fit_is_refused_and_records_nothing(started, capsys, argv, message):
    before = started.with_suffix(".journal").read_bytes()
    code, _, err = cli(capsys, "tell", started, *argv)
    assert code == 2 and message in err
    assert started.with_suffix(".journal").read_bytes() == before


def test_a_negative_value_after_the_end_of_the_options_is_recorded(started, capsys):
    code, _, err = cli(capsys, "tell", started, "--point", "0", "--", "-0.5", "-1e-3")
    assert code == 0 and "recorded 2 shots" in err
    with Recorder.attach(started) as recorder:
        assert [s.reading.value for s in recorder.state.taken] == [-0.5, -1e-3]


def test_a_finished_point_is_named_as_finished(started, capsys):
    cli(capsys, "tell", started, "1", "2", "3", "4")  # point 0's four shots
    code, _, err = cli(capsys, "tell", started, "--point", "0", "1.0")
    assert code == 2
    assert "--point 0: point 0 is finished (its shots are all recorded); the point being measured is 1" in err


def test_a_campaign_held_by_another_process_is_refused(started, capsys):
    with Recorder.attach(started):
        code, _, err = cli(capsys, "tell", started, "1.0")
    assert code == 2 and "journal" in err


def test_an_error_is_a_failed_attempt_and_the_same_shot_is_asked_again(started, capsys):
    cli(capsys, "tell", started, "1.5")
    code, out, _ = cli(capsys, "tell", started, "--error", "beam dumped", "--json")
    assert code == 0 and json.loads(out)["shot"] == 1 and json.loads(out)["attempt"] == 1
    with Recorder.attach(started) as recorder:
        assert [f.reason for f in recorder.state.failures] == ["operator: beam dumped"]


def test_spectra_are_told_from_npy_and_csv_files(tmp_path, capsys):
    _, path = config_file(tmp_path, base="data/configs/pfm.yaml")
    cli(capsys, "start", path, "--out", tmp_path)
    campaign = tmp_path / "pfm_double_s0000.h5"
    freq = np.linspace(367e3, 377e3, 200)
    amp = 50.0 / np.sqrt((1 - (freq / 372e3) ** 2) ** 2 + (freq / 372e3 / 250) ** 2)
    rows = np.stack([freq, amp, np.zeros_like(freq)])
    np.save(tmp_path / "a.npy", rows)
    np.savetxt(tmp_path / "b.csv", rows.T, delimiter=",", header="frequency,amplitude,phase")
    np.save(tmp_path / "bad.npy", rows[:, :3])
    code, _, err = cli(capsys, "tell", campaign, "--spectrum", tmp_path / "bad.npy")
    assert code == 2 and "3 samples per row" in err
    assert cli(capsys, "tell", campaign, "--spectrum", tmp_path / "a.npy", "--spectrum", tmp_path / "b.csv")[0] == 0
    with Recorder.attach(campaign) as recorder:
        shots = [s.reading for s in recorder.state.taken]
    assert [s.reduction for s in shots] == ["sho", "sho"]
    np.testing.assert_allclose(shots[0].spectrum, rows)
    np.testing.assert_allclose(shots[1].spectrum, rows, rtol=1e-15)
