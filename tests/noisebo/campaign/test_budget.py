"""Instrument-time budgets: a campaign plans each point within what is left, never overspends,
ends as "budget_spent" with its final models, and continues with a larger budget; the steps
limit still ends it first when it comes first."""

import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.instruments.forrester import ForresterInstrument
from noisebo.acquisition.proposal import affordable, cheapest_point_s
from noisebo.campaign import engine
from noisebo.campaign.driver import drive, in_memory, run_campaign
from noisebo.config import CampaignConfig, ConfigError, parse_config
from noisebo.events import BudgetChanged, DriverInfo, Status
from noisebo.models import noise_model
from noisebo.models.grids import grids
from noisebo.storage.event_codec import decode, encode, rebuild


def budgeted(tiny_config, budget_s, overhead_s=2.0, n_steps=100):
    return tiny_config.with_overrides(
        schedule={"budget_s": budget_s, "point_overhead_s": overhead_s, "n_steps": n_steps}
    )


def spent_by_hand(final) -> float:
    shots = sum(s.t for p in final.points for s in p.shots) + sum(s.t for s in final.taken)
    begun = len(final.points) + (1 if final.taken else 0)
    return shots + sum(f.t for f in final.failures) + final.config.schedule.point_overhead_s * begun


@pytest.fixture(scope="module")
def spent(tiny_config):
    config = budgeted(tiny_config, 120.0)
    return config, run_campaign(config, ForresterInstrument(), 3).final


def test_a_budget_is_never_overspent_and_ends_the_campaign(spent):
    config, final = spent
    assert final.status is Status.BUDGET_SPENT and final.reason.startswith("budget spent: ")
    assert final.spent_s == pytest.approx(spent_by_hand(final), rel=1e-12)
    assert final.spent_s <= 120.0
    assert 120.0 - final.spent_s < cheapest_point_s(config)  # it stopped because nothing more fits
    assert final.summary is not None and len(final.decisions) < 100


def test_every_decision_fits_what_was_left(spent):
    config, final = spent
    n_seed = config.schedule.n_seed
    for k, decision in enumerate(final.decisions):
        cost = config.schedule.point_overhead_s + decision.shots * decision.t
        before = sum(p.committed.point.t * len(p.shots) for p in final.points[: n_seed + k])
        before += config.schedule.point_overhead_s * (n_seed + k)
        assert cost <= 120.0 - before + 1e-9


def test_more_budget_continues_the_campaign(spent):
    config, final = spent
    events = [*engine.resumed(final, 180.0)]
    assert isinstance(events[0], BudgetChanged) and events[1].status is Status.RUNNING
    state = engine.apply_all(final, events)
    more = drive(state, ForresterInstrument(), in_memory)
    assert more.status is Status.BUDGET_SPENT and 120.0 < more.spent_s <= 180.0
    assert len(more.points) > len(final.points) and more.points[: len(final.points)] == final.points


def test_the_steps_limit_still_ends_a_campaign_first(tiny_config):
    final = run_campaign(budgeted(tiny_config, 10_000.0, n_steps=2), ForresterInstrument(), 3).final
    assert final.status is Status.COMPLETED and len(final.decisions) == 2 and final.spent_s < 10_000.0


def test_a_budget_below_the_seed_points_stops_before_the_first_that_does_not_fit(tiny_config):
    final = run_campaign(budgeted(tiny_config, 15.0, overhead_s=5.0), ForresterInstrument(), 3).final
    assert final.status is Status.BUDGET_SPENT and final.decisions == ()
    assert final.spent_s <= 15.0 and "point" in final.reason


def test_the_budget_travels_through_the_journal(spent, tiny_config):
    config, final = spent
    assert decode(encode(BudgetChanged(250.0))) == BudgetChanged(250.0)
    assert decode(encode(BudgetChanged(None))) == BudgetChanged(None)
    started = engine.new_campaign(config, 3, DriverInfo("forrester", "", {}), {}, "2026-11-24T00:00:00+00:00")
    events = [started]
    run_campaign(config, ForresterInstrument(), 3, on_commit=lambda state, new: events.extend(new))
    again = rebuild([encode(e) for e in [*events, *engine.resumed(final, 300.0)]])
    assert again.budget_s == 300.0 and again.spent_s == pytest.approx(final.spent_s, rel=1e-12)


# (shots wanted, seconds left) -> (allowed t, shots) on a grid of t = 1, 2, ..., 5 s, overhead 1 s
@pytest.mark.parametrize(
    "shots, left, allowed, used",
    [
        (3, None, [1, 2, 3, 4, 5], 3),
        (3, 100.0, [1, 2, 3, 4, 5], 3),
        (3, 10.0, [1, 2, 3], 3),  # 1 + 3 t <= 10
        (3, 4.0, [1], 3),
        (30, 10.0, [1], 9),  # 30 shots fit at no t: as many as fit at 1 s
        (30, 5.5, [1], 4),
    ],
)
def test_affordable_by_hand(shots, left, allowed, used):
    config = CampaignConfig(
        space={"t_min": 1.0, "t_max": 5.0, "n_t": 5}, schedule={"point_overhead_s": 1.0, "shots_after": 2}
    )
    mask, got = affordable(config, shots, left)
    assert grids(config).t[mask].tolist() == allowed and got == used


