"""Whether some station of the cell could take a piece, judged as the piece spawns.

The twin marks every ``spawned`` event with ``takeable`` (true or false) and, when false, the
``refusal``: the reasons the stations' controllers would never target the piece whatever the
timing (``no_bin``, ``too_wide``, ``too_flat``, ``too_small``, ``too_tilted``, ``too_heavy``;
several stations' distinct reasons joined by ``+``). The judgement is the controllers' own
(:func:`control.fit.line_refusal` over every station's configuration, handed to the twin as a
:class:`PieceJudge` by the command that starts the episode), applied to what a camera would
report of the piece as it spawns, from its true shape: its top view (:func:`twin.top_view.
top_view`: the seen length, width and height) and its suction point's disc radius and face
tilt (:class:`twin.suction_point.SuctionPoints`). The metric table then counts recovery over
the takeable pieces (``recovery_takeable``, :mod:`interfaces.metrics`), so a low recovery says
whether the tools or the picking fell short.

The twin module needs no controller: it only calls the judge it is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from twin.suction_point import SuctionPoints
from twin.top_view import FloatArray, TopView, top_view

if TYPE_CHECKING:
    from twin.ground_truth import GroundTruth
    from twin.objects import ObjectSpec


class PieceJudge(Protocol):
    """Why no station could take a piece of this class, seen box and suction point (a
    :data:`control.fit.REFUSALS` reason, several joined by ``+``), or None when some could."""

    def __call__(
        self,
        *,
        class_name: str,
        length_m: float,
        width_m: float,
        height_m: float,
        face_radius_m: float,
        face_tilt_rad: float,
    ) -> str | None:
        """The refusal, or None."""
        ...


def yaw_quat(yaw_rad: float) -> tuple[float, float, float, float]:
    """The xyzw quaternion of a turn by ``yaw_rad`` about z."""
    return (0.0, 0.0, math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad))


def resting_truth(
    key: int,
    spec: ObjectSpec,
    *,
    height_m: float,
    orientation_xyzw: tuple[float, float, float, float],
    vertices_m: Callable[[], FloatArray],
) -> GroundTruth:
    """The ground truth of a piece at rest at the origin in ``orientation_xyzw`` (its mesh
    frame's), ``height_m`` tall (``key`` its id for the suction-point finder): what its top
    view and suction point are computed from."""
    from twin.ground_truth import GroundTruth

    view: TopView = top_view(
        orientation_xyzw,
        spec.yaw_rad,
        length_m=spec.length_m,
        width_m=spec.width_m,
        height_m=height_m,
        vertices_m=vertices_m,
    )
    return GroundTruth(
        id=key,
        source_id=spec.object_id,
        class_name=spec.class_name,
        position_m=(0.0, 0.0, 0.0),
        orientation_xyzw=orientation_xyzw,
        linear_velocity_mps=(0.0, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=view,
        length_m=spec.length_m,
        width_m=spec.width_m,
        area_m2=spec.area_m2,
        volume_m3=spec.volume_m3 * height_m / spec.height_m,
        height_m=height_m,
        mass_kg=spec.mass_kg,
        on_belt=True,
        in_workspace=False,
        held=False,
        in_bin=False,
    )


class SeenShapes:
    """What a camera reports of a piece lying in a given orientation: ``(length_m, width_m,
    height_m, face_radius_m, face_tilt_rad)`` from its top view and suction point. Each shape
    (mesh file and height) is read and its faces found once."""

    def __init__(self, triangles: Callable[[ObjectSpec, float], FloatArray]) -> None:
        self._triangles = triangles
        self._meshes: list[FloatArray] = []
        self._keys: dict[tuple[str, float], int] = {}
        self._finder = SuctionPoints(self._meshes.__getitem__)

    def __call__(
        self,
        spec: ObjectSpec,
        height_m: float,
        orientation_xyzw: tuple[float, float, float, float],
    ) -> tuple[float, float, float, float, float]:
        """The seen length, width and height and the suction point's radius and tilt."""
        shape = (str(spec.mesh_path), height_m)
        key = self._keys.get(shape)
        if key is None:
            key = len(self._meshes)
            self._meshes.append(self._triangles(spec, height_m))
            self._keys[shape] = key
        mesh = self._meshes[key]
        truth = resting_truth(
            key,
            spec,
            height_m=height_m,
            orientation_xyzw=orientation_xyzw,
            vertices_m=lambda: mesh.reshape(-1, 3),
        )
        _, radius_m, tilt_rad = self._finder(truth)
        view = truth.top_view
        return view.length_m, view.width_m, view.height_m, radius_m, tilt_rad


class SpawnFit:
    """The ``spawned`` event's judgement of a piece (``{"takeable": true}`` or ``{"takeable":
    false, "refusal": ...}``): ``judge`` (:class:`PieceJudge`) of what the camera would
    report of it as it spawns, lying turned by its spawn yaw about z (:class:`SeenShapes`)."""

    def __init__(
        self, judge: PieceJudge, triangles: Callable[[ObjectSpec, float], FloatArray]
    ) -> None:
        self._judge = judge
        self._seen = SeenShapes(triangles)

    def __call__(self, spec: ObjectSpec, height_m: float, yaw_rad: float) -> dict[str, object]:
        """The judgement of ``spec`` spawned ``height_m`` tall, turned ``yaw_rad`` about z."""
        length_m, width_m, seen_height_m, radius_m, tilt_rad = self._seen(
            spec, height_m, yaw_quat(yaw_rad)
        )
        refusal = self._judge(
            class_name=spec.class_name,
            length_m=length_m,
            width_m=width_m,
            height_m=seen_height_m,
            face_radius_m=radius_m,
            face_tilt_rad=tilt_rad,
        )
        if refusal is None:
            return {"takeable": True}
        return {"takeable": False, "refusal": refusal}


__all__ = ["PieceJudge", "SeenShapes", "SpawnFit", "resting_truth", "yaw_quat"]
