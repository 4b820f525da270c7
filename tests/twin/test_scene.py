"""The scene's pure logic (frames, markers, object life cycle, colours, decimation) and the
twin's accessors it reads (link poses, link visuals, object meshes), without ROS."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as pb
import pybullet_data
import pytest
import trimesh

from interfaces.cell import default_cell, load_cell
from interfaces.cell_topics import cell_topics
from interfaces.class_colours import CLASS_RGB, class_rgb, dataset_class_rgb
from interfaces.contract import SCENE
from interfaces.urdf import station_urdf
from twin import scene as sc
from twin.errors import ConfigError
from twin.link_visuals import link_visuals
from twin.objects import read_obj_triangles
from twin.robot import Robot
from twin.scenario import ObjectLevel, Scenario, SystemLevel
from twin.sim import ArmCommand, Twin


# -- frames ------------------------------------------------------------------------------------
def test_frames_follow_the_topic_namespace_convention() -> None:
    assert sc.link_frame("s1", "panda_link3") == "s1/panda_link3"
    assert sc.tcp_frame("s1") == "s1/tcp"
    assert sc.link_frame("", "panda_link3") == "panda_link3"  # bare, as /joint_states
    assert sc.tcp_frame("") == "tcp"
    assert sc.object_frame(12) == "object/12"
    pose = ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
    frames = sc.station_frames("s2", {"a": pose, "b": pose}, pose)
    assert [(f.parent, f.child) for f in frames] == [
        ("world", "s2/a"),
        ("world", "s2/b"),
        ("world", "s2/tcp"),
    ]


def test_tf_messages_are_the_cdr_of_ros_tfmessage() -> None:
    """The hand-written CDR of a ``tf2_msgs/msg/TFMessage`` is byte for byte what rosbags (an
    independent CDR implementation, ROS 2 Jazzy's types) serializes for the same message, for
    names of every length modulo 4 and an empty message."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    frames = [
        sc.Frame("world", name, (0.1 * i, -0.2, 1e-9 * i), (0.0, 0.6, 0.0, 0.8))
        for i, name in enumerate(["tcp", "s1/tcp", "object/12", "panda_link0", "s22/panda_hand"])
    ]
    time = store.types["builtin_interfaces/msg/Time"](sec=12, nanosec=345_678_901)
    transforms = [
        store.types["geometry_msgs/msg/TransformStamped"](
            header=store.types["std_msgs/msg/Header"](stamp=time, frame_id=f.parent),
            child_frame_id=f.child,
            transform=store.types["geometry_msgs/msg/Transform"](
                translation=store.types["geometry_msgs/msg/Vector3"](*f.position_m),
                rotation=store.types["geometry_msgs/msg/Quaternion"](*f.orientation_xyzw),
            ),
        )
        for f in frames
    ]
    for some in (transforms, transforms[:1], []):
        msg = store.types["tf2_msgs/msg/TFMessage"](transforms=some)
        expected = bytes(store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
        assert sc.tf_message_cdr(frames[: len(some)], 12, 345_678_901) == expected


# -- decimation --------------------------------------------------------------------------------
def test_a_mesh_within_budget_is_unchanged() -> None:
    box = sc.box_triangles((0.1, 0.2, 0.3))
    assert np.array_equal(sc.decimate(box, 12), box)


def test_decimation_keeps_the_budget_and_the_shape() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.1)
    triangles = np.asarray(sphere.triangles)
    assert len(triangles) == 20480
    small = sc.decimate(triangles, 300)
    assert 100 <= len(small) <= 300
    radii = np.linalg.norm(small.reshape(-1, 3), axis=1)
    assert radii.max() <= 0.1 + 1e-9
    assert radii.min() >= 0.085  # cluster centroids stay near the surface
    extent = small.reshape(-1, 3).max(axis=0) - small.reshape(-1, 3).min(axis=0)
    assert extent == pytest.approx([0.2, 0.2, 0.2], abs=0.02)
    unique = {tuple(np.sort(t.round(9), axis=0).ravel()) for t in small}
    assert len(unique) == len(small)  # no repeated triangle
    areas = np.linalg.norm(np.cross(small[:, 1] - small[:, 0], small[:, 2] - small[:, 0]), axis=1)
    assert areas.min() > 0.0  # no collapsed triangle


