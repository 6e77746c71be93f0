"""No package imports itself in a circle: for every module that imports another of its package,
no chain leads back (imports inside functions included). storage is left out: storage.hdf5 and
storage.live still import each other (a lazy import back), to be split with the typed read side."""

import textwrap

import grimp
import pytest

PACKAGES = ("noisebo", "instruments", "tasks", "flows")


def cycles(package: str) -> list[tuple[str, str]]:
    graph = grimp.build_graph(package)
    found = set()
    for importer in graph.modules:
        for imported in graph.find_modules_directly_imported_by(importer):
            if imported != importer and graph.chain_exists(importer=imported, imported=importer):
                found.add(tuple(sorted((importer, imported))))
    return sorted(found)


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycles(package):
    assert cycles(package) == []


def test_a_cycle_is_found(tmp_path, monkeypatch):
    root = tmp_path / "circular"
    root.mkdir()
    (root / "__init__.py").write_text("")
    (root / "base.py").write_text(textwrap.dedent("""
        def build():
            from circular.registry import make
            return make()
    """))
    (root / "registry.py").write_text("from circular.base import build\n\ndef make():\n    return build\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert cycles("circular") == [("circular.base", "circular.registry")]
