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
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
from jax import export

ENVIRONMENT_VARIABLE = "NOISEBO_PROGRAM_CACHE"
_CORE = Path(__file__).resolve().parent


def program_dir() -> Path | None:
    """The folder programs are kept in, or None (off)."""
    value = os.environ.get(ENVIRONMENT_VARIABLE)
    return Path(value) if value else None


class _Loaded(NamedTuple):
    call: Callable  # (*leaves) -> output leaves
    out_tree: Any  # the output's PyTreeDef
    source: str  # "exported" (traced here) or "loaded" (from a file)


class Persisted:
    """A jitted function whose lowered programs are kept in ``program_dir()`` (see the module).
    Called like ``jax.jit(fn, static_argnums=static_argnums)``."""

    def __init__(self, name: str, fn: Callable, static_argnums: Sequence[int], depends_on: Sequence[object]):
        self.name, self._fn, self._static = name, fn, tuple(static_argnums)
        self._depends_on = tuple(depends_on)
        self._jitted = jax.jit(fn, static_argnums=self._static)
        self._loaded: dict[tuple, _Loaded] = {}
        self._lock = threading.Lock()

    def __call__(self, *args):
        folder = program_dir()
        if folder is None:
            return self._jitted(*args)
        statics = tuple(args[i] for i in self._static)
        dynamic = tuple(a for i, a in enumerate(args) if i not in self._static)
        leaves, tree = jax.tree_util.tree_flatten(dynamic)
        signature = (statics, tree, tuple(_leaf_signature(leaf) for leaf in leaves))
        loaded = self._loaded.get(signature)
        if loaded is None:
            with self._lock:
                loaded = self._loaded.get(signature) or self._load_or_export(folder, statics, tree, leaves)
                self._loaded[signature] = loaded
        return jax.tree_util.tree_unflatten(loaded.out_tree, loaded.call(*leaves))

    def sources(self) -> dict[tuple, str]:
        """How each argument structure's program came in this process: "exported" or "loaded"."""
        return {signature: loaded.source for signature, loaded in self._loaded.items()}

    def _load_or_export(self, folder: Path, statics: tuple, tree, leaves: list) -> _Loaded:
        avals = [jax.typeof(leaf) for leaf in leaves]
        path = folder / f"{self._key(statics, tree, avals)}.program"
        kept = _read(path)
        if kept is not None:
            exported, out_tree = kept
            _prepare_lapack()
            return _Loaded(jax.jit(exported.call), out_tree, "loaded")
        out_trees: list = []

        def flat(*flat_leaves):
            rebuilt = list(jax.tree_util.tree_unflatten(tree, flat_leaves))
            for index, value in zip(self._static, statics):
                rebuilt.insert(index, value)
            out = self._fn(*rebuilt)
            out_leaves, out_tree = jax.tree_util.tree_flatten(out)
            out_trees.append(out_tree)
            return out_leaves

        specs = [jax.ShapeDtypeStruct(a.shape, a.dtype, weak_type=a.weak_type) for a in avals]
        exported = export.export(jax.jit(flat))(*specs)
        _write(path, exported, out_trees[0])
        return _Loaded(jax.jit(exported.call), out_trees[0], "exported")

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


def persisted(
    name: str, fn: Callable, static_argnums: Sequence[int] = (), depends_on: Sequence[object] = ()
) -> Persisted:
    """``fn`` jitted, its programs kept across processes under ``name``: a name that says every
    config ``fn`` closes over. ``depends_on``: plugin classes or functions ``fn`` calls (a noise
    law, a policy) whose modules' source must key the programs too."""
    return Persisted(name, fn, static_argnums, depends_on)


def _leaf_signature(leaf) -> tuple:
    """What tells two calls' leaves apart cheaply: type, shape, dtype and weak typing."""
    return (type(leaf), getattr(leaf, "shape", None), str(getattr(leaf, "dtype", "")), getattr(leaf, "weak_type", None))


def _read(path: Path):
    """(Exported, output tree) kept in ``path``, or None when absent or unreadable."""
    try:
        kept = pickle.loads(path.read_bytes())
        return export.deserialize(bytearray(kept["exported"])), kept["out_tree"]
    except FileNotFoundError:
        return None
    except Exception:  # a torn, foreign or outdated file: export again and replace it
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
    jax.jit(jnp.linalg.cholesky).lower(jnp.eye(1))


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
