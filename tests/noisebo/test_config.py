from pathlib import Path

import pytest

from noisebo.config import CampaignConfig, ConfigError, load_config, parse_config

ROOT = Path(__file__).resolve().parents[2]


def test_shipped_forrester_config_has_the_papers_settings():
    cfg = load_config(ROOT / "data" / "configs" / "forrester.yaml")
    assert cfg.instrument.kind == "forrester" and cfg.instrument.settings == {"a0": 0.1, "a1": 2.0}
    assert (cfg.reward.alpha, cfg.reward.beta, cfg.reward.gamma) == (0.1, 2.0, 5.0)
    assert (cfg.space.x_min, cfg.space.x_max, cfg.space.t_min, cfg.space.t_max) == (0.0, 1.0, 0.2, 10.0)
    s = cfg.schedule
    assert (s.n_seed, s.n_steps, s.shots_before, s.shots_after, s.window, s.threshold) == (3, 15, 30, 3, 3, 5e-4)
    assert cfg.acquisition.f_acquisition == "ue"
    assert (cfg.noise_model.a0_prior.low, cfg.noise_model.a0_prior.high) == (0.0, 15.0)


def test_config_is_frozen_and_hashable():
    cfg = CampaignConfig()
    with pytest.raises(Exception):
        cfg.name = "other"
    assert hash(cfg) == hash(CampaignConfig())
    one = cfg.with_overrides(instrument={"settings": {"a0": 0.2, "a1": 1.0}})
    assert hash(one) == hash(cfg.with_overrides(instrument={"settings": {"a1": 1.0, "a0": 0.2}})) != hash(cfg)


def test_a_schema_1_config_is_migrated():
    v1 = {"schema_version": 1, "instrument": {"kind": "pfm", "q": 300.0, "q_bounds": [10, 1000], "timeout_s": 5.0}}
    cfg = parse_config(v1)
    assert cfg.schema_version == 2 and cfg.instrument.settings == {"q": 300.0} and cfg.instrument.timeout_s == 5.0
    assert cfg.reduction.sho.q_bounds == (10, 1000) and cfg.reduction.sho.nominal_q == 300.0
    assert parse_config({"schema_version": 1, "instrument": {"kind": "forrester", "a0": 0.3}}).instrument.settings == {"a0": 0.3}


def test_a_config_that_is_not_text_is_one_clear_error(tmp_path):
    path = tmp_path / "scan.yaml"
    path.write_bytes(b"\x89HDF\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(ConfigError, match="not a text .UTF-8. file: byte 0 cannot be decoded"):
        load_config(path)


def test_overrides_validate_and_leave_the_original_alone():
    cfg = CampaignConfig()
    double = cfg.with_overrides(acquisition={"policy": "double"})
    assert double.acquisition.policy == "double" and cfg.acquisition.policy == "reward"
    with pytest.raises(ConfigError, match="acquisition.policy"):
        cfg.with_overrides(acquisition={"policy": "greedy"})


BAD = [
    ({"space": {"x_min": 1.0, "x_max": 0.0}}, "space: Value error, x_min"),
    ({"space": {"t_min": 5.0, "t_max": 1.0}}, "space: Value error, t_min"),
    ({"space": {"t_min": 0.0}}, "space.t_min"),
    ({"space": {"t_min": -1.0}}, "space.t_min"),
    ({"space": {"x_max": float("nan")}}, "x_max (nan) must be a finite number"),
    ({"space": {"x_max": float("inf")}}, "x_max (inf) must be a finite number"),
    ({"space": {"x_max": 2.0, "axes": [{"name": "x", "low": 0, "high": 1}]}}, "either axes or x_min/x_max/n_x"),
    ({"space": {"axes": []}}, "1 to 4 axes, got 0"),
    ({"space": {"axes": [{"name": f"a{i}", "low": 0, "high": 1} for i in range(5)]}}, "1 to 4 axes, got 5"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1}] * 2}}, "names must differ"),
    ({"space": {"axes": [{"name": "x y", "low": 0, "high": 1}]}}, "space.axes.0.name"),
    ({"space": {"axes": [{"name": "x", "low": 1, "high": 1}]}}, "space.axes.0: Value error, low (1.0) must be below"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": float("nan")}]}}, "space.axes.0.high"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1, "n": 1}]}}, "space.axes.0.n"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1, "n": 200}, {"name": "y", "low": 0, "high": 1, "n": 200}]}},
     "more than 20000 points"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1, "colour": 1}]}}, "space.axes.0.colour"),
    ({"schedule": {"shots_before": -3}}, "schedule.shots_before"),
    ({"schedule": {"shots_after": 0}}, "schedule.shots_after"),
    ({"schedule": {"shots_before": 1}}, "schedule.shots_before"),
    ({"schedule": {"threshold": 0}}, "schedule.threshold"),
    ({"schedule": {"n_steps": "many"}}, "schedule.n_steps"),
    ({"reward": {"alpha": -0.1}}, "reward.alpha"),
    ({"colour": "blue"}, "colour: Extra inputs are not permitted"),
    ({"space": {"n_z": 3}}, "space.n_z"),
    ({"instrument": {"kind": ""}}, "instrument.kind"),
    ({"instrument": {"kind": "forrester", "a0": 0.1}}, "instrument.a0: Extra inputs are not permitted"),
    ({"instrument": {"kind": "forrester", "settings": [1]}}, "instrument.settings"),
    ({"reduction": {"sho": {"nominal_q": 3.0}}}, "give both nominal_resonance_hz and nominal_q"),
    ({"instrument": {"a0": 0.1}}, "instrument.kind: Field required"),
    ({"acquisition": {"f_acquisition": "pi"}}, "acquisition.f_acquisition"),
    ({"noise_model": {"a1_prior": {"low": 5, "high": 1}}}, "noise_model.a1_prior"),
    ({"inference": {"mode": "hmc"}}, "inference.mode"),
    ({"schema_version": 99}, "schema_version"),
]


@pytest.mark.parametrize("data, field", BAD, ids=[b[1] for b in BAD])
def test_invalid_values_name_the_field(data, field):
    with pytest.raises(ConfigError) as info:
        parse_config(data)
    assert field in str(info.value)


@pytest.mark.parametrize(
    "text, message",
    [
        ("space: [1, 2\n", "not valid YAML at line"),
        ("", "the file is empty"),
        ("- 1\n- 2\n", "expected a mapping"),
        ("schedule:\n  window: 1\n", "schedule.window"),
    ],
)
def test_bad_files_raise_config_errors(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    before = sorted(tmp_path.iterdir())
    with pytest.raises(ConfigError, match=message):
        load_config(path)
    assert sorted(tmp_path.iterdir()) == before


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(tmp_path / "absent.yaml")
