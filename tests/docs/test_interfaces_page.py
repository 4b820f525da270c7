"""``docs/interfaces.md`` against the code: every number and name a client relies on.

Each table of the page is rebuilt from what the twin actually loads (the robot and its tool in
PyBullet from the station's URDF, the URDF file itself, the shipped cell files, the scenario's
defaults, the topic contract :mod:`interfaces.contract`, the event types and the keys every
emitter passes, the rejection reasons) and compared with the page; a failure prints the rows the
page should carry. No number of the page is copied here.
"""

from __future__ import annotations

import ast
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable

import numpy as np
import pybullet as pb
import pytest

from interfaces import contract
from interfaces.camera_topics import camera_topics
from interfaces.cell import Cell, StationSpec, default_cell
from interfaces.events import Event, EventType
from interfaces.robots import resolve_urdf
from interfaces.tools import ParallelJawSpec
from tests.docs.conftest import (
    ROOT,
    Loaded,
    Page,
    assert_rows,
    cells,
    num,
    row,
    shipped_cells,
    short,
    ticked,
    yaw_of_down,
)
from twin.perception_config import PerceptionConfig
from twin.robot import HOLD_S
from twin.scenario import Scenario

MSG_DIR = ROOT / "interfaces" / "cdw_interfaces" / "msg"
Load = Callable[[StationSpec], Loaded]


def _reference() -> StationSpec:
    return default_cell().stations[0]


@pytest.fixture(scope="module")
def panda(load_station: Load) -> Loaded:
    """The reference cell's Panda with its hand, as the twin loads it, at the start pose."""
    return load_station(_reference())


# -- the robot and its limits -------------------------------------------------------------------
def _from_flange(loaded: Loaded) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Position and roll-pitch-yaw of the TCP link's frame in the robot's flange link's frame."""
    robot, client = loaded.robot, loaded.client
    frames = []
    for name in (loaded.station.robot.flange_link, loaded.station.tool.tcp_link):
        link = robot.link_index(name, "link")
        state = pb.getLinkState(
            robot.body, link, computeForwardKinematics=True, physicsClientId=client
        )
        frames.append((state[4], state[5]))
    (flange_pos, flange_orn), (tcp_pos, tcp_orn) = frames
    inv_pos, inv_orn = pb.invertTransform(flange_pos, flange_orn)
    pos, orn = pb.multiplyTransforms(inv_pos, inv_orn, tcp_pos, tcp_orn)
    return tuple(pos), tuple(pb.getEulerFromQuaternion(orn))


def robot_rows(panda: Loaded) -> list[str]:
    """The page's robot table, from the loaded robot and the reference cell's station."""
    station = panda.station
    spec, tool = station.robot, station.tool
    assert isinstance(tool, ParallelJawSpec)
    pos, rpy = _from_flange(panda)
    xyz = ", ".join(num(v) for v in pos)
    angles = ", ".join(num(v) for v in rpy)
    home = ", ".join(f"{q:g}" for q in spec.home_joint_positions)
    fingers = [panda.robot.infos[panda.robot.joint_index(j, "finger joint")] for j in tool.joints]
    finger_range = f"{min(f[8] for f in fingers):g} to {max(f[9] for f in fingers):g} m each"
    base = ", ".join(f"{v:g}" for v in station.base_position_m)
    arm = ", ".join(f"`{j}`" for j in spec.arm_joints)
    finger_names = ", ".join(f"`{j}`" for j in tool.joints)
    tcp, rotation = panda.tcp()
    yaw = yaw_of_down(rotation)
    assert yaw is not None, "the TCP points down at the start pose"
    return [
        row(
            "model",
            f"URDF `{spec.urdf}` from `pybullet_data` (Franka Emika Panda with its hand): "
            f"robot `{spec.name}`, tool `{tool.name}`",
        ),
        row(
            "base",
            f"link `{panda.robot.root_link}` at ({base}) m, yaw {station.base_yaw_rad:g} rad: "
            "the base frame is `world`",
        ),
        row("arm joints", f"{arm} (revolute)"),
        row(
            "finger joints", f"{finger_names} (prismatic, {finger_range}; report half the opening)"
        ),
        row(
            "TCP",
            f"link `{tool.tcp_link}`; from the flange `{spec.flange_link}`: xyz ({xyz}) m, "
            f"rpy ({angles}) rad",
        ),
        row("gripper opening", f"0 (closed) to {tool.max_opening_m:g} m (open)"),
        row("start pose", f"arm joints ({home}) rad, gripper open"),
        row(
            "TCP at the start pose",
            f"({', '.join(short(v, 3) for v in tcp)}) m, pointing down, yaw {short(yaw, 3)} rad "
            "(to 1 mm and 1 mrad)",
        ),
    ]


