"""Compile-ahead, in one place: a decision's programs compiled (or loaded from the persistent
cache) in a background thread while the instrument measures, first for the campaign's first
decision on stand-in seed points, then for the next padding capacity as a training set nears
its own. A decision that needs programs being compiled waits for them rather than compile the
same programs at the same time."""

from __future__ import annotations

import threading

import jax

from noisebo.acquisition.method import Method
from noisebo.campaign import background
from noisebo.acquisition.proposal import _propose_nd, propose_key, shot_choices
from noisebo.acquisition.records import Decision
from noisebo.campaign.steps import seed_points
from noisebo.config import CampaignConfig
from noisebo.models.fitting import capacities_needed, fit_key, fit_models
from noisebo.models.inputs import capacity_for
from noisebo.models.prediction import predict
from noisebo.state import CampaignState, Point
from noisebo.precision import float64


def stand_in_seeds(config: CampaignConfig, seed: int) -> CampaignState:
    """The campaign's seed points with stand-in readings (value = index, noise 1): a state of the
    shapes its first decision works on, before anything is measured."""
    shots = config.schedule.seed_shots
    points = tuple(
        Point(tuple(row[:-1]), float(row[-1]), float(i), 1.0, shots, 1.0, True)
        for i, row in enumerate(seed_points(config, seed))
    )
    return CampaignState(points=points)


@float64
def compile_first_decision(config: CampaignConfig, seed: int) -> None:
    """Compile (or load from the persistent cache) the programs of the campaign's first decision
    on stand-in seed points, so the real one need not: for a thread started while Prefect and
    the instrument start up. MAP mode only (NUTS samplers are per thread)."""
    if not config.inference.method.compiles_ahead:
        return
    state = stand_in_seeds(config, seed)
    compile_ahead(config, state, None, capacities_needed(config, state))


AHEAD_FILL = 0.75  # compile the next capacity once a training set fills this much of its own


def capacities_ahead(config: CampaignConfig, decision: Decision) -> tuple[int, int] | None:
    """The (primary, noise) capacities a campaign is about to need after ``decision``: a
    training set past ``AHEAD_FILL`` of its capacity will soon cross into the next (never beyond
    what ``inference.max_inputs`` needs for each). None when neither is close."""
    inf = config.inference

    def ahead(n: int, axes: int) -> int:
        capacity = capacity_for(n)
        return min(2 * capacity, capacity_for(inf.max_inputs_for(axes))) if n >= AHEAD_FILL * capacity else capacity

    now = (capacity_for(decision.primary_inputs), capacity_for(decision.noise_inputs))
    wanted = (ahead(decision.primary_inputs, config.space.dimensions), ahead(decision.noise_inputs, 1))
    return wanted if wanted != now else None


# Compilations under way in other threads, by programs and capacities: a decision that needs one
# waits for it instead of compiling the same programs at the same time (JAX would do both).
_COMPILING: dict[tuple, threading.Event] = {}


_COMPILING_LOCK = threading.Lock()


def programs_key(config: CampaignConfig, capacities: tuple[int, int] | None) -> tuple:
    """What identifies a decision's compiled programs: the config sections they depend on and
    the padded capacities."""
    return (
        config.primary_model,
        config.noise_model,
        config.inference,
        config.space,
        config.reward,
        config.acquisition,
        None if capacities is None else tuple(capacities),
    )


@float64
def compile_ahead(
    config: CampaignConfig, state: CampaignState, previous: dict | None, capacities: tuple[int, int]
) -> None:
    """Run a decision's programs (a multi-start fit and the prediction) at ``capacities`` and
    discard the results: JAX keeps them compiled for when the campaign crosses there. Meant for
    a background thread while the instrument measures (MAP mode; NUTS samplers are per thread);
    a ``decide`` that needs these capacities meanwhile waits for it."""
    key, done = programs_key(config, capacities), threading.Event()
    with _COMPILING_LOCK:
        _COMPILING.setdefault(key, done)
    try:
        method = Method.of(config)
        fitted = fit_models(config, method.noise_law, state, fit_key(0, 0), previous, False, capacities)
        posterior = predict(config, method.noise_law, fitted, state, method.policy.uses_spread).posterior
        jax.block_until_ready(posterior)
        if config.space.dimensions > 1:  # the refinement's program depends on the capacity too
            # one program per number of shot counts: a policy that chooses them has two, before
            # and after the noise model converges
            chooses = method.policy.chooses_shots
            for converged in (False, True) if chooses else (False,):
                choices = shot_choices(config, method.policy, converged, None)
                _propose_nd(config, method, fitted, posterior, propose_key(0, 0), choices)
    finally:
        done.set()
        with _COMPILING_LOCK:
            if _COMPILING.get(key) is done:
                del _COMPILING[key]


def wait_for_compilation(config: CampaignConfig, state: CampaignState) -> None:
    with _COMPILING_LOCK:
        if not _COMPILING:
            return
        done = _COMPILING.get(programs_key(config, capacities_needed(config, state)))
    if done is not None:
        done.wait()


class CompileAhead:
    """Compiles the decision programs of the next padding capacity in a background thread once a
    campaign's training set nears it (``decision.capacities_ahead``), so crossing a capacity costs
    no compilation in the decision itself (one that comes first waits for the thread rather than
    compile the same programs again). One thread at a time; each capacity once per process."""

    _done: set = set()
    _lock = threading.Lock()

    def __init__(self) -> None:
        self._thread: threading.Thread | None = None

    def after(self, state) -> None:
        """Start compiling ahead for ``state`` (the engine's ``EngineState``) if its latest decision
        says a crossing is near, or, before the first decision, that decision's programs (on
        stand-in seed points) while the seed points are measured."""
        config = state.config
        if not config.inference.method.compiles_ahead or self.busy:
            return
        if not state.decisions:
            self._start(config, None, lambda: compile_first_decision(config, state.seed))
            return
        capacities = capacities_ahead(config, state.decisions[-1])
        if capacities is not None:
            args = (config, state.data, state.decisions[-1].hyperparameters, capacities)
            self._start(config, capacities, lambda: compile_ahead(*args))

    def _start(self, config, capacities, work) -> None:
        key = programs_key(config, capacities)
        with self._lock:
            if key in self._done:
                return
            self._done.add(key)
        # Not a daemon: a thread inside an XLA compilation as the interpreter exits aborts the
        # process; ``drive`` joins it before returning, or leaves it (``leave``) on a stop.
        self._thread = threading.Thread(target=_quietly, args=(work,), name="noisebo-compile-ahead")
        self._thread.start()

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def join(self) -> None:
        if self._thread is not None:
            self._thread.join()

    def leave(self) -> None:
        """Stop waiting for this compilation: the campaign has stopped. The interpreter still
        joins the thread as it exits; a command that must end at once asks
        ``background.still_running`` and ends the process without it once its files are closed."""
        if self._thread is not None and self._thread.is_alive():
            background.leave(self._thread)


def _quietly(work) -> None:
    # Compiling ahead only saves time later: if it fails, the decision compiles in line and any
    # real problem surfaces there, in the decision itself.
    try:
        work()
    except Exception:  # noqa: BLE001
        pass
