import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.campaign.steps import make_point, seed_points
from noisebo.config import CampaignConfig
from noisebo.diagnostics import compile_count
from noisebo.reduction import NoUsableShots, Reading

SHORT = CampaignConfig().with_overrides(schedule={"n_steps": 5}, space={"n_x": 50, "n_t": 40})


@pytest.fixture(scope="module")
def short_run():
    return run_campaign(SHORT, build(SHORT.instrument), seed=11)


def test_seed_points_are_a_latin_hypercube_in_x_and_log_t():
    cfg = CampaignConfig().with_overrides(schedule={"n_seed": 5})
    pts = seed_points(cfg, 3)
    assert pts.shape == (5, 2)
    assert sorted(np.floor(pts[:, 0] * 5).astype(int)) == [0, 1, 2, 3, 4]
    log_strata = np.floor(np.log(pts[:, 1] / 0.2) / np.log(10 / 0.2) * 5).astype(int)
    assert sorted(log_strata) == [0, 1, 2, 3, 4]


def test_log_span_seeds_put_t_at_both_ends_and_the_geometric_middle():
    cfg = CampaignConfig().with_overrides(schedule={"seed_t_scale": "log_span"})
    pts = seed_points(cfg, 3)
    np.testing.assert_allclose(sorted(pts[:, 1]), [0.2, np.sqrt(0.2 * 10.0), 10.0])
    assert sorted(np.floor(pts[:, 0] * 3).astype(int)) == [0, 1, 2]


def test_shortest_seeds_are_all_at_t_min_and_still_stratified_over_x():
    cfg = CampaignConfig().with_overrides(schedule={"seed_t_scale": "shortest"})
    pts = seed_points(cfg, 3)
    np.testing.assert_array_equal(pts[:, 1], [0.2, 0.2, 0.2])
    assert sorted(np.floor(pts[:, 0] * 3).astype(int)) == [0, 1, 2]


def test_same_seed_same_campaign(short_run):
    again = run_campaign(SHORT, build(SHORT.instrument), seed=11)
    assert again.state == short_run.state
    assert [(d.x, d.t, d.acq_value) for d in again.decisions] == [(d.x, d.t, d.acq_value) for d in short_run.decisions]


def test_other_seed_other_campaign(short_run):
    seeded_only = SHORT.with_overrides(schedule={"n_steps": 0})  # the seed points differ already
    other = run_campaign(seeded_only, build(SHORT.instrument), seed=12)
    assert other.state.points[0] != short_run.state.points[0]


def test_campaign_shape_and_bookkeeping(short_run):
    state = short_run.state
    assert len(state.points) == 3 + 5 and len(state.t_opt_history) == 5
    for p in state.points:
        assert len(p.x) == 1 and 0.0 <= p.x[0] <= 1.0 and 0.2 <= p.t <= 10.0
    # Points proposed after convergence get 3 shots and model noise; before, 30 and measured noise.
    for step, decision in enumerate(short_run.decisions):
        point = state.points[3 + step]
        assert (point.x, point.t, point.n_shots) == (decision.x, decision.t, decision.shots)
        converged = state.converged_step is not None and step >= state.converged_step
        assert point.noise_measured is (not converged)
        assert point.n_shots == (3 if converged else 30)
        if converged:
            assert point.noise == decision.noise_at_t
    assert short_run.total_measurement_time == pytest.approx(sum(p.t * p.n_shots for p in state.points))


def test_no_recompilation_after_the_first_step(short_run):
    marks = []
    run_campaign(
        SHORT,
        build(SHORT.instrument),
        seed=5,
        on_commit=lambda state, events: marks.append(compile_count()) if state.decisions else None,
    )
    assert marks[-1] == marks[0]


def test_measured_noise_needs_two_usable_shots():
    forrester = CampaignConfig().reduction
    with pytest.raises(NoUsableShots, match="1 of 1 shots usable, 2 needed"):
        make_point(0.1, 1.0, [Reading(2.0)], None, forrester)
    with pytest.raises(NoUsableShots, match="1 of 2 shots usable, 2 needed .non-finite reading"):
        make_point(0.1, 1.0, [Reading(2.0), Reading(float("nan"))], None, forrester)
    point, shots = make_point(0.1, 1.0, [Reading(2.0), Reading(float("inf"))], 0.7, forrester)
    assert (point.value, point.n_shots, point.noise) == (2.0, 1, 0.7)
    assert [s.ok for s in shots] == [True, False] and shots[1].reason == "non-finite reading"


def _shots(values, ok=None):
    from noisebo.reduction import ShotValue

    ok = ok or [True] * len(values)
    return [ShotValue(v, o, "" if o else "bad", None) for v, o in zip(values, ok)]


