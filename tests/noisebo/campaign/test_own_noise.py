"""A noise law per instrument: each decision made for an instrument learns its noise from that
instrument's own points and converges on its own optimal t; the same journal replays to the same
per-instrument views; the config refuses what a law per instrument cannot do, in one line."""

import numpy as np
import pytest

from noisebo.campaign import engine
from noisebo.campaign.fleet import FleetTiming, run_fleet
from noisebo.bridge.exchange import noise_standing
from noisebo.campaign.own_noise import (
    Standing,
    decisions_for,
    min_own_points,
    own_data,
    own_previous,
    standings,
    state_standings,
)
from noisebo.cli.files import inspect_summary
from noisebo.storage.hdf5 import write_snapshot
from noisebo.campaign.stages import run_decision
from noisebo.config import CampaignConfig, ConfigError, parse_config
from noisebo.instruments import build
from noisebo.models.reward import true_optimal_t

A1 = {"good": 1.0, "bad": 8.0}


def two_laws(per_instrument=True, **noise_model) -> CampaignConfig:
    """Forrester on "good" (A1 = 1) and "bad" (A1 = 8), both A0 = 0.1."""
    dumped = (
        CampaignConfig()
        .with_overrides(
            space={"n_x": 40, "n_t": 30},
            schedule={"n_seed": 4, "n_steps": 6, "shots_before": 12, "shots_after": 4},
            noise_model=noise_model,
        )
        .model_dump(mode="json")
    )
    dumped["noise_model"]["per_instrument"] = per_instrument
    one = dumped.pop("instrument")
    named = [{**one, "name": n, "settings": {**one.get("settings", {}), "a0": 0.1, "a1": a}} for n, a in A1.items()]
    return parse_config({**dumped, "instruments": named})


@pytest.fixture(scope="module")
def campaign():
    config = two_laws()
    instruments = {i.name: build(i.section) for i in config.instruments}
    events = []
    run = run_fleet(
        config, instruments, 3, FleetTiming(shot_overhead_s=0.1, decision_s=1.0), lambda s, e: events.extend(e)
    )
    return config, instruments, run.final, events


def test_each_decision_is_recorded_for_the_instrument_its_point_went_to(campaign):
    _, _, final, _ = campaign
    assert len(final.decided_for) == len(final.decisions) == 6 and set(final.decided_for) == set(A1)
    for step, who in enumerate(final.decided_for):
        entry = next(p for p in final.points if p.committed.index == 4 + step)
        assert entry.instrument == who  # no take-over here: the point was measured where it was issued


def test_an_instruments_noise_model_sees_its_own_points_and_its_own_decisions(campaign):
    _, _, final, _ = campaign
    for name in A1:
        own = own_data(final, name)
        mine = [e.committed.point for e in final.points if e.instrument == name]
        steps = decisions_for(final, name)
        if len(mine) >= min_own_points(final.config):
            assert own.points == tuple(mine)
        else:
            assert own.points == final.data.points
        assert own.t_opt_history == tuple(final.decisions[k].t_opt for k in steps)
        converged = [n for n, k in enumerate(steps) if final.decisions[k].converged]
        assert own.converged_step == (converged[0] if converged else None)
        assert own_previous(final, name) is final.decisions[steps[-1]].hyperparameters


def test_from_one_state_each_instrument_is_sent_to_its_own_optimal_t_only_with_a_law_each(campaign):
    config, instruments, final, _ = campaign
    s, r = config.space, config.reward
    t_star = {n: true_optimal_t(instruments[n].noise_law, s.t_min, s.t_max, r.alpha, r.beta) for n in A1}
    assert t_star["bad"] > 1.5 * t_star["good"]  # a noisier instrument pays for longer exposures
    own = {n: run_decision(engine.step_inputs(final, n)).t_opt for n in A1}
    assert own["bad"] > 1.3 * own["good"]
    for n in A1:
        assert abs(own[n] / t_star[n] - 1) < 0.25, (own, t_star)
    shared = engine.EngineState(**{**final.__dict__, "config": two_laws(per_instrument=False)})
    one_law = {n: run_decision(engine.step_inputs(shared, n)).t_opt for n in A1}
    assert one_law["good"] == one_law["bad"]  # one law: the same data, the same decision


def test_a_replayed_journal_gives_the_same_views(campaign):
    _, _, final, events = campaign
    from noisebo.storage import event_codec

    start = engine.new_campaign(final.config, final.seed, final.driver, final.versions, final.created_utc)
    replayed = engine.replay([start, *(event_codec.decode(event_codec.encode(e)) for e in events)])
    assert replayed.decided_for == final.decided_for
    for name in A1:
        assert own_data(replayed, name).t_opt_history == own_data(final, name).t_opt_history
        np.testing.assert_array_equal(
            own_data(replayed, name).column("shot_std"), own_data(final, name).column("shot_std")
        )


