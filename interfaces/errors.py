"""The project's base error and the configuration error every package raises.

Every package of cdw-twin derives its errors from :class:`CdwTwinError`, so a caller can catch
everything the project raises on purpose with one ``except`` while real bugs still surface.
Messages always name the file, line, field or value that was wrong.
"""

from __future__ import annotations


class CdwTwinError(Exception):
    """Base class of every error cdw-twin raises on purpose."""


class ConfigError(CdwTwinError):
    """A configuration value (cell, scenario, robot, CLI option) is missing or out of range."""


def require(condition: bool, key: str, value: object, what: str) -> None:
    """Raise :class:`ConfigError` ``"<key> = <value>: <what>"`` unless ``condition`` holds."""
    if not condition:
        msg = f"{key} = {value!r}: {what}"
        raise ConfigError(msg)
