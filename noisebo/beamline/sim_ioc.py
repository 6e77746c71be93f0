"""An EPICS IOC (pythonSoftIOC) serving one of noisebo's simulators over Channel Access: a motor
per axis of x and a detector whose exposure sets the noise, for the bluesky path's tests, example
and benchmark.

    python -m noisebo.beamline.sim_ioc PREFIX: CONFIG [--velocity UNITS_PER_S]

serves, for the campaign config CONFIG's instrument (a simulator: Forrester, Branin, ...):

    PREFIX:M{i}          ao   axis i's setpoint; a put completes when the axis has arrived; its
                              DRVL, DRVH fields are the travel limits (the config's range, or
                              --limits), a setpoint beyond them held at the limit as EPICS does
    PREFIX:M{i}:RBV      ai   axis i's readback (moves at --velocity, units of x per s)
    PREFIX:EXPOSURE      ao   the exposure t (s)
    PREFIX:ACQUIRE       bo   put 1: expose for t and read; the put completes when the value is in
    PREFIX:VALUE         ai   the last shot's value (NaN where a shot is a spectrum)
    PREFIX:FREQUENCY, PREFIX:AMPLITUDE, PREFIX:PHASE   waveform (float32), for a simulator whose
                         shots are resonance sweeps (PFM): the last sweep's rows (Hz, pm, deg),
                         each as long as the longest sweep (t_max), NaN past the sweep's end
    PREFIX:SEED, PREFIX:POINT, PREFIX:SHOT   longout   the shot's random stream: with them set, a
                         shot is the one noisebo's own simulator draws for (seed, point, shot), so a
                         campaign through the IOC decides as ``noisebo run`` does. A real detector
                         has nothing like them.

With ``--plain`` the records have the shape of a common IOC that knows nothing of noisebo, for
the worked example of one's own devices (``examples/beamline/own_devices.py``): a put to
``PREFIX:M{i}`` or ``PREFIX:ACQUIRE`` completes at once, ``PREFIX:M{i}:DMOV`` (bi) is 0 while axis
i moves and 1 once it stands, ``PREFIX:ACQUIRE`` returns to 0 when the value is in, and there are
no SEED, POINT, SHOT records: each shot draws the next of the IOC's own random stream (``--seed``).

Channel Access stays on the addresses the environment names (EPICS_CAS_INTF_ADDR_LIST). The line
``NOISEBO_IOC_READY PREFIX`` on stdout says the records are served.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import os
import selectors
import signal
import subprocess
import sys
import threading
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

READY = "NOISEBO_IOC_READY"
STEP_S = 0.01  # the readback's update period while an axis moves


def serve(
    prefix: str,
    config_path: str,
    velocity: float,
    limits: tuple[float, float] | None = None,
    plain: bool = False,
    seed: int = 0,
) -> None:
    from softioc import asyncio_dispatcher, builder, softioc

    from noisebo.config import load_config
    from noisebo.instruments import build
    from noisebo.keys import MEASURE, numpy_rng

    config = load_config(config_path)
    simulator = build(config.instrument)
    if not callable(getattr(simulator, "simulate", None)):
        raise SystemExit(f"sim_ioc: {config.instrument.kind!r} is not a simulator (it has no simulate)")
    dispatcher = asyncio_dispatcher.AsyncioDispatcher()
    builder.SetDeviceName(prefix.removesuffix(":"))
    readbacks = [
        _axis(builder, i, axis.low, velocity, limits or (axis.low, axis.high), plain)
        for i, axis in enumerate(config.space.axes)
    ]
    exposure = builder.aOut("EXPOSURE", initial_value=config.space.t_min, PREC=6, EGU="s", DRVL=0.0)
    value = builder.aIn("VALUE", initial_value=math.nan, PREC=9)
    key = {} if plain else {name: builder.longOut(name, initial_value=0, DRVL=0) for name in ("SEED", "POINT", "SHOT")}
    shots_taken = [0]

    def shot_rng() -> np.random.Generator:
        if plain:  # the IOC's own stream, as a real detector's noise is its own
            shots_taken[0] += 1
            return numpy_rng(seed, MEASURE, shots_taken[0] - 1)
        return numpy_rng(int(key["SEED"].get()), MEASURE, int(key["POINT"].get()), int(key["SHOT"].get()))

    sweep = _longest_sweep(simulator, config)
    rows = [builder.WaveformIn(name, np.full(sweep, np.nan, np.float32)) for name in SPECTRUM] if sweep else []

    async def acquire_shot(start) -> None:
        if not start:
            return
        t = float(exposure.get())
        await asyncio.sleep(t)
        x = np.array([float(rb.get()) for rb in readbacks])
        reading = simulator.simulate(x, max(t, 1e-9), shot_rng())
        if reading.spectrum is None:
            value.set(float(reading.value))
        else:
            padded = np.full((len(SPECTRUM), sweep), np.nan, np.float32)
            padded[:, : reading.spectrum.shape[1]] = reading.spectrum[:, :sweep]
            for record, row in zip(rows, padded):
                record.set(row)
        acquire.set(0, process=plain)  # processed, so that monitors see it: a plain IOC's clients wait on them

    acquire = builder.boolOut(
        "ACQUIRE",
        initial_value=0,
        ZNAM="Idle",
        ONAM="Acquire",
        on_update=acquire_shot,
        always_update=True,
        blocking=not plain,
    )
    builder.LoadDatabase()
    softioc.iocInit(dispatcher, enable_pva=False)
    print(f"{READY} {prefix}", flush=True)
    softioc.non_interactive_ioc()


SPECTRUM = ("FREQUENCY", "AMPLITUDE", "PHASE")


def _longest_sweep(simulator, config) -> int:
    """The samples of the longest sweep (at t_max) of a simulator whose shots are spectra; 0 for
    one whose shots are values."""
    from noisebo.keys import MEASURE, numpy_rng

    x = np.array([axis.low for axis in config.space.axes])
    shot = simulator.simulate(x, config.space.t_max, numpy_rng(0, MEASURE, 0, 0))
    return 0 if shot.spectrum is None else int(shot.spectrum.shape[1])


def _axis(builder, index: int, start: float, velocity: float, limits: tuple[float, float], plain: bool):
    """Axis ``index``'s records; its readback. A newer setpoint takes over a move under way."""
    readback = builder.aIn(f"M{index}:RBV", initial_value=start, PREC=9)
    done = builder.boolIn(f"M{index}:DMOV", initial_value=1, ZNAM="Moving", ONAM="Done") if plain else None
    moves = [0]

    async def move(target) -> None:
        moves[0] += 1
        this = moves[0]
        if done is not None:
            done.set(0)
        position = float(readback.get())
        while abs(target - position) > 1e-12:
            position += math.copysign(min(abs(target - position), velocity * STEP_S), target - position)
            readback.set(position)
            await asyncio.sleep(STEP_S)
            if moves[0] != this:
                return
        readback.set(float(target))
        if done is not None:
            done.set(1)

    low, high = limits
    start = min(max(start, low), high)
    builder.aOut(
        f"M{index}",
        initial_value=start,
        PREC=9,
        DRVL=low,
        DRVH=high,
        on_update=move,
        always_update=True,
        blocking=not plain,
    )
    return readback


