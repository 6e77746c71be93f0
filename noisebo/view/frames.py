"""What a campaign looks like at each step: pure frames built from its tables.

A frame is everything the live view and the report draw at one moment of a campaign, in raw
units. The input is the campaign's typed tables (``CampaignTables``): a file's record
(``storage.record.read_record``) or a running campaign's (``storage.record.from_state``, or the
live recording's lighter view): the same frames come out of both, so a replayed recording
equals the live one. Their step columns number steps as a user sees them (``storage.steps``): 0
for the seed points, k (1..n_steps) for BO step k.

Frame numbering (the ``step`` timeline): 0 holds the seed points; k (1..n_steps) the decision of
BO step k and the point it measured (1-based, as the progress lines print it); n_steps + 1 the
final models after the last point.

With several instruments points are committed out of order, while others are measured: frame k
then holds the points committed before decision k + 1 (``Points.after``; for one instrument the
same as those of steps up to k), and the points in flight then (handed out and not yet committed:
``Frame.in_flight``); it is whole once decision k + 1 is made, or the campaign ended
(``complete_frames``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import jax.numpy as jnp
import numpy as np

from noisebo.config import CampaignConfig
from noisebo.storage.record import Points, Shots, Steps, Summary
from noisebo.models.reward import normalise, reward
from noisebo.state import format_position
from noisebo.precision import float64

POINT_FIELDS = ("x", "t", "value", "noise", "shot_std", "n_shots", "noise_measured", "index", "instrument")


class CampaignTables(Protocol):
    """What frames are drawn from: the grids ("x", "t", "t_fine"), the committed points, the BO
    steps, the shots (frames read their point and t) and the summary (None until done). A
    ``storage.record.CampaignRecord`` is one."""

    @property
    def grid(self) -> Mapping[str, np.ndarray]: ...

    @property
    def points(self) -> Points: ...

    @property
    def steps(self) -> Steps: ...

    @property
    def shots(self) -> Shots: ...

    @property
    def summary(self) -> Summary | None: ...


@dataclass(frozen=True)
class Curve:
    """A model prediction along one axis: grid (m,), mean (m,) and standard deviation (m,)."""

    grid: np.ndarray
    mean: np.ndarray
    sd: np.ndarray


@dataclass(frozen=True)
class Frame:
    """The campaign at one frame. ``points``: columns of POINT_FIELDS plus "frame" (the frame
    that measured each point) for every point committed by then; ``f``, ``noise`` (single-shot
    sd) and ``reward`` (normalised to [0, 1] on the noise grid, sd 0) are None where no model
    exists yet (frame 0); ``latest_point`` the index of the last point committed by then (None
    for none; with several instruments not always the highest); ``acq_map`` (n_x, n_t) only for BO steps ((m,), its best over t at
    each reference point, for d > 1 axes); ``proposal`` (x, t), x a float for one axis, a tuple
    for more; ``scalars`` the traces; ``in_flight`` (several instruments): the points handed out
    and not yet committed at the frame's end, columns x, t, index and instrument (the one its
    decision was made for), None for one instrument."""

    step: int
    points: dict
    f: Curve | None
    noise: Curve | None
    reward: Curve | None
    acq_map: np.ndarray | None
    t_opt: float | None
    proposal: tuple | None
    scalars: dict
    text: str
    latest_point: int | None
    in_flight: dict | None = None


@float64
def normalised_reward(t: np.ndarray, noise: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """R = -alpha t^2 - beta Noise on the grid t, min-max normalised to [0, 1] (numpy)."""
    return np.asarray(normalise(reward(jnp.asarray(t), jnp.asarray(noise), alpha, beta)), dtype=np.float64)


def n_frames(tables: CampaignTables, config: CampaignConfig) -> int:
    """Frames a campaign holds so far: seeds, one per committed BO point (several instruments: one
    per decision), the final one if done."""
    done = tables.summary is not None
    if _fleet(tables):
        return 1 + len(tables.steps.step) + done
    return 1 + int(np.sum(tables.points.step >= 1)) + done


def complete_frames(tables: CampaignTables, config: CampaignConfig) -> int:
    """Frames that no later commit changes: all of them once the campaign is done; while it runs,
    with several instruments those before the last decision (its frame takes the points committed
    until the next), with one every frame whose point is committed."""
    frames = n_frames(tables, config)
    return frames - 1 if _fleet(tables) and tables.summary is None else frames


def _fleet(tables: CampaignTables) -> bool:
    """Whether the points record the decisions each was committed after (several instruments)."""
    return tables.points.committed_after is not None


def frame_at(tables: CampaignTables, config: CampaignConfig, k: int) -> Frame:
    """Frame ``k`` (see the module docstring) of a campaign's tables."""
    steps = tables.steps
    final = tables.summary is not None and k == int(np.sum(tables.points.step >= 1)) + 1
    bo = min(k, len(steps.step)) - 1  # index of the latest decision shown, -1 for none
    points = _points_until(tables.points, k)
    in_flight = _in_flight(tables, config.schedule.n_seed, k) if _fleet(tables) and not final else None
    scalars = {"measurement_time_s": _measurement_time(tables.shots, points)}
    if final:
        return _final_frame(tables, config, k, points, scalars)
    if bo < 0:
        n = len(points["x"])
        return Frame(
            0,
            points,
            None,
            None,
            None,
            None,
            None,
            None,
            scalars,
            f"{n} seed points measured" + _flying(in_flight),
            _latest(points),
            in_flight,
        )
    arrays, grid = steps.arrays, tables.grid
    f = Curve(grid["x"], arrays["f_mean"][bo], np.sqrt(np.maximum(arrays["f_var"][bo], 0.0)))
    noise = Curve(grid["t"], arrays["noise_mean"][bo], np.sqrt(np.maximum(arrays["noise_var"][bo], 0.0)))
    t_opt, latency = float(steps.t_opt[bo]), float(steps.latency_s[bo])
    hyper = {name: float(v[bo]) for name, v in steps.hyperparameters.items()}
    scalars |= {"t_opt_s": t_opt, "latency_s": latency}
    scalars |= {name: hyper[f"noise.{name}"] for name in ("a0", "a1") if f"noise.{name}" in hyper}
    x, t = steps.x[bo], float(steps.t[bo])
    x = float(x) if np.ndim(x) == 0 else tuple(float(v) for v in x)
    text = (
        f"step {bo + 1}: measure x={format_position(x)} at t={t:.4g} s with {int(steps.shots[bo])} shots; "
        f"predicted optimal t {t_opt:.4g} s{' (noise model converged)' if steps.converged[bo] else ''}; "
        f"decision {latency:.3f} s"
        + (" (the first: it compiles or loads the models)" if bo == 0 else "")
        + _flying(in_flight)
    )
    return Frame(
        bo + 1,
        points,
        f,
        noise,
        _reward(noise, config),
        np.asarray(arrays["acq_map"][bo]),
        t_opt,
        (x, t),
        scalars,
        text,
        _latest(points),
        in_flight,
    )


