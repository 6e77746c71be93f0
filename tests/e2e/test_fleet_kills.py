"""Three instrument PCs on one campaign, each through a bridge of its own with its own token: one
instrument PC killed (SIGKILL) and started again, then the campaign itself killed and resumed
with `noisebo resume`; the campaign completes with every shot once, each with its instrument and
with the reading its (seed, point, shot) stream gives."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from noisebo.campaign.driver import take_shot
from noisebo.config import load_config
from noisebo.events import PointIssued, Request, ShotTaken
from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.storage import event_codec, journal
from tests.noisebo.bridge.kills import OVERRIDES, SOURCE, free_port, wait_for_length

pytestmark = pytest.mark.e2e
NAMES = ("north", "east", "south")
PACE = 0.3  # a shot of t seconds takes 0.3 t s: points overlap in time, as on real instruments


def write_fleet_config(folder, ports: dict) -> tuple:
    """A Forrester campaign on three remote instruments, each on its port with its token file."""
    base = validated(load_config(SOURCE)).with_overrides(**OVERRIDES).with_overrides(name="fleet")
    dumped = base.model_dump(mode="json")
    dumped.pop("instrument")
    dumped["schedule"] |= {"n_seed": 3, "n_steps": 6}
    tokens = {}
    instruments = []
    for name in NAMES:
        token_file = folder / f"{name}.token"
        tokens[name] = f"token-of-{name}-" + "x" * 24
        token_file.write_text(tokens[name] + "\n")
        token_file.chmod(0o600)
        settings = {"port": ports[name], "token_file": str(token_file), "silence_s": 60.0}
        instruments.append({"name": name, "kind": "remote", "settings": settings})
    path = folder / "fleet.yaml"
    path.write_text(yaml.safe_dump({**dumped, "instruments": instruments}))
    return path, tokens


def start_pc(port: int, token: str, capture: bool) -> subprocess.Popen:
    out = subprocess.PIPE if capture else subprocess.DEVNULL
    env = {**os.environ, "NOISEBO_BRIDGE_TOKEN": token}
    return subprocess.Popen(
        [sys.executable, "-m", "noisebo.bridge.serve_simulator", f"http://127.0.0.1:{port}", SOURCE, str(PACE)],
        env=env,
        stdout=out,
        stderr=out,
        text=True,
    )


def test_three_instrument_pcs_one_killed_then_the_campaign_killed_and_resumed(tmp_path, prefect_server, monkeypatch):
    monkeypatch.delenv("NOISEBO_BRIDGE_TOKEN", raising=False)  # each bridge its own token
    seed = 5
    ports = {name: free_port() for name in NAMES}
    config, tokens = write_fleet_config(tmp_path, ports)
    out = tmp_path / "runs"
    path = out / f"fleet_reward_s{seed:04d}.h5"
    env = {k: v for k, v in os.environ.items() if k != "NOISEBO_BRIDGE_TOKEN"} | prefect_server
    cli = [sys.executable, "-m", "noisebo.cli.main"]
    pcs = {name: start_pc(ports[name], tokens[name], capture=name != "east") for name in NAMES}
    campaign = None
    try:
        log = tmp_path / "campaign.log"
        with open(log, "w") as output:
            command = [*cli, "run", str(config), "--seed", str(seed), "--out", str(out), "--no-rrd"]
            campaign = subprocess.Popen(command, env=env, stdout=output, stderr=subprocess.STDOUT)
        alive = lambda process=campaign: process.poll() is None  # noqa: E731
        wait_for_length(path, 12, alive, what=lambda: log.read_text()[-3000:])
        pcs["east"].send_signal(signal.SIGKILL)  # one instrument PC dies
        pcs["east"].wait()
        pcs["east"] = start_pc(ports["east"], tokens["east"], capture=True)  # and is started again
        wait_for_flights(path, 3, alive, what=lambda: log.read_text()[-3000:])
        campaign.send_signal(signal.SIGKILL)  # then the campaign itself, three points in flight
        campaign.wait()
        at_kill = event_codec.rebuild(journal.read(path.with_suffix(".journal"))[0])
        assert len(at_kill.flights) >= 2, f"killed with {len(at_kill.flights)} points in flight"
        for name, pc in pcs.items():
            assert pc.poll() is None, f"instrument PC {name} ended: {pc.communicate()}"
        done = subprocess.run(
            [*cli, "resume", str(path), "--no-rrd"], env=env, capture_output=True, text=True, timeout=300, check=False
        )
        assert done.returncode == 0, done.stderr[-3000:]
        served = {name: pc.communicate(timeout=60) for name, pc in pcs.items()}
    finally:
        for process in (campaign, *pcs.values()):
            if process is not None and process.poll() is None:
                process.kill()
                process.communicate()
    for name, (said, err) in served.items():
        assert pcs[name].returncode == 0, err
        assert said.strip().splitlines()[-1] == "completed"
    assert_every_shot_once(path, seed)
    final = event_codec.rebuild(journal.read(path.with_suffix(".journal"))[0])
    for flight in at_kill.flights:  # the points in flight at the kill went on where they were
        entry = next(e for e in final.points if e.committed.index == flight.point)
        assert entry.shots[: len(flight.taken)] == flight.taken


def wait_for_flights(path, n: int, alive, what, timeout: float = 240) -> None:
    """Wait until the journal has ``n`` points in flight past the seed points."""
    deadline = time.monotonic() + timeout
    while True:
        state = event_codec.rebuild(journal.read(path.with_suffix(".journal"))[0])
        if len(state.flights) >= n and state.decisions:
            return
        assert alive(), f"the campaign ended before {n} points were in flight: {what()}"
        assert time.monotonic() < deadline, f"never {n} points in flight within {timeout:.0f} s: {what()}"
        time.sleep(0.05)


def assert_every_shot_once(path, seed: int) -> None:
    """The journal: completed; every point committed once, its shots 0..n-1 each once with the
    reading of its (seed, point, shot) stream and the instrument its point was on."""
    records, _ = journal.read(path.with_suffix(".journal"))
    events = [event_codec.decode(r) for r in records]
    state = event_codec.rebuild(records)
    assert state.status.value == "completed"
    indices = sorted(e.committed.index for e in state.points)
    assert indices == list(range(state.config.schedule.n_seed + state.config.schedule.n_steps))
    simulator = build(validated(load_config(SOURCE)).instrument)
    taken = [e for e in events if isinstance(e, ShotTaken)]
    assert len(taken) == len({(s.point, s.shot) for s in taken}) == state.n_shots
    issued = [e.point for e in events if isinstance(e, PointIssued)]
    assert sorted(issued) == indices  # each point issued once: none lost, none measured twice
    used = set()
    for entry in state.points:
        assert [s.shot for s in entry.shots] == list(range(len(entry.shots)))
        for shot in entry.shots:
            assert shot.instrument in NAMES
            used.add(shot.instrument)
            request = Request(shot.point, 0, shot.x, shot.t, shot.shot + 1, shot.shot, None)
            assert np.isclose(shot.reading.value, take_shot(simulator, seed, request).value)
    assert used == set(NAMES)