def _urdf_limits(station: StationSpec) -> dict[str, tuple[float, float]]:
    """The ``<limit>`` of each arm joint in the robot's URDF file as shipped."""
    root = ET.parse(resolve_urdf(station.robot.urdf)).getroot()
    out = {}
    for joint in root.findall("joint"):
        limit = joint.find("limit")
        if joint.get("name") in station.robot.arm_joints and limit is not None:
            out[joint.get("name", "")] = (
                float(limit.get("lower", "")),
                float(limit.get("upper", "")),
            )
    return out


def limit_rows(panda: Loaded) -> list[str]:
    """The page's joint-limit table: the limits the twin loads from the station's URDF, the
    acceleration limits its joint limiter applies, and the URDF file's own position limits."""
    lim = panda.robot.limits
    spec = panda.robot.spec
    urdf = _urdf_limits(panda.station)
    return [
        row(
            f"`{name}`",
            num(lim.lower[i]),
            num(lim.upper[i]),
            num(lim.velocity[i]),
            f"{spec.joint_max_acceleration_rps2[i]:g}",
            f"{lim.effort[i]:g}",
            num(urdf[name][0]),
            num(urdf[name][1]),
        )
        for i, name in enumerate(spec.arm_joints)
    ]


def test_the_robot_table_is_what_the_twin_loads(interfaces_page: Page, panda: Loaded) -> None:
    assert_rows(interfaces_page, "The robot", robot_rows(panda))


def test_the_joint_limits_in_force_are_those_the_twin_loads(
    interfaces_page: Page, panda: Loaded
) -> None:
    assert_rows(interfaces_page, "Joint limits", limit_rows(panda))
    # they are the catalogue's datasheet limits, not a default the loader put in their place
    spec = panda.robot.spec
    assert panda.robot.limits.lower.tolist() == [lo for lo, _ in spec.joint_position_limits_rad]
    assert panda.robot.limits.velocity.tolist() == list(spec.joint_max_velocity_rps)


def test_every_joint_limit_in_force_differs_from_the_urdf_files(panda: Loaded) -> None:
    """The page says every position limit is narrower than the URDF file's, and is that file's
    ``safety_controller`` soft limit: so it is."""
    urdf = _urdf_limits(panda.station)
    root = ET.parse(resolve_urdf(panda.station.robot.urdf)).getroot()
    soft = {
        joint.get("name"): (
            float(safety.get("soft_lower_limit", "")),
            float(safety.get("soft_upper_limit", "")),
        )
        for joint in root.findall("joint")
        if (safety := joint.find("safety_controller")) is not None
    }
    assert "`safety_controller` soft limits" in " ".join(
        (ROOT / "docs" / "interfaces.md").read_text(encoding="utf-8").split()
    )
    for i, name in enumerate(panda.robot.spec.arm_joints):
        lower, upper = urdf[name]
        in_force = (panda.robot.limits.lower[i], panda.robot.limits.upper[i])
        assert lower < in_force[0] < in_force[1] < upper, name
        assert in_force == pytest.approx(soft[name], abs=1e-9), name


def test_the_tcp_offset_is_the_urdf_files(panda: Loaded) -> None:
    """The TCP link's frame in the flange, from the URDF file's joints (flange -> hand -> TCP)
    composed by hand, equals what PyBullet loads."""
    root = ET.parse(resolve_urdf(panda.station.robot.urdf)).getroot()

    def link_of(joint: ET.Element, tag: str) -> str:
        element = joint.find(tag)
        assert element is not None
        return element.get("link", "")

    parent = {link_of(j, "child"): j for j in root.findall("joint")}
    chain, link = [], panda.station.tool.tcp_link
    while link != panda.station.robot.flange_link:
        chain.append(parent[link])
        link = link_of(parent[link], "parent")
    position, rotation = np.zeros(3), np.eye(3)
    for joint in reversed(chain):
        origin = joint.find("origin")
        assert origin is not None
        xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()])
        angles = [float(v) for v in origin.get("rpy", "0 0 0").split()]
        turn = np.array(pb.getMatrixFromQuaternion(pb.getQuaternionFromEuler(angles)))
        position, rotation = position + rotation @ xyz, rotation @ turn.reshape(3, 3)
    pos, rpy = _from_flange(panda)
    assert pos == pytest.approx(position, abs=1e-6)  # PyBullet keeps frames in float32
    turn = np.array(pb.getMatrixFromQuaternion(pb.getQuaternionFromEuler(rpy))).reshape(3, 3)
    assert turn == pytest.approx(rotation, abs=1e-6)