def test_decimation_refuses_an_empty_budget() -> None:
    with pytest.raises(ValueError, match="max_triangles = 0"):
        sc.decimate(sc.box_triangles((1.0, 1.0, 1.0)), 0)


# -- the static scene --------------------------------------------------------------------------
def test_belt_and_bins_have_the_cells_geometry() -> None:
    cell = default_cell()
    belt = sc.belt_marker(cell)
    assert belt.kind is sc.MarkerKind.CUBE
    assert belt.frame_id == "world"
    assert belt.scale == pytest.approx((3.4, 0.6, 0.04))
    assert belt.position_m[0] + 0.5 * belt.scale[0] == pytest.approx(cell.belt.end_x_m)
    assert belt.position_m[2] + 0.5 * belt.scale[2] == pytest.approx(cell.belt.surface_z_m)
    bins = sc.bin_markers(cell, class_rgb)
    assert len(bins) == len(cell.bins) == 4
    for marker, spec in zip(bins, cell.bins, strict=True):
        assert marker.kind is sc.MarkerKind.TRIANGLE_LIST
        assert marker.rgba[:3] == CLASS_RGB[spec.class_name]
        assert marker.points_m is not None
        lo, hi = marker.points_m.min(axis=0), marker.points_m.max(axis=0)
        half = 0.5 * spec.size_m
        assert lo == pytest.approx([spec.centre_x_m - half, spec.centre_y_m - half, spec.floor_z_m])
        assert hi == pytest.approx([spec.centre_x_m + half, spec.centre_y_m + half, spec.top_z_m])


def test_link_markers_are_decimated_and_locked_to_their_frames() -> None:
    visual = sc.LinkVisual("panda_link1", sc.decimate(sc.box_triangles((1, 1, 1)), 12))
    big = sc.LinkVisual(
        "panda_link2", np.asarray(trimesh.creation.icosphere(subdivisions=4).triangles)
    )
    empty = sc.LinkVisual("panda_link8", np.zeros((0, 3, 3)))
    markers = sc.link_markers("s1", [visual, big, empty], max_triangles=100)
    assert [m.frame_id for m in markers] == ["s1/panda_link1", "s1/panda_link2"]
    assert all(m.frame_locked and m.ns == "s1/links" for m in markers)
    assert all(m.points_m is not None and len(m.points_m) <= 300 for m in markers)


# -- objects -----------------------------------------------------------------------------------
def test_objects_are_added_once_resent_whole_and_deleted_when_gone() -> None:
    calls: list[int] = []
    classes = {1: "brick", 2: "wood", 3: "concrete"}

    def mesh(object_id: int) -> tuple[np.ndarray, str]:
        calls.append(object_id)
        return sc.box_triangles((0.01 * object_id, 0.02, 0.03)), classes[object_id]

    markers = sc.ObjectMarkers(mesh=mesh, colour=class_rgb)
    first = markers.update([1, 2])
    assert first is not None
    assert first.added == (1, 2)
    assert first.removed == ()
    assert [(m.ns, m.id, m.frame_id, m.action) for m in first.markers] == [
        ("objects", 1, "object/1", sc.MarkerAction.ADD),
        ("objects", 2, "object/2", sc.MarkerAction.ADD),
    ]
    brick = first.markers[0]
    assert brick.kind is sc.MarkerKind.TRIANGLE_LIST
    assert brick.frame_locked
    assert brick.rgba == (*CLASS_RGB["brick"], 1.0)
    assert brick.points_m is not None
    assert np.array_equal(brick.points_m, mesh(1)[0].reshape(-1, 3))
    calls.clear()
    assert markers.update([2, 1]) is None  # nothing changed: nothing to send
    second = markers.update([2, 3])
    assert second is not None
    assert (second.added, second.removed) == ((3,), (1,))
    assert [(m.id, m.action) for m in second.markers] == [
        (2, sc.MarkerAction.ADD),
        (3, sc.MarkerAction.ADD),
        (1, sc.MarkerAction.DELETE),
    ]
    assert second.markers[0] is first.markers[1]  # the same marker, not rebuilt
    assert second.markers[2].frame_id == "object/1"
    assert calls == [3]  # each mesh read once
    last = markers.update([])
    assert last is not None
    assert [(m.id, m.action) for m in last.markers] == [
        (2, sc.MarkerAction.DELETE),
        (3, sc.MarkerAction.DELETE),
    ]


