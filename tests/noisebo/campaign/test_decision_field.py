"""Decisions with a noise field (``noise_model.field``): a campaign on a Forrester instrument
with a noisy patch finds it and shortens t there; the per-position convergence rule; the maps
travel through the journal and the file; the paired seeds; and a field with NUTS refused."""

import numpy as np
import pytest

from noisebo.instruments.forrester import ForresterInstrument, ForresterSettings
from noisebo.campaign import engine
from noisebo.campaign.driver import run_campaign
from noisebo.campaign.steps import paired_positions, seed_points
from noisebo.config import CampaignConfig, ConfigError, NoiseProfile, ParameterPosterior, ProfileDriver, parse_config
from noisebo.events import DriverInfo
from noisebo.models.convergence import converged, converged_map
from noisebo.models.grids import grids
from noisebo.models.reward import true_optimal_t
from noisebo.storage.record import read_record
from noisebo.storage.hdf5 import write_snapshot
from noisebo.storage.event_codec import decode, encode, rebuild

# Quadrature law sqrt(A1^2/t + A0^2), A1 = 1, A0 = 0.1 off the patch and 4.1 on it (x = 0.5,
# width 0.05): t* = 1.90 s off it, 1.06 s on it for alpha 0.1, beta 2.
SETTINGS = ForresterSettings(a0=0.1, a1=1.0, law="quadrature", patch_a0=4.0, patch_x=0.5, patch_width=0.05)
CONFIG = CampaignConfig(
    name="patch",
    instrument={"kind": "forrester", "settings": SETTINGS.model_dump()},
    space={"n_x": 60, "n_t": 40},
    noise_model={"mean": "quadrature", "field": {"varies": "a0"}},
    schedule={"n_seed": 6, "n_steps": 10, "shots_before": 20},
)


@pytest.fixture(scope="module")
def run():
    events = []
    result = run_campaign(CONFIG, ForresterInstrument(SETTINGS), 4, on_commit=lambda state, new: events.extend(new))
    return result, events


def true_t_star(x):
    def law(t):
        t = np.asarray(t, dtype=np.float64)
        return ForresterInstrument(SETTINGS).noise_law_at(np.array([[x]]), t.reshape(-1))[0].reshape(t.shape)

    return true_optimal_t(law, CONFIG.space.t_min, CONFIG.space.t_max, 0.1, 2.0)


def test_the_truth_of_this_setting():
    assert true_t_star(0.1) == pytest.approx(1.90, abs=0.01)
    assert true_t_star(0.5) == pytest.approx(1.06, abs=0.01)


def test_a_campaign_finds_the_noisy_patch_and_shortens_t_there(run):
    result, _ = run
    x = grids(CONFIG).x
    t_map = result.summary.t_opt_map
    assert t_map.shape == x.shape and result.summary.noise_map.shape == x.shape
    on, off = t_map[np.abs(x - 0.5) < 0.02], t_map[np.abs(x - 0.5) > 0.25]
    assert on.max() < 0.75 * np.median(off)  # truth: 1.06 against 1.90
    assert np.median(off) == pytest.approx(1.90, rel=0.25)
    noise = result.summary.noise_map
    assert noise[np.abs(x - 0.5) < 0.02].min() > 2 * np.median(noise[np.abs(x - 0.5) > 0.25])
    for d in result.decisions:  # one map per step, and a single t for the sample within its range
        assert d.t_opt_map.shape == x.shape and d.t_opt_map.min() <= d.t_opt <= d.t_opt_map.max()
    hyper = result.summary.hyperparameters
    assert {"noise.g0_amplitude", "noise.g0_length", "noise.a0", "noise.a1"} <= set(hyper)
    assert not any(name.endswith("_z") for name in hyper)


def test_convergence_follows_the_maps(run):
    result, _ = run
    maps = [d.t_opt_map for d in result.decisions]
    rule = CONFIG.schedule
    first = next(k for k in range(len(maps)) if converged_map(maps[: k + 1], rule.window, rule.threshold))
    assert result.state.converged_step == first
    assert [d.converged for d in result.decisions] == [k >= first for k in range(len(maps))]


def test_the_maps_replay_from_the_journal_and_reach_the_file(run, tmp_path):
    result, events = run
    started = engine.new_campaign(CONFIG, 4, DriverInfo("forrester", "", {}), {}, "2026-11-24T00:00:00+00:00")
    records = [encode(e) for e in [started, *events]]
    again = rebuild(records)
    assert again.data.converged_step == result.state.converged_step
    assert len(again.data.t_opt_maps) == len(result.decisions)
    for a, b in zip(again.data.t_opt_maps, result.state.t_opt_maps):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(again.summary.t_opt_map, result.summary.t_opt_map)
    path = tmp_path / "patch.h5"
    write_snapshot(path, again)
    data = read_record(path)
    assert data.steps.arrays["t_opt_map"].shape == (len(result.decisions), grids(CONFIG).x.size)
    np.testing.assert_array_equal(data.summary.t_opt_map, result.summary.t_opt_map)
    np.testing.assert_array_equal(data.summary.noise_map, result.summary.noise_map)


