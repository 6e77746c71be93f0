"""A pydantic field in words: its type, default and constraints, as a reference table shows them."""

from __future__ import annotations

import json
import math
import types
from typing import Annotated, Any, Literal, Union, get_args, get_origin

from pydantic import BaseModel
from pydantic.fields import FieldInfo

from generate.markdown import code

BOUNDS = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
BASIC = {float: "number", int: "whole number", bool: "true or false", str: "text", type(None): "null"}


def unwrapped(annotation: Any) -> tuple[Any, list]:
    """The type inside ``Annotated`` layers, and their metadata."""
    metadata: list = []
    while get_origin(annotation) is Annotated:
        annotation, *more = get_args(annotation)
        metadata += more
    return annotation, metadata


def union_members(annotation: Any) -> list[Any]:
    return list(get_args(annotation)) if get_origin(annotation) in (Union, types.UnionType) else [annotation]


def models_in(annotation: Any) -> list[type[BaseModel]]:
    """The pydantic models a field can hold (alone, in a union, a tuple or a mapping's values)."""
    annotation, _ = unwrapped(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    found = []
    for member in get_args(annotation) if get_origin(annotation) is not Literal else ():
        found += [m for m in models_in(member) if m not in found]
    return found


def constraints(metadata: list) -> list[str]:
    """Bounds, lengths and patterns from a field's metadata, in words."""
    said = []
    for item in metadata:
        if isinstance(item, FieldInfo):
            said += constraints(item.metadata)
            continue
        for name, sign in BOUNDS:
            if getattr(item, name, None) is not None:
                said.append(f"{sign} {number(getattr(item, name))}")
        if getattr(item, "min_length", None) is not None:
            said.append(f"at least {item.min_length} long")
        if getattr(item, "max_length", None) is not None:
            said.append(f"at most {item.max_length} long")
        if getattr(item, "pattern", None) is not None:
            said.append(f"matches {code(item.pattern)}")
    return said


def type_text(annotation: Any, anchor_of) -> str:
    """The type in words; a model is a link made by ``anchor_of(model)``."""
    annotation, metadata = unwrapped(annotation)
    limits = constraints(metadata)
    members = union_members(annotation)
    if len(members) > 1:
        named = [type_text(m, anchor_of) for m in members if m is not type(None)]
        text = " or ".join(named) + (", or null" if type(None) in members else "")
    elif get_origin(annotation) is Literal:
        text = "one of " + ", ".join(code(v) for v in get_args(annotation))
    elif isinstance(annotation, type) and issubclass(annotation, BaseModel):
        text = f"[{annotation.__name__}]({anchor_of(annotation)})"
    elif get_origin(annotation) is tuple:
        args = get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            text = f"list of {type_text(args[0], anchor_of)}"
        else:
            text = "[" + ", ".join(type_text(a, anchor_of) for a in args) + "]"
    elif get_origin(annotation) is dict or annotation is dict:
        args = get_args(annotation)
        text = f"mapping of name to {type_text(args[1], anchor_of)}" if args and args[1] is not Any else "mapping"
    else:
        text = BASIC.get(annotation, getattr(annotation, "__name__", str(annotation)))
    return f"{text} ({', '.join(limits)})" if limits else text


def field_constraints(field: FieldInfo) -> str:
    """The constraints pydantic keeps on the field itself (a top-level ``Annotated`` is moved there)."""
    return ", ".join(constraints(field.metadata))


def number(value: float) -> str:
    """A number as written in a config, with its log where it is the log of a round number."""
    if isinstance(value, bool) or not isinstance(value, float):
        return json.dumps(value)
    text = f"{value:.6g}"
    if value < 0 and float(text) != value and math.isclose(round(math.exp(value), 4), math.exp(value), rel_tol=1e-12):
        return f"{text} (log {round(math.exp(value), 4):g})"
    return text


def default_text(field: FieldInfo) -> str:
    """The default as YAML would write it; "required" when there is none."""
    if field.is_required():
        return "required"
    value = field.get_default(call_default_factory=True)
    if isinstance(value, float) and not isinstance(value, bool):
        return code(number(value))
    if isinstance(value, BaseModel) and not plain(value):
        return "its keys' defaults"
    return code(json.dumps(plain(value)))


def plain(value: Any) -> Any:
    """A default as JSON data: a model as the keys it sets beyond its own defaults."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json", exclude_defaults=True)
    if isinstance(value, (tuple, list)):
        return [plain(v) for v in value]
    return value