def test_the_datasets_materials_colour_an_objects_mesh(tmp_path: Path) -> None:
    (tmp_path / "materials.mtl").write_text(
        "newmtl brick\nKd 0.1 0.2 0.3\nnewmtl odd\nKd 0.5 0.5 0.5\n", encoding="utf-8"
    )
    colour = partial(class_rgb, overrides=dataset_class_rgb(tmp_path))
    names = {1: "brick", 2: "wood"}
    markers = sc.ObjectMarkers(
        mesh=lambda i: (sc.box_triangles((0.1, 0.1, 0.1)), names[i]), colour=colour
    )
    update = markers.update([1, 2])
    assert update is not None
    assert update.markers[0].rgba == (0.1, 0.2, 0.3, 1.0)  # the dataset's brick
    assert update.markers[1].rgba == (*CLASS_RGB["wood"], 1.0)  # the shared table's wood


# -- targets and paths -------------------------------------------------------------------------
def test_a_target_moves_on_with_its_velocity_and_is_deleted_when_none() -> None:
    target = sc.Target((0.1, 0.5, 0.05), (0.4, 0.0, 0.0), stamp_s=2.0)
    marker = sc.target_marker(1, target, now_s=2.5)
    assert marker.kind is sc.MarkerKind.SPHERE
    assert (marker.ns, marker.id, marker.frame_id) == ("targets", 1, "world")
    assert marker.position_m == pytest.approx((0.3, 0.5, 0.05))
    gone = sc.target_marker(1, None, now_s=3.0)
    assert (gone.ns, gone.id, gone.action) == ("targets", 1, sc.MarkerAction.DELETE)


def test_a_tcp_path_keeps_its_window() -> None:
    path = sc.TcpPath(window_s=1.0)
    path.add(0.0, (0.0, 0.0, 0.0))
    assert path.marker(0).action is sc.MarkerAction.DELETE  # one point is no line
    for k in range(1, 31):
        path.add(k / 10.0, (k / 10.0, 0.0, 0.0))
    points = path.points_m
    assert points[0, 0] == pytest.approx(2.0)
    assert points[-1, 0] == pytest.approx(3.0)
    assert len(points) == 11
    marker = path.marker(2)
    assert (marker.kind, marker.ns, marker.id) == (sc.MarkerKind.LINE_STRIP, "tcp_paths", 2)
    assert marker.scale[0] == sc.PATH_WIDTH_M


# -- what the twin gives the scene ----------------------------------------------------------------
@pytest.fixture
def robot() -> Iterator[Robot]:
    client = pb.connect(pb.DIRECT)
    station = load_cell("two_pandas").stations[0]
    robot = Robot(
        client,
        station.robot,
        base_position_m=station.base_position_m,
        base_yaw_rad=0.3,
        urdf=station_urdf(station.robot, station.tool),
    )
    yield robot
    pb.disconnect(client)


