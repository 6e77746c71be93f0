"""The core package imports no adapter: no orchestration, storage, live view, network or driver."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[2] / "noisebo"
FORBIDDEN = {"prefect", "h5py", "rerun", "fastapi", "uvicorn", "instruments", "flows", "tasks", "storage", "view",
             "cli", "bridge", "starlette", "matplotlib", "httpx", "prefect_dask", "dask"}


def imported_roots(path: Path) -> set[str]:
    """Top-level names of every import in a module, including imports inside functions."""
    roots = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("module", sorted(p.relative_to(CORE).as_posix() for p in CORE.rglob("*.py")))
def test_no_core_module_imports_an_adapter(module):
    assert not imported_roots(CORE / module) & FORBIDDEN


def test_importing_the_whole_core_loads_no_adapter():
    modules = [".".join(("noisebo", *p.relative_to(CORE).with_suffix("").parts)).removesuffix(".__init__")
               for p in CORE.rglob("*.py")]
    code = (f"import importlib, sys\nfor m in {modules!r}: importlib.import_module(m)\n"
            f"print(sorted({{m.split('.')[0] for m in sys.modules}} & {FORBIDDEN!r}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_checker_sees_an_import_inside_a_function(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    import h5py.h5f\n    from prefect import flow\n")
    assert imported_roots(module) == {"h5py", "prefect"}
