"""What the report's figures share: one figure size and resolution, one colour per belt speed."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from experiments.report_data import RunData


def speed_colour(data: RunData, speed: float | None) -> Any:
    import matplotlib as mpl

    speeds = data.speeds()
    index = speeds.index(speed) if speed in speeds else 0
    return mpl.colormaps["tab10"](index % 10)


def new_figure(width: float = 7.0, height: float = 4.0) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100, layout="constrained")
