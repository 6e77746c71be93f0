"""flows/abort.py: the first signal drops work under way (a decision) at once; the work's thread
is interrupted and ends; without a clean abort installed the work runs in the caller's thread."""

import os
import signal
import threading
import time

from noisebo.campaign import background
from noisebo.flows import abort


def test_without_a_clean_abort_the_work_runs_here():
    assert abort.unless_stopped(lambda: threading.current_thread(), lambda name: name) is threading.current_thread()


def test_work_that_finishes_gives_its_result_from_the_same_worker_thread_each_time():
    with abort.AbortFlag().installed():
        threads = {abort.unless_stopped(threading.current_thread, lambda name: name) for _ in range(3)}
    assert len(threads) == 1 and threads != {threading.current_thread()}


def test_a_signal_while_the_work_runs_returns_the_stop_at_once_and_ends_the_work(capsys):
    ran = {"iterations": 0, "ended_by": None}

    def busy() -> str:
        try:
            deadline = time.monotonic() + 600
            while time.monotonic() < deadline:  # Python work, as a decision's optimiser loop
                ran["iterations"] += 1
            return "finished"
        except BaseException as ended:  # noqa: BLE001 - what ended it is the test's question
            ran["ended_by"] = type(ended)
            raise

    with abort.AbortFlag().installed():
        threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGTERM)).start()
        began = time.monotonic()
        answer = abort.unless_stopped(busy, lambda name: f"stopped on {name}")
        returned_s = time.monotonic() - began
    assert answer == "stopped on SIGTERM" and returned_s < 120  # a hang guard: the work runs for 600 s unless stopped
    deadline = time.monotonic() + 5
    while background.still_running() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not background.still_running() and ran["ended_by"] is abort.Abandoned and ran["iterations"] > 0
    assert "SIGTERM received" in capsys.readouterr().out
