"""Configs and profiles from YAML mappings, checked against their dataclasses' annotations.

One :func:`from_mapping` builds every config dataclass: the field's type says what a key may
hold (``bool``, ``int``, ``float``, ``str``, a ``Literal`` of choices, ``X | None``, tuples,
dicts, nested dataclasses) and the field's metadata its bounds (:func:`bounded`). Unknown keys
are rejected with the nearest known one. Every error is one :class:`RigError` naming where the
mapping came from, the key path, the bad value and what is allowed:

>>> from dataclasses import dataclass
>>> from typing import Literal
>>> @dataclass(frozen=True)
... class Solver:
...     max_iterations: int = bounded(30, min=1, max=10_000)
...     kind: Literal["block", "dense"] = "block"
...     gamma: tuple[float, float] = (3.0, 4.0)
>>> from_mapping(Solver, {"kind": "dense", "gamma": [1, 2]}, "run.yaml", "optimise.solver")
Solver(max_iterations=30, kind='dense', gamma=(1.0, 2.0))
>>> from_mapping(Solver, {"max_iterations": 0}, "run.yaml", "optimise.solver")
Traceback (most recent call last):
core.errors.RigError: run.yaml: key 'optimise.solver.max_iterations' is 0 — allowed: a whole ...
>>> from_mapping(Solver, {"kinds": "dense"}, "run.yaml")
Traceback (most recent call last):
core.errors.RigError: run.yaml: key 'kinds' is not known (did you mean 'kind'?) — allowed: ...
>>> from_mapping(Solver, {"max_iterations": True}, "run.yaml")
Traceback (most recent call last):
core.errors.RigError: run.yaml: key 'max_iterations' is True — allowed: a whole number in [1, ...

A nested dataclass field takes a nested mapping, and its errors carry the longer key path
(``tests/core/test_config.py`` runs these examples). :func:`check_arguments` applies the same
checks to a function's keyword arguments (a driver's settings in a profile).
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, Literal, TypeVar, Union

from core.errors import RigError

T = TypeVar("T")


def bounded(
    default: Any = dataclasses.MISSING,
    *,
    default_factory: Callable[[], Any] | Any = dataclasses.MISSING,
    min: float | None = None,
    max: float | None = None,
    above: float | None = None,
    min_items: int | None = None,
) -> Any:
    """A dataclass field with bounds: every number the field holds (itself, or each item of a
    tuple or dict) must be in ``[min, max]`` and ``> above``; a tuple or dict must have at least
    ``min_items`` items. Without ``default`` or ``default_factory`` the key is required."""
    meta = {"min": min, "max": max, "above": above, "min_items": min_items}
    return dataclasses.field(
        default=default,
        default_factory=default_factory,
        metadata={k: v for k, v in meta.items() if v is not None},
    )


def from_mapping(cls: type[T], data: Any, where: str, key: str = "") -> T:
    """An instance of the dataclass ``cls`` from ``data`` (a mapping, or None for all the
    defaults; an instance of ``cls`` passes as it is). ``where`` names the source (a file) and
    ``key`` the path of ``data`` in it; both appear in every error."""
    if isinstance(data, cls):
        return data
    if data is None:
        data = {}
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    if not isinstance(data, Mapping):
        raise _fail(where, key, data, f"a mapping with keys {', '.join(names)}")
    for name in data:
        if name not in names:
            close = difflib.get_close_matches(str(name), names, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise RigError(
                f"{where}: key '{_join(key, str(name))}' is not known{hint}",
                f"allowed: {', '.join(names)}",
            )
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        path = _join(key, f.name)
        if f.name in data:
            values[f.name] = parse_value(data[f.name], hints[f.name], where, path, f.metadata)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            allowed = describe(hints[f.name], f.metadata)
            raise RigError(f"{where}: key '{path}' is missing", f"allowed: {allowed}")
    return cls(**values)


def check_arguments(func: Callable[..., Any], options: Mapping[str, Any], where: str,
                    skip: int = 0, bounds: Mapping[str, Mapping[str, Any]] | None = None) -> None:
    """``options`` checked as keyword arguments of ``func`` after its first ``skip`` parameters
    (a driver's settings from a profile): unknown names rejected with the nearest known one,
    required ones present, and each value against its annotation where that is a config type
    (bool, numbers, str, ``Literal``, containers and unions of those) and the bounds given for
    its name (as :func:`bounded` takes them); ``func`` checks the rest."""
    params = list(inspect.signature(func).parameters.values())[skip:]
    named = [p for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    names = [p.name for p in named]
    if not any(p.kind is p.VAR_KEYWORD for p in params):
        for name in options:
            if name not in names:
                close = difflib.get_close_matches(str(name), names, n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise RigError(f"{where}: key '{name}' is not known{hint}",
                               f"allowed: {', '.join(names)}")
    for p in named:
        if p.default is p.empty and p.name not in options:
            raise RigError(f"{where}: key '{p.name}' is missing", "add it to the section")
    try:
        init = func.__init__ if isinstance(func, type) else func  # type: ignore[misc]
        hints = typing.get_type_hints(init)
    except (NameError, TypeError):  # an annotation this module cannot resolve: func checks
        hints = {}
    for name, value in options.items():
        if name in hints and _checkable(hints[name]):
            parse_value(value, hints[name], where, name, (bounds or {}).get(name))


def _checkable(kind: Any) -> bool:
    """Whether :func:`parse_value` understands ``kind`` without converting a YAML value."""
    if kind in (bool, int, float, str, type(None), Any) or typing.get_origin(kind) is Literal:
        return True
    if typing.get_origin(kind) in (Union, types.UnionType, tuple, list, dict, Mapping):
        return all(_checkable(a) for a in typing.get_args(kind) if a is not Ellipsis)
    return False


def parse_value(
    value: Any, kind: Any, where: str, key: str, meta: Mapping[str, Any] | None = None
) -> Any:
    """``value`` checked against the annotation ``kind`` and the bounds in ``meta`` (as
    :func:`bounded` writes them), converted where YAML cannot say it (lists to tuples, ints
    to floats); a :class:`RigError` naming ``where`` and ``key`` when it does not fit."""
    meta = meta or {}
    try:
        return _parse(value, kind, where, key, meta)
    except _Mismatch:
        raise _fail(where, key, value, describe(kind, meta)) from None


class _Mismatch(Exception):
    """``value`` does not fit the annotation (reported by the caller that knows the key)."""


def _parse(value: Any, kind: Any, where: str, key: str, meta: Mapping[str, Any]) -> Any:
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if kind is Any:
        return value
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for member in args:
            try:
                return _parse(value, member, where, key, meta)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
        raise _Mismatch
    if kind is bool:
        if isinstance(value, bool):
            return value
        raise _Mismatch
    if kind is int or kind is float:
        return _number(value, kind, meta)
    if kind is str:
        if isinstance(value, str):
            return value
        raise _Mismatch
    if dataclasses.is_dataclass(kind) and isinstance(kind, type):
        if value is None or isinstance(value, (Mapping, kind)):  # an empty YAML section: None
            return from_mapping(kind, value, where, key)
        raise _Mismatch
    if origin in (tuple, list):
        return _sequence(value, args, where, key, meta)
    if origin in (dict, Mapping) or kind in (dict, Mapping):
        return _mapping(value, args, where, key, meta)
    if isinstance(kind, type):
        if isinstance(value, kind):
            return value
        raise _Mismatch
    raise TypeError(f"{key}: annotation {kind!r} is not supported")


def _number(value: Any, kind: type, meta: Mapping[str, Any]) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Mismatch
    if kind is int and not isinstance(value, int):
        raise _Mismatch
    if not math.isfinite(value):
        raise _Mismatch
    low, high, above = meta.get("min"), meta.get("max"), meta.get("above")
    if (low is not None and value < low) or (high is not None and value > high):
        raise _Mismatch
    if above is not None and value <= above:
        raise _Mismatch
    return kind(value)


def _sequence(
    value: Any, args: tuple[Any, ...], where: str, key: str, meta: Mapping[str, Any]
) -> tuple[Any, ...]:
    if not isinstance(value, (list, tuple)):
        raise _Mismatch
    if len(args) == 2 and args[1] is Ellipsis or len(args) == 1:
        kinds = [args[0]] * len(value)
    elif len(args) == len(value):
        kinds = list(args)
    else:
        raise _Mismatch
    if len(value) < meta.get("min_items", 0):
        raise _Mismatch
    inner = {**meta, "min_items": 0}
    return tuple(  # a plain item that does not fit is reported with the whole list
        _parse(item, kind, where, f"{key}[{i}]", inner)
        for i, (item, kind) in enumerate(zip(value, kinds, strict=True))
    )


def _mapping(
    value: Any, args: tuple[Any, ...], where: str, key: str, meta: Mapping[str, Any]
) -> dict[Any, Any]:
    if not isinstance(value, Mapping):
        raise _Mismatch
    if len(value) < meta.get("min_items", 0):
        raise _Mismatch
    key_kind, item_kind = args or (Any, Any)
    inner = {**meta, "min_items": 0}
    out = {}
    for name, item in value.items():
        if key_kind is str and not isinstance(name, str):
            raise _Mismatch
        out[name] = parse_value(item, item_kind, where, _join(key, str(name)), inner)
    return out


def describe(kind: Any, meta: Mapping[str, Any] | None = None) -> str:
    """What a value of annotation ``kind`` with bounds ``meta`` may be, in a user's words."""
    meta = meta or {}
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (Union, types.UnionType):
        parts = [describe(a, meta) for a in args if a is not type(None)]
        return " or ".join(parts + (["null"] if type(None) in args else []))
    if origin is Literal:
        return ", ".join(a if isinstance(a, str) else _show(a) for a in args)
    if kind is bool:
        return "true or false"
    if kind is int or kind is float:
        noun = "a whole number" if kind is int else "a finite number"
        return noun + _range(meta)
    if kind is str:
        return "a string"
    if dataclasses.is_dataclass(kind):
        return "a mapping with keys " + ", ".join(f.name for f in dataclasses.fields(kind))
    if origin in (tuple, list):
        at_least = f" (at least {meta['min_items']})" if meta.get("min_items") else ""
        if len(args) == 2 and args[1] is Ellipsis or len(args) == 1:
            return f"a list{at_least}, each {describe(args[0], meta)}"
        items = [describe(a, meta) for a in args]
        if len(set(items)) == 1:
            return f"a list of {len(args)}, each {items[0]}"
        return f"a list of {len(args)}: {', '.join(items)}"
    if origin in (dict, Mapping) or kind in (dict, Mapping):
        item = typing.get_args(kind)[1] if typing.get_args(kind) else Any
        return "a mapping" + ("" if item is Any else f" of name: {describe(item, meta)}")
    return getattr(kind, "__name__", str(kind))


def _range(meta: Mapping[str, Any]) -> str:
    low, high, above = meta.get("min"), meta.get("max"), meta.get("above")
    if above is not None:
        return f" > {above:g}" + (f" and <= {high:g}" if high is not None else "")
    if low is not None and high is not None:
        return f" in [{low:g}, {high:g}]"
    if low is not None:
        return f" >= {low:g}"
    if high is not None:
        return f" <= {high:g}"
    return ""


def _fail(where: str, key: str, value: Any, allowed: str) -> RigError:
    what = f"{where}: key '{key}'" if key else where
    return RigError(f"{what} is {_show(value)}", f"allowed: {allowed}")


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
