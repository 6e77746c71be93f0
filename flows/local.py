"""Settings for flow runs started from this machine's command line or benchmarks."""

from __future__ import annotations

import contextlib
import os

import prefect.settings as ps


@contextlib.contextmanager
def flow_settings():
    """With Prefect's temporary server (PREFECT_API_URL unset) nothing watches flow-run
    heartbeats, and their thread makes every flow run end on a whole second (0.5-1 s lost per
    campaign): turn them off there. Against a real server, leave them on."""
    if os.environ.get("PREFECT_API_URL"):
        yield
        return
    with ps.temporary_settings({ps.PREFECT_FLOWS_HEARTBEAT_FREQUENCY: None}):
        yield
