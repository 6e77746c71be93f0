"""JAX's persistent compilation cache for this process, as the command line uses it (see
``noisebo.flows.runtime``): the folder (data/cache/jax-<jaxlib>-<CPU fingerprint> of the checkout,
or of ~/.noisebo; NOISEBO_JAX_CACHE), its cap and its repair. Standard library only, and JAX's
flags set without importing JAX, so that every layer (the command line, the bluesky plan) can
turn it on."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]
CACHE_MAX_BYTES = 2 * 1024**3  # the whole test run, every kind of campaign, writes about 20 MB
CACHE_SUFFIX, ATIME_SUFFIX = "-cache", "-atime"  # JAX's names for an entry and its access time


def state_dir() -> Path:
    """.prefect / data/cache inside a source checkout; ~/.noisebo otherwise."""
    if (PROJECT_ROOT / "pyproject.toml").exists():
        return PROJECT_ROOT
    return Path.home() / ".noisebo"


def use_compilation_cache() -> None:
    """JAX's persistent compilation cache and the lowered programs beside it, as the command line
    uses them, for this process; NOISEBO_JAX_CACHE chooses the folder (empty: none), and without
    it a folder the process gave JAX itself (``jax_compilation_cache_dir``, JAX loaded) is kept. The bluesky plan calls
    it, so that a campaign in a user's own Python process loads the decision programs another
    process compiled instead of compiling them at its first decision."""
    cache = os.environ.get("NOISEBO_JAX_CACHE")
    if cache is None:
        if _chosen_cache_dir():
            return
        cache = str(state_dir() / "data" / "cache" / f"jax-{_jaxlib_version()}-{cpu_fingerprint()}")
    if not cache:
        return
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
    _jax_setting("jax_compilation_cache_dir", cache)
    _jax_setting("jax_persistent_cache_min_compile_time_secs", 0.0)
    _jax_setting("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
    os.environ.setdefault("NOISEBO_PROGRAM_CACHE", str(Path(cache) / "programs"))
    repair_cache(Path(cache))


def _chosen_cache_dir() -> bool:
    """Whether JAX is loaded with a compilation cache folder already (the process's own choice)."""
    return "jax" in sys.modules and bool(sys.modules["jax"].config.jax_compilation_cache_dir)


def repair_cache(folder: Path) -> int:
    """Give every entry of JAX's capped compilation cache in ``folder`` that lacks its access-time
    file one (now); returns how many. JAX writes an entry, then its access time; a process killed
    between the two leaves an entry without one, and from then on every process's next write to
    the cache reads all access times first, fails, and warns ("Error writing persistent
    compilation cache entry ... FileNotFoundError") instead of keeping the program. Listing the
    folder costs about a millisecond."""
    try:
        names = {entry.name for entry in os.scandir(folder)}
    except OSError:  # no cache yet
        return 0
    now = time.time_ns().to_bytes(8, "little")
    repaired = 0
    for name in names:
        key = name.removesuffix(CACHE_SUFFIX)
        if key != name and key + ATIME_SUFFIX not in names:
            try:
                (folder / (key + ATIME_SUFFIX)).write_bytes(now)
                repaired += 1
            except OSError:  # a read-only cache: JAX will not write to it either
                pass
    return repaired


def _jax_setting(name: str, value) -> None:
    """Set a JAX flag without importing JAX (0.3-0.5 s): JAX reads JAX_<NAME> from the environment
    when it loads, so a command that never computes never loads it; if it is loaded already, the
    flag is updated in place."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(name, value)
    else:
        os.environ[name.upper()] = str(value)


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
