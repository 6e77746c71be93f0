"""noisebo's temporary Prefect server: the one flows use when no PREFECT_API_URL is set.

It is Prefect's own (``SubprocessASGIServer``), started through ``flows/server_guard.py`` so that
it dies with the process that started it, however that process ends. Each one is recorded in
PREFECT_HOME/noisebo-servers/ (its pid and start time, and its parent's); a later start stops a
recorded server whose parent is gone, and an unrecorded temporary server of the same PREFECT_HOME
whose parent is gone (pid 1, or a process younger than the server), as servers left by older
versions were. Both checks read /proc: elsewhere they find nothing to stop.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import prefect.settings as ps
from prefect.server.api.server import SubprocessASGIServer

from noisebo.flows import processes, server_launch

SERVER_APP = "prefect.server.api.server:create_app"
GUARD = server_launch.GUARD


def temporary_server() -> SubprocessASGIServer:
    """The temporary server Prefect's clients will use in this process: a ``GuardedServer``,
    put where Prefect looks for it (as ``prefect_test_harness`` puts its own), unless a server is
    already running there."""
    current = SubprocessASGIServer._instances.get(None)
    if current is not None and (current.running or isinstance(current, GuardedServer)):
        return current
    SubprocessASGIServer._instances.pop(None, None)
    return GuardedServer()


class GuardedServer(SubprocessASGIServer):
    """Prefect's temporary server (its app, settings and environment as Prefect 3.8.8 runs it), run
    by ``flows/server_guard.py`` and recorded while it runs."""

    _early: subprocess.Popen | None = None  # a process started before Prefect loaded, to adopt

    def start(self, timeout: int | None = None) -> None:
        if not self.running:
            stop_stale_servers(prefect_home())
            early = server_launch.take()  # the process a command started before loading Prefect
            if early is not None:
                self.port, self._early = early
        super().start(timeout)

    def _run_uvicorn_command(self) -> subprocess.Popen:
        self._forget()  # a retry on another port: the process before it has exited
        process, self._early = self._early, None
        if process is None or process.poll() is not None:
            assert self.port is not None  # start() chose it before it runs the command
            process = server_launch.start(self.port, server_environment())
        self._record: Path | None = record_server(prefect_home(), process.pid)
        return process

    def stop(self) -> None:
        super().stop()
        self._forget()

    def _forget(self) -> None:
        record = getattr(self, "_record", None)
        if record is not None:
            record.unlink(missing_ok=True)
            self._record = None


def server_environment() -> dict[str, str]:
    """The server process's environment (``server_launch.environment``) with Prefect's settings."""
    return server_launch.environment(ps.get_current_settings().to_environment_variables(exclude_unset=True))


def prefect_home() -> Path:
    return Path(ps.PREFECT_HOME.value())


def records(home: Path) -> Path:
    return home / "noisebo-servers"


def record_server(home: Path, pid: int) -> Path:
    """Write down the server ``pid`` just started by this process."""
    folder = records(home)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{pid}.json"
    path.write_text(
        json.dumps(
            {
                "server": pid,
                "server_started": processes.started_ticks(pid),
                "parent": os.getpid(),
                "parent_started": processes.started_ticks(os.getpid()),
            }
        )
    )
    return path


def is_temporary_server(pid: int) -> bool:
    """Whether ``pid`` runs a Prefect temporary server: Prefect's own, or noisebo's guarded one."""
    command = processes.command_line(pid)
    runs_server = SERVER_APP in command or any(Path(arg).name == GUARD.name for arg in command[1:3])
    return runs_server and processes.environment(pid).get("PREFECT__SERVER_EPHEMERAL") == "1"


def stop_stale_servers(home: Path) -> list[int]:
    """Stop the temporary servers of ``home`` whose parent is gone; the pids stopped."""
    if not processes.PROC.is_dir():  # nothing to tell a live process from a stale record with
        return []
    stopped = stop_recorded_orphans(home)
    return stopped + stop_unrecorded_orphans(home)


def stop_recorded_orphans(home: Path) -> list[int]:
    stopped = []
    for path in sorted(records(home).glob("*.json")):
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # being written, or not ours to judge
        server, started = record["server"], record["server_started"]
        alive = started is not None and processes.started_ticks(server) == started and is_temporary_server(server)
        if alive and processes.started_ticks(record["parent"]) == record["parent_started"]:
            continue  # its parent still runs
        if alive:
            processes.terminate(server, started)
            stopped.append(server)
        path.unlink(missing_ok=True)
    return stopped


def stop_unrecorded_orphans(home: Path) -> list[int]:
    stopped = []
    for pid in processes.live_pids():
        if not is_temporary_server(pid) or not same_home(processes.environment(pid).get("PREFECT_HOME"), home):
            continue
        started = processes.started_ticks(pid)
        if started is not None and is_orphan(pid, started):
            processes.terminate(pid, started)
            stopped.append(pid)
    return stopped


def same_home(value: str | None, home: Path) -> bool:
    return value is not None and Path(value).expanduser().resolve() == home.expanduser().resolve()


def is_orphan(pid: int, started: int) -> bool:
    """Adopted by pid 1 or by a process younger than itself: the process that started it is gone."""
    parent = processes.parent_of(pid)
    if parent is None:
        return False
    parent_started = processes.started_ticks(parent)
    return parent == 1 or (parent_started is not None and parent_started > started)
