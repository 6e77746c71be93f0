"""The numbers, flags and names a config (and a driver's settings) holds, and the base of every
settings model: frozen, unknown keys refused; a quoted number, a boolean where a number belongs, a
NaN or an infinity is an error naming the field."""

from __future__ import annotations

import math
import types
from typing import Annotated, Any, Union, get_args, get_origin
import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
)
from pydantic_core import PydanticCustomError
from noisebo import registry


class ConfigError(ValueError):
    """A configuration that cannot be used; the message names the offending field."""


class FrozenModel(BaseModel):
    """Base of every settings model: frozen, unknown keys refused (drivers' settings too)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def given(value: Any) -> str:
    """How an error names a value it refuses: "the string '8'", "the boolean true", "nan"."""
    if isinstance(value, (bool, np.bool_)):
        return f"the boolean {str(bool(value)).lower()}"
    if isinstance(value, str):
        return f"the string {value!r}"
    return repr(float(value)) if isinstance(value, float) else repr(value)


def refusal(value: Any, expected: str = "a number") -> str | None:
    """Why ``value`` cannot be a number, or None: a string (a quoted number too) or a boolean is
    not one, and a NaN or an infinity is not a finite one."""
    if isinstance(value, (bool, np.bool_, str)):
        return f"expected {expected}, got {given(value)}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be a finite number, got {given(value)}"
    return None


def _strict(expected: str):
    def check(value: Any) -> Any:
        problem = refusal(value, expected)
        if problem is not None:
            raise PydanticCustomError("strict_number", problem)
        return value

    return check


LOAD_PLUGINS = "load_plugins"  # validation context: False checks plug-ins by name only (parse_config)


def _installed(group: str):
    def check(value: Any, info: ValidationInfo) -> Any:
        try:
            return registry.checked(group, value, load_it=(info.context or {}).get(LOAD_PLUGINS, True))
        except ValueError as error:  # not installed, or broken: one line naming what is installed
            raise PydanticCustomError("not_installed", "{reason}", {"reason": str(error)}) from None

    return check


PolicyName = Annotated[str, BeforeValidator(_installed(registry.POLICIES))]
"""The name of an installed policy (``noisebo.registry``, group ``noisebo.policies``)."""
NoiseLawName = Annotated[str, BeforeValidator(_installed(registry.NOISE_LAWS))]
"""The name of an installed noise law (``noisebo.registry``, group ``noisebo.noise_laws``)."""


def _flag(value: Any) -> Any:
    if not isinstance(value, (bool, np.bool_)):
        raise PydanticCustomError("strict_flag", f"expected true or false, got {given(value)}")
    return bool(value)


# The types of every number and flag that comes from outside (a campaign config, a driver's
# settings): a string (a quoted "8" too) or a boolean where a number belongs, a NaN or an
# infinity, and anything but true or false where a flag belongs is refused, with a message that
# says what was given. An int is a Number; a whole float (2.0) is a Count.
Number = Annotated[float, BeforeValidator(_strict("a number")), Field(allow_inf_nan=False)]
Count = Annotated[int, BeforeValidator(_strict("a whole number"))]
Flag = Annotated[bool, BeforeValidator(_flag)]
FiniteFloat = Number
PositiveFloat = Annotated[Number, Field(gt=0)]
NonNegativeFloat = Annotated[Number, Field(ge=0)]
_PROBES = {float: ("1", True), int: ("1", True), bool: ("true", 1)}  # what a lax field takes and ours refuse


def _members(annotation: Any) -> list[Any]:
    """The types a field's annotation can hold: Annotated and None dropped, unions flattened."""
    if get_origin(annotation) is Annotated:
        return _members(get_args(annotation)[0])
    if get_origin(annotation) in (Union, types.UnionType):
        return [m for a in get_args(annotation) if a is not type(None) for m in _members(a)]
    return [annotation]


def lax_fields(model: type[BaseModel], prefix: str = "") -> list[str]:
    """The number and flag fields of ``model`` and of the models inside it (dotted paths) that
    take what ``Number``, ``Count`` and ``Flag`` refuse (a quoted number, a boolean for a number,
    anything but true or false for a flag): a driver's tests can assert that there are none."""
    lax = []
    for name, field in model.model_fields.items():
        for member in _members(field.annotation):
            args = [_members(a)[0] for a in get_args(member) if a is not Ellipsis]
            if get_origin(member) is tuple and all(isinstance(a, type) and issubclass(a, BaseModel) for a in args):
                lax += [f for a in args for f in lax_fields(a, f"{prefix}{name}.")]
            elif isinstance(member, type) and issubclass(member, BaseModel):
                lax += lax_fields(member, f"{prefix}{name}.")
            else:
                pair = get_origin(member) is tuple
                probes = _PROBES.get(args[0] if pair else member, ())
                values = [[p] * len(args) if pair else p for p in probes]
                where = {(name, k) for k in range(len(args))} if pair else {(name,)}
                if any(not _refuses(model, name, v, where) for v in values) and f"{prefix}{name}" not in lax:
                    lax.append(f"{prefix}{name}")
    return lax


def loose_values(model: type[BaseModel], raw: Any, prefix: str = "") -> list[str]:
    """What ``raw`` (the values a config gives ``model``) holds that a lax field of ``model`` takes
    and ``Number``, ``Count`` and ``Flag`` refuse (a quoted number or a boolean for a number,
    anything but true or false for a flag), each as "path: what is wanted, not what was given":
    noisebo checks a driver's settings this strictly whatever its own model says."""
    found: list[str] = []
    if not isinstance(raw, dict):
        return found
    for name, field in model.model_fields.items():
        if name in raw:
            found += _loose(_members(field.annotation), raw[name], f"{prefix}{name}")
    return found


def _loose(members: list[Any], value: Any, path: str) -> list[str]:
    for member in members:
        if isinstance(member, type) and issubclass(member, BaseModel) and isinstance(value, dict):
            return loose_values(member, value, f"{path}.")
        if get_origin(member) is tuple and isinstance(value, (list, tuple)):
            args = [_members(a) for a in get_args(member) if a is not Ellipsis]
            return [p for i, item in enumerate(value) for p in _loose(args[min(i, len(args) - 1)], item, f"{path}.{i}")]
    numeric = any(m in (float, int) for m in members)
    if isinstance(value, bool) and numeric and bool not in members:
        return [f"{path}: a number, not {value!r}"]
    if isinstance(value, str) and numeric and str not in members:
        return [f"{path}: a number, not the text {value!r}"]
    if members == [bool] and not isinstance(value, bool):
        return [f"{path}: true or false, not {value!r}"]
    return []


def _refuses(model: type[BaseModel], name: str, value: Any, where: set[tuple]) -> bool:
    """Whether ``model`` refuses ``value`` for ``name`` at every place ``where`` with our errors."""
    try:
        model.model_validate({name: value})
    except ValidationError as error:
        mine = [e for e in error.errors() if e["loc"][:1] == (name,)]
        return {tuple(e["loc"]) for e in mine} == where and all(
            e["type"] in ("strict_number", "strict_flag") for e in mine
        )
    return False


Rate = Annotated[Number, Field(ge=0, le=1)]
