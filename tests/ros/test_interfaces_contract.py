"""``docs/interfaces.md``'s topic tables against the real nodes, and what the twin node latches.

A real :class:`twin.ros_node.TwinNode` (around a real twin) and a real
:class:`control.node.ControllerNode` are created in this process on an isolated domain; their
publishers and subscriptions, with types and QoS, are compared with the page, so the page
cannot drift from the code.
"""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call"

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest
from twin_helpers import box_px

from twin.config import CellConfig
from twin.scenario import FaultLevel, Scenario, SystemLevel
from twin.sim import Twin

pytestmark = pytest.mark.usefixtures("require_interfaces")

PAGE = Path(__file__).resolve().parents[2] / "docs" / "interfaces.md"
ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}
ROS_OWN_TOPICS = {"/rosout", "/parameter_events"}


class Qos(NamedTuple):
    """What the page states of a topic: type and QoS."""

    msg_type: str
    reliability: str
    durability: str
    depth: int


def _table(title: str) -> dict[str, Qos]:
    """Topic -> type and QoS, from the page's table under the heading ``title``."""
    text = PAGE.read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"docs/interfaces.md has no section {title!r}"
    lines = match.group(1).splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []  # the section's first table
    for line in lines[first:]:
        if not line.startswith("|"):
            break
        rows.append(line)
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    col = {name: header.index(name) for name in ("topic", "type", "QoS")}
    table = {}
    for row in rows[2:]:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        qos = re.fullmatch(
            r"(reliable|best effort), (volatile|transient local), keep last (\d+)",
            cells[col["QoS"]],
        )
        assert qos, f"unparsable QoS {cells[col['QoS']]!r} in {row!r}"
        table[cells[col["topic"]].strip("`")] = Qos(
            cells[col["type"]].strip("`"), qos.group(1), qos.group(2), int(qos.group(3))
        )
    return table


def _of(endpoint: Any) -> Qos:
    """Type and QoS of a real publisher or subscription, in the page's words."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

    qos = endpoint.qos_profile
    assert qos.history == HistoryPolicy.KEEP_LAST, endpoint.topic_name
    msg_type = endpoint.msg_type
    reliability = {
        ReliabilityPolicy.RELIABLE: "reliable",
        ReliabilityPolicy.BEST_EFFORT: "best effort",
    }[qos.reliability]
    durability = {
        DurabilityPolicy.VOLATILE: "volatile",
        DurabilityPolicy.TRANSIENT_LOCAL: "transient local",
    }[qos.durability]
    return Qos(
        f"{msg_type.__module__.split('.')[0]}/{msg_type.__name__}",
        reliability,
        durability,
        int(qos.depth),
    )


def _endpoints(items: Iterator[Any]) -> dict[str, Qos]:
    return {e.topic_name: _of(e) for e in items if e.topic_name not in ROS_OWN_TOPICS}


@pytest.fixture
def ros(ros_env: dict[str, str]) -> Iterator[Any]:
    """rclpy initialised on an isolated domain, with an executor; shut down after the test."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor

    saved = dict(os.environ)
    os.environ.update(ros_env)
    rclpy.init()
    executor = EventsExecutor()
    try:
        yield executor
    finally:
        executor.shutdown()
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)


@pytest.fixture
def twin(mesh_polygons: Callable[..., Path]) -> Iterator[Twin]:
    """A real twin with one object; 0.2 s long, a detection dropout from 0.05 s to 0.1 s."""
    scenario = Scenario(
        duration_s=0.2,
        system=SystemLevel(belt_speed_mps=0.2, prefill_m=1.7, repeat_images=False),
        faults=FaultLevel(detection_dropout=((0.05, 0.1),)),
    )
    with Twin(scenario, dataset_dir=mesh_polygons(ONE_BOX)) as twin:
        twin.reset(seed=0)
        yield twin


def _spin_until(executor: Any, done: Callable[[], bool], timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.02)


def test_the_twin_nodes_topics_types_and_qos_are_the_pages(ros: Any, twin: Twin) -> None:
    from twin.ros_node import TwinNode

    node = TwinNode(twin, lockstep=True)
    try:
        published = _endpoints(node.publishers)
        subscribed = _endpoints(node.subscriptions)
    finally:
        node.destroy_node()
    assert published == _table("Published by the cell (the twin)")
    assert subscribed == _table("Subscribed by the cell")


def test_the_controller_uses_the_pages_qos_on_every_topic(ros: Any, twin: Twin) -> None:
    """The controller's side of each topic it uses (its ack publisher is created once its
    readers have matched the twin's writers, so both nodes run here)."""
    from control.config import ControllerConfig
    from control.node import ControllerNode
    from twin.ros_node import TwinNode

    twin_node = TwinNode(twin, lockstep=True)
    controller = ControllerNode(ControllerConfig(), lockstep=True)
    ros.add_node(twin_node)
    ros.add_node(controller)
    try:
        _spin_until(ros, lambda: controller.pub_ack is not None)
        published = _endpoints(controller.publishers)
        subscribed = _endpoints(controller.subscriptions)
    finally:
        controller.destroy_node()
        twin_node.destroy_node()
    cell_in = _table("Subscribed by the cell")
    cell_out = _table("Published by the cell (the twin)")
    assert set(published) == {
        "/arm_controller/joint_trajectory",
        "/gripper/command",
        "/controller/target",
        "/lockstep/ack",
    }
    assert published == {topic: cell_in[topic] for topic in published}
    assert "/sorting/priorities" in subscribed
    page = {**cell_out, **cell_in}  # /sorting/priorities: the controller reads it too
    assert subscribed == {topic: page[topic] for topic in subscribed}


def test_a_late_subscriber_gets_the_bins_and_every_logged_event(ros: Any, twin: Twin) -> None:
    """``/cell/bins`` is latched from the start; ``/events`` carries every event the twin logs,
    injected faults included (they used to stay in the episode log only)."""
    import rclpy
    from cdw_interfaces.msg import SortingBins, SortingEvent

    from twin.ros_node import EVENT_QOS, LATCHED_QOS, TwinNode, run_loop

    twin_node = TwinNode(twin, lockstep=False)
    ros.add_node(twin_node)
    run_loop(twin_node, ros)
    listener = rclpy.create_node("late_listener")
    bins: list[Any] = []
    events: list[Any] = []
    listener.create_subscription(SortingBins, "/cell/bins", bins.append, LATCHED_QOS)
    listener.create_subscription(SortingEvent, "/events", events.append, EVENT_QOS)
    ros.add_node(listener)
    try:
        _spin_until(ros, lambda: bool(bins) and len(events) >= len(twin.events))
    finally:
        listener.destroy_node()
        twin_node.destroy_node()
    (msg,) = bins
    assert msg.header.frame_id == "world"
    got = [
        (b.class_name, b.position.x, b.position.y, b.position.z, b.inner_half_m, b.size_m)
        for b in msg.bins
    ]
    cell = CellConfig()
    assert got == [
        (b.class_name, b.centre_x_m, b.centre_y_m, b.top_z_m, b.inner_half_m, b.size_m)
        for b in cell.bins
    ]
    assert [(e.type, e.object_id) for e in events] == [
        (str(e.type), e.object_id) for e in twin.events
    ]
    faults = [e.detail for e in events if e.type == "fault"]
    assert len(faults) == 2
    assert all("injected_detection_dropout" in text for text in faults)
