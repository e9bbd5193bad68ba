"""Type checks of config fields, driven by the sections' annotations.

A YAML file or a dict can put any value anywhere: ``prior: abc``, ``fov_deg: wide``,
``altitudes: 5``, ``budget: true``, ``gain: "no"`` (a quoted string, which Python reads as
true). Each section of :mod:`ipp_toolkit.config.schema` calls :func:`check_field_types` first
in its ``__post_init__``, so a wrong type is refused naming the field and the value before
the range checks compare it with numbers (a TypeError deep inside otherwise).

The predicates :func:`is_integer` and :func:`is_real`, and :func:`check_integers` that runs the
first over named fields, are the one place the configs of the trainers (COMA, SB3, RLlib, the
field prior) and the mission's sections test a count or a number: a bool is neither.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import reprlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["check_field_types", "check_integers", "is_integer", "is_real", "short_repr"]

_REPR = reprlib.Repr()
_REPR.maxstring = 60
_REPR.maxother = 60
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = 6
_REPR.maxlevel = 3


def short_repr(value: Any) -> str:
    """``repr(value)`` cut to a readable length (a message never echoes a whole file)."""
    return _REPR.repr(value)


def is_integer(value: Any, minimum: int, *, numpy: bool = True) -> bool:
    """Whether ``value`` is an integer of at least ``minimum``. A bool is not one; a numpy
    integer is one unless ``numpy`` is false (fields that only JSON or Python fill)."""
    kinds = (int, np.integer) if numpy else int
    return not isinstance(value, bool) and isinstance(value, kinds) and value >= minimum


def is_real(value: Any) -> bool:
    """Whether ``value`` is a plain int or float, not a bool (nan and inf included: the caller
    says which it takes)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def check_integers(owner: Any, minimums: Mapping[str, int], message: str, *,
                   numpy: bool = True) -> None:
    """Refuse the first attribute of ``owner`` named in ``minimums`` that is not an integer of
    at least its minimum (:func:`is_integer`).

    Raises:
        ValueError: ``message`` formatted with the field's ``name``, ``value`` and
            ``minimum``, e.g. ``"invalid RLlib config: {name} must be an integer >= {minimum},
            got {value!r}"``.
    """
    for name, minimum in minimums.items():
        value = getattr(owner, name)
        if not is_integer(value, minimum, numpy=numpy):
            raise ValueError(message.format(name=name, value=value, minimum=minimum))


class _Bad(Exception):
    """A value of the wrong type; the argument says what was expected."""


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) \
        and type(value).__name__ != "bool_"


_INFINITE = {"inf": math.inf, "+inf": math.inf, ".inf": math.inf, "-inf": -math.inf,
             "-.inf": -math.inf}


def _number(value: Any) -> Any:
    if _is_number(value):
        return value
    if isinstance(value, str) and value.strip().lower() in _INFINITE:
        return _INFINITE[value.strip().lower()]  # config.json writes inf as "inf"
    if isinstance(value, bool):
        raise _Bad("must be a number, not true/false")
    raise _Bad("must be a number")


def _integer(value: Any) -> Any:
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) \
            and type(value).__name__ != "bool_":
        return value
    raise _Bad("must be an integer")


def _boolean(value: Any) -> Any:
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return value
    if isinstance(value, str):
        raise _Bad("must be true or false, not a string (write it unquoted)")
    raise _Bad("must be true or false")


def _string(value: Any) -> Any:
    if isinstance(value, str):
        return value
    raise _Bad("must be a string")


def _optional(check: Callable[[Any], Any]) -> Callable[[Any], Any]:
    return lambda value: None if value is None else check(value)


def _path(value: Any) -> Any:
    if isinstance(value, str | os.PathLike):
        return value
    raise _Bad("must be a file path")


def _numbers(value: Any) -> Any:
    if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__iter__"):
        raise _Bad("must be a list of numbers")
    items = tuple(value)
    for item in items:
        try:
            _number(item)
        except _Bad:
            raise _Bad(f"must be a list of numbers ({short_repr(item)} is not one)") from None
    return value


def _number_or_pair(value: Any) -> Any:
    return value if _is_number(value) else _numbers(value)


_CHECKERS: dict[str, Callable[[Any], Any]] = {
    "float": _number,
    "int": _integer,
    "bool": _boolean,
    "str": _string,
    "str | None": _optional(_path),
    "float | None": _optional(_number),
    "tuple[float, ...]": _numbers,
    "tuple[float, float]": _number_or_pair,
    "float | tuple[float, float] | None": _optional(_number_or_pair),
}


def check_field_types(section: Any, name: str) -> None:
    """Check (and for ``"inf"`` strings, convert) every field of the frozen dataclass
    ``section`` named ``name`` against its annotation.

    Raises:
        ValueError: ``invalid config: SECTION.FIELD = VALUE: must be ...``.
    """
    for spec in dataclasses.fields(section):
        check = _CHECKERS.get(str(spec.type))
        if check is None:
            continue  # pairs and mappings: checked by the section's own code
        value = getattr(section, spec.name)
        try:
            checked = check(value)
        except _Bad as why:
            raise ValueError(f"invalid config: {name}.{spec.name} = {short_repr(value)}: "
                             f"{why}") from None
        if checked is not value:
            object.__setattr__(section, spec.name, checked)
