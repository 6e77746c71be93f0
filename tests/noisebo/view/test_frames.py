"""Frames are pure functions of a campaign's tables; checked on a hand-made two-step campaign
(steps as the file stores them: seed points 0, BO steps from 1)."""

import dataclasses

import numpy as np
import pytest

from noisebo.config import CampaignConfig
from noisebo.storage.layout import STEP_COLUMNS
from noisebo.storage.record import Points, Shots, Steps, Summary
from noisebo.view.frames import complete_frames, frame_at, frames, n_frames, normalised_reward

CONFIG = CampaignConfig().with_overrides(
    space={"n_x": 3, "n_t": 2, "t_min": 1.0, "t_max": 2.0}, schedule={"n_seed": 2, "n_steps": 2}
)


@dataclasses.dataclass(frozen=True)
class Tables:
    grid: dict
    points: Points
    steps: Steps
    shots: Shots
    summary: Summary | None


def tables(with_summary: bool) -> Tables:
    points = {
        "x": np.array([0.1, 0.9, 0.5]),
        "t": np.array([1.0, 2.0, 1.5]),
        "value": np.array([1.0, 2.0, 3.0]),
        "noise": np.array([0.3, 0.2, 0.25]),
        "shot_std": np.array([0.3, 0.2, 0.25]),
        "n_shots": np.array([2, 2, 1]),
        "noise_measured": np.array([True, True, False]),
        "step": np.array([0, 0, 1]),
        "index": np.array([0, 1, 2]),
        "instrument": ("", "", ""),
    }  # two seed points (step 0), then BO step 1's point
    steps = {
        "step": np.array([1, 2]),
        "x": np.array([0.5, 0.0]),
        "t": np.array([1.5, 1.0]),
        "shots": np.array([1, 1]),
        "t_opt": np.array([1.2, 1.3]),
        "latency_s": np.array([0.5, 0.1]),
        "converged": np.array([False, True]),
    }
    arrays = {
        "acq_map": np.zeros((2, 3, 2)),
        "f_mean": np.array([[0.0, 1.0, 2.0]] * 2),
        "f_var": np.array([[4.0, 1.0, 0.0]] * 2),
        "noise_mean": np.array([[0.4, 0.2]] * 2),
        "noise_var": np.array([[0.01, 0.04]] * 2),
    }
    hyper = {"noise.a0": np.array([0.1, 0.2]), "noise.a1": np.array([1.0, 2.0])}
    unused = {name: np.zeros(2) for name in STEP_COLUMNS if name not in steps}  # columns frames do not read
    point, t = np.array([0, 0, 1, 1, 2]), np.array([1.0, 1.0, 2.0, 2.0, 1.5])
    shots = Shots(point=point, shot=np.zeros(5), t=t, value=np.zeros(5), ok=np.ones(5, dtype=bool))
    summary = Summary(
        f_mean=np.zeros(3),
        f_var=np.ones(3),
        noise_fine=np.array([0.5, 0.4]),
        t_opt=1.25,
        hyperparameters={"noise.a0": 0.3},
        t_opt_map=np.zeros(0),
        noise_map=np.zeros(0),
    )
    grid = {"x": np.array([0.0, 0.5, 1.0]), "t": np.array([1.0, 2.0]), "t_fine": np.array([1.0, 2.0])}
    return Tables(
        grid,
        Points(**points),
        Steps(**steps, **unused, hyperparameters=hyper, arrays=arrays),
        shots,
        summary if with_summary else None,
    )


def test_seed_frame_has_the_seed_points_and_no_model():
    frame = frame_at(tables(False), CONFIG, 0)
    assert frame.step == 0 and frame.f is None and frame.acq_map is None and frame.latest_point == 1
    np.testing.assert_array_equal(frame.points["x"], [0.1, 0.9])
    assert frame.scalars == {"measurement_time_s": 6.0}  # 2 x 1 s + 2 x 2 s


def test_bo_frame_shows_its_decision_and_point():
    frame = frame_at(tables(False), CONFIG, 1)
    assert frame.step == 1 and frame.proposal == (0.5, 1.5) and frame.t_opt == 1.2
    np.testing.assert_array_equal(frame.points["frame"], [0, 0, 1])
    np.testing.assert_allclose(frame.f.sd, [2.0, 1.0, 0.0])
    np.testing.assert_allclose(frame.noise.sd, [0.1, 0.2])
    assert frame.scalars == {"measurement_time_s": 7.5, "t_opt_s": 1.2, "latency_s": 0.5, "a0": 0.1, "a1": 1.0}
    assert frame.text.startswith("step 1: measure x=0.5 at t=1.5 s with 1 shots")
    assert frame.text.endswith("decision 0.500 s (the first: it compiles or loads the models)")


