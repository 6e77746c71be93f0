"""``noise_model.profile``: a profile file read into the config, every bad profile one line
(exit 2 on the command line, nothing created), and a profile of another instrument refused."""

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from noisebo.cli.main import main
from noisebo.instruments.registry import driver_info, validated
from noisebo.config import CampaignConfig, ConfigError, InstrumentConfig, NoiseProfile, load_config, parse_config

SETTINGS = driver_info(InstrumentConfig(kind="forrester", settings={"a0": 0.1, "a1": 2.0})).settings  # complete
PROFILE = {
    "kind": "noisebo.noise_profile",
    "schema_version": 1,
    "driver": {"name": "forrester", "version": "1", "settings": SETTINGS},
    "law": "inv_sqrt",
    "parameters": {"a0": {"mean": 0.1, "sd": 0.01}, "a1": {"mean": 2.0, "sd": 0.05}},
    "t_range_s": [0.2, 10.0],
    "noise_points": 40,
    "campaigns": [],
    "made_utc": "2026-11-25T00:00:00+00:00",
}


def write(path, data) -> str:
    path.write_text(yaml.safe_dump(data))
    return str(path)


def config_with(tmp_path, profile, name="campaign.yaml", **noise) -> str:
    data = CampaignConfig().model_dump(mode="json")
    data["noise_model"] |= {"profile": profile, **noise}
    data["schedule"] |= {"n_steps": 1}
    return write(tmp_path / name, data)


def test_a_profile_path_is_read_relative_to_the_config_and_carried_inline(tmp_path):
    (tmp_path / "profiles").mkdir()
    write(tmp_path / "profiles" / "stage.yaml", PROFILE)
    config = load_config(config_with(tmp_path, "profiles/stage.yaml"))
    profile = config.noise_model.profile
    assert profile.parameters["a1"].mean == 2.0 and profile.driver.name == "forrester"
    again = parse_config(config.model_dump(mode="json"))  # as the campaign file and the journal hold it
    assert again == config and hash(again) == hash(config)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"law": "power"}, "it describes the law 'power', the config's noise_model.mean is 'inv_sqrt'"),
        ({"parameters": {"a1": {"mean": 2.0, "sd": 0.1}}}, "needs the parameter(s) a0"),
        (
            {"parameters": {"a0": {"mean": 20.0, "sd": 0.1}, "a1": {"mean": 2.0, "sd": 0.1}}},
            "its a0 = 20 lies outside noise_model.a0_prior [0, 15]",
        ),
        (
            {"parameters": {"a0": {"mean": 0.1, "sd": -1.0}, "a1": {"mean": 2.0, "sd": 0.1}}},
            "noise_model.profile.parameters.a0.sd",
        ),
        (
            {"parameters": {"a0": {"mean": "0.1", "sd": 0.1}, "a1": {"mean": 2.0, "sd": 0.1}}},
            "expected a number, got the string '0.1'",
        ),
        ({"schema_version": 3}, "noise_model.profile.schema_version"),
        ({"correlation": {"a0,a1": -0.5}}, "correlation needs schema_version 2"),
        ({"schema_version": 2, "correlation": {"a0,p": -0.5}}, "'a0,p': a pair of two of the law's parameters a0, a1"),
        ({"schema_version": 2, "correlation": {"a1,a1": 0.5}}, "'a1,a1': a pair of two"),
        ({"schema_version": 2, "correlation": {"a0 a1": 0.5}}, "as 'a0,a1'"),
        ({"schema_version": 2, "correlation": {"a0,a1": -1.0}}, "a correlation lies strictly between -1 and 1"),
        ({"schema_version": 2, "correlation": {"a0,a1": "0.5"}}, "expected a number, got the string '0.5'"),
    ],
)
def test_a_profile_that_cannot_be_this_campaign_s_prior_is_refused(change, message):
    data = CampaignConfig().model_dump(mode="json")
    data["noise_model"]["profile"] = PROFILE | change
    with pytest.raises(ConfigError) as info:
        parse_config(data)
    assert message in str(info.value)