# -- the belt, the bins, the camera, the stations -----------------------------------------
def belt_rows(cell: Cell) -> list[str]:
    """The page's belt table, from the cell and the scenario's default belt speed."""
    belt = cell.belt
    speed = Scenario().system.belt_speed_mps
    return [
        row(
            "belt",
            f"x from {belt.start_x_m:g} to {belt.end_x_m:g} m, {belt.width_m:g} m wide about its "
            f"centreline y = {belt.centre_y_m:g} m, surface at z = {belt.surface_z_m:g} m; "
            f"objects enter at x = {belt.infeed_x_m:g} m and fall off beyond "
            f"x = {belt.end_x_m:g} m",
        ),
        row(
            "speed",
            f"the scenario's `system.belt_speed_mps`: {speed:g} m/s unless the scenario or "
            "`cdw-twin twin-node --speed` sets another; the belt starts at rest and the drive "
            "brings it to that setpoint",
        ),
    ]


def bin_rows(cell: Cell) -> list[str]:
    """The page's bin table, from the cell."""
    return [
        row(
            f"`{b.class_name}`",
            *(
                f"{v:g}"
                for v in (
                    b.centre_x_m,
                    b.centre_y_m,
                    b.top_z_m,
                    b.inner_half_m,
                    b.size_m,
                    b.floor_z_m,
                    b.drop_z_m,
                )
            ),
        )
        for b in cell.bins
    ]


def camera_rows(cfg: PerceptionConfig, cell: Cell) -> list[str]:
    """The page's camera-model table (the defaults; a scenario's ``perception:`` overrides the
    error model, the cell's ``camera`` the field of view)."""
    camera = cell.camera
    return [
        row(
            "field of view",
            f"x in [{camera.fov_min_x_m:g}, {camera.fov_max_x_m:g}] m (the cell's `camera`), "
            "objects on the belt only",
        ),
        row("rate, latency", f"{cfg.rate_hz:g} Hz, {cfg.latency_s:g} s"),
        row(
            "noise (1 sigma)",
            f"position {cfg.position_noise_m:g} m in x and y, yaw {cfg.yaw_noise_rad:g} rad",
        ),
        row(
            "drops, misclassification",
            f"{cfg.drop_rate:g}, {cfg.misclassification_rate:g} per detection "
            "(a wrong class: uniform among the others)",
        ),
        row(
            "`confidence`",
            f"Beta(k m, k (1 - m)), k = {cfg.confidence_concentration:g}; "
            f"m = {cfg.confidence_correct_mean:g} when the class is right, "
            f"{cfg.confidence_wrong_mean:g} when it is wrong; 1 from the zero-noise camera",
        ),
    ]


def station_rows() -> list[str]:
    """The page's table of the shipped cells' stations."""
    rows = []
    for path, cell in shipped_cells():
        for s in cell.stations:
            base = ", ".join(f"{v:g}" for v in s.base_position_m)
            lo, hi = s.pick_window_x_m
            rows.append(
                row(
                    f"`{path.stem}`",
                    f"`{s.name}`",
                    f"`{s.namespace}`" if s.namespace else "(empty)",
                    f"`{s.robot.name}` + `{s.tool.name}`",
                    f"({base}), yaw {s.base_yaw_rad:g}",
                    f"[{lo:g}, {hi:g}]",
                    ", ".join(f"`{b.class_name}`" for b in s.bins),
                )
            )
    return rows


def test_the_cell_bins_camera_and_station_tables_are_the_shipped_cells(
    interfaces_page: Page,
) -> None:
    cell = default_cell()
    assert_rows(interfaces_page, "The belt", belt_rows(cell))
    assert_rows(interfaces_page, "Bins", bin_rows(cell))
    assert_rows(interfaces_page, "Perception", camera_rows(PerceptionConfig(), cell))
    assert_rows(interfaces_page, "Stations", station_rows())


