"""Nothing left behind: noisebo's temporary Prefect server dies with the process that started it,
however that process ends, and a later start stops servers whose parent is gone. Real processes,
real Prefect servers, real SIGKILL (Linux: these tests read /proc)."""

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time

import httpx
import pytest

from noisebo.flows import processes
from noisebo.flows import temporary_server as temporary

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def gone_within(pid: int, started: int, seconds: float) -> float | None:
    """Seconds until the process ``pid`` that started at ``started`` was gone, or None."""
    begin = time.monotonic()
    while time.monotonic() - begin < seconds:
        if processes.started_ticks(pid) != started:
            return time.monotonic() - begin
        time.sleep(0.02)
    return None


def server_children(pid: int) -> list[int]:
    return [child for child in processes.children_of(pid) if temporary.is_temporary_server(child)]


def run_env(tmp_path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PREFECT_API_URL"}
    env.update(PREFECT_HOME=str(tmp_path / "home"), NOISEBO_JAX_CACHE="", NOISEBO_LOG_DIR=str(tmp_path / "logs"))
    return env


def spawn_and_vanish(code: str, env: dict[str, str], folder) -> list[tuple[int, int]]:
    """Run ``code`` in a Python process that dies by SIGKILL after it; the processes it named by
    ``shown(pid)``, as (pid, start time). Output goes through files: the processes it leaves
    behind would hold a pipe open."""
    shown, errors = folder / "shown.txt", folder / "stderr.txt"
    code = (
        f"import os, signal\nfrom flows import processes\nshown_to = open({str(shown)!r}, 'w')\n"
        "def shown(pid): print(pid, processes.started_ticks(pid), file=shown_to, flush=True)\n"
        + textwrap.dedent(code)
        + "\nos.kill(os.getpid(), signal.SIGKILL)"
    )
    with errors.open("w") as stderr:
        parent = subprocess.run(
            [sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL, stderr=stderr, timeout=120, check=False
        )
    assert parent.returncode == -signal.SIGKILL, errors.read_text()[-3000:]
    return [(int(pid), int(started)) for pid, started in (line.split() for line in shown.read_text().splitlines())]


@pytest.mark.e2e
def test_kill_9_of_noisebo_run_takes_its_temporary_server_with_it(tmp_path, tiny_yaml):
    run = subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(tiny_yaml), "--out", str(tmp_path / "runs"), "--no-rrd"],
        env=run_env(tmp_path),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        for line in run.stdout:  # the first point measured: the flow run is using the server
            if line.startswith("seed point"):
                break
        servers = server_children(run.pid)
        assert len(servers) == 1, f"one temporary server under the run, not {servers}"
        started = processes.started_ticks(servers[0])
        assert (tmp_path / "home" / "noisebo-servers" / f"{servers[0]}.json").exists()
        run.kill()
        run.wait(timeout=30)
        took = gone_within(servers[0], started, 5.0)
        assert took is not None, "the temporary server outlived its kill -9'd parent by 5 s"
        print(f"server gone {took:.2f} s after the kill")
    finally:
        run.kill()
        run.stdout.close()


@pytest.mark.e2e
def test_the_guard_stops_the_server_when_the_parent_goes_without_a_death_signal(tmp_path):
    """The watch thread alone (as where PR_SET_PDEATHSIG is not available, or a thread that is
    not the main one started the server): the parent is killed once the server answers."""
    port = processes.free_port()
    [(server, started)] = spawn_and_vanish(
        f"""
        import subprocess, sys, time
        import httpx
        from noisebo.flows import temporary_server as temporary
        server = subprocess.Popen([sys.executable, "-P", str(temporary.GUARD), str(os.getpid()), "watch", "{port}"],
                                  env=temporary.server_environment())
        for _ in range(1200):
            try:
                if httpx.get("http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        shown(server.pid)
        """,
        run_env(tmp_path),
        tmp_path,
    )
    took = gone_within(server, started, 5.0)
    assert took is not None, "the server outlived its parent by 5 s"
    # nothing answers on the port: refused, or reset by a listening socket the kernel is closing
    with pytest.raises((httpx.ConnectError, httpx.ReadError)):
        httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1)


def database(tmp_path, name: str) -> str:
    """A database of its own for each server of one PREFECT_HOME: they start side by side."""
    return f"sqlite+aiosqlite:///{tmp_path}/{name}.db"


