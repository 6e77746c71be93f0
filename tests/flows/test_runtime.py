"""The Python API gets noisebo's Prefect defaults without the command line."""

import os
import subprocess
import sys


def test_importing_flows_sets_the_temporary_servers_defaults_and_keeps_what_is_set():
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env["PREFECT_LOGGING_LEVEL"] = "DEBUG"
    code = ("import os, flows.campaign\n"
            "print(os.environ['PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS'], os.environ['PREFECT_LOGGING_LEVEL'],"
            " os.environ['PREFECT_HOME'].endswith('.prefect'))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == ["120", "DEBUG", "True"]
