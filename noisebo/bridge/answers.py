"""What the bridge answers, as models for its API description (``/openapi.json``, ``/docs`` and
the documentation's protocol page). The answers themselves are built as plain dicts by
``bridge.exchange`` and ``bridge.wire``; ``tests/noisebo/bridge/test_answers.py`` holds them to these
models, field for field."""

from __future__ import annotations

from typing import Literal, Union

from pydantic import BaseModel, ConfigDict, Field


class Answer(BaseModel):
    """An answer's shape: exactly these keys."""

    model_config = ConfigDict(extra="forbid")


class ShotRequest(Answer):
    """A shot to measure: measure at ``x`` for ``t`` seconds, then post the reading to
    ``/shots/{point}/{shot}``."""

    kind: Literal["shot"] = Field(description="a shot is wanted")
    campaign: str = Field(
        description="the campaign's id, NAME/POLICY/sSEED@START (UTC); copy it into the reading "
        "to have a reading for another campaign refused"
    )
    point: int = Field(description="the point's index in the campaign, from 0 (seed points first)")
    shot: int = Field(description="the shot's index within the point, from 0: the one to measure now")
    step: int = Field(description="the BO step that proposed the point, counted from 1; 0 for a seed point")
    x: list[float] = Field(
        description="the position: one coordinate per axis of `space.axes`, in that axis's "
        "`units` (the config's own units, not scaled)"
    )
    t: float = Field(description="the exposure or sweep time (s)")
    wanted: int = Field(
        description="the shots the point gets in all: shots 0 to wanted - 1; those from `shot` on are still to come"
    )
    attempt: int = Field(
        description="failed attempts at this shot so far (0: the first try); an error posted for this shot carries it"
    )
    seed: int = Field(description="the campaign's seed (with point and shot, it keys a simulator's random draws)")
    reading: Literal["scalar", "spectrum"] = Field(description="what to post: a value, or a spectrum")


class WaitAnswer(Answer):
    """Nothing is wanted yet (the campaign is starting or deciding): ask again."""

    kind: Literal["wait"] = Field(description="nothing to measure yet")


class DoneAnswer(Answer):
    """The campaign has ended: stop serving it."""

    kind: Literal["done"] = Field(description="the campaign has ended")
    campaign: str = Field(description="the campaign's id")
    status: str = Field(description="how it ended: completed, aborted, failed or budget_spent")
    reason: str = Field(description="why, in words (empty when it completed)")


NextAnswer = Union[ShotRequest, WaitAnswer, DoneAnswer]


class Recorded(Answer):
    """The reading is journaled: it counts, and posting it again changes nothing."""

    recorded: Literal[True] = Field(description="the reading (or the failed attempt) is in the campaign's journal")
    duplicate: bool = Field(description="true: it was journaled before, by an earlier post of the same reading")
    point: int = Field(description="the point it belongs to")
    shot: int = Field(description="the shot it belongs to")
    next: ShotRequest | None = Field(
        None, description="the next wanted shot, when one is wanted at once (saves a poll of /next); absent otherwise"
    )


class ErrorAnswer(Answer):
    """A refusal: nothing was recorded."""

    error: str = Field(description="what is wrong, in words")


class CurrentShot(Answer):
    """The shot being measured now."""

    point: int = Field(description="the point's index, from 0")
    step: int = Field(description="the BO step that proposed it, from 1; 0 for a seed point")
    shot: int = Field(description="the shot wanted now, from 0")
    shots_wanted: int = Field(description="the shots the point gets in all")
    x: list[float] = Field(description="the position, in the units of `space.axes`")
    t: float = Field(description="the exposure or sweep time (s)")


class LastPoint(Answer):
    """The last point committed."""

    x: list[float] = Field(description="its position, in the units of `space.axes`")
    t: float = Field(description="its exposure or sweep time (s)")
    value: float = Field(description="the mean of its shots, in the units of f")
    noise: float = Field(
        description="the single-shot noise sd it was given (measured or from the noise model), in the units of f"
    )
    shots: int = Field(description="its number of shots")


class InstrumentNoise(Answer):
    """Where one instrument's own noise law stands (``noise_model.per_instrument``)."""

    t_opt: float | None = Field(
        description="the predicted optimal t of the last decision made for it (s; null: none yet)"
    )
    converged_at_step: int | None = Field(
        description="the BO step, from 1, of the first decision for it that found its law converged (null: not yet)"
    )


class NoiseStanding(Answer):
    """Where the noise model stands."""

    t_opt: float | None = Field(description="the last decision's predicted optimal t (s; null before the first)")
    converged_at_step: int | None = Field(
        description="the BO step, from 1, at which the noise model converged (null: not yet)"
    )
    by_instrument: dict[str, InstrumentNoise] | None = Field(
        description="with a noise law per instrument, each instrument's, by name (null: one law)"
    )


class InstrumentPC(Answer):
    """What the bridge has heard from the instrument PC."""

    connected: bool = Field(description="it has called the API at least once")
    polling: bool = Field(description="a long poll of /next is open now")
    last_seen_s_ago: float | None = Field(description="seconds since its last call (null: never)")


class StatusAnswer(Answer):
    """The campaign's progress; before it starts, only ``status`` "starting" and ``campaign``
    null."""

    status: str = Field(description="starting, running, completed, aborted, failed or budget_spent")
    campaign: str | None = Field(description="the campaign's id (null while starting)")
    instrument: str | None = Field(
        None, description="the instrument this bridge serves, in a campaign of several (null: the campaign's one)"
    )
    reason: str | None = Field(None, description="why it ended, in words (empty while running)")
    points: int | None = Field(None, description="points committed")
    points_total: int | None = Field(None, description="points planned: seed points plus BO steps")
    shots: int | None = Field(None, description="shots taken")
    failed_attempts: int | None = Field(None, description="failed attempts at shots")
    now: Literal["waiting", "measuring", "deciding", "done"] | None = Field(
        None,
        description="what the campaign is doing: waiting (a shot is wanted and no instrument PC has "
        "connected yet), measuring (a shot is wanted from the connected instrument PC), deciding, done",
    )
    current: CurrentShot | None = Field(None, description="the shot wanted now (null unless waiting or measuring)")
    last_point: LastPoint | None = Field(None, description="the last committed point (null before the first)")
    noise_model: NoiseStanding | None = Field(None, description="the predicted optimal t and convergence")
    instrument_pc: InstrumentPC | None = Field(None, description="what the bridge has heard from the instrument PC")