@pytest.mark.parametrize(
    "values, clip, rejected",
    [
        # median 10.5, MAD 0.5 -> robust sd 0.7413; 3 sd = 2.224: 16 (5.5 away) is out, 9.5 (1 away) in
        ([9.5, 10.0, 10.5, 11.0, 16.0], 3.0, [4]),
        ([9.5, 10.0, 10.5, 11.0, 16.0], 10.0, []),  # 10 sd = 7.41
        ([9.5, 10.0, 10.5, 11.0, 16.0], None, []),
        ([1.0, 50.0], 3.0, []),  # fewer than three: nothing to judge by
        ([2.0, 2.0, 2.0, 9.0], 3.0, []),  # MAD 0: left alone
    ],
)
def test_outlier_clipping_by_hand(values, clip, rejected):
    from noisebo.reduction import clip_outliers

    out = clip_outliers(_shots(values), clip)
    assert [i for i, v in enumerate(out) if not v.ok] == rejected
    assert all(v.reason.startswith("outlier: ") for v in out if not v.ok)


def test_clipping_ignores_shots_already_rejected_and_the_point_uses_the_rest():
    import math

    from noisebo.instruments.base import Reading
    from noisebo.campaign.steps import make_point
    from noisebo.config import ReductionConfig

    readings = [Reading(v) for v in (9.5, 10.0, 10.5, 11.0, 16.0, float("nan"))]
    point, shots = make_point(0.5, 1.0, readings, None, ReductionConfig(), clip_sd=3.0)
    assert [s.ok for s in shots] == [True, True, True, True, False, False]
    assert shots[5].reason == "non-finite reading"
    assert point.value == pytest.approx(10.25) and point.n_shots == 4
    assert point.shot_std == pytest.approx(math.sqrt((0.75**2 + 0.25**2 + 0.25**2 + 0.75**2) / 3))


def test_no_model_is_ever_trained_on_a_non_finite_value(tiny_config):
    from noisebo.models.fitting import NonFiniteData, fit_key, fit_models
    from noisebo.state import CampaignState, Point

    state = CampaignState()
    for i, value in enumerate([1.0, float("inf"), 2.0]):
        state = state.with_point(Point(0.1 * i, 1.0, value, 0.5, 10, 0.5, True))
    with pytest.raises(NonFiniteData, match=r"point\(s\) \[1\] have a non-finite value"):
        fit_models(tiny_config, Method.of(tiny_config).noise_law, state, fit_key(0, 0))


def test_few_shot_points_that_lost_shots_do_not_train_the_noise_model():
    from noisebo.state import CampaignState, Point

    state = CampaignState()
    for n, measured in [(30, True), (2, True), (3, False), (2, False), (1, False)]:
        state = state.with_point(Point(0.5, 1.0, 1.0, 0.3, n, 0.3, measured))
    assert state.noise_training_mask(False).tolist() == [True, True, False, False, False]
    assert state.noise_training_mask(True, 3).tolist() == [True, True, True, False, False]
    assert state.noise_training_mask(True, 2).tolist() == [True, True, True, True, False]


@pytest.mark.parametrize(
    ("rejected", "intact_shots", "expected"),
    [
        # kept shots: 30 (measured), 2, 3, 2, 1; the 2-shot points train when intact (budget mode)
        ((0, 0, 0, 0, 0), 2, [True, True, True, True, False]),
        ((0, 0, 0, 1, 0), 2, [True, True, True, False, False]),  # the 4th lost a shot: its 2 may hide an outlier
        ((1, 1, 1, 0, 0), 2, [True, False, True, True, False]),  # measured, or kept shots_after: trains as before
        ((0, 0, 0, 0, 0), None, [True, False, True, False, False]),  # the paper mode: shots_after as before
        ((0, 0, 0, 0, 0), 3, [True, False, True, False, False]),
    ],
)
def test_in_the_budget_mode_intact_two_shot_points_train_the_noise_model(rejected, intact_shots, expected):
    from noisebo.state import CampaignState, Point

    state = CampaignState()
    for (n, measured), lost in zip([(30, True), (2, False), (3, False), (2, False), (1, False)], rejected):
        state = state.with_point(Point(0.5, 1.0, 1.0, 0.3, n, 0.3, measured), lost)
    assert state.rejected == rejected
    assert state.intact().tolist() == [lost == 0 for lost in rejected]
    assert state.noise_training_mask(True, 3, intact_shots).tolist() == expected


def test_a_state_made_from_points_alone_knows_of_no_intact_point():
    from noisebo.state import CampaignState, Point

    points = tuple(Point(0.5, 1.0, 1.0, 0.3, 2, 0.3, False) for _ in range(3))
    state = CampaignState(points=points)
    assert state.intact().tolist() == [False] * 3
    assert state.noise_training_mask(True, 3, 2).tolist() == [False] * 3
    grown = state.with_point(Point(0.5, 1.0, 1.0, 0.3, 2, 0.3, False))  # still unknown for the first three
    assert grown.rejected == () and grown.intact().tolist() == [False] * 4
    assert CampaignState().with_point(points[0]).intact().tolist() == [True]
