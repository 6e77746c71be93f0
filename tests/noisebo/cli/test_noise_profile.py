"""`noisebo noise-profile`: an instrument's noise law from finished campaigns, and every bad
input one line, exit 2, nothing written."""

import h5py
import numpy as np
import pytest
import yaml

from noisebo.cli.main import main
from noisebo.instruments import build
from noisebo.instruments.registry import driver_info, validated
from noisebo.campaign import driver, engine
from noisebo.models.profile import NoiseProfile
from noisebo.storage.recorder import Recorder


def finished(path, config, seed):
    """A finished campaign file (and journal) run in this process, without Prefect."""
    started = engine.new_campaign(config, seed, driver_info(config.instrument), {}, "2026-11-25T00:00:00+00:00")
    with Recorder.create(path, started) as recorder:
        driver.drive(recorder.state, build(config.instrument), recorder.commit)
    return path


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory, tiny_config):
    folder = tmp_path_factory.mktemp("profiles")
    config = tiny_config.with_overrides(schedule={"n_steps": 2})
    other = config.with_overrides(instrument={"kind": "forrester", "settings": {"a0": 0.5, "a1": 1.0}})
    field = config.with_overrides(noise_model={"field": {}}, schedule={"n_seed": 4, "n_steps": 1})
    return {
        "a": finished(folder / "a.h5", config, 1),
        "b": finished(folder / "b.h5", config, 2),
        "other": finished(folder / "other.h5", other, 3),
        "field": finished(folder / "field.h5", field, 4),
    }


def test_a_profile_pools_the_campaigns_noise_measurements(campaigns, tmp_path, capsys):
    out = tmp_path / "forrester.yaml"
    assert main(["noise-profile", str(campaigns["a"]), str(campaigns["b"]), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "law inv_sqrt: a0 = " in said
    profile = NoiseProfile.model_validate(yaml.safe_load(out.read_text()))
    assert profile.driver.name == "forrester" and profile.driver.settings["a1"] == 2.0 and profile.law == "inv_sqrt"
    # the noise measured at a few t pins a0 + a1 / sqrt(t) there: a0 and a1 trade off
    assert profile.schema_version == 2 and set(profile.correlation) == {"a0,a1"} and profile.correlation["a0,a1"] < 0
    assert f"correlation a0,a1 {profile.correlation['a0,a1']:.2f}" in said
    measured = []
    for path in (campaigns["a"], campaigns["b"]):
        with h5py.File(path, "r") as f:
            measured.append(int(np.sum(f["points/noise_measured"][()])))
    assert [c.noise_points for c in profile.campaigns] == measured and profile.noise_points == sum(measured)
    assert [c.seed for c in profile.campaigns] == [1, 2]
    a1 = profile.parameters["a1"]
    assert abs(a1.mean - 2.0) < 3 * a1.sd + 0.3  # the simulator's A1 = 2


def test_a_field_campaign_gives_a_field_profile_a_field_campaign_takes(campaigns, tmp_path, capsys, tiny_config):
    out = tmp_path / "field.yaml"
    assert main(["noise-profile", str(campaigns["field"]), "--out", str(out)]) == 0
    assert "g0_amplitude = " in capsys.readouterr().out
    profile = NoiseProfile.model_validate(yaml.safe_load(out.read_text()))
    assert profile.field == "a0" and {"a0", "a1", "g0_amplitude", "g0_length"} == set(profile.parameters)
    assert all(p.sd == 0 for n, p in profile.parameters.items() if n.startswith("g0"))  # one campaign
    with h5py.File(campaigns["field"], "r") as f:
        assert profile.noise_points == int(np.sum(f["points/noise_measured"][()]))
    taken = validated(tiny_config.with_overrides(noise_model={"field": {}, "profile": profile.model_dump(mode="json")}))
    assert taken.noise_model.profile == profile


def table():
    return [
        ("missing", lambda c, tmp: [str(tmp / "nowhere.h5")], "nowhere.h5"),
        ("empty", lambda c, tmp: [str(_write(tmp / "empty.h5", b""))], "empty"),
        ("not HDF5", lambda c, tmp: [str(_write(tmp / "text.h5", b"not a campaign\n" * 100))], "not an HDF5 file"),
        ("two instruments", lambda c, tmp: [str(c["a"]), str(c["other"])], "one instrument with one setting"),
        (
            "a field and a law",
            lambda c, tmp: [str(c["a"]), str(c["field"])],
            "was made with the noise a field varying a0 over 1 axes",
        ),
    ]


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


@pytest.mark.parametrize(("case", "files", "message"), table(), ids=[row[0] for row in table()])
def test_bad_input_is_one_line_exit_2_and_nothing_written(campaigns, tmp_path, capsys, case, files, message):
    out = tmp_path / "profile.yaml"
    assert main(["noise-profile", *files(campaigns, tmp_path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("noisebo: error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists() and not out.with_name(out.name + ".partial").exists()


def test_an_existing_profile_is_not_overwritten(campaigns, tmp_path, capsys):
    out = _write(tmp_path / "profile.yaml", b"kept\n")
    assert main(["noise-profile", str(campaigns["a"]), "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err and out.read_bytes() == b"kept\n"
