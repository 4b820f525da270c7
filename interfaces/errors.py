"""The project's base error and the configuration error every package raises.

Every package of cdw-twin derives its errors from :class:`CdwTwinError`, so a caller can catch
everything the project raises on purpose with one ``except`` while real bugs still surface.
Messages always name the file, line, field or value that was wrong, and never quote a whole
value that may be huge: :func:`cut` shortens it (a list of a million numbers, a structure a
YAML alias bomb expands, a line of a binary file).
"""

from __future__ import annotations

import reprlib


class CdwTwinError(Exception):
    """Base class of every error cdw-twin raises on purpose."""


class ConfigError(CdwTwinError):
    """A configuration value (cell, scenario, robot, CLI option) is missing or out of range."""


MAX_SHOWN_CHARS = 120
"""The most characters of a value an error message quotes (:func:`cut`)."""

MAX_MESSAGE_CHARS = 2000
"""The longest error message :func:`cut_message` lets through."""

_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxtuple = _REPR.maxlist = _REPR.maxarray = 8
_REPR.maxdict = _REPR.maxset = _REPR.maxfrozenset = _REPR.maxdeque = 8
_REPR.maxstring = _REPR.maxother = MAX_SHOWN_CHARS
_REPR.maxlong = 60


def cut(value: object, limit: int = MAX_SHOWN_CHARS) -> str:
    """``repr(value)``, at most ``limit`` characters, ending in ``...`` when it was cut.

    Containers are abbreviated while they are printed (a few items per level, a few levels
    deep), so even a structure whose full repr would take gigabytes (shared references that a
    YAML alias bomb expands) costs a few microseconds here.
    """
    if isinstance(value, int) and not isinstance(value, bool):
        bits = value.bit_length()
        text = repr(value) if bits <= 10_000 else f"<an integer of {bits} bits>"
    elif isinstance(value, float):
        text = repr(value)
    else:
        text = _REPR.repr(value)
    if len(text) <= limit:
        return text
    return text[: max(0, limit - 3)] + "..."


def cut_message(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` as it is when short, else its start and its end around ``[... N characters cut
    ...]``: the start names the file and key, the end says what is wrong."""
    if len(text) <= limit:
        return text
    head = (2 * limit) // 3
    tail = limit - head
    return f"{text[:head]} [... {len(text) - head - tail} characters cut ...] {text[-tail:]}"


def require(
    condition: bool,
    key: str,
    value: object,
    what: str,
    *,
    error: type[ConfigError] = ConfigError,
) -> None:
    """Raise ``error`` (a :class:`ConfigError`) ``"<key> = <value>: <what>"`` unless
    ``condition`` holds (the value cut by :func:`cut`). The one check of a configuration value
    every package uses (a package passes its own subclass: ``ControlConfigError``)."""
    if not condition:
        msg = f"{key} = {cut(value)}: {what}"
        raise error(msg)
