"""The Python API gets noisebo's Prefect defaults without the command line."""

import os
import subprocess
import sys

from noisebo.flows import runtime


def test_configure_sets_the_temporary_servers_defaults_and_keeps_what_is_set():
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env["PREFECT_LOGGING_LEVEL"] = "DEBUG"
    code = (
        "import os\nfrom noisebo.flows import runtime\nruntime.configure()\nimport noisebo.flows.campaign\n"
        "print(os.environ['PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS'], os.environ['PREFECT_LOGGING_LEVEL'],"
        " os.environ['PREFECT_HOME'].endswith('.prefect'))"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == ["120", "DEBUG", "True"]


def test_failure_reports_go_to_the_failure_log_and_other_records_stay_on_the_terminal(tmp_path):
    code = (
        "import logging, sys\n"
        "from flows import runtime\n"
        "logging.getLogger().addHandler(logging.StreamHandler(sys.stderr))\n"
        "runtime.divert_failure_reports()\n"
        "log = logging.getLogger('prefect.flow_runs')\n"
        "log.error('Crash detected! Execution was aborted by a termination signal.')\n"
        "log.warning('a warning')\n"
        "logging.getLogger('prefect.client').error('a plain error')\n"
        "try:\n"
        "    1 / 0\n"
        "except ZeroDivisionError:\n"
        "    log.error('Encountered exception during execution', exc_info=True)\n"
        "print(runtime.failure_log().report(KeyError('missing')))\n"
    )
    env = dict(os.environ, NOISEBO_LOG_DIR=str(tmp_path / "logs"), NOISEBO_JAX_CACHE="")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120)
    assert out.stderr.splitlines() == ["a warning", "a plain error"]
    [log] = (tmp_path / "logs").glob("noisebo-*.log")
    assert out.stdout.strip() == f"KeyError: 'missing'; the traceback is in {log}"
    text = log.read_text()
    assert "Encountered exception during execution" in text and "ZeroDivisionError" in text and "KeyError" in text
    assert "Crash detected!" in text and "a warning" not in text and "a plain error" not in text
    assert (tmp_path / "logs" / ".gitignore").read_text() == "*\n"


def test_no_failure_no_log(tmp_path):
    code = "from flows import runtime\nruntime.divert_failure_reports()\nprint(runtime.failure_log().mention() == '')\n"
    env = dict(os.environ, NOISEBO_LOG_DIR=str(tmp_path / "logs"), NOISEBO_JAX_CACHE="")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "True" and not (tmp_path / "logs").exists()


def test_prefects_exit_notice_is_not_shown_and_its_other_warnings_are(caplog):
    import logging

    from noisebo.flows import runtime

    worker = logging.getLogger("EventsWorker")
    filters = list(worker.filters)
    worker.filters[:] = []  # another test in this process may have installed it already
    try:
        runtime.quiet_draining()
        runtime.quiet_draining()
        assert len(worker.filters) == 1
        worker.warning("Still processing items: 1 items remaining...")
        worker.warning("Service failed to send 3 events")
    finally:
        worker.filters[:] = filters
    assert [r.getMessage() for r in caplog.records] == ["Service failed to send 3 events"]


def test_the_pool_warning_at_exit_is_dropped_and_other_warnings_are_not():
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runtime.quiet_pool_at_exit()
        warnings.warn(
            f"{runtime.POOL_AT_EXIT} <AdaptedConnection>, which will be terminated.", UserWarning, stacklevel=1
        )
        warnings.warn("another warning", UserWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["another warning"]


def test_the_kept_programs_go_beside_the_compilation_cache_unless_told_otherwise(tmp_path):
    code = "import os\nfrom noisebo.flows import runtime\nruntime.configure()\nprint(os.environ.get('NOISEBO_PROGRAM_CACHE'))"
    base = {k: v for k, v in os.environ.items() if k != "NOISEBO_PROGRAM_CACHE"}
    cases = [
        ({"NOISEBO_JAX_CACHE": str(tmp_path / "cache")}, str(tmp_path / "cache" / "programs")),
        ({"NOISEBO_JAX_CACHE": ""}, "None"),  # no compilation cache: nothing kept either
        (
            {"NOISEBO_JAX_CACHE": str(tmp_path / "cache"), "NOISEBO_PROGRAM_CACHE": str(tmp_path / "mine")},
            str(tmp_path / "mine"),
        ),
    ]
    for extra, expected in cases:
        out = subprocess.run(
            [sys.executable, "-c", code], env=base | extra, capture_output=True, text=True, check=True, timeout=120
        )
        assert out.stdout.strip() == expected, extra


def test_the_compilation_cache_is_capped_so_jax_locks_its_entries(tmp_path):
    # Only a capped cache is JAX's locked one (its reads and writes under a file lock, an access
    # time beside each entry for the eviction), which processes sharing the folder need.
    code = (
        "from noisebo.flows import runtime\nruntime.configure()\nimport jax\n"
        "print(jax.config.jax_compilation_cache_max_size)\n"
        "jax.jit(lambda x: x * 2.0)(1.0).block_until_ready()\n"
    )
    env = dict(os.environ, NOISEBO_JAX_CACHE=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == str(runtime.CACHE_MAX_BYTES) == str(2 * 1024**3)
    names = [p.name for p in (tmp_path / "cache").iterdir()]
    assert any(n.endswith("-cache") for n in names) and any(n.endswith("-atime") for n in names), names


def test_an_entry_a_killed_process_left_without_its_access_time_is_repaired(tmp_path):
    # JAX writes an entry and then its access time; an entry without one made every later write
    # to the cache fail with a warning (seen after the crash tests' kills), so nothing new was kept.
    cache = tmp_path / "cache"
    code = "import jax\njax.jit(lambda x: x * {})(1.0).block_until_ready()\n"
    env = dict(os.environ, NOISEBO_JAX_CACHE=str(cache))
    run = [sys.executable, "-W", "error", "-c", "from noisebo.flows import runtime\nruntime.configure()\n"]
    subprocess.run([*run[:-1], run[-1] + code.format(2.0)], env=env, check=True, timeout=120, capture_output=True)
    atimes = sorted(cache.glob("*-atime"))
    assert atimes
    atimes[0].unlink()  # as a kill between the two writes leaves it
    assert runtime.repair_cache(cache) == 1 and runtime.repair_cache(cache) == 0
    atimes[0].unlink()
    out = subprocess.run([*run[:-1], run[-1] + code.format(3.0)], env=env, timeout=120, capture_output=True, text=True)
    assert out.returncode == 0 and "Error writing" not in out.stderr, out.stderr
    assert len(list(cache.glob("*-cache"))) == len(list(cache.glob("*-atime"))) > len(atimes)


def test_repairing_a_missing_cache_folder_does_nothing(tmp_path):
    assert runtime.repair_cache(tmp_path / "none") == 0