# Channel Access on loopback, and arrays up to 4 MB (a PFM sweep of 2 s is 80 kB; the default
# limit is 16 kB): the IOC and its clients need the same settings.
CA_ENVIRONMENT = {
    "EPICS_CA_ADDR_LIST": "127.0.0.1",
    "EPICS_CA_AUTO_ADDR_LIST": "NO",
    "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1",
    "EPICS_CA_MAX_ARRAY_BYTES": "4000000",
}


@dataclass(frozen=True)
class SimIoc:
    """A simulated IOC running in ``process``, serving its records under ``prefix``."""

    prefix: str
    process: subprocess.Popen


@contextmanager
def running_ioc(
    config: str | Path,
    prefix: str | None = None,
    velocity: float = 10.0,
    timeout_s: float = 60.0,
    limits: tuple[float, float] | None = None,
    plain: bool = False,
    seed: int = 0,
):
    """The simulated IOC for ``config`` in a process of its own, for as long as the ``with``
    lasts (a ``SimIoc``; ``prefix`` default a new one, "NB<8 hex digits>:"; ``limits``: every
    axis's travel limits, default the config's range; ``plain``: the records of a common IOC,
    with ``seed`` its own random stream's, as ``--plain`` serves them). Channel Access stays
    on loopback unless the environment names other addresses (``CA_ENVIRONMENT``). Run one at a time
    on a host: with searches sent to 127.0.0.1 alone, the last IOC to bind the server port
    answers them all."""
    prefix = prefix or f"NB{uuid.uuid4().hex[:8]}:"
    env = {**CA_ENVIRONMENT, **os.environ}
    command = [sys.executable, "-u", "-m", "noisebo.beamline.sim_ioc", prefix, str(config), "--velocity", str(velocity)]
    command += ["--parent", str(os.getpid())] + (["--limits", *map(str, limits)] if limits else [])
    command += ["--plain", "--seed", str(seed)] if plain else []
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_until_ready(process, prefix, timeout_s)
        yield SimIoc(prefix, process)
    finally:
        process.terminate()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        if process.stdout is not None:
            process.stdout.close()