SPREAD = {"g0_amplitude": {"mean": 0.5, "sd": 0.1}, "g0_length": {"mean": 0.2, "sd": 0.05}}
FIELD_PROFILE = PROFILE | {"field": "a0", "parameters": PROFILE["parameters"] | SPREAD}


@pytest.mark.parametrize(
    ("profile", "field", "space", "message"),
    [
        (PROFILE, {}, None, "it holds a noise law over t, made of campaigns without noise_model.field; the config's "),
        (
            FIELD_PROFILE,
            None,
            None,
            "it was made of noise-field campaigns (noise_model.field.varies: a0); the config has no",
        ),
        (FIELD_PROFILE, {"varies": "a0_a1"}, None, "field.varies: a0); the config's noise_model.field varies a0_a1"),
        (
            FIELD_PROFILE | {"field": "a0_a1"},
            {"varies": "a0_a1"},
            None,
            "the law 'inv_sqrt' needs the parameter(s) g1_amplitude",
        ),
        (
            FIELD_PROFILE,
            {},
            {"axes": [{"name": "x", "low": 0, "high": 1}, {"name": "y", "low": 0, "high": 1}]},
            "its noise field was learned over 1 axes, the space has 2",
        ),
        (
            FIELD_PROFILE
            | {"field": "a0_a1", "parameters": FIELD_PROFILE["parameters"] | {"g1_amplitude": SPREAD["g0_amplitude"]}},
            {"varies": "a0_a1"},
            None,
            "its noise field lacks g1_length",
        ),
    ],
    ids=[
        "law profile, field config",
        "field profile, no field",
        "other field",
        "no second spread",
        "other axes",
        "no second length",
    ],
)
def test_a_profile_must_be_of_the_same_kind_of_noise(profile, field, space, message):
    data = CampaignConfig().model_dump(mode="json")
    data["noise_model"] |= {"profile": profile, "field": field}
    if space is not None:
        data["space"] = {"axes": space["axes"], "t_min": 0.2, "t_max": 10.0}
    with pytest.raises(ConfigError) as info:
        parse_config(data)
    assert message in str(info.value)


def test_a_field_profile_is_a_field_campaign_s_prior():
    data = CampaignConfig().model_dump(mode="json")
    data["noise_model"] |= {"profile": FIELD_PROFILE, "field": {}}
    config = parse_config(data)
    assert config.noise_model.profile.field == "a0"
    assert config.noise_model.profile.parameters["g0_amplitude"].mean == 0.5


@pytest.mark.parametrize(
    ("instrument", "check", "message"),
    [
        (
            {"kind": "branin", "settings": {}},
            True,
            "it was made with the driver 'forrester', the campaign uses 'branin'",
        ),
        (
            {"kind": "forrester", "settings": {"a0": 0.5, "a1": 1.0}},
            True,
            "it was made with other instrument settings (a0: 0.1 in the profile, 0.5 here; a1: 2.0 in the profile, 1.0 here",
        ),
        ({"kind": "forrester", "settings": {"a0": 0.5, "a1": 1.0}}, False, None),
        ({"kind": "forrester", "settings": {"a0": 0.1, "a1": 2.0}}, True, None),
    ],
)
def test_a_profile_of_another_driver_or_settings_is_refused_unless_the_check_is_off(instrument, check, message):
    data = CampaignConfig().model_dump(mode="json")
    data["noise_model"] |= {"profile": PROFILE, "profile_check": check}
    data["instrument"] = instrument
    if instrument["kind"] == "branin":
        data["space"] = {
            "axes": [{"name": "x1", "low": -5, "high": 10, "n": 10}, {"name": "x2", "low": 0, "high": 15, "n": 10}],
            "t_min": 0.2,
            "t_max": 10,
            "n_t": 20,
        }
    config = parse_config(data)
    if message is None:
        assert validated(config).noise_model.profile.law == "inv_sqrt"
        return
    with pytest.raises(ConfigError) as info:
        validated(config)
    assert message in str(info.value) and "profile_check: false" in str(info.value)


