"""Typed campaign events (``noisebo.events``) to journal records and back, losslessly.

Record types, one per event: campaign (Started), decision (Decided), shot (ShotTaken), failure
(ShotFailed), more_shots (MoreShots), point (PointCommitted), issued (PointIssued), summary
(Summarised), status (StatusChanged), budget (BudgetChanged), wall_budget (WallBudgetChanged)
and clock (Clocked). Scalars
travel in the record's JSON fields, arrays (spectra, model outputs) as raw arrays.
"""

from __future__ import annotations

from dataclasses import asdict, fields

import numpy as np

from noisebo.acquisition.records import Decision
from noisebo.campaign.engine import EngineError, EngineState, replay
from noisebo.config import parse_config
from noisebo.events import (
    BudgetChanged,
    Clocked,
    WallBudgetChanged,
    Decided,
    DriverInfo,
    Event,
    MoreShots,
    PointCommitted,
    PointIssued,
    ShotFailed,
    ShotTaken,
    Started,
    Status,
    StatusChanged,
    Summarised,
    Summary,
)
from noisebo.reduction import Reading, ShotValue
from noisebo.sho import SHOFit
from noisebo.state import Point
from noisebo.storage.journal import Record

FIT_NUMBERS = ("amplitude", "amplitude_se", "resonance_hz", "resonance_se", "q", "q_se", "phase_deg", "sign")
DECISION_ARRAYS = ("acq_map", "f_mean", "f_var", "noise_mean", "noise_var", "t_opt_map")
SUMMARY_ARRAYS = ("f_mean", "f_var", "noise_fine", "t_opt_map", "noise_map")
FIELD_ARRAYS = ("t_opt_map", "noise_map")  # a noise field's, empty without one (and in older journals)
POINT_FIELDS = tuple(f.name for f in fields(Point))


class CorruptJournal(ValueError):
    """Records that do not form a campaign."""


def encode(event: Event) -> Record:
    """The journal record of one event."""
    if isinstance(event, Started):
        return Record(
            "campaign",
            {
                "config": event.config.model_dump(mode="json"),
                "seed": event.seed,
                "driver": asdict(event.driver),
                "versions": event.versions,
                "created_utc": event.created_utc,
            },
        )
    if isinstance(event, ShotTaken):
        r = event.reading
        value = None if r.value is None else float(r.value)
        fields_ = {"point": event.point, "shot": event.shot, "x": list(event.x), "t": event.t, "value": value}
        if r.reduction is not None:
            fields_["reduction"] = r.reduction
        if event.instrument:
            fields_["instrument"] = event.instrument
        return Record("shot", fields_, {} if r.spectrum is None else {"spectrum": np.asarray(r.spectrum)})
    if isinstance(event, ShotFailed):
        failed = {k: v for k, v in asdict(event).items() if k != "instrument" or v}
        return Record("failure", failed | {"x": list(event.x)})
    if isinstance(event, MoreShots):
        return Record("more_shots", asdict(event))
    if isinstance(event, PointIssued):
        return Record("issued", asdict(event))
    if isinstance(event, PointCommitted):
        return _encode_point(event)
    if isinstance(event, Decided):
        d = event.decision
        scalars = {k: getattr(d, k) for k in (f.name for f in fields(Decision)) if k not in DECISION_ARRAYS}
        return Record("decision", scalars, {k: np.asarray(getattr(d, k)) for k in DECISION_ARRAYS})
    if isinstance(event, Summarised):
        s = event.summary
        return Record(
            "summary",
            {"t_opt": s.t_opt, "hyperparameters": s.hyperparameters},
            {k: np.asarray(getattr(s, k)) for k in SUMMARY_ARRAYS},
        )
    if isinstance(event, StatusChanged):
        return Record("status", {"status": event.status.value, "reason": event.reason})
    if isinstance(event, BudgetChanged):
        return Record("budget", {"budget_s": event.budget_s})
    if isinstance(event, Clocked):
        return Record("clock", {"wall_s": event.wall_s})
    if isinstance(event, WallBudgetChanged):
        return Record("wall_budget", {"wall_budget_s": event.wall_budget_s})
    raise TypeError(f"not a campaign event: {type(event).__name__}")