def test_bad_budgets_name_the_field():
    for schedule, field in (
        ({"budget_s": 0}, "schedule.budget_s"),
        ({"budget_s": float("inf")}, "schedule.budget_s"),
        ({"point_overhead_s": -1}, "schedule.point_overhead_s"),
    ):
        with pytest.raises(ConfigError, match=field):
            parse_config({"schedule": schedule})


def test_an_unbudgeted_campaign_spends_what_it_measures(tiny_config):
    final = run_campaign(tiny_config.with_overrides(schedule={"n_steps": 1}), ForresterInstrument(), 0).final
    assert final.budget_s is None and final.spent_s == pytest.approx(spent_by_hand(final), rel=1e-12)
    assert np.isfinite(final.spent_s) and final.status is Status.COMPLETED


def test_the_posterior_rule_converges_when_the_interval_is_narrow_enough(tiny_config):
    config = tiny_config.with_overrides(schedule={"convergence": "posterior", "t_interval_rel": 0.2, "n_steps": 3})
    run = run_campaign(config, ForresterInstrument(), 0)
    intervals = [d.t_opt_interval for d in run.decisions]
    assert all(np.isfinite(intervals))
    first = next((k for k, v in enumerate(intervals) if v <= 0.2), None)
    assert run.state.converged_step == first
    assert [d.converged for d in run.decisions] == [first is not None and k >= first for k in range(3)]


def test_the_posterior_rule_needs_draws():
    with pytest.raises(ConfigError, match="the posterior rule needs the noise model's draws"):
        parse_config({"schedule": {"convergence": "posterior"}, "inference": {"laplace_samples": 4}})


# n = 1 + ceil(1 / (2 r^2)) within [max(2, shots_after), shots_before] = [3, 20]
@pytest.mark.parametrize("rel_sd, expected", [(0.5, 3), (0.2, 14), (0.05, 20), (1.0, 3)])
def test_adaptive_noise_point_shots_by_hand(rel_sd, expected):
    import jax.numpy as jnp

    from noisebo.acquisition.proposal import noise_point_shots
    from noisebo.config import ScheduleConfig
    from noisebo.models.grids import space_grids
    from noisebo.models.prediction import Posterior

    sched = ScheduleConfig(shots_before=20, shots_after=3)
    post = Posterior(
        f_mean=jnp.zeros(3),
        f_var=jnp.ones(3),
        noise_mean=jnp.full(4, 2.0),
        noise_var=jnp.full(4, (2.0 * rel_sd) ** 2),
        t=jnp.arange(1.0, 5.0),
        t_opt=jnp.asarray(2.0),
        noise_at_t_opt=jnp.asarray(2.0),
        f_best=jnp.asarray(0.0),
        reward_best=jnp.asarray(0.5),
    )
    assert noise_point_shots(post, 1, (0.5,), space_grids(CampaignConfig().space), sched) == expected


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"schedule": {"noise_t": "informative"}}, "set schedule.convergence: posterior"),
        (
            {"schedule": {"noise_t": "informative", "convergence": "posterior"}, "acquisition": {"fixed_t": 1.0}},
            "acquisition.fixed_t fixes",
        ),
        (
            {
                "schedule": {"noise_t": "informative", "convergence": "posterior"},
                "noise_model": {"field": {"length_loc": -1.0}},
            },
            "without noise_model.field",
        ),
        ({"schedule": {"noise_t": "often"}}, "schedule.noise_t"),
        ({"schedule": {"noise_t": "valued"}}, "set schedule.mode: budget"),
        (
            {"schedule": {"noise_t": "valued", "mode": "budget"}, "acquisition": {"policy": "info_rate"}},
            "the policy 'info_rate' does not choose t by",
        ),
        (
            {"schedule": {"noise_t": "valued", "mode": "budget"}, "acquisition": {"fixed_t": 1.0}},
            "acquisition.fixed_t fixes",
        ),
        (
            {"schedule": {"noise_t": "valued", "mode": "budget"}, "noise_model": {"field": {"length_loc": -1.0}}},
            "without noise_model.field",
        ),
    ],
)
def test_bad_noise_t_settings_say_why(overrides, message):
    with pytest.raises(ConfigError, match=message):
        parse_config(overrides)


