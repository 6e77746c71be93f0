import os
import shutil
import tempfile

import pytest
import yaml


_MADE_HERE: list[str] = []  # the temporary folders this process made, removed at the end


def _temporary_default(name: str, prefix: str) -> None:
    """Point the variable ``name`` at a new temporary folder unless it is set (as in an xdist
    worker, which inherits the controller's, or where the caller chose one)."""
    if name not in os.environ:
        os.environ[name] = tempfile.mkdtemp(prefix=prefix)
        _MADE_HERE.append(os.environ[name])


# One thread per process for XLA and the BLAS libraries, before anything imports numpy or JAX: the
# test workers and the processes tests start share the machine's cores, and pools sized to every
# core in every process oversubscribe them (tests/noisebo/campaign/test_engine.py took 30 s beside
# one other JAX process with the pools, 8 s with one thread each; 7 s alone either way). The
# processes a test starts inherit it. A value set by the caller wins.
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
ONE_THREAD_XLA_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
for _name, _value in ONE_THREAD.items():
    os.environ.setdefault(_name, _value)
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {ONE_THREAD_XLA_FLAGS}".strip()

# Before anything imports Prefect: a private Prefect home, quiet logs, no analytics.
_temporary_default("PREFECT_HOME", "noisebo-test-prefect-")
# One compilation cache for the run: the xdist workers and every process a test starts (a CLI
# run, a server) load the programs another has compiled instead of compiling them again. The
# workers inherit this process's environment, so they share the folder.
_temporary_default("NOISEBO_JAX_CACHE", "noisebo-test-jax-")
_temporary_default("NOISEBO_LOG_DIR", "noisebo-test-logs-")  # failure logs

from noisebo.flows import runtime  # noqa: E402

runtime.configure()

# The tests compute expected values with JAX themselves (kernels, likelihoods, posteriors by hand),
# in float64 as the core does: this process turns JAX's 64-bit mode on for everything, as a lab's
# process may. The processes a test starts do not inherit it (it is no environment variable), so
# the command line, the flows and the bridge run as they do for a user, with the core's own
# float64 (noisebo.precision); tests/noisebo/test_precision.py checks a process left in float32.
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from noisebo.config import CampaignConfig  # noqa: E402

TINY = CampaignConfig().with_overrides(
    name="tiny",
    space={"n_x": 40, "n_t": 30},
    schedule={"n_steps": 4, "shots_before": 10, "shots_after": 3},
)


# The files that take longest (measured: `python3 dev.py test --durations=60`, and with `-m e2e`),
# first. The workers take files in collection order (dev.py turns xdist's reordering by test count
# off), so a long file started last would leave the other workers idle at the end.
LONGEST_FIRST = (
    "e2e/test_long_kills.py",
    "e2e/test_wheel_install.py",
    "flows/test_crash_resume.py",
    "e2e/test_distributed.py",
    "e2e/test_deployments.py",
    "e2e/test_bridge_kills.py",
    "flows/test_temporary_server.py",
    "noisebo/models/test_noise_field.py",
    "noisebo/campaign/test_profile_campaign.py",
    "test_lint.py",
    "noisebo/cli/test_main.py",
    "flows/test_campaign_flow.py",
    "noisebo/campaign/test_decision.py",
    "noisebo/campaign/test_decision_field.py",
    "noisebo/storage/test_damage.py",
    "noisebo/cli/test_damaged_files.py",
    "noisebo/storage/test_hdf5.py",
    "noisebo/campaign/test_dimensions.py",
    "noisebo/models/test_profile.py",
    "noisebo/cli/test_noise_profile.py",
    "noisebo/cli/test_failures.py",
    "noisebo/test_plugin_registry.py",
    "noisebo/bridge/test_server.py",
    "noisebo/view/test_field_views.py",
)


QUICK_TO_COMPILE = "JAX_DISABLE_MOST_OPTIMIZATIONS"
# XLA's CPU fusion emitters compile each fusion through MLIR: slower to compile than the older
# emitters (29 % less time in tests/noisebo/models/test_noise_field.py and
# tests/noisebo/campaign/test_decision.py without them, cold cache).
QUICK_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false"


def pytest_configure(config):
    # Quick to compile rather than quick to run: most tests run each program a few times, so XLA's
    # optimisation passes cost more than they save. Not where end-to-end tests are selected: their
    # long campaigns run their programs thousands of times (the 200-point kills took 40 % longer).
    # Set in each process that runs tests (an xdist worker configures for itself) before anything
    # starts XLA (it reads XLA_FLAGS once); the processes a test starts inherit both. A value set by
    # the caller wins.
    if _selects_e2e(config.getoption("markexpr") or "") or QUICK_TO_COMPILE in os.environ:
        return
    os.environ[QUICK_TO_COMPILE] = "1"
    if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {QUICK_XLA_FLAGS}".strip()
    import jax

    jax.config.update("jax_disable_most_optimizations", True)


def _selects_e2e(markexpr: str) -> bool:
    """Whether ``-m markexpr`` may select end-to-end tests (the default, ``not slow and not e2e``,
    does not)."""
    return "e2e" in markexpr.replace("not e2e", "")


@pytest.hookimpl(trylast=True)  # after -m has deselected
def pytest_collection_modifyitems(config, items):
    _order_longest_first(config, items)


def _order_longest_first(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def place(item) -> int:
        try:
            path = item.path.relative_to(config.rootpath / "tests").as_posix()
        except ValueError:  # a test collected from outside tests/
            return len(LONGEST_FIRST)
        return rank.get(path, len(LONGEST_FIRST))

    items.sort(key=place)  # stable: the rest keep their order, and so do the tests within a file


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput"):  # the controller, once its workers are done
        for folder in _MADE_HERE:
            shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def tiny_config() -> CampaignConfig:
    """A small campaign (3 seeds + 4 steps, 10/3 shots, 40 x 30 grid) shared so it compiles once."""
    return TINY


@pytest.fixture
def tiny_yaml(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY.model_dump(mode="json")))
    return path


@pytest.fixture(scope="session")
def prefect_harness():
    """One temporary Prefect server for every test that runs flows."""
    import prefect.settings as settings
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        with settings.temporary_settings({settings.PREFECT_FLOWS_HEARTBEAT_FREQUENCY: None}):
            yield settings.PREFECT_API_URL.value()
