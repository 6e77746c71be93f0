"""Local helper processes: a Prefect server on a free loopback port, workers, serve processes;
and what Linux's /proc says about a process (elsewhere these answer None or nothing).

Used by the end-to-end tests, the sweep benchmark and the temporary server's clean-up. Every
process started here starts in its own process group, so stopping it also stops its children (a
worker's flow-run subprocesses).
"""

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args, env, log: Path) -> subprocess.Popen:
    """A process in its own group, its output to ``log``."""
    with Path(log).open("w") as out:
        return subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def stop(process: subprocess.Popen) -> None:
    """SIGTERM to the process group, SIGKILL after 20 s."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def wait_for(check, timeout_s: float, what: str, logs=()) -> None:
    """Poll ``check`` every 0.5 s; TimeoutError with the tails of ``logs`` if it stays false."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.5)
    tails = "\n".join(f"--- {p}\n{Path(p).read_text()[-3000:]}" for p in logs)
    raise TimeoutError(f"timed out after {timeout_s:.0f} s waiting for {what}\n{tails}")


@contextlib.contextmanager
def local_server(folder: Path):
    """A `prefect server start` on a free loopback port with its own PREFECT_HOME under
    ``folder``; yields the environment that points clients at it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    port = free_port()
    env = dict(
        os.environ,
        PREFECT_HOME=str(folder / "home"),
        PREFECT_API_URL=f"http://127.0.0.1:{port}/api",
        PREFECT_SERVER_ANALYTICS_ENABLED="false",
        DO_NOT_TRACK="1",
        TQDM_DISABLE="1",
    )
    log = folder / "server.log"
    process = start([str(BIN / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)], env, log)

    def healthy() -> bool:
        try:
            return httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(healthy, 180, "the Prefect server", [log])
        yield env
    finally:
        stop(process)


PROC = Path("/proc")


def started_ticks(pid: int) -> int | None:
    """When the process started (clock ticks after boot): with its pid, it names one process
    even after the pid is reused. None if there is no such live process (a zombie counts as gone)."""
    try:
        stat = (PROC / str(pid) / "stat").read_text()
    except (OSError, ValueError):
        return None
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (command name) "
    return None if fields[0] == "Z" else int(fields[19])


def parent_of(pid: int) -> int | None:
    try:
        stat = (PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    return int(stat[stat.rindex(")") + 2 :].split()[1])


def command_line(pid: int) -> list[str]:
    try:
        return (PROC / str(pid) / "cmdline").read_bytes().decode(errors="replace").split("\0")[:-1]
    except OSError:
        return []


def environment(pid: int) -> dict[str, str]:
    """The environment the process started with (readable for one's own processes)."""
    try:
        entries = (PROC / str(pid) / "environ").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return {}
    return dict(entry.split("=", 1) for entry in entries if "=" in entry)


def live_pids() -> list[int]:
    try:
        return [int(p.name) for p in PROC.iterdir() if p.name.isdigit()]
    except OSError:
        return []


def children_of(pid: int) -> list[int]:
    return [child for child in live_pids() if parent_of(child) == pid]


def terminate(pid: int, started: int, grace_s: float = 3.0) -> None:
    """SIGTERM to the process ``pid`` that started at ``started`` (and to no later one with its
    pid), SIGKILL if it is still there after ``grace_s``."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        if started_ticks(pid) != started:
            return
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, sig)
        deadline = time.monotonic() + grace_s
        while started_ticks(pid) == started and time.monotonic() < deadline:
            time.sleep(0.05)
