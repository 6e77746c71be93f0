"""Policies and noise laws found by name: the entry-point groups ``noisebo.policies`` and
``noisebo.noise_laws``, as instrument drivers are found in ``noisebo.instruments``.

A package adds a policy (or a noise law) by declaring, in its pyproject.toml,

    [project.entry-points."noisebo.policies"]
    my-policy = "my_package.policy:MyPolicy"

    [project.entry-points."noisebo.noise_laws"]
    my-law = "my_package.law:MyLaw"

where ``MyPolicy`` is a class with the members of ``noisebo.acquisition.policies.Policy`` (subclass it to
inherit the defaults) and ``MyLaw`` one with those of ``noisebo.models.noise_laws.NoiseLaw``. The
entry point's name is what a config's ``acquisition.policy`` (``noise_model.mean``) says. The
built-in policies and laws register the same way in noisebo's own pyproject.toml.

Each class is loaded once and made once (no arguments); the compiled programs are keyed by the
name, so a policy or law is used inside jitted functions as a fixed set of pure functions of
arrays. A plug-in that cannot be imported or lacks a member is ``PluginBroken``, named in one
line; it stops only the configs that name it.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import Any
from importlib.metadata import entry_points

POLICIES = "noisebo.policies"
NOISE_LAWS = "noisebo.noise_laws"

KINDS = {POLICIES: "policy", NOISE_LAWS: "noise law"}
COMMANDS = {POLICIES: "noisebo policies", NOISE_LAWS: "noisebo policies"}
REQUIRED = {
    POLICIES: ("acquisition_map", "point_scores", "uses_spread", "chooses_shots", "paper"),
    NOISE_LAWS: ("mean", "combine", "share", "infers_exponent", "sources_power"),
}


class PluginNotInstalled(ValueError):
    """No installed policy (noise law) has the name a config asks for."""


class PluginBroken(ValueError):
    """An installed policy (noise law) that cannot be loaded or lacks a member."""


@dataclass(frozen=True)
class Installed:
    """One installed plug-in: its name, the object path its entry point names, and the
    distribution (package) that provides it."""

    name: str
    target: str
    distribution: str
    distribution_version: str


def installed(group: str) -> dict[str, Installed]:
    """Every plug-in installed in ``group`` by name (not loaded)."""
    return dict(_installed(group, _path_state()))


def _path_state() -> tuple:
    """sys.path with each entry's modification time: what installing or removing a package
    changes. Reading the entry points again only then spares a decision 0.1 s of rescans."""
    state: list[tuple[str, int | None]] = []
    for entry in sys.path:
        try:
            state.append((entry, os.stat(entry or ".").st_mtime_ns))
        except OSError:
            state.append((entry, None))
    return tuple(state)


@lru_cache(maxsize=16)
def _installed(group: str, path_state: tuple) -> tuple[tuple[str, Installed], ...]:
    out = {}
    for ep in entry_points(group=group):
        dist = getattr(ep, "dist", None)
        out[ep.name] = Installed(ep.name, ep.value, dist.name if dist else "?", dist.version if dist else "?")
    return tuple(sorted(out.items()))


def names(group: str) -> tuple[str, ...]:
    """The installed names in ``group``, sorted."""
    return tuple(installed(group))


def not_installed(group: str, name: object) -> str:
    """The one line that says ``name`` is not installed in ``group`` and what is."""
    return (
        f"no installed {KINDS[group]} {name!r}; installed: {', '.join(installed(group)) or 'none'} "
        f"(`{COMMANDS[group]}` lists them; a package registers one in the entry-point group {group!r})"
    )


@lru_cache(maxsize=None)
def _load(group: str, name: str, target: str):
    from importlib.metadata import EntryPoint

    try:
        cls = EntryPoint(name, target, group).load()
    except Exception as error:  # noqa: BLE001 - any import failure of a third-party package
        raise PluginBroken(
            f"{KINDS[group]} {name!r} ({target}) could not be loaded: {type(error).__name__}: {error}"
        ) from None
    missing = [member for member in REQUIRED[group] if not hasattr(cls, member)]
    if missing:
        raise PluginBroken(f"{KINDS[group]} {name!r} ({target}) lacks {', '.join(missing)}")
    try:
        return cls() if isinstance(cls, type) else cls
    except Exception as error:  # noqa: BLE001
        raise PluginBroken(
            f"{KINDS[group]} {name!r} ({target}) could not be made: {type(error).__name__}: {error}"
        ) from None


_FOUND: dict[tuple[str, str], object] = {}  # what a name loaded to: the entry points are read once per name


def load(group: str, name: str):
    """The plug-in registered as ``name`` in ``group`` (one instance per installed target);
    ``PluginNotInstalled`` or ``PluginBroken`` with a one-line message otherwise."""
    known = _FOUND.get((group, name)) if isinstance(name, str) else None
    if known is not None:
        return known
    found = installed(group).get(name) if isinstance(name, str) else None
    if found is None:
        raise PluginNotInstalled(not_installed(group, name))
    _FOUND[(group, name)] = plugin = _load(group, name, found.target)
    return plugin


def policy(name: str):
    """The policy named ``name`` (``acquisition.policy``)."""
    return load(POLICIES, name)


def noise_law(name: str):
    """The noise law named ``name`` (``noise_model.mean``)."""
    return load(NOISE_LAWS, name)


def policy_names() -> tuple[str, ...]:
    return names(POLICIES)


def noise_law_names() -> tuple[str, ...]:
    return names(NOISE_LAWS)


def _loadable_policies() -> list[tuple[str, Any]]:
    out = []
    for name in policy_names():
        try:
            out.append((name, policy(name)))
        except PluginBroken:
            continue
    return out


def paper_policies() -> tuple[str, ...]:
    """The installed policies that are the paper's (a sweep's ``both``): those whose class gives
    ``paper`` a rank (1: reward, 2: double), in that order; broken ones are left out."""
    ranked = sorted((int(p.paper), name) for name, p in _loadable_policies() if p.paper)
    return tuple(name for _, name in ranked)


def working_policies() -> tuple[str, ...]:
    """Every installed policy that loads (a sweep's ``all``): the paper's first, then the others
    by name."""
    paper = paper_policies()
    return paper + tuple(name for name, _ in _loadable_policies() if name not in paper)


def checked(group: str, name: object, load_it: bool = True) -> str:
    """``name`` when it names a loadable plug-in of ``group`` (with ``load_it`` false: an
    installed one, not loaded yet); ValueError with one line otherwise (a config's validator)."""
    if not isinstance(name, str):
        raise PluginNotInstalled(f"expected the name of a {KINDS[group]}, got {name!r}")
    if load_it:
        load(group, name)
    elif (group, name) not in _FOUND and name not in installed(group):
        raise PluginNotInstalled(not_installed(group, name))
    return name


def chosen_policies(choice: str) -> tuple[str, ...]:
    """What a command's ``--policy`` means: "both" the paper's two, "all" every installed policy
    that loads, otherwise the one policy named."""
    if choice == "both":
        return paper_policies()
    if choice == "all":
        return working_policies()
    return (choice,)
