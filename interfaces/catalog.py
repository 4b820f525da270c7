"""The catalogue of robots and tools a cell file may name (``interfaces/catalog.yaml``).

A station's ``robot: panda`` or ``tool: panda_hand`` stands for the catalogue's mapping of that
name; a mapping written out in the cell file is used as it is.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path
from typing import Any

from interfaces.errors import ConfigError, cut
from interfaces.yamlio import load_yaml_file

CATALOG = Path(__file__).resolve().parent / "catalog.yaml"
"""Robots and tools a cell may name instead of describing them in full."""


@cache
def _catalog() -> dict[str, dict[str, Any]]:
    data = load_yaml_file(CATALOG, what="catalogue")
    if not isinstance(data, dict):
        msg = f"{CATALOG}: expected a mapping with robots and tools"
        raise ConfigError(msg)
    return {key: dict(data.get(key) or {}) for key in ("robots", "tools")}


def is_part_name(name: str) -> bool:
    """Whether ``name`` may name a robot or a tool: 1 to 64 letters, digits, ``_``, ``-`` or
    ``.``, not starting with ``.`` (it becomes part of a file name in the URDF cache)."""
    return (
        0 < len(name) <= 64
        and not name.startswith(".")
        and all(ch.isascii() and (ch.isalnum() or ch in "_-.") for ch in name)
    )


def catalog_names() -> dict[str, tuple[str, ...]]:
    """Names of the catalogue's robots and tools."""
    return {key: tuple(entries) for key, entries in _catalog().items()}


def entry(value: object, kind: str, where: str) -> object:
    """A catalogue name replaced by its mapping (with ``name``); a mapping passes as it is."""
    if isinstance(value, str):
        if len(value) > 200:
            msg = f"{where} = {cut(value)}: not a {kind[:-1]} name (too long)"
            raise ConfigError(msg)
        entries = _catalog()[kind]
        if value not in entries:
            known = ", ".join(entries)
            msg = f"{where}: unknown {kind[:-1]} {value!r} (the catalogue has: {known})"
            raise ConfigError(msg)
        return {"name": value, **entries[value]}
    return value


def missing_fields(cls: type, value: object, where: str, kind: str) -> None:
    """Raise :class:`ConfigError` naming ``where`` and every required field of the dataclass
    ``cls`` that the mapping ``value`` lacks (a robot or tool written out in full without its
    ``name``, ...), instead of the constructor's message; anything else passes."""
    if not isinstance(value, dict):
        return
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.init and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    lacking = [name for name in required if name not in value]
    if lacking:
        names = ", ".join(repr(n) for n in lacking)
        msg = (
            f"{where}: missing {names} (a {kind} written out in full needs "
            f"{', '.join(required)}; or name one of the catalogue's)"
        )
        raise ConfigError(msg)
