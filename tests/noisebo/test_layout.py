"""The core package imports no adapter: no orchestration, storage, live view, network or driver."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "noisebo"
ADAPTERS = {"flows", "tasks", "instruments", "storage", "view", "cli", "bridge", "beamline"}
CORE_FILES = sorted(
    p for p in PACKAGE.rglob("*.py") if p.relative_to(PACKAGE).parts[0] not in ADAPTERS | {"configs", "scans"}
)
FORBIDDEN = {f"noisebo.{name}" for name in ADAPTERS} | {
    "prefect",
    "h5py",
    "rerun",
    "fastapi",
    "uvicorn",
    "starlette",
    "matplotlib",
    "httpx",
    "prefect_dask",
    "dask",
    "bluesky",
    "ophyd_async",
    "softioc",
    "aioca",
}


def forbidden_in(name: str) -> set[str]:
    """The forbidden packages (FORBIDDEN) that the dotted module ``name`` is or lies in."""
    return {f for f in FORBIDDEN if name == f or name.startswith(f + ".")}


def imported_names(path: Path) -> set[str]:
    """Dotted names of every import in a module, including imports inside functions
    ("from a.b import c" gives a.b and a.b.c: c may be a module)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return names


def forbidden_imports(path: Path) -> set[str]:
    return set().union(*(forbidden_in(name) for name in imported_names(path)))


def test_the_core_is_what_remains_of_the_package():
    assert {p.relative_to(PACKAGE).parts[0] for p in CORE_FILES} >= {"models", "acquisition", "campaign", "config"}
    assert all(p.resolve().is_relative_to(PACKAGE) for p in CORE_FILES)  # no linked adapter folder among them


@pytest.mark.parametrize("module", [p.relative_to(PACKAGE).as_posix() for p in CORE_FILES])
def test_no_core_module_imports_an_adapter(module):
    assert forbidden_imports(PACKAGE / module) == set()


def test_importing_the_whole_core_loads_no_adapter():
    modules = [
        ".".join(("noisebo", *p.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(".__init__")
        for p in CORE_FILES
    ]
    code = (
        f"import importlib, sys\nfor m in {modules!r}: importlib.import_module(m)\n"
        f"print(sorted(m for m in sys.modules if any(m == f or m.startswith(f + '.') for f in {sorted(FORBIDDEN)!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_checker_sees_an_import_inside_a_function(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "def f():\n    import h5py.h5f\n    from prefect import flow\n    from noisebo import storage\n"
        "    from noisebo import config\n"
    )
    assert forbidden_imports(module) == {"h5py", "prefect", "noisebo.storage"}
