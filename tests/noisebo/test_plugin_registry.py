"""Policies and noise laws as plug-ins (``noisebo.registry``): every installed one validates, runs
a short campaign and is listed by `noisebo policies`; an unknown name lists what is installed; a
broken plug-in is named in one line and the others still load."""

import textwrap

import pytest

from noisebo.cli.main import main
from noisebo.instruments import build
from noisebo import registry
from noisebo.campaign.driver import run_campaign
from noisebo.config import CampaignConfig, ConfigError
from noisebo.models.grids import grids

TINY = CampaignConfig().with_overrides(
    name="tiny", space={"n_x": 30, "n_t": 20}, schedule={"n_steps": 2, "shots_before": 6, "shots_after": 3}
)
BUILT_IN = {
    registry.POLICIES: {"reward", "double", "info_rate"},
    registry.NOISE_LAWS: {"inv_sqrt", "power", "quadrature"},
}


def test_the_built_ins_are_registered_by_entry_point():
    for group, names in BUILT_IN.items():
        assert names <= set(registry.names(group))
        for name in names:
            assert registry.installed(group)[name].distribution == "noisebo"
    assert registry.paper_policies() == ("reward", "double")  # a sweep's "both", in the paper's order
    assert registry.chosen_policies("both") == registry.paper_policies()
    assert registry.chosen_policies("all")[:3] == ("reward", "double", "info_rate")
    assert registry.chosen_policies("info_rate") == ("info_rate",)


@pytest.fixture(scope="module")
def listed():
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["policies"]) == 0
    return out.getvalue()


def _run(config):
    run = run_campaign(config, build(config.instrument), 0)
    assert len(run.decisions) == config.schedule.n_steps and run.summary is not None
    t_grid = set(grids(config).t.tolist())
    assert all(d.t in t_grid and config.space.x_min <= d.x[0] <= config.space.x_max for d in run.decisions)
    return run


@pytest.mark.parametrize("name", registry.policy_names())
def test_every_installed_policy_validates_runs_and_is_listed(name, listed):
    config = TINY.with_overrides(acquisition={"policy": name})
    assert config.acquisition.policy == name
    _run(config)
    assert any(line.split()[:1] == [name] for line in listed.splitlines())


@pytest.mark.parametrize("name", registry.noise_law_names())
def test_every_installed_noise_law_validates_runs_and_is_listed(name, listed):
    config = TINY.with_overrides(noise_model={"mean": name})
    assert config.noise_model.mean == name
    run = _run(config)
    assert (
        any(key.endswith("p") for key in run.decisions[-1].hyperparameters) == registry.noise_law(name).infers_exponent
    )
    assert any(line.split()[:1] == [name] for line in listed.splitlines())


@pytest.mark.parametrize(
    "section, key, kind", [("acquisition", "policy", "policy"), ("noise_model", "mean", "noise law")]
)
def test_an_unknown_name_is_one_line_listing_what_is_installed(section, key, kind):
    with pytest.raises(ConfigError) as info:
        TINY.with_overrides(**{section: {key: "greedy"}})
    message = str(info.value)
    group = registry.POLICIES if key == "policy" else registry.NOISE_LAWS
    assert "\n" not in message
    assert f"{section}.{key}: no installed {kind} 'greedy'; installed: {', '.join(registry.names(group))}" in message


def test_old_configs_with_the_names_as_strings_still_load():
    data = TINY.model_dump(mode="json")
    data["acquisition"]["policy"], data["noise_model"]["mean"] = "double", "quadrature"
    config = type(TINY).model_validate(data)
    assert (config.acquisition.policy, config.noise_model.mean) == ("double", "quadrature")
    assert type(TINY).model_validate_json(config.model_dump_json()) == config


@pytest.fixture
def broken_plugins(tmp_path, monkeypatch):
    """Three plug-ins installed into a folder on sys.path: one that cannot be imported, one
    without ``point_scores``, and a noise law without ``share``."""
    (tmp_path / "broken_plugins.py").write_text(
        textwrap.dedent("""
        class NoScores:
            uses_spread = chooses_shots = False
            paper = 0

            def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
                return post.f_var[:, None]

        class NoShare:
            infers_exponent = False
            sources_power = 1.0

            def mean(self, t, a0, a1, p=0.5):
                return a1 / t**0.5 + a0

            def combine(self, shot, a0):
                return shot + a0
        """)
    )
    dist = tmp_path / "noisebo_broken_plugins-0.0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: noisebo-broken-plugins\nVersion: 0.0.1\n")
    (dist / "entry_points.txt").write_text(
        textwrap.dedent("""
        [noisebo.policies]
        missing-module = no_such_module_anywhere:Policy
        no-scores = broken_plugins:NoScores

        [noisebo.noise_laws]
        no-share = broken_plugins:NoShare
        """)
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def test_a_broken_plugin_is_named_in_one_line_and_the_others_still_load(broken_plugins, capsys):
    with pytest.raises(registry.PluginBroken) as info:
        registry.policy("missing-module")
    assert str(info.value).startswith(
        "policy 'missing-module' (no_such_module_anywhere:Policy) could not be loaded: ModuleNotFoundError"
    )
    with pytest.raises(
        registry.PluginBroken,
        match=r"^policy 'no-scores' \(broken_plugins:NoScores\) lacks "
        r"point_scores$",
    ):
        registry.policy("no-scores")
    with pytest.raises(registry.PluginBroken, match=r"^noise law 'no-share' .* lacks share$"):
        registry.noise_law("no-share")
    with pytest.raises(ConfigError) as config_error:
        TINY.with_overrides(acquisition={"policy": "no-scores"})
    assert "acquisition.policy: policy 'no-scores'" in str(config_error.value) and "\n" not in str(config_error.value)

    assert {"missing-module", "no-scores"} <= set(registry.policy_names())
    assert "missing-module" not in registry.working_policies() and "reward" in registry.working_policies()
    assert registry.paper_policies() == ("reward", "double")
    assert TINY.with_overrides(acquisition={"policy": "double"}).acquisition.policy == "double"

    assert main(["policies"]) == 0
    lines = capsys.readouterr().out.splitlines()
    broken = [line for line in lines if "BROKEN" in line]
    assert len(broken) == 3 and any(line.split()[0] == "no-share" for line in broken)
    assert any(line.split()[0] == "reward" and "BROKEN" not in line for line in lines)