def test_link_poses_are_the_forward_kinematics_of_the_urdf(robot: Robot) -> None:
    """Every link frame against Pinocchio's forward kinematics of the same URDF (an independent
    computation), at a random joint configuration."""
    model = pin.buildModelFromUrdf(str(robot.urdf))
    data = model.createData()
    rng = np.random.default_rng(3)
    q = pin.neutral(model)
    for j in range(len(robot.infos)):
        info = robot.infos[j]
        if info[2] == pb.JOINT_FIXED:
            continue
        lo, hi = (info[8], info[9]) if info[9] > info[8] else (-math.pi, math.pi)
        value = float(rng.uniform(lo, hi))
        pb.resetJointState(robot.body, j, value, physicsClientId=robot.client)
        joint = model.joints[model.getJointId(info[1].decode())]
        q[joint.idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    base = pin.SE3(
        pin.rpy.rpyToMatrix(0.0, 0.0, 0.3),
        np.array(load_cell("two_pandas").stations[0].base_position_m),
    )
    poses = robot.link_poses()
    root_pos, root_orn = robot.root_pose()
    poses[robot.root_link] = (root_pos, root_orn)
    assert len(poses) == len(robot.infos) + 1
    for link, (pos, orn) in poses.items():
        expected = base * data.oMf[model.getFrameId(link)]
        assert np.asarray(pos) == pytest.approx(expected.translation, abs=1e-6), link
        rotation = np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
        assert rotation == pytest.approx(expected.rotation, abs=1e-6), link


def test_link_visuals_cover_every_link_with_geometry(robot: Robot) -> None:
    visuals = link_visuals(robot.urdf)
    names = [v.link for v in visuals]
    assert names[:8] == [f"panda_link{i}" for i in range(8)]
    assert {"panda_hand", "panda_leftfinger", "panda_rightfinger"} <= set(names)
    for visual in visuals:
        assert 0 < len(visual.triangles) <= sc.LINK_MAX_TRIANGLES
    link1 = next(v for v in visuals if v.link == "panda_link1").triangles.reshape(-1, 3)
    data = Path(pybullet_data.getDataPath()) / "franka_panda" / "meshes" / "visual"
    mesh = trimesh.load(data / "link1.obj", force="mesh")
    assert isinstance(mesh, trimesh.Trimesh)
    full = np.asarray(mesh.vertices)
    assert len(full) > 5000
    # the decimated link keeps the place and extent of the file's mesh, to a few mm
    assert link1.min(axis=0) == pytest.approx(full.min(axis=0), abs=0.01)
    assert link1.max(axis=0) == pytest.approx(full.max(axis=0), abs=0.01)


def test_link_visuals_come_back_from_the_cache_as_they_were_made(
    robot: Robot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first call reads and decimates the meshes and writes the cache, a later process
    (the in-memory cache cleared) reads it: the same links, colours and triangles (to 1 um);
    a corrupt cache file is read around."""
    from twin import link_visuals as visuals_module

    monkeypatch.setenv("CDW_TWIN_CACHE", str(tmp_path))
    visuals_module._link_visuals.cache_clear()
    made = link_visuals(robot.urdf, 50)
    files = list((tmp_path / "scene").glob("visuals-*.json"))
    assert len(files) == 1
    visuals_module._link_visuals.cache_clear()
    again = link_visuals(robot.urdf, 50)
    assert [(v.link, v.rgba) for v in again] == [(v.link, v.rgba) for v in made]
    for a, b in zip(again, made, strict=True):
        assert len(b.triangles) <= 50
        assert a.triangles == pytest.approx(b.triangles, abs=1e-6)
    files[0].write_text("{not json", encoding="utf-8")
    visuals_module._link_visuals.cache_clear()
    assert [v.link for v in link_visuals(robot.urdf, 50)] == [v.link for v in made]
    visuals_module._link_visuals.cache_clear()


def test_an_objects_mesh_is_its_file_stretched_to_its_height(builtin_meshes: Path) -> None:
    scenario = Scenario(
        duration_s=1.0,
        objects=ObjectLevel(max_objects=5),
        system=SystemLevel(belt_speed_mps=0.4, prefill_m=1.0),
    )
    with Twin(scenario, dataset_dir=builtin_meshes) as twin:
        twin.reset(seed=1)
        truths = twin.observe_objects()
        assert truths
        for gt in truths:
            triangles, class_name = twin.object_mesh(gt.id)
            assert class_name == gt.class_name
            spec = next(
                o for layout in twin.layouts for o in layout.objects if o.object_id == gt.source_id
            )
            raw = read_obj_triangles(spec.mesh_path)
            assert triangles.shape == raw.shape
            assert triangles[..., :2] == pytest.approx(raw[..., :2])
            z = triangles[..., 2]
            assert z.max() - z.min() == pytest.approx(gt.height_m, abs=2e-6)  # OBJ's 1 um digits
        with pytest.raises(ConfigError, match="object id 999"):
            twin.object_mesh(999)


def test_reading_the_scene_does_not_change_the_physics(builtin_meshes: Path) -> None:
    """Link poses read at every ground-truth tick (forward kinematics) leave every trajectory
    bit for bit as it is without them."""

    def run(read_scene: bool) -> list[tuple[float, ...]]:
        scenario = Scenario(
            duration_s=1.5,
            objects=ObjectLevel(max_objects=8),
            system=SystemLevel(belt_speed_mps=0.5, prefill_m=1.0),
        )
        out = []
        with Twin(scenario, dataset_dir=builtin_meshes) as twin:
            twin.reset(seed=5)
            home = np.array(twin.cell.stations[0].robot.home_joint_positions)
            while twin.time_s < scenario.duration_s - 1e-9:
                q = tuple(home + 0.3 * np.sin(2 * twin.time_s + np.arange(home.size)))
                twin.advance(ArmCommand(q))
                if read_scene and twin.step_count % 8 == 0:
                    twin.stations[0].robot.link_poses()
                    twin.stations[0].robot.root_pose()
                obs = twin.observe()
                out.append(
                    tuple(v for o in obs.objects for v in (*o.position_m, *o.orientation_xyzw))
                    + obs.joint_positions
                )
        return out

    assert run(True) == run(False)


# -- the Foxglove layout -----------------------------------------------------------------------
LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove" / "cdw_twin_layout.json"


def _panels(node: object) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert isinstance(node, dict)
    return _panels(node["first"]) + _panels(node["second"])


def _script_topics(source: str) -> tuple[set[str], str]:
    """A Foxglove user script's input topics and output topic."""
    inputs = re.search(r"inputs = \[([^\]]*)\]", source)
    output = re.search(r'output = "([^"]+)"', source)
    assert inputs is not None
    assert output is not None
    return set(re.findall(r'"(/[^"]+)"', inputs.group(1))), output.group(1)


def test_the_foxglove_layout_names_only_topics_the_cell_publishes() -> None:
    """Every panel of the layout has a configuration, and every topic it reads (3D topics, plot
    and message paths, user-script inputs) is a topic of the reference cell's contract or the
    output of one of its user scripts; the 3D panel shows every marker topic of the scene."""
    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"])
    assert {p.split("!")[0] for p in panels} == {"3D", "Plot", "RawMessages", "Image"}
    wires = {wire for wire, _ in cell_topics(default_cell())}
    outputs: set[str] = set()
    for script in layout["userNodes"].values():
        inputs, output = _script_topics(script["sourceCode"])
        assert inputs <= wires, inputs - wires
        outputs.add(output)
    markers = {t.name for t in SCENE if t.msgtype.endswith("MarkerArray")}
    named: set[str] = set()
    for panel, config in layout["configById"].items():
        if panel.startswith("3D!"):
            assert config["followTf"] == "world"
            assert set(config["topics"]) == markers
            named |= set(config["topics"])
        if panel.startswith("Image!"):  # the reference cell's camera, with its pinhole model
            image = config["imageMode"]
            assert {image["imageTopic"], image["calibrationTopic"]} <= wires
            named |= {image["imageTopic"], image["calibrationTopic"]}
        for path in [p["value"] for p in config.get("paths", [])] + [config.get("topicPath", "")]:
            if path:
                named.add(path.split(".", 1)[0])
    assert named <= wires | outputs, named - wires - outputs
    assert {"/conveyor/state", "/events", *outputs} <= named
