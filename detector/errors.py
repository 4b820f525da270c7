"""Errors raised by the detector package.

The detector is its own process and imports nothing from ``twin`` or ``control``; its errors
derive from the project's base error in :mod:`interfaces.errors`.
"""

from __future__ import annotations

from interfaces.errors import CdwTwinError, ConfigError


class DetectorError(CdwTwinError):
    """Base class of every error the detector raises on purpose."""


class DetectorConfigError(DetectorError, ConfigError):
    """A detector setting (configuration field, constructor argument) is out of range."""


class FrameError(DetectorError):
    """A frame or image handed to the detector has the wrong shape, type or values."""


class ModelFileError(DetectorError):
    """A classifier or ONNX model file cannot be read or does not hold what it should."""


class DatasetError(DetectorError):
    """A photo dataset (images, labels, class names, height images) cannot be used."""


__all__ = ["DatasetError", "DetectorConfigError", "DetectorError", "FrameError", "ModelFileError"]