def test_the_release_height_is_stated_against_the_rim(interfaces_page: Page) -> None:
    """The bins' release height in world z and above the rim, as the reference cell sets it."""
    ((drop_z, top_z),) = {(b.drop_z_m, b.top_z_m) for b in default_cell().bins}
    text = interfaces_page.flat("Bins")
    assert f"world z {drop_z:.2f} m, {drop_z - top_z:.2f} m above the rim" in text
    assert "`cell/bins`" in text


def test_the_cell_file_section_names_the_files(interfaces_page: Page) -> None:
    text = interfaces_page.flat("The cell file")
    assert "`interfaces/cells/default.yaml`" in text
    for path, _ in shipped_cells():
        assert f"`{path.stem}`" in text, path.stem
    assert "--station NAME" in text
    assert "`cell/bins`" in text


# -- tools: TCP frames and the jaws' geometry ------------------------------------------------------
def _pairs() -> list[StationSpec]:
    """One station per robot and tool of the shipped cells, by robot then tool name."""
    seen: dict[tuple[str, str], StationSpec] = {}
    for _, cell in shipped_cells():
        for station in cell.stations:
            seen.setdefault((station.robot.name, station.tool.name), station)
    return [seen[key] for key in sorted(seen)]


def _finger_axis(loaded: Loaded) -> str:
    """Along which TCP axis the fingers move from open to closed (each finger link's frame)."""
    spec = loaded.station.tool
    if not isinstance(spec, ParallelJawSpec):
        return "(no fingers)"
    loaded.set_fingers(1.0)
    opened = [loaded.in_tcp(link) for link in spec.links]
    loaded.set_fingers(0.0)
    closed = [loaded.in_tcp(link) for link in spec.links]
    loaded.set_fingers(1.0)
    axes = set()
    for a, b in zip(opened, closed, strict=True):
        move = (b - a) / np.linalg.norm(b - a)
        axis = int(np.argmax(np.abs(move)))
        assert abs(move[axis]) == pytest.approx(1.0, abs=1e-9), move
        axes.add(axis)
    (axis,) = axes
    return f"TCP {'xyz'[axis]}"


def tcp_frame_rows(load_station: Load) -> list[str]:
    """The page's TCP-frame table, measured in PyBullet for each robot and tool."""
    rows = []
    for station in _pairs():
        loaded = load_station(station)
        pos, rpy = _from_flange(loaded)
        rows.append(
            row(
                f"`{station.robot.name}` + `{station.tool.name}`",
                f"`{station.tool.tcp_link}`",
                f"`{station.robot.flange_link}`",
                f"({', '.join(short(v) for v in pos)}), ({', '.join(short(v) for v in rpy)})",
                _finger_axis(loaded),
            )
        )
    return rows


def _jaw(load_station: Load) -> list[Loaded]:
    """Each parallel jaw of the shipped cells, loaded on the first robot that carries it."""
    jaws: dict[str, Loaded] = {}
    for _, cell in shipped_cells():
        for station in cell.stations:
            if isinstance(station.tool, ParallelJawSpec) and station.tool.name not in jaws:
                jaws[station.tool.name] = load_station(station)
    return list(jaws.values())


def _palm(loaded: Loaded) -> str:
    """The link the fingers hang from."""
    assert isinstance(loaded.station.tool, ParallelJawSpec)
    joint = loaded.robot.joint_index(loaded.station.tool.joints[0], "finger joint")
    return loaded.robot.link_name(loaded.robot.infos[joint][16])


def _span(low: float, high: float) -> str:
    """``±v`` for an interval symmetric about 0 (to 0.1 mm), else ``low to high``."""
    if short(-low) == short(high):
        return f"±{short(high)}"
    return f"{short(low)} to {short(high)}"


def jaw_rows(load_station: Load) -> list[str]:
    """The page's jaw-geometry table, measured on the collision shapes in PyBullet: the open
    fingers' and the palm's reach along each TCP axis, the pads' gap at full opening."""
    rows = []
    for loaded in _jaw(load_station):
        spec = loaded.station.tool
        assert isinstance(spec, ParallelJawSpec)
        loaded.set_fingers(1.0)
        first, second = spec.links
        palm = _palm(loaded)
        half_x = max(loaded.reach(link, 0, s) for link in spec.links for s in (1.0, -1.0))
        outer_low, outer_high = -loaded.reach(second, 1, -1.0), loaded.reach(first, 1, 1.0)
        tips = max(loaded.reach(link, 2, 1.0) for link in spec.links)
        rows.append(
            row(
                f"`{spec.name}`",
                f"0 to {spec.max_opening_m:g}",
                short(loaded.gap(first, second)),
                short(spec.pad_height_m),
                short(half_x),
                _span(outer_low, outer_high),
                short(tips),
                short(-loaded.reach(palm, 2, 1.0)),
                f"{_span(-loaded.reach(palm, 0, -1.0), loaded.reach(palm, 0, 1.0))}; "
                f"{_span(-loaded.reach(palm, 1, -1.0), loaded.reach(palm, 1, 1.0))}",
            )
        )
    return rows


