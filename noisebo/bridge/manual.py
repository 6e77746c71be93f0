"""A campaign measured by hand: ``noisebo ask FILE`` and ``noisebo tell FILE ...`` step the same
engine over the same journal as every other driver, one command at a time.

Each call takes the journal's lock (a campaign being run elsewhere is refused), replays it,
commits what it adds (journal first, then the HDF5 file) and lets go.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from noisebo.bridge.wire import ReadingShape, WireError, campaign_id, request_json, spectrum_of
from noisebo.campaign import engine
from noisebo.campaign.engine import EngineState
from noisebo.events import DecisionDue, Done, Event, Request, ShotError, Wait
from noisebo.reduction import Reading
from noisebo.storage.recorder import Recorder

Say = Callable[[str], None]


class ManualError(ValueError):
    """A reading or request that does not fit where the campaign stands; the message says why."""


def reading_shape(state: EngineState) -> ReadingShape:
    """What this campaign's readings look like: the "shape" of a remote or manual instrument's
    settings, else a spectrum for a driver that returns spectra, else one number."""
    from noisebo.instruments.registry import description

    settings = state.config.instrument.settings
    if "shape" in settings:
        return ReadingShape.model_validate(settings["shape"])
    spectra = description(state.config.instrument.kind).spectra
    return ReadingShape(reading="spectrum" if spectra else "scalar")


def next_step(recorder: Recorder, say: Say, commit: Callable | None = None) -> Request | Done:
    """The campaign's next request, making (and journaling) any decision that is due first."""
    commit = commit or recorder.commit
    while True:
        step = engine.ask(recorder.state)
        assert not isinstance(step, Wait)  # one instrument: nothing waits
        if not isinstance(step, DecisionDue):
            return step
        if not step.reduce:
            say(
                "deciding the final summary"
                if step.final
                else f"deciding step {step.step + 1} (the first decision on this machine compiles the models, about 10 s)"
            )
        commit(recorder.state, engine.advance(recorder.state))


def ask(path: Path, say: Say, resume: bool = False) -> tuple[EngineState, Request | Done]:
    """The next request of the campaign in ``path`` (its status first set back to running with
    ``resume``)."""
    with Recorder.attach(path) as recorder:
        if resume:
            recorder.commit(recorder.state, engine.resumed(recorder.state))
        return recorder.state, next_step(recorder, say)


def tell(
    path: Path,
    point: int | None,
    outcomes_for: Callable[[ReadingShape], Sequence[Reading | ShotError]],
    say: Say,
    on_events: Callable[[EngineState, Sequence[Event]], None] = lambda state, events: None,
) -> tuple[EngineState, Request | Done, int]:
    """Record the outcomes that ``outcomes_for(the campaign's reading shape)`` gives for the next
    wanted shots of the point being measured (``point``, when given, must be it), then make any
    decision that falls due; returns the state, the next request and the number recorded.
    ``ManualError`` before anything is recorded when they do not fit."""
    with Recorder.attach(path) as recorder:

        def commit(state, events):
            on_events(state, events)
            return recorder.commit(state, events)

        outcomes = outcomes_for(reading_shape(recorder.state))
        request = next_step(recorder, say, commit)
        if isinstance(request, Done):
            raise ManualError(
                f"the campaign has ended ({request.status.value}"
                + (f": {request.reason}" if request.reason else "")
                + "); nothing is wanted"
            )
        if point is not None and point != request.point:
            raise ManualError(f"--point {point}: {_not_under_way(point, request.point)}")
        left = request.wanted - request.taken
        if not outcomes or len(outcomes) > left:
            raise ManualError(
                f"point {request.point} wants {left} more shot{'s' * (left != 1)} "
                f"(shots {request.taken}-{request.wanted - 1}); got {len(outcomes)}"
            )
        for outcome in outcomes:
            step = engine.ask(recorder.state)
            if not isinstance(step, Request):
                break
            commit(recorder.state, engine.tell(recorder.state, step, {step.taken: outcome}, decide_next=False).events)
        return recorder.state, next_step(recorder, say, commit), len(outcomes)


def _not_under_way(point: int, measured: int) -> str:
    if point < measured:
        return f"point {point} is finished (its shots are all recorded); the point being measured is {measured}"
    return f"point {point} has not been asked for yet; the point being measured is {measured}"


def parse_values(texts: Sequence[str], shape: ReadingShape) -> list[Reading]:
    """Numbers from the command line as scalar readings; ``ManualError`` naming a bad one."""
    if shape.reading != "scalar":
        raise ManualError("this campaign's readings are spectra: give them with --spectrum FILE")
    out = []
    for text in _after_options_end(texts):
        try:
            value = float(text)
        except ValueError:
            raise ManualError(f"{text!r} is not a number") from None
        if not np.isfinite(value):
            raise ManualError(f"{text!r} is not a finite number; record a failed shot with --error REASON")
        out.append(Reading(value))
    return out


def _after_options_end(texts: Sequence[str]) -> Sequence[str]:
    """The values without the ``--`` that ends the options (``tell FILE --point 2 -- -0.5``), which
    argparse keeps among them."""
    texts = list(texts)
    if "--" in texts:
        texts.remove("--")
    return texts


def load_spectrum(path: Path, shape: ReadingShape, reduction: str | None) -> Reading:
    """One shot's spectrum from a file: .npy holds rows × samples; .csv/.txt one sample per line
    (frequency, amplitude[, phase] columns, comma- or space-separated, # comments)."""
    path = Path(path)
    if shape.reading != "spectrum":
        raise ManualError("this campaign's readings are numbers: give them as values, not --spectrum")
    try:
        if path.suffix == ".npy":
            rows = np.load(path, allow_pickle=False)
        else:
            text = path.read_text()
            rows = np.loadtxt(text.splitlines(), delimiter="," if "," in text else None, ndmin=2).T
    except (OSError, ValueError) as error:
        raise ManualError(f"{path}: cannot read a spectrum: {error}") from None
    if rows.ndim != 2:
        raise ManualError(f"{path}: a spectrum is rows × samples, got an array of shape {rows.shape}")
    try:
        return Reading(None, spectrum_of(rows.tolist(), shape), reduction or shape.reduction)
    except WireError as error:
        raise ManualError(f"{path}: {error}") from None


def describe(state: EngineState, step: Request | Done, path: Path) -> list[str]:
    """What a person is told to do next."""
    if isinstance(step, Done):
        return [f"the campaign has ended: {step.status.value}" + (f" ({step.reason})" if step.reason else "")]
    n_steps = state.config.schedule.n_steps
    label = "seed point" if step.step < 0 else f"BO step {step.step + 1}/{n_steps}"
    where = ", ".join(f"{v:.6g}" for v in step.x)
    left, last = step.wanted - step.taken, step.wanted - 1
    shots = f"1 more shot (shot {last})" if left == 1 else f"{left} more shots (shots {step.taken}-{last})"
    readings = "VALUE..." if reading_shape(state).reading == "scalar" else "--spectrum FILE..."
    return [
        f"point {step.point} ({label}): measure at x = {where} for t = {step.t:.6g} s; {shots}",
        f"then: noisebo tell {path} --point {step.point} {readings}",
    ]


def as_json(state: EngineState, step: Request | Done) -> dict:
    """The same request as the bridge serves (see ``bridge.wire``)."""
    if isinstance(step, Done):
        return {"kind": "done", "campaign": campaign_id(state), "status": step.status.value, "reason": step.reason}
    return request_json(state, step, reading_shape(state))