@pytest.mark.e2e
def test_a_later_start_stops_servers_whose_parent_is_gone_and_no_other(tmp_path):
    """Two real Prefect servers left behind by a parent killed before it could stop them, started
    as Prefect starts them: one recorded (as this version records its servers), one not (as older
    versions left them). A live server of the test's own, with its record, and an orphan of another
    PREFECT_HOME stay; so does a live process that is no server, named by a stale record."""
    env = run_env(tmp_path)
    home = tmp_path / "home"
    (recorded, recorded_at), (unrecorded, unrecorded_at) = spawn_and_vanish(
        f"""
        from prefect.server.api.server import SubprocessASGIServer
        from noisebo.flows import temporary_server as temporary
        server = SubprocessASGIServer()
        for record, url in ((True, {database(tmp_path, "recorded")!r}), (False, {database(tmp_path, "unrecorded")!r})):
            os.environ["PREFECT_API_DATABASE_CONNECTION_URL"] = url
            server.port = server.find_available_port()
            pid = server._run_uvicorn_command().pid
            if record:
                temporary.record_server(temporary.prefect_home(), pid)
            shown(pid)
        """,
        env,
        tmp_path,
    )
    (tmp_path / "other").mkdir()
    [(elsewhere, elsewhere_at)] = spawn_and_vanish(
        """
        from prefect.server.api.server import SubprocessASGIServer
        server = SubprocessASGIServer()
        server.port = server.find_available_port()
        shown(server._run_uvicorn_command().pid)
        """,
        run_env(tmp_path / "other"),
        tmp_path,
    )
    ours = subprocess.Popen(
        [sys.executable, "-P", str(temporary.GUARD), str(os.getpid()), "watch", str(processes.free_port())],
        env=env | {"PREFECT__SERVER_EPHEMERAL": "1", "PREFECT_API_DATABASE_CONNECTION_URL": database(tmp_path, "ours")},
    )
    bystander = subprocess.Popen(["sleep", "60"])
    try:
        started = {
            recorded: recorded_at,
            unrecorded: unrecorded_at,
            elsewhere: elsewhere_at,
            ours.pid: processes.started_ticks(ours.pid),
        }
        temporary.record_server(home, ours.pid)
        (temporary.records(home) / f"{bystander.pid}.json").write_text(
            json.dumps(
                {
                    "server": bystander.pid,
                    "server_started": processes.started_ticks(bystander.pid),
                    "parent": recorded,
                    "parent_started": 1,
                }
            )
        )  # a parent long gone

        assert temporary.stop_recorded_orphans(home) == [recorded]
        assert gone_within(recorded, started[recorded], 5.0) is not None
        assert temporary.stop_unrecorded_orphans(home) == [unrecorded]
        assert gone_within(unrecorded, started[unrecorded], 5.0) is not None
        assert temporary.stop_stale_servers(home) == []
        assert processes.started_ticks(ours.pid) == started[ours.pid]
        assert processes.started_ticks(elsewhere) == started[elsewhere]
        assert bystander.poll() is None
        assert [p.name for p in temporary.records(home).iterdir()] == [f"{ours.pid}.json"]
    finally:
        for process in (ours, bystander):
            process.kill()
            process.wait()
        processes.terminate(elsewhere, started[elsewhere])


@pytest.mark.e2e
def test_a_port_taken_meanwhile_is_retried_on_another_without_a_word(tmp_path):
    """The port Prefect picked is taken by the time the server binds it: uvicorn exits 3 after
    Prefect's lifespan shutdown traceback, Prefect starts it again elsewhere; none of it is shown."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))  # bound, not listening: Prefect's health check is refused there
        port = taken.getsockname()[1]
        code = textwrap.dedent(f"""
            import httpx
            from noisebo.flows import temporary_server
            server = temporary_server.GuardedServer(port={port})
            server.start()
            print(server.port != {port}, httpx.get(server.api_url + "/health").status_code)
            server.stop()
            """)
        done = subprocess.run(
            [sys.executable, "-c", code],
            env=run_env(tmp_path),
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
    assert (done.returncode, done.stdout.split(), done.stderr) == (0, ["True", "200"], "")


FOUR_HUNDRED_TASKS = """
import sys
from prefect import flow, task
from noisebo.flows import local

@task
def one(i):
    return i

@flow
def many():
    return sum(one(i) for i in range(400))

if sys.argv[1] == "guarded":
    with local.flow_settings():
        many()
else:
    many()
"""


@pytest.mark.e2e
def test_a_successful_flow_on_the_guarded_server_prints_no_shutdown_traceback(tmp_path):
    """400 tasks on Prefect's temporary server as Prefect starts it end with the task-run
    recorder's cancelled flushes (tracebacks on stderr, exit 0); on noisebo's, with nothing."""

    def run(mode: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-c", FOUR_HUNDRED_TASKS, mode],
            env=run_env(tmp_path),
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )

    plain = run("plain")
    assert plain.returncode == 0 and "Error flushing" in plain.stderr, plain.stderr[-3000:]
    guarded = run("guarded")
    assert guarded.returncode == 0 and guarded.stderr == "" and guarded.stdout == ""


def test_the_server_process_drops_the_pool_warning_at_exit_and_keeps_others(tmp_path, monkeypatch):
    """The server holds Prefect's database pool and imports nothing of noisebo: its environment
    carries the filter, beside any PYTHONWARNINGS of the user's."""
    from noisebo.flows import runtime, temporary_server

    monkeypatch.setenv("PYTHONWARNINGS", "default")
    env = temporary_server.server_environment()
    assert env["PYTHONWARNINGS"].split(",")[0] == "default"
    code = (
        "import warnings\n"
        "class SAWarning(RuntimeWarning): pass\n"
        f"warnings.warn({runtime.POOL_AT_EXIT!r} + ' <AdaptedConnection>, which will be terminated.', SAWarning)\n"
        "warnings.warn('another warning')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert "another warning" in done.stderr and runtime.POOL_AT_EXIT not in done.stderr
