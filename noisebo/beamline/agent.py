"""noisebo as the optimizer of blop (and of bluesky-adaptive 1.x, blop under another name): blop's
``Optimizer`` protocol (``suggest``, ``ingest``, ``get_best_points``), its stopping criterion and
its failed trials, over one noisebo campaign and its journal.

    optimizer = NoiseboOptimizer(config, "runs/sample.h5", axes=[stage_x], exposure=det.exposure)
    outcomes = ReadOutcomes(det.value)
    RE.subscribe(outcomes.collect)
    problem = OptimizationProblem(optimizer, actuators=[stage_x, det.exposure], sensors=[det],
                                  evaluation_function=outcomes)
    RE(blop.plans.optimize(problem, iterations=None, n_points=30))

A suggestion is one shot of the point the campaign measures now: ``{"_id": "POINT/SHOT", <axis
name>: x_i, ..., <exposure name>: t}``; ``suggest(n)`` gives up to n of the point's shots still
wanted, so blop's acquisition (a list scan) takes them as one bluesky run. ``ingest`` journals the
outcomes in shot order (a missing or non-finite value is a failed attempt, taken again);
``should_stop`` makes the decisions that are due and says when the campaign has ended. The
journal and the HDF5 file are those of ``noisebo run``; a new optimizer on the same path continues
the campaign.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

from noisebo.beamline.plan import decide_due, open_campaign
from noisebo.campaign import engine
from noisebo.campaign.engine import EngineState
from noisebo.config import CampaignConfig
from noisebo.events import DecisionDue, Done, Request, ShotError
from noisebo.reduction import Reading

ID_KEY = "_id"


class NoiseboOptimizer:
    """blop's ``Optimizer`` over the campaign of ``config`` kept at ``path`` (see the module).
    ``axes``: the actuators (or their names) of x, in the order of ``space.axes``;
    ``exposure``: the actuator (or its name) that takes a shot's t in seconds; ``value``: the
    outcomes' key that holds a shot's value (default "value"); ``shot_key``: a simulated
    detector's (seed, point, shot) actuators, so a shot is the one noisebo's simulator draws."""

    def __init__(
        self,
        config: CampaignConfig,
        path: str | Path,
        *,
        axes: Sequence[Any],
        exposure: Any,
        value: Any = "value",
        seed: int = 0,
        shot_key: Sequence[Any] | None = None,
    ) -> None:
        if len(axes) != config.space.dimensions:
            raise ValueError(f"the config has {config.space.dimensions} axes of x; {len(axes)} actuators were given")
        self.axes = [_name(a) for a in axes]
        self.exposure = _name(exposure)
        self.value = _name(value)
        self.shot_key = None if shot_key is None else [_name(k) for k in shot_key]
        self.recorder, _ = open_campaign(config, Path(path), seed)

    @property
    def state(self) -> EngineState:
        return self.recorder.state

    def suggest(self, num_points: int | None = None) -> list[dict]:
        """Up to ``num_points`` (default 1) of the shots the point under way still wants; none
        once the campaign has ended."""
        step = self._due()
        if not isinstance(step, Request):
            return []
        return [self._suggestion(step, shot) for shot in list(step.shots)[: max(num_points or 1, 1)]]

    def ingest(self, points: Sequence[Mapping]) -> None:
        """Journal the outcomes of suggested shots, in shot order."""
        for outcome in sorted(points, key=lambda p: _shot_of(p[ID_KEY])):
            value = outcome.get(self.value)
            if value is None or not math.isfinite(float(value)):
                self._tell(outcome[ID_KEY], ShotError("instrument error", f"the outcome has no finite {self.value!r}"))
            else:
                self._tell(outcome[ID_KEY], Reading(float(value)))

    def register_failures(self, suggestions: Sequence[Mapping]) -> None:
        """blop's failed trials: each suggested shot a failed attempt, taken again."""
        for suggestion in sorted(suggestions, key=lambda s: _shot_of(s[ID_KEY])):
            self._tell(suggestion[ID_KEY], ShotError("instrument error", "the acquisition of the trial failed"))

    def should_stop(self) -> tuple[bool, str | None]:
        """Whether the campaign has ended (the decisions due are made first)."""
        step = self._due()
        if isinstance(step, Done):
            return True, f"the campaign {step.status.value}" + (f": {step.reason}" if step.reason else "")
        return False, None

    def get_best_points(self) -> list[tuple[Any, dict, dict]]:
        """The measured point with the best value (largest, or smallest where the config
        minimises): its id ("POINT"), x and t, and its value."""
        points = self.state.data.points
        if not points:
            return []
        pick = max if self.state.config.acquisition.maximize else min
        k = pick(range(len(points)), key=lambda i: points[i].value)
        best = points[k]
        where = dict(zip(self.axes, map(float, best.x))) | {self.exposure: float(best.t)}
        return [(str(k), where, {self.value: float(best.value)})]

    def close(self) -> None:
        self.recorder.close()

    def _due(self):
        """What the campaign wants next, after the decisions that are due."""
        while isinstance(step := engine.ask(self.state), DecisionDue):
            self.recorder.commit(self.state, decide_due(self.state))
        return step

    def _suggestion(self, step: Request, shot: int) -> dict:
        suggestion: dict = {ID_KEY: f"{step.point}/{shot}"}
        suggestion |= {name: float(x) for name, x in zip(self.axes, step.x)}
        suggestion[self.exposure] = float(step.t)
        if self.shot_key is not None:
            seed, point, index = self.shot_key
            suggestion |= {seed: self.state.seed, point: step.point, index: shot}
        return suggestion

    def _tell(self, trial: Any, outcome) -> None:
        point, shot = (int(part) for part in str(trial).split("/"))
        step = engine.ask(self.state)
        if not isinstance(step, Request) or (step.point, step.taken) != (point, shot):
            wanted = f"point {step.point}, shot {step.taken}" if isinstance(step, Request) else "no shot"
            raise ValueError(f"trial {trial!r} is not the shot the campaign wants now ({wanted})")
        self.recorder.commit(self.state, engine.tell(self.state, step, {shot: outcome}, decide_next=False).events)


