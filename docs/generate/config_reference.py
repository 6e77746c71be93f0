"""The configuration reference, from the pydantic models: every section of a campaign config
(``noisebo.config.CampaignConfig``) and of the built-in instrument drivers' settings, each key with
its type, default, constraints and description."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterator

from pydantic import BaseModel

from generate.markdown import code, paragraphs, table
from generate.pydantic_fields import default_text, field_constraints, models_in, type_text

BUILT_IN = "noisebo"  # the distribution whose drivers are documented (not plug-ins installed beside it)


@dataclass(frozen=True)
class Section:
    """One model at one place in a config: ``path`` is where its keys go (``space.axes[]``)."""

    path: str
    model: type[BaseModel]
    when: str = ""  # the condition under which this model applies there (``instrument.kind: pfm``)
    driver: type | None = None  # the driver class whose settings these are

    @property
    def anchor(self) -> str:
        return re.sub(r"[^a-z0-9]+", "-", f"{self.path} {self.when}".lower()).strip("-") or "campaign"

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name


def sections_of(model: type[BaseModel], path: str = "", when: str = "") -> Iterator[Section]:
    """The model's section, then its sub-models' sections, depth first in field order."""
    yield Section(path, model, when)
    for name, field in model.model_fields.items():
        inner = models_in(field.annotation)
        for sub in inner:
            tag = sub.model_fields.get("source")  # a discriminated union: each member says its source
            sub_when = f"source: {tag.default}" if len(inner) > 1 and tag is not None else ""
            yield from sections_of(sub, f"{path}.{name}{suffix(field.annotation)}".lstrip("."), sub_when)


def suffix(annotation) -> str:
    """``[]`` for a list of models, ``.NAME`` for a mapping of them, nothing for one."""
    text = str(annotation)
    return "[]" if "..." in text or "Ellipsis" in text else ".NAME" if text.startswith("dict") else ""


def builtin_drivers() -> dict[str, type]:
    """The built-in driver classes, by name."""
    from noisebo.instruments.registry import driver_class, installed

    return {name: driver_class(name) for name, found in sorted(installed().items()) if found.distribution == BUILT_IN}


def all_sections() -> list[Section]:
    from noisebo.config import CampaignConfig

    sections = list(sections_of(CampaignConfig))
    for name, driver in builtin_drivers().items():
        first, *rest = sections_of(driver.Settings, "instrument.settings", f"instrument.kind: {name}")
        sections += [Section(first.path, first.model, first.when, driver), *rest]
    return sections


def render(sections: list[Section]) -> str:
    anchors = {(s.path, s.model): f"#{s.anchor}" for s in reversed(sections)}
    parts = []
    for s in sections:
        title = (code(s.path) if s.path else "Top level") + (f" ({code(s.when)})" if s.when else "")
        parts.append(f"### {title} {{#{s.anchor}}}\n")
        parts.append(f"Model: {code(s.model.__module__ + '.' + s.model.__qualname__)}\n")
        if s.driver is not None:  # what `noisebo instruments` says of it: its class's first docstring line
            said = (s.driver.__doc__ or "").strip().splitlines()
            parts.append(
                f"The driver {code(s.driver.__module__ + '.' + s.driver.__qualname__)}: {said[0] if said else ''}\n"
            )
        parts.append(paragraphs(s.model.__dict__.get("__doc__")))
        rows = [
            (
                code(s.key(name)),
                type_text(f.annotation, linker(anchors, s.key(name) + suffix(f.annotation))),
                default_text(f),
                field_constraints(f),
                f.description or "",
            )
            for name, f in s.model.model_fields.items()
        ]
        parts.append(table(["key", "type", "default", "constraints", "meaning"], rows))
    return "\n".join(parts)


def linker(anchors: dict, path: str):
    """How a field at ``path`` links to the sections of its models."""
    return lambda model: anchors.get((path, model), "#")


def page() -> str:
    """The generated part of the configuration reference."""
    return render(all_sections())
