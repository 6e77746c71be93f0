"""Decision programs kept traced across processes.

A decision's programs (the MAP fit's pieces, the prediction, the proposal) are jitted functions.
In a fresh process, tracing and lowering them is most of the first decision's time (1.7 s of a
manual ``noisebo tell`` that decides), and JAX's persistent compilation cache does not save it:
it keeps the compiled executables, found by the lowered module, which each process must first
make again. ``persisted`` keeps the lowered module too. The first call of a program with a given
argument structure exports it (``jax.export``) to a file; a later process reads that file instead
of tracing, and the compilation cache supplies the executable.

Off (``persisted`` is then plain ``jax.jit``) unless the environment variable
``NOISEBO_PROGRAM_CACHE`` names a folder; ``noisebo.flows.runtime.configure`` sets it beside the
compilation cache. A file is found by a hash of:

- the program's name, which must say everything the traced function closes over (the configs
  it was built from);
- its static arguments, and the structure, shapes and dtypes of the others;
- the versions of jax, jaxlib and numpyro, the backend and the x64 flag;
- the source of noisebo's core, and of every plugin module the program depends on.

So a changed config, model, plugin or package never loads another's program. A file that cannot
be read is exported again and replaced; writes are atomic, so processes may share the folder.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import inspect
import json
import os
import pickle
import threading
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
from jax import export

ENVIRONMENT_VARIABLE = "NOISEBO_PROGRAM_CACHE"
_CORE = Path(__file__).resolve().parent


def program_dir() -> Path | None:
    """The folder programs are kept in, or None (off)."""
    value = os.environ.get(ENVIRONMENT_VARIABLE)
    return Path(value) if value else None


class Persisted:
    """A jitted function whose lowered programs are kept in ``program_dir()`` (see the module).
    Called like ``jax.jit(fn, static_argnums=static_argnums)``; kept or not, a call costs what a
    jitted function's call costs: which program to load or export is decided while JAX traces
    the call, once per argument structure."""

    def __init__(self, name: str, fn: Callable, static_argnums: Sequence[int], depends_on: Sequence[object]):
        self.name, self._fn, self._static = name, fn, tuple(static_argnums)
        self._depends_on = tuple(depends_on)
        self._jitted = jax.jit(fn, static_argnums=self._static)
        self._kept = jax.jit(self._through_kept_program, static_argnums=self._static)
        self._sources: dict[str, str] = {}

    def __call__(self, *args):
        if os.environ.get(ENVIRONMENT_VARIABLE):
            return self._kept(*args)
        return self._jitted(*args)

    def sources(self) -> dict[str, str]:
        """How each program this process used came, by file name: "exported" (traced here and
        kept), "loaded" (from its file), or "not kept" (one that cannot be exported, such as a
        host callback's: traced here, as plain ``jax.jit`` would)."""
        return dict(self._sources)

    def _through_kept_program(self, *args):
        """Runs while JAX traces a call (``args`` hold tracers): the call's program, loaded from
        its file, or exported and kept."""
        folder = program_dir()
        assert folder is not None  # the call came through ``_kept``
        statics = tuple(args[i] for i in self._static)
        dynamic = tuple(a for i, a in enumerate(args) if i not in self._static)
        leaves, tree = jax.tree_util.tree_flatten(dynamic)
        avals = [jax.typeof(leaf) for leaf in leaves]
        path = folder / f"{self._key(statics, tree, avals)}.program"
        kept = _read(path)
        if kept is None:
            try:
                exported, out_tree = self._export(statics, tree, avals)
            except Exception:  # noqa: BLE001 - e.g. a plug-in's host callback, which no export may hold
                self._sources[path.name] = "not kept"
                return self._fn(*args)  # traced here, as plain jax.jit would
            _write(path, exported, out_tree)
            self._sources[path.name] = "exported"
        else:
            exported, out_tree = kept
            _prepare_lapack()
            self._sources[path.name] = "loaded"
        return jax.tree_util.tree_unflatten(out_tree, exported.call(*leaves))

    def _export(self, statics: tuple, tree, avals: list):
        """(Exported, output tree) of ``fn`` for these static values and argument avals."""
        out_trees: list = []

        def flat(*flat_leaves):
            rebuilt = list(jax.tree_util.tree_unflatten(tree, flat_leaves))
            for index, value in zip(self._static, statics):
                rebuilt.insert(index, value)
            out_leaves, out_tree = jax.tree_util.tree_flatten(self._fn(*rebuilt))
            out_trees.append(out_tree)
            return out_leaves

        specs = [jax.ShapeDtypeStruct(a.shape, a.dtype, weak_type=a.weak_type) for a in avals]
        exported = export.export(jax.jit(flat))(*specs)
        return exported, out_trees[0]

    def _key(self, statics: tuple, tree, avals: list) -> str:
        described = [
            self.name,
            repr(statics),
            str(tree),
            [str(a) for a in avals],
            _versions(),
            jax.default_backend(),
            bool(jax.config.read("jax_enable_x64")),
            _core_fingerprint(),
            [_module_fingerprint(obj) for obj in self._depends_on],
        ]
        return hashlib.sha256(json.dumps(described).encode()).hexdigest()[:32]


def label(plugin: object) -> str:
    """A plug-in object's class as a program name says it: ``module.QualifiedName``."""
    kind = plugin if isinstance(plugin, type) else type(plugin)
    return f"{kind.__module__}.{kind.__qualname__}"


def persisted(
    name: str, fn: Callable, static_argnums: Sequence[int] = (), depends_on: Sequence[object] = ()
) -> Persisted:
    """``fn`` jitted, its programs kept across processes under ``name``: a name that says every
    config ``fn`` closes over. ``depends_on``: plugin classes or functions ``fn`` calls (a noise
    law, a policy) whose modules' source must key the programs too."""
    return Persisted(name, fn, static_argnums, depends_on)


def _read(path: Path):
    """(Exported, output tree) kept in ``path``, or None when absent or unreadable."""
    try:
        kept = pickle.loads(path.read_bytes())
        return export.deserialize(bytearray(kept["exported"])), kept["out_tree"]
    except Exception:  # absent, or a torn, foreign or outdated file: export again and replace it
        return None


def _write(path: Path, exported, out_tree) -> None:
    """Write atomically (a temporary file renamed), so a reader never sees half a file; a folder
    that cannot be written keeps nothing, silently: the program still runs."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.{threading.get_ident()}.partial")
        partial.write_bytes(pickle.dumps({"exported": exported.serialize(), "out_tree": out_tree}))
        os.replace(partial, path)
    except OSError:
        return


@lru_cache(maxsize=None)
def _prepare_lapack() -> None:
    """Load jaxlib's LAPACK kernels, as lowering a LAPACK operation does: a deserialised program
    that calls them in a process that never lowered one crashes (jax-ml/jax#29610)."""
    jax.jit(jnp.linalg.cholesky).lower(jax.ShapeDtypeStruct((1, 1), jnp.float32))


@lru_cache(maxsize=None)
def _versions() -> dict[str, str]:
    return {name: importlib.metadata.version(name) for name in ("jax", "jaxlib", "numpyro")}


@lru_cache(maxsize=None)
def _core_fingerprint() -> str:
    """A hash of every Python source file of noisebo's core (this package's folder)."""
    digest = hashlib.sha256()
    for path in sorted(_CORE.rglob("*.py")):
        digest.update(path.relative_to(_CORE).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _module_fingerprint(obj: object) -> str:
    """A hash of the source file that defines ``obj`` (its class for an instance); the core's
    modules are in the core's fingerprint already."""
    target = obj if inspect.isclass(obj) or inspect.isfunction(obj) else type(obj)
    source = inspect.getsourcefile(target)  # type: ignore[arg-type]
    if source is None or Path(source).resolve().is_relative_to(_CORE):
        return ""
    return hashlib.sha256(Path(source).read_bytes()).hexdigest()
