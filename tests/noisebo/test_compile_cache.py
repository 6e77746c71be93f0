"""The compilation cache a process turns on without the command line (the bluesky plan does):
NOISEBO_JAX_CACHE chooses the folder, a folder the process gave JAX itself is kept, and an empty
NOISEBO_JAX_CACHE turns it off."""

import os
import subprocess
import sys

import pytest

CODE = """
import os, sys
{before}
from noisebo.compile_cache import use_compilation_cache
use_compilation_cache()
import jax
print(jax.config.jax_compilation_cache_dir, os.environ.get("NOISEBO_PROGRAM_CACHE"))
"""


@pytest.mark.parametrize(
    "before, jax_cache, expected",
    [
        ("", "{tmp}/mine", "{tmp}/mine {tmp}/mine/programs"),
        ("", "", "None None"),
        (
            "import jax; jax.config.update('jax_compilation_cache_dir', '{tmp}/own')",
            None,
            "{tmp}/own None",
        ),
    ],
    ids=["NOISEBO_JAX_CACHE", "turned off", "the process's own folder"],
)
def test_a_process_gets_the_cache_noisebo_run_uses_unless_it_chose_otherwise(tmp_path, before, jax_cache, expected):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NOISEBO_JAX_CACHE", "NOISEBO_PROGRAM", "JAX_"))}
    if jax_cache is not None:
        env["NOISEBO_JAX_CACHE"] = jax_cache.format(tmp=tmp_path)
    code = CODE.format(before=before.format(tmp=tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == expected.format(tmp=tmp_path)
