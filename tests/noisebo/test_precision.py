"""`import noisebo` changes nothing in the process, and noisebo computes in float64 all the same.

Each check runs in a fresh interpreter with JAX in its default, 32-bit mode: the lab's own JAX
code there keeps computing in float32 before and after a campaign, and the campaign decides
exactly what it decides in a process that turned JAX's 64-bit mode on for everything.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DECISIONS = ROOT / "benchmarks" / "compare_decisions.py"


# What noisebo.flows.runtime.configure() sets (the test process has run it), so a fresh process
# starts without them: an import that set them again would show.
CONFIGURED = {
    "JAX_ENABLE_X64",
    "OPENBLAS_NUM_THREADS",
    "DO_NOT_TRACK",
    "PREFECT_SERVER_ANALYTICS_ENABLED",
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS",
    "PREFECT_LOGGING_LEVEL",
    "TQDM_DISABLE",
    "TF_CPP_MIN_LOG_LEVEL",
    "NOISEBO_PROGRAM_CACHE",
    "JAX_COMPILATION_CACHE_DIR",
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
    "JAX_COMPILATION_CACHE_MAX_SIZE",
}


def fresh(code: str | Path, *args: str, **env: str) -> subprocess.CompletedProcess:
    """``code`` (a script's path, or Python source) in a new interpreter, without the settings
    ``CONFIGURED`` (JAX in its default mode) unless ``env`` gives them."""
    clean = {k: v for k, v in os.environ.items() if k not in CONFIGURED}
    return subprocess.run(
        [sys.executable, *([str(code)] if isinstance(code, Path) else ["-c", code]), *args],
        env={**clean, **env},
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )


@pytest.mark.parametrize(
    "modules",
    ["noisebo, noisebo.config, noisebo.campaign.driver, noisebo.instruments", "noisebo.flows, noisebo.flows.campaign"],
    ids=["core", "flows"],
)
def test_importing_noisebo_sets_nothing_in_the_process(modules):
    code = (
        # JAX sets two variables of its own when it loads (TF_CPP_MIN_LOG_LEVEL, TPU_SKIP_MDS_QUERY)
        "import os, json, jax, jax.numpy as jnp\nbefore = dict(os.environ)\n"
        f"import {modules}\n"
        "changed = sorted(k for k in set(before) | set(os.environ) if before.get(k) != os.environ.get(k))\n"
        "cache = jax.config.jax_compilation_cache_dir\n"
        "print(json.dumps([changed, bool(jax.config.jax_enable_x64), str(jnp.ones(2).dtype), cache]))"
    )
    changed, x64, dtype, cache = json.loads(fresh(code).stdout)
    assert changed == [] and x64 is False and dtype == "float32" and not cache


def test_a_campaign_leaves_the_process_in_float32_and_computes_in_float64():
    code = (
        "import json, jax, jax.numpy as jnp\n"
        "from noisebo.config import load_config\nfrom noisebo.instruments import build\n"
        "from noisebo.campaign.driver import run_campaign\nfrom noisebo.keys import FIT, jax_key\n"
        "mine = jax.jit(lambda a: a * 2)\nbefore = str(mine(jnp.ones(2)).dtype)\n"
        f"config = load_config({str(ROOT / 'data' / 'configs' / 'forrester.yaml')!r}).with_overrides("
        "schedule={'n_steps': 1})\n"
        "run = run_campaign(config, build(config.instrument), 0)\n"
        "after = str(mine(jnp.ones(2)).dtype)\n"
        "fitted = run.decisions[-1].hyperparameters\n"
        "dtypes = sorted({str(getattr(v, 'dtype', type(v).__name__)) for v in fitted.values()})\n"
        "print(json.dumps([before, after, bool(jax.config.jax_enable_x64), str(jax_key(0, FIT).dtype), dtypes]))"
    )
    before, after, x64, key_dtype, dtypes = json.loads(fresh(code).stdout)
    assert (before, after, x64) == ("float32", "float32", False)
    assert key_dtype == "uint32"
    assert "float32" not in dtypes


@pytest.mark.parametrize("campaign", ["forrester-reward-s0", "forrester_posterior-valued-budget-s0"])
def test_decisions_are_the_same_with_or_without_64_bit_mode(tmp_path, campaign):
    runs = {}
    for mode, env in {"default": {}, "x64": {"JAX_ENABLE_X64": "1"}}.items():
        out = tmp_path / f"{mode}.json"
        fresh(DECISIONS, "--only", campaign, "--json", str(out), **env)
        runs[mode] = json.loads(out.read_text())
    assert runs["default"] == runs["x64"]
    assert runs["default"][campaign]["decisions"]
