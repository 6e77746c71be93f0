"""Campaign events as journal records, and the campaign rebuilt from them (pure; no file I/O).

Record types, in the order a campaign writes them:
    campaign  config, seed, versions, start time (first record, once)
    decision  one BO step's proposal and model outputs (before its shots)
    shot      one shot: point index, shot index, x, t, value
    failure   a failed attempt at a shot (instrument error, timeout): point, shot, x, t, reason
    point     a point reduced from its shots: commits the point
    summary   the final models after the last point
    status    running / completed / aborted / failed, with a reason
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from noisebo.config import CampaignConfig, parse_config
from noisebo.reduction import Reading
from noisebo.state import CampaignState, Point
from noisebo.storage.journal import Record


def campaign_record(config: CampaignConfig, seed: int, versions: dict, created_utc: str) -> Record:
    return Record("campaign", {"config": config.model_dump(mode="json"), "seed": int(seed),
                               "versions": versions, "created_utc": created_utc})


def decision_record(decision, latency_s: float) -> Record:
    post = decision.prediction.posterior
    fields = {
        "step": decision.step, "x": decision.x, "t": decision.t, "acq_value": decision.acq_value,
        "shots": decision.shots, "measure_noise": decision.measure_noise, "noise_at_t": decision.noise_at_t,
        "t_opt": decision.t_opt, "converged": decision.converged, "hyperparameters": decision.hyperparameters,
        "latency_s": float(latency_s),
    }
    arrays = {
        "acq_map": np.asarray(decision.acq_map, dtype=np.float32),
        "f_mean": np.asarray(post.f_mean, dtype=np.float64),
        "f_var": np.asarray(post.f_var, dtype=np.float64),
        "noise_mean": np.asarray(post.noise_mean, dtype=np.float64),
        "noise_var": np.asarray(post.noise_var, dtype=np.float64),
    }
    return Record("decision", fields, arrays)


def shot_record(point: int, shot: int, x: float, t: float, reading) -> Record:
    """One raw shot: its scalar value (None for a spectrum, which is fitted at reduction) and
    its spectrum, if any, as an array."""
    value = None if reading.value is None else float(reading.value)
    fields = {"point": int(point), "shot": int(shot), "x": float(x), "t": float(t), "value": value}
    arrays = {} if reading.spectrum is None else {"spectrum": np.asarray(reading.spectrum)}
    return Record("shot", fields, arrays)


def failure_record(point: int, shot: int, x: float, t: float, error: BaseException) -> Record:
    kind = "timeout" if type(error).__name__ == "InstrumentTimeout" else "instrument error"
    return Record("failure", {"point": int(point), "shot": int(shot), "x": float(x), "t": float(t), "kind": kind,
                              "reason": str(error)})


def point_record(index: int, step: int, point: Point, shots=()) -> Record:
    """A committed point with each shot's reduced value, status and (for spectra) SHO fit."""
    fields = {
        "index": int(index), "step": int(step), **asdict(point),
        "shot_ok": [bool(v.ok) for v in shots], "shot_reason": [v.reason for v in shots],
        "fit_reason": [v.fit.reason if v.fit is not None else "" for v in shots],
    }
    arrays = {"shot_value": np.asarray([v.value for v in shots], dtype=np.float64)}
    if any(v.fit is not None for v in shots):
        arrays["shot_fit"] = np.asarray([_fit_numbers(v.fit) for v in shots], dtype=np.float64).reshape(-1, len(FIT_NUMBERS))
    return Record("point", fields, arrays)


FIT_NUMBERS = ("amplitude", "amplitude_se", "resonance_hz", "resonance_se", "q", "q_se", "phase_deg", "sign")


def _fit_numbers(fit) -> list[float]:
    return [float("nan")] * len(FIT_NUMBERS) if fit is None else [float(getattr(fit, k)) for k in FIT_NUMBERS]


def summary_record(summary) -> Record:
    return Record(
        "summary",
        {"t_opt": summary.t_opt, "hyperparameters": summary.hyperparameters},
        {"f_mean": summary.f_mean, "f_var": summary.f_var, "noise_fine": summary.noise_fine},
    )


def status_record(status: str, reason: str = "") -> Record:
    return Record("status", {"status": status, "reason": reason})