def test_the_tcp_frames_and_the_jaws_axes_are_what_the_twin_loads(
    interfaces_page: Page, load_station: Load
) -> None:
    assert_rows(interfaces_page, "TCP frames", tcp_frame_rows(load_station))


def test_the_jaw_geometry_is_the_collision_shapes(
    interfaces_page: Page, load_station: Load
) -> None:
    assert_rows(interfaces_page, "Jaw geometry", jaw_rows(load_station))


def test_the_first_finger_is_on_the_tcps_plus_y_side(load_station: Load) -> None:
    """What "one from each side" along y means: the first finger link lies at +y."""
    for loaded in _jaw(load_station):
        assert isinstance(loaded.station.tool, ParallelJawSpec)
        first, second = loaded.station.tool.links
        assert loaded.in_tcp(first)[1] > 0 > loaded.in_tcp(second)[1]


def test_the_tool_commands_are_the_catalogues(interfaces_page: Page) -> None:
    text = interfaces_page.flat("Tools")
    for _, cell in shipped_cells():
        for station in cell.stations:
            tool = station.tool
            if isinstance(tool, ParallelJawSpec):
                assert f"`{tool.name}` {tool.max_opening_m:g}" in text, tool.name


# -- pick success -------------------------------------------------------------------------------
def test_the_grasp_rule_numbers_are_the_tools(interfaces_page: Page) -> None:
    from twin.tools.parallel_jaw import GRIP_TOLERANCE_M, RELEASE_GAP_M

    text = interfaces_page.flat("Pick success")
    tool = _reference().tool
    assert isinstance(tool, ParallelJawSpec)
    assert f"{tool.dwell_s:g} s" in text
    half = ", ".join(f"{v:g}" for v in tool.tcp_half_extents_m)
    assert f"half extents ({half}) m for the Panda hand (`tcp_half_extents_m`)" in text
    assert f"{1e3 * GRIP_TOLERANCE_M:g} mm" in text
    assert f"{-1e3 * RELEASE_GAP_M:g} mm" in text
    assert f"{HOLD_S:g} s" in interfaces_page.section("Arm command")


def test_the_panda_hand_is_ideal_and_the_others_slip() -> None:
    """The page says the Panda hand's grasp has no slip check, the wide gripper's has."""
    grip = {
        s.tool.name: getattr(s.tool, "grip_force_N", None)
        for _, cell in shipped_cells()
        for s in cell.stations
    }
    assert grip["panda_hand"] is None
    assert grip["wide_gripper"] is not None


# -- events --------------------------------------------------------------------------------------
def _event_table(page: Page) -> dict[str, set[str]]:
    """Event type -> documented detail keys, from the page's events table."""
    table: dict[str, set[str]] = {}
    for line in page.rows("Events"):
        kind, _, keys, _ = cells(line)
        (name,) = ticked(kind)
        outside = re.sub(r"\([^)]*\)", "", keys)  # values and notes are in parentheses
        table[name] = set(ticked(outside))
    return table


