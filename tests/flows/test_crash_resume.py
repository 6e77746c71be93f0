"""kill -9 at many moments, including halfway through a journal record, a whole-file HDF5 write
or an in-place append, then `noisebo resume`: nothing committed is lost or duplicated, and the
finished campaign equals the uninterrupted one. Real processes, real SIGKILL."""

import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.storage import journal
from noisebo.storage.record import read_record

SEED = 9


def events_in(jpath) -> int:
    """The campaign events a journal holds: its records less the clock records of its commits."""
    return sum(1 for r in journal.read(jpath)[0] if r.type != "clock")


def cli_env(prefect_harness, crash=None):
    env = dict(os.environ)
    env["PREFECT_API_URL"] = prefect_harness
    env.pop("NOISEBO_CRASH_AT", None)
    if crash:
        env["NOISEBO_CRASH_AT"] = crash
    return env


def noisebo(args, env, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli.main", *args], env=env, capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture(scope="module")
def reference(tiny_config):
    result = run_campaign(tiny_config, build(tiny_config.instrument), SEED)
    shots = [(i, k) for i, p in enumerate(result.state.points) for k in range(p.n_shots)]
    return result.state, shots


def assert_equals_reference(path, reference):
    state, shots = reference
    with h5py.File(path, "r") as f:  # plain h5py, no SWMR, no repair tool
        assert f.attrs["status"] == "completed"
        np.testing.assert_array_equal(f["points/x"][()], [p.x[0] for p in state.points])
        np.testing.assert_array_equal(f["points/t"][()], [p.t for p in state.points])
        np.testing.assert_array_equal(f["points/value"][()], [p.value for p in state.points])
        np.testing.assert_array_equal(f["points/noise"][()], [p.noise for p in state.points])
        got = list(zip(f["shots/point"][()].tolist(), f["shots/shot"][()].tolist()))
        assert got == shots  # every shot exactly once, in order
        np.testing.assert_array_equal(f["steps/t_opt"][()], state.t_opt_history)


# Record 1 is the campaign record (killed while creating), 2 the first shot, 17 a shot of the
# second seed point, 45 inside the BO steps. Whole-file HDF5 writes: 1 the file created with the
# campaign, 2 its rewrite when the first decision brings the hyperparameters, 3 the finished file
# (killed before its rename). Appends (one per committed point but the first BO point's, five
# crash points each: after the points, steps, failures and shots tables, and after the flush
# before the counters): 17 falls between the tables of the second BO point's append, 20 just
# before its counters.
# The default run kills once, inside the BO steps; CI's end-to-end run (-m e2e) at the others.
CRASHES = [
    "journal:45",
    pytest.param("journal:2", marks=pytest.mark.e2e),
    pytest.param("hdf5:3", marks=pytest.mark.e2e),
    pytest.param("append:17", marks=pytest.mark.e2e),
    pytest.param("append:20", marks=pytest.mark.e2e),
    pytest.param("journal:1", marks=pytest.mark.slow),
    pytest.param("journal:17", marks=pytest.mark.slow),
    pytest.param("hdf5:1", marks=pytest.mark.slow),
    pytest.param("hdf5:2", marks=pytest.mark.slow),
    pytest.param("append:3", marks=pytest.mark.slow),
]


@pytest.mark.parametrize("crash", CRASHES)
def test_injected_kill_then_resume(crash, tiny_yaml, tmp_path, prefect_harness, reference):
    out = tmp_path / "runs"
    path = out / f"tiny_reward_s{SEED:04d}.h5"
    killed = noisebo(["run", str(tiny_yaml), "--seed", str(SEED), "--out", str(out)], cli_env(prefect_harness, crash))
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    if path.exists():
        # Whatever the moment, the file on disk opens. swmr=True: a file killed while open for
        # appending is flagged open-for-write, which plain h5py refuses without h5clear; an SWMR
        # reader opens it, and any finished file too.
        with h5py.File(path, "r", swmr=True) as f:
            assert f.attrs["status"] == "running"
        assert read_record(path).status == "running"
    if not path.with_suffix(".journal").exists():
        # Killed while creating: nothing was committed, and a fresh run starts cleanly.
        done = noisebo(["run", str(tiny_yaml), "--seed", str(SEED), "--out", str(out)], cli_env(prefect_harness))
    else:
        done = noisebo(["resume", str(path)], cli_env(prefect_harness))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == str(path)
    assert_equals_reference(path, reference)


@pytest.mark.e2e
def test_external_kill_at_a_random_moment_then_resume(tiny_yaml, tmp_path, prefect_harness, reference):
    out = tmp_path / "runs"
    path = out / f"tiny_reward_s{SEED:04d}.h5"
    jpath = path.with_suffix(".journal")
    env = cli_env(prefect_harness)
    proc = subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(tiny_yaml), "--seed", str(SEED), "--out", str(out)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if jpath.exists() and events_in(jpath) >= 40:  # into the BO steps
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert events_in(jpath) >= 40
    done = noisebo(["resume", str(path)], env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert_equals_reference(path, reference)


def test_another_process_reads_the_file_while_the_campaign_runs(tiny_yaml, tmp_path, prefect_harness, reference):
    out = tmp_path / "runs"
    path = out / f"tiny_reward_s{SEED:04d}.h5"
    proc = subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(tiny_yaml), "--seed", str(SEED), "--out", str(out)],
        env=cli_env(prefect_harness),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    seen, deadline = [], time.monotonic() + 240
    while proc.poll() is None and time.monotonic() < deadline:
        if path.exists():
            # noisebo's reader, while the campaign writes: the running file is open for appending
            # (plain h5py refuses it; the reader opens it with swmr=True) and its per-point counts
            # are in /committed, not in root attributes (no attribute is rewritten under SWMR).
            data = read_record(path)
            seen.append((str(data.status), len(data.points), len(data.shots.value)))
        time.sleep(0.01)
    assert proc.wait(timeout=60) == 0
    running = [s for s in seen if s[0] == "running"]
    assert len({s[1] for s in running}) >= 3, "the reader saw the file grow point by point"
    assert [s[1] for s in seen] == sorted(s[1] for s in seen)
    assert_equals_reference(path, reference)


@pytest.mark.e2e
@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)], ids=["SIGTERM", "SIGINT"])
def test_a_signal_aborts_cleanly_and_resume_finishes_the_same_campaign(
    signum, code, tiny_yaml, tmp_path, prefect_harness, reference
):
    out = tmp_path / "runs"
    path = out / f"tiny_reward_s{SEED:04d}.h5"
    jpath = path.with_suffix(".journal")
    env = cli_env(prefect_harness)
    proc = subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(tiny_yaml), "--seed", str(SEED), "--out", str(out)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if jpath.exists() and events_in(jpath) >= 40:  # into the BO steps
            break
        time.sleep(0.05)
    proc.send_signal(signum)
    sent = time.monotonic()
    stdout, stderr = proc.communicate(timeout=120)
    exited_s = time.monotonic() - sent
    assert proc.returncode == code, stderr[-2000:]
    assert exited_s < 5, f"noisebo run exited {exited_s:.1f} s after the signal"
    assert "continue it with `noisebo resume" in stderr.strip().splitlines()[-1]
    assert f"{signal.Signals(signum).name} received" in stdout
    with h5py.File(path, "r") as f:
        assert f.attrs["status"] == "aborted" and f.attrs["status_reason"] == f"{signal.Signals(signum).name} received"
        n_points = int(f.attrs["n_points"])
        committed = f["shots/committed"][()]  # a point stopped mid-way keeps its shots, uncommitted
        assert committed.size > 0 and committed[: committed.sum()].all()
    assert 3 <= n_points < 3 + 4
    done = noisebo(["resume", str(path)], env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert_equals_reference(path, reference)
