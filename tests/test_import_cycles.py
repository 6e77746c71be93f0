"""No module of noisebo imports itself in a circle: for every module that imports another, no chain
leads back (imports inside functions included). Checked on the checkout, which lays the package out
as it installs, so the adapters and the core are one graph."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

FIND_CYCLES = textwrap.dedent("""
    import json, sys
    import grimp
    graph = grimp.build_graph(sys.argv[1])
    found = set()
    for importer in graph.modules:
        for imported in graph.find_modules_directly_imported_by(importer):
            if imported != importer and graph.chain_exists(importer=imported, imported=importer):
                found.add(tuple(sorted((importer, imported))))
    print(json.dumps(sorted(found)))
""")


def cycles(package: str, where: Path) -> set[tuple[str, str]]:
    """The pairs of modules of ``package`` (found in the folder ``where``) that import each other
    through some chain, in a fresh interpreter."""
    out = subprocess.run(
        [sys.executable, "-c", FIND_CYCLES, package],
        cwd=where,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
        env={"PYTHONPATH": str(where), "PATH": ""},
    )
    return {tuple(pair) for pair in json.loads(out.stdout)}


def test_no_import_cycles():
    assert cycles("noisebo", ROOT) == set()


def test_a_cycle_is_found(tmp_path):
    root = tmp_path / "circular"
    root.mkdir()
    (root / "__init__.py").write_text("")
    (root / "base.py").write_text(
        textwrap.dedent("""
        def build():
            from circular.registry import make
            return make()
    """)
    )
    (root / "registry.py").write_text("from circular.base import build\n\ndef make():\n    return build\n")
    assert cycles("circular", tmp_path) == {("circular.base", "circular.registry")}