@dataclass
class Progress:
    """A campaign as far as its journal goes.

    ``state`` holds the committed points; ``decisions`` every recorded decision (fields and
    arrays); ``shots[i]`` the journaled readings of point i; ``shot_rows`` one dict per shot
    (raw fields, then its reduced value, status and fit once its point is committed); ``pending`` the decision of a BO
    step whose point is not committed yet (None if there is none)."""

    config: CampaignConfig
    seed: int
    versions: dict
    created_utc: str
    state: CampaignState = field(default_factory=CampaignState)
    decisions: list[Record] = field(default_factory=list)
    shots: dict[int, list] = field(default_factory=dict)
    shot_rows: list[dict] = field(default_factory=list)
    point_steps: list[int] = field(default_factory=list)
    summary: Record | None = None
    status: str = "running"
    reason: str = ""
    failures: list[dict] = field(default_factory=list)

    def failure_counts(self) -> tuple[int, int]:
        """(failed, attempted) shots so far: failed attempts plus rejected shots, of all attempts."""
        rejected = sum(1 for r in self.shot_rows if "reduced" in r and not r.get("ok", False))
        return len(self.failures) + rejected, len(self.failures) + len(self.shot_rows)

    @property
    def pending(self) -> Record | None:
        n_bo_points = sum(1 for s in self.point_steps if s >= 0)
        return self.decisions[-1] if len(self.decisions) > n_bo_points else None

    @property
    def next_step(self) -> int:
        """The BO step to decide next."""
        return len(self.decisions)


POINT_FIELDS = tuple(Point.__dataclass_fields__)


def _commit_shots(progress: Progress, fields: dict, arrays: dict) -> None:
    """Attach each shot's reduced value, status and fit to its row."""
    taken = len(progress.shots.get(fields["index"], []))
    rows = progress.shot_rows[len(progress.shot_rows) - taken:]  # a point's shots are the latest rows
    values = arrays.get("shot_value", np.full(len(rows), np.nan))
    fits = arrays.get("shot_fit")
    for k, row in enumerate(rows):
        if k >= len(values):
            break
        row.update(reduced=float(values[k]), ok=fields.get("shot_ok", [True] * len(rows))[k],
                   reason=fields.get("shot_reason", [""] * len(rows))[k],
                   fit_reason=fields.get("fit_reason", [""] * len(rows))[k])
        if fits is not None:
            row.update(zip(FIT_NUMBERS, (float(v) for v in fits[k])))


class CorruptJournal(ValueError):
    """Records that do not form a campaign."""


def replay(records: list[Record]) -> Progress:
    """Rebuild a campaign's progress from its records, checking their order."""
    if not records or records[0].type != "campaign":
        raise CorruptJournal("the journal does not start with a campaign record")
    head = records[0].fields
    progress = Progress(parse_config(head["config"], "journal"), head["seed"], head["versions"], head["created_utc"])
    for record in records[1:]:
        progress = replay_one(progress, record)
    return progress


def replay_one(progress: Progress, record: Record) -> Progress:
    """Apply one record to ``progress`` (in place) and return it; raise on a record out of order."""
    f = record.fields
    if record.type == "decision":
        if f["step"] != progress.next_step or progress.pending is not None:
            raise CorruptJournal(f"decision for step {f['step']} out of order")
        progress.decisions.append(record)
        progress.state = progress.state.with_t_opt(f["t_opt"], f["converged"])
    elif record.type == "shot":
        shots = progress.shots.setdefault(f["point"], [])
        if f["point"] != len(progress.state.points) or f["shot"] != len(shots):
            raise CorruptJournal(f"shot {f['shot']} of point {f['point']} out of order")
        shots.append(Reading(f["value"], record.arrays.get("spectrum")))
        progress.shot_rows.append(dict(f))
    elif record.type == "point":
        if f["index"] != len(progress.state.points):
            raise CorruptJournal(f"point {f['index']} out of order")
        fields = {k: v for k, v in f.items() if k in POINT_FIELDS}
        progress.state = progress.state.with_point(Point(**fields))
        _commit_shots(progress, f, record.arrays)
        progress.point_steps.append(f["step"])
    elif record.type == "failure":
        if f["point"] != len(progress.state.points) or f["shot"] != len(progress.shots.get(f["point"], [])):
            raise CorruptJournal(f"failure at shot {f['shot']} of point {f['point']} out of order")
        progress.failures.append(dict(f))
    elif record.type == "summary":
        progress.summary = record
    elif record.type == "status":
        progress.status, progress.reason = f["status"], f["reason"]
    elif record.type == "campaign":
        raise CorruptJournal("a second campaign record")
    else:
        raise CorruptJournal(f"unknown record type {record.type!r}")
    return progress