class ReadOutcomes:
    """blop's evaluation function from the documents themselves (``collect`` subscribed to the RunEngine):
    each acquisition run's ``primary`` events, in the order its start document's
    ``blop_acquisition_order`` gives, as ``{"_id": ..., "value": <value's reading>}``."""

    def __init__(self, value: Any, key: str = "value") -> None:
        self.field, self.key = _name(value), key
        self._order: dict[str, list] = {}
        self._values: dict[str, list[float]] = {}
        self._streams: dict[str, tuple[str, str]] = {}

    def __call__(self, uid: str, suggestions: Sequence[Mapping]) -> list[dict]:
        """The outcomes of the acquisition run ``uid``; a suggestion it has no value for gets NaN
        (a failed attempt when ingested)."""
        order, values = self._order.get(uid, []), self._values.get(uid, [])
        return [{ID_KEY: trial, self.key: value} for trial, value in zip(order, values)] + [
            {ID_KEY: s[ID_KEY], self.key: math.nan} for s in suggestions if s[ID_KEY] not in order[: len(values)]
        ]

    def collect(self, name: str, doc: dict) -> None:
        """The RunEngine's subscriber: ``RE.subscribe(outcomes.collect)``."""
        if name == "start" and "blop_acquisition_order" in doc:
            self._order[doc["uid"]], self._values[doc["uid"]] = list(doc["blop_acquisition_order"]), []
        elif name == "descriptor" and doc["run_start"] in self._order:
            self._streams[doc["uid"]] = (doc["run_start"], doc["name"])
        elif name == "event" and self._streams.get(doc["descriptor"], ("", ""))[1] == "primary":
            self._values[self._streams[doc["descriptor"]][0]].append(float(doc["data"][self.field]))


def _name(thing: Any) -> str:
    return thing if isinstance(thing, str) else str(thing.name)


def _shot_of(trial: Any) -> int:
    return int(str(trial).split("/")[1])
