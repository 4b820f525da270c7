"""Errors raised by the controller package.

The controller is its own process and imports nothing from ``twin``; its errors therefore derive
from :class:`ControlError`, not from the twin's base error.
"""

from __future__ import annotations


class ControlError(Exception):
    """Base class of every error the controller raises on purpose."""


class ControlConfigError(ControlError):
    """The controller configuration (YAML file or dataclass field) is invalid."""


class RobotModelError(ControlError):
    """The robot description (URDF, joint or link names) cannot be used."""


class IkError(ControlError):
    """Inverse kinematics failed or produced a configuration outside the joint limits."""


class PlanningError(ControlError):
    """The trajectory generator rejected its input or failed to compute a trajectory."""