WRITTEN = yaml.safe_dump(  # what `noisebo noise-profile` writes now: schema 2, with its correlation
    NoiseProfile.model_validate(PROFILE | {"schema_version": 2, "correlation": {"a0,a1": -0.8}}).model_dump(
        mode="json"
    ),
    sort_keys=False,
)

BAD_PROFILES = [  # file name, its content (None: no file), what the one line says
    (
        "absent.yaml",
        None,
        "noise_model.profile: {dir}/absent.yaml: cannot read noise profile (No such file or directory)",
    ),
    ("empty.yaml", "", "noise_model.profile: {dir}/empty.yaml: the file is empty"),
    (
        "corrupt.yaml",
        "kind: noisebo.noise_profile\nparameters: [1, 2\n",
        "noise_model.profile: {dir}/corrupt.yaml: not valid YAML at line",
    ),
    ("binary.yaml", b"\x89HDF\r\n\x1a\n\x00\xff", "not a text (UTF-8) file"),
    (
        "campaign.yaml",
        "name: another\nschedule: {n_steps: 2}\n",
        "is not a noise profile (no kind 'noisebo.noise_profile'; `noisebo noise-profile` writes one)",
    ),
    ("foreign.yaml", "kind: bluesky.plan\n", "is not a noise profile (kind 'bluesky.plan'"),
    ("list.yaml", "- 1\n- 2\n", "is not a noise profile"),
    (
        "cut_short.yaml",  # a written profile cut off after its correlation's key
        WRITTEN[: WRITTEN.index("correlation:") + len("correlation:\n")],
        "noise_model.profile.correlation: Input should be a valid dictionary",
    ),
    (
        "bad_correlation.yaml",
        WRITTEN.replace("a0,a1: -0.8", "a0,a1: 1.5"),
        "correlation 'a0,a1' = 1.5: a correlation lies strictly between -1 and 1",
    ),
    (
        "missing_law.yaml",
        yaml.safe_dump({k: v for k, v in PROFILE.items() if k != "law"}),
        "noise_model.profile.law: Field required",
    ),
]


@pytest.mark.parametrize(("name", "content", "message"), BAD_PROFILES, ids=[b[0] for b in BAD_PROFILES])
def test_a_bad_profile_file_is_one_line_exit_2_and_creates_nothing(
    name, content, message, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    if isinstance(content, bytes):
        (tmp_path / name).write_bytes(content)
    elif content is not None:
        (tmp_path / name).write_text(content)
    config = config_with(tmp_path, name, name="run.yaml")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert main(["run", config, "--out", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("noisebo: error: ")
    assert message.format(dir=tmp_path) in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


POWER = PROFILE | {
    "law": "power",
    "schema_version": 2,
    "parameters": PROFILE["parameters"] | {"p": {"mean": 0.5, "sd": 0.05}},
}


def test_a_profile_s_correlation_is_its_law_s_matrix():
    profile = NoiseProfile.model_validate(POWER | {"correlation": {"a1,p": 0.3, "a0,a1": -0.8}})
    assert profile.law_parameters() == ("a0", "a1", "p")
    expected = [[1.0, -0.8, 0.0], [-0.8, 1.0, 0.3], [0.0, 0.3, 1.0]]
    np.testing.assert_array_equal(profile.law_correlation(("a0", "a1", "p")), expected)
    np.testing.assert_array_equal(profile.law_correlation(("a1", "p")), [[1.0, 0.3], [0.3, 1.0]])
    assert NoiseProfile.model_validate(PROFILE).law_correlation(("a0", "a1")).tolist() == [[1, 0], [0, 1]]


def test_pairs_that_make_no_correlation_matrix_are_refused():
    # each pair alone is a correlation, the three together are not: a0 and p both go with a1
    # (0.9) but against each other (-0.9), det = 1 - 3 * 0.81 - 2 * 0.729 < 0
    with pytest.raises(ValidationError, match="do not make a positive definite correlation matrix"):
        NoiseProfile.model_validate(POWER | {"correlation": {"a0,a1": 0.9, "a1,p": 0.9, "a0,p": -0.9}})
