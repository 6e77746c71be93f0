"""The campaign configurations shipped with noisebo (package data ``noisebo.configs``), and how a
command's CONFIG argument finds its file: a path when one exists there, else a shipped config by
name (``forrester`` or ``forrester.yaml``).

    noisebo config                 # the shipped configs, one line each
    noisebo config forrester       # one of them, to start your own: noisebo config forrester > my.yaml
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from noisebo.storage.integrity import CampaignFileError


def shipped() -> dict[str, Path]:
    """Every shipped config by name (its file name without .yaml), sorted."""
    folder = resources.files("noisebo.configs")
    found = {Path(item.name).stem: Path(str(item)) for item in folder.iterdir() if item.name.endswith(".yaml")}
    return dict(sorted(found.items()))


def summary(path: Path) -> str:
    """A config's first comment line (what it is), or ''."""
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
        if line.strip():
            return ""
    return ""


def config_path(text: str) -> Path:
    """The file a command's CONFIG argument names: the path when a file is there, else the shipped
    config of that name; a one-line error naming both otherwise."""
    path = Path(text).expanduser()
    if path.exists():
        return path
    name = path.name.removesuffix(".yaml").removesuffix(".yml")
    if path.parent == Path(".") and name in (found := shipped()):
        return found[name]
    from noisebo.config import ConfigError

    raise ConfigError(
        f"{text}: cannot read config (no such file, and no shipped config of that name; shipped: "
        f"{', '.join(shipped())})"
    )


def run(args) -> int:
    """`noisebo config [NAME]`."""
    found = shipped()
    if args.name is None:
        width = max(map(len, found))
        for name, path in found.items():
            print(f"{name:<{width}}  {summary(path)}".rstrip())
        return 0
    name = args.name.removesuffix(".yaml")
    if name not in found:
        raise CampaignFileError(f"no shipped config {args.name!r}; shipped: {', '.join(found)}")
    print(found[name].read_text(encoding="utf-8"), end="")
    return 0


def add_parser(commands) -> None:
    config = commands.add_parser("config", help="list the shipped campaign configs, or print one to start from")
    config.add_argument("name", nargs="?", default=None, help="a shipped config, e.g. forrester (none: list them)")
    config.set_defaults(handler=run)
