"""The catalogue of robots and tools a cell file may name (``interfaces/catalog.yaml``).

A station's ``robot: panda`` or ``tool: panda_hand`` stands for the catalogue's mapping of that
name; a mapping written out in the cell file is used as it is.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from interfaces.errors import ConfigError
from interfaces.yamlio import load_yaml_strict

CATALOG = Path(__file__).resolve().parent / "catalog.yaml"
"""Robots and tools a cell may name instead of describing them in full."""


@cache
def _catalog() -> dict[str, dict[str, Any]]:
    data = load_yaml_strict(CATALOG.read_text(encoding="utf-8"), str(CATALOG))
    if not isinstance(data, dict):
        msg = f"{CATALOG}: expected a mapping with robots and tools"
        raise ConfigError(msg)
    return {key: dict(data.get(key) or {}) for key in ("robots", "tools")}


def catalog_names() -> dict[str, tuple[str, ...]]:
    """Names of the catalogue's robots and tools."""
    return {key: tuple(entries) for key, entries in _catalog().items()}


def entry(value: object, kind: str, where: str) -> object:
    """A catalogue name replaced by its mapping (with ``name``); a mapping passes as it is."""
    if isinstance(value, str):
        entries = _catalog()[kind]
        if value not in entries:
            known = ", ".join(entries)
            msg = f"{where}: unknown {kind[:-1]} {value!r} (the catalogue has: {known})"
            raise ConfigError(msg)
        return {"name": value, **entries[value]}
    return value
