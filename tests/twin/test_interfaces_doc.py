"""``docs/interfaces.md`` against the code: every number and name a controller relies on.

The page's tables are compared with what the twin actually loads and emits (the robot from its
URDF in PyBullet, the shipped cell files, the topic contract :mod:`interfaces.contract`, the
event types and the keys every emitter passes, the rejection reasons). Where a table is
generated, the failure message prints the lines the page should carry.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest

from interfaces import contract
from interfaces.cell import CELLS_DIR, DEFAULT_CELL, Cell, StationSpec, default_cell, load_cell
from interfaces.events import EventType
from interfaces.urdf import station_urdf
from twin.perception import PerceptionConfig
from twin.robot import HOLD_S, Robot

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "interfaces.md"
SORTING_EVENT_MSG = ROOT / "interfaces" / "cdw_interfaces" / "msg" / "SortingEvent.msg"


def _page() -> str:
    return PAGE.read_text(encoding="utf-8")


def _section(title: str) -> str:
    """The text of the page's section (any level) titled ``title``, up to the next heading."""
    match = re.search(rf"^#+ {re.escape(title)}\n(.*?)(?=^#+ |\Z)", _page(), re.M | re.S)
    assert match, f"docs/interfaces.md has no section {title!r}"
    return match.group(1)


def _table_lines(section: str) -> list[str]:
    """The body rows of the first table in ``section`` (header and rule dropped)."""
    rows = [line for line in section.splitlines() if line.startswith("|")]
    return rows[2:]


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in row.strip().strip("|").split("|")]


def _ticked(text: str) -> list[str]:
    return re.findall(r"`([^`]+)`", text)


def _num(value: float, digits: int = 4) -> str:
    text = f"{value:.{digits}f}"
    return "0." + "0" * digits if float(text) == 0.0 else text  # no "-0.0000"


def _station() -> StationSpec:
    return default_cell().stations[0]


@pytest.fixture(scope="module")
def robot() -> Iterator[Robot]:
    """The reference cell's Panda as the twin loads it (PyBullet, from the station's URDF,
    which carries the datasheet's joint limits)."""
    client = pb.connect(pb.DIRECT)
    try:
        station = _station()
        yield Robot(
            client,
            station.robot,
            base_position_m=station.base_position_m,
            base_yaw_rad=station.base_yaw_rad,
            urdf=station_urdf(station.robot, station.tool),
        )
    finally:
        pb.disconnect(physicsClientId=client)