def _wait_until_ready(process: subprocess.Popen, prefix: str, timeout_s: float) -> None:
    assert process.stdout is not None
    said: list[str] = []
    deadline = time.monotonic() + timeout_s
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline:
            if not selector.select(timeout=max(deadline - time.monotonic(), 0.0)):
                break
            line = process.stdout.readline()
            if line.startswith(f"{READY} {prefix}"):
                return
            if not line and process.poll() is not None:
                raise RuntimeError(f"the simulated IOC exited ({process.returncode}): {''.join(said[-20:]).strip()}")
            said.append(line)
    raise TimeoutError(f"the simulated IOC was not ready within {timeout_s:g} s: {''.join(said[-20:]).strip()}")


def _end_with(parent: int) -> None:
    """End this process (SIGTERM: the IOC exits cleanly) once ``parent`` is gone, so a killed
    campaign never leaves its IOC serving: at once on Linux (the kernel's parent-death signal),
    within half a second elsewhere (a thread that watches)."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="noisebo-ioc-parent", daemon=True).start()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m noisebo.beamline.sim_ioc", description=__doc__.splitlines()[0])
    parser.add_argument("prefix", help="the records' prefix, ending in a colon: NB1: serves NB1:M0, NB1:EXPOSURE, ...")
    parser.add_argument("config", help="a campaign config whose instrument is a simulator")
    parser.add_argument("--velocity", type=float, default=10.0, help="axis speed, units of x per s (default 10)")
    parser.add_argument("--limits", type=float, nargs=2, metavar=("LOW", "HIGH"), help="every axis's travel limits")
    parser.add_argument("--parent", type=int, help="end when this process ends (running_ioc passes its own)")
    parser.add_argument("--plain", action="store_true", help="the records of a common IOC: puts complete at once")
    parser.add_argument("--seed", type=int, default=0, help="with --plain: the seed of the IOC's own random stream")
    args = parser.parse_args(argv)
    if args.parent is not None:
        _end_with(args.parent)
    if not args.prefix.endswith(":") or len(args.prefix) < 2:
        parser.error(f"the prefix must end in a colon, as NB1: does; got {args.prefix!r}")
    if args.seed < 0:
        parser.error(f"--seed: a non-negative integer, got {args.seed}")
    serve(args.prefix, args.config, args.velocity, tuple(args.limits) if args.limits else None, args.plain, args.seed)


if __name__ == "__main__":
    main(sys.argv[1:])