@pytest.mark.parametrize("mode", ["paper", "budget"])
def test_an_informative_noise_point_measures_where_the_rate_on_t_star_peaks(tiny_config, mode):
    # The paper mode measures the noise of a point of shots_before shots; the budget mode of
    # every point, with its shots_after shots: each before convergence goes where the rate peaks.
    from noisebo.acquisition import information
    from noisebo.campaign.decision import decide_on
    from noisebo.models.fitting import fit_key, fit_models
    from noisebo.models.prediction import predict

    config = tiny_config.with_overrides(
        schedule={
            "convergence": "posterior",
            "t_interval_rel": 1e-6,
            "noise_t": "informative",
            "n_steps": 1,
            "mode": mode,
        }
    )
    seeds = run_campaign(config.with_overrides(schedule={"n_steps": 0}), ForresterInstrument(), 1).state
    fitted = fit_models(config, Method.of(config).noise_law, seeds, fit_key(1, 0))
    chosen, _ = decide_on(config, Method.of(config), fitted, seeds, 0)
    prediction = predict(config, Method.of(config).noise_law, fitted, seeds)
    shots = config.schedule.shots_before if mode == "paper" else config.schedule.shots_after
    c4 = noise_model.c4(shots)
    rate = np.asarray(
        information.t_opt_rate(
            prediction.t_draws, prediction.noise_draws, jnp.asarray(grids(config).t), (1 - c4**2) / c4**2, shots, 0.0
        )
    )
    assert not chosen.converged and chosen.measure_noise == (mode == "paper") and chosen.shots == shots
    assert chosen.t == grids(config).t[int(np.argmax(rate))] and rate.max() > 0
    policy, _ = decide_on(*_policy_t(config), fitted, seeds, 0)
    assert policy.x == chosen.x  # the point keeps the policy's x


@pytest.mark.parametrize("mode", ["paper", "budget"])
def test_a_wide_interval_after_convergence_narrows_again_only_in_the_budget_mode(tiny_config, mode):
    # A campaign that converged at an earlier step but whose interval of t* is wide again: the
    # budget mode's informative point goes back where the rate on t* peaks; the paper's protocol,
    # done learning, keeps the policy's t.
    from noisebo.acquisition import information
    from noisebo.campaign.decision import decide_on
    from noisebo.models.fitting import fit_key, fit_models
    from noisebo.models.prediction import predict

    config = tiny_config.with_overrides(
        schedule={"convergence": "posterior", "t_interval_rel": 1e-6, "noise_t": "informative", "mode": mode}
    )
    seeds = run_campaign(config.with_overrides(schedule={"n_steps": 0}), ForresterInstrument(), 1).state
    converged = seeds.with_t_opt(2.0, True)
    fitted = fit_models(config, Method.of(config).noise_law, converged, fit_key(1, 0))
    chosen, _ = decide_on(config, Method.of(config), fitted, converged, 0)
    policy, _ = decide_on(*_policy_t(config), fitted, converged, 0)
    prediction = predict(config, Method.of(config).noise_law, fitted, converged)
    rate = information.t_opt_rate(
        prediction.t_draws,
        prediction.noise_draws,
        jnp.asarray(grids(config).t),
        float(noise_model.sampling_rel_var(chosen.shots)),
        chosen.shots,
        0.0,
    )
    peak = grids(config).t[int(np.argmax(np.asarray(rate)))]
    assert chosen.converged and chosen.t_opt_interval > 1e-6 and chosen.x == policy.x
    assert chosen.t == (peak if mode == "budget" else policy.t)
    assert peak != policy.t  # the two outcomes differ, so the mode decides which one is taken


def test_a_valued_budget_decision_keeps_the_policys_x_and_leaves_its_t_only_while_it_pays(tiny_config):
    # Nine points into a valued budget campaign (3 seeds, 6 steps) the draws still disagree on
    # t*: with thousands of points to come a noise measurement elsewhere pays, at the t ValuedT
    # finds from this posterior; on the last step nothing is to come and the policy's t stands.
    import dataclasses

    from noisebo.acquisition.noise_t import ValuedT
    from noisebo.campaign.decision import decide_on
    from noisebo.models.fitting import fit_key, fit_models
    from noisebo.models.prediction import predict

    config = tiny_config.with_overrides(schedule={"mode": "budget", "noise_t": "valued", "n_steps": 5000})
    ran = run_campaign(config.with_overrides(schedule={"n_steps": 6}), ForresterInstrument(), 1).final
    state = dataclasses.replace(ran.data, points=ran.data.points[:9])
    fitted = fit_models(config, Method.of(config).noise_law, state, fit_key(1, 6))
    chosen, _ = decide_on(config, Method.of(config), fitted, state, 6)
    policy, _ = decide_on(*_policy_t(config), fitted, state, 6)
    t = list(grids(config).t)
    prediction = predict(config, Method.of(config).noise_law, fitted, state)
    assert chosen.x == policy.x and chosen.shots == policy.shots == 3 and not chosen.measure_noise
    j = ValuedT().choose(prediction, t.index(policy.t), 3, affordable(config, 3, None)[0], config, None, 6)
    assert chosen.t == t[j] != policy.t
    assert chosen.noise_at_t == pytest.approx(float(np.asarray(prediction.posterior.noise_mean)[t.index(chosen.t)]))
    last, _ = decide_on(config, Method.of(config), fitted, state, 4999)
    assert last.t == policy.t


def _policy_t(config):
    """``config`` with the rule ``noise_t: policy``, and its method."""
    plain = config.with_overrides(schedule={"noise_t": "policy"})
    return plain, Method.of(plain)
