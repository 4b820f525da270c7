"""Errors raised on purpose by the meshgen package."""

from __future__ import annotations

from interfaces.errors import CdwTwinError, ConfigError


class MeshgenError(CdwTwinError):
    """Base class of the errors meshgen raises on purpose."""


class ClassTableError(MeshgenError, ConfigError):
    """A class table (YAML file or built-in default) is malformed."""


class DatasetError(MeshgenError):
    """A dataset folder cannot be read at all (no annotations found, unknown format)."""


class OutputError(MeshgenError):
    """The output folder cannot be written or would overwrite something that is not ours."""


class ObjFileError(MeshgenError):
    """An OBJ mesh file cannot be read or has a malformed ``v`` or ``f`` line."""
