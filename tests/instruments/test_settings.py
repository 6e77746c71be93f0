"""Every built-in driver's settings take numbers as numbers: a quoted number or a boolean where a
number belongs, and a NaN or an infinity, are refused with one line that names the setting and
says what was given; ints where floats belong and lists for pairs still work."""

import pytest

from noisebo.instruments.registry import driver_class, validated
from noisebo.config import CampaignConfig, ConfigError, lax_fields, load_config

NAN, INF = float("nan"), float("inf")


def config_of(kind, **settings):
    return CampaignConfig().with_overrides(instrument={"kind": kind, "settings": settings})


@pytest.mark.parametrize("kind", ["forrester", "branin", "pfm"])
def test_every_number_of_every_driver_is_strict(kind):
    assert lax_fields(driver_class(kind).Settings) == []


SCAN, SYNTHETIC = {"source": "scan"}, {"source": "synthetic"}
AREA = {"source": "synthetic_area"}
SCAN_AREA = {"source": "scan_area"}
BAD = [
    ("forrester", {"a0": "0.1"}, "a0: expected a number, got the string '0.1'"),
    ("forrester", {"a1": True}, "a1: expected a number, got the boolean true"),
    ("forrester", {"a1": "{a1}"}, "a1: expected a number, got the string '{a1}'"),
    ("forrester", {"patch_a0": False}, "patch_a0: expected a number, got the boolean false"),
    ("forrester", {"patch_width": NAN}, "patch_width: must be a finite number, got nan"),
    ("forrester", {"patch_x": INF}, "patch_x: must be a finite number, got inf"),
    ("forrester", {"seed": "3"}, "seed: expected a whole number, got the string '3'"),
    ("forrester", {"seed": True}, "seed: expected a whole number, got the boolean true"),
    ("branin", {"a0": "0"}, "a0: expected a number, got the string '0'"),
    ("branin", {"a1": -INF}, "a1: must be a finite number, got -inf"),
    ("branin", {"seed": False}, "seed: expected a whole number, got the boolean false"),
    ("pfm", {"q": "250"}, "q: expected a number, got the string '250'"),
    ("pfm", {"resonance_hz": NAN}, "resonance_hz: must be a finite number, got nan"),
    ("pfm", {"gain_jitter": True}, "gain_jitter: expected a number, got the boolean true"),
    ("pfm", {"sample_noise_pm": INF}, "sample_noise_pm: must be a finite number, got inf"),
    ("pfm", {"seed": "0"}, "seed: expected a whole number, got the string '0'"),
    (
        "pfm",
        {"profile": SCAN | {"start_px": [20, "120"]}},
        "profile.scan.start_px.1: expected a number, got the string '120'",
    ),
    ("pfm", {"profile": SCAN | {"smooth_px": NAN}}, "profile.scan.smooth_px: must be a finite number, got nan"),
    (
        "pfm",
        {"profile": SCAN | {"amplitude_channel": "0"}},
        "profile.scan.amplitude_channel: expected a whole number, got the string '0'",
    ),
    (
        "pfm",
        {"profile": SYNTHETIC | {"length_um": "1"}},
        "profile.synthetic.length_um: expected a number, got the string '1'",
    ),
    (
        "pfm",
        {"profile": SYNTHETIC | {"n_domains": True}},
        "profile.synthetic.n_domains: expected a whole number, got the boolean true",
    ),
    (
        "pfm",
        {"profile": SCAN_AREA | {"rows_px": ["0", 10]}},
        "profile.scan_area.rows_px.0: expected a whole number, got the string '0'",
    ),
    (
        "pfm",
        {"profile": AREA | {"size_um": [1, INF]}},
        "profile.synthetic_area.size_um.1: must be a finite number, got inf",
    ),
    (
        "pfm",
        {"profile": AREA | {"angle_deg": "30"}},
        "profile.synthetic_area.angle_deg: expected a number, got the string '30'",
    ),
    (
        "pfm",
        {"profile": AREA | {"seed": True}},
        "profile.synthetic_area.seed: expected a whole number, got the boolean true",
    ),
]


@pytest.mark.parametrize("kind, settings, message", BAD, ids=[f"{b[0]}: {b[2]}" for b in BAD])
def test_a_string_a_boolean_or_a_non_finite_number_is_refused_naming_the_setting(kind, settings, message):
    with pytest.raises(ConfigError) as info:
        validated(config_of(kind, **settings), "my.yaml")
    assert str(info.value) == f"my.yaml: instrument.settings.{message}"


YAML = [
    ('a0: "0.1"', "a0: expected a number, got the string '0.1'"),
    ("a1: '2'", "a1: expected a number, got the string '2'"),
    ("a1: true", "a1: expected a number, got the boolean true"),
    ("a1: yes", "a1: expected a number, got the boolean true"),
    ("patch_width: .nan", "patch_width: must be a finite number, got nan"),
    ("patch_width: .inf", "patch_width: must be a finite number, got inf"),
    ("seed: '7'", "seed: expected a whole number, got the string '7'"),
]


@pytest.mark.parametrize("text, message", YAML, ids=[y[0] for y in YAML])
def test_what_yaml_reads_is_refused_as_it_was_written(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(f"instrument:\n  kind: forrester\n  settings:\n    {text}\n")
    with pytest.raises(ConfigError) as info:
        validated(load_config(path), str(path))
    assert str(info.value) == f"{path}: instrument.settings.{message}"


def test_ints_for_floats_and_lists_for_pairs_are_numbers(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text("instrument:\n  kind: forrester\n  settings:\n    a0: 0\n    a1: 2\n    seed: 3.0\n")
    assert validated(load_config(path)).instrument.settings == {
        "a0": 0.0,
        "a1": 2.0,
        "law": "inv_sqrt",
        "patch_a0": 0.0,
        "patch_x": 0.5,
        "patch_width": 0.05,
        "seed": 3,
    }
    area = config_of("pfm", profile=AREA | {"size_um": [2, 1], "n_domains": 2}).with_overrides(
        space={"axes": [{"name": "x", "low": 0, "high": 2}, {"name": "y", "low": 0, "high": 1}]}
    )
    assert validated(area).instrument.settings["profile"]["size_um"] == [2.0, 1.0]
