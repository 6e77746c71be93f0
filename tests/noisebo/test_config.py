import json
from pathlib import Path
from typing import Literal

import h5py
import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from noisebo.config import CampaignConfig, ConfigError, Count, Flag, Number, lax_fields, load_config, parse_config

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
    with pytest.raises(ValidationError, match="frozen"):
        cfg.name = "other"
    assert hash(cfg) == hash(CampaignConfig())
    one = cfg.with_overrides(instrument={"settings": {"a0": 0.2, "a1": 1.0}})
    assert hash(one) == hash(cfg.with_overrides(instrument={"settings": {"a1": 1.0, "a0": 0.2}})) != hash(cfg)


def test_a_schema_1_config_is_migrated():
    v1 = {"schema_version": 1, "instrument": {"kind": "pfm", "q": 300.0, "q_bounds": [10, 1000], "timeout_s": 5.0}}
    cfg = parse_config(v1)
    assert cfg.schema_version == 2 and cfg.instrument.settings == {"q": 300.0} and cfg.instrument.timeout_s == 5.0
    assert cfg.reduction.sho.q_bounds == (10, 1000) and cfg.reduction.sho.nominal_q == 300.0
    assert parse_config({"schema_version": 1, "instrument": {"kind": "forrester", "a0": 0.3}}).instrument.settings == {
        "a0": 0.3
    }


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
    ({"space": {"x_max": float("nan")}}, "space.x_max: must be a finite number, got nan"),
    ({"space": {"x_max": float("inf")}}, "space.x_max: must be a finite number, got inf"),
    ({"space": {"x_max": 2.0, "axes": [{"name": "x", "low": 0, "high": 1}]}}, "either axes or x_min/x_max/n_x"),
    ({"space": {"axes": []}}, "1 to 4 axes, got 0"),
    ({"space": {"axes": [{"name": f"a{i}", "low": 0, "high": 1} for i in range(5)]}}, "1 to 4 axes, got 5"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1}] * 2}}, "names must differ"),
    ({"space": {"axes": [{"name": "x y", "low": 0, "high": 1}]}}, "space.axes.0.name"),
    ({"space": {"axes": [{"name": "x", "low": 1, "high": 1}]}}, "space.axes.0: Value error, low (1.0) must be below"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": float("nan")}]}}, "space.axes.0.high"),
    ({"space": {"axes": [{"name": "x", "low": 0, "high": 1, "n": 1}]}}, "space.axes.0.n"),
    (
        {
            "space": {
                "axes": [{"name": "x", "low": 0, "high": 1, "n": 200}, {"name": "y", "low": 0, "high": 1, "n": 200}]
            }
        },
        "more than 20000 points",
    ),
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
    ({"inference": {"max_inputs": 4}}, "inference.max_inputs: Input should be greater than or equal to 8"),
    ({"inference": {"search_inputs": 0}}, "inference.search_inputs: Input should be greater than or equal to 8"),
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


NAN, INF = float("nan"), float("inf")
FIELD = {"noise_model": {"field": {}}}
STRICT = [
    ({"reward": {"alpha": "0.1"}}, "reward.alpha: expected a number, got the string '0.1'"),
    ({"reward": {"gamma": True}}, "reward.gamma: expected a number, got the boolean true"),
    ({"primary_model": {"length_loc": NAN}}, "primary_model.length_loc: must be a finite number, got nan"),
    ({"space": {"t_max": INF}}, "space.t_max: must be a finite number, got inf"),
    ({"space": {"t_min": "0.2"}}, "space.t_min: expected a number, got the string '0.2'"),
    ({"space": {"n_t": "100"}}, "space.n_t: expected a whole number, got the string '100'"),
    ({"space": {"x_min": "0"}}, "space.x_min: expected a number, got the string '0'"),
    ({"space": {"x_max": True}}, "space.x_max: expected a number, got the boolean true"),
    ({"space": {"x_max": -INF}}, "space.x_max: must be a finite number, got -inf"),
    ({"space": {"n_x": "40"}}, "space.n_x: expected a whole number, got the string '40'"),
    (
        {"space": {"axes": [{"name": "x", "low": "0", "high": 1}]}},
        "space.axes.0.low: expected a number, got the string '0'",
    ),
    (
        {"space": {"axes": [{"name": "x", "low": 0, "high": 1, "n": True}]}},
        "space.axes.0.n: expected a whole number, got the boolean true",
    ),
    ({"acquisition": {"maximize": "yes"}}, "acquisition.maximize: expected true or false, got the string 'yes'"),
    ({"acquisition": {"maximize": 1}}, "acquisition.maximize: expected true or false, got 1"),
    ({"acquisition": {"fixed_t": "2"}}, "acquisition.fixed_t: expected a number, got the string '2'"),
    ({"acquisition": {"ucb_kappa": NAN}}, "acquisition.ucb_kappa: must be a finite number, got nan"),
    (
        {"noise_model": {"learn_after_convergence": 0}},
        "noise_model.learn_after_convergence: expected true or false, got 0",
    ),
    (
        {"noise_model": {"a0_prior": {"high": "15"}}},
        "noise_model.a0_prior.high: expected a number, got the string '15'",
    ),
    (
        {"noise_model": {"field": {"boundary_factor": NAN}}},
        "noise_model.field.boundary_factor: must be a finite number, got nan",
    ),
    (
        {"noise_model": {"field": {"basis_per_axis": "32"}}},
        "noise_model.field.basis_per_axis: expected a whole number, got the string '32'",
    ),
    ({"inference": {"restarts": True}}, "inference.restarts: expected a whole number, got the boolean true"),
    (
        {"inference": {"max_inputs": "1024"}},
        "inference.max_inputs: expected a whole number, got the string '1024'",
    ),
    (
        {"inference": {"laplace_samples": "32"}},
        "inference.laplace_samples: expected a whole number, got the string '32'",
    ),
    ({"schedule": {"n_steps": "15"}}, "schedule.n_steps: expected a whole number, got the string '15'"),
    (
        {"schedule": {"adaptive_shots": "false"}},
        "schedule.adaptive_shots: expected true or false, got the string 'false'",
    ),
    ({"schedule": {"threshold": INF}}, "schedule.threshold: must be a finite number, got inf"),
    ({"schedule": {"budget_s": "300"}}, "schedule.budget_s: expected a number, got the string '300'"),
    ({"schedule": {"tolerated_rate": True}}, "schedule.tolerated_rate: expected a number, got the boolean true"),
    (
        {"reduction": {"sho": {"q_bounds": [5, "5000"]}}},
        "reduction.sho.q_bounds.1: expected a number, got the string '5000'",
    ),
    (
        {"reduction": {"sho": {"nominal_q": INF, "nominal_resonance_hz": 1e5}}},
        "reduction.sho.nominal_q: must be a finite number, got inf",
    ),
    (
        {"instrument": {"kind": "forrester", "timeout_s": "5"}},
        "instrument.timeout_s: expected a number, got the string '5'",
    ),
    (
        {"instrument": {"kind": "forrester", "faults": {"nan": "0.1"}}},
        "instrument.faults.nan: expected a number, got the string '0.1'",
    ),
    (
        {"instrument": {"kind": "forrester", "faults": {"seed": False}}},
        "instrument.faults.seed: expected a whole number, got the boolean false",
    ),
    ({"schema_version": True}, "schema_version: expected a whole number, got the boolean true"),
    ({"schema_version": "2"}, "schema_version: expected a whole number, got the string '2'"),
    ({"reward": {"beta": np.True_}}, "reward.beta: expected a number, got the boolean true"),
    ({"reward": {"beta": np.float64("nan")}}, "reward.beta: must be a finite number, got nan"),
]


@pytest.mark.parametrize("data, message", STRICT, ids=[s[1] for s in STRICT])
def test_a_string_a_boolean_or_a_non_finite_number_is_refused_naming_the_field(data, message):
    with pytest.raises(ConfigError) as info:
        parse_config(data)
    assert str(info.value) == f"config: {message}"


def test_every_number_and_flag_of_the_config_is_strict():
    assert lax_fields(CampaignConfig) == []


def test_lax_fields_names_the_numbers_and_flags_a_plain_model_lets_through():
    class Inner(BaseModel):
        gain: float = 1.0
        rows: Count = 2

    class Plain(BaseModel):
        name: str = "x"
        kind: Literal["a", "b"] = "a"
        rate: Number = 1.0
        span: tuple[float, Number] = (0.0, 1.0)
        limit: int | None = None
        verbose: bool = False
        quiet: Flag = False
        inner: Inner | None = None
        inners: tuple[Inner, ...] = ()

    assert lax_fields(Plain) == ["span", "limit", "verbose", "inner.gain", "inners.gain"]


def test_ints_for_numbers_whole_numbers_for_counts_and_lists_for_pairs_are_accepted():
    assert (
        parse_config({"schedule": {"n_steps": np.int64(4), "adaptive_shots": np.True_}}).schedule.adaptive_shots is True
    )
    cfg = parse_config(
        {
            "reward": {"alpha": 1},
            "schedule": {"n_steps": 4.0, "adaptive_shots": True},
            "reduction": {"sho": {"q_bounds": [5, 50]}},
            "space": {"x_min": 0, "x_max": 1, "n_x": 50},
        }
    )
    assert cfg.reward.alpha == 1.0 and isinstance(cfg.reward.alpha, float)
    assert cfg.schedule.n_steps == 4 and isinstance(cfg.schedule.n_steps, int) and cfg.schedule.adaptive_shots is True
    assert cfg.reduction.sho.q_bounds == (5.0, 50.0) and cfg.space.n_x == 50


@pytest.mark.parametrize("path", sorted((ROOT / "data" / "configs").glob("*.yaml")), ids=lambda p: p.name)
def test_a_config_comes_back_from_the_json_a_journal_stores(path):
    from noisebo.instruments.registry import validated

    cfg = load_config(path)  # a fleet's instruments are checked by their drivers as it loads
    cfg = cfg if cfg.instruments is not None else validated(cfg)
    stored = json.loads(json.dumps(cfg.model_dump(mode="json")))
    assert parse_config(stored, "journal") == cfg


def test_the_config_of_a_schema_1_file_still_loads():
    with h5py.File(ROOT / "tests" / "data" / "forrester_schema1.h5", "r") as f:
        cfg = parse_config(json.loads(f.attrs["config_json"]), "journal")
    assert cfg.schema_version == 2 and cfg.instrument.settings == {"a0": 0.1, "a1": 2.0}
    assert (cfg.space.n_x, cfg.schedule.n_steps, cfg.acquisition.maximize) == (40, 4, True)


@pytest.mark.parametrize(
    "max_inputs, axes, cap",
    [
        (None, 1, 256),  # one axis (and the noise model's t): proposals lie on the grid
        (None, 2, 512),  # over an area every proposal is an input of its own
        (None, 4, 512),
        (512, 1, 512),  # set: the same for every GP
        (512, 3, 512),
    ],
)
def test_max_inputs_unset_grows_with_the_axes(max_inputs, axes, cap):
    inference = parse_config({"inference": {"max_inputs": max_inputs}}).inference
    assert inference.max_inputs_for(axes) == cap


def test_loose_values_names_what_a_lax_model_took_that_noiseboes_numbers_and_flags_refuse():
    from noisebo.config import loose_values

    class Inner(BaseModel):
        gain: float = 1.0

    class Plain(BaseModel):
        rate: float = 1.0
        label: str | float = "a"
        verbose: bool = False
        span: tuple[float, float] = (0.0, 1.0)
        inner: Inner | None = None
        inners: tuple[Inner, ...] = ()

    raw = {
        "rate": "8",
        "label": "8",  # text is one of its types
        "verbose": 1,
        "span": [0, True],
        "inner": {"gain": "2"},
        "inners": [{"gain": 1.5}, {"gain": False}],
    }
    Plain.model_validate(raw)  # the lax model takes all of it
    assert loose_values(Plain, raw, "s.") == [
        "s.rate: a number, not the text '8'",
        "s.verbose: true or false, not 1",
        "s.span.1: a number, not True",
        "s.inner.gain: a number, not the text '2'",
        "s.inners.1.gain: a number, not False",
    ]
    assert loose_values(Plain, {"rate": 8, "verbose": True, "span": [0, 1.5], "inners": [{"gain": 2}]}) == []
