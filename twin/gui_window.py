"""PyBullet's window on the cell (``--gui``): a display check before PyBullet opens it (PyBullet
ends the whole process when its window cannot connect), the window quiet while the episode's
bodies load, then the cell in view."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from typing import TYPE_CHECKING

from interfaces.errors import CdwTwinError

if TYPE_CHECKING:
    from twin.sim import Twin

__all__ = ["DisplayError", "check_display", "window_off", "window_on"]


class DisplayError(CdwTwinError):
    """``--gui`` without a display PyBullet can open a window on."""


def check_display(environ: dict[str, str] | None = None) -> str:
    """The X display ``--gui`` will open (``DISPLAY``); raises :class:`DisplayError` when there
    is none or it cannot be opened.

    PyBullet ends the whole process when its window cannot connect, so the display is opened
    (and closed) here first, with the X library PyBullet loads itself.
    """
    display = (os.environ if environ is None else environ).get("DISPLAY", "")
    if not display:
        msg = "--gui: no display (DISPLAY is not set); run without --gui, or under xvfb-run"
        raise DisplayError(msg)
    name = ctypes.util.find_library("X11")
    if name is None:
        msg = f"--gui: cannot open display {display!r}: the X11 library (libX11) is not installed"
        raise DisplayError(msg)
    xlib = ctypes.CDLL(name)
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    handle = xlib.XOpenDisplay(display.encode())
    if not handle:
        msg = f"--gui: cannot open display {display!r} (DISPLAY); run without --gui"
        raise DisplayError(msg)
    xlib.XCloseDisplay(handle)
    return display


def window_off(twin: Twin) -> None:
    """Stop PyBullet's window from redrawing while the episode's bodies are loaded."""
    import pybullet as pb

    pb.configureDebugVisualizer(pb.COV_ENABLE_RENDERING, 0, physicsClientId=twin.client)


def window_on(twin: Twin) -> None:
    """Show the cell in PyBullet's window: the belt and stations in view, the side panels,
    camera previews and shadows off (each costs a redraw of the scene), drawing on again."""
    import pybullet as pb

    for flag in (
        pb.COV_ENABLE_GUI,
        pb.COV_ENABLE_SHADOWS,
        pb.COV_ENABLE_RGB_BUFFER_PREVIEW,
        pb.COV_ENABLE_DEPTH_BUFFER_PREVIEW,
        pb.COV_ENABLE_SEGMENTATION_MARK_PREVIEW,
    ):
        pb.configureDebugVisualizer(flag, 0, physicsClientId=twin.client)
    belt = twin.cell.belt
    centre = [0.5 * (belt.start_x_m + belt.end_x_m), belt.centre_y_m, belt.surface_z_m]
    pb.resetDebugVisualizerCamera(
        cameraDistance=max(1.5, 0.6 * belt.length_m),
        cameraYaw=30.0,
        cameraPitch=-40.0,
        cameraTargetPosition=centre,
        physicsClientId=twin.client,
    )
    pb.configureDebugVisualizer(pb.COV_ENABLE_RENDERING, 1, physicsClientId=twin.client)
    print("cdw-twin twin-node: PyBullet window open", flush=True)