@pytest.mark.parametrize(
    "per_instrument, law, between, message",
    [
        (
            False,
            "inv_sqrt",
            {"a0": 0.1},
            "between_instruments: a prior between the instruments' laws needs per_instrument",
        ),
        (True, "inv_sqrt", {"p": 0.1}, "between_instruments.p: the law 'inv_sqrt' has no exponent p"),
        (True, "inv_sqrt", {}, "between_instruments: give the spread of a0, a1 or p"),
        (True, "inv_sqrt", {"a0": 0}, "between_instruments.a0"),
        (True, "inv_sqrt", {"a0": 0.1, "a2": 0.1}, "between_instruments.a2"),
    ],
)
def test_a_prior_between_laws_refuses_what_it_cannot_do_in_one_line(per_instrument, law, between, message):
    dumped = two_laws().model_dump(mode="json")
    dumped["noise_model"] |= {"per_instrument": per_instrument, "mean": law, "between_instruments": between}
    with pytest.raises(ConfigError) as info:
        parse_config(dumped)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_the_prior_of_an_instrument_is_drawn_from_the_others_with_enough_points(campaign):
    from noisebo.campaign.own_noise import others_data, own_points
    from noisebo.models.between import Other

    _, _, final, _ = campaign
    assert others_data(final, "good") == ()  # no prior between the laws in this config
    dumped = final.config.model_dump(mode="json")
    dumped["noise_model"]["between_instruments"] = {"a0": 0.1}
    pooled = engine.EngineState(**{**final.__dict__, "config": parse_config(dumped)})
    counts = {n: len(own_points(final, n).points) for n in A1}
    for name, other in (("good", "bad"), ("bad", "good")):
        expected = (Other(own_data(final, other), own_previous(final, other)),) if min(counts.values()) >= 3 else ()
        assert others_data(pooled, name) == expected
        inputs = engine.step_inputs(pooled, name)
        assert inputs.others == expected and engine.step_inputs(final, name).others == ()


@pytest.mark.parametrize(
    "change, message",
    [
        ({"instruments": None}, "noise_model.per_instrument: a law per instrument needs several `instruments:`"),
        ({"field": {"varies": "a0"}}, "noise_model.per_instrument: not with noise_model.field"),
    ],
)
def test_a_law_per_instrument_refuses_what_it_cannot_do_in_one_line(change, message):
    dumped = two_laws().model_dump(mode="json")
    if "instruments" in change:
        one = dumped.pop("instruments")[0]
        dumped["instrument"] = {k: v for k, v in one.items() if k != "name"}
    else:
        dumped["noise_model"] |= change
    with pytest.raises(ConfigError) as info:
        parse_config(dumped)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_each_instruments_convergence_is_told_once_with_its_name(campaign):
    from noisebo.campaign.progress import progress_lines
    from noisebo.events import Decided, PointIssued

    _, _, final, events = campaign
    state = engine.start(engine.new_campaign(final.config, final.seed, final.driver, final.versions, final.created_utc))
    said, k = [], 0
    while k < len(events):  # a decision and the point it issues are committed together
        n = 2 if isinstance(events[k], Decided) and isinstance(events[k + 1], PointIssued) else 1
        said += progress_lines(state, events[k : k + n])
        state = engine.apply_all(state, events[k : k + n])
        k += n
    for name in A1:
        told = [line for line in said if line.startswith(f"noise model of {name} converged")]
        assert len(told) == (own_data(final, name).is_converged is True)
    assert not [line for line in said if line.startswith("noise model converged")]


@pytest.mark.parametrize("law, points", [("inv_sqrt", 3), ("quadrature", 3), ("power", 4)])
def test_an_instrument_learns_alone_once_it_has_a_point_more_than_its_law_has_parameters(law, points):
    assert min_own_points(two_laws(mean=law)) == points


def test_each_instruments_standing_by_hand():
    found = standings(("a", "b", "c"), ("a", "b", "a", "b"), (1.0, 2.0, 3.0, 4.0), (False, False, True, True))
    assert found == (Standing("a", 3.0, 3), Standing("b", 4.0, 4), Standing("c", None, None))
    assert [s.text() for s in found] == [
        "a 3 s (converged at step 3)",
        "b 4 s (converged at step 4)",
        "c no decision yet (not converged)",
    ]
    later = standings(("a",), ("a", "a"), (1.0, 2.0), (True, False))  # once converged, it stays so
    assert later == (Standing("a", 2.0, 1),)


def test_each_instruments_standing_is_its_own_laws_in_the_state_the_file_and_the_status(campaign, tmp_path):
    config, _, final, _ = campaign
    found = state_standings(final)
    for s in found:
        own = own_data(final, s.instrument)
        assert s.t_opt == own.t_opt_history[-1]
        steps = decisions_for(final, s.instrument)  # its own decisions' BO steps, from 0
        assert s.converged_step == (None if own.converged_step is None else steps[own.converged_step] + 1)
        assert own.t_opt_points == tuple(final.decisions[k].n_points for k in decisions_for(final, s.instrument))
    path = tmp_path / "two.h5"
    write_snapshot(path, final)
    by_file = inspect_summary(path)["t_opt_by_instrument"]
    assert by_file == {s.instrument: {"t_opt": s.t_opt, "converged_at_step": s.converged_step} for s in found}
    assert noise_standing(final)["by_instrument"] == by_file
    assert state_standings(engine.replay([engine.new_campaign(two_laws(False), 3, final.driver, {}, "now")])) == ()
