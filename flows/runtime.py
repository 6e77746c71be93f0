"""Process-wide settings for running campaigns: Prefect's local home and quiet defaults, and
(opt-in, with NOISEBO_JAX_CACHE=DIR) JAX's persistent compilation cache. Environment variables
already set win. The cache is off by default: it saves only about 1 s per process here, and
XLA:CPU prints alarming (harmless) machine-feature warnings when it loads cached programs.

``configure()`` runs when the ``flows`` package is imported, before Prefect is.
"""

from __future__ import annotations

import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def _state_dir() -> Path:
    """.prefect / data/cache inside a source checkout; ~/.noisebo otherwise."""
    if (PROJECT_ROOT / "pyproject.toml").exists():
        return PROJECT_ROOT
    return Path.home() / ".noisebo"


def configure() -> None:
    base = _state_dir()
    defaults = {
        "PREFECT_HOME": str(base / ".prefect"),
        "DO_NOT_TRACK": "1",
        "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "120",
        "PREFECT_LOGGING_LEVEL": "WARNING",
        "TQDM_DISABLE": "1",
    }
    for key, value in defaults.items():
        os.environ.setdefault(key, value)
    cache = os.environ.get("NOISEBO_JAX_CACHE", "")
    if cache:
        import jax

        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