def test_a_journal_without_maps_decodes_with_empty_ones(run):
    decided = next(e for e in run[1] if type(e).__name__ == "Decided")
    record = encode(decided)
    del record.arrays["t_opt_map"]
    assert decode(record).decision.t_opt_map.shape == (0,)


def test_an_x_independent_campaign_records_no_maps(tiny_config):
    result = run_campaign(tiny_config.with_overrides(schedule={"n_steps": 1}), ForresterInstrument(), 0)
    assert result.decisions[0].t_opt_map.shape == (0,) and result.summary.t_opt_map.shape == (0,)
    assert result.state.t_opt_maps == ()


@pytest.mark.parametrize(
    "window, maps, expected",
    [
        (3, [[1.0, 2.0]] * 2, False),  # fewer maps than the window
        (3, [[1.0, 2.0]] * 3, True),
        # population variance per position, then the mean: (1, 1.1, 1.2) -> 0.00667 and (2, 2, 2) -> 0
        (3, [[1.0, 2.0], [1.1, 2.0], [1.2, 2.0]], False),  # mean 0.00333 > 5e-4
        (3, [[1.0, 2.0], [1.01, 2.0], [1.02, 2.0]], True),  # mean 3.3e-5
    ],
)
def test_converged_map_by_hand(window, maps, expected):
    assert converged_map([np.asarray(m) for m in maps], window, 5e-4) is expected


def test_constant_maps_give_the_papers_rule():
    history = [2.0, 2.1, 2.12, 2.125, 2.126]
    for k in range(1, len(history) + 1):
        maps = [np.full(7, v) for v in history[:k]]
        assert converged_map(maps, 3, 5e-4) == converged(history[:k], 3, 5e-4)


def test_paired_seed_positions_by_hand():
    x = np.array([[0.1], [0.2], [0.3], [0.4], [0.5]])
    t = np.array([5.0, 0.3, 9.0, 1.0, 2.0])
    # shortest 0.3 (row 1) pairs with the longest 9.0 (row 2), 1.0 (row 3) with 5.0 (row 0); 2.0 alone
    np.testing.assert_array_equal(paired_positions(x, t)[:, 0], [0.4, 0.2, 0.2, 0.4, 0.5])
    seeds = seed_points(CONFIG, 4)
    assert len(np.unique(seeds[:, 0])) == 3 and len(np.unique(seeds[:, 1])) == 6


def test_a_noise_field_needs_map_inference():
    with pytest.raises(ConfigError, match="noise_model.field: the noise field is fitted by MAP"):
        parse_config({"noise_model": {"field": {}}, "inference": {"mode": "nuts"}})


def field_profile(settings: dict) -> dict:
    """A profile of this setting's noise field, by hand: level A0 = 0.1, A1 = 1, the patch a
    spread of about 1 in log A0 over 0.05 of x (x units: the space is [0, 1])."""
    posterior = {"a0": (0.1, 0.02), "a1": (1.0, 0.05), "g0_amplitude": (1.0, 0.2), "g0_length": (0.05, 0.01)}
    return NoiseProfile(
        driver=ProfileDriver(name="forrester", version="1", settings=settings),
        law="quadrature",
        field="a0",
        parameters={name: ParameterPosterior(mean=m, sd=s) for name, (m, s) in posterior.items()},
        t_range_s=(0.2, 10.0),
        noise_points=40,
        campaigns=(),
        made_utc="2026-11-25T00:00:00+00:00",
    ).model_dump(mode="json")


@pytest.mark.parametrize(
    ("instrument", "kept"),
    [({}, True), ({"a0": 0.5, "a1": 0.4}, False)],
    ids=["the same instrument", "another instrument"],
)
def test_a_field_profile_is_the_prior_until_the_replicate_scatter_contradicts_it(instrument, kept):
    settings = SETTINGS.model_copy(update=instrument)
    config = CONFIG.with_overrides(
        instrument={"settings": settings.model_dump()},
        noise_model={"profile": field_profile(SETTINGS.model_dump()), "profile_check": False},
        schedule={"n_steps": 2},
    )
    final = run_campaign(config, ForresterInstrument(settings), 5).final
    assert [d.profile_in_use for d in final.decisions] == [kept, kept]
    assert (final.data.profile_dropped_step is None) == kept
    first = final.decisions[0].profile_p
    assert first >= config.noise_model.profile_alpha if kept else first < config.noise_model.profile_alpha
