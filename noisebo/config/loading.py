"""Reading configs from YAML: the format's version and the migration of older ones, a noise profile
given by its path, errors named field by field."""

from __future__ import annotations

from pathlib import Path
from typing import Any
import yaml
from pydantic import (
    ValidationError,
)
from noisebo.config.numbers import ConfigError
from noisebo.config.profile_format import PROFILE_KIND


SCHEMA_VERSION = 2  # the configuration format's version


def describe_errors(error: ValidationError, prefix: str = "") -> str:
    """pydantic's errors as "field.path: message" joined by "; " (paths under ``prefix``)."""
    parts = []
    for item in error.errors():
        loc = ".".join(str(p) for p in ((prefix,) if prefix else ()) + tuple(item["loc"])) or "<root>"
        if item["type"] == "union_tag_not_found":  # pydantic's words for a missing discriminator
            field = str(item.get("ctx", {}).get("discriminator", "kind")).strip("'")
            parts.append(f"{loc}.{field}: Field required")
            continue
        hint = ""
        if item["type"] == "extra_forbidden" and tuple(item["loc"][:1]) == ("instrument",) and len(item["loc"]) == 2:
            hint = " (a driver's own settings go under instrument.settings)"
        parts.append(f"{loc}: {item['msg']}{hint}")
    return "; ".join(parts)


V1_GENERIC = ("kind", "timeout_s", "faults")


def migrate_v1(data: dict) -> dict:
    """A schema-1 config as schema 2: the instrument's own keys move under ``settings``, and a
    PFM instrument's tune (resonance_hz, q, q_bounds) becomes the "sho" reduction's settings."""
    data = dict(data, schema_version=SCHEMA_VERSION)
    instrument = dict(data.get("instrument") or {"kind": "forrester"})
    settings = {k: v for k, v in instrument.items() if k not in V1_GENERIC}
    data["instrument"] = {k: v for k, v in instrument.items() if k in V1_GENERIC} | {"settings": settings}
    if instrument.get("kind") == "pfm":
        sho = {"nominal_resonance_hz": settings.get("resonance_hz", 372_000.0), "nominal_q": settings.get("q", 250.0)}
        if "q_bounds" in settings:
            sho["q_bounds"] = settings.pop("q_bounds")
        data["reduction"] = {"sho": sho}
    return data


def _read_yaml(path: Path, what: str) -> Any:
    """The YAML document in ``path``; ``ConfigError`` (naming it as ``what``) for a file that
    cannot be read, is not UTF-8 text, is not YAML or is empty."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{path}: cannot read {what} ({error.strerror or error})") from None
    except UnicodeDecodeError as error:
        raise ConfigError(
            f"{path}: not a text (UTF-8) file: byte {error.start} cannot be decoded; "
            f"a {'campaign config' if what == 'config' else what} is YAML text"
        ) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from None
    if data is None:
        raise ConfigError(f"{path}: the file is empty")
    return data


def read_profile(path: str | Path, source: str = "config") -> dict:
    """The noise profile in the YAML file ``path`` as a mapping, for ``noise_model.profile``;
    ``ConfigError`` naming the field and the file for one that is missing, unreadable, empty,
    not YAML or not a noise profile (another kind of file)."""
    where = f"{source}: noise_model.profile"
    try:
        data = _read_yaml(Path(path), "noise profile")
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None
    kind = data.get("kind") if isinstance(data, dict) else None
    if kind != PROFILE_KIND:
        found = f"kind {kind!r}" if isinstance(data, dict) and "kind" in data else f"no kind {PROFILE_KIND!r}"
        raise ConfigError(f"{where}: {path} is not a noise profile ({found}; `noisebo noise-profile` writes one)")
    return data


def _inline_profile(data: dict, base: Path | None, source: str) -> dict:
    """``data`` with a profile given as a path (relative to ``base``, the config's folder)
    replaced by the profile it holds, so the config (and the campaign file) carries it."""
    noise = data.get("noise_model")
    if not isinstance(noise, dict) or not isinstance(noise.get("profile"), (str, Path)):
        return data
    path = Path(noise["profile"]).expanduser()
    if base is not None and not path.is_absolute():
        path = base / path
    return {**data, "noise_model": {**noise, "profile": read_profile(path, source)}}
