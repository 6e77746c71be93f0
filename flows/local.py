"""Settings for flow runs started from this machine's command line or benchmarks."""

from __future__ import annotations

import contextlib

import prefect.settings as ps

from noisebo.flows import runtime


@contextlib.contextmanager
def flow_settings():
    """With Prefect's temporary server (no API URL set) nothing watches flow-run heartbeats, and
    their thread makes every flow run end on a whole second (0.5-1 s lost per campaign): turn them
    off there, and start the server now, from this thread, guarded (flows/temporary_server.py).
    Against a real server, leave them on. Either way, Prefect's tracebacks and reports of failed
    runs go to the failure log, not the terminal, and its exit notices are not shown."""
    runtime.divert_failure_reports()
    runtime.quiet_draining()
    if ps.PREFECT_API_URL.value():
        yield
        return
    from noisebo.flows.temporary_server import temporary_server

    temporary_server().start()
    with ps.temporary_settings({ps.PREFECT_FLOWS_HEARTBEAT_FREQUENCY: None}):
        yield
