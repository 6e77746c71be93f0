"""Process-wide settings for running campaigns: Prefect's local home and quiet defaults, and
JAX's persistent compilation cache. Environment variables already set win.

The cache keeps compiled decision programs between processes, so a campaign's first decision
on a machine that has run one before loads them instead of compiling (about 10 s -> 3 s here,
benchmarks/scaling.py --cold). It lives in data/cache/jax-<jaxlib>-<CPU fingerprint> of the
checkout (or of ~/.noisebo): programs compiled for one CPU are never loaded on another, even from a
shared home directory. NOISEBO_JAX_CACHE=DIR puts it elsewhere; NOISEBO_JAX_CACHE= (empty) turns
it off. XLA:CPU logs two alarming, harmless error lines per program it loads (tuning flags it
mistakes for missing CPU features: openxla/xla#44565), so with the cache on, XLA's own C++ log
is kept to fatal messages (TF_CPP_MIN_LOG_LEVEL=3) unless that variable is set.

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
    cache = os.environ.get("NOISEBO_JAX_CACHE")
    if cache is None:
        cache = str(base / "data" / "cache" / f"jax-{_jaxlib_version()}-{cpu_fingerprint()}")
    if cache:
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
        import jax

        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def _jaxlib_version() -> str:
    import importlib.metadata

    return importlib.metadata.version("jaxlib")


def cpu_fingerprint() -> str:
    """A short hash of this CPU's model and instruction-set flags (/proc/cpuinfo; elsewhere the
    platform's processor string)."""
    import hashlib
    import platform

    try:
        lines = Path("/proc/cpuinfo").read_text(errors="replace").splitlines()
        wanted = sorted({line for line in lines if line.split(":")[0].strip() in ("model name", "flags")})
        text = "\n".join(wanted)
    except OSError:
        text = f"{platform.machine()} {platform.processor()}"
    return hashlib.sha256(text.encode()).hexdigest()[:12]