def _encode_point(event: PointCommitted) -> Record:
    values = event.values
    fields_ = {
        "index": event.index,
        "step": event.step,
        **asdict(event.point),
        "shot_ok": [bool(v.ok) for v in values],
        "shot_reason": [v.reason for v in values],
        "fit_reason": [v.fit.reason if v.fit is not None else "" for v in values],
        "fit_ok": [bool(v.fit.ok) if v.fit is not None else False for v in values],
    }
    arrays = {"shot_value": np.asarray([v.value for v in values], dtype=np.float64)}
    if any(v.fit is not None for v in values):
        fits = [
            [np.nan] * len(FIT_NUMBERS) if v.fit is None else [float(getattr(v.fit, k)) for k in FIT_NUMBERS]
            for v in values
        ]
        arrays["shot_fit"] = np.asarray(fits, dtype=np.float64).reshape(-1, len(FIT_NUMBERS))
        arrays["shot_has_fit"] = np.asarray([v.fit is not None for v in values])
    return Record("point", fields_, arrays)


def _decode_point(f: dict, arrays: dict) -> PointCommitted:
    n = len(f["shot_ok"])
    has_fit = arrays.get("shot_has_fit", np.zeros(n, dtype=bool))
    values = []
    for k in range(n):
        fit = None
        if bool(has_fit[k]):
            numbers = dict(zip(FIT_NUMBERS, (float(v) for v in arrays["shot_fit"][k])))
            fit = SHOFit(
                value=numbers["sign"] * numbers["amplitude"], ok=f["fit_ok"][k], reason=f["fit_reason"][k], **numbers
            )
        values.append(ShotValue(float(arrays["shot_value"][k]), f["shot_ok"][k], f["shot_reason"][k], fit))
    point = Point(**{k: f[k] for k in POINT_FIELDS})
    return PointCommitted(f["index"], f["step"], point, tuple(values))


def _arrays(arrays: dict, names: tuple[str, ...]) -> dict:
    """The named arrays of a record; a noise field's (FIELD_ARRAYS) empty where it has none."""
    return {k: arrays[k] if k in arrays or k not in FIELD_ARRAYS else np.zeros(0) for k in names}


def decode(record: Record) -> Event:
    """The event of one journal record; ``CorruptJournal`` for a record that is not one."""
    f, a = record.fields, record.arrays
    try:
        if record.type == "campaign":
            driver = DriverInfo(**f["driver"])
            return Started(
                parse_config(f["config"], "journal", load_plugins=False),
                f["seed"],
                driver,
                f["versions"],
                f["created_utc"],
            )
        if record.type == "shot":
            reading = Reading(f["value"], a.get("spectrum"), f.get("reduction"))
            return ShotTaken(f["point"], f["shot"], tuple(f["x"]), f["t"], reading, str(f.get("instrument", "")))
        if record.type == "failure":
            instrument = str(f.get("instrument", ""))
            return ShotFailed(f["point"], f["shot"], tuple(f["x"]), f["t"], f["kind"], f["reason"], instrument)
        if record.type == "more_shots":
            return MoreShots(**f)
        if record.type == "issued":
            return PointIssued(int(f["point"]), str(f["instrument"]), str(f["reason"]))
        if record.type == "point":
            return _decode_point(f, a)
        if record.type == "decision":
            return Decided(Decision(**f, **_arrays(a, DECISION_ARRAYS)))
        if record.type == "summary":
            return Summarised(
                Summary(t_opt=f["t_opt"], hyperparameters=f["hyperparameters"], **_arrays(a, SUMMARY_ARRAYS))
            )
        if record.type == "status":
            return StatusChanged(Status(f["status"]), f["reason"])
        if record.type == "budget":
            return BudgetChanged(None if f["budget_s"] is None else float(f["budget_s"]))
        if record.type == "clock":
            return Clocked(_finite_seconds(f["wall_s"]))
        if record.type == "wall_budget":
            return WallBudgetChanged(None if f["wall_budget_s"] is None else _finite_seconds(f["wall_budget_s"]))
    except (KeyError, TypeError, ValueError) as error:
        raise CorruptJournal(f"a {record.type!r} record that is not one ({type(error).__name__}: {error})") from None
    raise CorruptJournal(f"unknown record type {record.type!r}")


def rebuild(records: list[Record]) -> EngineState:
    """The campaign a journal's records describe, checking their order."""
    if not records or records[0].type != "campaign":
        raise CorruptJournal("the journal does not start with a campaign record")
    try:
        return replay([decode(r) for r in records])
    except EngineError as error:
        raise CorruptJournal(str(error)) from None


def _finite_seconds(value) -> float:
    """A clock record's wall time: a finite number of seconds, at least 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < float("inf"):
        raise ValueError(f"wall_s {value!r} is not a wall time in seconds")
    return float(value)