def frames(tables: CampaignTables, config: CampaignConfig) -> list[Frame]:
    """Every frame of a campaign's tables, in order."""
    return [frame_at(tables, config, k) for k in range(n_frames(tables, config))]


def _in_flight(tables: CampaignTables, n_seed: int, k: int) -> dict:
    """The points of decisions 1..k (point index n_seed + j - 1 for decision j) not committed
    before decision k + 1, at their proposals, with the instrument each decision was made for (a
    running campaign's tables and its file's say the same). Seed points are all committed before
    the first decision, so never in flight at a frame's end."""
    points, steps = tables.points, tables.steps
    done = {int(i) for i, after in zip(points.index, points.after) if after <= k}
    flying = [j for j in range(min(k, len(steps.step))) if n_seed + j not in done]
    names = steps.instrument if len(steps.instrument) == len(steps.step) else ("",) * len(steps.step)
    return {
        "x": np.asarray([steps.x[j] for j in flying], dtype=np.float64),
        "t": np.asarray([steps.t[j] for j in flying], dtype=np.float64),
        "index": np.asarray([n_seed + j for j in flying], dtype=np.int64),
        "instrument": tuple(str(names[j]) for j in flying),
    }


def _flying(in_flight: dict | None) -> str:
    if not in_flight or not len(in_flight["t"]):
        return ""
    return f"; in flight: {len(in_flight['t'])} point(s)"


def _points_until(points: Points, k: int) -> dict:
    keep = points.after <= k  # committed before decision k + 1 (one instrument: a point of step s is frame s's)
    out = {name: np.asarray(getattr(points, name))[keep] for name in POINT_FIELDS}
    out["frame"] = points.step[keep]
    return out


def _latest(points: dict) -> int | None:
    """The index of the last point committed of those shown."""
    return int(points["index"][-1]) if len(points["index"]) else None


def _measurement_time(shots: Shots, points: dict) -> float:
    """Total sweep/exposure time (s) of the shots of the points shown."""
    return float(np.sum(shots.t[np.isin(shots.point, points["index"])]))


def _reward(noise: Curve, config: CampaignConfig) -> Curve:
    r = config.reward
    return Curve(noise.grid, normalised_reward(noise.grid, noise.mean, r.alpha, r.beta), np.zeros_like(noise.grid))


def _final_frame(tables: CampaignTables, config: CampaignConfig, k: int, points: dict, scalars: dict) -> Frame:
    s, grid = tables.summary, tables.grid
    assert s is not None
    f = Curve(grid["x"], s.f_mean, np.sqrt(np.maximum(s.f_var, 0.0)))
    noise = Curve(grid["t_fine"], s.noise_fine, np.zeros_like(s.noise_fine))
    scalars = scalars | {"t_opt_s": s.t_opt}
    scalars |= {
        name: float(s.hyperparameters[f"noise.{name}"]) for name in ("a0", "a1") if f"noise.{name}" in s.hyperparameters
    }
    text = (
        f"final models on all {len(points['x'])} points: predicted optimal t {s.t_opt:.4g} s, "
        f"{scalars['measurement_time_s']:.1f} s of measurement"
    )
    return Frame(k, points, f, noise, _reward(noise, config), None, s.t_opt, None, scalars, text, None)