def test_points_committed_out_of_order_are_found_by_their_index():
    # several instruments: seed point 1 (2 shots of 2 s) was committed before seed point 0 (2 of 1 s)
    base = tables(False)
    points = dataclasses.replace(base.points, index=np.array([1, 0, 2]), x=np.array([0.9, 0.1, 0.5]))
    frame = frame_at(dataclasses.replace(base, points=points), CONFIG, 0)
    assert frame.latest_point == 0  # the last committed, not the highest index
    assert frame.scalars == {"measurement_time_s": 6.0}
    ahead = dataclasses.replace(points, index=np.array([0, 1, 3]))  # BO point 3 committed, point 2 in flight
    frame = frame_at(dataclasses.replace(base, points=ahead), CONFIG, 1)
    assert frame.latest_point == 3 and frame.scalars["measurement_time_s"] == 6.0  # point 2's shot not counted


@pytest.mark.parametrize("with_summary, expected", [(False, 2), (True, 3)])
def test_frame_count_is_seeds_plus_committed_points_plus_final(with_summary, expected):
    # the second decision's point is not committed: it has no frame yet
    assert n_frames(tables(with_summary), CONFIG) == expected
    assert [f.step for f in frames(tables(with_summary), CONFIG)] == list(range(expected))


def test_final_frame_uses_the_summary():
    final = frames(tables(True), CONFIG)[-1]
    assert final.t_opt == 1.25 and final.acq_map is None and final.scalars["a0"] == 0.3
    # R = -0.1 t^2 - 2 Noise: (1 s, 0.5) -> -1.1, (2 s, 0.4) -> -1.2
    np.testing.assert_allclose(final.reward.mean, [1.0, 0.0])


def test_normalised_reward_by_hand():
    # alpha 1, beta 2: R(1, 0.5) = -2, R(2, 0) = -4, R(3, 0) = -9 -> (1, 5/7, 0)
    np.testing.assert_allclose(
        normalised_reward(np.array([1.0, 2.0, 3.0]), np.array([0.5, 0.0, 0.0]), 1.0, 2.0), [1.0, 5 / 7, 0.0]
    )


def fleet_tables() -> Tables:
    """Two instruments: seeds 0 and 1 committed before any decision; decision 1's point 2 and
    decision 2's point 3 both committed after decision 2 (point 3 first); decision 3's point 4
    never committed (the campaign stopped)."""
    base = tables(False)
    points = dataclasses.replace(
        base.points,
        x=np.array([0.1, 0.9, 0.0, 0.5]),
        t=np.array([1.0, 2.0, 1.0, 1.5]),
        value=np.arange(4.0),
        noise=np.full(4, 0.3),
        shot_std=np.full(4, 0.3),
        n_shots=np.full(4, 2),
        noise_measured=np.ones(4, dtype=bool),
        step=np.array([0, 0, 2, 1]),
        index=np.array([0, 1, 3, 2]),
        instrument=("a", "b", "a", "b"),
        committed_after=np.array([0, 0, 2, 2]),
    )
    steps = base.steps
    three = {name: np.append(v, v[-1]) for name, v in vars(steps).items() if isinstance(v, np.ndarray)}
    three |= {"step": np.array([1, 2, 3]), "x": np.array([0.5, 0.0, 1.0]), "t": np.array([1.5, 1.0, 2.0])}
    arrays = {name: np.concatenate([v, v[-1:]]) for name, v in steps.arrays.items()}
    hyper = {name: np.append(v, v[-1]) for name, v in steps.hyperparameters.items()}
    steps = dataclasses.replace(steps, **three, arrays=arrays, hyperparameters=hyper, instrument=("b", "a", "a"))
    return dataclasses.replace(base, points=points, steps=steps)


def test_a_fleets_frames_hold_what_was_committed_and_what_was_in_flight_at_each_decision():
    fleet = fleet_tables()
    assert n_frames(fleet, CONFIG) == 4 and complete_frames(fleet, CONFIG) == 3  # one per decision
    shown = [(f.points["index"].tolist(), f.in_flight["index"].tolist()) for f in frames(fleet, CONFIG)]
    assert shown == [([0, 1], []), ([0, 1], [2]), ([0, 1, 3, 2], []), ([0, 1, 3, 2], [4])]
    at_three = frame_at(fleet, CONFIG, 3).in_flight
    assert at_three["x"].tolist() == [1.0] and at_three["t"].tolist() == [2.0]  # decision 3's proposal
    assert at_three["instrument"] == ("a",)  # never committed: the instrument it was made for
    at_one = frame_at(fleet, CONFIG, 1)
    assert at_one.in_flight["t"].tolist() == [1.5] and at_one.in_flight["instrument"] == ("b",)  # made for b
    assert at_one.text.endswith("; in flight: 1 point(s)")


def test_one_instrument_has_nothing_in_flight_and_its_frames_as_before():
    one = tables(True)
    assert frame_at(one, CONFIG, 1).in_flight is None
    assert complete_frames(one, CONFIG) == n_frames(one, CONFIG) == 3
