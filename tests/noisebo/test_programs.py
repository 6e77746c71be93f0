"""Programs kept traced across processes (noisebo.programs): what keys a file, that a kept
program gives what the plain jitted one gives, that a torn or unwritable file costs nothing but
time, and, in fresh processes, that a decision's fits load instead of trace and come out the same."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from noisebo import programs
from noisebo.programs import persisted

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def kept(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "programs"
    monkeypatch.setenv(programs.ENVIRONMENT_VARIABLE, str(folder))
    return folder


def _solve(a, b, scale):
    """A Cholesky solve (a LAPACK call on the CPU) scaled by a static number."""
    chol = jnp.linalg.cholesky(a @ a.T + jnp.eye(a.shape[0]))
    return {"x": jax.scipy.linalg.cho_solve((chol, True), b) * scale, "n": jnp.sum(b)}


A, B = np.arange(9.0).reshape(3, 3) / 9, np.array([1.0, 2.0, 3.0])


def _program(name="solve"):
    return persisted(name, _solve, static_argnums=(2,))


def test_off_it_is_plain_jit_and_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv(programs.ENVIRONMENT_VARIABLE, raising=False)
    out = _program()(A, B, 2.0)
    assert np.array_equal(out["x"], jax.jit(_solve, static_argnums=(2,))(A, B, 2.0)["x"])
    assert programs.program_dir() is None and not list(tmp_path.iterdir())


def test_a_kept_program_gives_the_jitted_programs_values_and_a_new_instance_loads_it(kept):
    plain = jax.jit(_solve, static_argnums=(2,))(A, B, 2.0)
    first = _program()
    out = first(A, B, 2.0)
    assert list(first.sources().values()) == ["exported"]
    assert len(list(kept.glob("*.program"))) == 1
    again = _program()  # as a new process would: nothing traced in memory
    loaded = again(A, B, 2.0)
    assert list(again.sources().values()) == ["loaded"]
    for result in (out, loaded):
        assert np.array_equal(result["x"], plain["x"]) and float(result["n"]) == 6.0


@pytest.mark.parametrize(
    "call",
    [
        pytest.param(lambda p: p(A, B, 3.0), id="another static argument"),
        pytest.param(lambda p: p(np.eye(4), np.ones(4), 2.0), id="another shape"),
        pytest.param(lambda p: p(A.astype(np.float32), B.astype(np.float32), 2.0), id="another dtype"),
        pytest.param(lambda p: _program("another name")(A, B, 2.0), id="another name"),
    ],
)
def test_each_difference_that_changes_the_program_is_another_file(kept, call):
    _program()(A, B, 2.0)
    call(_program())
    assert len(list(kept.glob("*.program"))) == 2


def test_a_torn_file_is_exported_again_and_replaced(kept):
    _program()(A, B, 2.0)
    (path,) = kept.glob("*.program")
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])
    fresh = _program()
    out = fresh(A, B, 2.0)
    assert list(fresh.sources().values()) == ["exported"]
    assert np.allclose(out["x"], jax.jit(_solve, static_argnums=(2,))(A, B, 2.0)["x"])
    assert path.read_bytes() != good[: len(good) // 2]  # written whole again
    assert not list(kept.glob("*.partial"))
    reader = _program()
    reader(A, B, 2.0)
    assert list(reader.sources().values()) == ["loaded"]


def test_a_folder_that_cannot_be_written_keeps_nothing_and_the_program_runs(tmp_path, monkeypatch):
    blocker = tmp_path / "a file"
    blocker.write_text("")
    monkeypatch.setenv(programs.ENVIRONMENT_VARIABLE, str(blocker / "programs"))
    out = _program()(A, B, 2.0)
    assert float(out["n"]) == 6.0


def test_a_program_that_cannot_be_exported_runs_and_keeps_nothing(kept):
    """A host callback (a plug-in might call one) cannot be serialised: traced in place instead."""

    def with_callback(x):
        doubled = jax.pure_callback(lambda v: np.asarray(v) * 2, jax.ShapeDtypeStruct(x.shape, x.dtype), x)
        return doubled + 1

    program = persisted("callback", with_callback)
    assert np.array_equal(program(B), B * 2 + 1)
    assert list(program.sources().values()) == ["not kept"] and not list(kept.glob("*.program"))


def test_a_plugin_module_keys_the_programs(kept, tmp_path):
    """A noise law or policy from outside noisebo: its module's source is in the key, so an
    edited plugin never loads the program traced from the old one."""
    plugin = tmp_path / "plugin_law.py"
    plugin.write_text("class Law:\n    pass\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import plugin_law

        persisted("solve", _solve, (2,), depends_on=(plugin_law.Law,))(A, B, 2.0)
        plugin.write_text("class Law:\n    scale = 2\n")
        persisted("solve", _solve, (2,), depends_on=(plugin_law.Law,))(A, B, 2.0)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("plugin_law", None)
    assert len(list(kept.glob("*.program"))) == 2


FIT = textwrap.dedent(
    """
    import json, sys
    from noisebo.flows import runtime
    runtime.configure()
    from noisebo.acquisition.method import Method
    from noisebo.campaign.compile_ahead import stand_in_seeds
    from noisebo.config import load_config
    from noisebo.models.fitting import fit_key, fit_models, hyperparameters
    config = load_config(sys.argv[1])
    fitted = fit_models(config, Method.of(config).noise_law, stand_in_seeds(config, 0), fit_key(0, 0))
    print(json.dumps({"hyperparameters": {k: repr(v) for k, v in hyperparameters(fitted).items()}}))
    """
)


def _fit_in_a_new_process(tmp_path: Path, folder: str) -> dict:
    script = tmp_path / "fit.py"
    script.write_text(FIT)
    env = {**os.environ, "NOISEBO_JAX_CACHE": str(tmp_path / "jax"), programs.ENVIRONMENT_VARIABLE: folder}
    done = subprocess.run(
        [sys.executable, str(script), str(ROOT / "data" / "configs" / "forrester.yaml")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.e2e  # real processes (CI runs -m e2e)
def test_in_new_processes_a_decisions_fits_load_their_programs_and_come_out_the_same(tmp_path):
    """Three processes fit the first decision's models: without kept programs, exporting them,
    and loading them (the case that crashed before LAPACK was prepared). The hyperparameters
    agree to the last bit."""
    folder = tmp_path / "programs"
    plain = _fit_in_a_new_process(tmp_path, "")
    exported = _fit_in_a_new_process(tmp_path, str(folder))
    files = sorted(folder.glob("*.program"))
    loaded = _fit_in_a_new_process(tmp_path, str(folder))
    assert files and sorted(folder.glob("*.program")) == files  # nothing new: all loaded
    assert plain == exported == loaded