def _emitted_keys() -> dict[str, set[str]]:
    """Event type -> every ``data`` key any emitter in the twin passes with it (from the
    source: ``emit(EventType.X, record, key=...)``, ``_record(EventType.X, {...})`` and
    ``Event(type=EventType.X, data={...})``)."""
    found: dict[str, set[str]] = {}
    for module in ("monitor", "monitor_records", "sim", "ros_node"):
        tree = ast.parse((ROOT / "twin" / f"{module}.py").read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            args = list(node.args) + [k.value for k in node.keywords if k.arg == "type"]
            kinds = [
                a.attr
                for a in args
                if isinstance(a, ast.Attribute)
                and isinstance(a.value, ast.Name)
                and a.value.id == "EventType"
            ]
            if not kinds:
                continue
            keys = {k.arg for k in node.keywords if k.arg not in (None, "type", "data")}
            if keys and any(k.arg in {"time_s", "object_id"} for k in node.keywords):
                keys = set()  # Event(...) itself: its data is the dict below
            dicts: list[ast.expr] = [a for a in node.args if isinstance(a, ast.Dict)]
            dicts += [k.value for k in node.keywords if k.arg == "data"]
            for d in dicts:
                if isinstance(d, ast.Dict):
                    keys |= {str(k.value) for k in d.keys if isinstance(k, ast.Constant)}
            found.setdefault(EventType[kinds[0]].value, set()).update(
                k for k in keys if k is not None
            )
    found["spawned"] |= _spawn_fit_keys()
    return found


def _spawn_fit_keys() -> set[str]:
    """The keys :class:`twin.spawn_fit.SpawnFit` adds to a ``spawned`` event's data (the
    dicts it returns, from the source)."""
    tree = ast.parse((ROOT / "twin" / "spawn_fit.py").read_text(encoding="utf-8"))
    return {
        str(key.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Return) and isinstance(node.value, ast.Dict)
        for key in node.value.keys
        if isinstance(key, ast.Constant)
    }


def test_the_page_lists_exactly_the_event_types(interfaces_page: Page) -> None:
    assert sorted(_event_table(interfaces_page)) == sorted(e.value for e in EventType)


def test_the_page_lists_every_detail_key_each_event_is_emitted_with(
    interfaces_page: Page,
) -> None:
    documented = _event_table(interfaces_page)
    emitted = _emitted_keys()
    assert set(emitted) == {e.value for e in EventType}  # every type is emitted somewhere
    for kind, keys in emitted.items():
        assert keys == documented[kind], kind


def test_the_event_logs_fields_are_documented(interfaces_page: Page) -> None:
    """``events.jsonl``'s keys, each named in the Events section, and nothing else."""
    line = Event(time_s=0.5, step=120, type=EventType.MISSED, object_id=3, data={}).to_json()
    keys = set(re.findall(r'"([a-z_]+)":', line))
    text = interfaces_page.flat("Events")
    paragraph = text[text.index("`events.jsonl`") : text.index("| `type`")]
    assert keys <= set(ticked(paragraph)), keys - set(ticked(paragraph))


def test_the_sorting_event_message_names_only_real_event_types() -> None:
    text = (MSG_DIR / "SortingEvent.msg").read_text(encoding="utf-8")
    comment = text[text.index("# Event type") : text.index("string type")]
    assert set(re.findall(r'"([a-z_]+)"', comment)) == {e.value for e in EventType}


# -- faults ------------------------------------------------------------------------------------
def _fault_kinds_in_code() -> set[str]:
    """Every ``fault`` kind the twin can record: rejection reasons, controller timeouts,
    injected faults."""
    kinds: set[str] = set()
    for module in ("commands", "ros_node", "claims_relay", "step_loop", "sim"):
        tree = ast.parse((ROOT / "twin" / f"{module}.py").read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and node.args:
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                first = node.args[0]
                if name in {"Rejected", "record_fault"} and isinstance(first, ast.Constant):
                    kinds.add(str(first.value))
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and node.value.startswith("injected_")
            ):
                kinds.add(node.value)
    return kinds


def test_the_page_lists_every_fault_kind(interfaces_page: Page) -> None:
    documented = {
        name for line in interfaces_page.rows("Faults") for name in ticked(cells(line)[0])
    }
    assert documented == _fault_kinds_in_code()


# -- topics, stamps, tracking, the message comments -----------------------------------------
def test_the_topic_tables_are_the_contract(interfaces_page: Page) -> None:
    """Name, scope, type and QoS of every topic, in the contract's order, then a camera's
    (:mod:`interfaces.camera_topics`; rate and notes are the page's own)."""
    for title, topics in (
        ("Published by the cell (the twin)", contract.PUBLISHED + camera_topics("NAME").all),
        ("Subscribed by the cell", contract.SUBSCRIBED),
    ):
        got = [tuple(cells(line)[:4]) for line in interfaces_page.rows(title)]
        expected = [
            (f"`{t.name}`", t.scope, f"`{t.package}/{t.type_name}`", t.qos.describe())
            for t in topics
        ]
        assert got == expected, f"{title}: the first four columns should read:\n" + "\n".join(
            " | ".join(c) for c in expected
        )


def test_the_command_stamp_and_latency_rule_is_stated(interfaces_page: Page) -> None:
    from twin.telemetry import RING_SIZE

    text = interfaces_page.flat("Arm command")
    assert (
        "`header.stamp`: the stamp of the station's `joint_states` message the command was "
        "computed from"
    ) in text
    assert f"over the last {RING_SIZE} stamps" in text


def test_the_tracking_time_rule_is_the_metrics(interfaces_page: Page) -> None:
    from twin.target_metric import PURSUIT_PHASES, TargetTracker

    tracker = TargetTracker()
    text = interfaces_page.flat("Tracking time")
    phases = re.search(r"`phase` one of (.*?): ", text)
    assert phases
    assert set(ticked(phases.group(1))) == PURSUIT_PHASES
    assert f"within {tracker.match_radius_m:g} m" in text
    assert f"below {1e3 * tracker.threshold_m:g} mm" in text
    # the message that carries the phase names the same ones, and the same radius
    comment = (MSG_DIR / "PickTarget.msg").read_text(encoding="utf-8")
    assert f"within {tracker.match_radius_m:g} m" in " ".join(comment.replace("#", " ").split())
    comment = comment[comment.index("# Phase of the pick") : comment.index("string phase")]
    named = re.findall(r'"([a-z_]+)"', comment[: comment.index("(a pursuit)")])
    assert set(named) == PURSUIT_PHASES


def test_every_message_that_names_the_frames_origin_puts_it_at_the_robot_base(
    interfaces_page: Page,
) -> None:
    assert "origin at the robot base" in interfaces_page.text
    assert _reference().base_position_m == (0.0, 0.0, 0.0)
    for msg in sorted(MSG_DIR.glob("*.msg")):
        text = " ".join(msg.read_text(encoding="utf-8").replace("#", " ").split())
        for origin in re.findall(r"origin at [^,;)]*", text):
            assert origin == "origin at the robot base", f"{msg.name}: {origin!r}"


def test_the_detection_message_states_the_confidence_model() -> None:
    cfg = PerceptionConfig()
    text = " ".join((MSG_DIR / "Detection.msg").read_text(encoding="utf-8").split())
    assert f"mean {cfg.confidence_correct_mean:g} for a correct class" in text
    assert f"{cfg.confidence_wrong_mean:g} for a misclassified one" in text
    assert f"(concentration {cfg.confidence_concentration:g})" in text


def test_the_bins_message_names_the_station_topic() -> None:
    """``SortingBins`` is published per station, under the station's namespace."""
    comment = (MSG_DIR / "SortingBins.msg").read_text(encoding="utf-8").replace("#", " ")
    text = " ".join(comment.split())
    assert f"each station's {contract.BINS.name}" in text
    assert f"{contract.BINS.resolve('')} for the empty namespace" in text
    assert f"{contract.BINS.resolve('s1')} for namespace s1" in text
    assert "z the top of its rim (below the belt surface in the shipped cells)" in " ".join(
        (MSG_DIR / "SortingBin.msg").read_text(encoding="utf-8").replace("#", " ").split()
    )
    for _, cell in shipped_cells():
        assert all(b.top_z_m < cell.belt.surface_z_m for b in cell.bins), cell.name


# -- a hand-started twin node's ROS environment ---------------------------------------------
def test_a_hand_started_twin_node_keeps_the_callers_domain(interfaces_page: Page) -> None:
    """What the page says of ``cdw-twin twin-node``: it keeps ``ROS_DOMAIN_ID`` and sets the
    discovery range only where the environment does not; the node calls exactly that."""
    from twin.ros_isolation import local_ros_defaults

    text = interfaces_page.flat("Timing modes")
    assert "keeps the caller's `ROS_DOMAIN_ID`" in text
    env = {"ROS_DOMAIN_ID": "17"}
    local_ros_defaults(env)
    assert env["ROS_DOMAIN_ID"] == "17"
    assert f"`ROS_AUTOMATIC_DISCOVERY_RANGE` to `{env['ROS_AUTOMATIC_DISCOVERY_RANGE']}`" in text
    own = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    local_ros_defaults(own)
    assert own["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert "ROS_DOMAIN_ID" not in own
    source = (ROOT / "twin" / "cmd_node.py").read_text(encoding="utf-8")
    calls = {
        node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Call)
    }
    assert "local_ros_defaults" in calls
    assert not calls & {"ros_domain", "isolated_ros_env", "claim_domain"}