def _tcp_from_flange(robot: Robot) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Position (m) and roll-pitch-yaw (rad) of the TCP link in the flange (``panda_link8``)."""
    c = robot.client
    flange_link = robot.link_index("panda_link8", "flange")
    flange = pb.getLinkState(
        robot.body, flange_link, computeForwardKinematics=True, physicsClientId=c
    )
    tcp_link = robot.link_index(_station().tool.tcp_link, "TCP link")
    tcp = pb.getLinkState(robot.body, tcp_link, computeForwardKinematics=True, physicsClientId=c)
    inv_pos, inv_orn = pb.invertTransform(flange[4], flange[5])
    pos, orn = pb.multiplyTransforms(inv_pos, inv_orn, tcp[4], tcp[5])
    return tuple(pos), tuple(pb.getEulerFromQuaternion(orn))


def _row(*cells: str) -> str:
    return "| " + " | ".join(cells) + " |"


def robot_rows(robot: Robot) -> list[str]:
    """The page's robot table, from the loaded robot and the reference cell's station."""
    station = _station()
    spec, tool = station.robot, station.tool
    pos, rpy = _tcp_from_flange(robot)
    xyz = ", ".join(_num(v) for v in pos)
    angles = ", ".join(_num(v) for v in rpy)
    home = ", ".join(f"{q:g}" for q in spec.home_joint_positions)
    fingers = [robot.infos[robot.joint_index(j, "finger joint")] for j in tool.joints]
    finger_range = f"{min(f[8] for f in fingers):g} to {max(f[9] for f in fingers):g} m each"
    base = ", ".join(f"{v:g}" for v in station.base_position_m)
    arm = ", ".join(f"`{j}`" for j in spec.arm_joints)
    finger_names = ", ".join(f"`{j}`" for j in tool.joints)
    return [
        _row(
            "model",
            f"URDF `{spec.urdf}` from `pybullet_data` (Franka Emika Panda with its hand): "
            f"robot `{spec.name}`, tool `{tool.name}`",
        ),
        _row(
            "base",
            f"link `panda_link0` at ({base}) m, yaw {station.base_yaw_rad:g} rad: "
            "the base frame is `world`",
        ),
        _row("arm joints", f"{arm} (revolute)"),
        _row(
            "finger joints",
            f"{finger_names} (prismatic, {finger_range}; report half the opening)",
        ),
        _row(
            "TCP",
            f"link `{tool.tcp_link}`; from the flange `panda_link8`: xyz ({xyz}) m, "
            f"rpy ({angles}) rad",
        ),
        _row("gripper opening", f"0 (closed) to {tool.max_opening_m:g} m (open)"),
        _row("start pose", f"arm joints ({home}) rad, gripper open"),
    ]


def limit_rows(robot: Robot) -> list[str]:
    """The page's joint-limit table, as the twin loads the limits from the station's URDF (and
    the acceleration limits its joint limiter applies, from the robot's spec)."""
    lim = robot.limits
    accel = robot.spec.joint_max_acceleration_rps2
    return [
        _row(
            f"`{name}`",
            _num(lim.lower[i]),
            _num(lim.upper[i]),
            _num(lim.velocity[i]),
            f"{accel[i]:g}",
            f"{lim.effort[i]:g}",
        )
        for i, name in enumerate(robot.spec.arm_joints)
    ]


def bin_rows(cell: Cell) -> list[str]:
    """The page's bin table, from the cell."""
    return [
        _row(
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


def belt_rows(cell: Cell) -> list[str]:
    """The page's belt table."""
    belt = cell.belt
    return [
        _row(
            "belt",
            f"x from {belt.start_x_m:g} to {belt.end_x_m:g} m, {belt.width_m:g} m wide about its "
            f"centreline y = {belt.centre_y_m:g} m, surface at z = {belt.surface_z_m:g} m; "
            f"objects enter at x = {belt.infeed_x_m:g} m and fall off beyond "
            f"x = {belt.end_x_m:g} m",
        ),
    ]


def shipped_cells() -> list[Cell]:
    """Every shipped cell, the reference first."""
    others = sorted(p for p in CELLS_DIR.glob("*.yaml") if p != DEFAULT_CELL)
    return [default_cell(), *(load_cell(p) for p in others)]


def station_rows() -> list[str]:
    """The page's table of the shipped cells' stations."""
    rows = []
    for path, cell in zip(
        [DEFAULT_CELL, *sorted(p for p in CELLS_DIR.glob("*.yaml") if p != DEFAULT_CELL)],
        shipped_cells(),
        strict=True,
    ):
        for s in cell.stations:
            base = ", ".join(f"{v:g}" for v in s.base_position_m)
            lo, hi = s.pick_window_x_m
            rows.append(
                _row(
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


def camera_rows(cfg: PerceptionConfig, cell: Cell) -> list[str]:
    """The page's camera-model table (the defaults; a scenario's ``perception:`` overrides the
    error model, the cell's ``camera`` the field of view)."""
    camera = cell.camera
    return [
        _row(
            "field of view",
            f"x in [{camera.fov_min_x_m:g}, {camera.fov_max_x_m:g}] m (the cell's `camera`), "
            "objects on the belt only",
        ),
        _row("rate, latency", f"{cfg.rate_hz:g} Hz, {cfg.latency_s:g} s"),
        _row(
            "noise (1 sigma)",
            f"position {cfg.position_noise_m:g} m in x and y, yaw {cfg.yaw_noise_rad:g} rad",
        ),
        _row(
            "drops, misclassification",
            f"{cfg.drop_rate:g}, {cfg.misclassification_rate:g} per detection "
            "(a wrong class: uniform among the others)",
        ),
        _row(
            "`confidence`",
            f"Beta(k m, k (1 - m)), k = {cfg.confidence_concentration:g}; "
            f"m = {cfg.confidence_correct_mean:g} when the class is right, "
            f"{cfg.confidence_wrong_mean:g} when it is wrong; 1 from the zero-noise camera",
        ),
    ]


def topic_cells(topics: tuple[contract.Topic, ...]) -> list[tuple[str, str, str, str]]:
    """Topic, scope, type and QoS of each topic, as the page's topic tables write them."""
    return [
        (f"`{t.name}`", t.scope, f"`{t.package}/{t.type_name}`", t.qos.describe()) for t in topics
    ]


def _assert_rows(title: str, expected: list[str]) -> None:
    got = _table_lines(_section(title))
    assert got == expected, "the table of '" + title + "' should read:\n" + "\n".join(expected)


def test_the_robot_table_is_what_the_twin_loads(robot: Robot) -> None:
    _assert_rows("The robot", robot_rows(robot))


def test_the_joint_limits_are_those_the_twin_loads_from_the_urdf(robot: Robot) -> None:
    _assert_rows("Joint limits", limit_rows(robot))
    # and the numbers are the URDF's, not a default the loader would put in their place
    assert np.all(robot.limits.velocity != 2.0)
    assert np.all(robot.limits.upper > robot.limits.lower)


def test_the_tcp_offset_is_the_urdfs(robot: Robot) -> None:
    pos, rpy = _tcp_from_flange(robot)
    assert pos == pytest.approx((0.0, 0.0, 0.105), abs=1e-6)
    assert rpy == pytest.approx((0.0, 0.0, -math.pi / 4), abs=1e-6)


def test_the_cell_bins_camera_and_station_tables_are_the_shipped_cells() -> None:
    cell = default_cell()
    _assert_rows("The belt", belt_rows(cell))
    _assert_rows("Bins", bin_rows(cell))
    _assert_rows("Perception", camera_rows(PerceptionConfig(), cell))
    _assert_rows("Stations", station_rows())


def test_the_cell_file_section_names_the_files() -> None:
    text = " ".join(_section("The cell file").split())
    assert "`interfaces/cells/default.yaml`" in text
    for path in CELLS_DIR.glob("*.yaml"):
        assert f"`{path.stem}`" in text, path.stem
    assert "--station NAME" in text
    assert "`cell/bins`" in text


def test_the_topic_tables_are_the_contract() -> None:
    """Name, scope, type and QoS of every topic, in the contract's order (rate and notes are
    the page's own)."""
    for title, topics in (
        ("Published by the cell (the twin)", contract.PUBLISHED),
        ("Subscribed by the cell", contract.SUBSCRIBED),
    ):
        got = [tuple(_cells(row)[:4]) for row in _table_lines(_section(title))]
        expected = topic_cells(topics)
        assert got == expected, f"{title}: the first four columns should read:\n" + "\n".join(
            " | ".join(cells) for cells in expected
        )


def test_the_grasp_rule_numbers_are_the_tools() -> None:
    from twin.tools.parallel_jaw import GRIP_TOLERANCE_M, RELEASE_GAP_M

    text = _section("Pick success")
    tool = _station().tool
    assert f"{tool.dwell_s:g} s" in text
    half = ", ".join(f"{v:g}" for v in tool.tcp_half_extents_m)
    assert f"half extents ({half}) m" in text
    assert f"{1e3 * GRIP_TOLERANCE_M:g} mm" in text
    assert f"{-1e3 * RELEASE_GAP_M:g} mm" in text
    assert f"{HOLD_S:g} s" in _section("Arm command")


# -- events ------------------------------------------------------------------------------------
def _event_table() -> dict[str, set[str]]:
    """Event type -> documented detail keys, from the page's events table."""
    table: dict[str, set[str]] = {}
    for row in _table_lines(_section("Events")):
        kind, _, keys, _ = _cells(row)
        (name,) = _ticked(kind)
        outside = re.sub(r"\([^)]*\)", "", keys)  # values and notes are in parentheses
        table[name] = set(_ticked(outside))
    return table


def _emitted_keys() -> dict[str, set[str]]:
    """Event type -> every ``data`` key any emitter in the twin passes with it (from the
    source: ``emit(EventType.X, record, key=...)``, ``_record(EventType.X, {...})`` and
    ``Event(type=EventType.X, data={...})``)."""
    found: dict[str, set[str]] = {}
    for module in ("monitor", "sim", "ros_node"):
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
            dicts = [a for a in node.args if isinstance(a, ast.Dict)]
            dicts += [k.value for k in node.keywords if k.arg == "data"]
            for d in dicts:
                if isinstance(d, ast.Dict):
                    keys |= {k.value for k in d.keys if isinstance(k, ast.Constant)}
            found.setdefault(EventType[kinds[0]].value, set()).update(keys)
    return found


def test_the_page_lists_exactly_the_event_types() -> None:
    assert sorted(_event_table()) == sorted(e.value for e in EventType)


def test_the_page_lists_every_detail_key_each_event_is_emitted_with() -> None:
    documented = _event_table()
    emitted = _emitted_keys()
    # every type is emitted somewhere in the twin
    assert set(emitted) == {e.value for e in EventType}
    for kind, keys in emitted.items():
        assert keys == documented[kind], kind


def test_the_sorting_event_message_names_only_real_event_types() -> None:
    text = SORTING_EVENT_MSG.read_text(encoding="utf-8")
    comment = text[text.index("# Event type") : text.index("string type")]
    named = set(re.findall(r'"([a-z_]+)"', comment))
    assert named == {e.value for e in EventType}


# -- faults ------------------------------------------------------------------------------------
def _fault_kinds_in_code() -> set[str]:
    """Every ``fault`` kind the twin can record: rejection reasons, controller timeouts,
    injected faults."""
    kinds: set[str] = set()
    for module in ("commands", "ros_node", "sim"):
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


def test_the_page_lists_every_fault_kind() -> None:
    documented = {
        name for row in _table_lines(_section("Faults")) for name in _ticked(_cells(row)[0])
    }
    assert documented == _fault_kinds_in_code()


# -- stamps, metrics and the message comments ----------------------------------------------------
MSG_DIR = ROOT / "interfaces" / "cdw_interfaces" / "msg"


def test_the_command_stamp_and_latency_rule_is_stated() -> None:
    from twin.telemetry import RING_SIZE

    text = " ".join(_section("Arm command").split())
    assert (
        "`header.stamp`: the stamp of the station's `joint_states` message the command was "
        "computed from"
    ) in text
    assert f"over the last {RING_SIZE} stamps" in text


def test_the_tracking_time_rule_is_the_metrics() -> None:
    from twin.target_metric import PURSUIT_PHASES, TargetTracker

    tracker = TargetTracker()
    text = " ".join(_section("Tracking time").split())
    phases = re.search(r"`phase` one of (.*?): ", text)
    assert phases
    assert set(_ticked(phases.group(1))) == PURSUIT_PHASES
    assert f"within {tracker.match_radius_m:g} m" in text
    assert f"below {1e3 * tracker.threshold_m:g} mm" in text
    # the message that carries the phase names the same ones
    comment = (MSG_DIR / "PickTarget.msg").read_text(encoding="utf-8")
    comment = comment[comment.index("# Phase of the pick") : comment.index("string phase")]
    named = re.findall(r'"([a-z_]+)"', comment[: comment.index("(a pursuit)")])
    assert set(named) == PURSUIT_PHASES


def test_every_message_that_names_the_frames_origin_puts_it_at_the_robot_base() -> None:
    assert "origin at the robot base" in _page()
    assert default_cell().stations[0].base_position_m == (0.0, 0.0, 0.0)
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
