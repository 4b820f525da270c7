"""Frozen dataclasses to and from plain data (YAML/JSON), with errors that name the key.

``from_data(cls, data, where)`` builds a dataclass from nested dicts and lists, checking every key
against the dataclass fields (an unknown key is an error, a missing one takes the default) and every
value against the field's annotation. ``to_data(obj)`` is the inverse, so a config written and read
back compares equal.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

from interfaces.errors import ConfigError, cut

T = TypeVar("T")


def to_data(obj: object) -> Any:
    """Plain (YAML-safe) data for a dataclass tree: dicts, lists, numbers, strings, None."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_data(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple | list):
        return [to_data(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_data(v) for k, v in obj.items()}
    return obj


def from_data(cls: type[T], data: object, where: str) -> T:
    """Build dataclass ``cls`` from ``data``; ``where`` names the location for error messages."""
    return typing.cast(T, _convert(cls, data, where))


def _fail(where: str, value: object, what: str) -> typing.NoReturn:
    msg = f"{where} = {cut(value)}: {what}"
    raise ConfigError(msg)


def _convert(tp: Any, value: object, where: str) -> object:
    if tp is Any:
        return value
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        return _convert_union(tp, value, where)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _convert_dataclass(tp, value, where)
    if origin is tuple:
        return _convert_tuple(tp, value, where)
    if origin is dict or origin is Mapping:
        return _convert_dict(tp, value, where)
    if origin is typing.Literal:
        if value not in get_args(tp):
            _fail(where, value, f"must be one of {list(get_args(tp))}")
        return value
    return _convert_scalar(tp, value, where)


def _convert_union(tp: Any, value: object, where: str) -> object:
    options = get_args(tp)
    if value is None and type(None) in options:
        return None
    for option in options:
        if option is type(None):
            continue
        try:
            return _convert(option, value, where)
        except ConfigError:
            continue
    _fail(where, value, "matches none of the allowed types")


def _convert_tuple(tp: Any, value: object, where: str) -> tuple[object, ...]:
    args = get_args(tp)
    if not isinstance(value, list | tuple):
        _fail(where, value, "expected a list")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
    if len(args) != len(value):
        _fail(where, value, f"expected {len(args)} values")
    return tuple(
        _convert(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
    )


def _convert_dict(tp: Any, value: object, where: str) -> dict[object, object]:
    key_type, value_type = get_args(tp)
    if not isinstance(value, dict):
        _fail(where, value, "expected a mapping")
    return {
        _convert(key_type, k, f"{where}.{k}"): _convert(value_type, v, f"{where}.{k}")
        for k, v in value.items()
    }


def _convert_scalar(tp: Any, value: object, where: str) -> object:
    if tp is bool:
        if not isinstance(value, bool):
            _fail(where, value, "expected true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(where, value, "expected an integer")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            _fail(where, value, "expected a number")
        if not math.isfinite(float(value)):
            _fail(where, value, "must be finite")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            _fail(where, value, "expected a string")
        return value
    _fail(where, value, f"unsupported field type {tp!r}")


def _convert_dataclass(cls: type, value: object, where: str) -> object:
    if isinstance(value, cls):
        return value
    if value is None:
        value = {}
    if not isinstance(value, dict):
        _fail(where, value, "expected a mapping")
    hints = get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    for key in value:
        if key not in names:
            allowed = ", ".join(sorted(names))
            prefix = f"{where}: " if where else ""
            msg = f"{prefix}unknown key {key!r} (allowed: {allowed})"
            raise ConfigError(msg)
    kwargs = {
        key: _convert(hints[key], item, f"{where}.{key}" if where else key)
        for key, item in value.items()
    }
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        msg = f"{where}: {exc}" if where else str(exc)
        raise ConfigError(msg) from None
    except TypeError as exc:
        msg = f"{where}: {exc}" if where else str(exc)
        raise ConfigError(msg) from None
