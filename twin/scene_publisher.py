"""The scene topics of the twin (``docs/interfaces.md``, values from :mod:`twin.scene`).

``/tf`` (every link of every station, each TCP, every object in the simulation; at the
ground-truth tick), ``/tf_static`` (each station's root link, each camera's two frames),
``/scene/markers`` (belt, bins, robot links; once), ``/scene/objects`` (every live object's
mesh, re-sent whole when the set changes, and a DELETE for each one gone) and
``/scene/targets`` (each station's announced target and TCP path, at
:data:`SCENE_TARGETS_HZ`), sent only while someone takes them (a tap or a matched subscriber),
and not at all when the scene is off.

Extra per-step publishers (:class:`StepPublisher`, such as a camera's images) ride along: the
node hands each the step's stamp after the twin's own messages and the scene.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

from builtin_interfaces.msg import Time
from visualization_msgs.msg import Marker, MarkerArray

from interfaces import contract as c
from interfaces.class_colours import class_colour
from twin import encoders as enc
from twin import scene as sc
from twin.ground_truth import GroundTruth
from twin.link_visuals import link_visuals
from twin.sim import Twin
from twin.tapped_wire import TappedWire

SCENE_TARGETS_HZ = 5.0
"""Rate of ``/scene/targets`` (each station's target and TCP path), sim time."""


class StepPublisher(Protocol):
    """Something the node publishes after every physics step besides its own messages (a
    camera's images, say): it creates its publishers on the node's wire (a
    :class:`twin.tapped_wire.TappedWire`, so the tap records them) when the node is built, and
    is handed each step's stamp (sim time) and step number, in step order. It decides itself
    what is due at that step and whether anyone takes it (:meth:`TappedWire.wanted`)."""

    def attach(self, io: TappedWire, twin: Twin) -> None:
        """Create the publishers on ``io`` for ``twin``'s episode (once, at the node's start)."""
        ...

    def publish_step(self, stamp: Time, step: int) -> None:
        """Publish what is due after step ``step`` (sim time ``stamp``)."""
        ...


class ScenePublisher:
    """The scene topics of one twin, over ``io`` (``enabled=False``: none is ever sent)."""

    def __init__(self, io: TappedWire, twin: Twin, *, enabled: bool) -> None:
        self.io = io
        self.twin = twin
        self.enabled = enabled
        self.pub_tf = io.publisher(c.TF)
        self.pub_tf_static = io.publisher(c.TF_STATIC)
        self.pub_markers = io.publisher(c.SCENE_MARKERS)
        self.pub_objects = io.publisher(c.SCENE_OBJECTS)
        self.pub_targets = io.publisher(c.SCENE_TARGETS)
        self._pubs = (
            self.pub_tf,
            self.pub_tf_static,
            self.pub_markers,
            self.pub_objects,
            self.pub_targets,
        )
        self._static_sent = False
        self.targets_every = max(1, round(1.0 / (SCENE_TARGETS_HZ * twin.dt_s)))
        self.colour = class_colour(twin.cell.materials)
        self._objects = sc.ObjectMarkers(mesh=twin.object_mesh, colour=self.colour)
        self._marker_msgs: dict[tuple[str, int], tuple[sc.SceneMarker, Marker]] = {}
        self.targets: list[sc.Target | None] = [None for _ in twin.stations]
        self.paths = [sc.TcpPath() for _ in twin.stations]

    def set_target(self, station_index: int, target: sc.Target | None) -> None:
        """A station's announced target (None: none in pursuit), drawn on ``/scene/targets``."""
        self.targets[station_index] = target

    def wanted(self) -> bool:
        """The scene is on and someone takes it: a tap (recording, live view) or a matched
        subscriber of a scene topic."""
        if not self.enabled:
            return False
        return any(self.io.wanted(p) for p in self._pubs)

    def publish(self, stamp: Time, objects: tuple[GroundTruth, ...], *, targets: bool) -> None:
        """The scene at a ground-truth tick: the static part once, ``/tf``, the objects'
        markers when their set changed, and (``targets``) each station's target and path."""
        twin = self.twin
        if not self._static_sent:
            self._static_sent = True
            self.publish_static(stamp)
        live = [gt for gt in objects if not gt.in_bin]
        frames: list[sc.Frame] = []
        for station, path in zip(twin.stations, self.paths, strict=True):
            tcp = twin.tcp_pose(station.index)
            frames += sc.station_frames(station.spec.namespace, station.robot.link_poses(), tcp)
            path.add(twin.time_s, tcp[0])
        frames += sc.world_frames(
            (sc.object_frame(gt.id), (gt.position_m, gt.orientation_xyzw)) for gt in live
        )
        self.io.send_serialized(self.pub_tf, sc.tf_message_cdr(frames, stamp.sec, stamp.nanosec))
        update = self._objects.update(gt.id for gt in live)
        if update is not None:
            self.io.send(self.pub_objects, self._marker_array(update.markers, stamp))
        if targets:
            markers: list[sc.SceneMarker] = []
            for i, (target, path) in enumerate(zip(self.targets, self.paths, strict=True)):
                markers += [sc.target_marker(i, target, twin.time_s), path.marker(i)]
            self.io.send(self.pub_targets, self._marker_array(markers, stamp))

    def publish_static(self, stamp: Time) -> None:
        """``/tf_static`` (each station's root link in ``world``, each camera's link and optical
        frame) and ``/scene/markers`` (belt, bins, every station's link meshes), once."""
        twin = self.twin
        frames: list[sc.Frame] = []
        markers = [sc.belt_marker(twin.cell), *sc.bin_markers(twin.cell, self.colour)]
        for station in twin.stations:
            robot, ns = station.robot, station.spec.namespace
            root = sc.link_frame(ns, robot.root_link)
            frames += sc.world_frames([(root, robot.root_pose())])
            markers += sc.link_markers(ns, link_visuals(robot.urdf))
        frames += sc.camera_frames(twin.cell.cameras)
        self.io.send_serialized(
            self.pub_tf_static, sc.tf_message_cdr(frames, stamp.sec, stamp.nanosec)
        )
        self.io.send(self.pub_markers, self._marker_array(markers, stamp))

    def _marker_array(self, markers: Iterable[Any], stamp: Time) -> MarkerArray:
        """The markers as a ``MarkerArray``, each stamped ``stamp``; a marker already converted
        (the same value) is reused, so a live object's mesh is converted once."""
        out = []
        for marker in markers:
            key = (marker.ns, marker.id)
            cached = self._marker_msgs.get(key)
            if cached is not None and cached[0] is marker:
                cached[1].header.stamp = stamp
                out.append(cached[1])
                continue
            msg = enc.marker(marker, stamp)
            if marker.action is sc.MarkerAction.ADD and marker.frame_locked:
                self._marker_msgs[key] = (marker, msg)
            else:
                self._marker_msgs.pop(key, None)
            out.append(msg)
        return MarkerArray(markers=out)


__all__ = ["SCENE_TARGETS_HZ", "ScenePublisher", "StepPublisher"]
